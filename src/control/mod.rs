//! Control: turns the lane measurement into a [`Command`] for the car.
//!
//! Steering is a plug-in ([`steering::Steering`], picked by `steering.method`): [`pid`] steers
//! on the lane error, [`pure_pursuit`] towards a look-ahead point on the lane, [`learned`]
//! with a small network trained on recordings. [`throttle`]
//! picks the speed, [`Controller`] combines a steering method and the throttle policy. Every
//! part takes the time step as an argument and never reads the clock, and publishes its
//! tunable parameters once ([`params`]; gathered in [`catalog`]). [`behaviour`] is the state machine for stop signs,
//! lights, obstacles and a lost lane on top of them; control never talks to the serial link:
//! a sink delivers commands.

pub mod behaviour;
pub mod catalog;
pub mod learned;
pub mod params;
pub mod pid;
pub mod pilot;
pub mod pure_pursuit;
pub mod steering;
pub mod throttle;

use params::{ParamInfo, Tunable};
use serde::{Deserialize, Serialize};

/// What the car is told to do, both values in [−1, 1].
///
/// `steer`: −1 full left, 0 straight, +1 full right. `throttle`: −1 full reverse, 0 stop
/// (ESC neutral), +1 full forward. [`Command::NEUTRAL`] is the safe state every exit path sends.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Command {
    /// Steering, −1 (left) ..= 1 (right).
    pub steer: f64,
    /// Throttle, −1 (reverse) ..= 1 (forward); 0 is stop.
    pub throttle: f64,
}

impl Command {
    /// Wheels straight, motor stopped.
    pub const NEUTRAL: Command = Command {
        steer: 0.0,
        throttle: 0.0,
    };

    /// A command with both values clamped to [−1, 1] (NaN becomes 0).
    pub fn clamped(steer: f64, throttle: f64) -> Command {
        let c = |v: f64| if v.is_nan() { 0.0 } else { v.clamp(-1.0, 1.0) };
        Command {
            steer: c(steer),
            throttle: c(throttle),
        }
    }
}

/// Lane keeping: a steering method + the throttle policy.
#[derive(Debug, Clone)]
pub struct Controller {
    steering: Box<dyn steering::Steering>,
    throttle: throttle::Throttle,
}

impl Controller {
    /// A controller steering with `steering` and driving with the policy `throttle`
    /// (`[steering]` and `[throttle]` of car.toml convert into them: `Config::controller`).
    pub fn new(steering: Box<dyn steering::Steering>, throttle: throttle::ThrottleOptions) -> Self {
        Self {
            steering,
            throttle: throttle::Throttle::new(throttle),
        }
    }

    /// One control step, `dt` seconds after the previous one. With the lane lost the steering
    /// method decides (the shipped ones hold the wheel) and the throttle policy decides when
    /// to stop.
    pub fn step(&mut self, input: &steering::SteeringInput<'_>, dt: f64) -> Command {
        let steer = self.steering.steer(input, dt);
        let throttle = self.throttle.update(input.lane.error, dt);
        Command::clamped(steer, throttle)
    }

    /// The steering method.
    pub fn steering(&self) -> &dyn steering::Steering {
        self.steering.as_ref()
    }

    /// The steering method, to reset or tune between frames.
    pub fn steering_mut(&mut self) -> &mut dyn steering::Steering {
        self.steering.as_mut()
    }

    /// Replaces the steering method (the set-up page's new ROI changes pure pursuit's map).
    pub fn set_steering(&mut self, steering: Box<dyn steering::Steering>) {
        self.steering = steering;
    }

    /// The throttle policy.
    pub fn throttle(&self) -> &throttle::Throttle {
        &self.throttle
    }

    /// The parameters that tune this controller: the steering method's, then the throttle's.
    pub fn params(&self) -> Vec<ParamInfo> {
        catalog::of_method(self.steering.method())
    }

    /// The value in force of a parameter of [`Controller::params`].
    pub fn get_param(&self, key: &str) -> Option<f64> {
        self.steering.get_param(key).or_else(|| self.throttle.get_param(key))
    }

    /// Sets a parameter of [`Controller::params`] from the next step on; `false` when `key` is
    /// not one of them. Check the value first (the configuration's range:
    /// `dashboard::validate_set`).
    pub fn set_param(&mut self, key: &str, value: f64) -> bool {
        self.steering.set_param(key, value) || self.throttle.set_param(key, value)
    }
}
