//! Who drives, as data (issue 26): the driving mode and who produced a command. Here, below
//! the loop and the telemetry record, so that both can name them; the mode's state (atomics,
//! the human's input, the deadline and the ceiling) is `crate::drive::manual`.

use serde::{Deserialize, Serialize};

/// Who decides the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum DriveMode {
    /// The pipeline steers and sets the throttle (the default).
    Autopilot = 0,
    /// The pipeline steers, the human holds the throttle.
    Assisted = 1,
    /// The human steers and sets the throttle.
    Manual = 2,
}

impl DriveMode {
    /// Every mode, in the page's order.
    pub const ALL: [DriveMode; 3] = [DriveMode::Manual, DriveMode::Assisted, DriveMode::Autopilot];

    /// The mode stored as `v` (`mode as u8`); anything else is the autopilot.
    pub fn from_u8(v: u8) -> Self {
        match v {
            1 => DriveMode::Assisted,
            2 => DriveMode::Manual,
            _ => DriveMode::Autopilot,
        }
    }

    /// Lower-case name, as telemetry and the page say it.
    pub fn name(self) -> &'static str {
        match self {
            DriveMode::Autopilot => "autopilot",
            DriveMode::Assisted => "assisted",
            DriveMode::Manual => "manual",
        }
    }

    /// The mode named `s` (as [`DriveMode::name`] says it).
    pub fn parse(s: &str) -> Option<DriveMode> {
        DriveMode::ALL.into_iter().find(|m| m.name() == s)
    }
}

/// Who produced a command (before the gate).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pilot {
    /// The pipeline.
    Autopilot,
    /// A human (page, pad).
    Human,
    /// The pipeline's steering with the human's throttle (assisted).
    Shared,
}
