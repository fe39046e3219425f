//! Multi-scale sliding-window detection with a boosted cascade, with the semantics of OpenCV
//! 4's `cv::CascadeClassifier::detectMultiScale` (cascadedetect.cpp), so that the same
//! cascade on the same grey image gives the same boxes.
//!
//! 1. **Scales.** `factor = 1, f, f², …` (f64) while the rounded window `round(W·factor)` ×
//!    `round(H·factor)` fits the image; scales whose window is below `min_size` are skipped,
//!    and the list stops at the first window above `max_size`. If `min_size == max_size` and
//!    no scale matched, the scale whose window is closest to it is used (OpenCV ≥ 3.4). Scales
//!    are then stored as f32, as OpenCV does.
//! 2. **Pyramid, not scaled features.** Each scale resizes the image to
//!    `round(w/scale)` × `round(h/scale)` with OpenCV's bit-exact bilinear resize and runs the
//!    cascade's unscaled features on it. This is what OpenCV does; it is the only way to get
//!    the same box set (scaled features round rectangle corners differently), and it is also
//!    the fast way: feature offsets are integers fixed once per image size.
//! 3. **Integral images** of each level (sum, squared sum, tilted if needed), with one row
//!    stride for all levels so the compiled feature offsets are shared.
//! 4. **Scan.** Step `1` if `scale ≥ 2`, else `2`, in x and y; a window whose first stage
//!    fails makes the scan skip the next x position too (OpenCV's `if (result == 0) x += step`).
//! 5. **Window normalisation** over the inner rectangle `(1, 1, W−2, H−2)`:
//!    `nf = √(area·Σi² − (Σi)²)` in f64, `k = (f32)(1/nf)`; the window is rejected if
//!    `nf ≤ 0` or `area·k ≥ 0.1` (a flat patch). A Haar feature's value is
//!    `(w0·s0 + w1·s1 [+ w2·s2])·k` in f32; stage sums accumulate the f32 leaves in f64.
//! 6. **Early exit**: the first stage whose sum is below its threshold rejects the window.
//! 7. **Boxes**: `(round(x·scale), round(y·scale), round(W·scale), round(H·scale))`, grouped
//!    by [`group_rectangles`] with `eps = 0.2` and clipped to the image.
//!
//! Units: pixels of the input image; `scale_factor` is the ratio between pyramid levels.

use super::cascade::{Cascade, FeatureType};
use super::group::{group_rectangles, Rect};
use super::integral::Integrals;
use super::resize::Resizer;
use image::GrayImage;

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

/// Scratch buffers of one worker: pyramid level, its integrals, resize tables.
#[derive(Debug, Clone, Default)]
struct Scratch {
    level: Vec<u8>,
    ii: Integrals,
    resizer: Resizer,
    hits: Vec<Rect>,
    /// Hits per level, in the order this worker scanned its levels (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    counts: Vec<usize>,
}

/// One pyramid level to scan.
#[derive(Debug, Clone, Copy)]
struct Level {
    scale: f32,
    width: usize,
    height: usize,
    step: usize,
}

/// A cascade ready to run on frames; keeps its buffers between calls, so steady-state
/// detection allocates little.
#[derive(Debug, Clone)]
pub struct Detector {
    cascade: Cascade,
    compiled: Compiled,
    scratch: Scratch,
    levels: Vec<Level>,
    raw: Vec<Rect>,
    /// One scratch set per worker thread (parallel mode), kept between calls.
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    pool: Vec<Scratch>,
    /// Worker of each level (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    assign: Vec<usize>,
}

impl Detector {
    /// A detector for a loaded cascade.
    pub fn new(cascade: Cascade) -> Self {
        Self {
            cascade,
            compiled: Compiled::default(),
            scratch: Scratch::default(),
            levels: Vec::new(),
            raw: Vec::new(),
            pool: Vec::new(),
            assign: Vec::new(),
        }
    }

    /// The cascade this detector runs.
    pub fn cascade(&self) -> &Cascade {
        &self.cascade
    }

    /// Detects objects in a grey image (OpenCV's `detectMultiScale` with `numDetections`).
    pub fn detect(&mut self, img: &GrayImage, params: &DetectParams) -> Result<Vec<Detection>, DetectError> {
        let (w, h) = img.dimensions();
        self.detect_gray(img.as_raw(), w as usize, h as usize, params)
    }

    /// Same as [`Detector::detect`] on a row-major `width` × `height` byte buffer.
    pub fn detect_gray(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        params: &DetectParams,
    ) -> Result<Vec<Detection>, DetectError> {
        self.detect_raw(img, width, height, params)?;
        let groups = if params.min_neighbors > 0 {
            group_rectangles(&self.raw, params.min_neighbors.min(i32::MAX as u32) as i32, GROUP_EPS)
        } else {
            self.raw.iter().map(|&r| (r, 1)).collect()
        };
        // clipObjects: keep the part inside the image, drop empty boxes.
        let frame = Rect::new(0, 0, width as i32, height as i32);
        Ok(groups
            .into_iter()
            .filter_map(|(r, n)| {
                let c = r.intersect(&frame);
                (c.area() > 0).then_some(Detection { rect: c, neighbors: n })
            })
            .collect())
    }

    /// The raw (ungrouped) window hits of the last call, in input-image pixels.
    pub fn raw_hits(&self) -> &[Rect] {
        &self.raw
    }

    /// Runs steps 1–6 and leaves the raw hits in [`Detector::raw_hits`].
    pub fn detect_raw(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        params: &DetectParams,
    ) -> Result<(), DetectError> {
        self.raw.clear();
        if !(params.scale_factor.is_finite() && params.scale_factor > 1.0) {
            return Err(DetectError::BadScaleFactor(params.scale_factor));
        }
        if width.saturating_mul(height) > 8 << 20 || width > 1 << 16 || height > 1 << 16 {
            return Err(DetectError::ImageTooLarge(width as u32, height as u32));
        }
        if img.len() < width * height {
            return Err(DetectError::BufferTooSmall {
                len: img.len(),
                width,
                height,
            });
        }
        let (cw, ch) = (self.cascade.width, self.cascade.height);
        if width < cw as usize || height < ch as usize {
            return Ok(());
        }
        // 1. Scales.
        let scales = scales(cw, ch, width as i32, height as i32, params);
        if scales.is_empty() {
            return Ok(());
        }
        self.levels.clear();
        for &sc in &scales {
            self.levels.push(Level {
                scale: sc,
                width: (width as f32 / sc).round_ties_even() as usize,
                height: (height as f32 / sc).round_ties_even() as usize,
                step: if sc >= 2.0 { 1 } else { 2 },
            });
        }
        // 3. One layout for all levels: the stride and row count of the largest.
        let stride = self.levels.iter().map(|l| l.width + 1).max().unwrap_or(1);
        let rows = self.levels.iter().map(|l| l.height + 1).max().unwrap_or(1);
        let tofs = if self.cascade.has_tilted { rows * stride } else { 0 };
        if self.compiled.stride != stride || self.compiled.tilted_offset != tofs || self.compiled.span == 0 {
            self.compiled = Compiled::new(&self.cascade, stride, tofs);
        }
        let job = Job {
            cascade: &self.cascade,
            compiled: &self.compiled,
            img,
            width,
            height,
            rows,
        };
        #[cfg(feature = "parallel")]
        if params.parallel && self.levels.len() > 1 && rayon::current_num_threads() > 1 {
            use rayon::prelude::*;
            // Levels go to workers largest first, each to the least loaded worker (by pixel
            // count), so the workers finish together; each worker keeps its buffers in `pool`.
            let t = rayon::current_num_threads().min(self.levels.len());
            if self.pool.len() < t {
                self.pool.resize_with(t, Scratch::default);
            }
            let mut load = [0usize; 64];
            let t = t.min(load.len());
            self.assign.clear();
            for l in &self.levels {
                let g = (0..t).min_by_key(|&g| load[g]).unwrap_or(0);
                load[g] += l.width * l.height;
                self.assign.push(g);
            }
            let (levels, assign) = (&self.levels, &self.assign);
            self.pool[..t].par_iter_mut().enumerate().for_each(|(g, s)| {
                s.hits.clear();
                s.counts.clear();
                for (l, _) in levels.iter().zip(assign).filter(|(_, &a)| a == g) {
                    let before = s.hits.len();
                    job.run_level(l, s);
                    s.counts.push(s.hits.len() - before);
                }
            });
            // Hits in level order, as the sequential scan gives them.
            let mut next = [(0usize, 0usize); 64]; // per worker: (count index, hit index)
            for &g in &self.assign {
                let s = &self.pool[g];
                let (ci, hi) = next[g];
                let n = s.counts[ci];
                self.raw.extend_from_slice(&s.hits[hi..hi + n]);
                next[g] = (ci + 1, hi + n);
            }
            return Ok(());
        }
        for l in &self.levels {
            job.run_level(l, &mut self.scratch);
            self.raw.extend_from_slice(&self.scratch.hits);
            self.scratch.hits.clear();
        }
        Ok(())
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

/// Everything a worker needs to scan levels (shared, read-only).
#[derive(Clone, Copy)]
struct Job<'a> {
    cascade: &'a Cascade,
    compiled: &'a Compiled,
    img: &'a [u8],
    width: usize,
    height: usize,
    rows: usize,
}

impl Job<'_> {
    /// Steps 2–6 for one pyramid level; hits are appended to `s.hits`.
    fn run_level(&self, l: &Level, s: &mut Scratch) {
        let c = self.cascade;
        let k = self.compiled;
        let (cw, ch) = (c.width as usize, c.height as usize);
        // 2. The pyramid level.
        let level: &[u8] = if (l.width, l.height) == (self.width, self.height) {
            self.img
        } else {
            s.level.resize(l.width * l.height, 0);
            s.resizer
                .resize(self.img, self.width, self.height, &mut s.level, l.width, l.height);
            &s.level
        };
        // 3. Its integral images.
        s.ii.compute(level, l.width, l.height, k.stride, self.rows, c.has_tilted);
        // 4. Scan.
        let ww = (c.width as f32 * l.scale).round_ties_even() as i32;
        let wh = (c.height as f32 * l.scale).round_ties_even() as i32;
        let xs = (l.width + 1).saturating_sub(cw);
        let ys = (l.height + 1).saturating_sub(ch);
        let data = &s.ii.data[..];
        let sq = &s.ii.sqsum[..];
        let area = ((cw - 2) * (ch - 2)) as f64;
        let mut y = 0;
        while y < ys {
            let mut x = 0;
            while x < xs {
                let p = y * k.stride + x;
                let result = match c.feature_type {
                    FeatureType::Haar => {
                        // 5. Window normalisation.
                        let n = &k.norm;
                        let d = &data[p..];
                        let vs = rect_sum(d[n[0] as usize], d[n[1] as usize], d[n[2] as usize], d[n[3] as usize]);
                        let q = &sq[p..];
                        let vq = (q[n[0] as usize] + q[n[3] as usize]).wrapping_sub(q[n[1] as usize] + q[n[2] as usize])
                            as u32;
                        let nf = area * vq as f64 - vs as f64 * vs as f64;
                        if nf > 0.0 {
                            let inv = (1.0 / nf.sqrt()) as f32;
                            if area * (inv as f64) < 0.1 {
                                // Panics only on a bug in the level geometry, never on input.
                                let d = &data[p..p + k.span];
                                if c.max_nodes_per_tree == 1 {
                                    eval_stumps(c, k, d, inv)
                                } else {
                                    eval_trees(c, k, d, inv)
                                }
                            } else {
                                -1
                            }
                        } else {
                            -1
                        }
                    }
                    FeatureType::Lbp => eval_lbp(c, k, &data[p..p + k.span]),
                };
                if result > 0 {
                    s.hits.push(Rect::new(
                        (x as f32 * l.scale).round_ties_even() as i32,
                        (y as f32 * l.scale).round_ties_even() as i32,
                        ww,
                        wh,
                    ));
                }
                if result == 0 {
                    x += l.step;
                }
                x += l.step;
            }
            y += l.step;
        }
    }
}

/// Steps 5–6 for a stump cascade: 1 if the window passes every stage, else −(failed stage).
#[inline]
fn eval_stumps(c: &Cascade, k: &Compiled, d: &[i32], inv: f32) -> i32 {
    let mut first = 0;
    for (si, st) in c.stages.iter().enumerate() {
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
fn eval_trees(c: &Cascade, k: &Compiled, d: &[i32], inv: f32) -> i32 {
    for (si, st) in c.stages.iter().enumerate() {
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
fn eval_lbp(c: &Cascade, k: &Compiled, d: &[i32]) -> i32 {
    let ss = c.subset_size;
    for (si, st) in c.stages.iter().enumerate() {
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

    #[test]
    fn bad_scale_factor_is_an_error() {
        let c = Cascade::from_xml_str(
            r#"<opencv_storage><cascade><stageType>BOOST</stageType><featureType>HAAR</featureType>
            <height>4</height><width>4</width><featureParams><maxCatCount>0</maxCatCount></featureParams>
            <stages><_><stageThreshold>0</stageThreshold><weakClassifiers><_><internalNodes>0 -1 0 0</internalNodes>
            <leafValues>1 1</leafValues></_></weakClassifiers></_></stages>
            <features><_><rects><_>0 0 4 4 1.</_></rects></_></features></cascade></opencv_storage>"#,
            "t",
        )
        .unwrap();
        let mut d = Detector::new(c);
        let img = GrayImage::new(10, 10);
        let p = DetectParams {
            scale_factor: 1.0,
            ..Default::default()
        };
        assert_eq!(d.detect(&img, &p), Err(DetectError::BadScaleFactor(1.0)));
        // A flat image has zero variance everywhere: no window passes.
        assert_eq!(d.detect(&img, &DetectParams::default()), Ok(vec![]));
        // An image smaller than the window: nothing, no error.
        assert_eq!(d.detect(&GrayImage::new(3, 3), &DetectParams::default()), Ok(vec![]));
        assert_eq!(d.detect(&GrayImage::new(0, 0), &DetectParams::default()), Ok(vec![]));
    }
}
