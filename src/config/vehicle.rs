//! `[vehicle]`: the car's chassis as the simulator and the dead reckoning model it: a kinematic
//! bicycle (metres), its steering servo (degrees, degrees per second, seconds) and its speed
//! response to the throttle (metres per second, seconds).

use super::check::Checker;
use crate::control::behaviour::DeadReckoning;
use serde::{Deserialize, Serialize};

/// `[vehicle]`: the simulated car, a kinematic bicycle (rear-axle reference point).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// Distance between the front and rear axles, metres.
    pub wheelbase_m: f64,
    /// Distance between the left and right wheels' centres, metres (lane-departure check).
    pub track_m: f64,
    /// How far the camera lens is ahead of the rear axle, metres.
    pub camera_x_m: f64,
    /// Front-wheel angle at full steering command (|steer| = 1), degrees.
    pub max_steer_deg: f64,
    /// Fastest the steering servo turns the wheels, degrees per second.
    pub servo_rate_dps: f64,
    /// Dead time between a steering command and the servo starting to move, seconds.
    pub servo_delay_s: f64,
    /// Speed at full throttle, metres per second.
    pub max_speed_mps: f64,
    /// Time constant of the speed's first-order response to the throttle, seconds (0 = instant).
    pub speed_tau_s: f64,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            wheelbase_m: 0.26,
            track_m: 0.16,
            camera_x_m: 0.24,
            max_steer_deg: 14.0,
            servo_rate_dps: 300.0,
            servo_delay_s: 0.03,
            max_speed_mps: 1.0,
            speed_tau_s: 0.3,
        }
    }
}

impl VehicleConfig {
    /// Range checks of `[vehicle]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let v = self;
        c.range("vehicle.wheelbase_m", v.wheelbase_m, 0.02, 2.0);
        c.range("vehicle.track_m", v.track_m, 0.02, 2.0);
        c.range("vehicle.camera_x_m", v.camera_x_m, -2.0, 2.0);
        c.range("vehicle.max_steer_deg", v.max_steer_deg, 1.0, 60.0);
        c.range("vehicle.servo_rate_dps", v.servo_rate_dps, 1.0, 10000.0);
        c.range("vehicle.servo_delay_s", v.servo_delay_s, 0.0, 1.0);
        c.range("vehicle.max_speed_mps", v.max_speed_mps, 0.01, 20.0);
        c.range("vehicle.speed_tau_s", v.speed_tau_s, 0.0, 10.0);
    }
}

impl From<&VehicleConfig> for DeadReckoning {
    /// Dead reckoning at rest with the speed model of `[vehicle]`.
    fn from(v: &VehicleConfig) -> Self {
        DeadReckoning::new(v.max_speed_mps, v.speed_tau_s)
    }
}
