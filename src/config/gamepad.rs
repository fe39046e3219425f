//! `[gamepad]`: a USB or Bluetooth gamepad read on the car (issue 26, feature `gamepad`,
//! src/pad/, docs/gamepad.md): which device, the sticks' dead zone, which axes steer and
//! drive, how long Start is held to arm (milliseconds).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[gamepad]`: the car's own gamepad (`rccar drive --pad`, or `enabled = true`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GamepadConfig {
    /// `rccar drive` reads the pad without `--pad` (`rccar sim` only with `--pad`).
    pub enabled: bool,
    /// `auto` (the first input device with a gamepad's buttons) or an event device,
    /// `/dev/input/eventN` (or a stable `/dev/input/by-id/…-event-joystick` link).
    pub device: String,
    /// A stick nearer the centre than this (0..0.5 of full travel) reads 0; beyond it the
    /// travel is rescaled so that the input starts from 0.
    pub dead_zone: f64,
    /// The axis that steers (an evdev name: ABS_X = the left stick sideways).
    pub steer_axis: String,
    /// The axis that drives (ABS_RY = the right stick; up is forward).
    pub throttle_axis: String,
    /// Start held this long arms the car, ms (300..5000).
    pub arm_hold_ms: u64,
    /// A pad unplugged (or out of Bluetooth range) disarms an armed car as well as giving
    /// neutral: the pad was its driver's stop button.
    pub disarm_on_disconnect: bool,
}

impl Default for GamepadConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            device: "auto".into(),
            dead_zone: 0.1,
            steer_axis: "ABS_X".into(),
            throttle_axis: "ABS_RY".into(),
            arm_hold_ms: 1000,
            disarm_on_disconnect: true,
        }
    }
}

/// The axes a stick may be mapped to: (evdev name, code).
pub const AXES: [(&str, u16); 6] = [
    ("ABS_X", 0x00),
    ("ABS_Y", 0x01),
    ("ABS_Z", 0x02),
    ("ABS_RX", 0x03),
    ("ABS_RY", 0x04),
    ("ABS_RZ", 0x05),
];

/// The code of an axis name of [`AXES`].
pub fn axis_code(name: &str) -> Option<u16> {
    AXES.iter().find(|(n, _)| *n == name).map(|(_, c)| *c)
}

impl GamepadConfig {
    /// The mapping's options (after [`crate::config::Config::validate`]: the axis names are
    /// known).
    pub fn options(&self) -> crate::pad::PadOptions {
        let def = crate::pad::PadOptions::default();
        crate::pad::PadOptions {
            steer_axis: axis_code(&self.steer_axis).unwrap_or(def.steer_axis),
            throttle_axis: axis_code(&self.throttle_axis).unwrap_or(def.throttle_axis),
            dead_zone: self.dead_zone,
            arm_hold_ms: self.arm_hold_ms,
        }
    }

    /// Checks of `[gamepad]`: ranges, axis names, the device's form.
    pub(super) fn check(&self, c: &mut Checker) {
        c.range("gamepad.dead_zone", self.dead_zone, 0.0, 0.5);
        c.range("gamepad.arm_hold_ms", self.arm_hold_ms, 300, 5000);
        let names = AXES.map(|(n, _)| n).join(", ");
        for (key, v) in [
            ("gamepad.steer_axis", &self.steer_axis),
            ("gamepad.throttle_axis", &self.throttle_axis),
        ] {
            if axis_code(v).is_none() {
                c.fail(key, format!("{v:?}"), &format!("one of {names}"));
            }
        }
        if self.steer_axis == self.throttle_axis {
            c.fail(
                "gamepad.throttle_axis",
                format!("{:?}", self.throttle_axis),
                "another axis than gamepad.steer_axis",
            );
        }
        if self.device != "auto" && !self.device.starts_with('/') {
            c.fail(
                "gamepad.device",
                format!("{:?}", self.device),
                "\"auto\" or an event device's absolute path, e.g. \"/dev/input/event3\"",
            );
        }
    }
}
