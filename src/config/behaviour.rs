//! `[behaviour]`: the state machine's thresholds: confirmation windows (frames), trigger and
//! ignore distances (metres, forward from the lens), holds and timeouts (seconds), speeds
//! (m/s) and the passing manoeuvre (steer and throttle 0..=1, distances in metres).

use super::check::Checker;
use crate::control::behaviour::BehaviourOptions;
use serde::{Deserialize, Serialize};

/// `[behaviour]`: the state machine of src/control/behaviour.rs (docs/behaviour.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BehaviourConfig {
    /// A detection is confirmed when seen in `confirm_frames` of the last `window_frames`.
    pub confirm_frames: u32,
    /// Length of the confirmation window, frames.
    pub window_frames: u32,
    /// Below this estimated speed the car counts as stopped, m/s.
    pub standstill_mps: f64,
    /// Stop for a stop sign once it is confirmed nearer than this, metres (forward distance).
    pub stop_trigger_m: f64,
    /// Where the car should come to rest before a stop sign, metres from the lens [near, far]
    /// (the simulator's scenario score).
    pub stop_window_m: [f64; 2],
    /// How long to stand at a stop sign, counted from standstill, seconds.
    pub stop_hold_s: f64,
    /// After leaving a stop sign, ignore stop signs until the car has driven this far, metres...
    pub stop_ignore_m: f64,
    /// ...and for at least this long, seconds.
    pub stop_ignore_s: f64,
    /// Stop for a red (or amber) light confirmed nearer than this, metres.
    pub light_trigger_m: f64,
    /// Green seen in this many consecutive frames releases a red-light stop.
    pub green_confirm_frames: u32,
    /// A red-light stop also ends when no light has been seen for this long, seconds.
    pub light_lost_s: f64,
    /// Stop while an obstacle in the lane is nearer than this, metres.
    pub obstacle_stop_m: f64,
    /// An obstacle counts as in the lane when its centre is within this of the car's axis, metres.
    pub obstacle_lane_half_m: f64,
    /// Pass a blocking obstacle through the other (left) lane.
    pub pass_enabled: bool,
    /// With passing enabled, stop this far before an obstacle instead (room to swing out), metres.
    pub pass_trigger_m: f64,
    /// Stand this long before starting to pass, seconds.
    pub pass_wait_s: f64,
    /// Steering used for each half of the lane change (0..1).
    pub pass_steer: f64,
    /// Distance driven for each half of the lane change, metres.
    pub pass_turn_m: f64,
    /// Distance driven in the other lane (lane keeping) before changing back, metres.
    pub pass_along_m: f64,
    /// Throttle while passing.
    pub pass_throttle: f64,
    /// The car must be back in its lane within this distance from the start of the pass, metres.
    pub pass_return_m: f64,
    /// Throttle while the lane is lost, before stopping.
    pub lost_throttle: f64,
    /// Stop after the lane has been lost this long, seconds.
    pub lost_stop_s: f64,
    /// Slow down for a yield sign confirmed nearer than this, metres.
    pub yield_slow_m: f64,
    /// Throttle cap while yielding (0..1).
    pub yield_creep: f64,
    /// While yielding, an obstacle in the lane nearer than this stops the car, metres.
    pub yield_clear_m: f64,
}

impl Default for BehaviourConfig {
    fn default() -> Self {
        Self {
            confirm_frames: 3,
            window_frames: 5,
            standstill_mps: 0.01,
            stop_trigger_m: 0.9,
            stop_window_m: [0.5, 1.0],
            stop_hold_s: 5.0,
            stop_ignore_m: 1.0,
            stop_ignore_s: 2.0,
            light_trigger_m: 1.0,
            green_confirm_frames: 2,
            light_lost_s: 3.0,
            obstacle_stop_m: 0.45,
            obstacle_lane_half_m: 0.12,
            pass_enabled: false,
            pass_trigger_m: 0.85,
            pass_wait_s: 1.0,
            pass_steer: 0.8,
            pass_turn_m: 0.6,
            pass_along_m: 0.3,
            pass_throttle: 0.35,
            pass_return_m: 3.5,
            lost_throttle: 0.2,
            lost_stop_s: 1.0,
            yield_slow_m: 1.0,
            yield_creep: 0.25,
            yield_clear_m: 1.2,
        }
    }
}

impl BehaviourConfig {
    /// Range checks of `[behaviour]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let b = self;
        c.range("behaviour.window_frames", b.window_frames, 1, 32);
        c.range(
            "behaviour.confirm_frames",
            b.confirm_frames,
            1,
            b.window_frames.clamp(1, 32),
        );
        c.range("behaviour.standstill_mps", b.standstill_mps, 0.0, 1.0);
        c.range("behaviour.stop_trigger_m", b.stop_trigger_m, 0.05, 10.0);
        c.range(
            "behaviour.stop_window_m[0]",
            b.stop_window_m[0],
            0.0,
            b.stop_window_m[1],
        );
        c.range("behaviour.stop_window_m[1]", b.stop_window_m[1], 0.0, 10.0);
        c.range("behaviour.stop_hold_s", b.stop_hold_s, 0.0, 600.0);
        c.range("behaviour.stop_ignore_m", b.stop_ignore_m, 0.0, 100.0);
        c.range("behaviour.stop_ignore_s", b.stop_ignore_s, 0.0, 600.0);
        c.range("behaviour.light_trigger_m", b.light_trigger_m, 0.05, 10.0);
        c.range("behaviour.green_confirm_frames", b.green_confirm_frames, 1, 32);
        c.range("behaviour.light_lost_s", b.light_lost_s, 0.0, 600.0);
        c.range("behaviour.obstacle_stop_m", b.obstacle_stop_m, 0.05, 10.0);
        c.range("behaviour.obstacle_lane_half_m", b.obstacle_lane_half_m, 0.0, 2.0);
        c.range("behaviour.pass_trigger_m", b.pass_trigger_m, 0.05, 10.0);
        c.range("behaviour.pass_wait_s", b.pass_wait_s, 0.0, 60.0);
        c.range("behaviour.pass_steer", b.pass_steer, 0.05, 1.0);
        c.range("behaviour.pass_turn_m", b.pass_turn_m, 0.05, 5.0);
        c.range("behaviour.pass_along_m", b.pass_along_m, 0.0, 10.0);
        c.range("behaviour.pass_throttle", b.pass_throttle, 0.0, 1.0);
        c.range("behaviour.pass_return_m", b.pass_return_m, 0.1, 50.0);
        c.range("behaviour.lost_throttle", b.lost_throttle, 0.0, 1.0);
        c.range("behaviour.lost_stop_s", b.lost_stop_s, 0.0, 60.0);
        c.range("behaviour.yield_slow_m", b.yield_slow_m, 0.05, 10.0);
        c.range("behaviour.yield_creep", b.yield_creep, 0.0, 1.0);
        c.range("behaviour.yield_clear_m", b.yield_clear_m, 0.05, 10.0);
    }
}

impl From<&BehaviourConfig> for BehaviourOptions {
    /// The state machine's thresholds of `[behaviour]` (`stop_window_m` and `pass_return_m`
    /// are the simulator's score, not the machine's).
    fn from(b: &BehaviourConfig) -> Self {
        Self {
            confirm_frames: b.confirm_frames,
            window_frames: b.window_frames,
            standstill_mps: b.standstill_mps,
            stop_trigger_m: b.stop_trigger_m,
            stop_hold_s: b.stop_hold_s,
            stop_ignore_m: b.stop_ignore_m,
            stop_ignore_s: b.stop_ignore_s,
            light_trigger_m: b.light_trigger_m,
            green_confirm_frames: b.green_confirm_frames,
            light_lost_s: b.light_lost_s,
            obstacle_stop_m: b.obstacle_stop_m,
            obstacle_lane_half_m: b.obstacle_lane_half_m,
            pass_enabled: b.pass_enabled,
            pass_trigger_m: b.pass_trigger_m,
            pass_wait_s: b.pass_wait_s,
            pass_steer: b.pass_steer,
            pass_turn_m: b.pass_turn_m,
            pass_along_m: b.pass_along_m,
            pass_throttle: b.pass_throttle,
            lost_throttle: b.lost_throttle,
            lost_stop_s: b.lost_stop_s,
            yield_slow_m: b.yield_slow_m,
            yield_creep: b.yield_creep,
            yield_clear_m: b.yield_clear_m,
        }
    }
}
