//! Grey threshold (Rivera & Andaluz 2021, Sec. 3.2 iii: "extract the region determined by an
//! appropriate threshold value"), Otsu's automatic level, and the union with the edges
//! ("the threshold image is matched with the edge detection").
//!
//! Semantics follow OpenCV's `threshold(..., THRESH_BINARY)`: a pixel becomes 255 when it is
//! *strictly* brighter than the level, else 0. Otsu (1979) picks the level that maximises the
//! between-class variance of the grey histogram, computed as OpenCV's `getThreshVal_Otsu_8u`.
//!
//! Under shadows and bright patches no single level fits the whole bird's-eye image: the
//! adaptive threshold compares each pixel with the mean of the `block × block` square round
//! it instead ([`adaptive_or_edges`], bit-exact to OpenCV's `adaptiveThreshold` with
//! `ADAPTIVE_THRESH_MEAN_C`, `THRESH_BINARY`: 255 where `src > mean − C`; the mean is
//! `boxFilter` with replicated borders, rounded to a grey level). The box sums are running
//! sums, so the cost does not grow with the block.

use image::GrayImage;
use serde::{Deserialize, Serialize};

/// How the binary image is thresholded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ThresholdMode {
    /// Fixed grey level (`lane.threshold`).
    Fixed,
    /// Otsu's method picks the level per frame.
    Otsu,
    /// Each pixel against the mean of the square round it (`lane.adaptive_block`,
    /// `lane.adaptive_c`).
    Adaptive,
}

/// Scratch of the box sums: the column sums of the current window and one padded row.
#[derive(Debug, Clone, Default)]
pub struct BoxScratch {
    cols: Vec<u32>,
    pad: Vec<u32>,
    sums: Vec<u32>,
}

/// Calls `row(y, sums)` for each row of `src` with the sums of the `block × block` square
/// (odd `block`) round each of its pixels, borders replicated (OpenCV's `BORDER_REPLICATE`).
/// Running sums: two additions per pixel whatever the block.
fn box_sums(src: &GrayImage, block: u32, scratch: &mut BoxScratch, mut row: impl FnMut(usize, &[u32])) {
    assert!(block % 2 == 1, "block must be odd");
    let (w, h) = (src.width() as usize, src.height() as usize);
    if w == 0 || h == 0 {
        return;
    }
    let (r, b) = ((block / 2) as usize, block as usize);
    let s = src.as_raw();
    let line = |y: isize| -> &[u8] {
        let y = y.clamp(0, h as isize - 1) as usize;
        &s[y * w..(y + 1) * w]
    };
    let BoxScratch { cols, pad, sums } = scratch;
    // 1. Column sums of the first window (rows -r..=r, replicated).
    cols.clear();
    cols.resize(w, 0);
    for dy in -(r as isize)..=r as isize {
        for (c, &p) in cols.iter_mut().zip(line(dy)) {
            *c += p as u32;
        }
    }
    pad.resize(w + 2 * r, 0);
    sums.resize(w, 0);
    for y in 0..h {
        // 2. The row's column sums with r replicated on each side, then a running sum along x.
        pad[r..r + w].copy_from_slice(cols);
        let (first, last) = (cols[0], cols[w - 1]);
        pad[..r].fill(first);
        pad[r + w..].fill(last);
        let mut acc: u32 = pad[..b].iter().sum();
        sums[0] = acc;
        for x in 1..w {
            acc = acc + pad[x + b - 1] - pad[x - 1];
            sums[x] = acc;
        }
        row(y, sums);
        // 3. Slide the column window down one row.
        if y + 1 < h {
            let (add, sub) = (line((y + 1 + r) as isize), line(y as isize - r as isize));
            for ((c, &a), &b) in cols.iter_mut().zip(add).zip(sub) {
                *c = *c + a as u32 - b as u32;
            }
        }
    }
}

/// The mean of the `block × block` square (odd `block`, at most 127) round each pixel of
/// `src`, borders replicated, rounded to the nearest grey level: OpenCV's `boxFilter(...,
/// normalize=true, BORDER_REPLICATE)` on 8-bit images. (OpenCV rounds a float product; an odd
/// area never ties, and up to 127 × 127 the float's error is smaller than the distance to a
/// tie, so the exact rounding here is the same.)
pub fn box_mean(src: &GrayImage, block: u32, scratch: &mut BoxScratch, out: &mut GrayImage) {
    assert_eq!(src.dimensions(), out.dimensions());
    let w = src.width() as usize;
    let area = block * block;
    let o: &mut [u8] = out;
    box_sums(src, block, scratch, |y, sums| {
        for (o, &s) in o[y * w..(y + 1) * w].iter_mut().zip(sums) {
            *o = ((2 * s + area) / (2 * area)) as u8;
        }
    });
}

/// OpenCV's `adaptiveThreshold(src, 255, ADAPTIVE_THRESH_MEAN_C, THRESH_BINARY, block, c)`
/// (odd `block` 3..=127, whole-number `c`) united with `edges`: 255 where `src > mean − c`
/// (the mean as [`box_mean`]) or an edge. Negative `c` = brighter than the mean by at least
/// 1 − c. Compared in integers without the mean: `round(sum / area) < src + c` is
/// `2 sum < (2 (src + c) − 1) area`.
pub fn adaptive_or_edges(
    src: &GrayImage,
    block: u32,
    c: i32,
    edges: &GrayImage,
    scratch: &mut BoxScratch,
    out: &mut GrayImage,
) {
    assert_eq!(edges.dimensions(), out.dimensions());
    adaptive_else(src, block, c, Some(edges.as_raw()), scratch, out);
}

/// OpenCV's `adaptiveThreshold(src, 255, ADAPTIVE_THRESH_MEAN_C, THRESH_BINARY, block, c)`
/// alone (as [`adaptive_or_edges`] without the edges).
pub fn adaptive(src: &GrayImage, block: u32, c: i32, scratch: &mut BoxScratch, out: &mut GrayImage) {
    adaptive_else(src, block, c, None, scratch, out);
}

/// The adaptive threshold; where a pixel does not pass, `other`'s pixel (or 0).
fn adaptive_else(
    src: &GrayImage,
    block: u32,
    c: i32,
    other: Option<&[u8]>,
    scratch: &mut BoxScratch,
    out: &mut GrayImage,
) {
    assert_eq!(src.dimensions(), out.dimensions());
    assert!(block <= 127, "block must be at most 127");
    let w = src.width() as usize;
    let area = (block * block) as i32;
    let s_all = src.as_raw();
    let o: &mut [u8] = out;
    box_sums(src, block, scratch, |y, sums| {
        let span = y * w..(y + 1) * w;
        let (o, s) = (&mut o[span.clone()], &s_all[span.clone()]);
        let pass = |s: u8, sum: u32| 2 * (sum as i32) < (2 * (s as i32 + c) - 1) * area;
        match other {
            Some(e_all) => {
                for (((o, &s), &e), &sum) in o.iter_mut().zip(s).zip(&e_all[span]).zip(sums) {
                    *o = if pass(s, sum) { 255 } else { e };
                }
            }
            None => {
                for ((o, &s), &sum) in o.iter_mut().zip(s).zip(sums) {
                    *o = if pass(s, sum) { 255 } else { 0 };
                }
            }
        }
    });
}

/// Morphological opening of `img` in place with a `side × side` square (odd `side`): erosion
/// (the minimum of the square round each pixel), then dilation (the maximum). On the binary
/// threshold image it removes every white speck the square does not fit in — a mottled
/// floor's, sensor noise — and leaves wider marks such as the tape (about 10 px in the
/// bird's-eye image) as they were. OpenCV's `morphologyEx(img, MORPH_OPEN, ones(side, side))`
/// with its default border (pixels outside the image take no part). Min and max over a
/// rectangle are separable: each is a pass along the rows, then one down the columns.
pub fn open_square(img: &mut GrayImage, side: u32, tmp: &mut Vec<u8>) {
    assert!(side % 2 == 1, "side must be odd");
    if side <= 1 {
        return;
    }
    let r = (side / 2) as usize;
    let (w, h) = (img.width() as usize, img.height() as usize);
    tmp.resize(w * h, 0);
    let px: &mut [u8] = img;
    min_max_pass(px, tmp, w, h, r, u8::min);
    min_max_pass(px, tmp, w, h, r, u8::max);
}

/// `pick` (min or max: a generic, so each is inlined and the loops vectorise) over the
/// `(2r+1) × (2r+1)` square round each pixel of the `w × h` image `px`, in place: along each
/// row into `tmp` (the window shifted by ±1..=r, clipped at the row's ends), then down each
/// column back into `px`.
fn min_max_pass(px: &mut [u8], tmp: &mut [u8], w: usize, h: usize, r: usize, pick: impl Fn(u8, u8) -> u8 + Copy) {
    for (src, dst) in px.chunks_exact(w).zip(tmp.chunks_exact_mut(w)) {
        dst.copy_from_slice(src);
        for k in 1..=r.min(w.saturating_sub(1)) {
            for (d, &s) in dst[..w - k].iter_mut().zip(&src[k..]) {
                *d = pick(*d, s);
            }
            for (d, &s) in dst[k..].iter_mut().zip(&src[..w - k]) {
                *d = pick(*d, s);
            }
        }
    }
    for y in 0..h {
        let (first, end) = (y.saturating_sub(r), (y + r + 1).min(h));
        let dst = &mut px[y * w..(y + 1) * w];
        dst.copy_from_slice(&tmp[first * w..(first + 1) * w]);
        for yy in first + 1..end {
            for (d, &s) in dst.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *d = pick(*d, s);
            }
        }
    }
}

/// `out |= edges`: the edges united with a threshold image.
pub fn or_edges(out: &mut GrayImage, edges: &GrayImage) {
    assert_eq!(edges.dimensions(), out.dimensions());
    let o: &mut [u8] = out;
    for (o, &e) in o.iter_mut().zip(edges.as_raw()) {
        *o |= e;
    }
}

/// Otsu's threshold level for `img` (0..=255).
pub fn otsu_level(img: &GrayImage) -> u8 {
    // 1. Histogram of grey levels.
    let mut hist = [0u32; 256];
    for &p in img.as_raw() {
        hist[p as usize] += 1;
    }
    let n = img.as_raw().len() as f64;
    if n == 0.0 {
        return 0;
    }
    // 2. Mean grey level of the whole image.
    let mu: f64 = hist.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum::<f64>() / n;
    // 3. Sweep the split, keeping the level of largest between-class variance q1 q2 (mu1 - mu2)^2.
    let (mut q1, mut mu1, mut best_sigma, mut best) = (0.0f64, 0.0f64, 0.0f64, 0u8);
    for (i, &c) in hist.iter().enumerate() {
        let p_i = c as f64 / n;
        mu1 *= q1;
        q1 += p_i;
        let q2 = 1.0 - q1;
        if q1.min(q2) < f32::EPSILON as f64 || q1.max(q2) > 1.0 - f32::EPSILON as f64 {
            continue;
        }
        mu1 = (mu1 + i as f64 * p_i) / q1;
        let mu2 = (mu - q1 * mu1) / q2;
        let sigma = q1 * q2 * (mu1 - mu2) * (mu1 - mu2);
        if sigma > best_sigma {
            best_sigma = sigma;
            best = i as u8;
        }
    }
    best
}

/// Binary threshold of `src` at `level` united with `edges`: 255 where the pixel is brighter
/// than `level` or is an edge, else 0. `out` may not alias the inputs.
pub fn threshold_or_edges(src: &GrayImage, level: u8, edges: &GrayImage, out: &mut GrayImage) {
    assert_eq!(src.dimensions(), out.dimensions());
    assert_eq!(edges.dimensions(), out.dimensions());
    let o: &mut [u8] = out;
    for ((o, &s), &e) in o.iter_mut().zip(src.as_raw()).zip(edges.as_raw()) {
        *o = if s > level { 255 } else { e };
    }
}

/// Plain binary threshold (for annotation and tests): 255 where brighter than `level`.
pub fn threshold(src: &GrayImage, level: u8, out: &mut GrayImage) {
    assert_eq!(src.dimensions(), out.dimensions());
    let o: &mut [u8] = out;
    for (o, &s) in o.iter_mut().zip(src.as_raw()) {
        *o = if s > level { 255 } else { 0 };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_is_strictly_greater() {
        let img = GrayImage::from_raw(4, 1, vec![169, 170, 171, 255]).unwrap();
        let mut out = GrayImage::new(4, 1);
        threshold(&img, 170, &mut out);
        assert_eq!(out.as_raw(), &vec![0, 0, 255, 255]);
    }

    #[test]
    fn otsu_splits_two_populations() {
        // 70% floor around 40, 30% tape around 210: the level falls between them.
        let img = GrayImage::from_fn(100, 10, |x, y| {
            image::Luma([if x < 70 {
                35 + ((x + y) % 10) as u8
            } else {
                205 + (x % 10) as u8
            }])
        });
        let t = otsu_level(&img);
        assert!((44..205).contains(&t), "level {t}");
        // matches imageproc's Otsu within one grey level
        let r = imageproc::contrast::otsu_level(&img);
        assert!(t.abs_diff(r) <= 1, "{t} vs imageproc {r}");
    }

    /// The box mean against a plain sum over the clamped square, rounded, on noise images of
    /// odd sizes, blocks smaller and larger than the image.
    #[test]
    fn box_mean_is_the_rounded_mean_of_the_replicated_square() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 56) as u8
        };
        let mut scratch = BoxScratch::default();
        for (w, h) in [(1u32, 1u32), (5, 3), (37, 23), (64, 9)] {
            let img = GrayImage::from_fn(w, h, |_, _| image::Luma([rnd()]));
            for block in [3u32, 5, 9, 41] {
                let mut got = GrayImage::new(w, h);
                box_mean(&img, block, &mut scratch, &mut got);
                let r = (block / 2) as i64;
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let mut sum = 0u64;
                        for dy in -r..=r {
                            for dx in -r..=r {
                                let (xx, yy) = ((x + dx).clamp(0, w as i64 - 1), (y + dy).clamp(0, h as i64 - 1));
                                sum += img.get_pixel(xx as u32, yy as u32)[0] as u64;
                            }
                        }
                        let want = (sum as f64 / (block * block) as f64).round() as u8;
                        assert_eq!(
                            got.get_pixel(x as u32, y as u32)[0],
                            want,
                            "{w}x{h} block {block} at ({x},{y})"
                        );
                    }
                }
            }
        }
    }

    /// The fused comparison is `src > mean − c` with the mean of [`box_mean`], for every c.
    #[test]
    fn adaptive_is_src_above_the_mean_minus_c() {
        let img = GrayImage::from_fn(53, 31, |x, y| {
            image::Luma([((x * 37 + y * 91 + x * y * 13) % 251) as u8])
        });
        let edges = GrayImage::from_fn(53, 31, |x, y| {
            image::Luma([if (x + 2 * y) % 17 == 0 { 255 } else { 0 }])
        });
        let mut scratch = BoxScratch::default();
        for block in [3u32, 11, 41, 127] {
            let mut mean = GrayImage::new(53, 31);
            box_mean(&img, block, &mut scratch, &mut mean);
            for c in [-255, -20, -5, 0, 3, 255] {
                let mut out = GrayImage::new(53, 31);
                adaptive_or_edges(&img, block, c, &edges, &mut scratch, &mut out);
                for ((&o, (&s, &m)), &e) in out
                    .as_raw()
                    .iter()
                    .zip(img.as_raw().iter().zip(mean.as_raw()))
                    .zip(edges.as_raw())
                {
                    let want = if s as i32 > m as i32 - c { 255 } else { e };
                    assert_eq!(o, want, "block {block} c {c}: src {s} mean {m}");
                }
            }
        }
    }

    /// A bird's-eye image under changing light: a lit floor with a gradient, a deep shadow
    /// over the rows the histogram sums (the tape there darker than the lit floor) and a
    /// bright sun patch (brighter than the tape in the shade). The fixed level and Otsu's lose
    /// the lines; the adaptive threshold finds both where they are.
    #[test]
    fn adaptive_finds_the_lines_in_a_shadow_where_fixed_and_otsu_fail() {
        let (w, h) = (320u32, 240u32);
        let (left, right) = (60u32..73, 250u32..263);
        let img = GrayImage::from_fn(w, h, |x, y| {
            let tape = left.contains(&x) || right.contains(&x);
            let mut v = if tape { 225.0 } else { 90.0 + 30.0 * x as f64 / w as f64 };
            if y >= 130 {
                v *= 0.3; // the shadow
            } else if (100..220).contains(&x) && y < 120 {
                v = 235.0; // the sun patch between the lines
            }
            image::Luma([v.round() as u8])
        });
        let opts = crate::lane::LaneOptions::from(&crate::config::LaneConfig::default());
        let band = crate::lane::lines::band_rows(h, opts.lines.band);
        let no_edges = GrayImage::new(w, h);
        let mut binary = GrayImage::new(w, h);
        let mut hist = vec![0u16; w as usize];
        let mut lines_of = |binary: &GrayImage| {
            crate::lane::lines::column_histogram(binary, band, &mut hist);
            crate::lane::lines::measure(&hist, band, &opts.lines)
        };
        let found = |m: &crate::lane::LaneMeasurement| {
            m.status == crate::lane::LaneStatus::Both
                && (m.p_left.unwrap() - 66.0).abs() < 2.0
                && (m.p_right.unwrap() - 256.0).abs() < 2.0
        };
        threshold_or_edges(&img, opts.threshold, &no_edges, &mut binary);
        let fixed = lines_of(&binary);
        let otsu = otsu_level(&img);
        threshold_or_edges(&img, otsu, &no_edges, &mut binary);
        let by_otsu = lines_of(&binary);
        adaptive_or_edges(
            &img,
            opts.adaptive.0,
            opts.adaptive.1,
            &no_edges,
            &mut BoxScratch::default(),
            &mut binary,
        );
        let adaptive = lines_of(&binary);
        assert!(!found(&fixed), "fixed {fixed:?}");
        assert!(!found(&by_otsu), "otsu (level {otsu}) {by_otsu:?}");
        assert!(found(&adaptive), "adaptive {adaptive:?}");
        // No floor passes inside the shadow or the patch (beyond half a block from their
        // edges: at a hard edge the lit side's strip is brighter than its mean).
        let r = opts.adaptive.0 / 2;
        let floor_on = binary
            .enumerate_pixels()
            .filter(|&(x, y, p)| {
                let inside = y > 130 + r || ((100 + r..220 - r).contains(&x) && y + r < 120);
                p[0] > 0 && inside && !left.contains(&x) && !right.contains(&x)
            })
            .count();
        assert_eq!(floor_on, 0, "{floor_on} floor pixels pass");
    }

    /// The opening against its definition (each pixel: the max over the squares containing
    /// it of the square's min, pixels outside the image taking no part), on random images.
    #[test]
    fn opening_is_the_max_of_the_mins_of_the_squares_round_each_pixel() {
        let mut seed = 7u64;
        let mut next = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for (w, h, side) in [(17u32, 11u32, 3u32), (9, 23, 5), (4, 4, 7), (30, 2, 3)] {
            let img = GrayImage::from_fn(w, h, |_, _| {
                image::Luma([if next() % 3 == 0 { 255 } else { (next() % 256) as u8 }])
            });
            let mut got = img.clone();
            open_square(&mut got, side, &mut Vec::new());
            let r = (side / 2) as i64;
            let inside = |x: i64, y: i64| x >= 0 && y >= 0 && x < w as i64 && y < h as i64;
            let at = |im: &GrayImage, x: i64, y: i64| im.get_pixel(x as u32, y as u32)[0];
            let fold = |im: &GrayImage, x: i64, y: i64, min: bool| {
                let mut acc: Option<u8> = None;
                for dy in -r..=r {
                    for dx in -r..=r {
                        if inside(x + dx, y + dy) {
                            let v = at(im, x + dx, y + dy);
                            acc = Some(acc.map_or(v, |a| if min { a.min(v) } else { a.max(v) }));
                        }
                    }
                }
                acc.unwrap()
            };
            let eroded = GrayImage::from_fn(w, h, |x, y| image::Luma([fold(&img, x as i64, y as i64, true)]));
            let want = GrayImage::from_fn(w, h, |x, y| image::Luma([fold(&eroded, x as i64, y as i64, false)]));
            assert_eq!(got, want, "{w}x{h}, side {side}");
        }
    }

    /// Specks narrower than the square go; a 10 px stripe (the tape) stays pixel for pixel.
    #[test]
    fn opening_removes_specks_and_keeps_the_tape() {
        let img = GrayImage::from_fn(60, 40, |x, y| {
            let tape = (30..40).contains(&x);
            let speck = (x % 7 == 1 && y % 5 == 2) || (x == 10 && (10..12).contains(&y));
            image::Luma([if tape || speck { 255 } else { 0 }])
        });
        let mut out = img.clone();
        open_square(&mut out, 3, &mut Vec::new());
        for (x, y, p) in out.enumerate_pixels() {
            assert_eq!(p[0] == 255, (30..40).contains(&x), "pixel ({x},{y})");
        }
    }

    #[test]
    fn union_keeps_edges_below_the_level() {
        let img = GrayImage::from_raw(3, 1, vec![10, 200, 10]).unwrap();
        let edges = GrayImage::from_raw(3, 1, vec![255, 0, 0]).unwrap();
        let mut out = GrayImage::new(3, 1);
        threshold_or_edges(&img, 100, &edges, &mut out);
        assert_eq!(out.as_raw(), &vec![255, 255, 0]);
    }
}
