//! Tight outlines inside a cascade's box, from the object's own colour: a stop sign's red
//! area, a traffic light's dark housing, a turn sign's blue disc, a yield sign's red triangle
//! (its own rule, `triangle`: the lower vertex extrapolated from the sides).
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

/// The pixels `[x0, y0, x1, y1)` a box in pixel-centre coordinates (`[x0, y0, x1, y1]`, a
/// pixel's centre at its index) covers at least in part, clipped to the image.
fn pixel_box(img: &RgbImage, bbox: [f64; 4]) -> [i64; 4] {
    let (w, h) = (img.width() as i64, img.height() as i64);
    [
        ((bbox[0] + 0.5).floor() as i64).clamp(0, w),
        ((bbox[1] + 0.5).floor() as i64).clamp(0, h),
        ((bbox[2] + 0.5).ceil() as i64).clamp(0, w),
        ((bbox[3] + 0.5).ceil() as i64).clamp(0, h),
    ]
}

/// Smallest fraction of a detector box's pixels in its class's face colour (red for a stop or
/// yield sign, blue for a turn sign) for the box to count: a box without its colour is a false
/// positive of the cascade (a stop sign's cascade firing on a blue turn sign, say).
pub const MIN_COLOUR_FRACTION: f64 = 0.05;

/// Whether a detector box of `class` shows the class's face colour (at least
/// [`MIN_COLOUR_FRACTION`] of its pixels); classes without a face colour always do.
pub fn shows_colour(img: &RgbImage, class: ObjectClass, bbox: [f64; 4]) -> bool {
    let test: fn([u8; 3]) -> bool = match class.info().colour_cue {
        ColourCue::RedFace | ColourCue::RedTriangle => red,
        ColourCue::BlueFace => blue,
        ColourCue::LitHousing | ColourCue::None => return true,
    };
    let [x0, y0, x1, y1] = pixel_box(img, bbox);
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

/// Whether a detector box of `class` is the floor in a shadow or a sun patch rather than an
/// object: the class stands on the floor in a colour of its own
/// ([`crate::classes::ClassInfo::not_floor_colour`]), and the middle of the box has the
/// colour of the floor just in front of it, only darker or brighter. A shadow or a patch of
/// light scales the light falling on the floor, so it changes the floor's brightness and not
/// its chromaticity, `(r, g, b) / (r + g + b)` (the brightness/chromaticity split of
/// Horprasert et al., 1999, used for shadows by Cucchiara et al., 2003). Compared: the median
/// chromaticity of the middle half of the box (in width and height) against that of the
/// floor strip under the box (its columns, a quarter of its height, at least 2 rows); "the
/// same" when no channel differs by more than `tolerance` (0 = never). `false` when the strip
/// or the middle has fewer than [`MIN_FLOOR_PIXELS`] usable pixels (a box at the frame's
/// bottom edge: nothing to compare with, the box is kept). Pixels darker than 8 grey levels
/// per channel on average or with a clipped channel say nothing of colour and are left out.
pub fn floor_coloured(img: &RgbImage, class: ObjectClass, bbox: [f64; 4], tolerance: f64) -> bool {
    if !class.info().not_floor_colour || tolerance <= 0.0 {
        return false;
    }
    let h = img.height() as i64;
    let [x0, y0, x1, y1] = pixel_box(img, bbox);
    let (bw, bh) = (x1 - x0, y1 - y0);
    let middle = [x0 + bw / 4, y0 + bh / 4, x1 - bw / 4, y1 - bh / 4];
    let strip = [x0, y1, x1, (y1 + (bh / 4).max(2)).min(h)];
    match (median_chromaticity(img, middle), median_chromaticity(img, strip)) {
        (Some(a), Some(b)) => a.iter().zip(&b).all(|(a, b)| (a - b).abs() <= tolerance),
        _ => false,
    }
}

/// Fewest usable pixels for a median chromaticity ([`floor_coloured`]).
pub const MIN_FLOOR_PIXELS: usize = 20;

/// Bins of the chromaticity histograms (resolution 1/1023).
const CHROMA_BINS: usize = 1024;

/// The median of each channel's chromaticity `c / (r + g + b)` over the pixels of
/// `[x0, y0, x1, y1)` that are neither too dark (`r + g + b < 24`) nor clipped (a channel at
/// 255); `None` with fewer than [`MIN_FLOOR_PIXELS`] of them.
fn median_chromaticity(img: &RgbImage, [x0, y0, x1, y1]: [i64; 4]) -> Option<[f64; 3]> {
    // 12 KB on the stack: no allocation per box in the per-frame path.
    let mut hist = [[0u32; 3]; CHROMA_BINS];
    let mut n = 0usize;
    for y in y0..y1 {
        for x in x0..x1 {
            let p = img.get_pixel(x as u32, y as u32).0;
            let sum: u32 = p.iter().map(|&v| v as u32).sum();
            if sum < 24 || p.contains(&255) {
                continue;
            }
            for (c, &v) in p.iter().enumerate() {
                hist[(CHROMA_BINS as u32 - 1) as usize * v as usize / sum as usize][c] += 1;
            }
            n += 1;
        }
    }
    if n < MIN_FLOOR_PIXELS {
        return None;
    }
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut seen = 0usize;
        for (bin, counts) in hist.iter().enumerate() {
            seen += counts[c] as usize;
            if 2 * seen >= n {
                *o = bin as f64 / (CHROMA_BINS - 1) as f64;
                break;
            }
        }
    }
    Some(out)
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
        ColourCue::RedTriangle => return triangle(img, [x0, y0, x1, y1]),
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

/// A yield sign's outline inside the region `[x0, y0, x1, y1)` (pixels): the red border of an
/// inverted triangle. Per row the red pixels' extent (rightmost − leftmost + 1); the top edge
/// is the first row whose extent reaches half the widest, its width the widest extent of the
/// rows at the top edge; below it the extent shrinks linearly to the lower vertex, which is
/// where a straight line fitted to the rows at 20–80% of the widest reaches 0 (the vertex's
/// own rows hold a pixel or two of red, or none: counting them, as the stop sign's outline
/// does, cut the vertex off). `[left, top, right, vertex]` in pixel-centre coordinates.
fn triangle(img: &RgbImage, [x0, y0, x1, y1]: [i64; 4]) -> Option<[f64; 4]> {
    let ny = (y1 - y0) as usize;
    // (leftmost, rightmost) red column of each row, if any.
    let mut ext: Vec<Option<(i64, i64)>> = vec![None; ny];
    let mut n = 0u32;
    for (r, e) in ext.iter_mut().enumerate() {
        let y = y0 + r as i64;
        for x in x0..x1 {
            if red(img.get_pixel(x as u32, y as u32).0) {
                *e = Some(e.map_or((x, x), |(a, _)| (a, x)));
                n += 1;
            }
        }
    }
    if n < 12 {
        return None;
    }
    let width = |e: &Option<(i64, i64)>| e.map_or(0.0, |(a, b)| (b - a + 1) as f64);
    let widest = ext.iter().map(width).fold(0.0, f64::max);
    let top = ext.iter().position(|e| width(e) >= 0.5 * widest)?;
    // The top edge: its rows are the widest (the border runs along it).
    let (mut left, mut right) = (i64::MAX, i64::MIN);
    for e in ext[top..].iter().take_while(|e| width(e) >= 0.9 * widest).flatten() {
        left = left.min(e.0);
        right = right.max(e.1);
    }
    if left > right {
        let (a, b) = ext[top]?;
        (left, right) = (a, b);
    }
    // The sides: least squares of width against row over the rows at 20–80% of the widest,
    // below the top edge.
    let pts: Vec<(f64, f64)> = ext
        .iter()
        .enumerate()
        .skip(top)
        .map(|(r, e)| (r as f64, width(e)))
        .filter(|&(_, wd)| wd >= 0.2 * widest && wd <= 0.8 * widest)
        .collect();
    let last = ext.iter().rposition(|e| width(e) >= 0.2 * widest)? as f64 + 0.5;
    let vertex = if pts.len() >= 3 {
        let m = pts.len() as f64;
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |(a, b), &(x, y)| (a + x, b + y));
        let (mx, my) = (sx / m, sy / m);
        let (sxy, sxx) = pts.iter().fold((0.0, 0.0), |(a, b), &(x, y)| {
            (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
        });
        let slope = sxy / sxx.max(1e-12);
        if slope < 0.0 {
            // width = my + slope·(row − mx) = 0
            mx - my / slope
        } else {
            last
        }
    } else {
        last
    };
    Some([
        left as f64 - 0.5,
        (y0 + top as i64) as f64 - 0.5,
        right as f64 + 0.5,
        y0 as f64 + vertex,
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

    /// A 60×40 px box standing on a warm grey floor ([112, 104, 96]) with floor in front of it,
    /// its middle filled with `inside`.
    fn box_on_floor(inside: [u8; 3]) -> (RgbImage, [f64; 4]) {
        let mut img = RgbImage::from_pixel(120, 100, Rgb([112, 104, 96]));
        for y in 20..60 {
            for x in 30..90 {
                img.put_pixel(x, y, Rgb(inside));
            }
        }
        (img, [29.5, 19.5, 89.5, 59.5])
    }

    #[test]
    fn a_shadow_or_a_sun_patch_on_the_floor_is_floor_coloured_an_object_is_not() {
        let tol = 0.02;
        // The floor at 45 % and at 180 % of its light (a deep shadow, a sun patch): the same
        // chromaticity, only darker or brighter.
        for inside in [[50, 47, 43], [202, 187, 173]] {
            let (img, b) = box_on_floor(inside);
            assert!(floor_coloured(&img, ObjectClass::Obstacle, b, tol), "{inside:?}");
        }
        // Obstacles: the simulator's blue and red-brown boxes, and a neutral grey one (0.035
        // from the warm floor in blue's chromaticity), brighter or darker than the floor.
        for inside in [[60, 90, 160], [170, 70, 40], [150, 150, 150], [60, 60, 60]] {
            let (img, b) = box_on_floor(inside);
            assert!(!floor_coloured(&img, ObjectClass::Obstacle, b, tol), "{inside:?}");
        }
        // Off (0), and classes that do not stand on the floor in their own colour: never.
        let (img, b) = box_on_floor([50, 47, 43]);
        assert!(!floor_coloured(&img, ObjectClass::Obstacle, b, 0.0));
        assert!(!floor_coloured(&img, ObjectClass::StopSign, b, tol));
        // A box at the frame's bottom edge has no floor in front of it: kept.
        assert!(!floor_coloured(
            &img,
            ObjectClass::Obstacle,
            [29.5, 59.5, 89.5, 99.5],
            tol
        ));
    }

    #[test]
    fn the_floor_colour_is_the_median_so_tape_in_front_does_not_change_it() {
        // A shadow box with a white tape line (a third of the strip's columns) in front of it.
        let (mut img, b) = box_on_floor([50, 47, 43]);
        for y in 60..100 {
            for x in 40..60 {
                img.put_pixel(x, y, Rgb([235, 235, 228]));
            }
        }
        assert!(floor_coloured(&img, ObjectClass::Obstacle, b, 0.02));
    }

    #[test]
    fn nothing_to_outline_is_none() {
        let img = RgbImage::from_pixel(40, 40, Rgb([120, 120, 120]));
        assert!(outline(&img, ObjectClass::StopSign, [10.5, 10.5, 30.5, 30.5]).is_none());
        assert!(outline(&img, ObjectClass::Obstacle, [10.5, 10.5, 30.5, 30.5]).is_none());
    }
    /// An inverted triangle (top edge 40 px at y = 10, vertex at y = 44.64, so √3/2 of the
    /// width) with a red border 4 px thick, supersampled 4×4 as a camera blurs it: the top edge
    /// and width to half a pixel, the vertex to a pixel, where counting the red rows (the stop
    /// sign's rule) stops 3 px short of it.
    #[test]
    fn a_yield_triangle_is_outlined_down_to_its_vertex() {
        let (left, top, w) = (20.0f64, 10.0f64, 40.0f64);
        let h = w * 0.75f64.sqrt();
        let mut img = RgbImage::from_pixel(80, 70, Rgb([150, 150, 150]));
        for y in 0..70u32 {
            for x in 0..80u32 {
                let (mut red_n, mut white_n) = (0, 0);
                for sy in 0..4 {
                    for sx in 0..4 {
                        // pixel centres at integers: the pixel covers [x - 0.5, x + 0.5)
                        let (px, py) = (
                            x as f64 - 0.5 + (sx as f64 + 0.5) / 4.0,
                            y as f64 - 0.5 + (sy as f64 + 0.5) / 4.0,
                        );
                        let yy = py - top;
                        let half = (h - yy) / h * w / 2.0;
                        let dx = (px - (left + w / 2.0)).abs();
                        if yy < 0.0 || yy > h || dx > half {
                            continue;
                        }
                        // distance inside the nearest edge
                        let m = yy.min((half - dx) * 0.75f64.sqrt());
                        if m < 4.0 {
                            red_n += 1
                        } else {
                            white_n += 1
                        }
                    }
                }
                let grey = 16 - red_n - white_n;
                let c = |r: u32, wv: u32, g: u32| ((r * red_n + wv * white_n + g * grey) / 16) as u8;
                img.put_pixel(x, y, Rgb([c(200, 235, 150), c(25, 235, 150), c(30, 232, 150)]));
            }
        }
        let o = outline(&img, ObjectClass::YieldSign, [17.5, 7.5, 62.5, 47.5]).unwrap();
        let truth = [left, top, left + w, top + h];
        for k in 0..3 {
            assert!((o[k] - truth[k]).abs() <= 0.5, "edge {k}: {o:?} against {truth:?}");
        }
        assert!((o[3] - truth[3]).abs() <= 1.0, "vertex: {o:?} against {truth:?}");
        // The stop sign's rule on the same picture: the vertex's rows are cut off.
        let square = outline(&img, ObjectClass::StopSign, [17.5, 7.5, 62.5, 47.5]).unwrap();
        assert!(square[3] < truth[3] - 2.0, "{square:?}");
    }
}
