//! Finding the reference camera's box in the other image (Zaarane et al. 2020, Sec. 3.2 and
//! Fig. 6): the box is a template slid along the same rows of the other rectified image;
//! the score is the mean-subtracted normalised cross-correlation (OpenCV's TM_CCOEFF_NORMED;
//! with several planes, as OpenCV does for a colour image: each plane's own mean, the sums
//! taken over all planes)
//!
//! ```text
//! R(d) = Σ T'(x, y)·I'(x ∓ d, y) / √(Σ T'² · Σ I'²),   T' = T − mean T, I' = I − mean I (window)
//! ```
//!
//! 1. Column sums of I and I² over the box's rows give every window's mean and energy by a
//!    sliding sum; Σ T'·I needs one pass per candidate disparity (Σ T' = 0, so I' = I there).
//!    That pass is kept row by row, so each row of the box can also be matched on its own
//!    ([`Matcher::rows`]) for the price of the row's window sums.
//! 2. The best disparity must score ≥ `min_score` (else the object is not in the other view:
//!    "no range").
//!    Occlusion prior: an object hides what is behind it, so of the local maxima scoring at
//!    least `near_peak_ratio` × the best, the one with the largest disparity (nearest) is
//!    taken. A flat-coloured object over a textured floor otherwise locks onto the floor
//!    behind it (its lines fill the box); 1.0 turns the prior off.
//! 3. Sub-pixel: a parabola through the peak and its two neighbours,
//!    δ = (R₋ − R₊) / (2(R₋ − 2R₀ + R₊)), |δ| ≤ 0.5. (An equiangular "V" fit was measured
//!    too, tests/stereo_sim.rs: no better for the signs, worse for the traffic light.)
//!
//! Plain coloured objects (obstacles) are matched on two linear colour-opponent planes
//! ([`opponent_from_rgb`]): grey and white (the floor, its lines) are nearly 0 there, so only
//! the object's silhouette correlates, and because the planes are linear in R, G, B a pixel
//! half covered by the object's edge keeps half its value, so the edge keeps its sub-pixel
//! position. (The chroma max − min used before is not linear: a pixel half blue, half
//! brown-grey has R ≈ B and reads as floor, every edge snapped to a whole pixel and the
//! disparity of a 0.06 m base came out 0.5 px short; docs/stereo.md.)
//!
//! With the left image as reference, the object sits d pixels further left in the right
//! image (x_r = x_l − d); with the right one as reference, further right. Units: pixels.
//! Why a box gets no range, here or in the geometry, is [`NoRange`].

use image::{GrayImage, RgbImage};

/// Why a box got no stereo range (never a wrong number).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoRange {
    /// The two images differ in size.
    #[error("the pair's images differ in size: {left_w}x{left_h} and {right_w}x{right_h}")]
    SizeMismatch {
        /// Reference image width.
        left_w: u32,
        /// Reference image height.
        left_h: u32,
        /// Other image width.
        right_w: u32,
        /// Other image height.
        right_h: u32,
    },
    /// The box is empty, too small to correlate, or outside the image.
    #[error("box {0:?} is too small or outside the image")]
    BadBox([i64; 4]),
    /// The template is flat (no texture to correlate).
    #[error("the box has no texture to match (flat grey)")]
    Flat,
    /// The best correlation is below the threshold: the object is not in the other image.
    #[error("best match {score:.3} is below the threshold {min:.3}")]
    BelowThreshold {
        /// Best normalised correlation found.
        score: f64,
        /// The threshold.
        min: f64,
    },
    /// Disparity zero or negative: the object is at infinity or the match is wrong.
    #[error("disparity {0:.3} px: no distance (at infinity or a wrong match)")]
    NonPositiveDisparity(f64),
    /// The disparity search range holds no position (box at the image edge).
    #[error("no room to search: the box is at the image edge")]
    NoSearchRoom,
    /// The box is a repeated pattern: it matches a copy of itself along its own rows as well
    /// as it matches the other image, so the match may be a copy (`reject_repeats`).
    #[error("the box repeats along its rows (a copy of it scores {copy:.3}, the match {score:.3}): no unique match")]
    Repeated {
        /// Best correlation of the box with a shifted copy of itself.
        copy: f64,
        /// Correlation of the match in the other image.
        score: f64,
    },
}

/// At most this many evenly spaced rows of a box are matched by [`Matcher::match_planes`]
/// (the face fit is a median over rows; a 115-row box at 0.3 m then costs what a 16-row one
/// does).
pub const MAX_ROWS: usize = 16;
/// At most this many evenly spaced columns of a box's rows are correlated by
/// [`Matcher::match_planes`] (the window still slides pixel by pixel).
pub const MAX_COLS: usize = 64;

/// Two colour-opponent planes of an RGB image, each linear in R, G, B:
/// `out[0]` = 128 + (R − G)/2 and `out[1]` = 128 + (R + G − 2B)/4 (rounded). Grey and white
/// (R = G = B) give 128 in both, so a grey floor and its white lines vanish and a coloured
/// object stays; a pixel that is a mix of object and floor gets the mix of their values, so
/// edges keep their sub-pixel position (which max − min, the "chroma", does not).
pub fn opponent_from_rgb(rgb: &RgbImage, out: &mut [GrayImage; 2]) {
    opponent_from_rgb_rows(rgb, out, 0..rgb.height());
}

/// [`opponent_from_rgb`] for the rows `rows` only (clipped to the image); the other rows of
/// `out` keep what they held (planes of another size are made anew, all zero).
pub fn opponent_from_rgb_rows(rgb: &RgbImage, out: &mut [GrayImage; 2], rows: std::ops::Range<u32>) {
    for o in out.iter_mut() {
        if o.dimensions() != rgb.dimensions() {
            *o = GrayImage::new(rgb.width(), rgb.height());
        }
    }
    let w = rgb.width() as usize;
    let (r0, r1) = (
        rows.start.min(rgb.height()) as usize,
        rows.end.min(rgb.height()) as usize,
    );
    if r0 >= r1 {
        return;
    }
    let [a, b] = out;
    let (a, b): (&mut [u8], &mut [u8]) = (&mut (**a)[r0 * w..r1 * w], &mut (**b)[r0 * w..r1 * w]);
    let src = &rgb.as_raw()[3 * r0 * w..3 * r1 * w];
    for ((pa, pb), p) in a.iter_mut().zip(b.iter_mut()).zip(src.chunks_exact(3)) {
        let [r, g, bl] = [p[0], p[1], p[2]].map(|v| v as i32);
        // Both in 0..=255 by construction; +1 / +2 before the shift round half up.
        *pa = ((256 + r - g + 1) >> 1) as u8;
        *pb = ((512 + r + g - 2 * bl + 2) >> 2).min(255) as u8;
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
    /// Refuse a box that is a repeated pattern ([`Matcher::match_box`]): one that matches a
    /// copy of itself along its own rows (≥ [`MIN_REPEAT_SHIFT`] px away) at least as well as
    /// it matches the other image ([`NoRange::Repeated`]).
    pub reject_repeats: bool,
}

/// The smallest shift along its own rows at which a box's self-correlation peak counts as a
/// copy of it ([`MatchOptions::reject_repeats`]); nearer shifts are the slope of the peak at 0.
pub const MIN_REPEAT_SHIFT: usize = 4;

impl Default for MatchOptions {
    fn default() -> Self {
        Self {
            min_disparity: 0,
            max_disparity: 120,
            min_score: 0.6,
            reference_left: true,
            near_peak_ratio: 0.9,
            reject_repeats: true,
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

/// One row of the box matched on its own ([`Matcher::match_planes`]): its best disparity
/// (sub-pixel) and score, kept when the score reaches `min_score` and the disparity is > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowMatch {
    /// Image row, pixels.
    pub row: u32,
    /// Disparity, pixels (sub-pixel), > 0.
    pub disparity: f64,
    /// The correlation at the integer peak.
    pub score: f64,
}

/// Scratch buffers reused between calls (a matcher per camera pair).
#[derive(Debug, Default, Clone)]
pub struct Matcher {
    tmpl: Vec<f32>,
    colsum: Vec<f64>,
    colsq: Vec<f64>,
    scores: Vec<f64>,
    /// Σ over planes and the row's columns of T'·I, per box row and disparity index.
    row_cross: Vec<f32>,
    row_scores: Vec<f64>,
    prefix: Vec<f64>,
    prefix_sq: Vec<f64>,
    rows: Vec<RowMatch>,
}

/// The sub-pixel offset of the parabola through `s[i − 1]`, `s[i]`, `s[i + 1]` (0 at an end
/// or without a proper maximum), |δ| ≤ 0.5.
fn parabola(s: &[f64], i: usize) -> f64 {
    if i == 0 || i + 1 >= s.len() {
        return 0.0;
    }
    let (a, b, c) = (s[i - 1], s[i], s[i + 1]);
    let den = a - 2.0 * b + c;
    if a.is_finite() && c.is_finite() && den < 0.0 {
        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

impl Matcher {
    /// A matcher with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// The NCC scores of every disparity in `min..=max` (index 0 = `min`), as
    /// [`match_box`] computes them; NaN where the window leaves the image.
    pub fn scores(&self) -> &[f64] {
        &self.scores
    }

    /// The rows of the box matched on their own by the last [`Matcher::match_planes`] (empty
    /// after [`Matcher::match_box`] or when it found no match).
    pub fn rows(&self) -> &[RowMatch] {
        &self.rows
    }

    /// Finds the box `[x, y, w, h]` (pixels, top-left and size) of `reference` in `other`.
    ///
    /// With [`MatchOptions::reject_repeats`], a match is refused when the box also matches
    /// itself elsewhere along its own rows at least as well ([`NoRange::Repeated`]): a
    /// wallpaper, tiles or a fence repeat, and where the object's true match is hidden in the
    /// other view a copy one period away passes the threshold with a confident, wrong
    /// disparity (measured on Middlebury Aloe, tests/stereo_photos.rs).
    pub fn match_box(
        &mut self,
        reference: &GrayImage,
        other: &GrayImage,
        bbox: [i64; 4],
        opts: &MatchOptions,
    ) -> Result<StereoMatch, NoRange> {
        let m = self.match_core(&[reference], &[other], bbox, opts, false)?;
        if opts.reject_repeats {
            let copy = self.self_similarity(reference, bbox, opts, m.disparity);
            if copy >= m.score {
                return Err(NoRange::Repeated { copy, score: m.score });
            }
        }
        Ok(m)
    }

    /// The best correlation of the box with a copy of itself along its own rows (local maxima
    /// at least [`MIN_REPEAT_SHIFT`] px away); −∞ without one. Only the shifts a copy can have
    /// been confused at are searched: a copy p px along the row on a surface of disparity d_s
    /// is found at d_s − p, so with the match at `d` and d_s in [0, max] the copy is at
    /// p ∈ [d − max, d] (reference left; mirrored for the right) — `max_disparity` shifts in
    /// all, not twice that. [`Matcher::scores`] keeps the scores of the match.
    fn self_similarity(&mut self, reference: &GrayImage, bbox: [i64; 4], opts: &MatchOptions, d: f64) -> f64 {
        let scores = std::mem::take(&mut self.scores);
        let mut best = f64::NEG_INFINITY;
        let max = opts.max_disparity as f64;
        // (shift towards the other camera's matches, up to d) and (the other way, up to max − d).
        let toward = (d.ceil() + 1.0).min(max) as u32;
        let away = (max - d.floor() + 1.0).max(0.0) as u32;
        for (reference_left, reach) in [(opts.reference_left, toward), (!opts.reference_left, away)] {
            if (reach as usize) <= MIN_REPEAT_SHIFT {
                continue;
            }
            let o = MatchOptions {
                min_disparity: 0,
                max_disparity: reach,
                min_score: -1.0,
                near_peak_ratio: 1.0,
                reference_left,
                reject_repeats: false,
            };
            // Errors (no room on one side) leave no scores to look at.
            let _ = self.match_core(&[reference], &[reference], bbox, &o, false);
            let s = &self.scores;
            for k in MIN_REPEAT_SHIFT..s.len().saturating_sub(1) {
                if s[k].is_finite() && s[k] >= s[k - 1] && s[k] >= s[k + 1] {
                    best = best.max(s[k]);
                }
            }
        }
        self.scores = scores;
        best
    }

    /// [`Matcher::match_box`] over several planes at once (e.g. [`opponent_from_rgb`]'s two;
    /// `reference` and `other` hold the same number), then each row of the box on its own
    /// ([`Matcher::rows`]): a tilted camera sees a vertical face with a disparity that changes
    /// from row to row, and the top of a box farther back; the rows tell them apart
    /// ([`super::StereoGeometry::vertical_face`]).
    pub fn match_planes(
        &mut self,
        reference: &[&GrayImage],
        other: &[&GrayImage],
        bbox: [i64; 4],
        opts: &MatchOptions,
    ) -> Result<StereoMatch, NoRange> {
        self.match_core(reference, other, bbox, opts, true)
    }

    fn match_core(
        &mut self,
        reference: &[&GrayImage],
        other: &[&GrayImage],
        bbox: [i64; 4],
        opts: &MatchOptions,
        want_rows: bool,
    ) -> Result<StereoMatch, NoRange> {
        self.rows.clear();
        let g = Sampling::of(reference, other, bbox, want_rows)?;
        // The template, each plane less its own mean.
        let tnorm = self.template(reference, &g);
        if tnorm < 1e-6 * g.n * g.planes as f64 {
            return Err(NoRange::Flat);
        }
        // 1. Column sums of each plane of the other image over the box's rows.
        self.column_sums(other, &g);
        // Candidate window starts: x_other = bx ∓ d.
        let (dmin, dmax) = (
            opts.min_disparity as i64,
            opts.max_disparity.max(opts.min_disparity) as i64,
        );
        let nd = (dmax - dmin + 1) as usize;
        let (bx, bw, iw) = (g.bx, g.bw, g.iw);
        let x0_of = |d: i64| -> Option<usize> {
            let x0 = if opts.reference_left {
                bx as i64 - d
            } else {
                bx as i64 + d
            };
            (x0 >= 0 && x0 as usize + bw <= iw).then_some(x0 as usize)
        };
        // 2. The normalised cross-correlation of every candidate window.
        let best = self.score_windows(other, &g, tnorm, (dmin, dmax, nd), &x0_of, want_rows);
        let Some((i, score)) = best else {
            return Err(NoRange::NoSearchRoom);
        };
        // 2b. The nearest of the near-best local maxima.
        let (i, score) = nearest_near_best(&self.scores, i, score, opts);
        // 2c. Threshold.
        if score < opts.min_score {
            return Err(NoRange::BelowThreshold {
                score,
                min: opts.min_score,
            });
        }
        // 3. Parabolic sub-pixel peak.
        let disparity = (dmin + i as i64) as f64 + parabola(&self.scores, i);
        if disparity <= 0.0 {
            return Err(NoRange::NonPositiveDisparity(disparity));
        }
        let x_ref = bx as f64 + (bw as f64 - 1.0) / 2.0;
        let x_other = if opts.reference_left {
            x_ref - disparity
        } else {
            x_ref + disparity
        };
        if want_rows {
            self.match_rows(reference, other, (g.by, bw, g.bhs, g.bws), (g.rs, g.cs), (dmin, nd), opts, &x0_of);
        }
        Ok(StereoMatch {
            disparity,
            score,
            x_ref,
            x_other,
        })
    }

    /// The template: the reference planes over the (sampled) box, each less its own mean,
    /// into `self.tmpl`; returns the sum of its squares.
    fn template(&mut self, reference: &[&GrayImage], g: &Sampling) -> f64 {
        let (iw, bx, by, bw, bh, rs, cs) = (g.iw, g.bx, g.by, g.bw, g.bh, g.rs, g.cs);
        self.tmpl.clear();
        let mut tnorm = 0f64;
        for r in reference.iter().take(g.planes).map(|p| p.as_raw()) {
            let start = self.tmpl.len();
            let mut tsum = 0f64;
            for y in (by..by + bh).step_by(rs) {
                for &v in r[y * iw + bx..y * iw + bx + bw].iter().step_by(cs) {
                    tsum += v as f64;
                    self.tmpl.push(v as f32);
                }
            }
            let tmean = (tsum / g.n) as f32;
            for v in self.tmpl[start..].iter_mut() {
                *v -= tmean;
                tnorm += (*v as f64) * (*v as f64);
            }
        }
        tnorm
    }

    /// Column sums and sums of squares of each plane of the other image over the box's
    /// (sampled) rows, every column of the image (`self.colsum`, `self.colsq`).
    fn column_sums(&mut self, other: &[&GrayImage], g: &Sampling) {
        let (iw, by, bh, rs, planes) = (g.iw, g.by, g.bh, g.rs, g.planes);
        self.colsum.clear();
        self.colsum.resize(iw * planes, 0.0);
        self.colsq.clear();
        self.colsq.resize(iw * planes, 0.0);
        for (p, o) in other.iter().take(planes).enumerate() {
            let o = o.as_raw();
            let (cs, cq) = (
                &mut self.colsum[p * iw..(p + 1) * iw],
                &mut self.colsq[p * iw..(p + 1) * iw],
            );
            for y in (by..by + bh).step_by(rs) {
                for ((s, q), &v) in cs.iter_mut().zip(cq.iter_mut()).zip(&o[y * iw..(y + 1) * iw]) {
                    let v = v as f64;
                    *s += v;
                    *q += v * v;
                }
            }
        }
    }

    /// The normalised cross-correlation of the template with the window at every disparity
    /// `dmin..=dmax` (NaN where the window leaves the image) into `self.scores`, and each
    /// sampled row's cross term into `self.row_cross` when `want_rows`; the best index and
    /// score.
    fn score_windows(
        &mut self,
        other: &[&GrayImage],
        g: &Sampling,
        tnorm: f64,
        (dmin, dmax, nd): (i64, i64, usize),
        x0_of: &dyn Fn(i64) -> Option<usize>,
        want_rows: bool,
    ) -> Option<(usize, f64)> {
        let (iw, by, bw, bh, rs, cs, bhs, bws, n, planes) =
            (g.iw, g.by, g.bw, g.bh, g.rs, g.cs, g.bhs, g.bws, g.n, g.planes);
        self.scores.clear();
        if want_rows {
            self.row_cross.clear();
            self.row_cross.resize(bhs * nd, 0.0);
        }
        let mut best: Option<(usize, f64)> = None;
        for (k, d) in (dmin..=dmax).enumerate() {
            let Some(x0) = x0_of(d) else {
                self.scores.push(f64::NAN);
                continue;
            };
            let mut var = 0f64;
            for p in 0..planes {
                let (mut s, mut s2) = (0f64, 0f64);
                for x in (x0..x0 + bw).step_by(cs) {
                    s += self.colsum[p * iw + x];
                    s2 += self.colsq[p * iw + x];
                }
                var += s2 - s * s / n;
            }
            let mut cross = 0f32;
            for (ty, y) in (by..by + bh).step_by(rs).enumerate() {
                let mut acc = 0f32;
                for (p, o) in other.iter().take(planes).enumerate() {
                    let row = &o.as_raw()[y * iw + x0..y * iw + x0 + bw];
                    let t = &self.tmpl[(p * bhs + ty) * bws..(p * bhs + ty + 1) * bws];
                    for (a, b) in row.iter().step_by(cs).zip(t) {
                        acc += *a as f32 * b;
                    }
                }
                if want_rows {
                    self.row_cross[ty * nd + k] = acc;
                }
                cross += acc;
            }
            let score = if var > 1e-9 {
                cross as f64 / (tnorm * var).sqrt()
            } else {
                0.0
            };
            if best.is_none_or(|b| score > b.1) {
                best = Some((self.scores.len(), score));
            }
            self.scores.push(score);
        }
        best
    }

    /// Each row of the box on its own: the template row less its own means, the window's
    /// sums from running sums along the other image's row. With T'' = T − mean of the box
    /// (what `row_cross` holds) and t_r, t the row's and the box's means of a plane,
    /// Σ (T − t_r)(I − Ī) = Σ T''·I − (t_r − t)·Σ I.
    #[allow(clippy::too_many_arguments)]
    fn match_rows(
        &mut self,
        reference: &[&GrayImage],
        other: &[&GrayImage],
        (by, bw, bhs, bws): (usize, usize, usize, usize),
        (rs, cs): (usize, usize),
        (dmin, nd): (i64, usize),
        opts: &MatchOptions,
        x0_of: &dyn Fn(i64) -> Option<usize>,
    ) {
        let planes = reference.len().min(other.len());
        let iw = reference[0].width() as usize;
        let bwf = bws as f64;
        // Per plane: the row's template mean less the box's, and the row's own energy.
        let mut offs = [0f64; 4];
        for ty in 0..bhs {
            let y = by + ty * rs;
            let mut vt = 0f64;
            let mut ok = planes <= offs.len();
            for p in 0..planes.min(offs.len()) {
                let t = &self.tmpl[(p * bhs + ty) * bws..(p * bhs + ty + 1) * bws];
                let m: f64 = t.iter().map(|&v| v as f64).sum::<f64>() / bwf;
                offs[p] = m;
                vt += t.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>();
            }
            ok &= vt > 1e-6 * bwf * planes as f64;
            if !ok {
                continue; // a flat row: nothing to match
            }
            // Running sums of each plane along the other image's row (every cs-th pixel
            // from each start: one prefix array per phase would cost more than direct sums
            // when cs > 1, so those are summed directly below).
            self.prefix.clear();
            self.prefix_sq.clear();
            if cs == 1 {
                for o in other.iter().take(planes) {
                    let row = &o.as_raw()[y * iw..(y + 1) * iw];
                    let (mut s, mut q) = (0f64, 0f64);
                    self.prefix.push(0.0);
                    self.prefix_sq.push(0.0);
                    for &v in row {
                        let v = v as f64;
                        s += v;
                        q += v * v;
                        self.prefix.push(s);
                        self.prefix_sq.push(q);
                    }
                }
            }
            self.row_scores.clear();
            let mut best: Option<(usize, f64)> = None;
            for k in 0..nd {
                let Some(x0) = x0_of(dmin + k as i64) else {
                    self.row_scores.push(f64::NAN);
                    continue;
                };
                let mut cov = self.row_cross[ty * nd + k] as f64;
                let mut vi = 0f64;
                for (p, off) in offs.iter().enumerate().take(planes) {
                    let (s, q) = if cs == 1 {
                        let base = p * (iw + 1);
                        (
                            self.prefix[base + x0 + bw] - self.prefix[base + x0],
                            self.prefix_sq[base + x0 + bw] - self.prefix_sq[base + x0],
                        )
                    } else {
                        let row = &other[p].as_raw()[y * iw + x0..y * iw + x0 + bw];
                        row.iter().step_by(cs).fold((0f64, 0f64), |(s, q), &v| {
                            let v = v as f64;
                            (s + v, q + v * v)
                        })
                    };
                    cov -= off * s;
                    vi += q - s * s / bwf;
                }
                let score = if vi > 1e-9 { cov / (vt * vi).sqrt() } else { 0.0 };
                if best.is_none_or(|b| score > b.1) {
                    best = Some((k, score));
                }
                self.row_scores.push(score);
            }
            let Some((i, score)) = best else { continue };
            if score < opts.min_score {
                continue;
            }
            let disparity = (dmin + i as i64) as f64 + parabola(&self.row_scores, i);
            if disparity > 0.0 {
                self.rows.push(RowMatch {
                    row: y as u32,
                    disparity,
                    score,
                });
            }
        }
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

/// Where the box is and how it is sampled, for [`Matcher::match_core`]'s steps.
struct Sampling {
    /// Image width (every plane's).
    iw: usize,
    /// Planes matched (the fewer of the two sides').
    planes: usize,
    /// The box: left, top, width, height, pixels.
    bx: usize,
    by: usize,
    bw: usize,
    bh: usize,
    /// Row and column steps (1 unless a large box is sampled row by row).
    rs: usize,
    cs: usize,
    /// Sampled rows and columns.
    bhs: usize,
    bws: usize,
    /// Samples per plane, `bws · bhs`.
    n: f64,
}

impl Sampling {
    /// The box checked against the images (all of one size, at least 3×3 pixels, inside),
    /// and its sampling: row by row (obstacles), a large box is sampled at most MAX_ROWS
    /// evenly spaced rows and MAX_COLS evenly spaced columns (the window slides by whole
    /// pixels all the same, so the disparity resolution is unchanged; the face fit is a
    /// median over rows).
    fn of(reference: &[&GrayImage], other: &[&GrayImage], bbox: [i64; 4], want_rows: bool) -> Result<Self, NoRange> {
        let Some(first) = reference.first() else {
            return Err(NoRange::Flat);
        };
        let (w, h) = first.dimensions();
        for img in reference.iter().chain(other.iter()) {
            if img.dimensions() != (w, h) {
                return Err(NoRange::SizeMismatch {
                    left_w: w,
                    left_h: h,
                    right_w: img.width(),
                    right_h: img.height(),
                });
            }
        }
        let [bx, by, bw, bh] = bbox;
        // Written so that no sum can overflow (a box from the command line may hold i64::MAX).
        if bw < 3 || bh < 3 || bx < 0 || by < 0 || bw > w as i64 - bx || bh > h as i64 - by {
            return Err(NoRange::BadBox(bbox));
        }
        let (bx, by, bw, bh) = (bx as usize, by as usize, bw as usize, bh as usize);
        let (rs, cs) = if want_rows {
            (bh.div_ceil(MAX_ROWS).max(1), bw.div_ceil(MAX_COLS).max(1))
        } else {
            (1, 1)
        };
        let (bhs, bws) = (bh.div_ceil(rs), bw.div_ceil(cs));
        Ok(Sampling {
            iw: w as usize,
            planes: reference.len().min(other.len()),
            bx,
            by,
            bw,
            bh,
            rs,
            cs,
            bhs,
            bws,
            n: (bws * bhs) as f64,
        })
    }
}

/// Of the local maxima of `scores` at or right of the best `i` (score `score`), the last one
/// within `near_peak_ratio` of the best and above `min_score`: the nearest object when two
/// surfaces match almost equally well.
fn nearest_near_best(scores: &[f64], mut i: usize, mut score: f64, opts: &MatchOptions) -> (usize, f64) {
    let floor = score * opts.near_peak_ratio.min(1.0);
    for k in (i + 1)..scores.len() {
        let v = scores[k];
        let left = scores[k - 1];
        let right = scores.get(k + 1).copied().unwrap_or(f64::NEG_INFINITY);
        if v >= floor
            && v >= opts.min_score
            && v >= left
            && right.partial_cmp(&v) != Some(std::cmp::Ordering::Greater)
        {
            i = k;
            score = v;
        }
    }
    (i, score)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box whose corner plus size overflows i64 is refused, not sliced out of range (issue
    /// 24: `rccar stereo --box 9223372036854775807,0,5,5` panicked here).
    #[test]
    fn a_box_at_the_end_of_i64_is_refused() {
        let g = GrayImage::from_fn(64, 48, |x, y| image::Luma([((x * 7 + y * 13) % 251) as u8]));
        for b in [[i64::MAX, 0, 5, 5], [0, i64::MAX, 5, 5], [10, 10, i64::MAX, 5], [60, 0, 5, 5]] {
            let e = match_box(&g, &g, b, &MatchOptions::default()).unwrap_err();
            assert_eq!(e, NoRange::BadBox(b));
        }
    }

    /// A plain blue box (disparity 20 px) in front of a floor of irregular white stripes
    /// (disparity 5 px) that fill most of the box: the opponent planes see only the box.
    #[test]
    fn opponent_planes_find_a_plain_box_in_front_of_stripes() {
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
        let (mut gl, mut gr) = (GrayImage::new(0, 0), GrayImage::new(0, 0));
        crate::detect::gray_from_rgb(&l, &mut gl);
        crate::detect::gray_from_rgb(&r, &mut gr);
        let (mut ol, mut or) = (planes(), planes());
        opponent_from_rgb(&l, &mut ol);
        opponent_from_rgb(&r, &mut or);
        let opts = MatchOptions {
            max_disparity: 60,
            near_peak_ratio: 1.0,
            ..MatchOptions::default()
        };
        let mut m = Matcher::new();
        let bx = [84, 10, 40, 40];
        let got = m.match_planes(&[&ol[0], &ol[1]], &[&or[0], &or[1]], bx, &opts).unwrap();
        assert!((got.disparity - 20.0).abs() < 0.1, "{got:?}");
        // Row by row: the 40-row box is sampled every 3rd row (MAX_ROWS = 16); its rows on
        // the box find the box, the floor-only rows above and below (this floor is not quite
        // grey and has no noise) find the floor's 5 px.
        assert_eq!(m.rows().len(), 14, "{:?}", m.rows());
        for r in m.rows() {
            let want = if (15..45).contains(&r.row) { 20.0 } else { 5.0 };
            assert!((r.disparity - want).abs() < 0.1, "{r:?}");
        }
        // Grey alone is pulled off the box by the stripes (18.0 px).
        let grey = m.match_box(&gl, &gr, bx, &opts).unwrap();
        assert!((grey.disparity - 20.0).abs() > 1.5, "{grey:?}");
        assert!(m.rows().is_empty());
        // A grey object has no colour: both planes are flat.
        let g = image::imageops::grayscale(&l);
        let grey_l = image::DynamicImage::ImageLuma8(g).to_rgb8();
        opponent_from_rgb(&grey_l, &mut ol);
        assert!(ol.iter().all(|p| p.pixels().all(|v| v.0[0] == 128)));
        assert_eq!(
            m.match_planes(&[&ol[0], &ol[1]], &[&ol[0], &ol[1]], bx, &opts),
            Err(NoRange::Flat)
        );
    }

    fn planes() -> [GrayImage; 2] {
        [GrayImage::new(0, 0), GrayImage::new(0, 0)]
    }

    /// A blue box over a brown-grey floor whose edges fall inside pixels (each pixel the
    /// coverage-weighted mix, as the simulator's 2×2 samples and a real lens give), 11.5 px
    /// of disparity: the linear opponent planes keep the half-covered pixels and find 11.5;
    /// max − min of R, G, B (the "chroma" matched before) reads a half blue, half floor
    /// pixel as floor (R ≈ B), snaps both edges to whole pixels and is 0.5 px off.
    #[test]
    fn opponent_planes_keep_subpixel_edges_where_max_minus_min_does_not() {
        let img = |left_edge: f64| {
            RgbImage::from_fn(200, 40, |x, y| {
                let x = x as f64;
                // Coverage of [x − 0.5, x + 0.5] by [left_edge, left_edge + 23.2).
                let c = ((x + 0.5).min(left_edge + 23.2) - (x - 0.5).max(left_edge)).clamp(0.0, 1.0);
                let c = if (8..32).contains(&y) { c } else { 0.0 };
                let floor = [112.0, 104.0, 96.0];
                let blue = [28.0, 42.0, 75.0];
                image::Rgb(std::array::from_fn(|k| {
                    (c * blue[k] + (1.0 - c) * floor[k]).round() as u8
                }))
            })
        };
        let (l, r) = (img(100.25), img(100.25 - 11.5));
        let (mut ol, mut or) = (planes(), planes());
        opponent_from_rgb(&l, &mut ol);
        opponent_from_rgb(&r, &mut or);
        let opts = MatchOptions::default();
        let bx = [90, 4, 44, 32];
        let mut m = Matcher::new();
        let got = m.match_planes(&[&ol[0], &ol[1]], &[&or[0], &or[1]], bx, &opts).unwrap();
        assert!((got.disparity - 11.5).abs() < 0.1, "{got:?}");
        assert!(
            m.rows().iter().all(|r| (r.disparity - 11.5).abs() < 0.1),
            "{:?}",
            m.rows()
        );
        let chroma = |rgb: &RgbImage| {
            GrayImage::from_fn(rgb.width(), rgb.height(), |x, y| {
                let p = rgb.get_pixel(x, y).0;
                image::Luma([p.iter().max().unwrap() - p.iter().min().unwrap()])
            })
        };
        let old = m.match_box(&chroma(&l), &chroma(&r), bx, &opts).unwrap();
        assert!((old.disparity - 11.5).abs() > 0.3, "{old:?}");
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

    /// Every row of a textured box matched on its own finds the box's shift; the rows agree
    /// with the whole box and the planes API on one plane agrees with `match_box`.
    #[test]
    fn rows_match_on_their_own() {
        let l = textured(320, 240, 0.0);
        let r = textured(320, 240, 17.4);
        let o = MatchOptions::default();
        let mut m = Matcher::new();
        let whole = m.match_box(&l, &r, [150, 100, 40, 30], &o).unwrap();
        let planes = m.match_planes(&[&l], &[&r], [150, 100, 40, 30], &o).unwrap();
        // The planes API samples every 2nd of the 30 rows (MAX_ROWS = 16).
        assert!((whole.disparity - planes.disparity).abs() < 0.1);
        assert!((12..=MAX_ROWS).contains(&m.rows().len()), "{}", m.rows().len());
        for row in m.rows() {
            assert!((100..130).contains(&row.row));
            assert!((row.disparity - 17.4).abs() < 0.25, "{row:?}");
        }
    }

    /// A wallpaper repeating every 40 px behind the box; in the right view the box's true
    /// place (disparity 12) is hidden by a plain object, so the best matches left are copies
    /// whole periods away (disparity 52, 92), confident and wrong. `reject_repeats` refuses it; an
    /// aperiodic texture is still matched.
    #[test]
    fn a_repeated_pattern_whose_match_is_hidden_gives_no_range() {
        let tile = textured(40, 240, 0.0);
        let wallpaper = |shift: i64| {
            GrayImage::from_fn(320, 240, |x, y| {
                *tile.get_pixel(((x as i64 + shift).rem_euclid(40)) as u32, y)
            })
        };
        let l = wallpaper(0);
        let mut r = wallpaper(12);
        for y in 90..140 {
            for x in 130..175 {
                r.put_pixel(x, y, image::Luma([70]));
            }
        }
        let bx = [150, 100, 30, 30];
        let without = MatchOptions {
            reject_repeats: false,
            ..MatchOptions::default()
        };
        let wrong = match_box(&l, &r, bx, &without).unwrap();
        // A copy whole periods away (the occlusion prior takes the nearest of the equal ones).
        let periods = (wrong.disparity - 12.0) / 40.0;
        assert!(
            periods.round() >= 1.0 && (periods - periods.round()).abs() < 0.02 && wrong.score > 0.95,
            "{wrong:?}"
        );
        let e = match_box(&l, &r, bx, &MatchOptions::default()).unwrap_err();
        assert!(matches!(e, NoRange::Repeated { copy, .. } if copy > 0.95), "{e}");
        assert!(e.to_string().contains("repeats along its rows"), "{e}");
        // The scores of the match are kept for the caller, not those of the self-check.
        let mut m = Matcher::new();
        let _ = m.match_box(&l, &r, bx, &MatchOptions::default());
        let best = m.scores().iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!((best - wrong.score).abs() < 1e-9, "{best} {}", wrong.score);
        // Aperiodic texture: the same check lets the true match through.
        let (l, r) = (textured(320, 240, 0.0), textured(320, 240, 12.0));
        let ok = match_box(&l, &r, bx, &MatchOptions::default()).unwrap();
        assert!((ok.disparity - 12.0).abs() < 0.1, "{ok:?}");
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
