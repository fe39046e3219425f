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
//! Coulter 1992). Adding one: docs/control.md, "Adding a steering method".

use super::params::{infos, ParamInfo, Params, Tunable};
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
}

impl SteeringMethod {
    /// Every method, in the order the docs list them.
    pub const ALL: [SteeringMethod; 2] = [SteeringMethod::Pid, SteeringMethod::PurePursuit];

    /// The config value, e.g. `pure_pursuit`.
    pub fn name(self) -> &'static str {
        match self {
            SteeringMethod::Pid => "pid",
            SteeringMethod::PurePursuit => "pure_pursuit",
        }
    }

    /// The method's parameter table.
    pub fn params(self) -> Vec<ParamInfo> {
        match self {
            SteeringMethod::Pid => infos(super::pid::Pid::PARAMS),
            SteeringMethod::PurePursuit => infos(super::pure_pursuit::PurePursuit::PARAMS),
        }
    }

    /// Whether `key` is one of this method's parameters.
    pub fn uses(self, key: &str) -> bool {
        self.params().iter().any(|p| p.key == key)
    }
}

/// Why `key` does nothing in a run that steers with `method`: `Some(reason)` when it is a
/// parameter of other steering methods only, `None` otherwise (one of `method`'s, the
/// throttle's, or not a steering parameter at all).
pub fn unused_by(method: SteeringMethod, key: &str) -> Option<String> {
    if method.uses(key) {
        return None;
    }
    let owners: Vec<&str> = SteeringMethod::ALL
        .iter()
        .filter(|m| m.uses(key))
        .map(|m| m.name())
        .collect();
    (!owners.is_empty()).then(|| {
        format!(
            "`{key}` is a parameter of steering.method = {}, and this run steers with {} (add --set steering.method={})",
            owners.join(" or "),
            method.name(),
            owners[0]
        )
    })
}

/// Why a steering method cannot be built from a configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SteeringError {
    /// Pure pursuit needs the bird's-eye image on the floor (camera model + ROI).
    #[error("steering.method = pure_pursuit: {0}")]
    PurePursuit(String),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_of_another_method_is_named_with_its_owner() {
        assert_eq!(unused_by(SteeringMethod::Pid, "steering.kp"), None);
        assert_eq!(unused_by(SteeringMethod::Pid, "throttle.base"), None);
        assert_eq!(unused_by(SteeringMethod::PurePursuit, "steering.max_steer"), None);
        let why = unused_by(SteeringMethod::Pid, "steering.lookahead_m").unwrap();
        assert!(why.contains("pure_pursuit") && why.contains("steers with pid"), "{why}");
        let why = unused_by(SteeringMethod::PurePursuit, "steering.kd").unwrap();
        assert!(why.contains("steering.method = pid"), "{why}");
    }
}
