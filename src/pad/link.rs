//! What the pad asks for, done to the car: the human's input and the mode into
//! [`crate::drive::Controls`], arming and the e-stop through [`Arming`] (by [`Actor::Pad`]),
//! the pad's health ([`Part::Pad`]), and lines for the terminal and the telemetry.
//!
//! Arming, disarming, the e-stop and mode changes already become telemetry events through the
//! gate and the loop ("armed by pad", "mode manual (was autopilot) by pad at wall …"); the
//! pad's own events (connected, disconnected, a refused gesture, the recording button) go
//! through [`PadEvents`], an observer that adds them to the next frame's record.

use super::machine::{next_mode, PadAction};
use crate::control::pilot::DriveMode;
use crate::drive::arming::{Actor, Arming};
use crate::drive::{Clock, Level, Observer, Say};
use crate::health::{Part, PartState};
use crate::telemetry::FrameRecord;
use std::sync::{Arc, Mutex};

/// The recording button's hook: called on every press; returns the line to report (e.g.
/// "recording on"). Not wired by `rccar drive` yet (docs/gamepad.md).
pub type RecordHook = Box<dyn FnMut() -> String + Send>;

/// Events waiting for the next frame's record (shared with the pad's thread).
#[derive(Debug, Clone, Default)]
pub struct PadEvents(Arc<Mutex<Vec<String>>>);

impl PadEvents {
    /// Adds an event.
    pub fn push(&self, e: String) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).push(e);
    }

    /// Takes the events so far.
    pub fn take(&self) -> Vec<String> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Observer for PadEvents {
    fn decorate(&mut self, record: &mut FrameRecord) {
        record.events.append(&mut self.take());
    }
}

/// Carries a pad's actions out on the car (see the module notes).
pub struct PadLink {
    arming: Arc<Arming>,
    /// The run's clock: when a mode changed.
    clock: Arc<dyn Clock + Send + Sync>,
    events: PadEvents,
    say: Option<Say>,
    disarm_on_disconnect: bool,
    record: Option<RecordHook>,
}

impl PadLink {
    /// Acting on `arming` (and its controls); mode changes timed on the run's `clock`.
    pub fn new(arming: Arc<Arming>, clock: Arc<dyn Clock + Send + Sync>, disarm_on_disconnect: bool) -> Self {
        Self {
            arming,
            clock,
            events: PadEvents::default(),
            say: None,
            disarm_on_disconnect,
            record: None,
        }
    }

    /// Lines for the terminal go to `say` too.
    pub fn with_say(mut self, say: Say) -> Self {
        self.say = Some(say);
        self
    }

    /// The recording button calls `hook` (see [`RecordHook`]).
    pub fn with_record_hook(mut self, hook: RecordHook) -> Self {
        self.record = Some(hook);
        self
    }

    /// The events for the telemetry (an observer of the loop).
    pub fn events(&self) -> PadEvents {
        self.events.clone()
    }

    /// The arming state acted on.
    pub fn arming(&self) -> &Arc<Arming> {
        &self.arming
    }

    fn note(&self, level: Level, line: String) {
        if let Some(s) = &self.say {
            s(level, &line);
        }
        self.events.push(line);
    }

    fn set_mode(&self, m: DriveMode) {
        let before = self.arming.controls().set_mode(m, Actor::Pad, self.clock.now_s());
        if before != m {
            if let Some(s) = &self.say {
                s(Level::Info, &format!("pad: mode {} (was {})", m.name(), before.name()));
            }
        }
    }

    /// Does `actions` in order; `human_s`: now on the human's clock
    /// ([`crate::drive::Controls::now_s`]), when the input arrived.
    pub fn apply(&mut self, actions: &[PadAction], human_s: f64) {
        let arming = self.arming.clone();
        let c = arming.controls();
        for a in actions {
            match a {
                PadAction::Input { steer, throttle } => {
                    // in range by construction; a refused one changes nothing
                    let _ = c.set_input_at(*steer, *throttle, human_s);
                }
                PadAction::TakeOver => self.set_mode(DriveMode::Manual),
                PadAction::NextMode => self.set_mode(next_mode(c.mode())),
                PadAction::Arm => match self.arming.arm(Actor::Pad) {
                    Ok(()) => self.say_line(Level::Info, "pad: armed"),
                    Err(why) => self.note(Level::Warn, format!("pad: not armed: {why}")),
                },
                PadAction::Disarm => {
                    if self.arming.is_armed() {
                        self.say_line(Level::Info, "pad: disarmed");
                    }
                    self.arming.disarm(Actor::Pad);
                }
                PadAction::EStop => {
                    self.arming.estop(Actor::Pad);
                    self.say_line(Level::Warn, "pad: EMERGENCY STOP (hold Back 2 s to release it)");
                }
                PadAction::ReleaseEStop => {
                    if self.arming.is_estopped() {
                        self.say_line(Level::Info, "pad: e-stop released (still disarmed: hold Start to arm)");
                    }
                    self.arming.release(Actor::Pad);
                }
                PadAction::ToggleRecording => {
                    let line = match self.record.as_mut() {
                        Some(hook) => format!("pad: recording: {}", hook()),
                        // The run's record switch (the page's too): pauses or resumes a
                        // `--record` run's frames; without a recorder it says so.
                        None => match self.arming.controls().record().toggle(Actor::Pad, self.clock.now_s()) {
                            Ok(true) => "pad: recording on".to_string(),
                            Ok(false) => "pad: recording paused".to_string(),
                            Err(e) => format!("pad: recording button: {e}"),
                        },
                    };
                    self.note(Level::Info, line);
                }
                PadAction::Connected(name) => {
                    self.arming.health().set(Part::Pad, PartState::Ok, "");
                    self.note(Level::Info, format!("pad: connected: {name}"));
                }
                PadAction::Disconnected(why) => {
                    let h = self.arming.health();
                    h.set(Part::Pad, PartState::Lost, &format!("disconnected: {why}"));
                    let disarm = self.disarm_on_disconnect && self.arming.is_armed();
                    if disarm {
                        self.arming.disarm(Actor::Pad);
                    }
                    self.note(
                        Level::Warn,
                        format!(
                            "pad: disconnected ({why}); neutral{}; waiting for it to come back",
                            if disarm { ", disarmed" } else { "" }
                        ),
                    );
                }
                PadAction::Refused(why) => self.note(Level::Info, format!("pad: {why}")),
            }
        }
    }

    fn say_line(&self, level: Level, line: &str) {
        if let Some(s) = &self.say {
            s(level, line);
        }
    }
}
