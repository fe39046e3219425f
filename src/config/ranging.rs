//! `[ranging]`: the distance of each detected box: the camera's calibration corrections (pixels,
//! a scale), the box noise (pixels, relative), the object tracker's noise (m/s², relative),
//! colour refinement and where the behaviours' distances come from (`method`). What each
//! class's box frames (heights and sizes, metres; a margin) is in its `[classes.<name>]`
//! section (`classes.rs`).

use super::check::Checker;
use super::Config;
use crate::camera::PinholeCamera;
use crate::classes::ObjectClass;
use crate::ranging::track::TrackerOptions;
use crate::ranging::{BoxRanging, TiltRanging};
use serde::{Deserialize, Serialize};
use std::fmt;

/// `ranging.method`: where the behaviours' distances come from. A value other than these is
/// refused when the configuration is read, naming the key, the value and the allowed ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RangingMethod {
    /// `mono`: the tilt and box size of one camera (src/ranging.rs).
    #[default]
    Mono,
    /// `stereo`: the disparity of a camera pair (`[stereo]`; docs/stereo.md).
    Stereo,
}

impl RangingMethod {
    /// The spelling in car.toml.
    pub fn name(self) -> &'static str {
        match self {
            RangingMethod::Mono => "mono",
            RangingMethod::Stereo => "stereo",
        }
    }
}

impl fmt::Display for RangingMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// `[ranging]`: distance of each detected box by tilt ranging (src/ranging.rs, docs/ranging.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RangingConfig {
    /// Calibrated principal-point row minus the image centre row, pixels
    /// (`rccar calibrate ranging` writes it).
    pub v0_offset_px: f64,
    /// Calibrated a_y divided by the nominal focal length from camera.hfov_deg.
    pub a_y_scale: f64,
    /// σ of a detector box's centre row, pixels.
    pub box_centre_sigma_px: f64,
    /// σ of a detector box's size, relative.
    pub box_size_sigma: f64,
    /// Object tracker: σ of an object's own acceleration along the line of sight, m/s².
    pub track_accel_sigma: f64,
    /// Object tracker: σ of the odometry's distance per frame, relative to that distance.
    pub track_odometry_sigma: f64,
    /// Object tracker: a track not matched on this many detection frames in a row is dropped.
    pub track_max_missed: u32,
    /// Refine stop-sign and traffic-light boxes by colour (red area, dark housing) before
    /// ranging them.
    pub refine_by_colour: bool,
    /// Share of a stop sign's face (across the flats) that is red inside its white rim.
    pub stop_sign_red_fraction: f64,
    /// Where the behaviours' distances come from: `mono` or `stereo` ([`RangingMethod`]).
    pub method: RangingMethod,
}

impl Default for RangingConfig {
    fn default() -> Self {
        Self {
            v0_offset_px: 0.0,
            a_y_scale: 1.0,
            box_centre_sigma_px: 1.0,
            box_size_sigma: 0.06,
            track_accel_sigma: 0.5,
            track_odometry_sigma: 0.1,
            track_max_missed: 3,
            refine_by_colour: true,
            stop_sign_red_fraction: 0.9,
            method: RangingMethod::Mono,
        }
    }
}

impl RangingConfig {
    /// Range checks of `[ranging]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let r = self;
        c.range("ranging.v0_offset_px", r.v0_offset_px, -200.0, 200.0);
        c.range("ranging.a_y_scale", r.a_y_scale, 0.5, 2.0);
        c.range("ranging.box_centre_sigma_px", r.box_centre_sigma_px, 0.01, 100.0);
        c.range("ranging.box_size_sigma", r.box_size_sigma, 0.001, 1.0);
        c.range("ranging.track_accel_sigma", r.track_accel_sigma, 0.0, 100.0);
        c.range("ranging.track_odometry_sigma", r.track_odometry_sigma, 0.0, 1.0);
        c.range("ranging.track_max_missed", r.track_max_missed, 0, 100);
        c.range("ranging.stop_sign_red_fraction", r.stop_sign_red_fraction, 0.1, 1.0);
    }
}

impl Config {
    /// Box ranging with the camera of `[camera]` corrected by the calibration of `[ranging]`
    /// (`v0_offset_px`, `a_y_scale`), what each class's box frames (`[classes.<name>]`) and
    /// the box noise.
    pub fn box_ranging(&self) -> BoxRanging {
        let r = &self.ranging;
        let mut camera = PinholeCamera::from(&self.camera);
        camera.v0 += r.v0_offset_px;
        camera.f_px *= r.a_y_scale;
        BoxRanging {
            tilt: TiltRanging::from_camera(&camera),
            camera,
            classes: ObjectClass::ALL.map(|c| self.classes[c].class_box()),
            centre_sigma_px: r.box_centre_sigma_px,
            size_sigma: r.box_size_sigma,
            refine: r.refine_by_colour,
            red_fraction: r.stop_sign_red_fraction,
        }
    }
}

impl From<&RangingConfig> for TrackerOptions {
    /// The object tracker's noise and patience of `[ranging]` (its association gates are the
    /// tracker's own defaults).
    fn from(r: &RangingConfig) -> Self {
        TrackerOptions {
            accel_sigma: r.track_accel_sigma,
            odometry_sigma: r.track_odometry_sigma,
            max_missed: r.track_max_missed,
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, RangingMethod};

    /// The TOML spellings are today's; another value names the key, the value and the
    /// allowed ones, from a file and from `--set`.
    #[test]
    fn method_reads_its_spellings_and_names_a_wrong_one() {
        for (text, want) in [("mono", RangingMethod::Mono), ("stereo", RangingMethod::Stereo)] {
            let c = Config::from_toml_str(&format!("[ranging]\nmethod = \"{text}\"\n"), "t.toml").unwrap();
            assert_eq!(
                (c.ranging.method, c.ranging.method.to_string()),
                (want, text.to_string())
            );
            assert!(c.to_toml().contains(&format!("method = \"{text}\"")));
        }
        let e = Config::from_toml_str("[ranging]\nmethod = \"Stereo\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: `ranging.method` = \"Stereo\": unknown variant `Stereo`, expected `mono` or `stereo`"
        );
        let e = Config::default()
            .with_override("ranging.method=laser")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`ranging.method` = \"laser\"") && e.contains("expected `mono` or `stereo`"),
            "{e}"
        );
    }
}
