//! The simulated car: a kinematic bicycle model (Rajamani, *Vehicle Dynamics and Control*,
//! Sec. 2.2, with the rear axle as reference point) plus the two lags a real RC car has:
//! a steering servo with dead time and a rate limit, and a speed that follows the throttle
//! with a first-order lag.
//!
//! Per fixed step `dt`:
//! 1. the steering command (−1..1, +1 = right) becomes a wheel angle target
//!    `δ* = −steer · δ_max` (positive δ turns left), delayed by `servo_delay_s`;
//! 2. the wheel angle moves towards the delayed target by at most `servo_rate · dt`;
//! 3. the speed approaches `throttle · v_max` with time constant τ: `v += (v* − v)(1 − e^(−dt/τ))`;
//! 4. the rear axle moves along an exact circular arc of curvature `tan δ / L`
//!    (`ẋ = v cos ψ, ẏ = v sin ψ, ψ̇ = v tan δ / L`).
//!
//! Units: metres, seconds, radians. Deterministic: no randomness, no clock.

use crate::config::VehicleConfig;
use crate::control::Command;
use std::collections::VecDeque;

/// Position and heading of the rear axle's centre in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Heading, radians counter-clockwise from +x.
    pub yaw: f64,
}

impl Pose {
    /// The world position of a point given in the car frame (x forward, y left) of this pose.
    pub fn to_world(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }
}

/// The car's state and parameters.
#[derive(Debug, Clone)]
pub struct Vehicle {
    /// Rear-axle pose.
    pub pose: Pose,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Front-wheel angle, radians, positive = left.
    pub wheel_angle: f64,
    cfg: VehicleConfig,
    dt: f64,
    /// Wheel-angle targets waiting out the servo's dead time.
    delay: VecDeque<f64>,
}

impl Vehicle {
    /// A car at rest at `pose`, stepping `dt` seconds at a time.
    pub fn new(cfg: &VehicleConfig, pose: Pose, dt: f64) -> Vehicle {
        let n = (cfg.servo_delay_s / dt).round() as usize;
        Vehicle {
            pose,
            speed: 0.0,
            wheel_angle: 0.0,
            cfg: cfg.clone(),
            dt,
            delay: vec![0.0; n].into(),
        }
    }

    /// The parameters.
    pub fn config(&self) -> &VehicleConfig {
        &self.cfg
    }

    /// Starts the car already rolling at `speed` m/s (skips the standing start).
    pub fn with_speed(mut self, speed: f64) -> Vehicle {
        self.speed = speed;
        self
    }

    /// Advances one fixed step under `cmd`.
    pub fn step(&mut self, cmd: Command) {
        let dt = self.dt;
        let max = self.cfg.max_steer_deg.to_radians();
        // 1. Command -> delayed wheel-angle target (+1 = right = negative angle).
        let target = -cmd.steer.clamp(-1.0, 1.0) * max;
        self.delay.push_back(target);
        let target = self.delay.pop_front().unwrap_or(target);
        // 2. Servo rate limit.
        let rate = self.cfg.servo_rate_dps.to_radians() * dt;
        self.wheel_angle += (target - self.wheel_angle).clamp(-rate, rate);
        // 3. Speed lag.
        let v_target = cmd.throttle.clamp(-1.0, 1.0) * self.cfg.max_speed_mps;
        let a = if self.cfg.speed_tau_s > 0.0 {
            1.0 - (-dt / self.cfg.speed_tau_s).exp()
        } else {
            1.0
        };
        self.speed += (v_target - self.speed) * a;
        // 4. Exact arc of the rear axle.
        let k = self.wheel_angle.tan() / self.cfg.wheelbase_m;
        let d = self.speed * dt;
        let p = &mut self.pose;
        if (k * d).abs() < 1e-9 {
            p.x += d * p.yaw.cos();
            p.y += d * p.yaw.sin();
        } else {
            let y1 = p.yaw + k * d;
            p.x += (y1.sin() - p.yaw.sin()) / k;
            p.y -= (y1.cos() - p.yaw.cos()) / k;
            p.yaw = y1;
        }
    }

    /// World positions of the four wheels' contact points: rear left, rear right, front left,
    /// front right.
    pub fn wheels(&self) -> [[f64; 2]; 4] {
        let (l, w) = (self.cfg.wheelbase_m, self.cfg.track_m / 2.0);
        [[0.0, w], [0.0, -w], [l, w], [l, -w]].map(|p| self.pose.to_world(p))
    }

    /// The car's centre (midway between the axles) in the world: where cross-track error is
    /// measured.
    pub fn centre(&self) -> [f64; 2] {
        self.pose.to_world([self.cfg.wheelbase_m / 2.0, 0.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(delay: f64) -> Vehicle {
        let cfg = VehicleConfig {
            servo_delay_s: delay,
            ..VehicleConfig::default()
        };
        Vehicle::new(
            &cfg,
            Pose {
                x: 0.0,
                y: 0.0,
                yaw: 0.0,
            },
            0.01,
        )
    }

    #[test]
    fn full_right_lock_drives_the_bicycle_circle() {
        let mut c = car(0.0);
        let cmd = Command {
            steer: 1.0,
            throttle: 0.5,
        };
        for _ in 0..2000 {
            c.step(cmd);
        }
        // Settled speed and wheel angle.
        assert!((c.speed - 0.5).abs() < 1e-6, "{}", c.speed);
        let max = 14f64.to_radians();
        assert!((c.wheel_angle + max).abs() < 1e-12);
        // The rear axle is on a circle of radius L / tan δ; sample its curvature directly.
        let r = 0.26 / max.tan();
        let p0 = c.pose;
        c.step(cmd);
        let dyaw = c.pose.yaw - p0.yaw;
        let ds = ((c.pose.x - p0.x).powi(2) + (c.pose.y - p0.y).powi(2)).sqrt();
        // ds is the chord 2 r sin(|Δψ|/2).
        let chord = 2.0 * r * (dyaw.abs() / 2.0).sin();
        assert!((ds - chord).abs() < 1e-12 && dyaw < 0.0, "{ds} vs {chord}");
    }

    #[test]
    fn speed_follows_a_first_order_lag() {
        let mut c = car(0.0);
        let tau = c.config().speed_tau_s;
        let n = (tau / 0.01).round() as usize;
        for _ in 0..n {
            c.step(Command {
                steer: 0.0,
                throttle: 1.0,
            });
        }
        // After one time constant: 1 − 1/e of the target.
        assert!((c.speed - (1.0 - (-1f64).exp())).abs() < 1e-9, "{}", c.speed);
        assert!((c.pose.y).abs() < 1e-12);
    }

    #[test]
    fn servo_waits_its_dead_time_then_slews_at_its_rate() {
        let mut c = car(0.05);
        let cmd = Command {
            steer: -1.0,
            throttle: 0.0,
        };
        for _ in 0..5 {
            c.step(cmd);
            assert_eq!(c.wheel_angle, 0.0);
        }
        c.step(cmd);
        let rate = 300f64.to_radians() * 0.01;
        assert!((c.wheel_angle - rate).abs() < 1e-12, "{}", c.wheel_angle);
    }

    #[test]
    fn deterministic() {
        let run = || {
            let mut c = car(0.03);
            for i in 0..500 {
                c.step(Command {
                    steer: ((i as f64) * 0.05).sin(),
                    throttle: 0.6,
                });
            }
            c.pose
        };
        assert_eq!(run(), run());
    }
}
