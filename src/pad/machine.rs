//! The gamepad's mapping as a state machine without hardware: timestamped pad events in
//! (a stick moved, a button down or up, the pad connected or gone, a tick of time), what to do
//! out ([`PadAction`]). The device thread (`device.rs`, feature `gamepad`) and the tests with
//! recorded event sequences (`script.rs`, tests/data/pad/) feed the same machine.
//!
//! | pad (Linux code; Xbox label) | does |
//! |---|---|
//! | `BTN_TL` or `BTN_TR` (LB, RB) held | the dead-man: only while one is held does the pad drive |
//! | left stick sideways (`gamepad.steer_axis`, `ABS_X`) | steer, right = +1 |
//! | right stick up/down (`gamepad.throttle_axis`, `ABS_RY`) | throttle, up = forward |
//! | `BTN_EAST` (B) | emergency stop, at the press |
//! | `BTN_SELECT` (Back / View / Share) | disarm, at the press; held 2 s: release the e-stop |
//! | `BTN_START` (Start / Menu / Options) held `gamepad.arm_hold_ms` | arm (throttle stick centred) |
//! | `BTN_SOUTH` (A) | manual mode (take over from the autopilot) |
//! | `BTN_NORTH` (Y on most drivers) | next mode: manual → assisted → autopilot → manual |
//! | `BTN_WEST` (X) | toggle recording ([`PadAction::ToggleRecording`]) |
//!
//! While the dead-man is held the pad's input goes out on every stick change and again at
//! least every [`RESEND_MS`], so the car's input deadline (`manual.input_timeout_ms`, 250 ms)
//! never runs out while the sticks rest. Letting go of the dead-man sends neutral once, at that
//! event, and nothing more (the page or another input may drive then). The pad gone sends
//! neutral at once. Buttons held while the pad (re)connects count only after they are let go
//! and pressed again: a pad that comes back with the dead-man held does not drive off.

use crate::control::pilot::DriveMode;
use std::collections::BTreeSet;

/// Linux input event codes (linux/input-event-codes.h) the mapping uses.
pub mod code {
    /// Event type: a key or button.
    pub const EV_KEY: u16 = 0x01;
    /// Event type: an absolute axis.
    pub const EV_ABS: u16 = 0x03;
    /// A (the bottom face button).
    pub const BTN_SOUTH: u16 = 0x130;
    /// B (the right face button).
    pub const BTN_EAST: u16 = 0x131;
    /// Y on most drivers (the kernel's `BTN_NORTH` = `BTN_X`).
    pub const BTN_NORTH: u16 = 0x133;
    /// X on most drivers (the kernel's `BTN_WEST` = `BTN_Y`).
    pub const BTN_WEST: u16 = 0x134;
    /// LB, the left shoulder button.
    pub const BTN_TL: u16 = 0x136;
    /// RB, the right shoulder button.
    pub const BTN_TR: u16 = 0x137;
    /// Back / View / Share.
    pub const BTN_SELECT: u16 = 0x13a;
    /// Start / Menu / Options.
    pub const BTN_START: u16 = 0x13b;
    /// The left stick sideways.
    pub const ABS_X: u16 = 0x00;
    /// The left stick up/down.
    pub const ABS_Y: u16 = 0x01;
    /// The right stick up/down (xpad, hid-playstation).
    pub const ABS_RY: u16 = 0x04;

    /// Key and axis names as evtest prints them, for the recorded sequences.
    pub const NAMES: [(&str, u16); 18] = [
        ("BTN_SOUTH", BTN_SOUTH),
        ("BTN_A", BTN_SOUTH),
        ("BTN_EAST", BTN_EAST),
        ("BTN_B", BTN_EAST),
        ("BTN_NORTH", BTN_NORTH),
        ("BTN_WEST", BTN_WEST),
        ("BTN_TL", BTN_TL),
        ("BTN_TR", BTN_TR),
        ("BTN_SELECT", BTN_SELECT),
        ("BTN_START", BTN_START),
        ("BTN_MODE", 0x13c),
        ("ABS_X", ABS_X),
        ("ABS_Y", ABS_Y),
        ("ABS_Z", 0x02),
        ("ABS_RX", 0x03),
        ("ABS_RY", ABS_RY),
        ("ABS_RZ", 0x05),
        ("ABS_HAT0X", 0x10),
    ];

    /// The code of a name of [`NAMES`].
    pub fn by_name(name: &str) -> Option<u16> {
        NAMES.iter().find(|(n, _)| *n == name).map(|(_, c)| *c)
    }
}

/// Input goes out again at least this often while the dead-man is held, ms (25 Hz: five
/// chances within the 250 ms deadline).
pub const RESEND_MS: u64 = 40;

/// Back held this long releases the e-stop, ms.
pub const RELEASE_HOLD_MS: u64 = 2000;

/// An absolute axis's range as the device reports it (evdev's `input_absinfo`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisRange {
    /// The value at one end.
    pub min: i32,
    /// The value at the other end.
    pub max: i32,
}

impl AxisRange {
    /// An Xbox pad's sticks (xpad): −32768 ..= 32767.
    pub const STICK: AxisRange = AxisRange {
        min: -32768,
        max: 32767,
    };

    /// `value` as −1..1 (the middle of the range is 0).
    pub fn normalise(self, value: i32) -> f64 {
        let mid = (f64::from(self.min) + f64::from(self.max)) / 2.0;
        let half = (f64::from(self.max) - f64::from(self.min)) / 2.0;
        if half <= 0.0 {
            return 0.0;
        }
        ((f64::from(value) - mid) / half).clamp(-1.0, 1.0)
    }
}

/// Zero within `dz` of the centre, and the travel beyond it rescaled to start from 0 (full
/// stick stays 1).
pub fn dead_zone(x: f64, dz: f64) -> f64 {
    if x.abs() <= dz {
        0.0
    } else {
        (x.signum() * (x.abs() - dz) / (1.0 - dz)).clamp(-1.0, 1.0)
    }
}

/// The mode the mode button goes to from `m`: manual → assisted → autopilot → manual.
pub fn next_mode(m: DriveMode) -> DriveMode {
    match m {
        DriveMode::Manual => DriveMode::Assisted,
        DriveMode::Assisted => DriveMode::Autopilot,
        DriveMode::Autopilot => DriveMode::Manual,
    }
}

/// What a pad reports (the device thread's reading, or a line of a recorded sequence).
#[derive(Debug, Clone, PartialEq)]
pub enum PadEvent {
    /// A pad was found and opened (its name).
    Connected(String),
    /// An axis's range (after [`PadEvent::Connected`], before its values).
    Range {
        /// The axis code.
        code: u16,
        /// Its range.
        range: AxisRange,
    },
    /// A button: value 1 down, 0 up, 2 the driver's auto-repeat (ignored).
    Key {
        /// The key code.
        code: u16,
        /// 1 down, 0 up, 2 repeat.
        value: i32,
    },
    /// An axis moved to `value` (in its range).
    Abs {
        /// The axis code.
        code: u16,
        /// Its raw value.
        value: i32,
    },
    /// The pad is gone (unplugged, out of range, a read error): why.
    Disconnected(String),
    /// Nothing happened; time passed (the device thread ticks every 20 ms).
    Tick,
}

/// What the pad asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum PadAction {
    /// The human's input, −1..1 each (after the dead zone; the ceiling comes later).
    Input {
        /// Steer, right = +1.
        steer: f64,
        /// Throttle, forward = +1.
        throttle: f64,
    },
    /// Manual mode (take over).
    TakeOver,
    /// The next mode ([`next_mode`] of the mode now).
    NextMode,
    /// Arm the car.
    Arm,
    /// Disarm the car.
    Disarm,
    /// Press the emergency stop.
    EStop,
    /// Release the emergency stop (the car stays disarmed).
    ReleaseEStop,
    /// Start or stop recording (the run's record switch, as the page's Record button).
    ToggleRecording,
    /// The pad is there (its name).
    Connected(String),
    /// The pad is gone (why).
    Disconnected(String),
    /// A gesture that did nothing, and why (for the terminal and the telemetry).
    Refused(&'static str),
}

/// The mapping's settings (`[gamepad]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadOptions {
    /// The axis that steers.
    pub steer_axis: u16,
    /// The axis that drives (up = forward: the value is negated).
    pub throttle_axis: u16,
    /// The sticks' dead zone, 0..0.5.
    pub dead_zone: f64,
    /// Start held this long arms, ms.
    pub arm_hold_ms: u64,
}

impl Default for PadOptions {
    fn default() -> Self {
        Self {
            steer_axis: code::ABS_X,
            throttle_axis: code::ABS_RY,
            dead_zone: 0.1,
            arm_hold_ms: 1000,
        }
    }
}

/// A button held since a time, and whether its hold already did what it does.
#[derive(Debug, Clone, Copy)]
struct Hold {
    since_ms: u64,
    done: bool,
}

/// The mapping (see the module notes). Pure: time comes with each event.
#[derive(Debug, Clone)]
pub struct PadMachine {
    opts: PadOptions,
    ranges: Vec<(u16, AxisRange)>,
    /// Buttons held (pressed since the pad connected).
    held: BTreeSet<u16>,
    steer: f64,
    throttle: f64,
    /// When input last went out while the dead-man is held.
    last_sent_ms: Option<u64>,
    start: Option<Hold>,
    select: Option<Hold>,
    connected: bool,
}

impl PadMachine {
    /// Not connected, sticks centred, nothing held.
    pub fn new(opts: PadOptions) -> Self {
        Self {
            opts,
            ranges: Vec::new(),
            held: BTreeSet::new(),
            steer: 0.0,
            throttle: 0.0,
            last_sent_ms: None,
            start: None,
            select: None,
            connected: false,
        }
    }

    /// Whether the dead-man (LB or RB) is held.
    pub fn deadman(&self) -> bool {
        self.held.contains(&code::BTN_TL) || self.held.contains(&code::BTN_TR)
    }

    /// Whether a pad is connected.
    pub fn connected(&self) -> bool {
        self.connected
    }

    /// The sticks now, after the dead zone: (steer, throttle).
    pub fn sticks(&self) -> (f64, f64) {
        (self.steer, self.throttle)
    }

    fn reset(&mut self) {
        let opts = self.opts;
        *self = Self::new(opts);
    }

    fn range(&self, code: u16) -> AxisRange {
        self.ranges
            .iter()
            .find(|(c, _)| *c == code)
            .map_or(AxisRange::STICK, |(_, r)| *r)
    }

    fn input(&self) -> PadAction {
        PadAction::Input {
            steer: self.steer,
            throttle: self.throttle,
        }
    }

    /// One event at `t_ms` (any monotonic milliseconds); what to do goes into `out`, in order.
    pub fn feed(&mut self, t_ms: u64, ev: &PadEvent, out: &mut Vec<PadAction>) {
        match ev {
            PadEvent::Connected(name) => {
                // Nothing held counts until pressed after this (see the module notes).
                self.reset();
                self.connected = true;
                out.push(PadAction::Connected(name.clone()));
            }
            PadEvent::Disconnected(why) => {
                // Neutral first, whatever was held: the car must not keep the last stick.
                out.push(PadAction::Input {
                    steer: 0.0,
                    throttle: 0.0,
                });
                self.reset();
                out.push(PadAction::Disconnected(why.clone()));
            }
            PadEvent::Range { code, range } => {
                self.ranges.retain(|(c, _)| c != code);
                self.ranges.push((*code, *range));
            }
            PadEvent::Key { code, value } if self.connected => self.key(t_ms, *code, *value, out),
            PadEvent::Abs { code, value } if self.connected => self.axis(t_ms, *code, *value, out),
            PadEvent::Key { .. } | PadEvent::Abs { .. } | PadEvent::Tick => {}
        }
        self.timers(t_ms, out);
    }

    fn key(&mut self, t_ms: u64, code: u16, value: i32, out: &mut Vec<PadAction>) {
        let down = match value {
            0 => false,
            1 => true,
            _ => return, // auto-repeat
        };
        let deadman_before = self.deadman();
        if down {
            if !self.held.insert(code) {
                return;
            }
        } else if !self.held.remove(&code) {
            // let go of a button held since before the pad connected: nothing
            return;
        }
        match (code, down) {
            (code::BTN_TL | code::BTN_TR, _) => {
                let now = self.deadman();
                if now && !deadman_before {
                    out.push(self.input());
                    self.last_sent_ms = Some(t_ms);
                } else if !now && deadman_before {
                    out.push(PadAction::Input {
                        steer: 0.0,
                        throttle: 0.0,
                    });
                    self.last_sent_ms = None;
                }
            }
            (code::BTN_EAST, true) => out.push(PadAction::EStop),
            (code::BTN_SOUTH, true) => out.push(PadAction::TakeOver),
            (code::BTN_NORTH, true) => out.push(PadAction::NextMode),
            (code::BTN_WEST, true) => out.push(PadAction::ToggleRecording),
            (code::BTN_SELECT, true) => {
                out.push(PadAction::Disarm);
                self.select = Some(Hold {
                    since_ms: t_ms,
                    done: false,
                });
            }
            (code::BTN_SELECT, false) => self.select = None,
            (code::BTN_START, true) => {
                self.start = Some(Hold {
                    since_ms: t_ms,
                    done: false,
                })
            }
            (code::BTN_START, false) => {
                // let go before the hold armed: say why nothing happened
                let early = self.start.take().filter(|h| !h.done);
                out.extend(early.map(|_| PadAction::Refused("arm: hold Start longer (gamepad.arm_hold_ms)")));
            }
            _ => {}
        }
    }

    fn axis(&mut self, t_ms: u64, code: u16, value: i32, out: &mut Vec<PadAction>) {
        let x = dead_zone(self.range(code).normalise(value), self.opts.dead_zone);
        let before = (self.steer, self.throttle);
        if code == self.opts.steer_axis {
            self.steer = x;
        } else if code == self.opts.throttle_axis {
            // up is negative on every pad: forward is up
            self.throttle = if x == 0.0 { 0.0 } else { -x };
        } else {
            return;
        }
        if self.deadman() && (self.steer, self.throttle) != before {
            out.push(self.input());
            self.last_sent_ms = Some(t_ms);
        }
    }

    /// Held buttons that act after a time, and the re-sending of a held input.
    fn timers(&mut self, t_ms: u64, out: &mut Vec<PadAction>) {
        if let Some(h) = self.start.as_mut().filter(|h| !h.done) {
            if t_ms.saturating_sub(h.since_ms) >= self.opts.arm_hold_ms {
                h.done = true;
                out.push(if self.throttle == 0.0 {
                    PadAction::Arm
                } else {
                    PadAction::Refused("arm: centre the throttle stick first")
                });
            }
        }
        if let Some(h) = self.select.as_mut().filter(|h| !h.done) {
            if t_ms.saturating_sub(h.since_ms) >= RELEASE_HOLD_MS {
                h.done = true;
                out.push(PadAction::ReleaseEStop);
            }
        }
        if self.deadman() {
            if let Some(last) = self.last_sent_ms {
                if t_ms.saturating_sub(last) >= RESEND_MS {
                    out.push(self.input());
                    self.last_sent_ms = Some(t_ms);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalise_and_dead_zone() {
        let r = AxisRange { min: -100, max: 100 };
        assert_eq!(r.normalise(50), 0.5);
        assert_eq!(r.normalise(-300), -1.0, "clamped");
        assert_eq!(AxisRange { min: 0, max: 255 }.normalise(255), 1.0);
        assert!(AxisRange::STICK.normalise(0).abs() < 1e-4);
        assert_eq!(dead_zone(0.05, 0.1), 0.0);
        assert_eq!(dead_zone(1.0, 0.1), 1.0);
        assert!((dead_zone(-0.55, 0.1) + 0.5).abs() < 1e-12);
    }

    #[test]
    fn the_modes_cycle() {
        let mut m = DriveMode::Manual;
        let mut seen = Vec::new();
        for _ in 0..3 {
            m = next_mode(m);
            seen.push(m);
        }
        assert_eq!(seen, [DriveMode::Assisted, DriveMode::Autopilot, DriveMode::Manual]);
    }

    #[test]
    fn nothing_counts_before_the_pad_connects() {
        let mut p = PadMachine::new(PadOptions::default());
        let mut out = Vec::new();
        p.feed(
            0,
            &PadEvent::Key {
                code: code::BTN_TL,
                value: 1,
            },
            &mut out,
        );
        p.feed(
            10,
            &PadEvent::Key {
                code: code::BTN_EAST,
                value: 1,
            },
            &mut out,
        );
        assert!(out.is_empty(), "{out:?}");
        assert!(!p.deadman());
    }
}
