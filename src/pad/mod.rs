//! A gamepad on the car (issue 26, docs/gamepad.md): the mapping as a state machine without
//! hardware ([`machine`]), recorded event sequences for its tests ([`script`]), what its
//! actions do to the car ([`link`]: the driving mode and the human's input, arming, the
//! e-stop, the pad's health), and the device itself on Linux ([`device`], feature `gamepad`:
//! evdev, a thread of its own).
//!
//! ```text
//!  /dev/input/eventN ──evdev──► device thread ──PadEvent(t)──► PadMachine ──PadAction──► PadLink
//!  tests/data/pad/*.txt ──script::parse─────────────────────────┘                      │
//!        Controls (input, mode) · Arming (arm, disarm, e-stop) · Health (pad) · events ◄┘
//! ```

#[cfg(all(feature = "gamepad", target_os = "linux"))]
pub mod device;
pub mod link;
pub mod machine;
pub mod script;

pub use link::{PadEvents, PadLink};
pub use machine::{AxisRange, PadAction, PadEvent, PadMachine, PadOptions};
