//! The pilot network for training: forward with the activations kept, backward (the chain
//! rule written out per layer), and Adam (Kingma & Ba 2015, Algorithm 1).
//!
//! Same architecture as the car's ([`rccar::control::learned::ARCH`]), computed differently on
//! purpose: activations channels-first (CHW) in plain loops, in f32, one sample at a time
//! (a batch is spread over threads by the caller), with the PyTorch layouts of the weights
//! file. The car's channels-last kernels are checked against this forward
//! (`forward_equals_the_cars`), and this backward against finite differences
//! (`gradient_matches_finite_differences`).
//!
//! Loss per sample: `(y − t)²` (the mean over a batch is the caller's).

// The loops index several tensors with the same indices, as the equations do.
#![allow(clippy::needless_range_loop)]

use rccar::control::learned::{flush, ConvSpec, PilotWeights, ARCH, IN_H, IN_W};
#[cfg(doc)]
use rccar::control::learned::NEGLIGIBLE;
use rccar::sim::rng::SplitMix64;

/// Every tensor of the network, flat, in [`rccar::control::learned::Arch::tensors`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// The values of each tensor.
    pub t: Vec<Vec<f32>>,
}

impl Params {
    /// All zeros (a gradient accumulator).
    pub fn zeros() -> Self {
        Self {
            t: ARCH.tensors().iter().map(|(_, s)| vec![0.0; s.iter().product()]).collect(),
        }
    }

    /// He-uniform initial weights (bound `√(6 / fan_in)`), zero biases, from `seed`.
    pub fn init(seed: u64) -> Self {
        let mut rng = SplitMix64::new(seed);
        let mut p = Self::zeros();
        for ((_, shape), v) in ARCH.tensors().iter().zip(&mut p.t) {
            if shape.len() == 1 {
                continue;
            }
            let fan_in: usize = shape[1..].iter().product();
            let bound = (6.0 / fan_in as f64).sqrt();
            for x in v.iter_mut() {
                *x = ((rng.next_f64() * 2.0 - 1.0) * bound) as f32;
            }
        }
        p
    }

    /// From a weights file's tensors.
    pub fn from_weights(w: &PilotWeights) -> Self {
        Self {
            t: ARCH.tensors().iter().map(|(n, _)| w.tensors[n].clone()).collect(),
        }
    }

    /// As a weights file's tensors (with `metadata`); [`NEGLIGIBLE`] weights written as zeros
    /// (no subnormal floats in the file: they would slow every reader down).
    pub fn to_weights(&self, metadata: std::collections::BTreeMap<String, String>) -> PilotWeights {
        PilotWeights {
            tensors: ARCH
                .tensors()
                .into_iter()
                .map(|(n, _)| n)
                .zip(self.t.iter().map(|v| v.iter().copied().map(flush).collect()))
                .collect(),
            metadata,
        }
    }

    /// `self += other`.
    pub fn add(&mut self, other: &Params) {
        for (a, b) in self.t.iter_mut().zip(&other.t) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
    }
}

/// Activations of one forward pass (post-ReLU), kept for the backward pass.
#[derive(Debug, Clone, Default)]
pub struct Trace {
    /// Input, then each convolution's output (CHW).
    acts: Vec<Vec<f32>>,
    /// The hidden layer after ReLU.
    hidden: Vec<f32>,
}

/// `y[co,oy,ox] = b[co] + Σ W[co,ci,ky,kx]·x[ci, oy·s+ky, ox·s+kx]`, then ReLU.
fn conv_fwd(c: &ConvSpec, (h, w): (usize, usize), x: &[f32], wt: &[f32], b: &[f32]) -> Vec<f32> {
    let (ho, wo) = ((h - c.k) / c.stride + 1, (w - c.k) / c.stride + 1);
    let mut y = vec![0.0f32; c.cout * ho * wo];
    for co in 0..c.cout {
        for oy in 0..ho {
            for ox in 0..wo {
                let mut a = b[co];
                for ci in 0..c.cin {
                    for ky in 0..c.k {
                        let xr = &x[(ci * h + oy * c.stride + ky) * w + ox * c.stride..][..c.k];
                        let wr = &wt[((co * c.cin + ci) * c.k + ky) * c.k..][..c.k];
                        a += xr.iter().zip(wr).map(|(p, q)| p * q).sum::<f32>();
                    }
                }
                y[(co * ho + oy) * wo + ox] = a.max(0.0);
            }
        }
    }
    y
}

/// Backward of [`conv_fwd`]: `dy` is the loss gradient at the ReLU's output, `y` that output.
/// Adds to `dw`, `db`; returns the gradient at `x` when `want_dx`.
#[allow(clippy::too_many_arguments)]
fn conv_bwd(
    c: &ConvSpec,
    (h, w): (usize, usize),
    x: &[f32],
    wt: &[f32],
    y: &[f32],
    dy: &[f32],
    dw: &mut [f32],
    db: &mut [f32],
    want_dx: bool,
) -> Vec<f32> {
    let (ho, wo) = ((h - c.k) / c.stride + 1, (w - c.k) / c.stride + 1);
    let mut dx = if want_dx { vec![0.0f32; c.cin * h * w] } else { Vec::new() };
    for co in 0..c.cout {
        for oy in 0..ho {
            for ox in 0..wo {
                let i = (co * ho + oy) * wo + ox;
                // ReLU: no gradient where the unit was off.
                if y[i] <= 0.0 {
                    continue;
                }
                let g = dy[i];
                db[co] += g;
                for ci in 0..c.cin {
                    for ky in 0..c.k {
                        let xo = (ci * h + oy * c.stride + ky) * w + ox * c.stride;
                        let wo_ = ((co * c.cin + ci) * c.k + ky) * c.k;
                        for kx in 0..c.k {
                            dw[wo_ + kx] += g * x[xo + kx];
                            if want_dx {
                                dx[xo + kx] += g * wt[wo_ + kx];
                            }
                        }
                    }
                }
            }
        }
    }
    dx
}

/// The network's output for `input` (`IN_H × IN_W` values), and the trace for
/// [`backward`].
pub fn forward(p: &Params, input: &[f32]) -> (f32, Trace) {
    let sizes = ARCH.sizes();
    let mut acts = vec![input.to_vec()];
    for (i, c) in ARCH.convs.iter().enumerate() {
        let y = conv_fwd(c, sizes[i], &acts[i], &p.t[2 * i], &p.t[2 * i + 1]);
        acts.push(y);
    }
    let flat = &acts[3];
    let (f1, b1, f2, b2) = (&p.t[6], &p.t[7], &p.t[8], &p.t[9]);
    let n = flat.len();
    let hidden: Vec<f32> = (0..ARCH.hidden)
        .map(|j| (b1[j] + f1[j * n..(j + 1) * n].iter().zip(flat).map(|(a, b)| a * b).sum::<f32>()).max(0.0))
        .collect();
    let y = b2[0] + hidden.iter().zip(f2).map(|(a, b)| a * b).sum::<f32>();
    (y, Trace { acts, hidden })
}

/// Adds the gradient of `(y − t)²` with respect to every parameter to `g`.
pub fn backward(p: &Params, tr: &Trace, y: f32, target: f32, g: &mut Params) {
    let sizes = ARCH.sizes();
    let dy = 2.0 * (y - target);
    // fc2
    g.t[9][0] += dy;
    let mut dh = [0.0f32; ARCH.hidden];
    for j in 0..ARCH.hidden {
        g.t[8][j] += dy * tr.hidden[j];
        dh[j] = if tr.hidden[j] > 0.0 { dy * p.t[8][j] } else { 0.0 };
    }
    // fc1
    let flat = &tr.acts[3];
    let n = flat.len();
    let mut dflat = vec![0.0f32; n];
    for j in 0..ARCH.hidden {
        if dh[j] == 0.0 {
            continue;
        }
        g.t[7][j] += dh[j];
        let wrow = &p.t[6][j * n..(j + 1) * n];
        let grow = &mut g.t[6][j * n..(j + 1) * n];
        for i in 0..n {
            grow[i] += dh[j] * flat[i];
            dflat[i] += dh[j] * wrow[i];
        }
    }
    // convolutions, last first
    let mut d = dflat;
    for i in (0..3).rev() {
        let (gw, rest) = g.t.split_at_mut(2 * i + 1);
        d = conv_bwd(
            &ARCH.convs[i],
            sizes[i],
            &tr.acts[i],
            &p.t[2 * i],
            &tr.acts[i + 1],
            &d,
            &mut gw[2 * i],
            &mut rest[0],
            i > 0,
        );
    }
}

/// Adam's state: first and second moments and the step count.
#[derive(Debug, Clone)]
pub struct Adam {
    m: Params,
    v: Params,
    step: i32,
    /// Learning rate.
    pub lr: f32,
    /// L2 weight decay added to the gradient of weights (not biases).
    pub decay: f32,
}

impl Adam {
    /// Adam with `lr` (β₁ = 0.9, β₂ = 0.999, ε = 1e-8).
    pub fn new(lr: f32, decay: f32) -> Self {
        Self {
            m: Params::zeros(),
            v: Params::zeros(),
            step: 0,
            lr,
            decay,
        }
    }

    /// One update of `p` with the (mean) gradient `g`.
    pub fn update(&mut self, p: &mut Params, g: &Params) {
        let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
        self.step += 1;
        let c1 = 1.0 - b1.powi(self.step);
        let c2 = 1.0 - b2.powi(self.step);
        for (k, ((w, gr), (m, v))) in p
            .t
            .iter_mut()
            .zip(&g.t)
            .zip(self.m.t.iter_mut().zip(self.v.t.iter_mut()))
            .enumerate()
        {
            let decay = if k % 2 == 0 { self.decay } else { 0.0 };
            for i in 0..w.len() {
                let gi = gr[i] + decay * w[i];
                m[i] = b1 * m[i] + (1.0 - b1) * gi;
                v[i] = b2 * v[i] + (1.0 - b2) * gi * gi;
                w[i] -= self.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + eps);
            }
        }
    }
}

/// Input size, values.
pub const INPUT_LEN: usize = IN_H * IN_W;

#[cfg(test)]
mod tests {
    use super::*;
    use rccar::control::learned::{PilotNet, Scratch};

    fn input(seed: u64) -> Vec<f32> {
        let mut r = SplitMix64::new(seed);
        (0..INPUT_LEN).map(|_| r.next_f64() as f32).collect()
    }

    /// The car's forward (channels-last kernels, weights re-ordered on load, the file's bytes
    /// in between) equals this one on the same weights: |Δ| ≤ 1e-5 · max(1, |y|) on 20 inputs.
    #[test]
    fn forward_equals_the_cars() {
        let mut p = Params::init(7);
        // non-zero biases, so a bias read from the wrong place shows
        for k in [1, 3, 5, 7, 9] {
            p.t[k].iter_mut().enumerate().for_each(|(i, b)| *b = 0.01 * (i as f32 % 5.0 - 2.0));
        }
        let bytes = p.to_weights(Default::default()).to_bytes();
        let car = PilotNet::new(&PilotWeights::from_bytes(&bytes).unwrap());
        let mut s = Scratch::default();
        let mut spread = 0.0f32;
        for k in 0..20 {
            let x = input(k);
            let (want, _) = forward(&p, &x);
            let got = car.forward(&x, &mut s);
            assert!((got - want).abs() <= 1e-5 * want.abs().max(1.0), "input {k}: car {got}, trainer {want}");
            spread += want.abs();
        }
        assert!(spread > 0.05, "outputs all near zero: a degenerate test");
    }

    /// Backward against central differences of the loss, on a few weights of every tensor:
    /// relative error ≤ 2 % (f32; a ReLU kink between the two probes is skipped).
    #[test]
    fn gradient_matches_finite_differences() {
        let p = Params::init(3);
        let x = input(99);
        let t = 0.3;
        let (y, tr) = forward(&p, &x);
        let mut g = Params::zeros();
        backward(&p, &tr, y, t, &mut g);
        let loss = |q: &Params| {
            let (y, tr) = forward(q, &x);
            (((y - t) as f64).powi(2), tr)
        };
        // which ReLUs are on: a probe pair that switches one is on a kink, not a slope
        let mask = |tr: &Trace| -> Vec<bool> { tr.acts[1..].iter().flatten().chain(&tr.hidden).map(|v| *v > 0.0).collect() };
        let mut checked = 0;
        for k in 0..p.t.len() {
            let n = p.t[k].len();
            for i in [0, n / 3, n / 2, n - 1] {
                let e = 1e-3f32;
                let mut a = p.clone();
                a.t[k][i] += e;
                let mut b = p.clone();
                b.t[k][i] -= e;
                let ((la, ta), (lb, tb)) = (loss(&a), loss(&b));
                if mask(&ta) != mask(&tb) {
                    continue;
                }
                let num = (la - lb) / (2.0 * e as f64);
                let ana = g.t[k][i] as f64;
                if num.abs() < 1e-4 && ana.abs() < 1e-4 {
                    continue;
                }
                let rel = (num - ana).abs() / num.abs().max(ana.abs());
                assert!(rel <= 0.02, "tensor {k} [{i}]: numeric {num}, backward {ana}");
                checked += 1;
            }
        }
        assert!(checked >= 20, "only {checked} gradients large enough to check");
    }
}
