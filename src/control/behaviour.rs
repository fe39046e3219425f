//! The behaviour state machine: what the car does about stop signs, traffic lights, obstacles
//! and a lost lane, on top of lane keeping (the seed paper's Sec. 3.3 behaviours, written as
//! an explicit machine instead of flags and blocking delays in the firmware).
//!
//! ```text
//!            stop sign confirmed < stop_trigger_m          standstill + stop_hold_s
//!   Cruise ─────────────────────────────────► StopSign ───────────────────────────► Cruise
//!     │  ▲  red/amber confirmed < light_trigger_m            (ignore signs for stop_ignore_m / _s)
//!     │  └───────────────────────────────────── RedLight ◄── green in green_confirm_frames
//!     │  obstacle in lane < obstacle_stop_m                   (or no light for light_lost_s)
//!     ├─────────────────────────────────────► Obstacle ──(pass_enabled, stood pass_wait_s)──►
//!     │                                         PassOut → PassAlong → PassBack → Cruise
//!     ├── yield sign confirmed < yield_slow_m ──► Yield (throttle ≤ yield_creep) ── passed ──► Cruise
//!     │                obstacle in lane < yield_clear_m ──► YieldStop ── lane clear ──► Yield
//!     └── lane lost ──► LaneLost (lost_throttle, then 0 after lost_stop_s) ── lane seen ──► Cruise
//! ```
//!
//! Priorities: an obstacle in the lane beats everything but a pass under way; a red light
//! beats a stop sign. A stop sign confirmed while passing is remembered and obeyed as soon as
//! the car is back in its lane (it never stops in the other lane). A yield sign comes after
//! both; a turn sign is only observed (the route takes it; no throttle behaviour).
//!
//! Time and observations are passed in ([`Behaviour::step`]); the machine never reads a clock,
//! so every test is deterministic. The car has no wheel encoder: speed and distance come from
//! [`DeadReckoning`], the commanded throttle run through the `[vehicle]` speed model
//! (`v̇ = (throttle · max_speed − v) / τ`).
//!
//! Units: metres, seconds, m/s; distances are forward distances from the lens.

use serde::{Deserialize, Serialize};

/// The machine's thresholds (`[behaviour]` of car.toml converts into them; docs/behaviour.md).
/// Units: metres (forward distances from the lens), seconds, m/s; frames for the windows.
#[derive(Debug, Clone, PartialEq)]
pub struct BehaviourOptions {
    /// A detection is confirmed when seen in `confirm_frames` of the last `window_frames`.
    pub confirm_frames: u32,
    /// Length of the confirmation window, frames.
    pub window_frames: u32,
    /// Below this estimated speed the car counts as stopped, m/s.
    pub standstill_mps: f64,
    /// Stop for a stop sign confirmed nearer than this, metres.
    pub stop_trigger_m: f64,
    /// Stand at a stop sign this long from standstill, seconds.
    pub stop_hold_s: f64,
    /// After a stop sign, ignore stop signs for this distance, metres...
    pub stop_ignore_m: f64,
    /// ...and at least this long, seconds.
    pub stop_ignore_s: f64,
    /// Stop for a red or amber light confirmed nearer than this, metres.
    pub light_trigger_m: f64,
    /// Green in this many consecutive frames releases a red-light stop.
    pub green_confirm_frames: u32,
    /// A red-light stop also ends after no light for this long, seconds.
    pub light_lost_s: f64,
    /// Stop while an obstacle in the lane is nearer than this, metres.
    pub obstacle_stop_m: f64,
    /// An obstacle is in the lane when its centre is within this of the car's axis, metres.
    pub obstacle_lane_half_m: f64,
    /// Pass a blocking obstacle through the other (left) lane.
    pub pass_enabled: bool,
    /// With passing, stop this far before an obstacle instead, metres.
    pub pass_trigger_m: f64,
    /// Stand this long before passing, seconds.
    pub pass_wait_s: f64,
    /// Steering of each half of the lane change, 0..=1.
    pub pass_steer: f64,
    /// Distance of each half of the lane change, metres.
    pub pass_turn_m: f64,
    /// Distance in the other lane before changing back, metres.
    pub pass_along_m: f64,
    /// Throttle while passing, 0..=1.
    pub pass_throttle: f64,
    /// Throttle while the lane is lost, before stopping, 0..=1.
    pub lost_throttle: f64,
    /// Stop after the lane has been lost this long, seconds.
    pub lost_stop_s: f64,
    /// Slow down for a yield sign confirmed nearer than this, metres.
    pub yield_slow_m: f64,
    /// Throttle cap while yielding, 0..=1.
    pub yield_creep: f64,
    /// While yielding, an obstacle in the lane nearer than this stops the car, metres.
    pub yield_clear_m: f64,
}

/// A traffic light's colour as the detector read it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightColor {
    /// Stop.
    Red,
    /// Stop if you can (treated as red).
    Amber,
    /// Go.
    Green,
    /// A light is there but its lamp could not be read.
    Unknown,
}

/// One ranged object.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ranged {
    /// Forward distance from the lens, metres.
    pub distance_m: f64,
    /// Lateral offset from the car's axis, metres, positive = left.
    pub lateral_m: f64,
}

/// What the car perceives and knows in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Observations {
    /// The lane was measured this frame.
    pub lane_seen: bool,
    /// The nearest stop sign, if any.
    pub stop_sign: Option<Ranged>,
    /// The nearest traffic light and its colour, if any.
    pub light: Option<(Ranged, LightColor)>,
    /// The nearest obstacle, if any (the machine decides whether it is in the lane).
    pub obstacle: Option<Ranged>,
    /// The nearest yield sign, if any.
    pub yield_sign: Option<Ranged>,
    /// The nearest turn sign and its arrow, if any (for the route; no throttle behaviour).
    pub turn_sign: Option<(Ranged, crate::classes::TurnArrow)>,
    /// Estimated speed, m/s (from [`DeadReckoning`]).
    pub speed_mps: f64,
    /// Estimated distance driven since the start, metres.
    pub odometry_m: f64,
    /// A stop or give-way line across the lane, seen in the bird's-eye image this frame.
    pub stop_line: Option<crate::lane::stop_line::StopLineSeen>,
}

/// The states of the machine (no data: the timers live in [`Behaviour`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Lane keeping.
    Cruise,
    /// Stopping for, or standing at, a stop sign.
    StopSign,
    /// Stopping for, or waiting at, a red light.
    RedLight,
    /// Standing before an obstacle in the lane.
    Obstacle,
    /// Changing into the other lane (an S: left, then right).
    PassOut,
    /// Lane keeping in the other lane, past the obstacle.
    PassAlong,
    /// Changing back (right, then left).
    PassBack,
    /// The lane is not seen: slow, then stop.
    LaneLost,
    /// Creeping past a yield sign.
    Yield,
    /// At a yield sign with an obstacle in the lane: stopping at the yield point (or before
    /// the obstacle) and standing while it stays.
    YieldStop,
}

impl Mode {
    /// A state in which standing still is intended (stop sign, red light, obstacle, yielding
    /// to one).
    pub fn is_waiting(self) -> bool {
        matches!(self, Mode::StopSign | Mode::RedLight | Mode::Obstacle | Mode::YieldStop)
    }

    /// One of the three passing states (the car may be in the other lane).
    pub fn is_passing(self) -> bool {
        matches!(self, Mode::PassOut | Mode::PassAlong | Mode::PassBack)
    }

    /// The name used in telemetry.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Cruise => "cruise",
            Mode::StopSign => "stop_sign",
            Mode::RedLight => "red_light",
            Mode::Obstacle => "obstacle",
            Mode::PassOut => "pass_out",
            Mode::PassAlong => "pass_along",
            Mode::PassBack => "pass_back",
            Mode::LaneLost => "lane_lost",
            Mode::Yield => "yield",
            Mode::YieldStop => "yield_stop",
        }
    }
}

/// A change of state and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transition {
    /// State left.
    pub from: Mode,
    /// State entered.
    pub to: Mode,
    /// Why, for people reading telemetry.
    pub reason: String,
}

/// What the machine asks of the controller this frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The state after this step.
    pub mode: Mode,
    /// `Some(t)`: drive with throttle `t` instead of the lane controller's; `None`: lane
    /// controller's throttle.
    pub throttle: Option<f64>,
    /// `Some(s)`: steer `s` instead of following the lane (lane change).
    pub steer: Option<f64>,
    /// Upper limit on whatever throttle results (1 = none).
    pub throttle_cap: f64,
}

/// Speed and distance from the commanded throttle through the `[vehicle]` model (no encoder).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeadReckoning {
    max_speed: f64,
    tau: f64,
    /// Estimated speed, m/s.
    pub speed_mps: f64,
    /// Estimated distance driven, metres.
    pub odometry_m: f64,
}

impl DeadReckoning {
    /// At rest, with the speed model of `[vehicle]`: `max_speed_mps` at full throttle, reached
    /// with the time constant `speed_tau_s` seconds (0 = at once).
    pub fn new(max_speed_mps: f64, speed_tau_s: f64) -> Self {
        Self {
            max_speed: max_speed_mps,
            tau: speed_tau_s,
            speed_mps: 0.0,
            odometry_m: 0.0,
        }
    }

    /// The throttle `throttle` was held for `dt` seconds: the exact solution of the first-order
    /// lag over the step, and the distance it covers.
    pub fn advance(&mut self, throttle: f64, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let target = throttle.clamp(-1.0, 1.0) * self.max_speed;
        let v0 = self.speed_mps;
        if self.tau > 0.0 {
            let e = (-dt / self.tau).exp();
            let v1 = target + (v0 - target) * e;
            // ∫ v dt over the step.
            self.odometry_m += (target * dt + (v0 - target) * self.tau * (1.0 - e)).abs();
            self.speed_mps = v1;
        } else {
            self.odometry_m += (target * dt).abs();
            self.speed_mps = target;
        }
    }
}

/// A bit per frame: was the condition true in the last frames?
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Window(u32);

impl Window {
    fn push(&mut self, hit: bool) {
        self.0 = (self.0 << 1) | hit as u32;
    }
    /// Hits among the last `m` frames.
    fn count(self, m: u32) -> u32 {
        let mask = if m >= 32 { u32::MAX } else { (1u32 << m) - 1 };
        (self.0 & mask).count_ones()
    }
    /// The last `n` frames were all hits.
    fn last_all(self, n: u32) -> bool {
        self.count(n) == n.min(32)
    }
}

/// The behaviour state machine.
#[derive(Debug, Clone)]
pub struct Behaviour {
    cfg: BehaviourOptions,
    mode: Mode,
    /// When the current mode was entered, seconds.
    since: f64,
    /// Odometry when the current mode was entered, metres.
    since_odo: f64,
    /// When the car came to rest in the current stop, seconds.
    standstill_since: Option<f64>,
    /// Stop signs are ignored until both have passed.
    ignore_until_s: f64,
    ignore_until_odo: f64,
    /// A stop sign was confirmed while passing: obey it when back in the lane.
    pending_stop: bool,
    /// Last time a traffic light was seen, seconds.
    light_seen_at: f64,
    lane_lost_since: Option<f64>,
    /// Odometry when the lane was lost (a yielding car creeps across a crossing's gap).
    lane_lost_odo: Option<f64>,
    /// Odometry at which the car reaches the confirmed yield point ([`yield_point_m`]).
    yield_at_odo: f64,
    /// Distance of the obstacle that blocks a yield when last seen, metres.
    yield_obstacle_m: f64,
    yield_w: Window,
    yield_block_w: Window,
    stop_w: Window,
    red_w: Window,
    green_w: Window,
    obstacle_w: Window,
    /// The transition of the last step.
    last: Option<Transition>,
    /// Stopping at a line across the lane ([`Behaviour::stop_line_distance`]).
    line: LineStop,
}

/// A stop sign with a line across the lane stops with the car's front at the line's near
/// edge. The car's front is its front axle (`vehicle.wheelbase_m` ahead of the rear axle, so
/// `wheelbase_m − camera_x_m` ahead of the lens). The line is remembered in odometry, since it
/// leaves the camera's view about 0.4 m before the car reaches it.
#[derive(Debug, Clone, Copy, Default)]
struct LineStop {
    /// The car's front ahead of the lens, metres.
    front_m: f64,
    /// The speed model (`[vehicle]`), for the approach; `None` until [`Behaviour::set_car`].
    car: Option<DeadReckoning>,
    /// Odometry at which the front reaches the last line seen, and whether it is dashed.
    at: Option<(f64, bool)>,
    /// The previous step's time, seconds.
    prev_s: Option<f64>,
    /// The last step's time step, seconds.
    dt: f64,
    /// The last step's estimated speed, m/s.
    speed: f64,
}

/// A line belongs to a stop sign when it lies at most this far beyond the sign, metres.
pub const LINE_PAST_SIGN_M: f64 = 0.3;

/// Two sightings of a line across the lane are the same line when they place it within this
/// distance of each other on the floor, metres (a frame's ranging error is ~1 cm).
const LINE_SAME_M: f64 = 0.1;

impl Behaviour {
    /// A machine in `Cruise` at time 0.
    pub fn new(cfg: BehaviourOptions) -> Self {
        Self {
            cfg,
            mode: Mode::Cruise,
            since: 0.0,
            since_odo: 0.0,
            standstill_since: None,
            ignore_until_s: f64::NEG_INFINITY,
            ignore_until_odo: f64::NEG_INFINITY,
            pending_stop: false,
            light_seen_at: f64::NEG_INFINITY,
            lane_lost_since: None,
            lane_lost_odo: None,
            yield_at_odo: f64::NEG_INFINITY,
            yield_obstacle_m: f64::INFINITY,
            yield_w: Window::default(),
            yield_block_w: Window::default(),
            stop_w: Window::default(),
            red_w: Window::default(),
            green_w: Window::default(),
            obstacle_w: Window::default(),
            last: None,
            line: LineStop::default(),
        }
    }

    /// The car the machine drives: its front `front_m` metres ahead of the lens (the front
    /// axle: `vehicle.wheelbase_m − vehicle.camera_x_m`) and its speed model (`[vehicle]`).
    /// Without it a stop sign never stops at a line (the car stops where the trigger puts it).
    pub fn set_car(&mut self, front_m: f64, model: DeadReckoning) {
        self.line.front_m = front_m;
        self.line.car = Some(model);
    }

    /// Distance to stop at for a sign `sign_m` metres from the lens (`None`: the caller's
    /// own), at odometry `odo`: from the car's front to the near edge of the line across the
    /// lane seen last, when one lies ahead and at most [`LINE_PAST_SIGN_M`] beyond the sign;
    /// with whether it is dashed. `None` without a line: stop at the ranged distance.
    pub fn stop_line_distance(&self, odo: f64, sign_m: Option<f64>) -> Option<(f64, bool)> {
        let (at, dashed) = self.line.at?;
        let d = at - odo;
        let reach = sign_m.unwrap_or(self.cfg.stop_trigger_m) - self.line.front_m + LINE_PAST_SIGN_M;
        (self.line.car.is_some() && d > -0.1 && d <= reach).then_some((d, dashed))
    }

    /// The current state.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The transition made by the last [`Behaviour::step`], if any.
    pub fn last_transition(&self) -> Option<&Transition> {
        self.last.as_ref()
    }

    /// The thresholds in use.
    pub fn options(&self) -> &BehaviourOptions {
        &self.cfg
    }

    fn go(&mut self, to: Mode, now: f64, odo: f64, reason: String) {
        self.last = Some(Transition {
            from: self.mode,
            to,
            reason,
        });
        self.mode = to;
        self.since = now;
        self.since_odo = odo;
        self.standstill_since = None;
    }

    fn confirmed(&self, w: Window) -> bool {
        w.count(self.cfg.window_frames) >= self.cfg.confirm_frames
    }

    /// One step at time `now` (seconds, any origin, non-decreasing) with this frame's
    /// observations. Returns what the controller should do.
    pub fn step(&mut self, obs: &Observations, now: f64) -> Decision {
        self.last = None;
        // 1. Per-frame evidence into the confirmation windows.
        let e = self.evidence(obs, now);
        // 2. Transitions: the obstacle first (safety), then each state's own exits.
        self.transition(obs, now, e);
        // 3. What the new state asks for.
        self.decision(now, obs.odometry_m)
    }

    /// Step 1 of [`Behaviour::step`]: this frame's evidence into the confirmation windows,
    /// the standstill and lane-lost clocks; what is confirmed.
    fn evidence(&mut self, obs: &Observations, now: f64) -> Evidence {
        let c = &self.cfg;
        let odo = obs.odometry_m;
        // A line across the lane: remembered in odometry, forgotten once passed.
        self.line.dt = self.line.prev_s.map_or(0.0, |t| now - t);
        self.line.prev_s = Some(now);
        self.line.speed = obs.speed_mps;
        if let Some(l) = obs.stop_line {
            let seen = odo + l.distance_m - self.line.front_m;
            // The nearest line ahead is the one to stop at: once it has left the view (about
            // 0.4 m before the car reaches it), a line further on (the edge of the road being
            // crossed, seen as the car creeps up) does not replace it until it is passed.
            let nearer_ahead = self
                .line
                .at
                .is_some_and(|(at, _)| at - odo > -0.1 && seen > at + LINE_SAME_M);
            if !nearer_ahead {
                self.line.at = Some((seen, l.dashed));
            }
        } else if self.line.at.is_some_and(|(at, _)| odo > at + 0.5) {
            self.line.at = None;
        }
        let ignoring = now < self.ignore_until_s || odo < self.ignore_until_odo;
        let stop_near = obs.stop_sign.is_some_and(|s| s.distance_m < c.stop_trigger_m);
        self.stop_w.push(stop_near && !ignoring);
        let (red_near, green) = match obs.light {
            Some((r, col)) => {
                self.light_seen_at = now;
                (
                    matches!(col, LightColor::Red | LightColor::Amber) && r.distance_m < c.light_trigger_m,
                    col == LightColor::Green,
                )
            }
            None => (false, false),
        };
        self.red_w.push(red_near);
        self.green_w.push(green);
        // Passing needs room to swing out: then the car stops further back.
        let stop_m = if c.pass_enabled {
            c.obstacle_stop_m.max(c.pass_trigger_m)
        } else {
            c.obstacle_stop_m
        };
        let blocking = obs
            .obstacle
            .is_some_and(|o| o.distance_m < stop_m && o.lateral_m.abs() <= c.obstacle_lane_half_m);
        self.obstacle_w.push(blocking);
        let stop_ok = self.confirmed(self.stop_w);
        let red_ok = self.confirmed(self.red_w);
        let green_ok = self.green_w.last_all(c.green_confirm_frames);
        let obstacle_ok = self.confirmed(self.obstacle_w);
        let obstacle_gone = self.obstacle_w.count(c.window_frames) == 0;
        // Yield: the sign near, and what blocks the lane ahead while yielding.
        let yield_at = yield_point_m(obs);
        self.yield_w.push(yield_at.is_some_and(|d| d < c.yield_slow_m));
        let yield_ok = self.confirmed(self.yield_w);
        if let (true, Some(d)) = (yield_ok, yield_at) {
            // A give-way (or stop) line across the lane near the sign is where to stand.
            self.yield_at_odo = odo + self.stop_line_distance(odo, Some(d)).map_or(d, |(l, _)| l);
        }
        let block = obs
            .obstacle
            .filter(|o| o.distance_m < c.yield_clear_m && o.lateral_m.abs() <= c.obstacle_lane_half_m);
        self.yield_block_w.push(block.is_some());
        if let Some(o) = block {
            self.yield_obstacle_m = o.distance_m;
        }
        let yield_blocked = self.confirmed(self.yield_block_w);
        let yield_clear = self.yield_block_w.count(c.window_frames) == 0;
        let still = obs.speed_mps.abs() < c.standstill_mps;
        if still && self.standstill_since.is_none() {
            self.standstill_since = Some(now);
        }
        if !still {
            self.standstill_since = None;
        }
        self.lane_lost_since = if obs.lane_seen {
            None
        } else {
            Some(self.lane_lost_since.unwrap_or(now))
        };
        self.lane_lost_odo = if obs.lane_seen { None } else { Some(self.lane_lost_odo.unwrap_or(odo)) };
        let in_pass = matches!(self.mode, Mode::PassOut | Mode::PassAlong | Mode::PassBack);
        if in_pass && stop_ok {
            self.pending_stop = true;
        }
        Evidence {
            stop_ok,
            red_ok,
            green_ok,
            obstacle_ok,
            obstacle_gone,
            in_pass,
            yield_ok: yield_ok || odo < self.yield_at_odo,
            yield_blocked,
            yield_clear,
        }
    }

    /// Step 2 of [`Behaviour::step`]: the transitions, the obstacle first (safety), then each
    /// state's own exits.
    fn transition(&mut self, obs: &Observations, now: f64, e: Evidence) {
        let c = &self.cfg;
        let odo = obs.odometry_m;
        let Evidence {
            stop_ok,
            red_ok,
            green_ok,
            obstacle_ok,
            obstacle_gone,
            in_pass,
            yield_ok,
            yield_blocked,
            yield_clear,
        } = e;
        // Yielding to it already: the yield stop stands at the line (an obstacle in the crossing
        // beyond the line is what a give-way line is for).
        if obstacle_ok && !in_pass && self.mode != Mode::Obstacle && self.mode != Mode::YieldStop {
            let d = obs.obstacle.map_or(f64::NAN, |o| o.distance_m);
            self.go(Mode::Obstacle, now, odo, format!("obstacle in lane at {d:.2} m"));
        } else {
            match self.mode {
                Mode::Cruise | Mode::LaneLost => {
                    if red_ok {
                        let d = obs.light.map_or(f64::NAN, |l| l.0.distance_m);
                        self.go(Mode::RedLight, now, odo, format!("red light at {d:.2} m"));
                    } else if stop_ok || self.pending_stop {
                        let why = if self.pending_stop {
                            "stop sign seen while passing".to_string()
                        } else {
                            let d = obs.stop_sign.map_or(f64::NAN, |s| s.distance_m);
                            match self.stop_line_distance(odo, Some(d)) {
                                Some((l, _)) => format!("stop sign at {d:.2} m, line {l:.2} m ahead"),
                                None => format!("stop sign at {d:.2} m"),
                            }
                        };
                        self.pending_stop = false;
                        self.go(Mode::StopSign, now, odo, why);
                    } else if yield_ok && obs.lane_seen {
                        let d = self.yield_at_odo - odo;
                        self.go(Mode::Yield, now, odo, format!("yield sign at {d:.2} m"));
                    } else if self.mode == Mode::Cruise && !obs.lane_seen {
                        self.go(Mode::LaneLost, now, odo, "lane not seen".into());
                    } else if self.mode == Mode::LaneLost && obs.lane_seen {
                        self.go(Mode::Cruise, now, odo, "lane seen again".into());
                    }
                }
                Mode::StopSign => {
                    // Hold counted from standstill.
                    if let Some(t0) = self.standstill_since {
                        if now - t0 >= c.stop_hold_s - 1e-9 {
                            self.ignore_until_s = now + c.stop_ignore_s;
                            self.ignore_until_odo = odo + c.stop_ignore_m;
                            self.stop_w = Window::default();
                            self.line.at = None;
                            let held = now - t0;
                            self.go(Mode::Cruise, now, odo, format!("held {held:.2} s at the stop sign"));
                        }
                    }
                }
                Mode::RedLight => {
                    if green_ok {
                        self.red_w = Window::default();
                        self.go(Mode::Cruise, now, odo, "green light".into());
                    } else if now - self.light_seen_at >= c.light_lost_s {
                        self.red_w = Window::default();
                        self.go(
                            Mode::Cruise,
                            now,
                            odo,
                            format!("no light seen for {:.1} s", c.light_lost_s),
                        );
                    }
                }
                Mode::Obstacle => {
                    if obstacle_gone {
                        self.go(Mode::Cruise, now, odo, "lane clear".into());
                    } else if c.pass_enabled && self.standstill_since.is_some_and(|t0| now - t0 >= c.pass_wait_s) {
                        self.go(Mode::PassOut, now, odo, "passing the obstacle".into());
                    }
                }
                Mode::Yield => {
                    if yield_blocked {
                        let d = self.yield_obstacle_m;
                        let why = format!("yielding: obstacle in lane at {d:.2} m");
                        self.go(Mode::YieldStop, now, odo, why);
                    } else if odo >= self.yield_at_odo {
                        self.yield_at_odo = f64::NEG_INFINITY;
                        self.yield_w = Window::default();
                        self.go(Mode::Cruise, now, odo, "past the yield sign".into());
                    } else if self.lane_lost_odo.is_some_and(|o0| odo - o0 > YIELD_LOST_M) {
                        // A crossing's gap in the lines is short; creeping, it takes a while.
                        self.go(Mode::LaneLost, now, odo, "lane not seen".into());
                    }
                }
                Mode::YieldStop => {
                    if yield_clear {
                        self.yield_obstacle_m = f64::INFINITY;
                        self.go(Mode::Yield, now, odo, "lane clear".into());
                    }
                }
                Mode::PassOut => {
                    if odo - self.since_odo >= 2.0 * c.pass_turn_m {
                        self.go(Mode::PassAlong, now, odo, "in the other lane".into());
                    }
                }
                Mode::PassAlong => {
                    if odo - self.since_odo >= c.pass_along_m {
                        self.go(Mode::PassBack, now, odo, "past the obstacle".into());
                    }
                }
                Mode::PassBack => {
                    if odo - self.since_odo >= 2.0 * c.pass_turn_m {
                        self.obstacle_w = Window::default();
                        self.go(Mode::Cruise, now, odo, "back in the lane".into());
                    }
                }
            }
        }
    }

    /// Step 3 of [`Behaviour::step`]: what the new state asks for at `now`, odometry `odo`.
    fn decision(&self, now: f64, odo: f64) -> Decision {
        let c = &self.cfg;
        let driven = odo - self.since_odo;
        let mut throttle_cap = 1.0;
        let (throttle, steer) = match self.mode {
            Mode::Cruise => (None, None),
            // With a line ahead: the lane's throttle, capped so the car comes to rest at it.
            Mode::StopSign if self.stop_line_distance(odo, None).is_some() => {
                throttle_cap = self.line_approach(odo);
                (None, None)
            }
            Mode::StopSign | Mode::RedLight | Mode::Obstacle => (Some(0.0), None),
            // An S: first half towards the other lane, second half straightening up.
            Mode::PassOut => {
                let s = if driven < c.pass_turn_m {
                    -c.pass_steer
                } else {
                    c.pass_steer
                };
                (Some(c.pass_throttle), Some(s))
            }
            Mode::PassAlong => (Some(c.pass_throttle), None),
            Mode::PassBack => {
                let s = if driven < c.pass_turn_m {
                    c.pass_steer
                } else {
                    -c.pass_steer
                };
                (Some(c.pass_throttle), Some(s))
            }
            // A cap, so the lane controller's own lost-lane policy still applies when stricter.
            Mode::LaneLost => {
                let lost = self.lane_lost_since.map_or(0.0, |t0| now - t0);
                throttle_cap = if lost >= c.lost_stop_s { 0.0 } else { c.lost_throttle };
                (None, None)
            }
            // Creep; blocked, stand at the yield point or obstacle_stop_m before the obstacle.
            // With a line: roll to rest with the front on it (as at a stop sign's line).
            Mode::Yield | Mode::YieldStop => {
                throttle_cap = c.yield_creep;
                if self.mode == Mode::YieldStop && self.stop_line_distance(odo, None).is_some() {
                    throttle_cap = throttle_cap.min(self.line_approach(odo));
                }
                // obstacle_stop_m before an obstacle, unless it stands beyond the line (in the
                // crossing): then the line.
                let beyond_line = self
                    .stop_line_distance(odo, None)
                    .is_some_and(|(l, _)| self.yield_obstacle_m > l + self.line.front_m);
                let at_point =
                    odo >= self.yield_at_odo || (!beyond_line && self.yield_obstacle_m <= c.obstacle_stop_m);
                let stand = self.mode == Mode::YieldStop && at_point;
                // Across a crossing's gap (lane lost) the throttle law would stop the car:
                // creep on, holding the steering (YIELD_LOST_M at most).
                let creep_blind = self.lane_lost_odo.is_some();
                let to_line = self.mode == Mode::YieldStop && self.stop_line_distance(odo, None).is_some();
                let throttle = if stand {
                    Some(0.0)
                } else if to_line {
                    // Rolling to rest with the front on the line, the lane seen or not.
                    Some(c.yield_creep.min(self.line_approach(odo)))
                } else if creep_blind {
                    Some(c.yield_creep)
                } else {
                    None
                };
                (throttle, None)
            }
        };
        Decision {
            mode: self.mode,
            throttle,
            steer,
            throttle_cap,
        }
    }
}

impl Behaviour {
    /// The throttle cap that brings the front to rest at the line (step 3, stop sign with a
    /// line). The speed model `v̇ = (u·V − v)/τ` held at `u` for one step `dt` and then at 0
    /// travels exactly `u·V·dt + v·τ` (the lag's integral), so
    /// `u = (d − v·τ) / (V·dt)`, clamped to 0..=1, puts the car's rest point on the line
    /// (recomputed every frame).
    fn line_approach(&self, odo: f64) -> f64 {
        let (Some((d, _)), Some(car)) = (self.stop_line_distance(odo, None), self.line.car) else {
            return 0.0;
        };
        let v = self.line.speed.max(0.0);
        let dt = if self.line.dt > 0.0 { self.line.dt } else { 1.0 / 30.0 };
        ((d - v * car.tau) / (car.max_speed * dt).max(1e-9)).clamp(0.0, 1.0)
    }
}

/// What one frame confirmed (step 1 of [`Behaviour::step`]).
#[derive(Debug, Clone, Copy)]
struct Evidence {
    stop_ok: bool,
    red_ok: bool,
    green_ok: bool,
    obstacle_ok: bool,
    obstacle_gone: bool,
    in_pass: bool,
    /// A yield sign confirmed near, or its point still ahead.
    yield_ok: bool,
    /// An obstacle confirmed in the lane within `yield_clear_m`.
    yield_blocked: bool,
    /// No such obstacle in the whole window.
    yield_clear: bool,
}

/// A yielding car goes on creeping with the lane lost for this far (a crossing's gap in the
/// lines, where a give-way sign stands), metres; then it is lane-lost as anywhere.
pub const YIELD_LOST_M: f64 = 0.8;

/// How far ahead of the lens a yielding car stops when the way is not clear, metres: the
/// yield sign's ranged distance; a line across the lane near it takes over where the sign's
/// point is set ([`Behaviour::stop_line_distance`]).
fn yield_point_m(obs: &Observations) -> Option<f64> {
    obs.yield_sign.map(|s| s.distance_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 1.0 / 30.0;

    /// The thresholds of the shipped `[behaviour]`.
    fn defaults() -> BehaviourOptions {
        BehaviourOptions {
            confirm_frames: 3,
            window_frames: 5,
            standstill_mps: 0.01,
            stop_trigger_m: 0.9,
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
            lost_throttle: 0.2,
            lost_stop_s: 1.0,
            yield_slow_m: 1.0,
            yield_creep: 0.25,
            yield_clear_m: 1.2,
        }
    }

    /// The speed model of the shipped `[vehicle]` (1 m/s at full throttle, τ = 0.3 s).
    fn car() -> DeadReckoning {
        DeadReckoning::new(1.0, 0.3)
    }

    /// A scripted run: a behaviour, a dead-reckoned car and a clock.
    struct Rig {
        b: Behaviour,
        car: DeadReckoning,
        t: f64,
        /// Distance of the scripted object from the lens at odometry 0.
        log: Vec<(f64, Mode, f64)>,
    }

    impl Rig {
        fn new(cfg: BehaviourOptions) -> Rig {
            Rig {
                b: Behaviour::new(cfg),
                car: car(),
                t: 0.0,
                log: Vec::new(),
            }
        }
        /// One frame: `f` makes the observations from the distance driven; lane throttle 0.5.
        fn frame(&mut self, f: impl Fn(f64) -> Observations) -> Decision {
            let mut o = f(self.car.odometry_m);
            o.speed_mps = self.car.speed_mps;
            o.odometry_m = self.car.odometry_m;
            let d = self.b.step(&o, self.t);
            let thr = d.throttle.unwrap_or(0.5).min(d.throttle_cap);
            self.car.advance(thr, DT);
            self.t += DT;
            self.log.push((self.t, d.mode, self.car.speed_mps));
            d
        }
    }

    fn at(d: f64) -> Ranged {
        Ranged {
            distance_m: d,
            lateral_m: 0.0,
        }
    }

    fn lane() -> Observations {
        Observations {
            lane_seen: true,
            ..Default::default()
        }
    }

    #[test]
    fn dead_reckoning_matches_the_vehicle_lag() {
        let mut c = car();
        for _ in 0..300 {
            c.advance(0.5, 0.01);
        }
        // 3 s = 10 τ: at 0.5 m/s; distance = 0.5·(3 − τ(1 − e^−10)).
        assert!((c.speed_mps - 0.5).abs() < 1e-3, "{}", c.speed_mps);
        assert!((c.odometry_m - 0.5 * (3.0 - 0.3)).abs() < 1e-3, "{}", c.odometry_m);
    }

    #[test]
    fn stop_sign_stop_hold_resume_and_ignore() {
        // A sign 2 m ahead of the start, seen on every frame while in front of the car.
        let sign = |odo: f64| Observations {
            stop_sign: (2.0 - odo > 0.3).then(|| at(2.0 - odo)),
            ..lane()
        };
        let mut r = Rig::new(defaults());
        let mut entered = None;
        let mut left = None;
        let mut stops = 0;
        for _ in 0..(20.0 / DT) as usize {
            let before = r.b.mode();
            let d = r.frame(sign);
            if before != Mode::StopSign && d.mode == Mode::StopSign {
                stops += 1;
                entered = Some(2.0 - r.car.odometry_m);
            }
            if before == Mode::StopSign && d.mode == Mode::Cruise {
                left = Some(r.t);
                assert!(r.b.last_transition().unwrap().reason.contains("held"));
            }
        }
        assert_eq!(stops, 1, "stopped once for the sign");
        // Triggered within 3 frames (≈ 5 cm) after crossing stop_trigger_m.
        let e = entered.unwrap();
        assert!(e < 0.9 && e > 0.8, "entered at {e} m");
        // Stood still (estimated speed < standstill) for 5 s ± one frame.
        let still: f64 = r
            .log
            .windows(2)
            .filter(|w| w[1].2 < 0.01 && w[0].2 < 0.01)
            .map(|w| w[1].0 - w[0].0)
            .sum();
        assert!((still - 5.0).abs() <= DT + 1e-9, "still {still} s");
        assert!(left.is_some());
        assert!(r.car.odometry_m > 2.0, "drove on past the sign");
    }

    #[test]
    fn stop_sign_with_a_line_stops_the_front_at_the_line() {
        // Sign 2 m ahead of the lens; a line's near edge 1.9 m ahead, seen while 0.4..1.0 m
        // away; the front 0.02 m ahead of the lens.
        let (front, line) = (0.02, 1.9);
        let obs = |odo: f64| Observations {
            stop_sign: (2.0 - odo > 0.3).then(|| at(2.0 - odo)),
            stop_line: (0.4..1.0)
                .contains(&(line - odo))
                .then_some(crate::lane::stop_line::StopLineSeen {
                    distance_m: line - odo,
                    dashed: false,
                    row: 0.0,
                }),
            ..lane()
        };
        // The front at rest at the line (within 2 mm), then on past it.
        let (rest, odo) = stop_and_go(front, obs);
        assert!((rest + front - line).abs() < 0.002, "front at {} m", rest + front);
        assert!(odo > line + 1.0);
        // Without `set_car` no line is used: the ranged stop, well before the line.
        let mut r = Rig::new(defaults());
        for _ in 0..(3.0 / DT) as usize {
            r.frame(obs);
        }
        assert!(r.car.odometry_m + front < line - 0.5, "{}", r.car.odometry_m);
    }

    /// Creeping up to a give-way line, the line leaves the view and the far edge of the road
    /// being crossed comes into it: the car still stops at the first line (it kept the line
    /// 0.25 m further and, that one lying beyond the sign's reach, stopped 10 cm short of
    /// the give-way line in the town).
    #[test]
    fn a_further_line_does_not_replace_the_nearer_one_ahead() {
        let (front, line, far) = (0.02, 1.9, 2.15);
        let seen = |odo: f64, at: f64| {
            (0.4..1.0)
                .contains(&(at - odo))
                .then_some(crate::lane::stop_line::StopLineSeen {
                    distance_m: at - odo,
                    dashed: false,
                    row: 0.0,
                })
        };
        let obs = |odo: f64| Observations {
            stop_sign: (2.0 - odo > 0.3).then(|| at(2.0 - odo)),
            // The first line while in view, then the road beyond it.
            stop_line: seen(odo, line).or_else(|| seen(odo, far)),
            ..lane()
        };
        let (rest, _) = stop_and_go(front, obs);
        assert!((rest + front - line).abs() < 0.002, "front at {} m", rest + front);
    }

    /// 20 s of a car whose front is `front` m ahead of the lens through the scene `obs`: the
    /// odometry where it went on after its stop-sign stop (entered for a line), and at the end.
    fn stop_and_go(front: f64, obs: impl Fn(f64) -> Observations) -> (f64, f64) {
        let mut r = Rig::new(defaults());
        r.b.set_car(front, car());
        let mut rest = None;
        for _ in 0..(20.0 / DT) as usize {
            let before = r.b.mode();
            let d = r.frame(&obs);
            if before == Mode::StopSign && d.mode == Mode::Cruise {
                rest = Some(r.car.odometry_m);
            }
            if before == Mode::Cruise && d.mode == Mode::StopSign {
                assert!(r.b.last_transition().unwrap().reason.contains("line"));
            }
        }
        (rest.expect("stopped and went on"), r.car.odometry_m)
    }

    #[test]
    fn flicker_of_one_frame_still_confirms_but_single_hits_do_not() {
        let cfg = defaults();
        // Seen, missed, seen, seen: 3 of the last 5 → confirmed on the 4th frame.
        let mut b = Behaviour::new(cfg.clone());
        let pattern = [true, false, true, true];
        let mut modes = vec![];
        for (k, &seen) in pattern.iter().enumerate() {
            let o = Observations {
                stop_sign: seen.then(|| at(0.6)),
                speed_mps: 0.5,
                ..lane()
            };
            modes.push(b.step(&o, k as f64 * DT).mode);
        }
        assert_eq!(modes, [Mode::Cruise, Mode::Cruise, Mode::Cruise, Mode::StopSign]);
        // One frame in three: never confirmed.
        let mut b = Behaviour::new(cfg);
        for k in 0..60 {
            let o = Observations {
                stop_sign: (k % 3 == 0).then(|| at(0.6)),
                speed_mps: 0.5,
                ..lane()
            };
            assert_eq!(b.step(&o, k as f64 * DT).mode, Mode::Cruise, "frame {k}");
        }
    }

    #[test]
    fn flicker_during_the_hold_does_not_restart_it() {
        let mut r = Rig::new(defaults());
        // The sign stays at 0.7 m (the car is scripted as if it never moves), flickering.
        let mut k = 0usize;
        let mut left_at = None;
        while r.t < 10.0 {
            k += 1;
            let seen = !k.is_multiple_of(4);
            let before = r.b.mode();
            let d = r.frame(|_| Observations {
                stop_sign: seen.then(|| at(0.7)),
                ..lane()
            });
            if before == Mode::StopSign && d.mode == Mode::Cruise {
                left_at = Some(r.t);
                break;
            }
        }
        // Standstill (< 0.01 m/s from 0.5 m/s at τ = 0.3 s) after ~1.2 s, then 5 s.
        let t = left_at.expect("resumed");
        let stood_from = r.log.iter().find(|l| l.1 == Mode::StopSign && l.2 < 0.01).unwrap().0;
        assert!(
            (t - stood_from - 5.0).abs() < 2.0 * DT,
            "left {t}, standing from {stood_from}"
        );
    }

    #[test]
    fn red_light_waits_for_green_within_two_frames() {
        let mut r = Rig::new(defaults());
        // Red until 6 s, then green; the light 1.6 m ahead of the start.
        let mut green_at_mode = None;
        for _ in 0..(10.0 / DT) as usize {
            let t = r.t;
            let col = if t < 6.0 { LightColor::Red } else { LightColor::Green };
            let d = r.frame(|odo| Observations {
                light: Some((at(1.6 - odo), col)),
                ..lane()
            });
            if t >= 6.0 && d.mode == Mode::Cruise && green_at_mode.is_none() {
                green_at_mode = Some(t);
            }
            if t < 6.0 && r.t > 3.0 {
                assert_eq!(d.mode, Mode::RedLight, "t = {t}");
            }
        }
        let g = green_at_mode.unwrap();
        // green_confirm_frames = 2: goes on the second green frame.
        assert!(g - 6.0 < 2.0 * DT + 1e-9 && g >= 6.0, "went at {g}");
        assert!(1.6 - r.car.odometry_m < 0.0, "drove past the light");
    }

    #[test]
    fn light_turning_green_while_stopping_releases_before_standstill() {
        let mut b = Behaviour::new(defaults());
        let mut t = 0.0;
        let mut step = |col, speed: f64| {
            let o = Observations {
                light: Some((at(0.8), col)),
                speed_mps: speed,
                ..lane()
            };
            t += DT;
            b.step(&o, t)
        };
        for _ in 0..3 {
            step(LightColor::Red, 0.5);
        }
        assert_eq!(step(LightColor::Red, 0.4).mode, Mode::RedLight);
        // Still rolling at 0.3 m/s when it turns green.
        assert_eq!(step(LightColor::Green, 0.3).mode, Mode::RedLight);
        let d = step(LightColor::Green, 0.2);
        assert_eq!(d.mode, Mode::Cruise);
        assert_eq!(d.throttle, None);
        // Amber on approach counts as red.
        let mut b = Behaviour::new(defaults());
        let mut m = Mode::Cruise;
        for k in 0..3 {
            let o = Observations {
                light: Some((at(0.8), LightColor::Amber)),
                speed_mps: 0.5,
                ..lane()
            };
            m = b.step(&o, k as f64 * DT).mode;
        }
        assert_eq!(m, Mode::RedLight);
    }

    #[test]
    fn far_red_light_or_sign_is_ignored() {
        let mut b = Behaviour::new(defaults());
        for k in 0..30 {
            let o = Observations {
                light: Some((at(1.5), LightColor::Red)),
                stop_sign: Some(at(1.2)),
                speed_mps: 0.5,
                ..lane()
            };
            assert_eq!(b.step(&o, k as f64 * DT).mode, Mode::Cruise);
        }
    }

    #[test]
    fn obstacle_stops_and_waits_then_goes_when_clear() {
        let mut b = Behaviour::new(defaults());
        let mut t = 0.0;
        let mut step = |ob: Option<Ranged>, speed: f64| {
            t += DT;
            b.step(
                &Observations {
                    obstacle: ob,
                    speed_mps: speed,
                    ..lane()
                },
                t,
            )
        };
        // Beside the lane: ignored.
        for _ in 0..10 {
            let side = Ranged {
                distance_m: 0.3,
                lateral_m: 0.3,
            };
            assert_eq!(step(Some(side), 0.5).mode, Mode::Cruise);
        }
        for _ in 0..3 {
            step(Some(at(0.4)), 0.5);
        }
        let d = step(Some(at(0.38)), 0.0);
        assert_eq!((d.mode, d.throttle), (Mode::Obstacle, Some(0.0)));
        // Passing disabled: waits as long as it is there.
        for _ in 0..300 {
            assert_eq!(step(Some(at(0.38)), 0.0).mode, Mode::Obstacle);
        }
        // Gone for a whole window: resumes.
        let mut m = Mode::Obstacle;
        for _ in 0..5 {
            m = step(None, 0.0).mode;
        }
        assert_eq!(m, Mode::Cruise);
    }

    #[test]
    fn passing_is_an_s_out_a_stretch_and_an_s_back() {
        let cfg = BehaviourOptions {
            pass_enabled: true,
            ..defaults()
        };
        let (turn, along) = (cfg.pass_turn_m, cfg.pass_along_m);
        let mut r = Rig::new(cfg);
        // Obstacle 1.0 m ahead of the start; visible in the lane until the car has left it.
        let mut steer_log = vec![];
        for _ in 0..(15.0 / DT) as usize {
            let passing = matches!(r.b.mode(), Mode::PassOut | Mode::PassAlong | Mode::PassBack)
                || r.log.iter().any(|l| l.1 == Mode::PassOut);
            let d = r.frame(|odo| Observations {
                obstacle: (!passing && 1.0 - odo > 0.0).then(|| at(1.0 - odo)),
                ..lane()
            });
            steer_log.push((r.car.odometry_m, d.mode, d.steer));
        }
        let first = |m: Mode| steer_log.iter().find(|l| l.1 == m).map(|l| l.0);
        let out = first(Mode::PassOut).expect("passed");
        let al = first(Mode::PassAlong).unwrap();
        let back = first(Mode::PassBack).unwrap();
        // Each phase lasts its configured distance (within one frame's travel, ≤ 1.2 cm).
        assert!((al - out - 2.0 * turn).abs() < 0.015, "{out} {al}");
        assert!((back - al - along).abs() < 0.015, "{al} {back}");
        // Steering: left, right, none, right, left.
        let signs: Vec<i32> =
            steer_log
                .iter()
                .map(|l| l.2.map_or(0, |s| s.signum() as i32))
                .fold(vec![], |mut v, s| {
                    if v.last() != Some(&s) {
                        v.push(s)
                    }
                    v
                });
        assert_eq!(signs, [0, -1, 1, 0, 1, -1, 0]);
        assert_eq!(r.b.mode(), Mode::Cruise);
    }

    #[test]
    fn a_sign_seen_while_passing_is_obeyed_after_returning() {
        let cfg = BehaviourOptions {
            pass_enabled: true,
            pass_wait_s: 0.0,
            ..defaults()
        };
        let mut b = Behaviour::new(cfg.clone());
        let mut car = car();
        let mut t = 0.0;
        let mut modes = vec![];
        for _ in 0..(25.0 / DT) as usize {
            let m = b.mode();
            let passing = matches!(m, Mode::PassOut | Mode::PassAlong | Mode::PassBack);
            let o = Observations {
                // The obstacle until the pass begins, a stop sign only during PassAlong.
                obstacle: (!modes.contains(&Mode::PassOut)).then(|| at(0.4)),
                stop_sign: (m == Mode::PassAlong).then(|| at(0.7)),
                speed_mps: car.speed_mps,
                odometry_m: car.odometry_m,
                ..lane()
            };
            let d = b.step(&o, t);
            if passing && matches!(d.mode, Mode::PassOut | Mode::PassAlong | Mode::PassBack) {
                // Never stops in the other lane.
                assert!(d.throttle.unwrap() > 0.0, "{:?}", d.mode);
            }
            if modes.last() != Some(&d.mode) {
                modes.push(d.mode);
            }
            car.advance(d.throttle.unwrap_or(0.5), DT);
            t += DT;
        }
        assert_eq!(
            modes,
            // Back in the lane (one frame of Cruise), then the remembered sign.
            [
                Mode::Cruise,
                Mode::Obstacle,
                Mode::PassOut,
                Mode::PassAlong,
                Mode::PassBack,
                Mode::Cruise,
                Mode::StopSign,
                Mode::Cruise
            ],
            "{modes:?}"
        );
    }

    #[test]
    fn lane_lost_slows_then_stops_then_recovers() {
        let mut b = Behaviour::new(defaults());
        let lost = Observations::default();
        let mut t = 0.0;
        let d = b.step(&lost, t);
        assert_eq!((d.mode, d.throttle_cap), (Mode::LaneLost, 0.2));
        while t < 0.9 {
            t += DT;
            assert_eq!(b.step(&lost, t).throttle_cap, 0.2);
        }
        t += 0.2;
        assert_eq!(b.step(&lost, t).throttle_cap, 0.0);
        let d = b.step(&lane(), t + DT);
        assert_eq!((d.mode, d.throttle), (Mode::Cruise, None));
        assert_eq!(b.last_transition().unwrap().reason, "lane seen again");
    }

    /// A yield sign 1.6 m ahead at odometry 0 (seen while more than 0.3 m ahead of the lens),
    /// and, with `obstacle`, an obstacle in the lane 0.6 m beyond it.
    fn yield_scene(odo: f64, obstacle: bool) -> Observations {
        let sign = 1.6 - odo;
        Observations {
            yield_sign: (sign > 0.3).then(|| at(sign)),
            obstacle: obstacle.then(|| at(sign + 0.6)),
            ..lane()
        }
    }

    #[test]
    fn yield_creeps_near_the_sign_and_cruises_past_it() {
        let mut r = Rig::new(defaults());
        let mut modes = vec![];
        for _ in 0..300 {
            let odo = r.car.odometry_m;
            let d = r.frame(|odo| yield_scene(odo, false));
            modes.push((odo, d.mode, d.throttle_cap));
        }
        // Cruise beyond yield_slow_m; creep (throttle capped) within; cruise again past it.
        let first = modes.iter().find(|m| m.1 == Mode::Yield).expect("yielded");
        assert!(first.0 > 0.55 && first.0 < 0.75, "slowed at odometry {}", first.0);
        assert!(modes.iter().filter(|m| m.1 == Mode::Yield).all(|m| m.2 == 0.25));
        assert!(modes.iter().all(|m| m.1 != Mode::YieldStop), "never stops when clear");
        let last = modes.iter().rposition(|m| m.1 == Mode::Yield).unwrap();
        let (before, after) = (modes[last], modes[last + 1]);
        assert!(before.0 < 1.6 && after.0 >= 1.6, "{before:?} {after:?}");
        assert_eq!(modes[last + 1].1, Mode::Cruise);
        // The creep is slower than cruising (lane throttle 0.5 in the rig: 0.5 m/s).
        let creeping = r.log.iter().rfind(|l| l.1 == Mode::Yield).unwrap().2;
        assert!((creeping - 0.25).abs() < 0.01, "{creeping}");
    }

    #[test]
    fn yield_stops_while_an_obstacle_is_in_the_lane_and_goes_when_clear() {
        let mut r = Rig::new(defaults());
        let mut stood = 0;
        let mut yield_stop_at = None;
        for _ in 0..400 {
            let d = r.frame(|odo| yield_scene(odo, true));
            if d.mode == Mode::YieldStop {
                yield_stop_at.get_or_insert(r.car.odometry_m);
                if r.car.speed_mps.abs() < 0.01 {
                    stood += 1;
                }
            }
        }
        assert!(yield_stop_at.is_some(), "stopped for the obstacle");
        assert!(stood > 30, "stood {stood} frames");
        // Stood at the sign (coasting from the creep, 0.25 m/s × τ 0.3 s + a frame, past it), well
        // before the obstacle.
        let odo = r.car.odometry_m;
        assert!((1.6..=1.6 + 0.09).contains(&odo), "stood at odometry {odo}");
        assert!(1.6 + 0.6 - odo >= defaults().obstacle_stop_m, "{odo}");
        assert_eq!(r.b.mode(), Mode::YieldStop);
        // It holds while the obstacle stays.
        for _ in 0..60 {
            assert_eq!(r.frame(|odo| yield_scene(odo, true)).throttle, Some(0.0));
        }
        // Clear: back to creeping, then past the sign to cruise.
        let mut seen = vec![];
        for _ in 0..200 {
            seen.push(r.frame(|odo| yield_scene(odo, false)).mode);
        }
        let lane_clear = seen.iter().position(|m| *m == Mode::Yield).expect("went on");
        assert!(lane_clear <= 5, "within a window: {lane_clear}");
        assert_eq!(*seen.last().unwrap(), Mode::Cruise);
        assert!(r.car.odometry_m > 1.7);
    }

    #[test]
    fn yield_ignores_an_obstacle_beside_the_lane_or_far_away() {
        let mut r = Rig::new(defaults());
        for _ in 0..300 {
            let d = r.frame(|odo| Observations {
                obstacle: Some(Ranged {
                    distance_m: 0.6,
                    lateral_m: 0.3,
                }),
                ..yield_scene(odo, false)
            });
            assert_ne!(d.mode, Mode::YieldStop);
        }
        assert_eq!(r.b.mode(), Mode::Cruise);
    }

    #[test]
    fn obstacle_beats_red_light_and_sign() {
        let mut b = Behaviour::new(defaults());
        let mut m = Mode::Cruise;
        for k in 0..4 {
            let o = Observations {
                obstacle: Some(at(0.3)),
                light: Some((at(0.5), LightColor::Red)),
                stop_sign: Some(at(0.5)),
                speed_mps: 0.5,
                ..lane()
            };
            m = b.step(&o, k as f64 * DT).mode;
        }
        assert_eq!(m, Mode::Obstacle);
    }
}
