//! One cascade on one pyramid level: the cascade compiled to integral-image offsets and its
//! windows scanned (steps 1 and 4–6 of `detector.rs`, OpenCV's `detectMultiScale`), with the
//! raw hits grouped (step 7). [`super::pyramid`] builds the levels and calls [`Scanner::scan`]
//! on each; [`super::detector::Detector`] is the one-cascade entry point over both.
//!
//! Below both, so the pyramid and the detector each import this and not each other.
//! Units: pixels (input image, or level where said).

use super::cascade::{Cascade, FeatureType};
use super::group::{group_rectangles, Rect};

/// OpenCV's `GROUP_EPS`.
pub const GROUP_EPS: f64 = 0.2;

/// Options of one detection call (OpenCV's `detectMultiScale` arguments).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetectParams {
    /// Ratio between successive scales, > 1 (OpenCV's `scaleFactor`, default 1.1).
    pub scale_factor: f64,
    /// A group needs more than this many raw hits to be kept; 0 returns raw hits.
    pub min_neighbors: u32,
    /// Smallest window (width, height) in pixels; (0, 0) = no limit.
    pub min_size: (u32, u32),
    /// Largest window (width, height) in pixels; (0, 0) = the image size.
    pub max_size: (u32, u32),
    /// Spread the scales over threads (needs the `parallel` feature; ignored without it).
    pub parallel: bool,
}

impl Default for DetectParams {
    fn default() -> Self {
        Self {
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size: (0, 0),
            max_size: (0, 0),
            parallel: false,
        }
    }
}

/// One detected object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Detection {
    /// Box in input-image pixels.
    pub rect: Rect,
    /// Raw hits merged into this box (1 when `min_neighbors` is 0).
    pub neighbors: u32,
}

/// Why a detection call was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DetectError {
    /// `scale_factor` must be a finite number above 1.
    #[error("scale_factor {0} must be finite and > 1")]
    BadScaleFactor(f64),
    /// The image is too large for 32-bit integral images.
    #[error("image {0}x{1} is too large (at most 8 megapixels)")]
    ImageTooLarge(u32, u32),
    /// The pixel buffer holds fewer than `width * height` bytes.
    #[error("pixel buffer of {len} bytes is too small for {width}x{height}")]
    BufferTooSmall {
        /// Bytes given.
        len: usize,
        /// Claimed width.
        width: usize,
        /// Claimed height.
        height: usize,
    },
}

/// A feature compiled to offsets from a window's top-left integral element.
#[derive(Debug, Clone, Copy, Default)]
struct HaarOpt {
    ofs: [[u32; 4]; 3],
    w: [f32; 3],
    three: bool,
}

impl HaarOpt {
    /// The feature's raw value on the window whose integral starts at `d[0]`.
    /// `d` must be a window slice of length `Compiled::span` (every offset is below it).
    #[inline(always)]
    fn calc(&self, d: &[i32]) -> f32 {
        let s = |k: usize| {
            let o = &self.ofs[k];
            rect_sum(at(d, o[0]), at(d, o[1]), at(d, o[2]), at(d, o[3]))
        };
        let mut v = self.w[0] * s(0) as f32 + self.w[1] * s(1) as f32;
        if self.three {
            v += self.w[2] * s(2) as f32;
        }
        v
    }
}

/// `p0 − p1 − p2 + p3`, the sum of a rectangle from its four integral corners. Computed with
/// wrapping arithmetic, as OpenCV's `int` arithmetic does in practice: intermediate values of
/// an image near 8 Mpx can leave i32, the result never does.
#[inline(always)]
fn rect_sum(p0: i32, p1: i32, p2: i32, p3: i32) -> i32 {
    p0.wrapping_sub(p1).wrapping_sub(p2).wrapping_add(p3)
}

/// `d[i]` without a bounds check in release builds.
///
/// Sound because every offset stored in a [`Compiled`] is below its `span` (it is computed as
/// one past the largest offset) and every window slice passed in has length `span`.
#[inline(always)]
fn at(d: &[i32], i: u32) -> i32 {
    debug_assert!((i as usize) < d.len());
    // SAFETY: see above; `d.len() == span > i` by construction of `Compiled`.
    unsafe { *d.get_unchecked(i as usize) }
}

/// A stump with its feature inlined (cascades whose trees have one node).
#[derive(Debug, Clone, Copy, Default)]
struct HaarStump {
    f: HaarOpt,
    threshold: f32,
    left: f32,
    right: f32,
}

/// MB-LBP feature: the 16 grid corners.
#[derive(Debug, Clone, Copy, Default)]
struct LbpOpt {
    ofs: [u32; 16],
}

impl LbpOpt {
    #[inline(always)]
    fn calc(&self, d: &[i32]) -> usize {
        let o = &self.ofs;
        let s = |a: usize, b: usize, c: usize, e: usize| rect_sum(at(d, o[a]), at(d, o[b]), at(d, o[c]), at(d, o[e]));
        let c = s(5, 6, 9, 10);
        // Clockwise from the top-left cell, most significant bit first.
        ((s(0, 1, 4, 5) >= c) as usize) << 7
            | ((s(1, 2, 5, 6) >= c) as usize) << 6
            | ((s(2, 3, 6, 7) >= c) as usize) << 5
            | ((s(6, 7, 10, 11) >= c) as usize) << 4
            | ((s(10, 11, 14, 15) >= c) as usize) << 3
            | ((s(9, 10, 13, 14) >= c) as usize) << 2
            | ((s(8, 9, 12, 13) >= c) as usize) << 1
            | ((s(4, 5, 8, 9) >= c) as usize)
    }
}

/// The cascade compiled for one integral layout (stride and tilted offset).
#[derive(Debug, Clone, Default)]
struct Compiled {
    stride: usize,
    tilted_offset: usize,
    stumps: Vec<HaarStump>,
    haar: Vec<HaarOpt>,
    lbp: Vec<LbpOpt>,
    norm: [u32; 4],
    /// Elements a window reaches past its top-left element (for the bounds check).
    span: usize,
}

fn sum_ofs(x: i32, y: i32, w: i32, h: i32, stride: usize) -> [u32; 4] {
    let p = |x: i32, y: i32| (x as usize + y as usize * stride) as u32;
    [p(x, y), p(x + w, y), p(x, y + h), p(x + w, y + h)]
}

fn tilted_ofs(x: i32, y: i32, w: i32, h: i32, stride: usize, tofs: usize) -> [u32; 4] {
    let p = |x: i32, y: i32| (tofs + x as usize + y as usize * stride) as u32;
    [p(x, y), p(x - h, y + h), p(x + w, y + w), p(x + w - h, y + w + h)]
}

impl Compiled {
    fn new(c: &Cascade, stride: usize, tilted_offset: usize) -> Self {
        let mut out = Compiled {
            stride,
            tilted_offset,
            ..Default::default()
        };
        let haar = |f: &super::cascade::HaarFeature| {
            let mut o = HaarOpt {
                three: f.count > 2 && f.rects[2].weight != 0.0,
                ..Default::default()
            };
            for k in 0..3 {
                let r = f.rects[k];
                o.w[k] = r.weight;
                o.ofs[k] = if k >= f.count {
                    [0; 4]
                } else if f.tilted {
                    tilted_ofs(r.x, r.y, r.w, r.h, stride, tilted_offset)
                } else {
                    sum_ofs(r.x, r.y, r.w, r.h, stride)
                };
            }
            o
        };
        match c.feature_type {
            FeatureType::Haar => {
                out.haar = c.haar_features.iter().map(haar).collect();
                if c.max_nodes_per_tree == 1 {
                    out.stumps = c
                        .trees
                        .iter()
                        .map(|t| {
                            let n = c.nodes[t.first_node];
                            HaarStump {
                                f: out.haar[n.feature],
                                threshold: n.threshold,
                                left: c.leaves[t.first_leaf],
                                right: c.leaves[t.first_leaf + 1],
                            }
                        })
                        .collect();
                }
            }
            FeatureType::Lbp => {
                out.lbp = c
                    .lbp_features
                    .iter()
                    .map(|f| {
                        let mut o = LbpOpt::default();
                        for j in 0..4 {
                            for i in 0..4 {
                                o.ofs[j * 4 + i] = sum_ofs(f.x + i as i32 * f.w, f.y + j as i32 * f.h, 0, 0, stride)[0];
                            }
                        }
                        o
                    })
                    .collect();
            }
        }
        out.norm = sum_ofs(1, 1, c.width - 2, c.height - 2, stride);
        // The window's reach: one past the largest offset any feature reads. Every window
        // slice handed to `calc` has exactly this length, which is what makes the unchecked
        // reads there sound.
        let max_ofs = out
            .haar
            .iter()
            .flat_map(|f| f.ofs.iter().flatten())
            .chain(out.stumps.iter().flat_map(|s| s.f.ofs.iter().flatten()))
            .chain(out.lbp.iter().flat_map(|f| f.ofs.iter()))
            .chain(out.norm.iter())
            .copied()
            .max()
            .unwrap_or(0);
        out.span = max_ofs as usize + 1;
        out
    }
}

/// One cascade compiled for the pyramid's integral layout, with its raw hits of the last run.
#[derive(Debug, Clone)]
pub struct Scanner {
    cascade: Cascade,
    compiled: Compiled,
    raw: Vec<Rect>,
}

impl Scanner {
    /// A scanner for a loaded cascade (compiled on first use).
    pub fn new(cascade: Cascade) -> Self {
        Self {
            cascade,
            compiled: Compiled::default(),
            raw: Vec::new(),
        }
    }

    /// The cascade this scanner runs.
    pub fn cascade(&self) -> &Cascade {
        &self.cascade
    }

    /// Step 7 on the raw hits of the last call: grouped (or raw when `min_neighbors` is 0)
    /// and clipped to the `width` × `height` image.
    pub(crate) fn grouped(&self, width: usize, height: usize, min_neighbors: u32) -> Vec<Detection> {
        let groups = if min_neighbors > 0 {
            group_rectangles(&self.raw, min_neighbors.min(i32::MAX as u32) as i32, GROUP_EPS)
        } else {
            self.raw.iter().map(|&r| (r, 1)).collect()
        };
        // clipObjects: keep the part inside the image, drop empty boxes.
        let frame = Rect::new(0, 0, width as i32, height as i32);
        groups
            .into_iter()
            .filter_map(|(r, n)| {
                let c = r.intersect(&frame);
                (c.area() > 0).then_some(Detection { rect: c, neighbors: n })
            })
            .collect()
    }

    /// The raw (ungrouped) window hits of the last call, in input-image pixels.
    pub fn raw_hits(&self) -> &[Rect] {
        &self.raw
    }

    /// The raw hits, for the shared pyramid to fill.
    pub(crate) fn raw_mut(&mut self) -> &mut Vec<Rect> {
        &mut self.raw
    }
}

/// Step 1: the list of scales, exactly as `detectMultiScaleNoGrouping` builds it.
fn scales(cw: i32, ch: i32, iw: i32, ih: i32, p: &DetectParams) -> Vec<f32> {
    let (mut maxw, mut maxh) = (p.max_size.0 as i64, p.max_size.1 as i64);
    if maxw == 0 || maxh == 0 {
        maxw = iw as i64;
        maxh = ih as i64;
    }
    let (minw, minh) = (p.min_size.0 as i64, p.min_size.1 as i64);
    let mut all = Vec::new();
    let mut factor = 1.0f64;
    loop {
        let ww = (cw as f64 * factor).round_ties_even();
        let wh = (ch as f64 * factor).round_ties_even();
        if ww > iw as f64 || wh > ih as f64 || all.len() > 10_000 {
            break;
        }
        all.push(factor as f32);
        factor *= p.scale_factor;
    }
    let win = |s: f32| {
        (
            (cw as f32 * s).round_ties_even() as i64,
            (ch as f32 * s).round_ties_even() as i64,
        )
    };
    let mut out = Vec::new();
    for &s in &all {
        let (ww, wh) = win(s);
        if ww > maxw || wh > maxh {
            break;
        }
        if ww < minw || wh < minh {
            continue;
        }
        out.push(s);
    }
    if out.is_empty() && !all.is_empty() && p.min_size == p.max_size {
        let dist = |s: f32| {
            let (ww, wh) = win(s);
            ((minw - ww) * (minw - ww) + (minh - wh) * (minh - wh)) as f64
        };
        let mut best = 0;
        for i in 0..all.len() {
            if dist(all[best]) > dist(all[i]) {
                best = i;
            }
        }
        out.push(all[best]);
    }
    out
}

/// One pyramid level: the input resized by `1/scale` (shared by every cascade that uses it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Level {
    /// The scale factor of the level (f32, as OpenCV stores it).
    pub scale: f32,
    /// Level size, pixels.
    pub width: usize,
    /// Level size, pixels.
    pub height: usize,
    /// Scan step, pixels: 1 from scale 2 on, else 2.
    pub step: usize,
}

impl Level {
    /// The level of `scale` for a `width` × `height` input (steps 2 and 4).
    pub fn new(scale: f32, width: usize, height: usize) -> Self {
        Self {
            scale,
            width: (width as f32 / scale).round_ties_even() as usize,
            height: (height as f32 / scale).round_ties_even() as usize,
            step: if scale >= 2.0 { 1 } else { 2 },
        }
    }
}

/// The window positions one cascade scans on one level: top-left corners `x` in
/// `xa..=xb`, `y` in `ya..=yb`, all on the level's step grid (level pixels).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct WinRange {
    pub xa: usize,
    pub xb: usize,
    pub ya: usize,
    pub yb: usize,
}

impl Scanner {
    /// Step 1 for this cascade on a `width` × `height` image, after the input checks.
    pub(crate) fn scales_for(
        &self,
        width: usize,
        height: usize,
        params: &DetectParams,
    ) -> Result<Vec<f32>, DetectError> {
        if !(params.scale_factor.is_finite() && params.scale_factor > 1.0) {
            return Err(DetectError::BadScaleFactor(params.scale_factor));
        }
        let (cw, ch) = (self.cascade.width, self.cascade.height);
        if width < cw as usize || height < ch as usize {
            return Ok(Vec::new());
        }
        Ok(scales(cw, ch, width as i32, height as i32, params))
    }

    /// Compiles the feature offsets for an integral layout (no-op when unchanged).
    pub(crate) fn prepare(&mut self, stride: usize, tilted_offset: usize) {
        let tofs = if self.cascade.has_tilted { tilted_offset } else { 0 };
        if self.compiled.stride != stride || self.compiled.tilted_offset != tofs || self.compiled.span == 0 {
            self.compiled = Compiled::new(&self.cascade, stride, tofs);
        }
    }

    /// The window positions of level `l` whose boxes lie inside `region` (input pixels;
    /// `None` = the whole input), or `None` when there are none. The boxes are step 7's:
    /// `(round(x·scale), round(y·scale), round(W·scale), round(H·scale))`.
    pub(crate) fn window_range(&self, l: &Level, region: Option<Rect>) -> Option<WinRange> {
        let (cw, ch) = (self.cascade.width as usize, self.cascade.height as usize);
        let xs = (l.width + 1).checked_sub(cw)?; // positions 0..xs fit the level
        let ys = (l.height + 1).checked_sub(ch)?;
        if xs == 0 || ys == 0 {
            return None;
        }
        let last = |n: usize| (n - 1) / l.step * l.step;
        let Some(r) = region else {
            return Some(WinRange {
                xa: 0,
                xb: last(xs),
                ya: 0,
                yb: last(ys),
            });
        };
        let ww = (self.cascade.width as f32 * l.scale).round_ties_even() as i64;
        let wh = (self.cascade.height as f32 * l.scale).round_ties_even() as i64;
        let span = |n: usize, lo: i32, hi: i64, win: i64| {
            let mut out: Option<(usize, usize)> = None;
            for p in (0..n).step_by(l.step) {
                let b = (p as f32 * l.scale).round_ties_even() as i64;
                if b >= lo as i64 && b + win <= hi {
                    out = Some(out.map_or((p, p), |(a, _)| (a, p)));
                }
            }
            out
        };
        let (xa, xb) = span(xs, r.x, r.x as i64 + r.width as i64, ww)?;
        let (ya, yb) = span(ys, r.y, r.y as i64 + r.height as i64, wh)?;
        Some(WinRange { xa, xb, ya, yb })
    }

    /// The cascade's window size, pixels.
    pub(crate) fn window(&self) -> (usize, usize) {
        (self.cascade.width as usize, self.cascade.height as usize)
    }

    /// Steps 4–6 on level `l` for the windows `win`; `data`/`sq` are the level's integral
    /// tables (layout [`Scanner::prepare`]d) starting at level row `row0`. Hits are appended
    /// to `hits` in input pixels.
    ///
    /// OpenCV's scan skips the next x position after a window that fails the first stage, so
    /// whether the first window of `win` is scanned depends on the windows left of it. It is
    /// found without scanning them: going left from `xa`, count the windows whose result
    /// would be 0 (first stage failed) until one whose result is not 0 (or x = 0); the window
    /// after a non-zero one is always scanned, and each further 0 flips the answer.
    pub(crate) fn scan(&self, data: &[i32], sq: &[u64], row0: usize, l: &Level, win: WinRange, hits: &mut Vec<Rect>) {
        let c = &self.cascade;
        let k = &self.compiled;
        let (cw, ch) = (c.width as usize, c.height as usize);
        let ww = (c.width as f32 * l.scale).round_ties_even() as i32;
        let wh = (c.height as f32 * l.scale).round_ties_even() as i32;
        let area = ((cw - 2) * (ch - 2)) as f64;
        let step = l.step;
        // Result of the window at element p: 1 = passed, ≤ 0 = −(stage failed), −1 also flat.
        let eval = |p: usize, first_only: bool| -> i32 {
            match c.feature_type {
                FeatureType::Haar => {
                    // 5. Window normalisation.
                    let n = &k.norm;
                    let d = &data[p..];
                    let vs = rect_sum(d[n[0] as usize], d[n[1] as usize], d[n[2] as usize], d[n[3] as usize]);
                    let q = &sq[p..];
                    let vq =
                        (q[n[0] as usize] + q[n[3] as usize]).wrapping_sub(q[n[1] as usize] + q[n[2] as usize]) as u32;
                    let nf = area * vq as f64 - vs as f64 * vs as f64;
                    if nf > 0.0 {
                        let inv = (1.0 / nf.sqrt()) as f32;
                        if area * (inv as f64) < 0.1 {
                            // Panics only on a bug in the level geometry, never on input.
                            let d = &data[p..p + k.span];
                            if c.max_nodes_per_tree == 1 {
                                eval_stumps(c, k, d, inv, first_only)
                            } else {
                                eval_trees(c, k, d, inv, first_only)
                            }
                        } else {
                            -1
                        }
                    } else {
                        -1
                    }
                }
                FeatureType::Lbp => eval_lbp(c, k, &data[p..p + k.span], first_only),
            }
        };
        let _ = (cw, ch);
        let mut y = win.ya;
        while y <= win.yb {
            let base = (y - row0) * k.stride;
            // 4. Is the first window scanned? (see above)
            let mut x = win.xa;
            let mut zeros = 0usize;
            let mut p = x;
            while p >= step {
                p -= step;
                if eval(base + p, true) != 0 {
                    break;
                }
                zeros += 1;
            }
            if zeros % 2 == 1 {
                x += step;
            }
            while x <= win.xb {
                let result = eval(base + x, false);
                if result > 0 {
                    hits.push(Rect::new(
                        (x as f32 * l.scale).round_ties_even() as i32,
                        (y as f32 * l.scale).round_ties_even() as i32,
                        ww,
                        wh,
                    ));
                }
                if result == 0 {
                    x += step;
                }
                x += step;
            }
            y += step;
        }
    }
}

/// Steps 5–6 for a stump cascade: 1 if the window passes every stage, else −(failed stage).
#[inline]
fn eval_stumps(c: &Cascade, k: &Compiled, d: &[i32], inv: f32, first_only: bool) -> i32 {
    let mut first = 0;
    let n = if first_only {
        c.stages.len().min(1)
    } else {
        c.stages.len()
    };
    for (si, st) in c.stages[..n].iter().enumerate() {
        let mut sum = 0.0f64;
        for stump in &k.stumps[first..first + st.tree_count] {
            let v = stump.f.calc(d) * inv;
            sum += if v < stump.threshold { stump.left } else { stump.right } as f64;
        }
        if sum < st.threshold as f64 {
            return -(si as i32);
        }
        first += st.tree_count;
    }
    1
}

/// Steps 5–6 for a cascade of trees.
fn eval_trees(c: &Cascade, k: &Compiled, d: &[i32], inv: f32, first_only: bool) -> i32 {
    let n = if first_only {
        c.stages.len().min(1)
    } else {
        c.stages.len()
    };
    for (si, st) in c.stages[..n].iter().enumerate() {
        let mut sum = 0.0f64;
        for t in &c.trees[st.first_tree..st.first_tree + st.tree_count] {
            let mut idx = 0i32;
            loop {
                let n = &c.nodes[t.first_node + idx as usize];
                let v = k.haar[n.feature].calc(d) * inv;
                idx = if v < n.threshold { n.left } else { n.right };
                if idx <= 0 {
                    break;
                }
            }
            sum += c.leaves[t.first_leaf + (-idx) as usize] as f64;
        }
        if sum < st.threshold as f64 {
            return -(si as i32);
        }
    }
    1
}

/// Steps 5–6 for an LBP cascade (category stumps or trees).
fn eval_lbp(c: &Cascade, k: &Compiled, d: &[i32], first_only: bool) -> i32 {
    let ss = c.subset_size;
    let n = if first_only {
        c.stages.len().min(1)
    } else {
        c.stages.len()
    };
    for (si, st) in c.stages[..n].iter().enumerate() {
        let mut sum = 0.0f64;
        for t in &c.trees[st.first_tree..st.first_tree + st.tree_count] {
            let mut idx = 0i32;
            loop {
                let ni = t.first_node + idx as usize;
                let n = &c.nodes[ni];
                let code = k.lbp[n.feature].calc(d);
                let subset = &c.subsets[ni * ss..(ni + 1) * ss];
                let bit = subset[code >> 5] & (1 << (code & 31));
                idx = if bit != 0 { n.left } else { n.right };
                if idx <= 0 {
                    break;
                }
            }
            sum += c.leaves[t.first_leaf + (-idx) as usize] as f64;
        }
        if sum < st.threshold as f64 {
            return -(si as i32);
        }
    }
    1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_follow_opencv_rules() {
        let p = DetectParams::default();
        let s = scales(24, 24, 100, 100, &p);
        // 24·1.1^k ≤ 100 → k ≤ 14 (24·1.1^14 = 91.1, 24·1.1^15 = 100.3 → rounds to 100: fits)
        assert_eq!(s.len(), 16);
        assert_eq!(s[0], 1.0);
        let p = DetectParams {
            min_size: (40, 40),
            max_size: (40, 40),
            ..Default::default()
        };
        let s = scales(24, 24, 100, 100, &p);
        assert_eq!(s.len(), 1);
        assert_eq!((24.0 * s[0]).round(), 39.0); // the closest window to 40 (38.9 → 39)
    }
}
