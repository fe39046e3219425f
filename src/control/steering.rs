//! Steering as a plug-in: the [`Steering`] trait every steering method implements, the
//! [`SteeringInput`] it gets each frame, and the list of methods `steering.method` picks from.
//!
//! A method turns one frame's input and the time since the previous frame (`dt`, seconds:
//! passed in, never read from a clock) into a steering command in −1 (full left) ..= 1 (full
//! right), forgets its history on [`Steering::reset`], and publishes its tunable parameters
//! once ([`super::params::Params`]); the dashboard, the configuration checks, `--set`, sweeps
//! and `local.toml` saving read that table. The throttle policy, the behaviour machine's
//! overrides and the arming gate stay outside: every method's command goes the same way.
//!
//! Methods: [`super::pid::Pid`] (`pid`, the default: PID on the normalised lane error) and
//! [`super::pure_pursuit::PurePursuit`] (`pure_pursuit`: a look-ahead point on the lane,
//! Coulter 1992) and [`super::learned::Learned`] (`learned`: a small network trained by
//! `rccar-train pilot` steers from the camera frame). This file stands below them (they implement its trait and share its limits
//! [`MAX_STEER`] and [`SLEW_RATE`]); the table of which method has which parameters stands
//! above them, in [`super::catalog`]. Adding one: docs/control.md, "Adding a steering method".

use super::params::{ParamInfo, Tunable};
use crate::lane::{LaneDetector, LaneMeasurement};
use image::RgbImage;
use serde::{Deserialize, Serialize};

/// What a steering method gets each frame.
#[derive(Clone, Copy)]
pub struct SteeringInput<'a> {
    /// The lane as measured this frame (the histogram band nearest the car).
    pub lane: &'a LaneMeasurement,
    /// The lane detector after this frame: its bird's-eye images (the binary image a method
    /// may measure other rows of), its options and its warp.
    pub lane_detector: &'a LaneDetector,
    /// The camera frame at the pipeline's size (for a method that looks at the image itself).
    pub frame: &'a RgbImage,
}

/// A steering method.
pub trait Steering: Tunable + Send + std::fmt::Debug {
    /// Which method this is (`steering.method`).
    fn method(&self) -> SteeringMethod;
    /// The steering command for this frame, −1 (left) ..= 1 (right), `dt` seconds after the
    /// previous one. With the lane lost the method decides (the shipped ones hold the wheel).
    fn steer(&mut self, input: &SteeringInput<'_>, dt: f64) -> f64;
    /// Forgets the history (integrals, filters): the lane was lost, the behaviour machine
    /// steered for a while, or the car was put somewhere else. The last output is kept, so a
    /// rate limit still applies from there.
    fn reset(&mut self);
    /// A boxed copy (pipelines are cloned, e.g. by sweeps).
    fn clone_box(&self) -> Box<dyn Steering>;
}

impl Clone for Box<dyn Steering> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

/// `steering.method`: which [`Steering`] drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SteeringMethod {
    /// PID on the normalised lane error ([`super::pid`]).
    #[default]
    Pid,
    /// Pure pursuit of a look-ahead point on the lane ([`super::pure_pursuit`]).
    PurePursuit,
    /// A network trained on recordings steers from the camera frame ([`super::learned`]).
    Learned,
}

impl SteeringMethod {
    /// Every method, in the order the docs list them.
    pub const ALL: [SteeringMethod; 3] = [SteeringMethod::Pid, SteeringMethod::PurePursuit, SteeringMethod::Learned];

    /// The config value, e.g. `pure_pursuit`.
    pub fn name(self) -> &'static str {
        match self {
            SteeringMethod::Pid => "pid",
            SteeringMethod::PurePursuit => "pure_pursuit",
            SteeringMethod::Learned => "learned",
        }
    }
}

/// `steering.max_steer`: the output clamp every shipped method applies (steer units).
pub const MAX_STEER: ParamInfo = ParamInfo {
    key: "steering.max_steer",
    unit: "steer",
    range: [0.0, 1.0],
    slider: [0.0, 1.0, 0.01],
    doc: "steering output clamp; 1 = full servo travel",
};

/// `steering.slew_rate`: the rate limit every shipped method applies (steer units per second).
pub const SLEW_RATE: ParamInfo = ParamInfo {
    key: "steering.slew_rate",
    unit: "1/s",
    range: [0.1, 1000.0],
    slider: [0.5, 30.0, 0.5],
    doc: "largest change of the steering command per second; protects the servo, too low is late into curves",
};

/// The limits every shipped method applies to its wanted command `target`: clamped to
/// ±`max_steer` ([`MAX_STEER`]), then moved at most `slew_rate · dt` from the previous output
/// ([`SLEW_RATE`]). Returns the new output.
pub fn limit(target: f64, previous: f64, max_steer: f64, slew_rate: f64, dt: f64) -> f64 {
    let step = slew_rate * dt;
    target.clamp(-max_steer, max_steer).clamp(previous - step, previous + step)
}

/// Why a steering method cannot be built from a configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SteeringError {
    /// Pure pursuit needs the bird's-eye image on the floor (camera model + ROI).
    #[error("steering.method = pure_pursuit: {0}")]
    PurePursuit(String),
    /// The learned pilot's weights file cannot be used (the message names the file).
    #[error("steering.method = learned: steering.model = {0}")]
    Learned(String),
    /// Pure pursuit's look-ahead band lies (partly) outside the bird's-eye view.
    #[error(
        "steering.method = pure_pursuit: steering.lookahead_m = {lookahead_m} ± steering.lookahead_band_m = \
         {band_m} reaches outside the bird's-eye view, {near_m:.3} ..= {far_m:.3} m ahead of the rear axle \
         with this [camera], [warp] and vehicle.camera_x_m"
    )]
    OutsideView {
        /// `steering.lookahead_m`.
        lookahead_m: f64,
        /// `steering.lookahead_band_m`.
        band_m: f64,
        /// Nearest floor the view shows, metres ahead of the rear axle.
        near_m: f64,
        /// Farthest.
        far_m: f64,
    },
}
