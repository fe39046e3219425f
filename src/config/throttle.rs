//! `[throttle]`: the speed policy (throttle 0..=1, its drop per unit of normalised lane error,
//! and how long the lane may be lost, seconds).

use super::check::Checker;
use crate::control::throttle::ThrottleOptions;
use serde::{Deserialize, Serialize};

/// `[throttle]`: speed policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThrottleConfig {
    /// Throttle on a straight with zero error, 0..=1.
    pub base: f64,
    /// Throttle never drops below this while the lane is seen, 0..=base.
    pub min: f64,
    /// How much the throttle drops per unit of |normalised error|.
    pub error_slowdown: f64,
    /// After the lane has been lost this long, seconds, the throttle is zero.
    pub lost_timeout_s: f64,
}

impl Default for ThrottleConfig {
    fn default() -> Self {
        Self {
            base: 0.5,
            min: 0.2,
            error_slowdown: 0.6,
            lost_timeout_s: 0.5,
        }
    }
}

impl ThrottleConfig {
    /// Range checks of `[throttle]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let t = self;
        c.range("throttle.base", t.base, 0.0, 1.0);
        c.range("throttle.min", t.min, 0.0, t.base.max(0.0));
        c.range("throttle.error_slowdown", t.error_slowdown, 0.0, 5.0);
        c.range("throttle.lost_timeout_s", t.lost_timeout_s, 0.0, 60.0);
    }
}

impl From<&ThrottleConfig> for ThrottleOptions {
    /// The throttle policy of `[throttle]`.
    fn from(t: &ThrottleConfig) -> Self {
        Self {
            base: t.base,
            min: t.min,
            error_slowdown: t.error_slowdown,
            lost_timeout_s: t.lost_timeout_s,
        }
    }
}
