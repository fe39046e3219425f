//! One boosted stage (Friedman, Hastie & Tibshirani 2000, "Additive logistic regression":
//! Gentle, Real and Discrete AdaBoost and LogitBoost; OpenCV's `CvCascadeBoost`), over feature
//! values precomputed once per stage.
//!
//! Precomputation ([`FeatureMatrix`]): every feature's normalised value on every sample,
//! quantised to at most 256 bins whose edges are quantiles of a seeded subsample. A split "value
//! < edge_b" is then "bin ≤ b", so the best split of a feature is one pass over its bin bytes
//! building a weighted histogram — OpenCV sorts the values instead (`precalcValBufSize`); the
//! bins make a weak learner O(features × samples) with 1 byte per value, which is what lets
//! the memory budget (`--mem-mb`) hold all features for thousands of samples. Features are
//! searched in parallel with rayon.
//!
//! Labels y ∈ {−1, +1}; weights start uniform (OpenCV: `w0 = 1/n`). Per weak learner:
//! 1. Gentle: weighted least-squares regression stump/tree on y; leaf = Σwy/Σw;
//!    w ← w·exp(−y f).
//! 2. Real: split minimising Z = Σ_leaves 2√(W₊W₋); leaf = ½ ln(W₊/W₋) (smoothed).
//! 3. Discrete: split minimising the weighted error; leaves ±α, α = ½ ln((1−e)/e).
//! 4. Logit: p = 1/(1+e^(−2F)), z = (y01 − p)/(p(1−p)) clipped to ±4, weights p(1−p);
//!    least-squares fit on z, leaves ½·Σwz/Σw.

use crate::model::{BoostType, Split, Weak};
use rayon::prelude::*;

/// Binned feature values: `bins[f * n + i]` is feature `f`'s bin on sample `i`; a value is in
/// bin b when `edges[b-1] ≤ v < edges[b]`.
#[derive(Debug, Clone)]
pub struct FeatureMatrix {
    /// Samples per feature.
    pub n: usize,
    /// Pool index of each row.
    pub features: Vec<usize>,
    /// Bin bytes, feature-major.
    pub bins: Vec<u8>,
    /// Per feature, its ascending edges (≤ 255).
    pub edges: Vec<Vec<f32>>,
}

/// Quantile edges of `vals` (at most 255), midpoints between distinct neighbours.
fn edges_of(mut vals: Vec<f32>) -> Vec<f32> {
    vals.sort_by(|a, b| a.total_cmp(b));
    vals.dedup();
    if vals.len() <= 1 {
        return Vec::new();
    }
    let k = (vals.len() - 1).min(255);
    let mut out: Vec<f32> = (1..=k)
        .map(|j| {
            let i = j * (vals.len() - 1) / k;
            let (a, b) = (vals[i - 1], vals[i]);
            // Midpoint, kept strictly above a (a value equal to a stays left).
            let m = a + (b - a) * 0.5;
            if m > a {
                m
            } else {
                b
            }
        })
        .collect();
    out.dedup();
    out
}

impl FeatureMatrix {
    /// Computes and bins `n` samples' values of the features `features` (pool indices), with
    /// `value(f, i)` giving feature `f`'s value on sample `i`. Edges come from at most
    /// `subsample` samples (evenly spaced).
    pub fn build<F>(features: Vec<usize>, n: usize, subsample: usize, value: F) -> FeatureMatrix
    where
        F: Fn(usize, usize) -> f32 + Sync,
    {
        let step = (n / subsample.max(1)).max(1);
        // Written in place, one row per feature: the budget holds the bins once. Values are
        // computed in blocks of FEATURE_BLOCK features × SAMPLE_BLOCK samples so the samples'
        // integral tables stay in cache while every feature of the block reads them (feature
        // by feature over all samples missed the cache on every read: 5-10× slower).
        const FEATURE_BLOCK: usize = 64;
        const SAMPLE_BLOCK: usize = 48;
        let nn = n.max(1);
        let mut bins = vec![0u8; features.len() * n];
        let blocks: Vec<Vec<Vec<f32>>> = bins
            .par_chunks_mut(nn * FEATURE_BLOCK)
            .zip(features.par_chunks(FEATURE_BLOCK))
            .map(|(rows, fs)| {
                let mut vals = vec![0f32; fs.len() * n];
                for s0 in (0..n).step_by(SAMPLE_BLOCK) {
                    let s1 = (s0 + SAMPLE_BLOCK).min(n);
                    for (k, &f) in fs.iter().enumerate() {
                        for (i, v) in vals[k * n + s0..k * n + s1].iter_mut().enumerate() {
                            *v = value(f, s0 + i);
                        }
                    }
                }
                rows.chunks_mut(nn)
                    .enumerate()
                    .map(|(k, row)| {
                        let v = &vals[k * n..(k + 1) * n];
                        let edges = edges_of(v.iter().step_by(step).copied().collect());
                        for (b, x) in row.iter_mut().zip(v) {
                            *b = edges.partition_point(|e| *e <= *x) as u8;
                        }
                        edges
                    })
                    .collect()
            })
            .collect();
        let edges: Vec<Vec<f32>> = blocks.into_iter().flatten().collect();
        FeatureMatrix {
            n,
            features,
            bins,
            edges,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bins.len() + self.edges.iter().map(|e| e.len() * 4).sum::<usize>()
    }

    fn row(&self, r: usize) -> &[u8] {
        &self.bins[r * self.n..(r + 1) * self.n]
    }
}

/// Per-sample training state of one stage.
#[derive(Debug, Clone)]
pub struct Booster {
    /// Labels, ±1.
    pub y: Vec<f64>,
    /// Current weights (sum 1).
    pub w: Vec<f64>,
    /// Stage sum so far (the leaves as f32, added in f64 as the detector does).
    pub score: Vec<f64>,
    kind: BoostType,
}

/// Histogram of one feature over a subset: per bin Σw and Σw·t.
fn histogram(row: &[u8], w: &[f64], wt: &[f64], mask: Option<&[bool]>) -> ([f64; 256], [f64; 256]) {
    let mut hw = [0f64; 256];
    let mut ht = [0f64; 256];
    match mask {
        None => {
            for i in 0..row.len() {
                let b = row[i] as usize;
                hw[b] += w[i];
                ht[b] += wt[i];
            }
        }
        Some(m) => {
            for i in 0..row.len() {
                if m[i] {
                    let b = row[i] as usize;
                    hw[b] += w[i];
                    ht[b] += wt[i];
                }
            }
        }
    }
    (hw, ht)
}

/// The best split of one histogram: (gain, last left bin, left (Σw, Σwt), right (Σw, Σwt)).
/// Higher gain is better for every boosting type.
fn best_split(kind: BoostType, hw: &[f64; 256], ht: &[f64; 256], nbins: usize) -> Option<(f64, usize, [f64; 4])> {
    let (tw, tt): (f64, f64) = (hw[..nbins + 1].iter().sum(), ht[..nbins + 1].iter().sum());
    let mut best: Option<(f64, usize, [f64; 4])> = None;
    let (mut lw, mut lt) = (0.0, 0.0);
    for b in 0..nbins {
        lw += hw[b];
        lt += ht[b];
        let (rw, rt) = (tw - lw, tt - lt);
        if lw <= 0.0 || rw <= 0.0 {
            continue;
        }
        let gain = match kind {
            BoostType::Gentle | BoostType::Logit => lt * lt / lw + rt * rt / rw,
            BoostType::Real => {
                // W± = (Σw ± Σwy)/2; minimise Σ 2√(W₊W₋).
                let z = |w: f64, t: f64| ((w + t).max(0.0) * (w - t).max(0.0)).sqrt();
                -(z(lw, lt) + z(rw, rt))
            }
            BoostType::Discrete => lt.abs() + rt.abs(),
        };
        if best.is_none_or(|bb| gain > bb.0) {
            best = Some((gain, b, [lw, lt, rw, rt]));
        }
    }
    best
}

fn leaf_value(kind: BoostType, w: f64, t: f64, total_w: f64) -> f64 {
    match kind {
        BoostType::Gentle => {
            if w > 0.0 {
                t / w
            } else {
                0.0
            }
        }
        BoostType::Logit => {
            if w > 0.0 {
                0.5 * t / w
            } else {
                0.0
            }
        }
        BoostType::Real => {
            let eps = 1e-3 * total_w.max(1e-300) / 2.0;
            let (wp, wn) = (((w + t) / 2.0).max(0.0), ((w - t) / 2.0).max(0.0));
            (0.5 * ((wp + eps) / (wn + eps)).ln()).clamp(-4.0, 4.0)
        }
        BoostType::Discrete => t.signum(),
    }
}

impl Booster {
    /// Uniform weights over `npos` positives followed by `nneg` negatives.
    pub fn new(kind: BoostType, npos: usize, nneg: usize) -> Booster {
        let n = npos + nneg;
        let mut y = vec![1.0; npos];
        y.resize(n, -1.0);
        Booster {
            y,
            w: vec![1.0 / n as f64; n],
            score: vec![0.0; n],
            kind,
        }
    }

    /// The (weight, target) pairs the next weak learner fits.
    fn targets(&self) -> (Vec<f64>, Vec<f64>) {
        match self.kind {
            BoostType::Logit => {
                let mut w = Vec::with_capacity(self.y.len());
                let mut t = Vec::with_capacity(self.y.len());
                for i in 0..self.y.len() {
                    let p = 1.0 / (1.0 + (-2.0 * self.score[i]).exp());
                    let pq = (p * (1.0 - p)).max(1e-10);
                    let y01 = if self.y[i] > 0.0 { 1.0 } else { 0.0 };
                    let z = ((y01 - p) / pq).clamp(-4.0, 4.0);
                    w.push(pq);
                    t.push(pq * z);
                }
                let s: f64 = w.iter().sum();
                (w.iter().map(|v| v / s).collect(), t.iter().map(|v| v / s).collect())
            }
            _ => (self.w.clone(), self.w.iter().zip(&self.y).map(|(w, y)| w * y).collect()),
        }
    }

    /// Finds the best weak learner of depth `depth` (1 or 2) over `m`, adds it to the scores
    /// and re-weights. Returns `None` when no feature splits the samples.
    pub fn add_weak(&mut self, m: &FeatureMatrix, depth: u32) -> Option<Weak> {
        let (w, wt) = self.targets();
        let kind = self.kind;
        let total_w: f64 = w.iter().sum();
        // 1. Root: best split over all features, in parallel.
        let search = |mask: Option<&[bool]>| best_feature_split(m, kind, &w, &wt, mask);
        let (_, r0, b0, s0) = search(None)?;
        let split0 = Split {
            feature: m.features[r0],
            threshold: m.edges[r0][b0],
            left: 0,
            right: -1,
        };
        // (matrix row, last left bin) of each split, to apply the tree to the samples.
        let mut rb: Vec<(usize, usize)> = Vec::new();
        let mut weak = if depth >= 2 {
            // 2. Depth 2: each side gets its own best split (or stays a leaf).
            depth2_tree(m, kind, total_w, (r0, b0, s0), split0, &mut rb, search)
        } else {
            rb.push((r0, b0));
            Weak {
                splits: vec![split0],
                leaves: vec![
                    leaf_value(kind, s0[0], s0[1], total_w) as f32,
                    leaf_value(kind, s0[2], s0[3], total_w) as f32,
                ],
            }
        };
        // 3. Discrete: scale the ±1 leaves by α from the weighted error.
        if kind == BoostType::Discrete {
            self.scale_discrete(&mut weak, &rb, m, total_w);
        }
        // 4. Scores and weights.
        self.update(&weak, &rb, m);
        Some(weak)
    }

    /// Discrete AdaBoost: the ±1 leaves scaled by α = ½ ln((1 − e)/e), e the weighted error.
    fn scale_discrete(&self, weak: &mut Weak, rb: &[(usize, usize)], m: &FeatureMatrix, total_w: f64) {
        let mut err = 0.0;
        for i in 0..self.y.len() {
            let f = apply(weak, rb, m, i);
            if f * self.y[i] <= 0.0 {
                err += self.w[i];
            }
        }
        let e = (err / total_w).clamp(1e-10, 1.0 - 1e-10);
        let alpha = 0.5 * ((1.0 - e) / e).ln();
        for l in &mut weak.leaves {
            *l = (*l as f64 * alpha) as f32;
        }
    }

    /// Adds the weak learner to the scores and re-weights the samples (normalised; Logit's
    /// weights come from the scores instead).
    fn update(&mut self, weak: &Weak, rb: &[(usize, usize)], m: &FeatureMatrix) {
        let kind = self.kind;
        let mut s = 0.0;
        for i in 0..self.y.len() {
            let f = apply(weak, rb, m, i);
            self.score[i] += f;
            if kind != BoostType::Logit {
                self.w[i] *= (-self.y[i] * f).exp();
                s += self.w[i];
            }
        }
        if kind != BoostType::Logit && s > 0.0 {
            for v in &mut self.w {
                *v /= s;
            }
        }
    }
}

/// The best split over all features of `m` (rows in parallel; ties go to the lower row):
/// (gain, matrix row, last left bin, the sides' sums), or `None` when nothing splits. `mask`
/// keeps only some samples (one side of a depth-2 tree's root).
fn best_feature_split(
    m: &FeatureMatrix,
    kind: BoostType,
    w: &[f64],
    wt: &[f64],
    mask: Option<&[bool]>,
) -> Option<(f64, usize, usize, [f64; 4])> {
    (0..m.features.len())
        .into_par_iter()
        .filter_map(|r| {
            let nb = m.edges[r].len();
            if nb == 0 {
                return None;
            }
            let (hw, ht) = histogram(m.row(r), w, wt, mask);
            best_split(kind, &hw, &ht, nb).map(|(g, b, s)| (g, r, b, s))
        })
        .reduce_with(|a, b| if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) { b } else { a })
}

/// A depth-2 tree under the root split `(r0, b0, s0)`: each side gets its own best split, or
/// stays a leaf. Pushes each split's (matrix row, last left bin) onto `rb`.
fn depth2_tree(
    m: &FeatureMatrix,
    kind: BoostType,
    total_w: f64,
    (r0, b0, s0): (usize, usize, [f64; 4]),
    split0: Split,
    rb: &mut Vec<(usize, usize)>,
    search: impl Fn(Option<&[bool]>) -> Option<(f64, usize, usize, [f64; 4])>,
) -> Weak {
    let row0 = m.row(r0);
    let left_mask: Vec<bool> = row0.iter().map(|&b| (b as usize) <= b0).collect();
    let right_mask: Vec<bool> = left_mask.iter().map(|v| !v).collect();
    let mut splits = vec![Split {
        left: 1,
        right: 2,
        ..split0
    }];
    rb.push((r0, b0));
    let mut leaves = Vec::new();
    for (side, mask) in [left_mask, right_mask].iter().enumerate() {
        let (sw, st) = if side == 0 { (s0[0], s0[1]) } else { (s0[2], s0[3]) };
        match search(Some(mask)) {
            Some((_, r, b, s)) => {
                let l = leaves.len() as i32;
                leaves.push(leaf_value(kind, s[0], s[1], total_w) as f32);
                leaves.push(leaf_value(kind, s[2], s[3], total_w) as f32);
                splits.push(Split {
                    feature: m.features[r],
                    threshold: m.edges[r][b],
                    left: -l,
                    right: -(l + 1),
                });
                rb.push((r, b));
            }
            None => {
                // A leaf directly under the root.
                let l = leaves.len() as i32;
                leaves.push(leaf_value(kind, sw, st, total_w) as f32);
                if side == 0 {
                    splits[0].left = -l;
                } else {
                    splits[0].right = -l;
                }
                splits.push(Split {
                    feature: split0.feature,
                    threshold: split0.threshold,
                    left: -l,
                    right: -l,
                });
                rb.push((r0, b0));
            }
        }
    }
    // Renumber: internal children are at node indices 1 and 2 (possibly unused).
    Weak { splits, leaves }
}

/// A weak learner's leaf (as f32, widened) on sample `i`; `rb` holds each split's matrix row
/// and last left bin.
fn apply(weak: &Weak, rb: &[(usize, usize)], m: &FeatureMatrix, i: usize) -> f64 {
    let mut idx = 0i32;
    loop {
        let (r, b) = rb[idx as usize];
        let sp = &weak.splits[idx as usize];
        idx = if (m.bins[r * m.n + i] as usize) <= b {
            sp.left
        } else {
            sp.right
        };
        if idx <= 0 {
            return weak.leaves[(-idx) as usize] as f64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_split_values_at_midpoints() {
        let e = edges_of(vec![3.0, 1.0, 2.0, 2.0]);
        assert_eq!(e, vec![1.5, 2.5]);
        assert!(edges_of(vec![1.0; 5]).is_empty());
    }

    #[test]
    fn every_boost_type_separates_a_one_feature_problem() {
        // Feature 0 separates (positives high), feature 1 is noise.
        let n = 200;
        let vals = |f: usize, i: usize| -> f32 {
            let pos = i < 100;
            if f == 0 {
                (if pos { 1.0 } else { -1.0 }) + ((i * 7919) % 100) as f32 / 200.0
            } else {
                ((i * 104729) % 97) as f32
            }
        };
        let m = FeatureMatrix::build(vec![0, 1], n, 1000, vals);
        for kind in [
            BoostType::Gentle,
            BoostType::Real,
            BoostType::Discrete,
            BoostType::Logit,
        ] {
            for depth in [1, 2] {
                let mut b = Booster::new(kind, 100, 100);
                let w = b.add_weak(&m, depth).expect("a split");
                assert_eq!(w.splits[0].feature, 0, "{kind:?} depth {depth}");
                let correct = (0..n).filter(|&i| (b.score[i] > 0.0) == (i < 100)).count();
                assert_eq!(correct, n, "{kind:?} depth {depth}");
            }
        }
    }
}
