//! One image pyramid for several cascades (issue 13): each frame is resized and integrated
//! once per scale, and every cascade that searches that scale scans the same level.
//!
//! OpenCV's `detectMultiScale` builds level `k` as the input resized to
//! `round(w/s_k)` × `round(h/s_k)` with `s_k = (f32)(f^k)` (Viola & Jones 2001, Sec. 4: the
//! detector is scanned across scales and locations). A level therefore depends only on its
//! scale, not on the cascade: cascades with different window sizes (16×16, 8×20, 20×16) and
//! different size limits use different *sets* of scales of the same sequence, and where two
//! sets meet they need the same pixels and the same integral images. So:
//!
//! 1. **Plan** (once per frame size / parameter set): every cascade's scale list (step 1 of
//!    `detector.rs`, with its own min/max size), and per scale the window positions whose boxes
//!    lie in the cascade's *region* of the frame ([`Scanner::window_range`]). The level is
//!    needed only in the rows those windows cover (`row0..row1`) and only left of the last
//!    window's right edge (`0..cols`).
//! 2. **Build** each needed level once: that part of the bit-exact resize
//!    ([`Resizer::resize_part`]) and its integral images (sum, squared sum, tilted when any
//!    cascade has tilted features), all levels in one row stride so every cascade's feature
//!    offsets are compiled once.
//! 3. **Scan** every cascade's windows on it ([`Scanner::scan`]); raw hits per cascade stay in
//!    ascending scale order, as OpenCV produces them, so grouping gives OpenCV's boxes.
//!
//! In parallel (feature `parallel`, [`DetectParams::parallel`]), levels costing more than an
//! eighth of the frame's work (two threads) are cut into bands of window rows, each built and
//! scanned like a level of its own, and rayon's threads take plans, costliest first, as each
//! becomes free: a thread that ran the lane stage beside the detector (src/pipeline.rs) joins
//! in when it is done instead of being handed half the levels up front. Hits are put back in
//! plan order, so the raw hits are the sequential ones, in order.
//!
//! With no region (the whole frame) a cascade's raw hits are exactly those of its own
//! `detectMultiScale`; with a region, exactly the subset whose boxes lie inside it (the scan
//! reproduces OpenCV's skip-after-a-failed-first-stage chain at the region's left edge).
//! Units: pixels.

use super::scan::{DetectError, DetectParams, Level, Scanner, WinRange};
use super::group::Rect;
use super::integral::Integrals;
use super::resize::Resizer;
use std::ops::Range;

/// Where the bottom edge of a box of each width may lie, frame rows: entry `w` is the range
/// `lo..=hi` of bottom edges (`y + height`) allowed for a `w` pixels wide box; a width
/// past the end, or an empty entry, is never searched. Made from the ground-plane geometry
/// (an object of known size and contact height seen at a distance in a known range, see
/// `crate::pipeline::detect_limits`): a window whose box is too high or too low in the frame
/// for its size cannot be such an object, so it is not scanned.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RowBand {
    /// Per box width (pixels): the bottom edges `lo..=hi` geometry allows.
    pub by_width: Vec<(i32, i32)>,
    /// Widening of that range on either side, as a fraction of the box height.
    pub slack: f64,
    /// Widening on either side, pixels (added to `slack`'s).
    pub slack_px: f64,
}

impl RowBand {
    /// The allowed bottom edges of a `width` × `height` pixels box, widened by the slack;
    /// `None` when there are none.
    pub fn bottoms(&self, width: usize, height: usize) -> Option<(i32, i32)> {
        let (lo, hi) = self.by_width.get(width).copied().filter(|&(lo, hi)| hi >= lo)?;
        let m = (self.slack * height as f64 + self.slack_px).ceil() as i32;
        Some((lo - m, hi + m))
    }
}

/// Scratch buffers of one worker: the level crop, its integrals, resize tables, hits.
#[derive(Debug, Clone, Default)]
struct Scratch {
    level: Vec<u8>,
    ii: Integrals,
    resizer: Resizer,
    /// Hits of this worker's scan jobs (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    hits: Vec<Rect>,
    /// Hits per scan job, in the order this worker ran them (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    counts: Vec<usize>,
    /// The plans this worker ran: (plan, its first count, its first hit) (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    done: Vec<(usize, usize, usize)>,
}

/// One level to build and the cascades to scan on it.
#[derive(Debug, Clone)]
struct Plan {
    level: Level,
    /// Level rows built.
    row0: usize,
    row1: usize,
    /// Level columns built (from 0).
    cols: usize,
    /// (detector index, its windows).
    jobs: Vec<(usize, WinRange)>,
}

impl Plan {
    /// Estimated work: the level pixels built, once per cascade scanning them and once to
    /// build them.
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    fn cost(&self) -> usize {
        self.cols * (self.row1 - self.row0) * (1 + self.jobs.len())
    }
}

/// What a plan was made for (re-planned when any of it changes).
#[derive(Debug, Clone, Default, PartialEq)]
struct Key {
    width: usize,
    height: usize,
    params: Vec<DetectParams>,
    regions: Vec<Option<Rect>>,
    windows: Vec<(usize, usize)>,
    bands: Vec<Option<RowBand>>,
}

/// A pyramid shared by several detectors; keeps its plan and buffers between frames.
#[derive(Debug, Clone, Default)]
pub struct Pyramid {
    key: Option<Key>,
    plans: Vec<Plan>,
    stride: usize,
    rows: usize,
    tilted: bool,
    scratch: Scratch,
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    pool: Vec<Scratch>,
    /// The plans by cost, costliest first (made with the plan; parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    order: Vec<usize>,
    /// Per plan: the worker that ran it, and where its counts and hits start there
    /// (parallel mode).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    placed: Vec<(usize, usize, usize)>,
    /// Per detector: the row band of its boxes (none = the region only).
    bands: Vec<Option<RowBand>>,
}

fn check_size(width: usize, height: usize) -> Result<(), DetectError> {
    if width.saturating_mul(height) > 8 << 20 || width > 1 << 16 || height > 1 << 16 {
        return Err(DetectError::ImageTooLarge(width as u32, height as u32));
    }
    Ok(())
}

impl Pyramid {
    /// An empty pyramid; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Limits detector `i`'s boxes to `bands[i]` (within its region; missing or `None` = no
    /// limit). Re-plans on the next call.
    pub(crate) fn set_bands(&mut self, bands: Vec<Option<RowBand>>) {
        if bands != self.bands {
            self.bands = bands;
            self.key = None;
        }
    }

    /// Step 1: plans the levels for `dets` on a `width` × `height` input (cached).
    pub(crate) fn plan(
        &mut self,
        width: usize,
        height: usize,
        dets: &[Scanner],
        params: &[DetectParams],
        regions: &[Option<Rect>],
    ) -> Result<(), DetectError> {
        assert!(
            dets.len() == params.len() && dets.len() == regions.len(),
            "one parameter set and region per detector"
        );
        check_size(width, height)?;
        let same = self.key.as_ref().is_some_and(|k| {
            k.width == width
                && k.height == height
                && k.params == params
                && k.regions == regions
                && k.windows.iter().copied().eq(dets.iter().map(Scanner::window))
        });
        if same {
            return Ok(());
        }
        self.key = None;
        self.plans.clear();
        for (i, d) in dets.iter().enumerate() {
            let scales = d.scales_for(width, height, &params[i])?;
            // Not clipped to the frame: OpenCV's rounded boxes may reach a pixel past it, and a
            // region covering the frame must keep them as no region does.
            let region = regions[i];
            if region.is_some_and(|r| r.width <= 0 || r.height <= 0) {
                continue;
            }
            let band = self.bands.get(i).and_then(|b| b.as_ref());
            for sc in scales {
                let level = Level::new(sc, width, height);
                let region = match band {
                    None => region,
                    Some(b) => {
                        // Boxes whose bottom edge lies in the band for their width.
                        let (cw, ch) = d.window();
                        let ww = (cw as f32 * sc).round_ties_even() as usize;
                        let wh = (ch as f32 * sc).round_ties_even() as i32;
                        let Some((lo, hi)) = b.bottoms(ww, wh as usize) else {
                            continue;
                        };
                        let r = region.unwrap_or(Rect::new(0, 0, width as i32 + 1, height as i32 + 1));
                        let (y0, y1) = (r.y.max(lo - wh), (r.y + r.height).min(hi));
                        if y1 - y0 < wh {
                            continue;
                        }
                        Some(Rect::new(r.x, y0, r.width, y1 - y0))
                    }
                };
                let Some(win) = d.window_range(&level, region) else {
                    continue;
                };
                let (cw, ch) = d.window();
                let (r0, r1, c1) = (win.ya, win.yb + ch, win.xb + cw);
                match self.plans.iter_mut().find(|p| p.level.scale == sc) {
                    Some(p) => {
                        p.row0 = p.row0.min(r0);
                        p.row1 = p.row1.max(r1);
                        p.cols = p.cols.max(c1);
                        p.jobs.push((i, win));
                    }
                    None => self.plans.push(Plan {
                        level,
                        row0: r0,
                        row1: r1,
                        cols: c1,
                        jobs: vec![(i, win)],
                    }),
                }
            }
        }
        self.plans.sort_by(|a, b| a.level.scale.total_cmp(&b.level.scale));
        // With the levels spread over threads, the large ones in bands (sequential runs keep
        // whole levels: the reference the parallel one is tested against).
        #[cfg(feature = "parallel")]
        if params.iter().any(|p| p.parallel) && rayon::current_num_threads() > 1 {
            self.split_large(dets, 4 * rayon::current_num_threads());
        }
        // The order threads take the plans in: costliest first (made once per plan).
        self.order.clear();
        self.order.extend(0..self.plans.len());
        let plans = &self.plans;
        self.order.sort_by_key(|&k| std::cmp::Reverse(plans[k].cost()));
        // 2. One layout for all levels: the stride and row count of the largest.
        self.stride = self.plans.iter().map(|p| p.level.width + 1).max().unwrap_or(1);
        self.rows = self.plans.iter().map(|p| p.level.height + 1).max().unwrap_or(1);
        self.tilted = self
            .plans
            .iter()
            .flat_map(|p| &p.jobs)
            .any(|&(i, _)| dets[i].cascade().has_tilted);
        self.key = Some(Key {
            width,
            height,
            params: params.to_vec(),
            regions: regions.to_vec(),
            windows: dets.iter().map(Scanner::window).collect(),
            bands: self.bands.clone(),
        });
        Ok(())
    }

    /// Splits every plan costing more than `1/parts` of all of them into bands of window rows,
    /// so that the workers of [`Pyramid::run`] share the large levels instead of one worker
    /// scanning the whole scale-1 level while the others wait. A band is built like a plan
    /// (its rows plus a window's height below); rows of windows are independent (OpenCV's own
    /// `detectMultiScale` splits them into stripes for its threads), and the bands of a level
    /// follow each other in the plan list, so each cascade's hits keep their order.
    #[cfg(feature = "parallel")]
    fn split_large(&mut self, dets: &[Scanner], parts: usize) {
        let total: usize = self.plans.iter().map(Plan::cost).sum();
        let limit = (total / parts.max(1)).max(1);
        let mut out = Vec::with_capacity(self.plans.len() + parts);
        for p in self.plans.drain(..) {
            let n = p.cost().div_ceil(limit);
            let (y0, y1) = (
                p.jobs.iter().map(|j| j.1.ya).min().unwrap_or(0),
                p.jobs.iter().map(|j| j.1.yb).max().unwrap_or(0),
            );
            let step = p.level.step.max(1);
            if n < 2 || (y1 - y0) / step < 2 * n {
                out.push(p);
                continue;
            }
            // Band b scans the window rows y with cut[b] <= y < cut[b + 1].
            let cuts: Vec<usize> = (0..=n).map(|b| y0 + (y1 + 1 - y0) * b / n).collect();
            for b in 0..n {
                let (lo, hi) = (cuts[b], cuts[b + 1]);
                let mut band = Plan {
                    level: p.level,
                    row0: usize::MAX,
                    row1: 0,
                    cols: p.cols,
                    jobs: Vec::with_capacity(p.jobs.len()),
                };
                for &(i, w) in &p.jobs {
                    // The job's first row at or after `lo`, and its last before `hi`.
                    let first = if lo <= w.ya { w.ya } else { w.ya + (lo - w.ya).div_ceil(step) * step };
                    if hi <= w.ya || first >= hi || first > w.yb {
                        continue;
                    }
                    let last = (w.ya + (hi - 1 - w.ya) / step * step).min(w.yb);
                    let ch = dets[i].window().1;
                    band.row0 = band.row0.min(first);
                    band.row1 = band.row1.max(last + ch);
                    band.jobs.push((i, WinRange { ya: first, yb: last, ..w }));
                }
                if !band.jobs.is_empty() {
                    out.push(band);
                }
            }
        }
        self.plans = out;
    }

    /// The input rows the planned levels read, as sorted, disjoint half-open ranges (after
    /// [`Pyramid::plan`]; empty when nothing is scanned).
    pub(crate) fn source_rows(&self) -> Vec<Range<usize>> {
        let Some(key) = &self.key else {
            return Vec::new();
        };
        let mut spans: Vec<Range<usize>> = self
            .plans
            .iter()
            .map(|p| Resizer::source_rows(key.height, p.level.height, p.row0..p.row1))
            .filter(|r| !r.is_empty())
            .collect();
        spans.sort_by_key(|r| r.start);
        let mut out: Vec<Range<usize>> = Vec::with_capacity(spans.len());
        for r in spans {
            match out.last_mut() {
                Some(l) if r.start <= l.end => l.end = l.end.max(r.end),
                _ => out.push(r),
            }
        }
        out
    }

    /// Steps 1–3 for every detector on the row-major `width` × `height` image `img`, with
    /// detector `i`'s options `params[i]` and region `regions[i]` (input pixels; `None` = the
    /// whole image). Each detector's raw hits are left in [`Scanner::raw_hits`].
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        dets: &mut [Scanner],
        params: &[DetectParams],
        regions: &[Option<Rect>],
        parallel: bool,
    ) -> Result<(), DetectError> {
        for d in dets.iter_mut() {
            d.raw_mut().clear();
        }
        check_size(width, height)?;
        if img.len() < width * height {
            return Err(DetectError::BufferTooSmall {
                len: img.len(),
                width,
                height,
            });
        }
        self.plan(width, height, dets, params, regions)?;
        if self.plans.is_empty() {
            return Ok(());
        }
        let tofs = if self.tilted { self.rows * self.stride } else { 0 };
        for d in dets.iter_mut() {
            d.prepare(self.stride, tofs);
        }
        let ctx = Ctx {
            img,
            width,
            height,
            stride: self.stride,
            rows: self.rows,
            tilted: self.tilted,
        };
        #[cfg(feature = "parallel")]
        if parallel && self.plans.len() > 1 && rayon::current_num_threads() > 1 {
            self.run_parallel(&ctx, dets);
            return Ok(());
        }
        let _ = parallel;
        let s = &mut self.scratch;
        for p in &self.plans {
            ctx.build(p, s);
            for &(i, win) in &p.jobs {
                let mut hits = std::mem::take(dets[i].raw_mut());
                dets[i].scan(&s.ii.data, &s.ii.sqsum, p.row0, &p.level, win, &mut hits);
                *dets[i].raw_mut() = hits;
            }
        }
        Ok(())
    }

    /// Plans (levels, or bands of the large ones) handed to rayon's threads as each becomes
    /// free, the costliest first (a worker that draws cheap plans takes more of them); raw
    /// hits are then put back in plan order, as the sequential scan gives them.
    #[cfg(feature = "parallel")]
    fn run_parallel(&mut self, ctx: &Ctx<'_>, dets: &mut [Scanner]) {
        use rayon::prelude::*;
        use std::sync::atomic::{AtomicUsize, Ordering};
        let t = rayon::current_num_threads().min(self.plans.len()).min(64);
        if self.pool.len() < t {
            self.pool.resize_with(t, Scratch::default);
        }
        let (plans, order, next) = (&self.plans, &self.order, AtomicUsize::new(0));
        let shared: &[Scanner] = dets;
        self.pool[..t].par_iter_mut().for_each(|s| {
            s.hits.clear();
            s.counts.clear();
            s.done.clear();
            loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(&pi) = order.get(k) else { break };
                let p = &plans[pi];
                s.done.push((pi, s.counts.len(), s.hits.len()));
                ctx.build(p, s);
                for &(i, win) in &p.jobs {
                    let before = s.hits.len();
                    let mut hits = std::mem::take(&mut s.hits);
                    shared[i].scan(&s.ii.data, &s.ii.sqsum, p.row0, &p.level, win, &mut hits);
                    s.hits = hits;
                    s.counts.push(s.hits.len() - before);
                }
            }
        });
        // Hits in plan order: where each plan's counts and hits are (worker, count, hit).
        self.placed.clear();
        self.placed.resize(self.plans.len(), (0, 0, 0));
        for (g, s) in self.pool[..t].iter().enumerate() {
            for &(pi, ci, hi) in &s.done {
                self.placed[pi] = (g, ci, hi);
            }
        }
        for (p, &(g, mut ci, mut hi)) in self.plans.iter().zip(&self.placed) {
            let s = &self.pool[g];
            for &(i, _) in &p.jobs {
                let n = s.counts[ci];
                dets[i].raw_mut().extend_from_slice(&s.hits[hi..hi + n]);
                (ci, hi) = (ci + 1, hi + n);
            }
        }
    }
}

/// The frame and layout every worker builds its levels from (read-only).
struct Ctx<'a> {
    img: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
    rows: usize,
    tilted: bool,
}

impl Ctx<'_> {
    /// Step 2 for one level: its planned part, resized and integrated into `s.ii`.
    fn build(&self, p: &Plan, s: &mut Scratch) {
        let l = &p.level;
        let n = p.row1 - p.row0;
        if (l.width, l.height) == (self.width, self.height) {
            // Scale 1: the input itself.
            s.ii.compute_strided(
                &self.img[p.row0 * self.width..],
                self.width,
                p.cols,
                n,
                self.stride,
                self.rows,
                self.tilted,
            );
        } else {
            s.level.resize(p.cols * n, 0);
            s.resizer.resize_part(
                self.img,
                self.width,
                self.height,
                &mut s.level,
                l.width,
                l.height,
                p.row0..p.row1,
                p.cols,
            );
            s.ii.compute_strided(&s.level, p.cols, p.cols, n, self.stride, self.rows, self.tilted);
        }
    }
}
