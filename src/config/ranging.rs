//! `[ranging]`: the distance of each detected box: the camera's calibration corrections (pixels,
//! a scale), what each class's box frames (heights and sizes, metres; margins), the box noise
//! (pixels, relative), the object tracker's noise (m/s², relative), colour refinement and where
//! the behaviours' distances come from (`method`).

use super::check::Checker;
use super::CameraConfig;
use crate::camera::PinholeCamera;
use crate::classes::ObjectClass;
use crate::ranging::track::TrackerOptions;
use crate::ranging::{BoxRanging, ClassBox, TiltRanging};
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
    /// Height above the floor of a stop sign box's bottom edge (the face's lower edge), metres.
    pub stop_sign_bottom_m: f64,
    /// Height of a traffic-light box's bottom edge (the housing's lower edge), metres.
    pub traffic_light_bottom_m: f64,
    /// Height of an obstacle box's bottom edge, metres (0: it stands on the floor).
    pub obstacle_bottom_m: f64,
    /// [width, height] of the face a stop-sign box frames, metres (0 = unknown: not used).
    pub stop_sign_size_m: [f64; 2],
    /// [width, height] of the face a traffic-light box frames (the housing), metres.
    pub traffic_light_size_m: [f64; 2],
    /// [width, height] of an obstacle's face, metres (0, 0: obstacles differ; contact row only).
    pub obstacle_size_m: [f64; 2],
    /// A stop-sign detector box's size over the face's outline (the training margin).
    pub stop_sign_box_margin: f64,
    /// A traffic-light detector box's size over the housing's outline.
    pub traffic_light_box_margin: f64,
    /// An obstacle detector box's size over the obstacle's outline.
    pub obstacle_box_margin: f64,
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
            stop_sign_bottom_m: 0.12,
            traffic_light_bottom_m: 0.10,
            obstacle_bottom_m: 0.0,
            stop_sign_size_m: [0.10, 0.10],
            traffic_light_size_m: [0.0, 0.12],
            obstacle_size_m: [0.0, 0.0],
            stop_sign_box_margin: 1.085,
            traffic_light_box_margin: 1.21,
            obstacle_box_margin: 1.36,
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
    /// What a detector box of `class` frames (`ranging.<name>_size_m`, `_bottom_m`,
    /// `_box_margin`; the one place that maps a class to its `[ranging]` fields).
    pub fn class_box(&self, class: ObjectClass) -> ClassBox {
        let (size, bottom_m, margin) = match class {
            ObjectClass::StopSign => (
                self.stop_sign_size_m,
                self.stop_sign_bottom_m,
                self.stop_sign_box_margin,
            ),
            ObjectClass::TrafficLight => (
                self.traffic_light_size_m,
                self.traffic_light_bottom_m,
                self.traffic_light_box_margin,
            ),
            ObjectClass::Obstacle => (self.obstacle_size_m, self.obstacle_bottom_m, self.obstacle_box_margin),
        };
        ClassBox {
            width_m: size[0],
            height_m: size[1],
            bottom_m,
            margin,
        }
    }

    /// Range checks of `[ranging]` (the box bottoms against the camera height are checked in
    /// `check.rs`).
    pub(super) fn check(&self, c: &mut Checker) {
        let r = self;
        c.range("ranging.v0_offset_px", r.v0_offset_px, -200.0, 200.0);
        c.range("ranging.a_y_scale", r.a_y_scale, 0.5, 2.0);
        c.range("ranging.stop_sign_bottom_m", r.stop_sign_bottom_m, 0.0, 3.0);
        c.range("ranging.traffic_light_bottom_m", r.traffic_light_bottom_m, 0.0, 3.0);
        c.range("ranging.obstacle_bottom_m", r.obstacle_bottom_m, 0.0, 3.0);
        for (key, v) in [
            ("ranging.stop_sign_size_m", r.stop_sign_size_m),
            ("ranging.traffic_light_size_m", r.traffic_light_size_m),
            ("ranging.obstacle_size_m", r.obstacle_size_m),
        ] {
            c.range(&format!("{key}[0]"), v[0], 0.0, 3.0);
            c.range(&format!("{key}[1]"), v[1], 0.0, 3.0);
        }
        c.range("ranging.stop_sign_box_margin", r.stop_sign_box_margin, 0.5, 3.0);
        c.range("ranging.traffic_light_box_margin", r.traffic_light_box_margin, 0.5, 3.0);
        c.range("ranging.obstacle_box_margin", r.obstacle_box_margin, 0.5, 3.0);
        c.range("ranging.box_centre_sigma_px", r.box_centre_sigma_px, 0.01, 100.0);
        c.range("ranging.box_size_sigma", r.box_size_sigma, 0.001, 1.0);
        c.range("ranging.track_accel_sigma", r.track_accel_sigma, 0.0, 100.0);
        c.range("ranging.track_odometry_sigma", r.track_odometry_sigma, 0.0, 1.0);
        c.range("ranging.track_max_missed", r.track_max_missed, 0, 100);
        c.range("ranging.stop_sign_red_fraction", r.stop_sign_red_fraction, 0.1, 1.0);
    }
}

impl RangingConfig {
    /// Box ranging with the camera of `[camera]` corrected by the calibration of `[ranging]`
    /// (`v0_offset_px`, `a_y_scale`), what each class's box frames and the box noise.
    pub fn box_ranging(&self, camera: &CameraConfig) -> BoxRanging {
        let mut camera = PinholeCamera::from(camera);
        camera.v0 += self.v0_offset_px;
        camera.f_px *= self.a_y_scale;
        BoxRanging {
            tilt: TiltRanging::from_camera(&camera),
            camera,
            classes: ObjectClass::ALL.map(|c| self.class_box(c)),
            centre_sigma_px: self.box_centre_sigma_px,
            size_sigma: self.box_size_sigma,
            refine: self.refine_by_colour,
            red_fraction: self.stop_sign_red_fraction,
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
