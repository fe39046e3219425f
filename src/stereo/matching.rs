//! Finding the reference camera's box in the other image (Zaarane et al. 2020, Sec. 3.2 and
//! Fig. 6): the box is a template slid along the same rows of the other rectified image;
//! the score is the mean-subtracted normalised cross-correlation (OpenCV's TM_CCOEFF_NORMED)
//!
//! ```text
//! R(d) = Σ T'(x, y)·I'(x ∓ d, y) / √(Σ T'² · Σ I'²),   T' = T − mean T, I' = I − mean I (window)
//! ```
//!
//! 1. Column sums of I and I² over the box's rows give every window's mean and energy by a
//!    sliding sum; Σ T'·I needs one pass per candidate disparity (Σ T' = 0, so I' = I there).
//! 2. The best disparity must score ≥ `min_score` (else the object is not in the other view:
//!    "no range").
//!    Occlusion prior: an object hides what is behind it, so of the local maxima scoring at
//!    least `near_peak_ratio` × the best, the one with the largest disparity (nearest) is
//!    taken. A flat-coloured object over a textured floor otherwise locks onto the floor
//!    behind it (its lines fill the box); 1.0 turns the prior off.
//! 3. Sub-pixel: a parabola through the peak and its two neighbours,
//!    δ = (R₋ − R₊) / (2(R₋ − 2R₀ + R₊)), |δ| ≤ 0.5.
//!
//! With the left image as reference, the object sits d pixels further left in the right
//! image (x_r = x_l − d); with the right one as reference, further right. Units: pixels.

use super::NoRange;
use image::{GrayImage, RgbImage};

/// The chroma of each pixel, max(R, G, B) − min(R, G, B): grey and white (a floor, its lines)
/// become 0, a coloured object stays bright. Matching a plain coloured object on chroma
/// instead of grey leaves only its silhouette to correlate, so the texture of the floor
/// around it in the box cannot win (docs/stereo.md, the obstacle with a short base).
pub fn chroma_from_rgb(rgb: &RgbImage, out: &mut GrayImage) {
    if out.dimensions() != rgb.dimensions() {
        *out = GrayImage::new(rgb.width(), rgb.height());
    }
    for (o, p) in out.pixels_mut().zip(rgb.pixels()) {
        let [r, g, b] = p.0;
        o.0[0] = r.max(g).max(b) - r.min(g).min(b);
    }
}

/// Matches `bbox` on grey, checked against a match on chroma ([`chroma_from_rgb`]) for a
/// plain coloured object: when the two disparities differ by more than `gap` = max(2 px,
/// `max_gap` × the chroma disparity) the grey peak belongs to something else in the box (the
/// floor's lines behind an obstacle), and the grey match is repeated within ±gap of the
/// chroma disparity (the chroma match itself if that finds nothing). Without a chroma match (a grey object: `Flat`) the grey
/// match stands. Returns the match and whether chroma overruled grey.
#[allow(clippy::too_many_arguments)]
pub fn match_box_chroma_checked(
    m: &mut Matcher,
    gray: (&GrayImage, &GrayImage),
    chroma: (&GrayImage, &GrayImage),
    bbox: [i64; 4],
    opts: &MatchOptions,
    max_gap: f64,
) -> (Result<StereoMatch, NoRange>, bool) {
    let g = m.match_box(gray.0, gray.1, bbox, opts);
    let Ok(c) = m.match_box(chroma.0, chroma.1, bbox, opts) else {
        return (g, false);
    };
    let max_gap_px = (max_gap * c.disparity).max(2.0);
    match g {
        Ok(g) if (g.disparity - c.disparity).abs() <= max_gap_px => (Ok(g), false),
        _ => {
            let near = MatchOptions {
                min_disparity: ((c.disparity - max_gap_px).round().max(0.0)) as u32,
                max_disparity: (c.disparity + max_gap_px).round() as u32,
                near_peak_ratio: 1.0,
                ..*opts
            };
            match m.match_box(gray.0, gray.1, bbox, &near) {
                // A grey peak well inside the window: the object's own edges.
                Ok(g2) if (g2.disparity - c.disparity).abs() < max_gap_px / 2.0 => (Ok(g2), true),
                _ => (Ok(c), true),
            }
        }
    }
}

/// How to search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchOptions {
    /// Smallest disparity searched, pixels (≥ 0).
    pub min_disparity: u32,
    /// Largest disparity searched, pixels.
    pub max_disparity: u32,
    /// Lowest acceptable correlation (−1..1); below it there is no range.
    pub min_score: f64,
    /// The reference image is the left one (else the right one).
    pub reference_left: bool,
    /// Of the local maxima scoring at least this fraction of the best, take the nearest
    /// (largest disparity); 1.0 = always the best.
    pub near_peak_ratio: f64,
}

impl Default for MatchOptions {
    fn default() -> Self {
        Self {
            min_disparity: 0,
            max_disparity: 120,
            min_score: 0.6,
            reference_left: true,
            near_peak_ratio: 0.9,
        }
    }
}

/// A box found in the other image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoMatch {
    /// Disparity, pixels (sub-pixel), > 0.
    pub disparity: f64,
    /// The correlation at the integer peak.
    pub score: f64,
    /// Box centre column in the reference image, pixels.
    pub x_ref: f64,
    /// The matched centre column in the other image, pixels.
    pub x_other: f64,
}

/// Scratch buffers reused between calls (a matcher per camera pair).
#[derive(Debug, Default, Clone)]
pub struct Matcher {
    tmpl: Vec<f32>,
    colsum: Vec<f64>,
    colsq: Vec<f64>,
    scores: Vec<f64>,
}

impl Matcher {
    /// A matcher with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// The NCC scores of every disparity in `min..=max` (index 0 = `min`), as
    /// [`match_box`] computes them; `None` entries where the window leaves the image.
    pub fn scores(&self) -> &[f64] {
        &self.scores
    }

    /// Finds the box `[x, y, w, h]` (pixels, top-left and size) of `reference` in `other`.
    pub fn match_box(
        &mut self,
        reference: &GrayImage,
        other: &GrayImage,
        bbox: [i64; 4],
        opts: &MatchOptions,
    ) -> Result<StereoMatch, NoRange> {
        let (w, h) = reference.dimensions();
        if other.dimensions() != (w, h) {
            return Err(NoRange::SizeMismatch {
                left_w: w,
                left_h: h,
                right_w: other.width(),
                right_h: other.height(),
            });
        }
        let [bx, by, bw, bh] = bbox;
        if bw < 3 || bh < 3 || bx < 0 || by < 0 || bx + bw > w as i64 || by + bh > h as i64 {
            return Err(NoRange::BadBox(bbox));
        }
        let (bx, by, bw, bh) = (bx as usize, by as usize, bw as usize, bh as usize);
        let iw = w as usize;
        let n = (bw * bh) as f64;
        // The template, mean-subtracted.
        let r = reference.as_raw();
        self.tmpl.clear();
        let mut tsum = 0f64;
        for y in by..by + bh {
            for x in bx..bx + bw {
                let v = r[y * iw + x] as f32;
                tsum += v as f64;
                self.tmpl.push(v);
            }
        }
        let tmean = (tsum / n) as f32;
        let mut tnorm = 0f64;
        for v in self.tmpl.iter_mut() {
            *v -= tmean;
            tnorm += (*v as f64) * (*v as f64);
        }
        if tnorm < 1e-6 * n {
            return Err(NoRange::Flat);
        }
        // 1. Column sums of the other image over the box's rows.
        let o = other.as_raw();
        self.colsum.clear();
        self.colsum.resize(iw, 0.0);
        self.colsq.clear();
        self.colsq.resize(iw, 0.0);
        for y in by..by + bh {
            let row = &o[y * iw..(y + 1) * iw];
            for (x, &v) in row.iter().enumerate() {
                let v = v as f64;
                self.colsum[x] += v;
                self.colsq[x] += v * v;
            }
        }
        // Candidate window starts: x_other = bx ∓ d.
        let (dmin, dmax) = (opts.min_disparity as i64, opts.max_disparity as i64);
        self.scores.clear();
        let mut best: Option<(usize, f64)> = None;
        for d in dmin..=dmax {
            let x0 = if opts.reference_left {
                bx as i64 - d
            } else {
                bx as i64 + d
            };
            if x0 < 0 || x0 as usize + bw > iw {
                self.scores.push(f64::NAN);
                continue;
            }
            let x0 = x0 as usize;
            let (mut s, mut s2) = (0f64, 0f64);
            for x in x0..x0 + bw {
                s += self.colsum[x];
                s2 += self.colsq[x];
            }
            let var = s2 - s * s / n;
            let mut cross = 0f32;
            for (ty, y) in (by..by + bh).enumerate() {
                let row = &o[y * iw + x0..y * iw + x0 + bw];
                let t = &self.tmpl[ty * bw..(ty + 1) * bw];
                let mut acc = 0f32;
                for (a, b) in row.iter().zip(t) {
                    acc += *a as f32 * b;
                }
                cross += acc;
            }
            let score = if var > 1e-9 {
                cross as f64 / (tnorm * var).sqrt()
            } else {
                0.0
            };
            if best.map_or(true, |b| score > b.1) {
                best = Some((self.scores.len(), score));
            }
            self.scores.push(score);
        }
        let Some((mut i, mut score)) = best else {
            return Err(NoRange::NoSearchRoom);
        };
        // 2b. The nearest of the near-best local maxima.
        let floor = score * opts.near_peak_ratio.min(1.0);
        for k in (i + 1)..self.scores.len() {
            let v = self.scores[k];
            let left = self.scores[k - 1];
            let right = self.scores.get(k + 1).copied().unwrap_or(f64::NEG_INFINITY);
            if v >= floor
                && v >= opts.min_score
                && v >= left
                && right.partial_cmp(&v) != Some(std::cmp::Ordering::Greater)
            {
                i = k;
                score = v;
            }
        }
        // 2. Threshold.
        if score < opts.min_score {
            return Err(NoRange::BelowThreshold {
                score,
                min: opts.min_score,
            });
        }
        // 3. Parabolic sub-pixel peak.
        let mut delta = 0.0;
        if i > 0 && i + 1 < self.scores.len() {
            let (a, b, c) = (self.scores[i - 1], self.scores[i], self.scores[i + 1]);
            let den = a - 2.0 * b + c;
            if a.is_finite() && c.is_finite() && den < 0.0 {
                delta = (0.5 * (a - c) / den).clamp(-0.5, 0.5);
            }
        }
        let disparity = (dmin + i as i64) as f64 + delta;
        if disparity <= 0.0 {
            return Err(NoRange::NonPositiveDisparity(disparity));
        }
        let x_ref = bx as f64 + (bw as f64 - 1.0) / 2.0;
        let x_other = if opts.reference_left {
            x_ref - disparity
        } else {
            x_ref + disparity
        };
        Ok(StereoMatch {
            disparity,
            score,
            x_ref,
            x_other,
        })
    }
}

/// [`Matcher::match_box`] with fresh buffers.
pub fn match_box(
    reference: &GrayImage,
    other: &GrayImage,
    bbox: [i64; 4],
    opts: &MatchOptions,
) -> Result<StereoMatch, NoRange> {
    Matcher::new().match_box(reference, other, bbox, opts)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plain blue box (disparity 20 px) in front of a floor of irregular white stripes
    /// (disparity 5 px) that fill most of the box: chroma sees only the box.
    #[test]
    fn chroma_check_finds_a_plain_box_in_front_of_stripes() {
        let stripes = |x: i64| (x * 7919 % 23) < 9;
        let pair = |shift_box: i64, shift_floor: i64| {
            RgbImage::from_fn(220, 60, |x, y| {
                let (x, y) = (x as i64, y as i64);
                if (100 - shift_box..108 - shift_box).contains(&x) && (15..45).contains(&y) {
                    image::Rgb([40, 60, 200])
                } else if stripes(x + shift_floor) {
                    image::Rgb([235, 235, 230])
                } else {
                    image::Rgb([110, 104, 96])
                }
            })
        };
        let (l, r) = (pair(0, 0), pair(20, 5));
        let (mut gl, mut gr, mut cl, mut cr) = (
            GrayImage::new(0, 0),
            GrayImage::new(0, 0),
            GrayImage::new(0, 0),
            GrayImage::new(0, 0),
        );
        crate::detect::gray_from_rgb(&l, &mut gl);
        crate::detect::gray_from_rgb(&r, &mut gr);
        chroma_from_rgb(&l, &mut cl);
        chroma_from_rgb(&r, &mut cr);
        let opts = MatchOptions {
            max_disparity: 60,
            near_peak_ratio: 1.0,
            ..MatchOptions::default()
        };
        let mut m = Matcher::new();
        let bx = [84, 10, 40, 40];
        let (got, _) = match_box_chroma_checked(&mut m, (&gl, &gr), (&cl, &cr), bx, &opts, 0.1);
        let got = got.unwrap();
        assert!((got.disparity - 20.0).abs() < 0.1, "{got:?}");
        // Grey alone is pulled off the box by the stripes (18.0 px).
        let grey = m.match_box(&gl, &gr, bx, &opts).unwrap();
        assert!((grey.disparity - 20.0).abs() > 1.5, "{grey:?}");
        // A grey object has no chroma: grey alone decides.
        let g = image::imageops::grayscale(&l);
        let grey_l = image::DynamicImage::ImageLuma8(g).to_rgb8();
        chroma_from_rgb(&grey_l, &mut cl);
        assert!(cl.pixels().all(|p| p.0[0] == 0));
    }

    /// Aperiodic value noise (hashed lattice every 3 px, bilinear), shifted by `shift` px.
    fn textured(w: u32, h: u32, shift: f64) -> GrayImage {
        let hash = |i: i64, j: i64| -> f64 {
            let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            z ^= z >> 29;
            z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z ^= z >> 32;
            (z % 1000) as f64 / 1000.0
        };
        GrayImage::from_fn(w, h, |x, y| {
            let (u, v) = ((x as f64 + shift) / 3.0, y as f64 / 3.0);
            let (i, j) = (u.floor(), v.floor());
            let (a, b) = (u - i, v - j);
            let (i, j) = (i as i64, j as i64);
            let top = hash(i, j) * (1.0 - a) + hash(i + 1, j) * a;
            let bot = hash(i, j + 1) * (1.0 - a) + hash(i + 1, j + 1) * a;
            image::Luma([(40.0 + 170.0 * (top * (1.0 - b) + bot * b)).round() as u8])
        })
    }

    #[test]
    fn finds_a_known_subpixel_shift() {
        // The right image sees the scene 17.4 px further left: right(x) = left(x + 17.4).
        let l = textured(320, 240, 0.0);
        let r = textured(320, 240, 17.4);
        let m = match_box(&l, &r, [150, 100, 40, 30], &MatchOptions::default()).unwrap();
        assert!((m.disparity - 17.4).abs() < 0.1, "{m:?}");
        assert!(m.score > 0.95);
        // The right image as reference finds the same disparity the other way.
        let opts = MatchOptions {
            reference_left: false,
            ..MatchOptions::default()
        };
        let m = match_box(&r, &l, [150, 100, 40, 30], &opts).unwrap();
        assert!((m.disparity - 17.4).abs() < 0.1, "{m:?}");
    }

    #[test]
    fn bad_input_gives_no_range() {
        let l = textured(320, 240, 0.0);
        let small = textured(160, 120, 0.0);
        let o = MatchOptions::default();
        assert!(matches!(
            match_box(&l, &small, [10, 10, 20, 20], &o),
            Err(NoRange::SizeMismatch { .. })
        ));
        assert!(matches!(
            match_box(&l, &l, [310, 10, 20, 20], &o),
            Err(NoRange::BadBox(_))
        ));
        let flat = GrayImage::from_pixel(320, 240, image::Luma([90]));
        assert!(matches!(
            match_box(&flat, &l, [100, 100, 20, 20], &o),
            Err(NoRange::Flat)
        ));
        // The same image: disparity 0 is the peak → no range.
        assert!(matches!(
            match_box(&l, &l, [100, 100, 20, 20], &o),
            Err(NoRange::NonPositiveDisparity(_))
        ));
        // An unrelated image: the best score is low.
        let noise = GrayImage::from_fn(320, 240, |x, y| image::Luma([((x * 7919 + y * 104729) % 251) as u8]));
        let e = match_box(&l, &noise, [100, 100, 30, 30], &o).unwrap_err();
        assert!(matches!(e, NoRange::BelowThreshold { .. }), "{e}");
        // No room: a box at the left edge with the left image as reference and min disparity 5.
        let o2 = MatchOptions {
            min_disparity: 5,
            max_disparity: 10,
            ..o
        };
        assert!(matches!(
            match_box(&l, &r(), [0, 10, 20, 20], &o2),
            Err(NoRange::NoSearchRoom)
        ));
        fn r() -> GrayImage {
            textured(320, 240, 3.0)
        }
    }
}
