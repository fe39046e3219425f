//! Canny edge detection on the grey bird's-eye image (Rivera & Andaluz 2021, Sec. 3.2 iii:
//! "For lane edge finding, the Canny algorithm is used").
//!
//! The steps, as in Canny (1986) and OpenCV's `GaussianBlur(5×5, σ=0)` followed by
//! `Canny(..., L2gradient=false)`, written as fused integer kernels so that the lane pipeline
//! stays well under a millisecond per frame:
//! 1. Gaussian blur with the 5×5 kernel `[1 4 6 4 1]ᵀ[1 4 6 4 1] / 256`, rounded half up,
//!    border reflected without repeating the edge pixel (OpenCV's `BORDER_REFLECT_101`).
//! 2. Sobel 3×3 gradients `dx`, `dy` (border replicated) and the L1 magnitude `|dx| + |dy|`.
//! 3. Non-maximum suppression: a pixel survives only if its magnitude is a maximum across the
//!    edge, along the gradient direction quantised to 0°, 45°, 90° or 135° with the fixed-point
//!    tan(22.5°) test OpenCV uses.
//! 4. Hysteresis: survivors above `high` start edges; survivors above `low` that touch an edge
//!    (8-neighbourhood) join it.
//!
//! Units: grey levels in, gradient magnitude (grey levels × 4 for a unit step, max 2040) for
//! the thresholds. All buffers live in [`CannyScratch`], allocated once per image size.

use image::GrayImage;

/// Canny options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CannyOptions {
    /// Hysteresis low threshold on the L1 gradient magnitude (a pixel must exceed it).
    pub low: u16,
    /// Hysteresis high threshold on the L1 gradient magnitude.
    pub high: u16,
    /// Run the 5×5 Gaussian blur first.
    pub blur: bool,
}

/// Reusable buffers for [`canny`]: no allocation per frame.
#[derive(Debug, Clone)]
pub struct CannyScratch {
    w: usize,
    h: usize,
    /// Horizontal blur pass, `w × h`.
    hblur: Vec<u16>,
    /// Blurred (or copied) image with a 1-pixel replicated border, `(w+2) × (h+2)`.
    padded: Vec<u8>,
    /// `dx`, `dy` per pixel, `w × h`.
    dx: Vec<i16>,
    dy: Vec<i16>,
    /// L1 magnitude with a 1-pixel zero border, `(w+2) × (h+2)`.
    mag: Vec<u16>,
    /// 0 = candidate, 1 = not an edge, 2 = edge; 1-pixel border of 1, `(w+2) × (h+2)`.
    map: Vec<u8>,
    stack: Vec<u32>,
}

impl CannyScratch {
    /// Buffers for `w × h` images.
    pub fn new(w: u32, h: u32) -> Self {
        let (w, h) = (w as usize, h as usize);
        let padded_len = (w + 2) * (h + 2);
        Self {
            w,
            h,
            hblur: vec![0; w * h],
            padded: vec![0; padded_len],
            dx: vec![0; w * h],
            dy: vec![0; w * h],
            mag: vec![0; padded_len],
            map: vec![1; padded_len],
            stack: Vec::with_capacity(w * h),
        }
    }

    /// The blurred image of the last call (interior of the padded buffer), row by row.
    pub fn blurred_row(&self, y: usize) -> &[u8] {
        let s = (y + 1) * (self.w + 2) + 1;
        &self.padded[s..s + self.w]
    }
}

/// Reflect-101 index into `0..n` (…, 2, 1, | 0, 1, …, n−1 |, n−2, …) for offsets of ±2.
#[inline(always)]
fn reflect101(i: isize, n: isize) -> usize {
    let r = if i < 0 {
        -i
    } else if i >= n {
        2 * n - 2 - i
    } else {
        i
    };
    r.clamp(0, n - 1) as usize
}

/// Step 1: 5×5 Gaussian blur of `src` into the interior of `s.padded`.
///
/// Both passes are written over shifted sub-slices zipped together, so the compiler turns them
/// into SIMD code; only the two columns at each end take the reflected slow path.
fn blur5_into_padded(src: &GrayImage, s: &mut CannyScratch) {
    let (w, h) = (s.w, s.h);
    let px: &[u8] = src.as_raw();
    // Horizontal pass: weights 1 4 6 4 1 (sum 16).
    for y in 0..h {
        let row = &px[y * w..(y + 1) * w];
        let out = &mut s.hblur[y * w..(y + 1) * w];
        if w >= 5 {
            let n = w - 4;
            let (a, b, c, d, e) = (
                &row[0..n],
                &row[1..n + 1],
                &row[2..n + 2],
                &row[3..n + 3],
                &row[4..n + 4],
            );
            for (o, ((((a, b), c), d), e)) in out[2..w - 2].iter_mut().zip(a.iter().zip(b).zip(c).zip(d).zip(e)) {
                *o = *a as u16 + 4 * *b as u16 + 6 * *c as u16 + 4 * *d as u16 + *e as u16;
            }
        }
        for x in (0..w.min(2)).chain(w.saturating_sub(2).max(2.min(w))..w) {
            let g = |d: isize| row[reflect101(x as isize + d, w as isize)] as u16;
            out[x] = g(-2) + 4 * g(-1) + 6 * g(0) + 4 * g(1) + g(2);
        }
    }
    // Vertical pass into the padded buffer, rounding (sum + 128) / 256.
    let pw = w + 2;
    for y in 0..h {
        let r = |k: isize| {
            let yy = reflect101(y as isize + k, h as isize);
            &s.hblur[yy * w..(yy + 1) * w]
        };
        let (a, b, c, d, e) = (r(-2), r(-1), r(0), r(1), r(2));
        let out = &mut s.padded[(y + 1) * pw + 1..(y + 1) * pw + 1 + w];
        for (o, ((((a, b), c), d), e)) in out.iter_mut().zip(a.iter().zip(b).zip(c).zip(d).zip(e)) {
            let v = *a as u32 + 4 * *b as u32 + 6 * *c as u32 + 4 * *d as u32 + *e as u32;
            *o = ((v + 128) >> 8) as u8;
        }
    }
}

/// Fills the 1-pixel border of `s.padded` by replicating the interior's edge pixels.
fn replicate_border(s: &mut CannyScratch) {
    let (w, h, pw) = (s.w, s.h, s.w + 2);
    for y in 1..=h {
        s.padded[y * pw] = s.padded[y * pw + 1];
        s.padded[y * pw + w + 1] = s.padded[y * pw + w];
    }
    let (top, rest) = s.padded.split_at_mut(pw);
    top.copy_from_slice(&rest[..pw]);
    let last = (h + 1) * pw;
    let (body, bottom) = s.padded.split_at_mut(last);
    bottom.copy_from_slice(&body[last - pw..last]);
}

/// fixed-point tan(22.5°) · 2^15, as OpenCV's `TG22`.
const TG22: i32 = 13573;
const CANNY_SHIFT: i32 = 15;

/// Runs the four Canny steps on `src`, writing 255 (edge) or 0 into `edges`.
pub fn canny(src: &GrayImage, opts: &CannyOptions, s: &mut CannyScratch, edges: &mut GrayImage) {
    assert_eq!(
        (s.w as u32, s.h as u32),
        src.dimensions(),
        "scratch built for another size"
    );
    assert_eq!(src.dimensions(), edges.dimensions(), "edge image of another size");
    let (w, h, pw) = (s.w, s.h, s.w + 2);

    // 1. Blur (or copy) into the padded buffer; replicate its border for Sobel.
    if opts.blur {
        blur5_into_padded(src, s);
    } else {
        for y in 0..h {
            s.padded[(y + 1) * pw + 1..(y + 1) * pw + 1 + w].copy_from_slice(&src.as_raw()[y * w..(y + 1) * w]);
        }
    }
    replicate_border(s);
    // 2. Sobel dx, dy and the L1 magnitude.
    sobel(s);
    // 3. Non-maximum suppression and classification; strong pixels go on the stack.
    suppress_and_classify(s, opts.low as i32, opts.high as i32);
    // 4. Hysteresis: grow edges from strong pixels through candidates.
    hysteresis(s, edges);
}

/// Canny step 2: Sobel dx, dy and the L1 magnitude (zero border around `mag`) of the padded
/// buffer, over shifted row slices so that it vectorises.
fn sobel(s: &mut CannyScratch) {
    let (w, h, pw) = (s.w, s.h, s.w + 2);
    for y in 0..h {
        let up = &s.padded[y * pw..y * pw + pw];
        let mid = &s.padded[(y + 1) * pw..(y + 1) * pw + pw];
        let dn = &s.padded[(y + 2) * pw..(y + 2) * pw + pw];
        let dxr = &mut s.dx[y * w..(y + 1) * w];
        let dyr = &mut s.dy[y * w..(y + 1) * w];
        let magr = &mut s.mag[(y + 1) * pw + 1..(y + 1) * pw + 1 + w];
        let cols = up[..w]
            .iter()
            .zip(&up[1..w + 1])
            .zip(&up[2..])
            .zip(mid[..w].iter().zip(&mid[2..]))
            .zip(dn[..w].iter().zip(&dn[1..w + 1]).zip(&dn[2..]));
        for ((((((a, b), c), (d, f)), ((g, hh), i)), gx_o), (gy_o, m_o)) in
            cols.zip(dxr.iter_mut()).zip(dyr.iter_mut().zip(magr.iter_mut()))
        {
            let (a, b, c, d, f, g, hh, i) = (
                *a as i16, *b as i16, *c as i16, *d as i16, *f as i16, *g as i16, *hh as i16, *i as i16,
            );
            let gx = (c - a) + 2 * (f - d) + (i - g);
            let gy = (g - a) + 2 * (hh - b) + (i - c);
            *gx_o = gx;
            *gy_o = gy;
            *m_o = gx.unsigned_abs() + gy.unsigned_abs();
        }
    }
}

/// Canny step 3: non-maximum suppression along the gradient direction (OpenCV's fixed-point
/// tan 22.5° / 67.5° sectors) and classification against `low` and `high`: `map` gets 1 (not
/// an edge), 0 (a candidate) or 2 (strong, also pushed on the stack).
fn suppress_and_classify(s: &mut CannyScratch, low: i32, high: i32) {
    let (w, h, pw) = (s.w, s.h, s.w + 2);
    s.stack.clear();
    for y in 0..h {
        let row = (y + 1) * pw;
        let (prev, cur, next) = (
            &s.mag[row - pw..row],
            &s.mag[row..row + pw],
            &s.mag[row + pw..row + 2 * pw],
        );
        let (dxr, dyr) = (&s.dx[y * w..(y + 1) * w], &s.dy[y * w..(y + 1) * w]);
        let map = &mut s.map[row..row + pw];
        for x in 0..w {
            let j = x + 1; // index in the padded rows
            let m = cur[j] as i32;
            if m <= low {
                map[j] = 1;
                continue;
            }
            let (xs, ys) = (dxr[x] as i32, dyr[x] as i32);
            let ax = xs.abs();
            let ay = ys.abs() << CANNY_SHIFT;
            let tg22x = ax * TG22;
            let keep = if ay < tg22x {
                // gradient near horizontal: compare left and right
                m > cur[j - 1] as i32 && m >= cur[j + 1] as i32
            } else {
                let tg67x = tg22x + (ax << (CANNY_SHIFT + 1));
                if ay > tg67x {
                    // near vertical: compare up and down
                    m > prev[j] as i32 && m >= next[j] as i32
                } else {
                    // diagonal: the sign of dx·dy picks which diagonal
                    let (up, dn) = if (xs ^ ys) < 0 { (j + 1, j - 1) } else { (j - 1, j + 1) };
                    m > prev[up] as i32 && m > next[dn] as i32
                }
            };
            map[j] = if !keep {
                1
            } else if m > high {
                s.stack.push((row + j) as u32);
                2
            } else {
                0
            };
        }
    }
}

/// Canny step 4: hysteresis, growing edges from the strong pixels through the candidates
/// (8-connected), then 255 (edge) or 0 into `edges`.
fn hysteresis(s: &mut CannyScratch, edges: &mut GrayImage) {
    let (w, h, pw) = (s.w, s.h, s.w + 2);
    while let Some(i) = s.stack.pop() {
        let i = i as isize;
        let p = pw as isize;
        for d in [-p - 1, -p, -p + 1, -1, 1, p - 1, p, p + 1] {
            let j = (i + d) as usize;
            if s.map[j] == 0 {
                s.map[j] = 2;
                s.stack.push(j as u32);
            }
        }
    }

    let out: &mut [u8] = edges;
    for y in 0..h {
        let mrow = &s.map[(y + 1) * pw + 1..(y + 1) * pw + 1 + w];
        for (o, &m) in out[y * w..(y + 1) * w].iter_mut().zip(mrow) {
            *o = if m == 2 { 255 } else { 0 };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bar_image(w: u32, h: u32, x0: u32, x1: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, _| image::Luma([if x >= x0 && x < x1 { 220 } else { 30 }]))
    }

    fn edge_columns(e: &GrayImage, y: u32) -> Vec<u32> {
        (0..e.width()).filter(|&x| e.get_pixel(x, y).0[0] == 255).collect()
    }

    #[test]
    fn finds_a_drawn_bars_edges_at_the_right_columns() {
        // A bright bar over columns 40..52: the step edges lie between 39|40 and 51|52.
        let img = bar_image(100, 40, 40, 52);
        let mut s = CannyScratch::new(100, 40);
        let mut e = GrayImage::new(100, 40);
        for blur in [false, true] {
            canny(
                &img,
                &CannyOptions {
                    low: 100,
                    high: 200,
                    blur,
                },
                &mut s,
                &mut e,
            );
            for y in 0..40 {
                let cols = edge_columns(&e, y);
                assert_eq!(cols.len(), 2, "blur={blur} row {y}: {cols:?}");
                // One pixel on each side of each step, as NMS picks the first of two equal maxima.
                assert!(
                    (39..=40).contains(&cols[0]) && (51..=52).contains(&cols[1]),
                    "blur={blur} row {y}: {cols:?}"
                );
            }
        }
    }

    #[test]
    fn flat_image_has_no_edges_and_weak_steps_are_ignored() {
        let mut s = CannyScratch::new(50, 30);
        let mut e = GrayImage::new(50, 30);
        canny(
            &GrayImage::from_pixel(50, 30, image::Luma([128])),
            &CannyOptions {
                low: 10,
                high: 20,
                blur: true,
            },
            &mut s,
            &mut e,
        );
        assert!(e.pixels().all(|p| p.0[0] == 0));
        // A step of 10 grey levels gives |dx| = 40 < low.
        let weak = GrayImage::from_fn(50, 30, |x, _| image::Luma([if x < 25 { 100 } else { 110 }]));
        canny(
            &weak,
            &CannyOptions {
                low: 50,
                high: 100,
                blur: false,
            },
            &mut s,
            &mut e,
        );
        assert!(e.pixels().all(|p| p.0[0] == 0));
    }

    #[test]
    fn hysteresis_follows_weak_continuations_of_strong_edges() {
        // Left half of the step is strong (contrast 100), right half weak (contrast 30):
        // the weak part survives only because it touches the strong part.
        let img = GrayImage::from_fn(60, 40, |x, y| {
            let hi = if x < 30 { 150 } else { 80 };
            image::Luma([if y >= 20 { hi } else { 50 }])
        });
        let mut s = CannyScratch::new(60, 40);
        let mut e = GrayImage::new(60, 40);
        canny(
            &img,
            &CannyOptions {
                low: 60,
                high: 300,
                blur: false,
            },
            &mut s,
            &mut e,
        );
        // Far from the junction at x = 30 (where the gradient turns), every column of the weak
        // half is on the edge, in row 19 or 20.
        for x in (0..26).chain(34..60) {
            let hit = e.get_pixel(x, 19).0[0] == 255 || e.get_pixel(x, 20).0[0] == 255;
            assert!(hit, "column {x} lost");
        }
        // Without the strong half nothing is found.
        let weak_only = GrayImage::from_fn(60, 40, |_, y| image::Luma([if y >= 20 { 80 } else { 50 }]));
        canny(
            &weak_only,
            &CannyOptions {
                low: 60,
                high: 300,
                blur: false,
            },
            &mut s,
            &mut e,
        );
        assert!(e.pixels().all(|p| p.0[0] == 0));
    }

    #[test]
    fn blur_matches_the_integer_gaussian_formula() {
        let img = GrayImage::from_fn(13, 9, |x, y| image::Luma([((x * 37 + y * 91) % 256) as u8]));
        let mut s = CannyScratch::new(13, 9);
        blur5_into_padded(&img, &mut s);
        let k = [1u32, 4, 6, 4, 1];
        for y in 0..9i32 {
            for x in 0..13i32 {
                let mut sum = 0;
                for (i, ki) in k.iter().enumerate() {
                    for (j, kj) in k.iter().enumerate() {
                        let yy = reflect101((y + i as i32 - 2) as isize, 9);
                        let xx = reflect101((x + j as i32 - 2) as isize, 13);
                        sum += ki * kj * img.get_pixel(xx as u32, yy as u32).0[0] as u32;
                    }
                }
                assert_eq!(
                    s.blurred_row(y as usize)[x as usize] as u32,
                    (sum + 128) >> 8,
                    "({x},{y})"
                );
            }
        }
    }

    #[test]
    fn agrees_with_imageproc_on_a_bar_when_blur_is_off() {
        // imageproc's canny blurs with its own σ; compare only the columns found on a clean bar.
        let img = bar_image(80, 30, 20, 35);
        let mut s = CannyScratch::new(80, 30);
        let mut e = GrayImage::new(80, 30);
        canny(
            &img,
            &CannyOptions {
                low: 100,
                high: 200,
                blur: false,
            },
            &mut s,
            &mut e,
        );
        let reference = imageproc::edges::canny(&img, 50.0, 100.0);
        for y in 5..25 {
            let ours = edge_columns(&e, y);
            let theirs = edge_columns(&reference, y);
            // imageproc keeps both pixels of a symmetric step (its NMS uses >= on both sides),
            // OpenCV and we keep one: every edge of ours lies on one of theirs, and every one of
            // theirs is within a pixel of one of ours.
            assert_eq!(ours.len(), 2, "row {y}: {ours:?}");
            assert!(
                ours.iter().all(|a| theirs.contains(a)),
                "row {y}: {ours:?} vs {theirs:?}"
            );
            assert!(
                theirs.iter().all(|b| ours.iter().any(|a| a.abs_diff(*b) <= 1)),
                "row {y}: {ours:?} vs {theirs:?}"
            );
        }
    }
}
