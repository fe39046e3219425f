//! Tight outlines inside a cascade's box, from the object's own colour: a stop sign's red
//! area, a traffic light's dark housing.
//!
//! A cascade's box is only as tight as its scale steps and grouping make it (±10% in size,
//! with a bias that changes with distance); the object's colour edge is a pixel sharp. The
//! region searched is the box grown by `grow` on every side; inside it:
//!
//! 1. Stop sign: a pixel is red when `R ≥ 50`, `R ≥ 1.8·G` and `R ≥ 1.6·B` (turn sign: blue
//!    when `B ≥ 50`, `B ≥ 1.6·R` and `B ≥ 1.2·G`). Traffic light: a
//!    pixel is dark when its luminance is at most `2·L₁₀ + 8`, with L₁₀ the region's 10th
//!    percentile (the housing's own level, whatever the exposure: the housing is the darkest
//!    thing in its box, its post and the floor behind are 2.5–4× brighter, and a two-class
//!    split such as Otsu's puts the floor with the housing when the floor fills the region).
//! 2. Row and column profiles (pixels per row / column); the outline spans the rows and
//!    columns whose count reaches `frac` of the profile's maximum (the thin post under a
//!    housing and single noisy pixels stay below it; a regular octagon's flats are 41% of its
//!    width, above the sign's 20%).
//!
//! The outline is `[left, top, right, bottom]` in pixel-centre coordinates (edges at ±0.5).
//! `None` when fewer than `min_pixels` pixels qualify. Units: pixels.

use super::ObjectClass;
use crate::classes::ColourCue;
use image::RgbImage;

/// How much the search region exceeds the box on each side, as a fraction of its size.
pub const GROW: f64 = 0.15;

/// Smallest fraction of a detector box's pixels in its class's face colour (red for a stop or
/// yield sign, blue for a turn sign) for the box to count: a box without its colour is a false
/// positive of the cascade (a stop sign's cascade firing on a blue turn sign, say).
pub const MIN_COLOUR_FRACTION: f64 = 0.05;

/// Whether a detector box of `class` shows the class's face colour (at least
/// [`MIN_COLOUR_FRACTION`] of its pixels); classes without a face colour always do.
pub fn shows_colour(img: &RgbImage, class: ObjectClass, bbox: [f64; 4]) -> bool {
    let test: fn([u8; 3]) -> bool = match class.info().colour_cue {
        ColourCue::RedFace => red,
        ColourCue::BlueFace => blue,
        ColourCue::LitHousing | ColourCue::None => return true,
    };
    let (w, h) = (img.width() as i64, img.height() as i64);
    let x0 = ((bbox[0] + 0.5).floor() as i64).clamp(0, w);
    let x1 = ((bbox[2] + 0.5).ceil() as i64).clamp(0, w);
    let y0 = ((bbox[1] + 0.5).floor() as i64).clamp(0, h);
    let y1 = ((bbox[3] + 0.5).ceil() as i64).clamp(0, h);
    let total = ((x1 - x0) * (y1 - y0)).max(0) as f64;
    if total == 0.0 {
        return false;
    }
    let mut n = 0usize;
    for y in y0..y1 {
        for x in x0..x1 {
            n += test(img.get_pixel(x as u32, y as u32).0) as usize;
        }
    }
    n as f64 >= MIN_COLOUR_FRACTION * total
}

/// A red face's pixel (stop and yield signs).
fn red(p: [u8; 3]) -> bool {
    let (r, g, b) = (p[0] as u32, p[1] as u32, p[2] as u32);
    r >= 50 && 10 * r >= 18 * g && 10 * r >= 16 * b
}

/// A blue face's pixel (turn signs).
fn blue(p: [u8; 3]) -> bool {
    let (r, g, b) = (p[0] as u32, p[1] as u32, p[2] as u32);
    b >= 50 && 10 * b >= 16 * r && 10 * b >= 12 * g
}

/// The tight outline of `class`'s coloured part inside `bbox` (see the module notes), or
/// `None` (no refinement for obstacles, too few pixels, box outside the image).
pub fn outline(img: &RgbImage, class: ObjectClass, bbox: [f64; 4]) -> Option<[f64; 4]> {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (bw, bh) = (bbox[2] - bbox[0], bbox[3] - bbox[1]);
    let x0 = ((bbox[0] + 0.5 - GROW * bw).floor() as i64).clamp(0, w);
    let x1 = ((bbox[2] + 0.5 + GROW * bw).ceil() as i64).clamp(0, w);
    let y0 = ((bbox[1] + 0.5 - GROW * bh).floor() as i64).clamp(0, h);
    let y1 = ((bbox[3] + 0.5 + GROW * bh).ceil() as i64).clamp(0, h);
    if x1 - x0 < 3 || y1 - y0 < 3 {
        return None;
    }
    let (nx, ny) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let luma = |p: [u8; 3]| (299 * p[0] as u32 + 587 * p[1] as u32 + 114 * p[2] as u32) / 1000;
    // 1. The pixel test.
    let cue = class.info().colour_cue;
    let test: Box<dyn Fn([u8; 3]) -> bool> = match cue {
        ColourCue::RedFace => Box::new(red),
        ColourCue::LitHousing => {
            let mut hist = [0u32; 256];
            for y in y0..y1 {
                for x in x0..x1 {
                    hist[luma(img.get_pixel(x as u32, y as u32).0) as usize] += 1;
                }
            }
            let n: u32 = hist.iter().sum();
            let (mut acc, mut p10) = (0u32, 0u32);
            for (i, &c) in hist.iter().enumerate() {
                acc += c;
                if 10 * acc >= n {
                    p10 = i as u32;
                    break;
                }
            }
            let t = 2 * p10 + 8;
            Box::new(move |p: [u8; 3]| luma(p) <= t)
        }
        ColourCue::BlueFace => Box::new(blue),
        ColourCue::None => return None,
    };
    // 2. Profiles.
    let (mut rows, mut cols) = (vec![0u32; ny], vec![0u32; nx]);
    let mut n = 0u32;
    for y in y0..y1 {
        for x in x0..x1 {
            if test(img.get_pixel(x as u32, y as u32).0) {
                rows[(y - y0) as usize] += 1;
                cols[(x - x0) as usize] += 1;
                n += 1;
            }
        }
    }
    let frac = match cue {
        ColourCue::RedFace => 0.2,
        // A disc's chord is 10% of its diameter 0.5% of the radius from its edge.
        ColourCue::BlueFace => 0.1,
        _ => 0.5,
    };
    if n < 12 {
        return None;
    }
    let span = |p: &[u32]| -> Option<(usize, usize)> {
        let m = *p.iter().max()? as f64;
        let first = p.iter().position(|&c| c as f64 >= frac * m)?;
        let last = p.iter().rposition(|&c| c as f64 >= frac * m)?;
        Some((first, last))
    };
    let (r0, r1) = span(&rows)?;
    let (c0, c1) = span(&cols)?;
    Some([
        (x0 + c0 as i64) as f64 - 0.5,
        (y0 + r0 as i64) as f64 - 0.5,
        (x0 + c1 as i64) as f64 + 0.5,
        (y0 + r1 as i64) as f64 + 0.5,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn a_red_square_on_grey_is_outlined_to_the_pixel() {
        let mut img = RgbImage::from_pixel(60, 50, Rgb([150, 150, 150]));
        for y in 12..30 {
            for x in 20..41 {
                img.put_pixel(x, y, Rgb([200, 30, 30]));
            }
        }
        // A loose box around it, 3 px too big on every side.
        let o = outline(&img, ObjectClass::StopSign, [16.5, 8.5, 43.5, 32.5]).unwrap();
        assert_eq!(o, [19.5, 11.5, 40.5, 29.5]);
    }

    #[test]
    fn a_dark_housing_on_a_post_is_outlined_without_the_post() {
        let mut img = RgbImage::from_pixel(40, 60, Rgb([180, 175, 170]));
        for y in 10..30 {
            for x in 15..24 {
                img.put_pixel(x, y, Rgb([28, 28, 30]));
            }
        }
        for y in 30..60 {
            for x in 18..21 {
                img.put_pixel(x, y, Rgb([70, 72, 75]));
            }
        }
        let o = outline(&img, ObjectClass::TrafficLight, [13.5, 8.5, 25.5, 34.5]).unwrap();
        assert_eq!(o, [14.5, 9.5, 23.5, 29.5]);
    }

    #[test]
    fn nothing_to_outline_is_none() {
        let img = RgbImage::from_pixel(40, 40, Rgb([120, 120, 120]));
        assert!(outline(&img, ObjectClass::StopSign, [10.5, 10.5, 30.5, 30.5]).is_none());
        assert!(outline(&img, ObjectClass::Obstacle, [10.5, 10.5, 30.5, 30.5]).is_none());
    }
}
