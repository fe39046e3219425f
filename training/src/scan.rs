//! Negative windows from background images, as OpenCV traincascade's `NegReader` draws them
//! (every position and scale of every background, visited in a shuffled order, kept only when
//! the cascade trained so far wrongly accepts them — `updateTrainingSet`), with the detector's
//! own arithmetic (`src/detect/detector.rs` steps 1–6: pyramid levels by the exact bilinear
//! resize, integral images, the flat-window rejection), so every negative is a false alarm the
//! car would actually see.
//!
//! [`NegativePool`]: the pool is every `w` × `h` window at every pixel offset of every pyramid
//! level (scales `1, s, s², …` with `s` = the scale step) of every background, and of its
//! mirror image when `mirror` is on, and upside down (both again) when `upside_down` is on. A
//! *tile* is one (background, level, flip) triple. Each
//! stage visits the tiles in a new seeded order and each tile's windows in a seeded
//! pseudo-random permutation (`i ↦ (a·i + b) mod n`, `gcd(a, n) = 1`); a tile gives at most
//! its share of the stage's negatives per pass (`⌈2·num_neg·n_tile / n_pool⌉`, at least 1),
//! so the negatives spread over all backgrounds and scales; passes repeat (share doubled) until
//! `num_neg` are found or every window of the pool has been checked. Only then are the
//! negatives truly used up. A 320 × 240 frame holds ≈ 323 000 windows of 24 × 24 this way
//! (twice that mirrored), against ≈ 118 000 on the detector's grid (step 2 below scale 2).
//!
//! [`scan`] (the detector's own grid and step, a reservoir of `cap` hits per image) is kept for
//! measurements. Units: pixels.

use crate::features::{tilted_offset, SampleIntegral};
use crate::model::CompiledCascade;
use crate::samples::Background;
use rayon::prelude::*;
use rccar::detect::integral::Integrals;
use rccar::detect::resize::Resizer;
use rccar::detect::{Cascade, Rect};
use rccar::sim::rng::{mix, SplitMix64};

/// Windows overlapping an object box by at least this IoU are not negatives.
pub const AVOID_IOU: f64 = 0.3;

/// What scanning one image gave.
#[derive(Debug, Clone, Default)]
pub struct ScanResult {
    /// Windows the detector would evaluate (after the flat-window test).
    pub windows: u64,
    /// Windows the cascade accepted (outside the avoid boxes).
    pub hits: u64,
    /// Up to `cap` of the hits, `w` × `h` grey each.
    pub kept: Vec<Vec<u8>>,
}

/// The detector's scale list for a `cw` × `ch` window on an `iw` × `ih` image (no size limits).
pub fn scales(cw: i32, ch: i32, iw: i32, ih: i32, factor_step: f64) -> Vec<f32> {
    let mut out = Vec::new();
    let mut factor = 1.0f64;
    loop {
        let ww = (cw as f64 * factor).round_ties_even();
        let wh = (ch as f64 * factor).round_ties_even();
        if ww > iw as f64 || wh > ih as f64 || out.len() > 10_000 {
            break;
        }
        out.push(factor as f32);
        factor *= factor_step;
    }
    out
}

/// Scans `bg` with `cascade` (`None`: every window passes) for a `cw` × `ch` window.
pub fn scan(
    bg: &Background,
    cascade: Option<&Cascade>,
    cw: usize,
    ch: usize,
    scale_factor: f64,
    cap: usize,
    seed: u64,
) -> ScanResult {
    let (iw, ih) = (bg.img.width() as usize, bg.img.height() as usize);
    let mut res = ScanResult::default();
    if iw < cw || ih < ch || cw < 3 || ch < 3 {
        return res;
    }
    let mut rng = SplitMix64::new(seed);
    let stride = iw + 1;
    let rows = ih + 1;
    let tilted = cascade.is_some_and(|c| c.has_tilted);
    let tofs = if tilted { rows * stride } else { 0 };
    let compiled = cascade.map(|c| CompiledCascade::new(c, stride, tofs));
    let mut ii = Integrals::new();
    let mut rs = Resizer::new();
    let mut level = Vec::new();
    let area = ((cw - 2) * (ch - 2)) as f64;
    let norm = [
        stride + 1,
        stride + cw - 1,
        (ch - 1) * stride + 1,
        (ch - 1) * stride + cw - 1,
    ];
    for sc in scales(cw as i32, ch as i32, iw as i32, ih as i32, scale_factor) {
        // 1. The level and its integrals.
        let lw = (iw as f32 / sc).round_ties_even() as usize;
        let lh = (ih as f32 / sc).round_ties_even() as usize;
        let pix: &[u8] = if (lw, lh) == (iw, ih) {
            bg.img.as_raw()
        } else {
            level.resize(lw * lh, 0);
            rs.resize(bg.img.as_raw(), iw, ih, &mut level, lw, lh);
            &level
        };
        ii.compute(pix, lw, lh, stride, rows, tilted);
        let step = if sc >= 2.0 { 1 } else { 2 };
        let ww = (cw as f32 * sc).round_ties_even() as i32;
        let wh = (ch as f32 * sc).round_ties_even() as i32;
        let xs = (lw + 1).saturating_sub(cw);
        let ys = (lh + 1).saturating_sub(ch);
        let mut y = 0;
        while y < ys {
            let mut x = 0;
            while x < xs {
                // 2. Normalisation, as the detector.
                let p = y * stride + x;
                let result = window_result(&ii.data[p..], &ii.sqsum[p..], &norm, area, compiled.as_ref(), &mut res);
                if result > 0 {
                    // 3. A false alarm unless it is one of the objects.
                    let r = Rect::new(
                        (x as f32 * sc).round_ties_even() as i32,
                        (y as f32 * sc).round_ties_even() as i32,
                        ww,
                        wh,
                    );
                    if !bg.avoid.iter().any(|a| a.iou(&r) >= AVOID_IOU) {
                        res.hits += 1;
                        keep_hit(&mut res, &mut rng, cap, || {
                            let mut win = Vec::with_capacity(cw * ch);
                            for yy in y..y + ch {
                                win.extend_from_slice(&pix[yy * lw + x..yy * lw + x + cw]);
                            }
                            win
                        });
                    }
                }
                if result == 0 {
                    x += step;
                }
                x += step;
            }
            y += step;
        }
    }
    res
}

/// The cascade's answer on the window whose integrals start at `d` / `q` (`norm`: the
/// offsets of the variance rectangle's corners): −1 for a flat window the detector skips
/// (not counted), else the cascade's result (1 without a cascade), counted in `res.windows`.
fn window_result(
    d: &[i32],
    q: &[u64],
    norm: &[usize; 4],
    area: f64,
    compiled: Option<&CompiledCascade>,
    res: &mut ScanResult,
) -> i32 {
    let vs = d[norm[0]]
        .wrapping_sub(d[norm[1]])
        .wrapping_sub(d[norm[2]])
        .wrapping_add(d[norm[3]]);
    let vq = (q[norm[0]] + q[norm[3]]).wrapping_sub(q[norm[1]] + q[norm[2]]) as u32;
    let nf = area * vq as f64 - vs as f64 * vs as f64;
    let mut result = -1;
    if nf > 0.0 {
        let inv = (1.0 / nf.sqrt()) as f32;
        if area * (inv as f64) < 0.1 {
            res.windows += 1;
            result = match compiled {
                Some(c) => c.eval(d, inv),
                None => 1,
            };
        }
    }
    result
}

/// Reservoir sampling of `cap` windows: the `res.hits`-th hit (already counted) takes a free
/// slot, or replaces a kept one with probability `cap / hits`; `window` cuts it only then.
fn keep_hit(res: &mut ScanResult, rng: &mut SplitMix64, cap: usize, window: impl FnOnce() -> Vec<u8>) {
    let slot = if res.kept.len() < cap {
        Some(res.kept.len())
    } else {
        let j = (rng.next_u64() % res.hits) as usize;
        (j < cap).then_some(j)
    };
    if let Some(j) = slot {
        let win = window();
        if j == res.kept.len() {
            res.kept.push(win);
        } else {
            res.kept[j] = win;
        }
    }
}

/// One (background, pyramid level, flip) part of the negative pool.
#[derive(Debug, Clone, Copy)]
struct Tile {
    bg: u32,
    scale: f32,
    mirror: bool,
    upside_down: bool,
    lw: u32,
    lh: u32,
    /// Window positions: `(lw − w + 1)·(lh − h + 1)`.
    n: u64,
}

/// Every window of every background at every scale (and mirrored), to draw negatives from.
#[derive(Debug, Clone)]
pub struct NegativePool {
    tiles: Vec<Tile>,
    total: u64,
    w: usize,
    h: usize,
}

/// What one stage's draw from the pool gave.
#[derive(Debug, Clone, Default)]
pub struct Mined {
    /// The negatives (`w` × `h` grey each), at most `num_neg`.
    pub windows: Vec<Vec<u8>>,
    /// Windows checked (not flat: the detector would evaluate them).
    pub evaluated: u64,
    /// Of those, accepted by the cascade (outside the object boxes).
    pub accepted: u64,
    /// Whether every window of the pool was checked (the negatives are all there are).
    pub exhausted: bool,
    /// Passes over the tiles.
    pub passes: u32,
}

impl Mined {
    /// `accepted / evaluated`: the cascade's false-alarm rate per window so far.
    pub fn acceptance(&self) -> f64 {
        if self.evaluated == 0 {
            0.0
        } else {
            self.accepted as f64 / self.evaluated as f64
        }
    }
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Tiles processed per parallel batch (fixed, so results do not depend on the thread count).
const BATCH: usize = 16;

impl NegativePool {
    /// The pool of `w` × `h` windows over `bgs` with scale step `scale_step` (> 1).
    pub fn new(bgs: &[Background], w: usize, h: usize, scale_step: f64, mirror: bool) -> NegativePool {
        NegativePool::with_flips(bgs, w, h, scale_step, mirror, false)
    }

    /// [`NegativePool::new`], also with every background (and its mirror image) upside down
    /// when `upside_down` is on: twice the windows. Turned over, a photo's textures are still
    /// not the object, and a few hundred frames then last a cascade of 20 stages (`train`'s
    /// `--upside-down-negatives`, off by default: see docs/training.md).
    pub fn with_flips(
        bgs: &[Background],
        w: usize,
        h: usize,
        scale_step: f64,
        mirror: bool,
        upside_down: bool,
    ) -> NegativePool {
        let mut tiles = Vec::new();
        let mut total = 0;
        for (bi, bg) in bgs.iter().enumerate() {
            let (iw, ih) = (bg.img.width() as i32, bg.img.height() as i32);
            for sc in scales(w as i32, h as i32, iw, ih, scale_step.max(1.0001)) {
                let lw = (iw as f32 / sc).round_ties_even() as u32;
                let lh = (ih as f32 / sc).round_ties_even() as u32;
                if (lw as usize) < w || (lh as usize) < h {
                    continue;
                }
                let n = (lw as u64 - w as u64 + 1) * (lh as u64 - h as u64 + 1);
                for (m, u) in [(false, false), (true, false), (false, true), (true, true)] {
                    if (m && !mirror) || (u && !upside_down) {
                        continue;
                    }
                    tiles.push(Tile {
                        bg: bi as u32,
                        scale: sc,
                        mirror: m,
                        upside_down: u,
                        lw,
                        lh,
                        n,
                    });
                    total += n;
                }
            }
        }
        NegativePool { tiles, total, w, h }
    }

    /// Window positions in the pool (before the flat-window test).
    pub fn windows(&self) -> u64 {
        self.total
    }

    /// Draws up to `num_neg` windows that `cascade` (`None`: every window) accepts; see the
    /// module notes. Deterministic for a given `seed`, whatever the thread count.
    pub fn mine(&self, bgs: &[Background], cascade: Option<&Cascade>, num_neg: usize, seed: u64) -> Mined {
        let mut out = Mined::default();
        if self.tiles.is_empty() || num_neg == 0 {
            out.exhausted = true;
            return out;
        }
        // 1. Tile order and each tile's permutation for this stage.
        let mut rng = SplitMix64::new(mix(seed ^ 0x7115));
        let mut order: Vec<usize> = (0..self.tiles.len()).collect();
        for i in (1..order.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        let mut next = vec![0u64; self.tiles.len()];
        let mut perm = vec![(1u64, 0u64); self.tiles.len()];
        for (t, p) in self.tiles.iter().zip(perm.iter_mut()) {
            let mut a = (rng.next_u64() % t.n.max(1)).max(1) | 1;
            while gcd(a, t.n) != 1 {
                a += 1;
            }
            *p = (a % t.n.max(1), rng.next_u64() % t.n.max(1));
            if t.n == 1 {
                *p = (1, 0);
            }
        }
        // 2. Passes until enough, or every window checked.
        let mut share = 2.0 * num_neg as f64 / self.total.max(1) as f64;
        let mut live: Vec<usize> = order;
        while !live.is_empty() && out.windows.len() < num_neg {
            out.passes += 1;
            let mut still = Vec::new();
            for chunk in live.chunks(BATCH) {
                let res: Vec<(usize, TileDraw)> = chunk
                    .par_iter()
                    .map(|&ti| {
                        let t = &self.tiles[ti];
                        let cap = ((share * t.n as f64).ceil() as u64).max(1);
                        (ti, self.draw(&bgs[t.bg as usize], t, cascade, perm[ti], next[ti], cap))
                    })
                    .collect();
                for (ti, d) in res {
                    out.evaluated += d.evaluated;
                    out.accepted += d.kept.len() as u64;
                    next[ti] = d.next;
                    if d.next < self.tiles[ti].n {
                        still.push(ti);
                    }
                    for k in d.kept {
                        if out.windows.len() < num_neg {
                            out.windows.push(k);
                        }
                    }
                }
                if out.windows.len() >= num_neg {
                    break;
                }
            }
            if out.windows.len() >= num_neg {
                break;
            }
            live = still;
            share *= 2.0;
        }
        out.exhausted = out.windows.len() < num_neg;
        out
    }

    /// Checks the windows of one tile from permutation index `start` until `cap` are accepted.
    fn draw(
        &self,
        bg: &Background,
        t: &Tile,
        cascade: Option<&Cascade>,
        (a, b): (u64, u64),
        start: u64,
        cap: u64,
    ) -> TileDraw {
        let (cw, ch) = (self.w, self.h);
        let (iw, ih) = (bg.img.width() as usize, bg.img.height() as usize);
        let (lw, lh) = (t.lw as usize, t.lh as usize);
        let mut level = if (lw, lh) == (iw, ih) {
            bg.img.as_raw().clone()
        } else {
            let mut l = vec![0u8; lw * lh];
            Resizer::new().resize(bg.img.as_raw(), iw, ih, &mut l, lw, lh);
            l
        };
        if t.mirror {
            for row in level.chunks_mut(lw) {
                row.reverse();
            }
        }
        if t.upside_down {
            for y in 0..lh / 2 {
                let (top, bottom) = level.split_at_mut((lh - 1 - y) * lw);
                top[y * lw..(y + 1) * lw].swap_with_slice(&mut bottom[..lw]);
            }
        }
        let stride = lw + 1;
        let rows = lh + 1;
        let tilted = cascade.is_some_and(|c| c.has_tilted);
        let tofs = if tilted { rows * stride } else { 0 };
        let compiled = cascade.map(|c| CompiledCascade::new(c, stride, tofs));
        let mut ii = Integrals::new();
        ii.compute(&level, lw, lh, stride, rows, tilted);
        let area = ((cw - 2) * (ch - 2)) as f64;
        let norm = [
            stride + 1,
            stride + cw - 1,
            (ch - 1) * stride + 1,
            (ch - 1) * stride + cw - 1,
        ];
        let xs = (lw - cw + 1) as u64;
        let ww = (cw as f32 * t.scale).round_ties_even() as i32;
        let wh = (ch as f32 * t.scale).round_ties_even() as i32;
        let mut out = TileDraw {
            next: start,
            ..TileDraw::default()
        };
        while out.next < t.n && (out.kept.len() as u64) < cap {
            let k = ((a as u128 * out.next as u128 + b as u128) % t.n as u128) as u64;
            out.next += 1;
            let (x, y) = ((k % xs) as usize, (k / xs) as usize);
            let p = y * stride + x;
            let d = &ii.data[p..];
            let vs = d[norm[0]]
                .wrapping_sub(d[norm[1]])
                .wrapping_sub(d[norm[2]])
                .wrapping_add(d[norm[3]]);
            let q = &ii.sqsum[p..];
            let vq = (q[norm[0]] + q[norm[3]]).wrapping_sub(q[norm[1]] + q[norm[2]]) as u32;
            let nf = area * vq as f64 - vs as f64 * vs as f64;
            if nf <= 0.0 {
                continue;
            }
            let inv = (1.0 / nf.sqrt()) as f32;
            if area * (inv as f64) >= 0.1 {
                continue;
            }
            out.evaluated += 1;
            let pass = match &compiled {
                Some(c) => c.eval(d, inv) > 0,
                None => true,
            };
            if !pass {
                continue;
            }
            // A false alarm unless it is one of the objects (boxes in the unflipped frame).
            let x0 = if t.mirror { lw - cw - x } else { x };
            let y0 = if t.upside_down { lh - ch - y } else { y };
            let r = Rect::new(
                (x0 as f32 * t.scale).round_ties_even() as i32,
                (y0 as f32 * t.scale).round_ties_even() as i32,
                ww,
                wh,
            );
            if bg.avoid.iter().any(|a| a.iou(&r) >= AVOID_IOU) {
                continue;
            }
            let mut win = Vec::with_capacity(cw * ch);
            for yy in y..y + ch {
                win.extend_from_slice(&level[yy * lw + x..yy * lw + x + cw]);
            }
            out.kept.push(win);
        }
        out
    }
}

#[derive(Debug, Default)]
struct TileDraw {
    kept: Vec<Vec<u8>>,
    evaluated: u64,
    next: u64,
}

/// Whether a `w` × `h` sample passes `cascade` (`None`: yes) and the detector would look at it.
pub fn passes(s: &SampleIntegral, cascade: Option<&CompiledCascade>) -> bool {
    s.scannable && cascade.is_none_or(|c| c.eval(&s.data, s.inv) > 0)
}

/// A cascade compiled for one sample's tables (stride `w + 1`).
pub fn compile_for_samples(c: &Cascade, w: usize, h: usize) -> CompiledCascade {
    CompiledCascade::new(c, w + 1, tilted_offset(w, h))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::GrayImage;

    #[test]
    fn empty_cascade_hits_every_textured_window_at_the_detectors_grid() {
        // 40×30 noise: at scale 1 the grid is 0,2,..,24 × 0,2,..,14 for a 16×16 window.
        let mut rng = SplitMix64::new(3);
        let img = GrayImage::from_fn(40, 30, |_, _| image::Luma([(rng.next_u64() % 256) as u8]));
        let bg = Background {
            name: "noise".into(),
            img,
            avoid: vec![],
        };
        let r = scan(&bg, None, 16, 16, 1.1, 5, 1);
        let s = scales(16, 16, 40, 30, 1.1);
        assert!(s.len() >= 5);
        assert_eq!(r.kept.len(), 5);
        assert_eq!(r.hits, r.windows);
        assert!(r.windows >= 13 * 8, "{}", r.windows);
        // An avoid box covering everything leaves only small windows far from it.
        let bg2 = Background {
            avoid: vec![Rect::new(0, 0, 40, 30)],
            ..bg
        };
        let r2 = scan(&bg2, None, 16, 16, 1.1, 5, 1);
        assert!(r2.hits < r.hits);
    }

    #[test]
    fn pool_draws_every_window_once_and_says_when_it_is_used_up() {
        let mut rng = SplitMix64::new(5);
        let img = GrayImage::from_fn(30, 20, |_, _| image::Luma([(rng.next_u64() % 256) as u8]));
        let bg = Background {
            name: "noise".into(),
            img,
            avoid: vec![],
        };
        let bgs = [bg];
        // Scale 1 only (step 2 leaves no second level for 16×16 in 30×20): 15·5 = 75 windows.
        let pool = NegativePool::new(&bgs, 16, 16, 2.0, false);
        assert_eq!(pool.windows(), 75);
        let all = pool.mine(&bgs, None, 1000, 1);
        assert!(all.exhausted);
        assert_eq!(all.windows.len(), 75);
        let mut uniq = all.windows.clone();
        uniq.sort();
        uniq.dedup();
        assert_eq!(uniq.len(), 75, "each window once");
        // Mirrored: twice the pool; fewer than asked is not exhausted.
        let pool2 = NegativePool::new(&bgs, 16, 16, 2.0, true);
        assert_eq!(pool2.windows(), 150);
        let some = pool2.mine(&bgs, None, 40, 1);
        assert_eq!(some.windows.len(), 40);
        assert!(!some.exhausted);
        // Same seed, same draw.
        assert_eq!(pool2.mine(&bgs, None, 40, 1).windows, some.windows);
        // Mirrored and upside down: four times, every window once, the upside-down ones are
        // the original's rows reversed.
        let pool4 = NegativePool::with_flips(&bgs, 16, 16, 2.0, true, true);
        assert_eq!(pool4.windows(), 300);
        let all4 = pool4.mine(&bgs, None, 1000, 2);
        assert!(all4.exhausted);
        let mut u4 = all4.windows.clone();
        u4.sort();
        u4.dedup();
        assert_eq!(u4.len(), 300, "each window once (noise: no two alike)");
        let flipped: Vec<u8> = all.windows[0].chunks(16).rev().flatten().copied().collect();
        assert!(
            all4.windows.contains(&flipped),
            "upside-down copy of a window is in the pool"
        );
        // An object box in the unflipped frame keeps its upside-down windows out too.
        let boxed = [Background {
            avoid: vec![Rect::new(0, 0, 16, 16)],
            ..bgs[0].clone()
        }];
        let up = NegativePool::with_flips(&boxed, 16, 16, 2.0, false, true).mine(&boxed, None, 1000, 3);
        let px = |x: u32, y: u32| boxed[0].img.get_pixel(x, y)[0];
        let corner: Vec<u8> = (0..16).flat_map(|y| (0..16).map(move |x| px(x, y))).collect();
        let corner_up: Vec<u8> = corner.chunks(16).rev().flatten().copied().collect();
        assert!(!up.windows.contains(&corner) && !up.windows.contains(&corner_up));
        // (16 − x)(16 − y) ≥ 119 (IoU ≥ 0.3) for 9 + 9 + 8 + 7 + 7 = 40 of the 75 offsets.
        assert_eq!(
            up.windows.len(),
            2 * (75 - 40),
            "windows with IoU >= 0.3 with the box are out"
        );
        // The pool is several times the detector's 2-pixel grid.
        let big = Background {
            name: "n".into(),
            img: GrayImage::from_fn(320, 240, |x, y| image::Luma([((x * 7 + y * 13) % 256) as u8])),
            avoid: vec![],
        };
        let grid = scan(&big, None, 24, 24, 1.1, 1, 1).windows;
        let p = NegativePool::new(std::slice::from_ref(&big), 24, 24, 1.1, false).windows();
        assert!(p as f64 > 2.5 * grid as f64, "pool {p} grid {grid}");
    }
}
