//! Hard-negative mining: scans background images with the cascade trained so far, exactly as
//! the detector scans a frame (`src/detect/detector.rs` steps 1–6: scales `1, s, s², …`, pyramid
//! levels by the exact bilinear resize, step 2 below scale 2 and 1 from it, the skip after a
//! first-stage rejection, the flat-window rejection), and keeps the windows it wrongly
//! accepts. This is OpenCV traincascade's `updateTrainingSet` for negatives (which re-reads
//! `bg.txt` until it has `numNeg` windows the current cascade passes), with the detector's own
//! window grid, so every negative is a false alarm the car would actually see.
//!
//! Per image at most `cap` hits are kept, drawn uniformly (reservoir sampling, seeded), so the
//! negatives spread over many images. Units: pixels.

use crate::features::{tilted_offset, SampleIntegral};
use crate::model::CompiledCascade;
use crate::samples::Background;
use rccar::detect::integral::Integrals;
use rccar::detect::resize::Resizer;
use rccar::detect::{Cascade, Rect};
use rccar::sim::rng::SplitMix64;

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
                let d = &ii.data[p..];
                let vs = d[norm[0]]
                    .wrapping_sub(d[norm[1]])
                    .wrapping_sub(d[norm[2]])
                    .wrapping_add(d[norm[3]]);
                let q = &ii.sqsum[p..];
                let vq = (q[norm[0]] + q[norm[3]]).wrapping_sub(q[norm[1]] + q[norm[2]]) as u32;
                let nf = area * vq as f64 - vs as f64 * vs as f64;
                let mut result = -1;
                if nf > 0.0 {
                    let inv = (1.0 / nf.sqrt()) as f32;
                    if area * (inv as f64) < 0.1 {
                        res.windows += 1;
                        result = match &compiled {
                            Some(c) => c.eval(d, inv),
                            None => 1,
                        };
                    }
                }
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
                        // Reservoir sampling of `cap` windows.
                        let slot = if res.kept.len() < cap {
                            Some(res.kept.len())
                        } else {
                            let j = (rng.next_u64() % res.hits) as usize;
                            (j < cap).then_some(j)
                        };
                        if let Some(j) = slot {
                            let mut win = Vec::with_capacity(cw * ch);
                            for yy in y..y + ch {
                                win.extend_from_slice(&pix[yy * lw + x..yy * lw + x + cw]);
                            }
                            if j == res.kept.len() {
                                res.kept.push(win);
                            } else {
                                res.kept[j] = win;
                            }
                        }
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
}
