//! The Haar feature pool of a training window, as OpenCV's `CvHaarEvaluator::generateFeatures`
//! (opencv_traincascade, `haarfeatures.cpp`) builds it, and feature values on samples computed
//! with exactly the detector's arithmetic (`src/detect/detector.rs`: `(w0·s0 + w1·s1 [+ w2·s2])`
//! in f32, times `(f32)(1/nf)` with `nf = √(area·Σi² − (Σi)²)` over the inner window
//! `(1, 1, W−2, H−2)`), so a threshold learnt here splits the detector's values the same way.
//!
//! Modes (Lienhart & Maydt 2002): BASIC = upright edge (x2, y2), line (x3, y3) and the
//! diagonal x2_y2; CORE adds the 4-wide lines (x4, y4) and centre-surround; ALL adds the
//! 45°-tilted edges and lines. Units: pixels of the training window.

use rccar::detect::cascade::{HaarFeature, WeightedRect};
use rccar::detect::integral::Integrals;

/// OpenCV's `-mode` of `opencv_traincascade`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "UPPERCASE")]
pub enum HaarMode {
    /// Upright 2- and 3-rectangle features.
    Basic,
    /// BASIC plus 4-wide lines and centre-surround.
    Core,
    /// CORE plus the 45° tilted features.
    All,
}

fn rect(x: i32, y: i32, w: i32, h: i32, weight: f32) -> WeightedRect {
    WeightedRect { x, y, w, h, weight }
}

fn feat2(tilted: bool, a: WeightedRect, b: WeightedRect) -> HaarFeature {
    HaarFeature {
        rects: [a, b, WeightedRect::default()],
        count: 2,
        tilted,
    }
}

fn feat3(a: WeightedRect, b: WeightedRect, c: WeightedRect) -> HaarFeature {
    HaarFeature {
        rects: [a, b, c],
        count: 3,
        tilted: false,
    }
}

/// Every Haar feature of a `w` × `h` window in `mode`, in OpenCV's order.
pub fn generate(w: i32, h: i32, mode: HaarMode) -> Vec<HaarFeature> {
    let mut out = Vec::new();
    for x in 0..w {
        for y in 0..h {
            for dx in 1..=w {
                for dy in 1..=h {
                    // 1. Upright edges and lines (every mode).
                    if x + dx * 2 <= w && y + dy <= h {
                        out.push(feat2(false, rect(x, y, dx * 2, dy, -1.0), rect(x + dx, y, dx, dy, 2.0)));
                    }
                    if x + dx <= w && y + dy * 2 <= h {
                        out.push(feat2(false, rect(x, y, dx, dy * 2, -1.0), rect(x, y + dy, dx, dy, 2.0)));
                    }
                    if x + dx * 3 <= w && y + dy <= h {
                        out.push(feat2(false, rect(x, y, dx * 3, dy, -1.0), rect(x + dx, y, dx, dy, 3.0)));
                    }
                    if x + dx <= w && y + dy * 3 <= h {
                        out.push(feat2(false, rect(x, y, dx, dy * 3, -1.0), rect(x, y + dy, dx, dy, 3.0)));
                    }
                    // 2. 4-wide lines (CORE, ALL).
                    if mode != HaarMode::Basic {
                        if x + dx * 4 <= w && y + dy <= h {
                            out.push(feat2(
                                false,
                                rect(x, y, dx * 4, dy, -1.0),
                                rect(x + dx, y, dx * 2, dy, 2.0),
                            ));
                        }
                        if x + dx <= w && y + dy * 4 <= h {
                            out.push(feat2(
                                false,
                                rect(x, y, dx, dy * 4, -1.0),
                                rect(x, y + dy, dx, dy * 2, 2.0),
                            ));
                        }
                    }
                    // 3. The diagonal (every mode).
                    if x + dx * 2 <= w && y + dy * 2 <= h {
                        out.push(feat3(
                            rect(x, y, dx * 2, dy * 2, -1.0),
                            rect(x, y, dx, dy, 2.0),
                            rect(x + dx, y + dy, dx, dy, 2.0),
                        ));
                    }
                    // 4. Centre-surround (CORE, ALL).
                    if mode != HaarMode::Basic && x + dx * 3 <= w && y + dy * 3 <= h {
                        out.push(feat2(
                            false,
                            rect(x, y, dx * 3, dy * 3, -1.0),
                            rect(x + dx, y + dy, dx, dy, 9.0),
                        ));
                    }
                    // 5. Tilted edges and lines (ALL).
                    if mode == HaarMode::All {
                        if x + 2 * dx <= w && y + 2 * dx + dy <= h && x - dy >= 0 {
                            out.push(feat2(true, rect(x, y, dx * 2, dy, -1.0), rect(x, y, dx, dy, 2.0)));
                        }
                        if x + dx <= w && y + dx + 2 * dy <= h && x - 2 * dy >= 0 {
                            out.push(feat2(true, rect(x, y, dx, 2 * dy, -1.0), rect(x, y, dx, dy, 2.0)));
                        }
                        if x + 3 * dx <= w && y + 3 * dx + dy <= h && x - dy >= 0 {
                            out.push(feat2(
                                true,
                                rect(x, y, dx * 3, dy, -1.0),
                                rect(x + dx, y + dx, dx, dy, 3.0),
                            ));
                        }
                        if x + dx <= w && y + dx + 3 * dy <= h && x - 3 * dy >= 0 {
                            out.push(feat2(
                                true,
                                rect(x, y, dx, 3 * dy, -1.0),
                                rect(x - dy, y + dy, dx, dy, 3.0),
                            ));
                        }
                        if x + 4 * dx <= w && y + 4 * dx + dy <= h && x - dy >= 0 {
                            out.push(feat2(
                                true,
                                rect(x, y, dx * 4, dy, -1.0),
                                rect(x + dx, y + dx, dx * 2, dy, 2.0),
                            ));
                        }
                        if x + dx <= w && y + dx + 4 * dy <= h && x - 4 * dy >= 0 {
                            out.push(feat2(
                                true,
                                rect(x, y, dx, 4 * dy, -1.0),
                                rect(x - dy, y + dy, dx, 2 * dy, 2.0),
                            ));
                        }
                    }
                }
            }
        }
    }
    out
}

/// A feature compiled to offsets into one sample's integral tables (stride `w + 1`; the tilted
/// table follows the upright one, as in [`Integrals`]).
#[derive(Debug, Clone, Copy)]
pub struct Compiled {
    ofs: [[u32; 4]; 3],
    w: [f32; 3],
    three: bool,
}

impl Compiled {
    /// Compiles `f` for integral tables of `stride` elements per row whose tilted table starts
    /// at `tofs`.
    pub fn new(f: &HaarFeature, stride: usize, tofs: usize) -> Compiled {
        let mut c = Compiled {
            ofs: [[0; 4]; 3],
            w: [0.0; 3],
            three: f.count > 2 && f.rects[2].weight != 0.0,
        };
        for k in 0..f.count.min(3) {
            let r = f.rects[k];
            c.w[k] = r.weight;
            let p = |x: i32, y: i32, base: usize| (base + x as usize + y as usize * stride) as u32;
            c.ofs[k] = if f.tilted {
                [
                    p(r.x, r.y, tofs),
                    p(r.x - r.h, r.y + r.h, tofs),
                    p(r.x + r.w, r.y + r.w, tofs),
                    p(r.x + r.w - r.h, r.y + r.w + r.h, tofs),
                ]
            } else {
                [
                    p(r.x, r.y, 0),
                    p(r.x + r.w, r.y, 0),
                    p(r.x, r.y + r.h, 0),
                    p(r.x + r.w, r.y + r.h, 0),
                ]
            };
        }
        c
    }

    /// The raw value (before normalisation) on integral data `d`, as the detector computes it.
    #[inline(always)]
    pub fn raw(&self, d: &[i32]) -> f32 {
        let s = |k: usize| {
            let o = &self.ofs[k];
            d[o[0] as usize]
                .wrapping_sub(d[o[1] as usize])
                .wrapping_sub(d[o[2] as usize])
                .wrapping_add(d[o[3] as usize])
        };
        let mut v = self.w[0] * s(0) as f32 + self.w[1] * s(1) as f32;
        if self.three {
            v += self.w[2] * s(2) as f32;
        }
        v
    }
}

/// One training sample: a `w` × `h` grey patch's integral tables and its normalisation.
#[derive(Debug, Clone)]
pub struct SampleIntegral {
    /// Upright sum table, then (for tilted features) the tilted table; stride `w + 1`.
    pub data: Vec<i32>,
    /// `(f32)(1/nf)` as the detector computes it; 0 for a flat patch.
    pub inv: f32,
    /// Whether the detector would look at this window at all (`nf > 0` and `area·inv < 0.1`).
    pub scannable: bool,
}

/// Where the tilted table starts in [`SampleIntegral::data`] for a `w` × `h` window.
pub fn tilted_offset(w: usize, h: usize) -> usize {
    (w + 1) * (h + 1)
}

impl SampleIntegral {
    /// The tables of the row-major `w` × `h` patch `pix` (tilted table always computed, so
    /// any mode's features can read it).
    pub fn new(pix: &[u8], w: usize, h: usize, ii: &mut Integrals) -> SampleIntegral {
        ii.compute(pix, w, h, w + 1, h + 1, true);
        let n = (w + 1) * (h + 1);
        let mut data = Vec::with_capacity(2 * n);
        data.extend_from_slice(&ii.data[..n]);
        data.extend_from_slice(&ii.data[ii.tilted_offset..ii.tilted_offset + n]);
        // Normalisation over the inner window (1, 1, w−2, h−2), as detector step 5.
        let stride = w + 1;
        let at = |x: usize, y: usize| y * stride + x;
        let (x0, y0, x1, y1) = (1, 1, w - 1, h - 1);
        let vs = data[at(x0, y0)]
            .wrapping_sub(data[at(x1, y0)])
            .wrapping_sub(data[at(x0, y1)])
            .wrapping_add(data[at(x1, y1)]);
        let q = &ii.sqsum;
        let vq = (q[at(x0, y0)] + q[at(x1, y1)]).wrapping_sub(q[at(x1, y0)] + q[at(x0, y1)]) as u32;
        let area = ((w - 2) * (h - 2)) as f64;
        let nf = area * vq as f64 - vs as f64 * vs as f64;
        let (inv, scannable) = if nf > 0.0 {
            let inv = (1.0 / nf.sqrt()) as f32;
            (inv, area * (inv as f64) < 0.1)
        } else {
            (0.0, false)
        };
        SampleIntegral { data, inv, scannable }
    }

    /// The normalised value of a compiled feature, as the detector computes it.
    #[inline(always)]
    pub fn value(&self, f: &Compiled) -> f32 {
        f.raw(&self.data) * self.inv
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basic_pool_size_matches_opencv_count_for_24x24() {
        // The BASIC pool is what the loops give: count it in closed form.
        let f = generate(24, 24, HaarMode::Basic);
        let tri = |n: i32, k: i32| (1..=n / k).map(|d| n - k * d + 1).sum::<i32>();
        let expect = 2 * tri(24, 2) * tri(24, 1) + 2 * tri(24, 3) * tri(24, 1) + tri(24, 2) * tri(24, 2);
        assert_eq!(f.len() as i32, expect);
        assert!(generate(24, 24, HaarMode::Core).len() > f.len());
        let all = generate(24, 24, HaarMode::All);
        assert!(all.iter().any(|f| f.tilted));
        assert!(generate(24, 24, HaarMode::Core).iter().all(|f| !f.tilted));
    }

    #[test]
    fn feature_values_match_brute_force_sums() {
        let (w, h) = (12usize, 10usize);
        let pix: Vec<u8> = (0..w * h).map(|i| ((i * 37 + i / 7 * 11) % 251) as u8).collect();
        let mut ii = Integrals::new();
        let s = SampleIntegral::new(&pix, w, h, &mut ii);
        let px = |x: i32, y: i32| pix[y as usize * w + x as usize] as i64;
        for f in generate(w as i32, h as i32, HaarMode::Core).iter().step_by(7) {
            let c = Compiled::new(f, w + 1, tilted_offset(w, h));
            let mut expect = 0.0f64;
            for r in &f.rects[..f.count] {
                let mut sum = 0i64;
                {
                    for yy in r.y..r.y + r.h {
                        for xx in r.x..r.x + r.w {
                            sum += px(xx, yy);
                        }
                    }
                }
                expect += r.weight as f64 * sum as f64;
            }
            let got = c.raw(&s.data) as f64;
            assert!(
                (got - expect).abs() <= 1e-3 * expect.abs().max(1.0),
                "{f:?}: {got} vs {expect}"
            );
        }
    }
}
