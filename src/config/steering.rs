//! `[steering]`: which steering method drives (`method`), and every method's parameters: the
//! PID's gains on the normalised lane error (per unit of error; seconds for the integral,
//! derivative and its filter), pure pursuit's look-ahead (metres), and the limits both apply
//! (steer units, −1..=1, and per second). The ranges are the methods' own parameter tables
//! (`crate::control::params`); this file holds the values, their defaults and the conversion.

use super::check::Checker;
use super::Config;
use crate::camera::PinholeCamera;
use crate::control::learned::{self, Learned, LearnedOptions, PilotNet};
use crate::control::pid::{Pid, PidGains};
use crate::control::pure_pursuit::{PurePursuit, PurePursuitOptions};
pub use crate::control::steering::SteeringMethod;
use crate::control::steering::{Steering, SteeringError};
use crate::control::Controller;
use crate::lane::warp::{bird_to_floor, Homography};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// `[steering]`: the steering method and its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringConfig {
    /// Which method steers: `pid`, `pure_pursuit` or `learned`.
    pub method: SteeringMethod,
    /// Learned: the weights file of the network (`rccar-train pilot` writes it); a relative
    /// path is relative to the folder of the config file that names it (the default,
    /// `pilot.safetensors`, to the base config's folder: config/pilot.safetensors).
    pub model: String,
    /// PID: proportional gain, steer per unit of normalised error.
    pub kp: f64,
    /// PID: integral gain, steer per (unit error x second).
    pub ki: f64,
    /// PID: derivative gain, steer per (unit error / second), on the measurement.
    pub kd: f64,
    /// PID: largest contribution of the integral term, steer units (anti-windup).
    pub integral_limit: f64,
    /// Output clamp, steer units 0..=1 (every method).
    pub max_steer: f64,
    /// Largest change of the steering command per second, steer units per second (every
    /// method).
    pub slew_rate: f64,
    /// PID: low-pass time constant of the derivative, seconds (0 = none; default 0.2, measured
    /// in docs/sim.md "Steering chatter").
    pub derivative_tau: f64,
    /// Pure pursuit: look-ahead distance L_d ahead of the rear axle, metres (inside the
    /// bird's-eye view).
    pub lookahead_m: f64,
    /// Pure pursuit: half the depth of the floor band around L_d the lane centre is measured
    /// in, metres.
    pub lookahead_band_m: f64,
}

impl Default for SteeringConfig {
    fn default() -> Self {
        Self {
            method: SteeringMethod::Pid,
            model: "pilot.safetensors".into(),
            kp: 1.0,
            ki: 0.0,
            kd: 0.05,
            integral_limit: 0.3,
            max_steer: 1.0,
            slew_rate: 8.0,
            derivative_tau: 0.2,
            lookahead_m: 0.9,
            lookahead_band_m: 0.06,
        }
    }
}

impl SteeringConfig {
    /// Range checks of `[steering]`: every method's parameter table.
    pub(super) fn check(&self, c: &mut Checker) {
        c.params("steering", self);
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

impl Config {
    /// The steering method `steering.method` picks, built from `[steering]` and the sections it
    /// reads (pure pursuit: `[camera]`, `[warp]`, `[vehicle]`).
    pub fn steering_method(&self) -> Result<Box<dyn Steering>, SteeringError> {
        Ok(match self.steering.method {
            SteeringMethod::Pid => Box::new(Pid::new((&self.steering).into())),
            SteeringMethod::PurePursuit => Box::new(PurePursuit::new(self.pure_pursuit_options()?)?),
            SteeringMethod::Learned => {
                let net = PilotNet::load(Path::new(&self.steering.model)).map_err(|e| SteeringError::Learned(e.to_string()))?;
                let (w, h) = (self.camera.width, self.camera.height);
                if (w, h) != (learned::FRAME_W, learned::FRAME_H) {
                    return Err(SteeringError::Learned(format!(
                        "{}: the network reads {}x{} frames and [camera] is {w}x{h}",
                        self.steering.model,
                        learned::FRAME_W,
                        learned::FRAME_H
                    )));
                }
                Box::new(Learned::new(
                    Arc::new(net),
                    LearnedOptions {
                        max_steer: self.steering.max_steer,
                        slew_rate: self.steering.slew_rate,
                    },
                ))
            }
        })
    }

    /// The lane controller: the steering method and the `[throttle]` policy.
    pub fn controller(&self) -> Result<Controller, SteeringError> {
        Ok(Controller::new(self.steering_method()?, (&self.throttle).into()))
    }

    /// Pure pursuit's options: `[steering]`'s look-ahead and limits, the bicycle of
    /// `[vehicle]`, and the bird's-eye → floor map of `[camera]` and `[warp]` moved from the
    /// lens to the rear axle (`vehicle.camera_x_m`).
    pub fn pure_pursuit_options(&self) -> Result<PurePursuitOptions, SteeringError> {
        let (w, h) = (self.warp.out_width, self.warp.out_height);
        let lens = bird_to_floor(&PinholeCamera::from(&self.camera), &self.warp.src, w, h).ok_or_else(|| {
            SteeringError::PurePursuit("a corner of warp.src does not see the floor with this [camera]".into())
        })?;
        let mut to_axle = nalgebra::Matrix3::identity();
        to_axle[(0, 2)] = self.vehicle.camera_x_m;
        let s = &self.steering;
        Ok(PurePursuitOptions {
            bird_to_floor: Homography(to_axle * lens.0),
            bird_size: (w, h),
            wheelbase_m: self.vehicle.wheelbase_m,
            max_wheel_rad: self.vehicle.max_steer_deg.to_radians(),
            lookahead_m: s.lookahead_m,
            lookahead_band_m: s.lookahead_band_m,
            max_steer: s.max_steer,
            slew_rate: s.slew_rate,
        })
    }

    /// The chosen steering method must build from the other sections (pure pursuit: its
    /// look-ahead band inside the bird's-eye view).
    pub(super) fn check_steering_method(&self, c: &mut Checker) {
        // The learned pilot's file is read when the controller is built (a default path is
        // only resolved after these checks); here only the key itself.
        if self.steering.method == SteeringMethod::Learned {
            if self.steering.model.trim().is_empty() {
                c.fail("steering.model", "\"\"".into(), "the path of a weights file (rccar-train pilot writes one)");
            }
            return;
        }
        match self.steering_method() {
            Ok(_) => {}
            Err(SteeringError::OutsideView {
                band_m, near_m, far_m, ..
            }) => c.fail(
                "steering.lookahead_m",
                self.steering.lookahead_m.to_string(),
                &format!(
                    "{:.3} ..= {:.3} with steering.method = pure_pursuit: ± steering.lookahead_band_m = {band_m} \
                     inside the bird's-eye view, {near_m:.3} ..= {far_m:.3} m ahead of the rear axle",
                    ((near_m + band_m) * 1e3).ceil() / 1e3,
                    ((far_m - band_m) * 1e3).floor() / 1e3
                ),
            ),
            Err(e) => c.fail("steering.method", self.steering.method.name().into(), &e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::catalog::all;

    /// Every table key is a number of `[steering]`/`[throttle]`, and what the configuration
    /// sets is what the running part reads back (key, field and conversion agree).
    #[test]
    fn every_parameter_round_trips_from_config_to_the_running_part() {
        for method in SteeringMethod::ALL {
            let mut base = Config::default()
                .with_override(&format!("steering.method={}", method.name()))
                .unwrap();
            // the shipped weights of the learned pilot, config/pilot.safetensors
            base.resolve_paths(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config"));
            let ctl = base.controller().unwrap();
            for p in ctl.params() {
                assert_eq!(base.number(p.key), ctl.get_param(p.key), "{}", p.key);
                // One slider step from the value in force (a value the other keys allow).
                let now = base.number(p.key).unwrap();
                let v = if now + p.slider[2] <= p.slider[1] { now + p.slider[2] } else { now - p.slider[2] };
                let cfg = base.with_override(&format!("{}={v}", p.key)).unwrap();
                assert_eq!(cfg.number(p.key), Some(v), "{}", p.key);
                assert_eq!(cfg.controller().unwrap().get_param(p.key), Some(v), "{} from the config", p.key);
                let mut live = base.controller().unwrap();
                assert!(live.set_param(p.key, v));
                assert_eq!(live.get_param(p.key), Some(v), "{} set live", p.key);
            }
        }
        for p in all() {
            assert!(Config::default().number(p.key).is_some(), "{} is not a config number", p.key);
        }
    }

    #[test]
    fn ranges_come_from_the_tables() {
        let e = Config::default().with_override("steering.lookahead_m=7").unwrap_err().to_string();
        assert!(e.contains("steering.lookahead_m = 7 is out of range (allowed: 0.1 ..= 5)"), "{e}");
        let e = Config::default().with_override("steering.slew_rate=0").unwrap_err().to_string();
        assert!(e.contains("steering.slew_rate = 0 is out of range (allowed: 0.1 ..= 1000)"), "{e}");
    }

    /// Pure pursuit's band must lie in the bird's-eye view (0.64..1.24 m ahead of the rear
    /// axle with the shipped ROI and camera_x_m = 0.24); pid does not care.
    #[test]
    fn a_look_ahead_outside_the_view_is_refused_for_pure_pursuit_only() {
        let pp = Config::default().with_override("steering.method=pure_pursuit").unwrap();
        let e = pp.with_override("steering.lookahead_m=1.5").unwrap_err().to_string();
        assert!(
            e.contains("steering.lookahead_m = 1.5 is out of range (allowed: 0.701 ..= 1.180 with steering.method = pure_pursuit")
                && e.contains("0.640 ..= 1.240 m"),
            "{e}"
        );
        assert!(pp.with_override("steering.lookahead_m=0.701").is_ok());
        assert!(pp.with_override("steering.lookahead_m=0.7").is_err());
        assert!(Config::default().with_override("steering.lookahead_m=1.5").is_ok());
        let view = PurePursuit::new(pp.pure_pursuit_options().unwrap()).unwrap().view_m();
        assert!((view.0 - 0.64).abs() < 1e-4 && (view.1 - 1.24).abs() < 1e-4, "{view:?}");
    }
}
