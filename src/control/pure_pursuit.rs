//! Pure pursuit steering (Coulter 1992, "Implementation of the Pure Pursuit Path Tracking
//! Algorithm", CMU-RI-TR-92-01; the first lab of F1TENTH): steer the rear axle along the
//! circular arc that passes through a goal point on the path a look-ahead distance ahead.
//!
//! Car frame: x forward from the centre of the rear axle, y left, metres. Per frame:
//! 1. **Band.** The bird's-eye rows that show the floor `lookahead_m ± lookahead_band_m`
//!    ahead of the rear axle (the bird's-eye → floor homography comes from `[camera]`,
//!    `[warp]` and `vehicle.camera_x_m`: [`crate::lane::warp::bird_to_floor`]).
//! 2. **Lane centre in the band.** The column histogram of those rows of the binary bird's-eye
//!    image, and the lines and lane centre of the lane pipeline (src/lane/lines.rs, with
//!    `[lane]`'s lane width, peak rule and plausibility check), the left line searched left of
//!    the near band's lane centre and the right line right of it (far ahead in a curve the
//!    lane is no longer near the image's middle column). A line not seen is estimated from the
//!    other; with neither seen in the band, the near band's lane centre (the lane pipeline's
//!    own measurement, at its distance) is the goal instead.
//! 3. **Goal point** `(x, y)`: the lane centre's column on the band's middle row, mapped to the
//!    floor; `y` taken relative to the car's centre column `L_F` on that row (so
//!    `lane.center_offset_px` holds here too). `L² = x² + y²` (≈ `lookahead_m²`).
//! 4. **Curvature** of the arc through the goal, tangent to the car's heading (Coulter Eq. 1–3):
//!    `κ = 2·y / L²`, 1/m, positive to the left.
//! 5. **Wheel angle** of the kinematic bicycle (the simulator's model, src/sim/vehicle.rs):
//!    `δ = atan(κ · wheelbase_m)`, radians, positive left.
//! 6. **Command** normalised to the car's steering range: `steer = −δ / δ_max`
//!    (`vehicle.max_steer_deg` is the wheel angle at |steer| = 1; +1 = right), clamped to
//!    ±`max_steer` and rate-limited to `slew_rate` per second, as the PID's output is.
//!
//! With the lane lost (no lane centre in the near band) the wheel is held. Time is passed in
//! (`dt`, seconds). Limits of the measurement: the goal point must lie inside the bird's-eye
//! view (0.64–1.24 m ahead of the rear axle with the shipped ROI), the far rows of the view are
//! magnified from fewer camera pixels (blurrier lines), and in a tight curve the outer line
//! leaves the view first, so far look-aheads measure one line and estimate the other.

use super::params::{Param, ParamInfo, Params};
use super::steering::{limit, Steering, SteeringError, SteeringInput, SteeringMethod, MAX_STEER, SLEW_RATE};
use crate::lane::lines::{column_histogram_rows, measure_in, LineOptions};
use crate::lane::warp::Homography;

/// Settings and geometry of pure pursuit (`[steering]`, `[vehicle]`, `[camera]` and `[warp]`
/// convert into them: `Config::steering_method`).
#[derive(Debug, Clone, PartialEq)]
pub struct PurePursuitOptions {
    /// Bird's-eye pixel → floor point (x forward from the rear axle, y left), metres.
    pub bird_to_floor: Homography,
    /// Size of the bird's-eye image, pixels.
    pub bird_size: (u32, u32),
    /// Distance between the axles, metres.
    pub wheelbase_m: f64,
    /// Front-wheel angle at |steer| = 1, radians.
    pub max_wheel_rad: f64,
    /// Look-ahead distance L_d ahead of the rear axle, metres.
    pub lookahead_m: f64,
    /// Half the depth of the floor band measured around L_d, metres.
    pub lookahead_band_m: f64,
    /// Output clamp, steer units 0..=1.
    pub max_steer: f64,
    /// Largest |Δsteer| per second.
    pub slew_rate: f64,
}

/// Where the goal point of the last frame was (for tests, telemetry and the lab).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// Forward distance from the rear axle, metres.
    pub x_m: f64,
    /// Lateral offset of the lane centre, metres, left positive.
    pub y_m: f64,
    /// Curvature of the arc to it, 1/m, left positive.
    pub curvature: f64,
    /// `true`: found in the look-ahead band; `false`: the near band's lane centre.
    pub in_band: bool,
}

/// Pure pursuit of a look-ahead point on the lane.
#[derive(Debug, Clone)]
pub struct PurePursuit {
    opts: PurePursuitOptions,
    floor_to_bird: Homography,
    hist: Vec<u16>,
    output: f64,
    goal: Option<Goal>,
}

impl PurePursuit {
    /// Pure pursuit with `opts`; an error when the bird's-eye map cannot be inverted or the
    /// look-ahead band lies outside the bird's-eye view ([`PurePursuit::view_m`]).
    pub fn new(opts: PurePursuitOptions) -> Result<Self, SteeringError> {
        let floor_to_bird = opts
            .bird_to_floor
            .inverse()
            .ok_or_else(|| SteeringError::PurePursuit("the bird's-eye map of the floor is singular".into()))?;
        let pp = Self {
            hist: vec![0; opts.bird_size.0 as usize],
            opts,
            floor_to_bird,
            output: 0.0,
            goal: None,
        };
        let (near, far) = pp.view_m();
        let (l, b) = (pp.opts.lookahead_m, pp.opts.lookahead_band_m);
        // 1 µm of slack: the view's edges come through a homography and its inverse.
        if !(l - b >= near - 1e-6 && l + b <= far + 1e-6) {
            return Err(SteeringError::OutsideView {
                lookahead_m: l,
                band_m: b,
                near_m: near,
                far_m: far,
            });
        }
        Ok(pp)
    }

    /// The floor the bird's-eye view shows along its middle column: (nearest, farthest)
    /// distance ahead of the rear axle, metres.
    pub fn view_m(&self) -> (f64, f64) {
        let (w, h) = self.opts.bird_size;
        let u = (w as f64 - 1.0) / 2.0;
        let x = |v: f64| self.opts.bird_to_floor.apply(u, v).map_or(f64::NAN, |p| p.0);
        let (a, b) = (x(h as f64 - 1.0), x(0.0));
        (a.min(b), a.max(b))
    }

    /// The goal point of the last frame (`None` before the first, or with the lane lost).
    pub fn goal(&self) -> Option<Goal> {
        self.goal
    }

    /// Steps 1–3: the goal point on the lane, or `None` with the lane lost.
    fn goal_point(&mut self, input: &SteeringInput<'_>) -> Option<Goal> {
        let near_centre = input.lane.lane_center?;
        let binary = &input.lane_detector.images().binary;
        let lines: &LineOptions = &input.lane_detector.options().lines;
        let (w, h) = (binary.width() as usize, binary.height() as usize);
        // 1. The band's rows: where the floor L_d ± b ahead crosses the middle column.
        let row = |x: f64| self.floor_to_bird.apply(x, 0.0).map_or(f64::NAN, |p| p.1);
        let (l, b) = (self.opts.lookahead_m, self.opts.lookahead_band_m);
        let (ra, rb) = (row(l + b), row(l - b));
        let (top, bottom) = (ra.min(rb).floor().max(0.0), ra.max(rb).ceil().min(h as f64 - 1.0));
        let mut centre = None;
        if bottom >= top && w > 0 {
            let rows = top as usize..bottom as usize + 1;
            self.hist.resize(w, 0);
            // 2. Lines either side of the near band's lane centre, at most a lane width away.
            column_histogram_rows(binary, rows.clone(), &mut self.hist);
            let split = (near_centre.round().max(0.0) as usize).min(w);
            let reach = (lines.lane_width_px * (1.0 + lines.width_tolerance)).ceil() as usize;
            let m = measure_in(
                &self.hist,
                rows.len() as u32,
                lines,
                split.saturating_sub(reach)..split,
                split..(split + reach).min(w),
            );
            centre = m.lane_center.map(|c| (c, (top + bottom) / 2.0, m.frame_center));
        }
        let in_band = centre.is_some();
        // Fallback: the near band's own lane centre, on its middle row.
        let (c, v, lf) = centre.unwrap_or_else(|| {
            let band = crate::lane::lines::band_rows(h as u32, lines.band) as f64;
            (near_centre, h as f64 - band / 2.0, input.lane.frame_center)
        });
        // 3. The goal on the floor, relative to the car's centre column on that row.
        let (x, y) = self.opts.bird_to_floor.apply(c, v)?;
        let (_, y0) = self.opts.bird_to_floor.apply(lf, v)?;
        let y = y - y0;
        // 4. Curvature of the arc through it.
        let curvature = 2.0 * y / (x * x + y * y);
        curvature.is_finite().then_some(Goal {
            x_m: x,
            y_m: y,
            curvature,
            in_band,
        })
    }
}

impl Steering for PurePursuit {
    fn method(&self) -> SteeringMethod {
        SteeringMethod::PurePursuit
    }

    fn steer(&mut self, input: &SteeringInput<'_>, dt: f64) -> f64 {
        self.goal = self.goal_point(input);
        let Some(goal) = self.goal else {
            return self.output; // lane lost: hold the wheel
        };
        if !(dt.is_finite() && dt > 0.0) {
            return self.output;
        }
        let o = &self.opts;
        // 5. Wheel angle of the bicycle, 6. normalised, clamped and rate-limited.
        let delta = (goal.curvature * o.wheelbase_m).atan();
        self.output = limit(-delta / o.max_wheel_rad, self.output, o.max_steer, o.slew_rate, dt);
        self.output
    }

    fn reset(&mut self) {
        self.goal = None;
    }

    fn clone_box(&self) -> Box<dyn Steering> {
        Box::new(self.clone())
    }
}

impl Params for PurePursuit {
    const PARAMS: &'static [Param<PurePursuit>] = &[
        Param {
            info: ParamInfo {
                key: "steering.lookahead_m",
                unit: "m",
                range: [0.1, 5.0],
                slider: [0.71, 1.18, 0.01],
                doc: "look-ahead distance L_d ahead of the rear axle: longer is smoother but cuts curves",
            },
            get: |p| p.opts.lookahead_m,
            set: |p, v| p.opts.lookahead_m = v,
        },
        Param {
            info: ParamInfo {
                key: "steering.lookahead_band_m",
                unit: "m",
                range: [0.01, 0.5],
                slider: [0.01, 0.2, 0.01],
                doc: "half the depth of the floor band the look-ahead lane centre is measured in",
            },
            get: |p| p.opts.lookahead_band_m,
            set: |p, v| p.opts.lookahead_band_m = v,
        },
        Param {
            info: MAX_STEER,
            get: |p| p.opts.max_steer,
            set: |p, v| p.opts.max_steer = v,
        },
        Param {
            info: SLEW_RATE,
            get: |p| p.opts.slew_rate,
            set: |p, v| p.opts.slew_rate = v,
        },
    ];
}
