//! Control: turns the lane measurement into a [`Command`] for the car.
//!
//! [`pid`] steers on the lane error, [`throttle`] picks the speed, [`Controller`] combines
//! them. Both take the time step as an argument and never read the clock. [`behaviour`] is
//! the state machine for stop signs, lights, obstacles and a lost lane on top of them; control
//! never talks to the serial link: a sink delivers commands.

pub mod behaviour;
pub mod pid;
pub mod throttle;

use crate::lane::LaneMeasurement;
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

/// Lane keeping: PID steering + throttle policy.
#[derive(Debug, Clone)]
pub struct Controller {
    /// Steering PID.
    pub pid: pid::Pid,
    /// Throttle policy.
    pub throttle: throttle::Throttle,
}

impl Controller {
    /// A controller steering with `gains` and driving with the policy `throttle`
    /// (`[steering]` and `[throttle]` of car.toml convert into them).
    pub fn new(gains: pid::PidGains, throttle: throttle::ThrottleOptions) -> Self {
        Self {
            pid: pid::Pid::new(gains),
            throttle: throttle::Throttle::new(throttle),
        }
    }

    /// One control step, `dt` seconds after the previous one. With the lane lost the steering
    /// is held (the PID's history is forgotten) and the throttle policy decides when to stop.
    pub fn step(&mut self, lane: &LaneMeasurement, dt: f64) -> Command {
        let steer = match lane.error {
            Some(e) => self.pid.update(e, dt),
            None => {
                self.pid.reset();
                self.pid.output()
            }
        };
        let throttle = self.throttle.update(lane.error, dt);
        Command::clamped(steer, throttle)
    }
}
