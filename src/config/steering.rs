//! `[steering]`: the PID on the normalised lane error (gains per unit of error; seconds for the
//! integral, derivative and its filter; steer units, -1..=1, for the limits).

use super::check::Checker;
use crate::control::pid::PidGains;
use serde::{Deserialize, Serialize};

/// `[steering]`: PID on the normalised lane error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringConfig {
    /// Proportional gain: steer per unit of normalised error.
    pub kp: f64,
    /// Integral gain: steer per (unit error x second).
    pub ki: f64,
    /// Derivative gain: steer per (unit error / second), on the measurement.
    pub kd: f64,
    /// Largest contribution of the integral term, steer units (anti-windup).
    pub integral_limit: f64,
    /// Output clamp, steer units 0..=1.
    pub max_steer: f64,
    /// Largest change of the steering command per second, steer units per second.
    pub slew_rate: f64,
    /// Low-pass time constant of the derivative, seconds (0 = none; default 0.2, measured
    /// in docs/sim.md "Steering chatter").
    pub derivative_tau: f64,
}

impl Default for SteeringConfig {
    fn default() -> Self {
        Self {
            kp: 1.0,
            ki: 0.0,
            kd: 0.05,
            integral_limit: 0.3,
            max_steer: 1.0,
            slew_rate: 8.0,
            derivative_tau: 0.2,
        }
    }
}

impl SteeringConfig {
    /// Range checks of `[steering]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let s = self;
        c.range("steering.kp", s.kp, 0.0, 20.0);
        c.range("steering.ki", s.ki, 0.0, 20.0);
        c.range("steering.kd", s.kd, 0.0, 5.0);
        c.range("steering.integral_limit", s.integral_limit, 0.0, 1.0);
        c.range("steering.max_steer", s.max_steer, 0.0, 1.0);
        c.range("steering.slew_rate", s.slew_rate, 0.1, 1000.0);
        c.range("steering.derivative_tau", s.derivative_tau, 0.0, 5.0);
    }
}

impl From<&SteeringConfig> for PidGains {
    /// The PID's gains and limits of `[steering]`.
    fn from(s: &SteeringConfig) -> Self {
        Self {
            kp: s.kp,
            ki: s.ki,
            kd: s.kd,
            integral_limit: s.integral_limit,
            max_out: s.max_steer,
            slew_rate: s.slew_rate,
            derivative_tau: s.derivative_tau,
        }
    }
}
