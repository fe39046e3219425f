//! The car's faults are states: the health of each part (camera, serial link, ultrasonic
//! brake, GPIO) in one place that the status LED, the status line, telemetry, the dashboard
//! and the exit code all read.
//!
//! Each part is in one [`PartState`]: not used on this car, waiting (not up yet), ok, lost
//! (down, may come back: a stalled camera, a link reconnecting, a brake sensor that stopped
//! answering) or failed (for good: the run cannot go on safely). A part that is lost or failed
//! and guards the car's motion (link, brake) is an **interlock**: [`super::arming::Arming`]
//! refuses to arm while one is active, and the gate disarms when one appears. The first fatal
//! fault is kept ([`Health::fatal`]): the loop stops, the process exits non-zero and names it.
//!
//! Atomics and one short lock; any thread may report (the GPIO and link threads, the loop).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};

/// A part of the car whose health is watched.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Part {
    /// The frame source (camera, folder, simulator camera).
    Camera,
    /// The serial link to the Arduino.
    Link,
    /// The HC-SR04 ultrasonic emergency brake.
    Brake,
    /// The Pi's GPIO (button, LED) threads.
    Gpio,
    /// A gamepad read on the car (`rccar drive --pad`): lost while unplugged. Not an
    /// interlock: a pad that is gone gives neutral, and the other ways to arm still work.
    Pad,
}

impl Part {
    /// Every part, in the order of [`HealthSnapshot`].
    pub const ALL: [Part; 5] = [Part::Camera, Part::Link, Part::Brake, Part::Gpio, Part::Pad];

    fn index(self) -> usize {
        self as usize
    }

    /// Lower-case name (`camera`, `link`, `brake`, `gpio`, `pad`).
    pub fn name(self) -> &'static str {
        match self {
            Part::Camera => "camera",
            Part::Link => "link",
            Part::Brake => "brake",
            Part::Gpio => "gpio",
            Part::Pad => "pad",
        }
    }
}

/// How one part is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum PartState {
    /// Not on this car or in this run (no link in a replay, no GPIO off the Pi).
    #[default]
    Unused = 0,
    /// Not up yet (no first frame, no handshake yet).
    Waiting = 1,
    /// Working.
    Ok = 2,
    /// Down, may come back (camera stalled, link reconnecting, brake sensor silent).
    Lost = 3,
    /// Down for good.
    Failed = 4,
}

impl PartState {
    fn from_u8(v: u8) -> Self {
        match v {
            1 => PartState::Waiting,
            2 => PartState::Ok,
            3 => PartState::Lost,
            4 => PartState::Failed,
            _ => PartState::Unused,
        }
    }

    /// Lost or failed.
    pub fn is_down(self) -> bool {
        matches!(self, PartState::Lost | PartState::Failed)
    }
}

/// A fault that ended (or will end) the run: which part and why, in one line.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Fault {
    /// The part.
    pub part: Part,
    /// What happened, for a person (names the device or file).
    pub message: String,
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.part.name(), self.message)
    }
}

/// Every part's state at one moment (telemetry, dashboard).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct HealthSnapshot {
    /// The frame source.
    pub camera: PartState,
    /// The serial link.
    pub link: PartState,
    /// The ultrasonic brake.
    pub brake: PartState,
    /// The GPIO threads.
    pub gpio: PartState,
    /// The car's gamepad.
    pub pad: PartState,
}

/// The health of every part of one run. Shared by `Arc`.
#[derive(Debug, Default)]
pub struct Health {
    states: [AtomicU8; 5],
    notes: Mutex<[String; 5]>,
    fatal: Mutex<Option<Fault>>,
    version: AtomicU64,
}

impl Health {
    /// Every part unused, no fault.
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    /// Sets `part` to `state` with a note saying why (kept for [`Health::note`]). Returns
    /// whether the state changed.
    pub fn set(&self, part: Part, state: PartState, note: &str) -> bool {
        let old = self.states[part.index()].swap(state as u8, Ordering::SeqCst);
        if let Ok(mut n) = self.notes.lock() {
            n[part.index()] = note.to_string();
        }
        let changed = old != state as u8;
        if changed {
            self.version.fetch_add(1, Ordering::SeqCst);
        }
        changed
    }

    /// Marks `part` failed for good and keeps the first such fault as the run's fatal one.
    pub fn fail(&self, part: Part, message: impl Into<String>) {
        let message = message.into();
        self.set(part, PartState::Failed, &message);
        let mut f = self.fatal.lock().unwrap_or_else(|e| e.into_inner());
        if f.is_none() {
            *f = Some(Fault { part, message });
        }
    }

    /// The state of `part`.
    pub fn state(&self, part: Part) -> PartState {
        PartState::from_u8(self.states[part.index()].load(Ordering::SeqCst))
    }

    /// Why `part` is in its state (the last note given).
    pub fn note(&self, part: Part) -> String {
        self.notes.lock().map(|n| n[part.index()].clone()).unwrap_or_default()
    }

    /// The first fatal fault, once there is one.
    pub fn fatal(&self) -> Option<Fault> {
        self.fatal.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Why the car may not be armed now: a guarding part (link, brake, GPIO) lost or failed, or
    /// a fatal fault. `None`: nothing stands in the way.
    pub fn interlock(&self) -> Option<Fault> {
        if let Some(f) = self.fatal() {
            return Some(f);
        }
        [Part::Link, Part::Brake, Part::Gpio]
            .into_iter()
            .find(|p| self.state(*p).is_down())
            .map(|part| Fault {
                part,
                message: self.note(part),
            })
    }

    /// Every part's state.
    pub fn snapshot(&self) -> HealthSnapshot {
        HealthSnapshot {
            camera: self.state(Part::Camera),
            link: self.state(Part::Link),
            brake: self.state(Part::Brake),
            gpio: self.state(Part::Gpio),
            pad: self.state(Part::Pad),
        }
    }

    /// Changes so far (a watcher can tell something happened).
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::SeqCst)
    }
}

/// What the car is doing, from its health and arming, the most urgent first: what the LED,
/// the status line and the dashboard show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CarStatus {
    /// A part failed, or a guarding part is lost: the car is stopped.
    Fault,
    /// No frame from the camera yet, or the camera stalled.
    WaitingCamera,
    /// The link is not up yet.
    WaitingLink,
    /// The emergency stop is pressed.
    EStopped,
    /// Everything is up; not armed (the LED's "ready": a press arms).
    Disarmed,
    /// Armed, but the ultrasonic brake holds the car.
    Braking,
    /// Armed and driving.
    Driving,
}

impl CarStatus {
    /// The status of a car with `health`, armed (`armed`), e-stopped and braking as given.
    pub fn of(health: &HealthSnapshot, interlock: bool, armed: bool, estop: bool, braking: bool) -> Self {
        if interlock || health.camera == PartState::Failed {
            CarStatus::Fault
        } else if matches!(health.camera, PartState::Waiting | PartState::Lost) {
            CarStatus::WaitingCamera
        } else if health.link == PartState::Waiting {
            CarStatus::WaitingLink
        } else if estop {
            CarStatus::EStopped
        } else if !armed {
            CarStatus::Disarmed
        } else if braking {
            CarStatus::Braking
        } else {
            CarStatus::Driving
        }
    }

    /// Lower-case name for the status line.
    pub fn name(self) -> &'static str {
        match self {
            CarStatus::Fault => "fault",
            CarStatus::WaitingCamera => "waiting for camera",
            CarStatus::WaitingLink => "waiting for Arduino",
            CarStatus::EStopped => "e-stopped",
            CarStatus::Disarmed => "disarmed",
            CarStatus::Braking => "braking",
            CarStatus::Driving => "driving",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_fatal_fault_is_kept_and_interlocks() {
        let h = Health::new();
        assert!(h.interlock().is_none());
        h.set(Part::Brake, PartState::Ok, "");
        h.set(Part::Link, PartState::Lost, "/dev/ttyACM0: read: EIO");
        let i = h.interlock().unwrap();
        assert_eq!(i.part, Part::Link);
        assert!(i.to_string().contains("EIO"), "{i}");
        h.fail(Part::Brake, "no echo for 0.5 s");
        h.fail(Part::Camera, "second");
        assert_eq!(h.fatal().unwrap().part, Part::Brake);
        assert_eq!(h.interlock().unwrap().part, Part::Brake, "a fatal fault comes first");
        // a camera that is merely lost is no interlock (the loop sends neutral itself)
        let h = Health::new();
        h.set(Part::Camera, PartState::Lost, "stalled");
        assert!(h.interlock().is_none());
    }

    #[test]
    fn status_picks_the_most_urgent() {
        let ok = HealthSnapshot {
            camera: PartState::Ok,
            link: PartState::Ok,
            brake: PartState::Ok,
            gpio: PartState::Ok,
            pad: PartState::Unused,
        };
        assert_eq!(CarStatus::of(&ok, false, true, false, false), CarStatus::Driving);
        assert_eq!(CarStatus::of(&ok, false, false, false, false), CarStatus::Disarmed);
        assert_eq!(CarStatus::of(&ok, true, false, false, false), CarStatus::Fault);
        let waiting = HealthSnapshot {
            camera: PartState::Waiting,
            ..ok
        };
        assert_eq!(CarStatus::of(&waiting, false, true, false, false), CarStatus::WaitingCamera);
        let link = HealthSnapshot {
            link: PartState::Waiting,
            ..ok
        };
        assert_eq!(CarStatus::of(&link, false, false, false, false), CarStatus::WaitingLink);
        assert_eq!(CarStatus::of(&ok, false, true, false, true), CarStatus::Braking);
        assert_eq!(CarStatus::of(&ok, false, false, true, false), CarStatus::EStopped);
    }
}
