//! Who acts on the car (the arming state's [`Actor`]: the flag, the button, the page, a pad, a
//! broker, the link, the brake sensor, the heartbeat) and a float shared between threads
//! ([`AtomicF64`]): below both the arming state (src/drive/arming.rs) and who drives
//! (src/drive/manual.rs), which each need them.

use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};

/// Who changed the arming state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Actor {
    /// rccar itself (a simulation armed from the start, the end of a run).
    Program = 0,
    /// The `--arm` flag.
    Flag = 1,
    /// The start/stop button (GPIO, or SIGUSR1 at the desk).
    Button = 2,
    /// The dashboard page.
    Page = 3,
    /// A gamepad.
    Pad = 4,
    /// A fleet broker.
    Broker = 5,
    /// The serial link (lost, reconnected, refused to arm).
    Link = 6,
    /// The ultrasonic brake sensor (dead).
    Sensor = 7,
    /// A heartbeat that stopped (the page went away).
    Heartbeat = 8,
}

impl Actor {
    pub(crate) fn from_u8(v: u8) -> Self {
        match v {
            1 => Actor::Flag,
            2 => Actor::Button,
            3 => Actor::Page,
            4 => Actor::Pad,
            5 => Actor::Broker,
            6 => Actor::Link,
            7 => Actor::Sensor,
            8 => Actor::Heartbeat,
            _ => Actor::Program,
        }
    }

    /// Lower-case name, as telemetry events and the status line say it.
    pub fn name(self) -> &'static str {
        match self {
            Actor::Program => "rccar",
            Actor::Flag => "--arm",
            Actor::Button => "button",
            Actor::Page => "page",
            Actor::Pad => "pad",
            Actor::Broker => "broker",
            Actor::Link => "link",
            Actor::Sensor => "brake sensor",
            Actor::Heartbeat => "heartbeat",
        }
    }
}

/// A float in an atomic (its bits); NaN = not set.
#[derive(Debug)]
pub struct AtomicF64(AtomicU64);

impl AtomicF64 {
    /// Holding `v`.
    pub fn new(v: f64) -> Self {
        Self(AtomicU64::new(v.to_bits()))
    }
    /// Not set (NaN).
    pub fn nan() -> Self {
        Self(AtomicU64::new(f64::NAN.to_bits()))
    }
    /// The value.
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::SeqCst))
    }
    /// Sets it.
    pub fn set(&self, v: f64) {
        self.0.store(v.to_bits(), Ordering::SeqCst)
    }
}

impl Default for AtomicF64 {
    fn default() -> Self {
        Self::nan()
    }
}

