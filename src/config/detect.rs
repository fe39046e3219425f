//! `[detect]`: the cascades the pipeline runs (file paths), their search parameters, where each
//! class is searched (fractions of the frame) and at which sizes (box widths and distances,
//! metres), and how often (frames).

use super::check::Checker;
use crate::classes::ObjectClass;
use crate::detect::detector::DetectParams;
use serde::{Deserialize, Serialize};

/// `[detect]`: the cascades the pipeline runs on every frame (docs/detect.md). A missing file
/// switches that detector off (the pipeline says so once and keeps lane keeping).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DetectConfig {
    /// Run detection at all.
    pub enabled: bool,
    /// Stop-sign cascade (OpenCV XML); a relative path is relative to the folder of the config
    /// file that names it.
    pub stop_sign: String,
    /// Traffic-light cascade; the light's state is read inside its boxes.
    pub traffic_light: String,
    /// Obstacle cascade.
    pub obstacle: String,
    /// Ratio between successive detection scales (> 1; OpenCV's scaleFactor).
    pub scale_factor: f64,
    /// A box needs more than this many raw hits (OpenCV's minNeighbors).
    pub min_neighbors: u32,
    /// Smallest window, pixels (both sides; 0 = the cascade's own size).
    pub min_size_px: u32,
    /// Where stop signs are searched: [left, top, right, bottom], fractions of the frame
    /// (0..1); a box must lie inside.
    pub stop_sign_region: [f64; 4],
    /// Where traffic lights are searched (as `stop_sign_region`).
    pub traffic_light_region: [f64; 4],
    /// Where obstacles are searched (as `stop_sign_region`).
    pub obstacle_region: [f64; 4],
    /// Distances at which objects must be found, [near, far] metres along the floor; with the
    /// box widths below they bound each cascade's window size.
    pub range_m: [f64; 2],
    /// Width of what the stop-sign cascade's box frames, [min, max] metres (its box, not the
    /// sign: trained boxes include a margin).
    pub stop_sign_box_m: [f64; 2],
    /// Width of a traffic-light box, [min, max] metres.
    pub traffic_light_box_m: [f64; 2],
    /// Width of an obstacle box, [min, max] metres.
    pub obstacle_box_m: [f64; 2],
    /// Run the cascades on every Nth frame only; the object tracker (src/ranging/track.rs)
    /// predicts boxes and ranges from odometry on the frames between. 1 = every frame.
    pub every_n_frames: u32,
    /// Search each class only where its box can stand for its size: the box bottom at the
    /// class's height (`[ranging] *_bottom_m`) seen at the distances within `range_m` that its
    /// width allows (`*_box_m`), give or take `pipeline::BAND_SLACK` of the window height.
    pub ground_band: bool,
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            stop_sign: ObjectClass::StopSign.info().model_file.into(),
            traffic_light: ObjectClass::TrafficLight.info().model_file.into(),
            obstacle: ObjectClass::Obstacle.info().model_file.into(),
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size_px: 0,
            stop_sign_region: [0.45, 0.0, 1.0, 0.6],
            traffic_light_region: [0.45, 0.0, 1.0, 0.6],
            obstacle_region: [0.0, 0.08, 1.0, 1.0],
            range_m: [0.2, 1.6],
            stop_sign_box_m: [0.11, 0.16],
            traffic_light_box_m: [0.065, 0.10],
            obstacle_box_m: [0.18, 0.45],
            every_n_frames: 2,
            ground_band: true,
        }
    }
}

/// One class's part of `[detect]` (`detect.<name>`, `<name>_region`, `<name>_box_m`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectClass<'a> {
    /// Its model file (a cascade), as written in the config.
    pub model: &'a str,
    /// Where it is searched, [left, top, right, bottom] fractions of the frame.
    pub region: [f64; 4],
    /// Width of its box, [min, max] metres.
    pub box_m: [f64; 2],
}

impl DetectConfig {
    /// The keys of `class` (the one place that maps a class to its `[detect]` fields).
    pub fn class(&self, class: ObjectClass) -> DetectClass<'_> {
        let (model, region, box_m) = match class {
            ObjectClass::StopSign => (&self.stop_sign, self.stop_sign_region, self.stop_sign_box_m),
            ObjectClass::TrafficLight => (&self.traffic_light, self.traffic_light_region, self.traffic_light_box_m),
            ObjectClass::Obstacle => (&self.obstacle, self.obstacle_region, self.obstacle_box_m),
        };
        DetectClass { model, region, box_m }
    }

    /// Checks of `[detect]`: scan parameters, regions inside the frame, ordered size ranges.
    pub(super) fn check(&self, c: &mut Checker) {
        let d = self;
        c.range("detect.scale_factor", d.scale_factor, 1.01, 2.0);
        c.range("detect.min_neighbors", d.min_neighbors, 0, 100);
        c.range("detect.min_size_px", d.min_size_px, 0, 4096);
        for (key, r) in [
            ("detect.stop_sign_region", d.stop_sign_region),
            ("detect.traffic_light_region", d.traffic_light_region),
            ("detect.obstacle_region", d.obstacle_region),
        ] {
            if !(r.iter().all(|v| (0.0..=1.0).contains(v)) && r[0] < r[2] && r[1] < r[3]) {
                c.fail(
                    key,
                    format!("{r:?}"),
                    "[left, top, right, bottom] in 0..=1 with left < right, top < bottom",
                );
            }
        }
        if !(d.range_m[0] >= 0.05 && d.range_m[0] < d.range_m[1] && d.range_m[1] <= 20.0) {
            c.fail(
                "detect.range_m",
                format!("{:?}", d.range_m),
                "[near, far] metres, 0.05 <= near < far <= 20",
            );
        }
        for (key, b) in [
            ("detect.stop_sign_box_m", d.stop_sign_box_m),
            ("detect.traffic_light_box_m", d.traffic_light_box_m),
            ("detect.obstacle_box_m", d.obstacle_box_m),
        ] {
            if !(b[0] > 0.0 && b[0] <= b[1] && b[1] <= 5.0) {
                c.fail(key, format!("{b:?}"), "[min, max] metres, 0 < min <= max <= 5");
            }
        }
        c.range("detect.every_n_frames", d.every_n_frames, 1, 30);
    }
}

impl From<&DetectConfig> for DetectParams {
    /// The cascade scan's parameters of `[detect]` (the same for every class; each class's
    /// region and sizes are set per cascade by the pipeline, `pipeline::detect_limits`).
    fn from(d: &DetectConfig) -> Self {
        DetectParams {
            scale_factor: d.scale_factor,
            min_neighbors: d.min_neighbors,
            min_size: (d.min_size_px, d.min_size_px),
            ..Default::default()
        }
    }
}
