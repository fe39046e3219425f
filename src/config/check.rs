//! Checking a configuration: [`Config::validate`] runs every section's own checks (in the
//! section's file) in a fixed order, then the checks that join two sections, and collects every
//! bad value instead of stopping at the first. An error names the key, the value and what is
//! allowed.

use super::{Config, ConfigError, InvalidValue};
use std::fmt;

/// Checks that collect every out-of-range value instead of stopping at the first.
#[derive(Debug, Default)]
pub(super) struct Checker(Vec<InvalidValue>);

impl Checker {
    /// `v` must lie in `lo ..= hi` (NaN never does).
    pub(super) fn range<T: PartialOrd + fmt::Display + Copy>(&mut self, key: &str, v: T, lo: T, hi: T) {
        if !(v >= lo && v <= hi) {
            let value = v.to_string();
            let not_finite = matches!(value.as_str(), "inf" | "-inf" | "NaN");
            self.0.push(InvalidValue {
                key: key.into(),
                allowed: if not_finite {
                    format!("{lo} ..= {hi}; inf and NaN are not allowed")
                } else {
                    format!("{lo} ..= {hi}")
                },
                value,
            });
        }
    }

    /// `v` must be a finite number.
    pub(super) fn finite(&mut self, key: &str, v: f64) {
        if !v.is_finite() {
            self.0.push(InvalidValue {
                key: key.into(),
                value: v.to_string(),
                allowed: "a finite number".into(),
            });
        }
    }

    /// Every tunable parameter of `section` (`crate::control::catalog::all`, keys
    /// `section.name`) against its table range, its value read from the serialised section.
    pub(super) fn params<T: serde::Serialize>(&mut self, section: &str, values: &T) {
        let table = super::value::to_table(values);
        for p in crate::control::catalog::all() {
            let Some(name) = p.key.strip_prefix(section).and_then(|k| k.strip_prefix('.')) else {
                continue;
            };
            match super::value::number_at(&table, name) {
                Some(v) => self.range(p.key, v, p.range[0], p.range[1]),
                None => self.fail(p.key, "missing".into(), "a number (the key of a tunable parameter)"),
            }
        }
    }

    /// Records a bad value with what is allowed instead.
    pub(super) fn fail(&mut self, key: &str, value: String, allowed: &str) {
        self.0.push(InvalidValue {
            key: key.into(),
            value,
            allowed: allowed.into(),
        });
    }
}

impl Config {
    /// Checks every value against its range; returns all problems at once.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let mut c = Checker::default();
        self.camera.check(&mut c);
        self.warp.check(&mut c);
        self.check_lens(&mut c);
        self.lane.check(&mut c, self.warp.out_width);
        self.steering.check(&mut c);
        self.throttle.check(&mut c);
        self.vehicle.check(&mut c);
        self.sim.check(&mut c);
        self.check_sim_lens(&mut c);
        self.detect.check(&mut c);
        self.ranging.check(&mut c);
        self.classes.check(&mut c);
        self.check_box_bottoms(&mut c);
        self.behaviour.check(&mut c);
        self.gpio.check(&mut c);
        self.record.check(&mut c);
        self.dashboard.check(&mut c);
        self.manual.check(&mut c);
        self.route.check(&mut c);
        self.gamepad.check(&mut c);
        self.colour_template.check(&mut c);
        self.stereo.check(&mut c, self.camera.width);
        if c.0.is_empty() {
            // The steering method as built from the sections it reads (checked above).
            self.check_steering_method(&mut c);
        }
        if c.0.is_empty() {
            Ok(())
        } else {
            Err(ConfigError::Invalid {
                origin: "config".into(),
                errors: c.0,
            })
        }
    }

    /// `[classes.<name>]` against `[camera]`: a box bottom at or above the lens is never seen
    /// below the horizon, so Eq. 5 cannot range it.
    fn check_box_bottoms(&self, c: &mut Checker) {
        for (class, k) in self.classes.iter() {
            if k.bottom_m >= self.camera.height_m {
                c.fail(
                    &format!("classes.{class}.bottom_m"),
                    k.bottom_m.to_string(),
                    "below camera.height_m (a ray through the box bottom must go down)",
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        Config::default().validate().unwrap();
    }

    #[test]
    fn out_of_range_names_key_value_and_range() {
        let e = Config::from_toml_str("[steering]\nkp = -3.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: steering.kp = -3 is out of range (allowed: 0 ..= 20)");
    }

    #[test]
    fn collinear_roi_is_rejected() {
        let e = Config::from_toml_str(
            "[warp]\nsrc = [[0.0,0.0],[10.0,10.0],[20.0,20.0],[30.0,30.0]]\n",
            "t.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("warp.src"), "{e}");
    }

    #[test]
    fn gpio_pin_used_twice_names_both_keys() {
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 17\nled_pin = 5\nechO_pin = 1\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gpio.echO_pin") && e.contains("did you mean `echo_pin`"),
            "{e}"
        );
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 23\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: gpio.trig_pin = 23 is out of range (allowed: a pin not already used by gpio.button_pin)"
        );
        let e = Config::from_toml_str("[gpio]\nled_pin = 24\ntrig_pin = 24\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gpio.trig_pin = 24") && e.contains("used by gpio.led_pin"),
            "{e}"
        );
        assert!(e.contains("gpio.echo_pin = 24") && e.lines().count() == 2, "{e}");
        // Without an ultrasonic sensor its pins are free for other uses.
        Config::from_toml_str("[gpio]\nultrasonic = false\nled_pin = 23\n", "t.toml").unwrap();
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 40\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: gpio.button_pin = 40 is out of range (allowed: 2 ..= 27)");
    }

    #[test]
    fn gpio_and_record_ranges() {
        let bad = [
            ("gpio.debounce_ms=0", "gpio.debounce_ms"),
            ("gpio.long_press_ms=50", "gpio.long_press_ms"),
            ("gpio.release_m=0.2", "gpio.release_m"), // below brake_m
            ("gpio.brake_m=5", "gpio.brake_m"),
            ("gpio.sensor_temp_c=90", "gpio.sensor_temp_c"),
            ("gpio.median_n=0", "gpio.median_n"),
            ("gpio.period_ms=10", "gpio.period_ms"),
            ("record.jpeg_quality=0", "record.jpeg_quality"),
            ("record.jpeg_quality=101", "record.jpeg_quality"),
            ("record.max_mb=0", "record.max_mb"),
            ("record.segment_frames=0", "record.segment_frames"),
        ];
        for (set, key) in bad {
            let e = Config::default().with_override(set).unwrap_err().to_string();
            assert!(e.contains(key), "{set}: {e}");
        }
        let g = Config::default().gpio.options();
        assert_eq!((g.button_pin, g.led_pin, g.trig_pin, g.echo_pin), (17, 27, 23, 24));
        assert!((g.button.debounce_s - 0.03).abs() < 1e-12 && g.button.long_press_s.is_none());
        assert!((g.sonar.brake_m - 0.35).abs() < 1e-12 && (g.sonar_period_s - 0.06).abs() < 1e-12);
        let r = Config::default().record.options();
        assert_eq!((r.jpeg_quality, r.segment_frames), (90, 300));
        assert_eq!(r.max_bytes, 2_000_000_000);
    }
}
