//! Monocular distance from the camera's tilt (Rivera & Andaluz 2021, Eq. 5, after Chu et al.
//! 2004), and its calibration.
//!
//! A camera at height `h` above the floor, tilted down by `α`, sees a floor point on image row
//! `v` at ground distance
//!
//! ```text
//!     d = h / tan(α + atan((v − v0) / a_y)),      a_y = f / d_y        (Eq. 5)
//! ```
//!
//! with `v0` the principal point's row and `a_y` the focal length in pixels. For an object that
//! stands on the floor (an obstacle box) `v` is the bottom row of its detection box. A stop sign
//! or a traffic light does not touch the floor where its box ends: its box bottom is at a known
//! height `z` above the floor (the sign's lower edge on its post), so rccar intersects the ray
//! with the plane at that height instead: `d = (h − z) / tan(α + atan((v − v0)/a_y))`. With
//! `z = 0` this is Eq. 5 itself. (The alternative, finding the post's foot in the image, needs
//! the post to be visible and segmented; the known mounting height needs one tape measure.)
//!
//! Calibration ([`fit`]) finds `α` and `v0` (and optionally `a_y`) from measured pairs
//! (box-bottom row, true distance) by nonlinear least squares (Gauss–Newton with a
//! Levenberg–Marquardt damping), minimising the error in the predicted *row*, where the pixel
//! noise lives.
//!
//! Units: metres, radians, pixels.

use crate::camera::PinholeCamera;
use serde::{Deserialize, Serialize};

/// The parameters of Eq. 5.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TiltRanging {
    /// Lens height above the floor h, metres.
    pub h: f64,
    /// Downward tilt α, radians.
    pub alpha: f64,
    /// Principal point row v0, pixels.
    pub v0: f64,
    /// Focal length in pixels along the rows, a_y = f / d_y.
    pub a_y: f64,
}

impl TiltRanging {
    /// The nominal parameters of a camera (before calibration).
    pub fn from_camera(cam: &PinholeCamera) -> Self {
        Self {
            h: cam.height_m,
            alpha: cam.tilt_rad,
            v0: cam.v0,
            a_y: cam.f_px,
        }
    }

    /// Eq. 5 for a point `z` metres above the floor seen on row `v`: its distance along the
    /// ground, metres. `None` when the ray never reaches that height in front of the camera.
    pub fn distance(&self, v: f64, z: f64) -> Option<f64> {
        let angle = self.alpha + ((v - self.v0) / self.a_y).atan();
        let t = angle.tan();
        let d = (self.h - z) / t;
        (angle.abs() < std::f64::consts::FRAC_PI_2 && t.abs() > 1e-9 && d.is_finite() && d > 0.0).then_some(d)
    }

    /// The inverse of Eq. 5: the image row of a point `z` above the floor at distance `d`.
    pub fn row(&self, d: f64, z: f64) -> f64 {
        self.v0 + self.a_y * (((self.h - z) / d).atan() - self.alpha).tan()
    }
}

/// One calibration measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Image row of the box bottom, pixels.
    pub v: f64,
    /// True ground distance, metres.
    pub d: f64,
    /// Height of the box bottom above the floor, metres (0 for a marker on the floor).
    pub z: f64,
}

/// Result of a calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    /// The fitted parameters.
    pub ranging: TiltRanging,
    /// Per pair: predicted distance minus true distance, metres.
    pub residuals_m: Vec<f64>,
    /// Root-mean-square row error after the fit, pixels.
    pub rms_row_px: f64,
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Not enough pairs for the unknowns.
    #[error("need at least {need} pairs to fit {unknowns}, got {got}")]
    TooFewPairs {
        /// Pairs needed.
        need: usize,
        /// Unknowns being fitted.
        unknowns: &'static str,
        /// Pairs given.
        got: usize,
    },
    /// A pair with a non-positive or non-finite distance or row.
    #[error("pair {index}: distance {d} m and row {v} px must be finite, distance > 0")]
    BadPair {
        /// Index of the pair (0-based).
        index: usize,
        /// Its distance.
        d: f64,
        /// Its row.
        v: f64,
    },
    /// The solver did not converge (pairs inconsistent with any tilt).
    #[error("the fit did not converge; check that the distances and rows belong together")]
    NoConvergence,
}

/// What to fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Also fit a_y (needs pairs spread over many rows).
    pub fit_ay: bool,
    /// How far the principal point row may plausibly be from the starting value, pixels (a
    /// Gaussian prior). Tilt and v0 nearly trade off against each other in Eq. 5 (a row shift
    /// looks like a tilt change of Δv0/a_y), so a few noisy pairs cannot separate them; the prior
    /// keeps v0 near the image centre unless the data insist. `f64::INFINITY` = free.
    pub v0_sigma_px: f64,
    /// Expected noise of a measured row, pixels.
    pub row_sigma_px: f64,
    /// Expected error of a measured distance, metres (a tape measure: ~5 mm). Near the car a
    /// millimetre moves the row a lot, so each pair is weighted by its total row uncertainty
    /// `sqrt(σ_row² + (∂v/∂d · σ_d)²)` (the effective-variance method).
    pub distance_sigma_m: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            fit_ay: false,
            v0_sigma_px: 3.0,
            row_sigma_px: 1.0,
            distance_sigma_m: 0.005,
        }
    }
}

/// Fits `α` and `v0` (and `a_y` when asked) to `pairs`, starting from `start` (whose `h` is
/// kept). Minimises the squared row error plus the prior on v0.
pub fn fit(pairs: &[Pair], start: TiltRanging, opts: FitOptions) -> Result<Fit, FitError> {
    let fit_ay = opts.fit_ay;
    let n_par = if fit_ay { 3 } else { 2 };
    if pairs.len() < n_par + 1 {
        return Err(FitError::TooFewPairs {
            need: n_par + 1,
            unknowns: if fit_ay { "tilt, v0 and a_y" } else { "tilt and v0" },
            got: pairs.len(),
        });
    }
    for (index, p) in pairs.iter().enumerate() {
        if !(p.d.is_finite() && p.v.is_finite() && p.d > 0.0 && p.z.is_finite()) {
            return Err(FitError::BadPair { index, d: p.d, v: p.v });
        }
    }
    // Residual r_i = row(d_i) − v_i, plus the prior (v0 − v0_start)·σ_row/σ_v0;
    // parameters x = (α, v0, a_y).
    let prior_w = if opts.v0_sigma_px.is_finite() && opts.v0_sigma_px > 0.0 {
        opts.row_sigma_px / opts.v0_sigma_px
    } else {
        0.0
    };
    let sigma = |r: &TiltRanging, p: &Pair| {
        let dv_dd = (r.row(p.d + 1e-4, p.z) - r.row(p.d - 1e-4, p.z)) / 2e-4;
        (opts.row_sigma_px.powi(2) + (dv_dd * opts.distance_sigma_m).powi(2))
            .sqrt()
            .max(1e-6)
    };
    let weights: Vec<f64> = pairs.iter().map(|p| opts.row_sigma_px / sigma(&start, p)).collect();
    let residuals = |r: &TiltRanging| -> Vec<f64> {
        let mut e: Vec<f64> = pairs
            .iter()
            .zip(&weights)
            .map(|(p, w)| (r.row(p.d, p.z) - p.v) * w)
            .collect();
        e.push((r.v0 - start.v0) * prior_w);
        e
    };
    let cost = |r: &TiltRanging| residuals(r).iter().map(|e| e * e).sum::<f64>();
    let mut cur = start;
    let mut lambda = 1e-3;
    let mut c = cost(&cur);
    for _ in 0..200 {
        // 1. Jacobian by central differences (the model is smooth and cheap).
        let res = residuals(&cur);
        let mut jac = nalgebra::DMatrix::<f64>::zeros(pairs.len() + 1, n_par);
        for k in 0..n_par {
            let step = [1e-7, 1e-5, 1e-5][k];
            let (mut a, mut b) = (cur, cur);
            match k {
                0 => {
                    a.alpha += step;
                    b.alpha -= step
                }
                1 => {
                    a.v0 += step;
                    b.v0 -= step
                }
                _ => {
                    a.a_y += step;
                    b.a_y -= step
                }
            }
            let (ra, rb) = (residuals(&a), residuals(&b));
            for i in 0..=pairs.len() {
                jac[(i, k)] = (ra[i] - rb[i]) / (2.0 * step);
            }
        }
        // 2. Damped normal equations (JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr.
        let r = nalgebra::DVector::from_vec(res);
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * r;
        let mut a = jtj.clone();
        for k in 0..n_par {
            a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
        }
        let delta = a.lu().solve(&(-jtr)).ok_or(FitError::NoConvergence)?;
        let mut next = cur;
        next.alpha += delta[0];
        next.v0 += delta[1];
        if fit_ay {
            next.a_y += delta[2];
        }
        let cn = cost(&next);
        // 3. Accept and relax the damping, or reject and increase it.
        if cn.is_finite() && cn <= c {
            let done = (c - cn) <= 1e-14 * (1.0 + c) && delta.norm() < 1e-10;
            cur = next;
            c = cn;
            lambda = (lambda * 0.3).max(1e-12);
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    if !c.is_finite() || cur.a_y <= 0.0 {
        return Err(FitError::NoConvergence);
    }
    let residuals_m = pairs
        .iter()
        .map(|p| cur.distance(p.v, p.z).map_or(f64::NAN, |d| d - p.d))
        .collect();
    let rms_row_px = (pairs.iter().map(|p| (cur.row(p.d, p.z) - p.v).powi(2)).sum::<f64>() / pairs.len() as f64).sqrt();
    Ok(Fit {
        ranging: cur,
        residuals_m,
        rms_row_px,
    })
}

/// The kinds of objects the pipeline ranges, each with its own box-bottom height.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectClass {
    /// A stop sign (box = the face).
    StopSign,
    /// A traffic light (box = the housing).
    TrafficLight,
    /// An obstacle standing on the floor.
    Obstacle,
}

impl ObjectClass {
    /// The class of a detector label (`stop_sign`, `traffic_light`, `obstacle`).
    pub fn from_label(label: &str) -> Option<ObjectClass> {
        match label {
            "stop_sign" | "stop" => Some(ObjectClass::StopSign),
            "traffic_light" | "light" => Some(ObjectClass::TrafficLight),
            "obstacle" => Some(ObjectClass::Obstacle),
            _ => None,
        }
    }
}

/// Ranges image boxes: Eq. 5 on the box bottom at the class's contact height for the
/// distance, and the camera ray through the bottom centre, cut at that height, for the
/// lateral position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRanging {
    /// Eq. 5 with the calibrated tilt, v0 and a_y.
    pub tilt: TiltRanging,
    /// The camera with the same calibration (for the lateral position).
    pub camera: PinholeCamera,
    /// Box-bottom heights above the floor: stop sign, traffic light, obstacle, metres.
    pub bottom_m: [f64; 3],
}

impl BoxRanging {
    /// From `[camera]` (tilt, possibly calibrated) and `[ranging]` (v0 offset, a_y scale,
    /// contact heights).
    pub fn from_config(cam: &crate::config::CameraConfig, r: &crate::config::RangingConfig) -> Self {
        let mut camera = PinholeCamera::from_config(cam);
        camera.v0 += r.v0_offset_px;
        camera.f_px *= r.a_y_scale;
        Self {
            tilt: TiltRanging::from_camera(&camera),
            camera,
            bottom_m: [r.stop_sign_bottom_m, r.traffic_light_bottom_m, r.obstacle_bottom_m],
        }
    }

    /// The contact height of a class's box bottom, metres.
    pub fn bottom_of(&self, class: ObjectClass) -> f64 {
        self.bottom_m[class as usize]
    }

    /// Forward distance and lateral offset (left positive) from the lens of an object of
    /// `class` whose box is `[left, top, right, bottom]` (pixel-centre coordinates; a detector
    /// box of rows y..y+h−1 has its bottom edge at y + h − 0.5). `None` above the horizon.
    pub fn range(&self, class: ObjectClass, bbox: [f64; 4]) -> Option<(f64, f64)> {
        let z = self.bottom_of(class);
        // 1. Eq. 5 on the bottom row gives the forward distance to the plane at height z.
        let d = self.tilt.distance(bbox[3], z)?;
        // 2. The ray through the bottom centre, scaled to that forward distance, gives the side.
        let r = self.camera.ray((bbox[0] + bbox[2]) / 2.0, bbox[3]);
        if r[0] <= 1e-9 {
            return None;
        }
        Some((d, self.camera.lateral_m + d * r[1] / r[0]))
    }
}

/// Parses `row,distance[,height]` lines (a header line and `#` comments are skipped). Errors
/// name the line.
pub fn parse_pairs_csv(text: &str, origin: &str) -> Result<Vec<Pair>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = l.split(',').map(str::trim).collect();
        let nums: Result<Vec<f64>, _> = cols.iter().map(|c| c.parse::<f64>()).collect();
        match nums {
            Ok(n) if n.len() == 2 || n.len() == 3 => out.push(Pair {
                v: n[0],
                d: n[1],
                z: n.get(2).copied().unwrap_or(0.0),
            }),
            Err(_) if out.is_empty() && i == 0 => continue, // header
            _ => {
                return Err(format!(
                    "{origin}:{}: expected `row_px,distance_m[,height_m]`, got `{l}`",
                    i + 1
                ))
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::CameraConfig;
    use crate::lane::synth::SplitMix;

    fn nominal() -> TiltRanging {
        TiltRanging::from_camera(&PinholeCamera::from_config(&CameraConfig::default()))
    }

    #[test]
    fn eq5_agrees_with_the_camera_projection() {
        let cam = PinholeCamera::from_config(&CameraConfig::default());
        let r = TiltRanging::from_camera(&cam);
        for &d in &[0.2, 0.5, 1.0, 1.5] {
            for &z in &[0.0, 0.08, 0.3] {
                let (_, v) = cam.project([d, 0.0, z]).unwrap();
                let got = r.distance(v, z).unwrap();
                assert!((got - d).abs() < 1e-9, "d {d} z {z}: {got}");
                assert!((r.row(d, z) - v).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn no_distance_above_the_horizon() {
        let r = nominal();
        assert!(r.distance(r.v0 - 200.0, 0.0).is_none());
    }

    #[test]
    fn calibration_recovers_tilt_within_half_a_degree_from_ten_noisy_pairs() {
        // The true camera is tilted 3° more than nominal (a bent mount); rows carry 1 px of noise,
        // distances 5 mm (a tape measure).
        let truth = TiltRanging {
            alpha: nominal().alpha + 3f64.to_radians(),
            ..nominal()
        };
        let mut rng = SplitMix::new(7);
        let pairs: Vec<Pair> = (0..10)
            .map(|i| {
                let d = 0.25 + 0.13 * i as f64;
                Pair {
                    v: truth.row(d, 0.0) + rng.normal() * 1.0,
                    d: d + 0.005 * rng.normal(),
                    z: 0.0,
                }
            })
            .collect();
        let f = fit(&pairs, nominal(), FitOptions::default()).unwrap();
        let err_deg = (f.ranging.alpha - truth.alpha).to_degrees().abs();
        assert!(err_deg < 0.5, "tilt error {err_deg}°");
        assert!((f.ranging.v0 - truth.v0).abs() < 5.0, "v0 {}", f.ranging.v0);

        assert!(f.rms_row_px < 2.0);
    }

    #[test]
    fn calibration_holds_over_many_noise_draws() {
        let truth = TiltRanging {
            alpha: nominal().alpha - 2f64.to_radians(),
            ..nominal()
        };
        let mut worst: f64 = 0.0;
        for seed in 0..50 {
            let mut rng = SplitMix::new(seed);
            let pairs: Vec<Pair> = (0..10)
                .map(|i| {
                    let d = 0.2 + 0.14 * i as f64;
                    Pair {
                        v: truth.row(d, 0.0) + rng.normal(),
                        d: d + 0.005 * rng.normal(),
                        z: 0.0,
                    }
                })
                .collect();
            let f = fit(&pairs, nominal(), FitOptions::default()).unwrap();
            worst = worst.max((f.ranging.alpha - truth.alpha).to_degrees().abs());
        }
        assert!(worst < 0.5, "worst tilt error over 50 draws {worst}°");
    }

    #[test]
    fn an_off_centre_principal_point_still_gives_good_distances() {
        // v0 4 px off: tilt and v0 trade off (Δα ≈ Δv0/a_y), but the fitted pair still ranges
        // within 3 % over 0.2..1.5 m, which is what the car needs.
        let truth = TiltRanging {
            alpha: nominal().alpha + 1f64.to_radians(),
            v0: nominal().v0 + 4.0,
            ..nominal()
        };
        let mut rng = SplitMix::new(3);
        let pairs: Vec<Pair> = (0..10)
            .map(|i| {
                let d = 0.2 + 0.14 * i as f64;
                Pair {
                    v: truth.row(d, 0.0) + rng.normal(),
                    d: d + 0.005 * rng.normal(),
                    z: 0.0,
                }
            })
            .collect();
        let f = fit(&pairs, nominal(), FitOptions::default()).unwrap();
        for k in 0..=26 {
            let d = 0.2 + 0.05 * k as f64;
            let got = f.ranging.distance(truth.row(d, 0.0), 0.0).unwrap();
            assert!(((got - d) / d).abs() < 0.03, "at {d} m: {got}");
        }
    }

    #[test]
    fn too_few_or_bad_pairs_are_refused() {
        let p = Pair {
            v: 150.0,
            d: 0.5,
            z: 0.0,
        };
        assert!(matches!(
            fit(&[p, p], nominal(), FitOptions::default()),
            Err(FitError::TooFewPairs { .. })
        ));
        let bad = Pair { d: -1.0, ..p };
        assert!(matches!(
            fit(&[p, p, bad], nominal(), FitOptions::default()),
            Err(FitError::BadPair { index: 2, .. })
        ));
    }

    #[test]
    fn csv_parsing_names_the_line() {
        let ok = parse_pairs_csv("row_px,distance_m\n150,0.5\n# comment\n120,0.9,0.1\n", "p.csv").unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[1].z, 0.1);
        let e = parse_pairs_csv("150,0.5\n12;x\n", "p.csv").unwrap_err();
        assert!(e.starts_with("p.csv:2:"), "{e}");
    }
}
