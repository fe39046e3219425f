//! `[manual]`: driving by hand (issue 26): how long a human's input holds (milliseconds) and
//! the most throttle a human may give (0..1).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[manual]`: driving by hand from the dashboard (src/drive/manual.rs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ManualConfig {
    /// A human input older than this counts as released (neutral), ms.
    pub input_timeout_ms: u64,
    /// Full stick (keys, joystick, pad) gives this throttle, forward or reverse (0..1).
    pub max_throttle: f64,
}

impl Default for ManualConfig {
    fn default() -> Self {
        Self {
            input_timeout_ms: 250,
            max_throttle: 0.5,
        }
    }
}

impl ManualConfig {
    /// Checks of `[manual]`: the ranges.
    pub(super) fn check(&self, c: &mut Checker) {
        c.range("manual.input_timeout_ms", self.input_timeout_ms, 50, 2000);
        c.range("manual.max_throttle", self.max_throttle, 0.0, 1.0);
    }
}
