//! Who drives: the driving mode and the human's newest input, held beside the arming state
//! (issue 26). The loop picks the command by mode *before* the gate, so disarming, the e-stop,
//! the brake and the interlocks win over a human exactly as over the autopilot.
//!
//! ```text
//!  page / pad ──set_input(steer, throttle, at)──► Controls (atomics) ◄── set_mode(mode, by, at)
//!                                                     │
//!  pipeline ──its command──► Controls::choose(cmd, now) ──► Gate ──► actuators
//! ```
//!
//! | mode | steer | throttle |
//! |---|---|---|
//! | `autopilot` | the pipeline's | the pipeline's |
//! | `assisted` | the pipeline's | the human's |
//! | `manual` | the human's | the human's |
//!
//! The human's input is the newest `(steer, throttle)` in −1..1 with the time it arrived on
//! the human's clock: the wall clock, never the run's (a human acts in wall time, and a run's
//! clock may read nothing at all, as under `--no-timing`: an input timed on it would never go
//! stale). Older than the deadline (`manual.input_timeout_ms`) it counts as released:
//! neutral (steer 0, throttle 0). A page that goes away, a browser that freezes, a Wi-Fi that
//! drops all end the same way: the car stops within the deadline. The human's throttle is
//! scaled by the ceiling (`manual.max_throttle`): full stick gives at most that.
//!
//! Any thread may set the mode or the input (atomics only, never a lock the loop holds); a
//! mode change remembers who made it ([`Actor`]) and when, and the loop turns it into a
//! telemetry event of the next frame.

use super::actor::{Actor, AtomicF64};
pub use crate::control::pilot::{DriveMode, Pilot};
use crate::control::Command;
use crate::timing::Clock;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// The command the loop hands to the gate, and who made it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// The command (the gate may still hold it back).
    pub command: Command,
    /// The mode it was chosen in.
    pub mode: DriveMode,
    /// Who made it.
    pub pilot: Pilot,
    /// The human's input as used (after the ceiling; neutral when released or stale), when
    /// the mode takes anything from the human.
    pub human: Option<Command>,
    /// How old the human's input was, ms on the human's (wall) clock (`None`: released or
    /// stale).
    pub input_age_ms: Option<f64>,
}

/// `manual.input_timeout_ms` and `manual.max_throttle` by default.
const DEFAULT_DEADLINE_S: f64 = 0.25;
const DEFAULT_CEILING: f64 = 0.5;

/// The human's clock: monotonic wall time since the controls were made.
#[derive(Debug)]
struct Wall(Instant);

impl Clock for Wall {
    fn now_s(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
}

/// The driving mode and the human's newest input (see the module notes). Lock-free.
pub struct Controls {
    mode: AtomicU8,
    mode_actor: AtomicU8,
    /// Bumped on every mode change.
    mode_version: AtomicU64,
    /// When the mode last changed, seconds on the run's clock.
    mode_at_s: AtomicF64,
    /// The mode before the last change.
    mode_before: AtomicU8,
    /// Steer and throttle of the newest input as two f32 in one word (never torn).
    input: AtomicU64,
    /// When the newest input arrived, seconds on the human's clock (NaN: never).
    input_at_s: AtomicF64,
    /// The human's clock: the wall clock unless a test gave another ([`Controls::use_clock`]).
    wall: Wall,
    clock: OnceLock<Arc<dyn Clock + Send + Sync>>,
    deadline_s: AtomicF64,
    ceiling: AtomicF64,
    /// A human input is attached to this run (a dashboard, a pad): records say the mode.
    attached: AtomicBool,
    /// The record switch.
    record: RecordSwitch,
}

impl std::fmt::Debug for Controls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Controls")
            .field("mode", &self.mode())
            .field("input_at_s", &self.input_at_s.get())
            .field("deadline_s", &self.deadline_s.get())
            .field("ceiling", &self.ceiling.get())
            .finish_non_exhaustive()
    }
}

impl Default for Controls {
    fn default() -> Self {
        Self::new()
    }
}

fn pack(steer: f64, throttle: f64) -> u64 {
    (u64::from((steer as f32).to_bits()) << 32) | u64::from((throttle as f32).to_bits())
}

fn unpack(w: u64) -> (f64, f64) {
    (
        f64::from(f32::from_bits((w >> 32) as u32)),
        f64::from(f32::from_bits(w as u32)),
    )
}

/// Why a human input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what} = {value} is out of range (allowed: -1 ..= 1)")]
pub struct BadInput {
    /// `steer` or `throttle`.
    pub what: &'static str,
    /// The value as given.
    pub value: String,
}

/// The record switch (issue 26): whether the run's recorder keeps frames, switched from the
/// page or the pad, and what the recorder reports back. Only a run started with `--record DIR`
/// has a recorder ([`RecordSwitch::available`]); it starts recording (as before the switch
/// existed), and switching it off keeps the folder and pauses the frames — one run, one folder,
/// never a second recording mixed into it.
#[derive(Debug)]
pub struct RecordSwitch {
    available: AtomicBool,
    on: AtomicBool,
    version: AtomicU64,
    actor: AtomicU8,
    at_s: AtomicF64,
    frames: AtomicU64,
    bytes_left: AtomicU64,
}

impl Default for RecordSwitch {
    fn default() -> Self {
        Self {
            available: AtomicBool::new(false),
            on: AtomicBool::new(false),
            version: AtomicU64::new(0),
            actor: AtomicU8::new(Actor::Program as u8),
            at_s: AtomicF64::nan(),
            frames: AtomicU64::new(0),
            bytes_left: AtomicU64::new(u64::MAX),
        }
    }
}

/// Why the record switch did not move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("this run has no recorder: start it with --record DIR to record")]
pub struct NoRecorder;

impl RecordSwitch {
    /// The run has a recorder, recording from the start (`--record DIR`).
    pub fn make_available(&self) {
        self.available.store(true, Ordering::SeqCst);
        self.on.store(true, Ordering::SeqCst);
    }

    /// Whether the run has a recorder.
    pub fn available(&self) -> bool {
        self.available.load(Ordering::SeqCst)
    }

    /// Whether frames are being recorded now.
    pub fn is_on(&self) -> bool {
        self.available() && self.on.load(Ordering::SeqCst)
    }

    /// Records (`on`) or pauses, `by` whom at `at_s` on the run's clock. Returns the state before.
    pub fn set(&self, on: bool, by: Actor, at_s: f64) -> Result<bool, NoRecorder> {
        if !self.available() {
            return Err(NoRecorder);
        }
        let before = self.on.swap(on, Ordering::SeqCst);
        if before != on {
            self.actor.store(by as u8, Ordering::SeqCst);
            self.at_s.set(at_s);
            self.version.fetch_add(1, Ordering::SeqCst);
        }
        Ok(before)
    }

    /// Flips the switch (a pad's button). Returns the state after.
    pub fn toggle(&self, by: Actor, at_s: f64) -> Result<bool, NoRecorder> {
        let on = !self.is_on();
        self.set(on, by, at_s).map(|_| on)
    }

    /// Changes so far.
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::SeqCst)
    }

    /// The last change: (on, who, when on the run's clock).
    pub fn last_change(&self) -> (bool, Actor, f64) {
        (
            self.on.load(Ordering::SeqCst),
            Actor::from_u8(self.actor.load(Ordering::SeqCst)),
            self.at_s.get(),
        )
    }

    /// The recorder's report: frames kept on disk and bytes left of the budget.
    pub fn report(&self, frames: u64, bytes_left: u64) {
        self.frames.store(frames, Ordering::SeqCst);
        self.bytes_left.store(bytes_left, Ordering::SeqCst);
    }

    /// Frames kept on disk.
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::SeqCst)
    }

    /// Bytes left of the disk budget (`u64::MAX` before the first report).
    pub fn bytes_left(&self) -> u64 {
        self.bytes_left.load(Ordering::SeqCst)
    }
}

impl Controls {
    /// Autopilot, no input yet, the default deadline (250 ms) and ceiling (0.5).
    pub fn new() -> Self {
        Self {
            mode: AtomicU8::new(DriveMode::Autopilot as u8),
            mode_actor: AtomicU8::new(Actor::Program as u8),
            mode_version: AtomicU64::new(0),
            mode_at_s: AtomicF64::nan(),
            mode_before: AtomicU8::new(DriveMode::Autopilot as u8),
            input: AtomicU64::new(pack(0.0, 0.0)),
            input_at_s: AtomicF64::nan(),
            wall: Wall(Instant::now()),
            clock: OnceLock::new(),
            deadline_s: AtomicF64::new(DEFAULT_DEADLINE_S),
            ceiling: AtomicF64::new(DEFAULT_CEILING),
            attached: AtomicBool::new(false),
            record: RecordSwitch::default(),
        }
    }

    /// The deadline (seconds) after which an input counts as released, and the human's
    /// throttle ceiling (0..1) — `manual.input_timeout_ms` and `manual.max_throttle`.
    pub fn configure(&self, deadline_s: f64, ceiling: f64) {
        self.deadline_s.set(deadline_s);
        self.ceiling.set(ceiling.clamp(0.0, 1.0));
    }

    /// Times inputs on `clock` instead of the wall clock (a test replaying a recorded input
    /// sequence on its own clock). Only before the first use; `false` if too late.
    pub fn use_clock(&self, clock: Arc<dyn Clock + Send + Sync>) -> bool {
        self.clock.set(clock).is_ok()
    }

    /// Seconds on the human's clock (see the module notes).
    pub fn now_s(&self) -> f64 {
        match self.clock.get() {
            Some(c) => c.now_s(),
            None => self.wall.now_s(),
        }
    }

    /// The record switch.
    pub fn record(&self) -> &RecordSwitch {
        &self.record
    }

    /// The input deadline, seconds.
    pub fn deadline_s(&self) -> f64 {
        self.deadline_s.get()
    }

    /// The human's throttle ceiling.
    pub fn ceiling(&self) -> f64 {
        self.ceiling.get()
    }

    /// A human input is attached to the run (a dashboard, a pad): from now on every record
    /// says the mode and who drove.
    pub fn attach(&self) {
        self.attached.store(true, Ordering::SeqCst);
    }

    /// Whether the records must say the mode (an input is attached, or the mode was changed).
    pub fn reported(&self) -> bool {
        self.attached.load(Ordering::SeqCst) || self.mode_version.load(Ordering::SeqCst) > 0
    }

    /// The mode now.
    pub fn mode(&self) -> DriveMode {
        DriveMode::from_u8(self.mode.load(Ordering::SeqCst))
    }

    /// Sets the mode (`by` whom, at `at_s` on the run's clock). Returns the mode before.
    pub fn set_mode(&self, mode: DriveMode, by: Actor, at_s: f64) -> DriveMode {
        let before = DriveMode::from_u8(self.mode.swap(mode as u8, Ordering::SeqCst));
        if before != mode {
            self.mode_before.store(before as u8, Ordering::SeqCst);
            self.mode_actor.store(by as u8, Ordering::SeqCst);
            self.mode_at_s.set(at_s);
            self.mode_version.fetch_add(1, Ordering::SeqCst);
        }
        before
    }

    /// Mode changes so far.
    pub fn mode_version(&self) -> u64 {
        self.mode_version.load(Ordering::SeqCst)
    }

    /// The last mode change: (mode before, who, when on the run's clock).
    pub fn last_change(&self) -> (DriveMode, Actor, f64) {
        (
            DriveMode::from_u8(self.mode_before.load(Ordering::SeqCst)),
            Actor::from_u8(self.mode_actor.load(Ordering::SeqCst)),
            self.mode_at_s.get(),
        )
    }

    /// The human's newest input, arriving now on the human's clock. Both in −1..1 (NaN and
    /// infinities refused).
    pub fn set_input(&self, steer: f64, throttle: f64) -> Result<(), BadInput> {
        self.set_input_at(steer, throttle, self.now_s())
    }

    /// The human's newest input, arrived at `at_s` on the human's clock.
    pub fn set_input_at(&self, steer: f64, throttle: f64, at_s: f64) -> Result<(), BadInput> {
        for (what, v) in [("steer", steer), ("throttle", throttle)] {
            if !(-1.0..=1.0).contains(&v) {
                return Err(BadInput {
                    what,
                    value: v.to_string(),
                });
            }
        }
        // Values first, then the time: a reader that sees the new time sees the new values.
        self.input.store(pack(steer, throttle), Ordering::SeqCst);
        self.input_at_s.set(at_s);
        Ok(())
    }

    /// When the newest input arrived, seconds on the human's clock (NaN: never), stale or not.
    pub fn input_at_s(&self) -> f64 {
        self.input_at_s.get()
    }

    /// The human's input at `now_s`: `(steer, throttle after the ceiling, age ms)`, or
    /// `None` when released (never given, or older than the deadline).
    pub fn input(&self, now_s: f64) -> Option<(f64, f64, f64)> {
        let at = self.input_at_s.get();
        let (steer, throttle) = unpack(self.input.load(Ordering::SeqCst));
        let age = now_s - at;
        // NaN (never given) fails the comparison; a time from the future is not trusted
        // beyond the deadline either.
        let fresh = age.abs() <= self.deadline_s.get();
        if !fresh {
            return None;
        }
        Some((steer, throttle * self.ceiling.get(), age.max(0.0) * 1e3))
    }

    /// The command by mode (see the table in the module notes) now, from the pipeline's
    /// `auto`. The gate comes after this.
    pub fn choose(&self, auto: Command) -> Choice {
        self.choose_at(auto, self.now_s())
    }

    /// [`Controls::choose`] at `now_s` on the human's clock.
    pub fn choose_at(&self, auto: Command, now_s: f64) -> Choice {
        let mode = self.mode();
        if mode == DriveMode::Autopilot {
            return Choice {
                command: auto,
                mode,
                pilot: Pilot::Autopilot,
                human: None,
                input_age_ms: None,
            };
        }
        let input = self.input(now_s);
        let human = input.map_or(Command::NEUTRAL, |(steer, throttle, _)| Command { steer, throttle });
        let (command, pilot) = match mode {
            DriveMode::Manual => (human, Pilot::Human),
            _ => (
                Command {
                    steer: auto.steer,
                    throttle: human.throttle,
                },
                Pilot::Shared,
            ),
        };
        Choice {
            command,
            mode,
            pilot,
            human: Some(human),
            input_age_ms: input.map(|i| i.2),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AUTO: Command = Command {
        steer: -0.3,
        throttle: 0.45,
    };

    #[test]
    fn autopilot_takes_the_pipeline_whatever_the_input() {
        let c = Controls::new();
        c.set_input_at(1.0, 1.0, 0.0).unwrap();
        let ch = c.choose_at(AUTO, 0.01);
        assert_eq!((ch.command, ch.pilot, ch.human), (AUTO, Pilot::Autopilot, None));
    }

    #[test]
    fn a_recorded_input_sequence_in_manual_and_assisted() {
        let c = Controls::new();
        c.configure(0.25, 0.5);
        assert_eq!(c.set_mode(DriveMode::Manual, Actor::Page, 1.0), DriveMode::Autopilot);
        // (time input arrived, steer, throttle), then the loop's steps at these times.
        let inputs = [(1.00, 0.5, 1.0), (1.05, 0.6, 0.8), (1.10, -1.0, -1.0)];
        let mut got = Vec::new();
        let mut ins = inputs.iter().peekable();
        for t in [1.00, 1.06, 1.12, 1.30, 1.36, 1.40] {
            while let Some(&&(ti, s, th)) = ins.peek() {
                if ti > t {
                    break;
                }
                c.set_input_at(s, th, ti).unwrap();
                ins.next();
            }
            got.push((t, c.choose_at(AUTO, t).command));
        }
        let cmd = |steer: f64, throttle: f64| Command { steer, throttle };
        let f32s = |v: f64| f64::from(v as f32);
        assert_eq!(got[0].1, cmd(0.5, 0.5), "full stick = the ceiling");
        assert_eq!(got[1].1, cmd(f32s(0.6), f64::from(0.8f32) * 0.5));
        assert_eq!(got[2].1, cmd(-1.0, -0.5), "reverse scaled too");
        // The last input came at 1.10: 1.30 is 200 ms later, still held; 1.36 is 260 ms: stale.
        assert_eq!(got[3].1, cmd(-1.0, -0.5));
        assert_eq!(got[4].1, Command::NEUTRAL, "stale input → neutral on the next step");
        assert_eq!(got[5].1, Command::NEUTRAL);
        // Assisted: the pipeline's steering, the human's throttle.
        c.set_input_at(0.9, 0.6, 2.0).unwrap();
        c.set_mode(DriveMode::Assisted, Actor::Pad, 2.0);
        let ch = c.choose_at(AUTO, 2.01);
        assert_eq!(ch.command, cmd(AUTO.steer, f64::from(0.6f32) * 0.5));
        assert_eq!(ch.pilot, Pilot::Shared);
        // … and neutral throttle (the pipeline still steers) once the input is stale.
        assert_eq!(c.choose_at(AUTO, 2.5).command, cmd(AUTO.steer, 0.0));
        assert_eq!(c.last_change(), (DriveMode::Manual, Actor::Pad, 2.0));
        assert_eq!(c.mode_version(), 2);
    }

    #[test]
    fn no_input_ever_is_neutral_and_bad_inputs_are_refused() {
        let c = Controls::new();
        c.set_mode(DriveMode::Manual, Actor::Page, 0.0);
        assert_eq!(c.choose_at(AUTO, 0.0).command, Command::NEUTRAL);
        for (s, t) in [(f64::NAN, 0.0), (0.0, f64::INFINITY), (1.01, 0.0), (0.0, -1.5)] {
            assert!(c.set_input_at(s, t, 0.0).is_err(), "{s} {t}");
        }
        assert_eq!(
            c.choose_at(AUTO, 0.0).command,
            Command::NEUTRAL,
            "a refused input changes nothing"
        );
        c.configure(0.25, 0.3);
        c.set_input_at(0.0, 1.0, 5.0).unwrap();
        assert_eq!(c.choose_at(AUTO, 5.0).command.throttle, 0.3, "the ceiling");
        // An input stamped in the future (another clock) is not held beyond the deadline.
        assert_eq!(c.choose_at(AUTO, 4.0).command, Command::NEUTRAL);
    }
}
