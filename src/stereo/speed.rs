//! Speed of an object relative to the car from successive stereo distances (Abdollahi 2011,
//! Sec. 3.2.3): "for each frame the average disparity in the vicinity of five frames is
//! considered", the distance follows by D = b·f/d̄ (Eq. 12), and the speed is the change of
//! that distance over time.
//!
//! ```text
//!     d̄_k = (1/n) Σ_{j=k−n+1..k} d_j                  (the last n = 5 disparities)
//!     D_k = b·f / d̄_k                                  (depth; forward distance via the tilt)
//!     v_k = (D_{k−s} − D_k) / (t_k − t_{k−s})           (closing speed, m/s; > 0 = nearing)
//! ```
//!
//! The difference is taken over a span of s ≥ n frames, so the two averaged distances share
//! no frame. With s = n = 5 at 30 fps each speed rests on 1/6 s of travel, and disparity
//! noise of a tenth of a pixel far away swamps it (the thesis reports the speed averaged
//! over 60 frames); a span of 30 frames (1 s) gives usable per-frame values (docs/stereo.md
//! has both, measured). A frame without a range (no match) is skipped; the
//! window holds the last n ranged frames. Units: pixels, metres, seconds.

use super::StereoGeometry;
use std::collections::VecDeque;

/// Relative speed from a stream of disparities.
#[derive(Debug, Clone)]
pub struct RelativeSpeed {
    n: usize,
    span: usize,
    /// (t, disparity) of the last n ranged frames.
    disp: VecDeque<(f64, f64)>,
    /// (t, averaged forward distance) of the last span + 1 frames.
    dist: VecDeque<(f64, f64)>,
}

/// One estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedEstimate {
    /// Forward distance from the averaged disparity, metres.
    pub distance_m: f64,
    /// Closing speed, m/s (positive: the object comes nearer); `None` until span + 1
    /// averaged distances exist.
    pub closing_mps: Option<f64>,
}

impl RelativeSpeed {
    /// Disparities averaged over `n` frames (the thesis: 5; at least 1), speeds from
    /// distances `span` frames apart (at least `n`).
    pub fn new(n: usize, span: usize) -> Self {
        let n = n.max(1);
        let span = span.max(n);
        Self {
            n,
            span,
            disp: VecDeque::with_capacity(n + 1),
            dist: VecDeque::with_capacity(span + 2),
        }
    }

    /// Forgets everything (a new object).
    pub fn reset(&mut self) {
        self.disp.clear();
        self.dist.clear();
    }

    /// Adds the disparity `disparity_px` of the object's box centred at (u, v) at time `t_s`;
    /// `None` until n disparities were seen or when the averaged one gives no distance.
    pub fn push(&mut self, geo: &StereoGeometry, t_s: f64, disparity_px: f64, u: f64, v: f64) -> Option<SpeedEstimate> {
        self.disp.push_back((t_s, disparity_px));
        while self.disp.len() > self.n {
            self.disp.pop_front();
        }
        if self.disp.len() < self.n {
            return None;
        }
        let mean = self.disp.iter().map(|p| p.1).sum::<f64>() / self.n as f64;
        let depth = geo.depth_bfd(mean)?;
        let (fwd, _) = geo.forward_of_depth(depth, u, v);
        self.dist.push_back((t_s, fwd));
        while self.dist.len() > self.span + 1 {
            self.dist.pop_front();
        }
        let closing = if self.dist.len() == self.span + 1 {
            let (t0, d0) = self.dist[0];
            let dt = t_s - t0;
            (dt > 0.0).then(|| (d0 - fwd) / dt)
        } else {
            None
        };
        Some(SpeedEstimate {
            distance_m: fwd,
            closing_mps: closing,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::PinholeCamera;

    #[test]
    fn constant_approach_gives_its_speed() {
        let cam = PinholeCamera::new(320, 240, 62.2, 0.20, 20.0);
        let geo = StereoGeometry::ideal(&cam, 0.06);
        let (u, v) = (geo.cx, geo.cy);
        let mut s = RelativeSpeed::new(5, 5);
        let mut last = None;
        for k in 0..30 {
            let t = k as f64 / 30.0;
            let fwd = 1.5 - 0.3 * t;
            // The depth whose forward distance at the image centre is `fwd`.
            let z = fwd / geo.forward_of_depth(1.0, u, v).0;
            let d = geo.base_m * geo.f / z;
            last = s.push(&geo, t, d, u, v).or(last);
        }
        let e = last.unwrap();
        // The average of 1/D over 5 frames is not 1/D of the average: a small lag-free bias.
        assert!((e.closing_mps.unwrap() - 0.3).abs() < 0.003, "{e:?}");
    }
}
