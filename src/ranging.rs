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
//! **Detector boxes** ([`BoxRanging::range_detector`]). A cascade's box is the object's face
//! outline (plus the training margin `m`), widened to the cascade window's aspect, at a size
//! and position quantised by the detector's scale steps. Two cues, both from the pinhole
//! model with the tilt (camera frame: depth along the optical axis of a point `z` above the
//! floor at forward distance `d` is `Z = d·cos α + (h − z)·sin α`):
//!
//! ```text
//!     width:  w_px = f·W / Z(z_top)                      (a fronto-parallel edge of width W)
//!     height: h_px = f·H·d / (Z(z_b)·Z(z_t))             (a vertical edge from z_b to z_t)
//!     box:    h_box = m·max(h_px, w_px / aspect),  centre row = (v(z_b) + v(z_t)) / 2,
//!             v(z) = v0 + a_y·tan(atan((h − z)/d) − α)   (Eq. 5 inverted)
//! ```
//!
//! (the height formula is the difference of two Eq. 5 rows: `tan(a − α) = (k − d·t)/(d + k·t)`
//! with `k = h − z`, `t = tan α`, and `d + k·t = Z / cos α`). The distance that reproduces the
//! box's height and the one that reproduces its centre row (or, for an obstacle of unknown
//! size, Eq. 5 on the outline's bottom row `v_c + h_box/(2m)` at the contact height) are fused
//! by inverse variance, `d = Σ(d_i/σ_i²) / Σ(1/σ_i²)`, `σ_d² = 1 / Σ(1/σ_i²)`, each `σ_i`
//! from the box noise through the cue's derivative. [`BoxRanging::range_refined`] does the
//! same on a pixel-sharp colour outline found inside the box (src/ranging/refine.rs), and
//! [`track`] follows each object across frames (Kalman filter, odometry as control input).
//!
//! Calibration ([`fit`]) finds `α` and `v0` (and optionally `a_y`) from measured pairs
//! (box-bottom row, true distance) by nonlinear least squares (Gauss–Newton with a
//! Levenberg–Marquardt damping), minimising the error in the predicted *row*, where the pixel
//! noise lives.
//!
//! Units: metres, radians, pixels.

use crate::camera::PinholeCamera;
use crate::classes::ColourCue;

pub mod refine;
pub mod track;
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
    /// How far the principal point row may plausibly be from `v0_prior_px`, pixels (a
    /// Gaussian prior). Tilt and v0 nearly trade off against each other in Eq. 5 (a row shift
    /// looks like a tilt change of Δv0/a_y), so a few noisy pairs cannot separate them; the prior
    /// keeps v0 near the image centre unless the data insist. `f64::INFINITY` = free.
    pub v0_sigma_px: f64,
    /// Centre of the v0 prior, pixels; `None` = the starting value's v0. Give the image centre
    /// (`(height − 1) / 2`): a prior centred on an earlier fit's v0 keeps that fit's answer
    /// whatever the pairs say (tilt and v0 trade off), so the result would depend on the last
    /// calibration rather than on the data.
    pub v0_prior_px: Option<f64>,
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
            v0_prior_px: None,
            row_sigma_px: 1.0,
            distance_sigma_m: 0.005,
        }
    }
}

/// Fits `α` and `v0` (and `a_y` when asked) to `pairs`, starting from `start` (whose `h` is
/// kept). Minimises the squared row error plus the prior on v0 (centred on `opts.v0_prior_px`,
/// else on `start.v0`).
pub fn fit(pairs: &[Pair], start: TiltRanging, opts: FitOptions) -> Result<Fit, FitError> {
    let fit_ay = opts.fit_ay;
    check_pairs(pairs, fit_ay)?;
    // Residual r_i = row(d_i) − v_i, plus the prior (v0 − v0_prior)·σ_row/σ_v0;
    // parameters x = (α, v0, a_y).
    let v0_prior = opts.v0_prior_px.unwrap_or(start.v0);
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
    // The weights depend on the parameters (∂v/∂d): fitted with weights taken at the start,
    // then again with weights taken at the result, until the result stops moving, so the
    // answer does not depend on where the fit started.
    let mut cur = start;
    for _ in 0..5 {
        let weights: Vec<f64> = pairs.iter().map(|p| opts.row_sigma_px / sigma(&cur, p)).collect();
        let next = solve_weighted(pairs, cur, &weights, v0_prior, prior_w, fit_ay)?;
        let settled = (next.alpha - cur.alpha).abs() < 1e-10
            && (next.v0 - cur.v0).abs() < 1e-7
            && (next.a_y - cur.a_y).abs() < 1e-7;
        cur = next;
        if settled {
            break;
        }
    }
    if cur.a_y <= 0.0 {
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

/// One Levenberg–Marquardt solve of [`fit`] with fixed per-pair `weights`, from `start`.
fn solve_weighted(
    pairs: &[Pair],
    start: TiltRanging,
    weights: &[f64],
    v0_prior: f64,
    prior_w: f64,
    fit_ay: bool,
) -> Result<TiltRanging, FitError> {
    let n_par = if fit_ay { 3 } else { 2 };
    let residuals = |r: &TiltRanging| -> Vec<f64> {
        let mut e: Vec<f64> = pairs
            .iter()
            .zip(weights)
            .map(|(p, w)| (r.row(p.d, p.z) - p.v) * w)
            .collect();
        e.push((r.v0 - v0_prior) * prior_w);
        e
    };
    let cost = |r: &TiltRanging| residuals(r).iter().map(|e| e * e).sum::<f64>();
    let mut cur = start;
    let mut lambda = 1e-3;
    let mut c = cost(&cur);
    for _ in 0..200 {
        // 1. Jacobian by central differences (the model is smooth and cheap).
        let res = residuals(&cur);
        let jac = jacobian(&residuals, cur, n_par, pairs.len() + 1);
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
    Ok(cur)
}

/// The number of unknowns of [`fit`] (2, or 3 with `a_y`), or why `pairs` cannot be fitted
/// (too few, or a pair not finite / at a distance ≤ 0).
fn check_pairs(pairs: &[Pair], fit_ay: bool) -> Result<usize, FitError> {
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
    Ok(n_par)
}

/// Step 1 of [`fit`]: the `n_rows` × `n_par` Jacobian of `residuals` at `cur` by central
/// differences over (α, v0, a_y) (the model is smooth and cheap).
fn jacobian(
    residuals: &dyn Fn(&TiltRanging) -> Vec<f64>,
    cur: TiltRanging,
    n_par: usize,
    n_rows: usize,
) -> nalgebra::DMatrix<f64> {
    let mut jac = nalgebra::DMatrix::<f64>::zeros(n_rows, n_par);
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
        for i in 0..n_rows {
            jac[(i, k)] = (ra[i] - rb[i]) / (2.0 * step);
        }
    }
    jac
}

/// The object classes (the one registry, src/classes.rs), re-exported where ranging uses them.
pub use crate::classes::ObjectClass;

/// What a detector's box of one class frames (`[ranging]`): the object's face, where it
/// hangs, and how much looser than the face the trained boxes are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassBox {
    /// Width of the face the box spans (a stop sign's face), metres; 0 = unknown (no width cue).
    pub width_m: f64,
    /// Height of the face the box spans (a light's housing), metres; 0 = unknown.
    pub height_m: f64,
    /// Height above the floor of the face's lower edge, metres (0: it stands on the floor).
    pub bottom_m: f64,
    /// Size of the detector's box over the face's outline (the training crops' margin,
    /// training/src/simgen.rs): 1 = tight, 1.2 = 10% of floor either side.
    pub margin: f64,
}

/// One range from one detector box: the fused distance, its uncertainty, and the cues.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRange {
    /// Forward distance from the lens to the object's face, metres (inverse-variance fusion).
    pub distance_m: f64,
    /// Its standard deviation, metres.
    pub sigma_m: f64,
    /// Lateral offset of the face's bottom centre, metres, left positive.
    pub lateral_m: f64,
    /// The distance from the box's size alone and its σ, metres (objects of known size).
    pub by_size: Option<(f64, f64)>,
    /// The distance from the box's row alone and its σ, metres.
    pub by_row: Option<(f64, f64)>,
}

/// Ranges image boxes.
///
/// * [`BoxRanging::range`]: a tight outline (the simulator's true boxes): Eq. 5 on the box
///   bottom at the class's contact height for the distance, and the camera ray through the
///   bottom centre, cut at that height, for the lateral position.
/// * [`BoxRanging::range_detector`]: a cascade's box (fixed aspect, a training margin, size
///   and position quantised by the pyramid): the pinhole model of the face (module notes)
///   predicts the box's height and centre row from the distance; each is inverted for a
///   distance and the two are fused by their inverse variances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRanging {
    /// Eq. 5 with the calibrated tilt, v0 and a_y.
    pub tilt: TiltRanging,
    /// The camera with the same calibration (for the lateral position).
    pub camera: PinholeCamera,
    /// What each class's box frames: stop sign, traffic light, obstacle.
    pub classes: [ClassBox; ObjectClass::COUNT],
    /// σ of a detector box's centre row, pixels.
    pub centre_sigma_px: f64,
    /// σ of a detector box's size, relative (0.04 = 4%).
    pub size_sigma: f64,
    /// Refine detector boxes by colour (src/ranging/refine.rs) before ranging.
    pub refine: bool,
    /// The share of a stop sign's face (across the flats) that is red inside its white rim.
    pub red_fraction: f64,
}

impl BoxRanging {
    /// The contact height of a class's box bottom, metres.
    pub fn bottom_of(&self, class: ObjectClass) -> f64 {
        self.classes[class.index()].bottom_m
    }

    /// Forward distance and lateral offset (left positive) from the lens of an object of
    /// `class` whose tight outline is `[left, top, right, bottom]` (pixel-centre coordinates;
    /// a box of rows y..y+h−1 has its bottom edge at y + h − 0.5). `None` above the horizon.
    pub fn range(&self, class: ObjectClass, bbox: [f64; 4]) -> Option<(f64, f64)> {
        let z = self.bottom_of(class);
        // 1. Eq. 5 on the bottom row gives the forward distance to the plane at height z.
        let d = self.tilt.distance(bbox[3], z)?;
        Some((d, self.lateral(bbox, d)))
    }

    /// [`BoxRanging::range`] with a σ: the row is known to half a pixel (snapped to the pixel
    /// grid), `σ = 0.5 / |∂v/∂d|` (the derivative of Eq. 5's inverse).
    pub fn range_outline(&self, class: ObjectClass, bbox: [f64; 4]) -> Option<BoxRange> {
        let (d, lateral_m) = self.range(class, bbox)?;
        let z = self.bottom_of(class);
        let slope = ((self.tilt.row(d * 1.001, z) - self.tilt.row(d * 0.999, z)) / (0.002 * d)).abs();
        let sigma = (0.5 / slope.max(1e-9)).max(1e-4);
        Some(BoxRange {
            distance_m: d,
            sigma_m: sigma,
            lateral_m,
            by_size: None,
            by_row: Some((d, sigma)),
        })
    }

    /// The lateral offset of an object at forward distance `d` whose box is `bbox`: the ray
    /// through the box's centre column at the bottom row, scaled to that forward distance.
    fn lateral(&self, bbox: [f64; 4], d: f64) -> f64 {
        let r = self.camera.ray((bbox[0] + bbox[2]) / 2.0, bbox[3]);
        if r[0] <= 1e-9 {
            return self.camera.lateral_m;
        }
        self.camera.lateral_m + d * r[1] / r[0]
    }

    /// Depth along the optical axis of a point `z` above the floor at forward distance `d`:
    /// `Z = d cos α + (h − z) sin α`, metres.
    pub fn depth(&self, d: f64, z: f64) -> f64 {
        let (s, c) = self.tilt.alpha.sin_cos();
        d * c + (self.tilt.h - z) * s
    }

    /// The detector box height (pixels) and centre row the class's face at forward distance
    /// `d` gives, for boxes of aspect `aspect` (width / height): the face's outline
    /// (rows by Eq. 5, width `f·W/Z` at its top edge), widened to the aspect, times the margin.
    /// The centre row is `None` when the face's height is unknown.
    pub fn predicted_box(&self, class: ObjectClass, d: f64, aspect: f64) -> (f64, Option<f64>) {
        let cb = &self.classes[class.index()];
        let z_top = cb.bottom_m + cb.height_m;
        let v_bottom = self.tilt.row(d, cb.bottom_m);
        let (mut h, mut centre) = (0.0f64, None);
        if cb.height_m > 0.0 {
            let v_top = self.tilt.row(d, z_top);
            h = v_bottom - v_top;
            centre = Some((v_bottom + v_top) / 2.0);
        }
        if cb.width_m > 0.0 && aspect > 0.0 {
            // A fronto-parallel edge of width W at depth Z spans f·W/Z pixels; for a camera
            // looking down the top edge is the nearest, so the widest.
            h = h.max(self.camera.f_px * cb.width_m / self.depth(d, z_top) / aspect);
        }
        (h * cb.margin, centre)
    }

    /// The fused range of a detector box `bbox` of `class` (pixel-centre coordinates).
    /// `None` when no cue gives a distance (box above the horizon, or of a size the face cannot
    /// have in 0.05..50 m).
    ///
    /// 1. Size cue (face width and/or height known): the distance whose predicted box height
    ///    equals the box's (bisection; the height falls monotonically with distance there);
    ///    σ = σ_size·h / |∂h/∂d|.
    /// 2. Row cue: with a known face height, the distance whose predicted centre row equals
    ///    the box's (the margin and the widening to the aspect are symmetric about it), σ =
    ///    σ_centre / |∂v/∂d|; without (an obstacle), Eq. 5 on the outline's bottom row
    ///    `v_c + h/(2·margin)` at the contact height, σ from the row's σ (centre and size).
    /// 3. Inverse-variance fusion: `d = Σ d_i/σ_i² / Σ 1/σ_i²`, `σ² = 1 / Σ 1/σ_i²`.
    pub fn range_detector(&self, class: ObjectClass, bbox: [f64; 4]) -> Option<BoxRange> {
        let cb = self.classes[class.index()];
        let (hb, wb) = (bbox[3] - bbox[1], bbox[2] - bbox[0]);
        if !(hb > 0.0 && wb > 0.0) {
            return None;
        }
        let (aspect, vc) = (wb / hb, (bbox[1] + bbox[3]) / 2.0);
        let deriv = |f: &dyn Fn(f64) -> f64, d: f64| (f(d * 1.001) - f(d * 0.999)) / (0.002 * d);
        // 1. Size.
        let by_size = if cb.width_m > 0.0 || cb.height_m > 0.0 {
            let hf = |d: f64| self.predicted_box(class, d, aspect).0;
            solve_monotone(&hf, hb, 0.05, 50.0).map(|d| {
                let slope = deriv(&hf, d).abs().max(1e-9);
                (d, self.size_sigma * hb / slope)
            })
        } else {
            None
        };
        // 2. Row.
        let by_row = if cb.height_m > 0.0 {
            let cf = |d: f64| self.predicted_box(class, d, aspect).1.unwrap_or(f64::NAN);
            solve_monotone(&cf, vc, 0.05, 50.0).map(|d| {
                let slope = deriv(&cf, d).abs().max(1e-9);
                (d, self.centre_sigma_px / slope)
            })
        } else {
            let half = hb / (2.0 * cb.margin);
            self.tilt.distance(vc + half, cb.bottom_m).map(|d| {
                let slope = deriv(&|x: f64| self.tilt.row(x, cb.bottom_m), d).abs().max(1e-9);
                let sv = (self.centre_sigma_px.powi(2) + (self.size_sigma * half).powi(2)).sqrt();
                (d, sv / slope)
            })
        };
        // 3. Fusion.
        let (mut num, mut den) = (0.0, 0.0);
        for (d, s) in [by_size, by_row].into_iter().flatten() {
            let w = 1.0 / (s * s).max(1e-12);
            num += w * d;
            den += w;
        }
        if den <= 0.0 {
            return None;
        }
        let d = num / den;
        // The face's bottom edge, for the lateral ray: the box shrunk by its margin.
        let mut outline = bbox;
        outline[3] = vc + hb / (2.0 * cb.margin);
        Some(BoxRange {
            distance_m: d,
            sigma_m: den.sqrt().recip(),
            lateral_m: self.lateral(outline, d),
            by_size,
            by_row,
        })
    }
}

impl BoxRanging {
    /// The range of a detector box, refined by the object's colour when `[ranging]
    /// refine_by_colour` is on and the outline found agrees with the box (within 3σ of the box's
    /// own range, or within 25%: the box's σ underestimates its worst scale errors):
    /// [`BoxRanging::range_refined`], else [`BoxRanging::range_detector`].
    pub fn range_in_image(&self, img: &image::RgbImage, class: ObjectClass, bbox: [f64; 4]) -> Option<BoxRange> {
        let coarse = self.range_detector(class, bbox);
        if !self.refine {
            return coarse;
        }
        let fine = refine::outline(img, class, bbox).and_then(|o| self.range_refined(class, o));
        match (coarse, fine) {
            (Some(c), Some(f)) if (f.distance_m - c.distance_m).abs() <= (3.0 * c.sigma_m).max(0.25 * c.distance_m) => {
                Some(f)
            }
            (None, Some(f)) => Some(f),
            (c, _) => c,
        }
    }

    /// The range of a colour outline (src/ranging/refine.rs) of a stop sign's red area or a
    /// light's housing, each edge known to `σ_e = 0.5` px. Cues, fused by inverse variance:
    ///
    /// 1. width (stop sign, turn sign): the red area (the blue disc, [`BLUE_FRACTION`]·W), `red_fraction·W` wide, is widest at the face's
    ///    centre height z_c: `Z = f·W_r / w_px`, `d = (Z − (h − z_c)·sin α) / cos α`;
    /// 2. height: a vertical edge from z_b to z_t at forward distance d spans
    ///    `f·H·d / (Z_b·Z_t)` rows (`Z_i = d cos α + (h − z_i) sin α`), solved for d;
    /// 3. bottom row: Eq. 5 at z_b.
    pub fn range_refined(&self, class: ObjectClass, o: [f64; 4]) -> Option<BoxRange> {
        const SIGMA_EDGE: f64 = 0.5;
        let cb = self.classes[class.index()];
        let (w_px, h_px) = (o[2] - o[0], o[3] - o[1]);
        if !(w_px > 0.0 && h_px > 0.0) || cb.height_m <= 0.0 {
            return None;
        }
        // The coloured part: the red area of a sign (centred on the face), a turn sign's blue
        // disc inside its white rim, a light's housing.
        let cue = class.info().colour_cue;
        let k = match cue {
            ColourCue::RedFace => self.red_fraction,
            ColourCue::BlueFace => BLUE_FRACTION,
            _ => 1.0,
        };
        let (hh, zc) = (cb.height_m * k, cb.bottom_m + cb.height_m / 2.0);
        let (zb, zt) = (zc - hh / 2.0, zc + hh / 2.0);
        // The height the measured width belongs to: a sign's red area and a disc are widest at
        // the face's centre; a yield sign's triangle at its top edge.
        let zw = if cue == ColourCue::RedTriangle { zt } else { zc };
        let (s, c) = self.tilt.alpha.sin_cos();
        let f = self.camera.f_px;
        let mut cues: [Option<(f64, f64)>; 3] = [None; 3];
        let sw = SIGMA_EDGE * std::f64::consts::SQRT_2;
        // 1. Width.
        if matches!(cue, ColourCue::RedFace | ColourCue::BlueFace | ColourCue::RedTriangle) && cb.width_m > 0.0 {
            let z = f * cb.width_m * k / w_px;
            let d = (z - (self.tilt.h - zw) * s) / c;
            if d > 0.0 {
                cues[0] = Some((d, z / w_px / c * sw));
            }
        }
        // 2. Height.
        let hf = |d: f64| f * hh * d / (self.depth(d, zb) * self.depth(d, zt));
        if let Some(d) = solve_monotone(&hf, h_px, 0.05, 50.0) {
            let slope = ((hf(d * 1.001) - hf(d * 0.999)) / (0.002 * d)).abs().max(1e-9);
            cues[1] = Some((d, sw / slope));
        }
        // 3. Bottom row.
        if let Some(d) = self.tilt.distance(o[3], zb) {
            let slope = ((self.tilt.row(d * 1.001, zb) - self.tilt.row(d * 0.999, zb)) / (0.002 * d)).abs();
            cues[2] = Some((d, SIGMA_EDGE / slope.max(1e-9)));
        }
        let (mut num, mut den) = (0.0, 0.0);
        for (d, sd) in cues.into_iter().flatten() {
            let w = 1.0 / (sd * sd).max(1e-12);
            num += w * d;
            den += w;
        }
        if den <= 0.0 {
            return None;
        }
        let d = num / den;
        Some(BoxRange {
            distance_m: d,
            sigma_m: den.sqrt().recip(),
            lateral_m: self.lateral(o, d),
            by_size: cues[0].or(cues[1]),
            by_row: cues[2],
        })
    }
}

/// The share of a turn sign's disc, across, that is blue inside its white rim (the
/// simulator's sign, src/sim/scene.rs).
pub const BLUE_FRACTION: f64 = 0.92;

/// The `d` in `[lo, hi]` where the monotonic function `f` equals `target` (bisection on
/// log d), or `None` when `target` is outside `f`'s range there.
fn solve_monotone(f: &dyn Fn(f64) -> f64, target: f64, lo: f64, hi: f64) -> Option<f64> {
    let (flo, fhi) = (f(lo), f(hi));
    if !(flo.is_finite() && fhi.is_finite() && target.is_finite()) || target > flo.max(fhi) || target < flo.min(fhi) {
        return None;
    }
    let falling = flo > fhi;
    let (mut a, mut b) = (lo.ln(), hi.ln());
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if (f(m.exp()) > target) == falling {
            a = m;
        } else {
            b = m;
        }
    }
    Some((0.5 * (a + b)).exp())
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
    use crate::lane::synth::SplitMix;

    /// The shipped camera (`[camera]`).
    fn camera() -> PinholeCamera {
        PinholeCamera::new(320, 240, 62.2, 0.20, 20.0)
    }

    fn nominal() -> TiltRanging {
        TiltRanging::from_camera(&camera())
    }

    #[test]
    fn eq5_agrees_with_the_camera_projection() {
        let cam = camera();
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

    /// The shipped `[ranging]` with the shipped camera.
    fn box_ranging() -> BoxRanging {
        let class = |width_m, height_m, bottom_m, margin| ClassBox {
            width_m,
            height_m,
            bottom_m,
            margin,
        };
        BoxRanging {
            tilt: nominal(),
            camera: camera(),
            classes: [
                class(0.10, 0.10, 0.12, 1.085),
                class(0.0, 0.12, 0.10, 1.21),
                class(0.0, 0.0, 0.0, 1.36),
                class(0.12, 0.104, 0.118, 1.165),
                class(0.10, 0.10, 0.12, 1.093),
            ],
            centre_sigma_px: 1.0,
            size_sigma: 0.06,
            refine: true,
            red_fraction: 0.9,
        }
    }

    #[test]
    fn the_height_formula_is_the_difference_of_two_eq5_rows() {
        let b = box_ranging();
        let f = b.camera.f_px;
        for &d in &[0.3, 0.7, 1.5] {
            let (zb, zt) = (0.10, 0.22);
            let rows = b.tilt.row(d, zb) - b.tilt.row(d, zt);
            let formula = f * (zt - zb) * d / (b.depth(d, zb) * b.depth(d, zt));
            assert!((rows - formula).abs() < 1e-9, "{rows} vs {formula}");
        }
    }

    #[test]
    fn a_box_the_model_predicts_is_ranged_back_to_its_distance() {
        let b = box_ranging();
        for class in [ObjectClass::StopSign, ObjectClass::TrafficLight, ObjectClass::Obstacle] {
            for &d in &[0.3, 0.8, 1.5] {
                let aspect = if class == ObjectClass::TrafficLight { 0.4 } else { 1.25 };
                let cb = b.classes[class.index()];
                let (h, c) = b.predicted_box(class, d, aspect);
                // An obstacle (size unknown, so no predicted height): any box whose outline
                // bottom is on Eq. 5's row.
                let h = if h > 0.0 { h } else { 12.0 / d };
                let c = c.unwrap_or_else(|| b.tilt.row(d, cb.bottom_m) - h / (2.0 * cb.margin));
                let u = b.camera.u0;
                let bbox = [u - aspect * h / 2.0, c - h / 2.0, u + aspect * h / 2.0, c + h / 2.0];
                let r = b.range_detector(class, bbox).unwrap();
                assert!((r.distance_m - d).abs() < 1e-6 * d, "{class:?} at {d}: {r:?}");
                assert!(r.sigma_m > 0.0 && r.sigma_m < 0.2 * d);
                // Fusion never gives more weight than the better cue deserves.
                let best = [r.by_size, r.by_row]
                    .into_iter()
                    .flatten()
                    .map(|c| c.1)
                    .fold(f64::INFINITY, f64::min);
                assert!(r.sigma_m <= best + 1e-12);
            }
        }
    }

    #[test]
    fn an_exact_colour_outline_is_ranged_back_to_its_distance() {
        let b = box_ranging();
        let cam = b.camera;
        for &d in &[0.3, 0.8, 1.5] {
            // A sign's red area: 0.09 m square centred 0.17 m up, straight ahead.
            let (_, t) = cam.project([d, 0.045, 0.215]).unwrap();
            let (r, _) = cam.project([d, -0.045, 0.17]).unwrap();
            let (_, bo) = cam.project([d, 0.0, 0.125]).unwrap();
            // The widest row is the centre: use its width, the face's top and bottom rows.
            let (l2, _) = cam.project([d, 0.045, 0.17]).unwrap();
            let got = b.range_refined(ObjectClass::StopSign, [l2, t, r, bo]).unwrap();
            assert!(((got.distance_m - d) / d).abs() < 1e-3, "at {d}: {got:?}");
        }
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
