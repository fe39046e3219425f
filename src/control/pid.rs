//! PID steering on the lane error (Rivera & Andaluz 2021, Sec. 3.2: "the vehicle positioning
//! error for which the control of the steering commands is generated", Eq. 2).
//!
//! `u = kp·e + ki·∫e dt − kd·dy/dt`, with the usual practical guards:
//! 1. derivative on the measurement `y` (not the error), low-pass filtered with time constant
//!    `derivative_tau`, so a change of set-point (a lane change later) gives no kick;
//! 2. the integral's contribution clamped to ±`integral_limit`, and not accumulated while the
//!    output is saturated in the same direction (anti-windup);
//! 3. the output clamped to ±`max_steer`;
//! 4. the output's rate of change limited to `slew_rate` per second (the servo's friend).
//!
//! Time is passed in (`dt`, seconds): the controller never reads a clock.

use super::params::{Param, ParamInfo, Params};
use super::steering::{limit, Steering, SteeringInput, SteeringMethod, MAX_STEER, SLEW_RATE};

/// PID gains and limits (units: steer per unit of normalised error, seconds); `[steering]` of
/// car.toml converts into them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain, per second.
    pub ki: f64,
    /// Derivative gain, seconds.
    pub kd: f64,
    /// Largest |ki·∫e|.
    pub integral_limit: f64,
    /// Output clamp.
    pub max_out: f64,
    /// Largest |Δu| per second.
    pub slew_rate: f64,
    /// Derivative low-pass time constant, seconds.
    pub derivative_tau: f64,
}

/// A PID controller's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    /// Gains and limits.
    pub gains: PidGains,
    integral: f64,
    prev_measurement: Option<f64>,
    derivative: f64,
    output: f64,
}

impl Pid {
    /// A controller at rest.
    pub fn new(gains: PidGains) -> Self {
        Self {
            gains,
            integral: 0.0,
            prev_measurement: None,
            derivative: 0.0,
            output: 0.0,
        }
    }

    /// One step with set-point 0: `error = −measurement` (the lane error of Eq. 2).
    pub fn update(&mut self, error: f64, dt: f64) -> f64 {
        self.update_setpoint(0.0, -error, dt)
    }

    /// One step towards `setpoint` from `measurement`, `dt` seconds after the previous one.
    pub fn update_setpoint(&mut self, setpoint: f64, measurement: f64, dt: f64) -> f64 {
        let g = self.gains;
        if dt.is_nan() || dt <= 0.0 || !dt.is_finite() || !measurement.is_finite() {
            return self.output; // no time has passed, or nothing to go on: hold
        }
        let e = setpoint - measurement;
        // 1. Derivative on the measurement, low-passed.
        let raw_d = self.prev_measurement.map_or(0.0, |p| -(measurement - p) / dt);
        let alpha = if g.derivative_tau > 0.0 {
            dt / (g.derivative_tau + dt)
        } else {
            1.0
        };
        self.derivative += alpha * (raw_d - self.derivative);
        self.prev_measurement = Some(measurement);
        // 2. Integral with clamping and conditional integration.
        let unsat = g.kp * e + self.integral + g.kd * self.derivative;
        let saturating = (unsat >= g.max_out && e > 0.0) || (unsat <= -g.max_out && e < 0.0);
        if !saturating {
            self.integral = (self.integral + g.ki * e * dt).clamp(-g.integral_limit, g.integral_limit);
        }
        // 3. Clamp, 4. slew-rate limit.
        let wanted = g.kp * e + self.integral + g.kd * self.derivative;
        self.output = limit(wanted, self.output, g.max_out, g.slew_rate, dt);
        self.output
    }

    /// The last output.
    pub fn output(&self) -> f64 {
        self.output
    }

    /// The integral term's current contribution.
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// Forgets the integral and the derivative history (e.g. after the lane was lost).
    /// The output is kept so the slew limit still applies.
    pub fn reset(&mut self) {
        self.integral = 0.0;
        self.prev_measurement = None;
        self.derivative = 0.0;
    }
}

/// The lane-keeping PID as a steering method (`steering.method = "pid"`): `u` of
/// [`Pid::update`] on the frame's normalised lane error. With the lane lost the history is
/// forgotten and the last output held.
impl Steering for Pid {
    fn method(&self) -> SteeringMethod {
        SteeringMethod::Pid
    }

    fn steer(&mut self, input: &SteeringInput<'_>, dt: f64) -> f64 {
        match input.lane.error {
            Some(e) => self.update(e, dt),
            None => {
                Pid::reset(self);
                self.output()
            }
        }
    }

    fn reset(&mut self) {
        Pid::reset(self);
    }

    fn clone_box(&self) -> Box<dyn Steering> {
        Box::new(self.clone())
    }
}

impl Params for Pid {
    const PARAMS: &'static [Param<Pid>] = &[
        Param {
            info: ParamInfo {
                key: "steering.kp",
                unit: "steer per unit error",
                range: [0.0, 20.0],
                slider: [0.0, 5.0, 0.05],
                doc: "proportional gain: too low drifts out of curves, too high weaves",
            },
            get: |p| p.gains.kp,
            set: |p, v| p.gains.kp = v,
        },
        Param {
            info: ParamInfo {
                key: "steering.ki",
                unit: "steer per error·s",
                range: [0.0, 20.0],
                slider: [0.0, 2.0, 0.01],
                doc: "integral gain: removes a steady offset, too high overshoots slowly",
            },
            get: |p| p.gains.ki,
            set: |p, v| p.gains.ki = v,
        },
        Param {
            info: ParamInfo {
                key: "steering.kd",
                unit: "steer per error/s",
                range: [0.0, 5.0],
                slider: [0.0, 5.0, 0.01],
                doc: "derivative gain, on the measurement: damps weaving, too high twitches with camera noise",
            },
            get: |p| p.gains.kd,
            set: |p, v| p.gains.kd = v,
        },
        Param {
            info: ParamInfo {
                key: "steering.integral_limit",
                unit: "steer",
                range: [0.0, 1.0],
                slider: [0.0, 1.0, 0.01],
                doc: "largest contribution of the integral term (anti-windup)",
            },
            get: |p| p.gains.integral_limit,
            set: |p, v| p.gains.integral_limit = v,
        },
        Param {
            info: MAX_STEER,
            get: |p| p.gains.max_out,
            set: |p, v| p.gains.max_out = v,
        },
        Param {
            info: SLEW_RATE,
            get: |p| p.gains.slew_rate,
            set: |p, v| p.gains.slew_rate = v,
        },
        Param {
            info: ParamInfo {
                key: "steering.derivative_tau",
                unit: "s",
                range: [0.0, 5.0],
                slider: [0.0, 1.0, 0.01],
                doc: "low-pass time constant of the derivative (0 = none): smoother steering, later damping",
            },
            get: |p| p.gains.derivative_tau,
            set: |p, v| p.gains.derivative_tau = v,
        },
    ];
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn gains() -> PidGains {
        PidGains {
            kp: 1.0,
            ki: 0.0,
            kd: 0.0,
            integral_limit: 0.3,
            max_out: 1.0,
            slew_rate: 1000.0,
            derivative_tau: 0.0,
        }
    }

    #[test]
    fn proportional_only() {
        let mut p = Pid::new(gains());
        assert!((p.update(0.25, 0.1) - 0.25).abs() < 1e-12);
        assert!((p.update(-0.5, 0.1) + 0.5).abs() < 1e-12);
    }

    #[test]
    fn integral_is_clamped_against_windup() {
        let mut p = Pid::new(PidGains {
            kp: 0.0,
            ki: 1.0,
            ..gains()
        });
        for _ in 0..100 {
            p.update(1.0, 0.1);
        }
        assert!((p.integral() - 0.3).abs() < 1e-12);
        // and unwinds as soon as the error changes sign
        p.update(-1.0, 0.1);
        assert!((p.integral() - 0.2).abs() < 1e-12);
    }

    #[test]
    fn no_integration_while_saturated() {
        let mut p = Pid::new(PidGains {
            kp: 5.0,
            ki: 1.0,
            integral_limit: 1.0,
            ..gains()
        });
        for _ in 0..10 {
            assert_eq!(p.update(0.5, 0.1), 1.0);
        }
        assert_eq!(p.integral(), 0.0);
    }

    #[test]
    fn derivative_on_measurement_has_no_setpoint_kick() {
        let mut p = Pid::new(PidGains {
            kp: 0.0,
            kd: 1.0,
            ..gains()
        });
        p.update_setpoint(0.0, 0.0, 0.1);
        // The set-point jumps, the measurement does not: no derivative action.
        assert_eq!(p.update_setpoint(1.0, 0.0, 0.1), 0.0);
        // The measurement moves by 0.1 in 0.1 s: D = −kd·dy/dt = −1.
        assert!((p.update_setpoint(1.0, 0.1, 0.1) + 1.0).abs() < 1e-12);
    }

    #[test]
    fn slew_rate_limits_the_change_per_second() {
        let mut p = Pid::new(PidGains {
            slew_rate: 2.0,
            ..gains()
        });
        assert!((p.update(1.0, 0.1) - 0.2).abs() < 1e-12);
        assert!((p.update(1.0, 0.1) - 0.4).abs() < 1e-12);
    }

    #[test]
    fn zero_or_bad_dt_holds_the_output() {
        let mut p = Pid::new(gains());
        p.update(0.3, 0.1);
        assert_eq!(p.update(0.9, 0.0), 0.3);
        assert_eq!(p.update(0.9, f64::NAN), 0.3);
        assert_eq!(p.update(f64::NAN, 0.1), 0.3);
    }

    proptest! {
        #[test]
        fn output_always_within_clamp(errors in proptest::collection::vec(-5.0f64..5.0, 1..50), kp in 0.0f64..20.0, ki in 0.0f64..20.0, kd in 0.0f64..5.0) {
            let mut p = Pid::new(PidGains { kp, ki, kd, integral_limit: 0.5, max_out: 0.8, slew_rate: 5.0, derivative_tau: 0.02 });
            let mut prev = 0.0;
            for e in errors {
                let u = p.update(e, 1.0 / 30.0);
                prop_assert!(u.abs() <= 0.8 + 1e-12);
                prop_assert!((u - prev).abs() <= 5.0 / 30.0 + 1e-12);
                prev = u;
            }
        }
    }
}
