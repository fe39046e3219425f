//! Several cascades on one still image, as `rccar detect` runs them: the flags' bounds
//! ([`check_options`]), the image in grey (as
//! OpenCV's `cvtColor`), every cascade's boxes (with the traffic-light reading inside each when
//! asked), the image's JSON line ([`image_record`]), and a copy of the image with the boxes
//! drawn, one colour per cascade.

use super::{gray_from_rgb, light_state, DetectError, DetectParams, Detection, Detector, LightReading, Rect};
use image::{DynamicImage, GrayImage, Rgb, RgbImage};

/// Outline colours, one per cascade (repeating after six).
pub const COLOURS: [[u8; 3]; 6] = [
    [255, 40, 40],
    [40, 220, 40],
    [60, 120, 255],
    [255, 200, 0],
    [255, 0, 255],
    [0, 220, 220],
];

/// One box found in the image.
#[derive(Debug, Clone)]
pub struct FoundBox {
    /// Index of the cascade that found it.
    pub cascade: usize,
    /// The box and its raw hits.
    pub detection: Detection,
    /// The traffic-light reading inside it (when asked for).
    pub light: Option<LightReading>,
}

/// Bounds of `--scale-factor`: at 1.01 a 4096-pixel image already has ~500 pyramid levels.
pub const SCALE_FACTOR: (f64, f64) = (1.01, 4.0);
/// Most `--cascade` files (each runs on every image).
pub const MAX_CASCADES: usize = 16;
/// Largest `--min-neighbors` (as `detect.min_neighbors`).
pub const MAX_MIN_NEIGHBORS: u32 = 100;

/// `rccar detect`'s options out of their bounds (the message names the flag and the bound).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptionsError {
    /// `--scale-factor` outside [`SCALE_FACTOR`].
    #[error("--scale-factor {0}: must be {min}..={max} (the ratio between pyramid levels; nearer 1 means more levels: 1.0000001 would ask for millions)", min = SCALE_FACTOR.0, max = SCALE_FACTOR.1)]
    ScaleFactor(f64),
    /// More than [`MAX_CASCADES`] cascades.
    #[error("{0} --cascade files: at most {MAX_CASCADES} (each runs on every image)")]
    Cascades(usize),
    /// `--min-neighbors` above [`MAX_MIN_NEIGHBORS`].
    #[error("--min-neighbors {0}: must be 0..={MAX_MIN_NEIGHBORS}")]
    MinNeighbors(u32),
    /// A box size side above the largest image side.
    #[error("{flag} {}x{}: each side must be 0..={max_side} pixels (the largest image side)", size.0, size.1)]
    Size {
        /// `--min-size` or `--max-size`.
        flag: &'static str,
        /// The size given.
        size: (u32, u32),
        /// The largest image side, pixels.
        max_side: u32,
    },
}

/// Checks `rccar detect`'s `params` and its number of `cascades` against their bounds
/// (`max_side`: the largest image side, pixels).
pub fn check_options(params: &DetectParams, cascades: usize, max_side: u32) -> Result<(), OptionsError> {
    let (lo, hi) = SCALE_FACTOR;
    if !(params.scale_factor >= lo && params.scale_factor <= hi) {
        return Err(OptionsError::ScaleFactor(params.scale_factor));
    }
    if cascades > MAX_CASCADES {
        return Err(OptionsError::Cascades(cascades));
    }
    if params.min_neighbors > MAX_MIN_NEIGHBORS {
        return Err(OptionsError::MinNeighbors(params.min_neighbors));
    }
    for (flag, size) in [("--min-size", params.min_size), ("--max-size", params.max_size)] {
        if size.0 > max_side || size.1 > max_side {
            return Err(OptionsError::Size { flag, size, max_side });
        }
    }
    Ok(())
}

/// The image in colour and in grey (a grey image is taken as it is; colour is converted as
/// OpenCV's `cvtColor(RGB2GRAY)`).
pub fn rgb_and_gray(img: &DynamicImage) -> (RgbImage, GrayImage) {
    let rgb = img.to_rgb8();
    let gray = match img {
        DynamicImage::ImageLuma8(g) => g.clone(),
        _ => {
            let mut g = GrayImage::new(0, 0);
            gray_from_rgb(&rgb, &mut g);
            g
        }
    };
    (rgb, gray)
}

/// The JSON line of one image of `rccar detect`: its name, width and height, and every box
/// with the name (`names[cascade]`) of the cascade that found it, its raw hits and, when read,
/// the traffic light inside it.
pub fn image_record(image: &str, (width, height): (u32, u32), found: &[FoundBox], names: &[String]) -> serde_json::Value {
    let boxes: Vec<serde_json::Value> = found
        .iter()
        .map(|f| {
            let d = &f.detection;
            let mut b = serde_json::json!({
                "cascade": names[f.cascade],
                "x": d.rect.x, "y": d.rect.y, "width": d.rect.width, "height": d.rect.height,
                "neighbors": d.neighbors,
            });
            if let Some(light) = f.light {
                b["light"] = serde_json::json!(light);
            }
            b
        })
        .collect();
    serde_json::json!({"image": image, "width": width, "height": height, "boxes": boxes})
}

/// Every detector's boxes in `gray` with its own scan parameters, in detector order (`light`:
/// with the light reading of `rgb` inside each box); the error names the index of the detector
/// that refused the image.
pub fn detect_all<'a>(
    detectors: impl IntoIterator<Item = (&'a mut Detector, &'a DetectParams)>,
    gray: &GrayImage,
    rgb: &RgbImage,
    light: bool,
) -> Result<Vec<FoundBox>, (usize, DetectError)> {
    let mut boxes = Vec::new();
    for (ci, (det, params)) in detectors.into_iter().enumerate() {
        let found = det.detect(gray, params).map_err(|e| (ci, e))?;
        boxes.extend(found.into_iter().map(|d| FoundBox {
            cascade: ci,
            light: light.then(|| light_state(rgb, d.rect)),
            detection: d,
        }));
    }
    Ok(boxes)
}

/// A copy of `rgb` with every box outlined in its cascade's colour.
pub fn annotated(rgb: &RgbImage, boxes: &[FoundBox]) -> RgbImage {
    let mut img = rgb.clone();
    for b in boxes {
        draw_box(&mut img, b.detection.rect, COLOURS[b.cascade % COLOURS.len()]);
    }
    img
}

/// A 2-pixel outline, clipped to the image.
pub fn draw_box(img: &mut RgbImage, r: Rect, colour: [u8; 3]) {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let mut put = |x: i32, y: i32| {
        if x >= 0 && y >= 0 && x < w && y < h {
            img.put_pixel(x as u32, y as u32, Rgb(colour));
        }
    };
    for t in 0..2 {
        for x in r.x..r.x + r.width {
            put(x, r.y + t);
            put(x, r.y + r.height - 1 - t);
        }
        for y in r.y..r.y + r.height {
            put(r.x + t, y);
            put(r.x + r.width - 1 - t, y);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draw_box_outlines_two_pixels_and_clips() {
        let mut img = RgbImage::new(10, 10);
        draw_box(&mut img, Rect::new(2, 2, 5, 5), [255, 0, 0]);
        // Corners and the second ring are drawn, the inside is not.
        assert_eq!(img.get_pixel(2, 2).0, [255, 0, 0]);
        assert_eq!(img.get_pixel(3, 3).0, [255, 0, 0]);
        assert_eq!(img.get_pixel(6, 6).0, [255, 0, 0]);
        assert_eq!(img.get_pixel(4, 4).0, [0, 0, 0]);
        let lit = img.pixels().filter(|p| p.0 == [255, 0, 0]).count();
        assert_eq!(lit, 24, "5x5 box, 2-pixel outline: 25 - 1 inner pixel");
        // A box reaching past the edge is clipped, not a panic.
        draw_box(&mut img, Rect::new(8, 8, 5, 5), [0, 255, 0]);
        assert_eq!(img.get_pixel(9, 9).0, [0, 255, 0]);
    }
}
