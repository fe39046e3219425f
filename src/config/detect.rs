//! `[detect]`: whether the cascades run, their search parameters, at which distances objects
//! must be found (metres), and how often (frames). Each class's cascade file, region and box
//! width are in its `[classes.<name>]` section (`classes.rs`).

use super::check::Checker;
use crate::detect::detector::DetectParams;
use serde::{Deserialize, Serialize};

/// `[detect]`: how the cascades of the `[classes.<name>]` sections run on the frames
/// (docs/detect.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DetectConfig {
    /// Run detection at all.
    pub enabled: bool,
    /// Ratio between successive detection scales (> 1; OpenCV's scaleFactor).
    pub scale_factor: f64,
    /// A box needs more than this many raw hits (OpenCV's minNeighbors).
    pub min_neighbors: u32,
    /// Smallest window, pixels (both sides; 0 = the cascade's own size).
    pub min_size_px: u32,
    /// Distances at which objects must be found, [near, far] metres along the floor; with each
    /// class's box width (`classes.<name>.box_m`) they bound its cascade's window size.
    pub range_m: [f64; 2],
    /// Run the cascades on every Nth frame only; the object tracker (src/ranging/track.rs)
    /// predicts boxes and ranges from odometry on the frames between. 1 = every frame.
    pub every_n_frames: u32,
    /// Search each class only where its box can stand for its size: the box bottom at the
    /// class's height (`classes.<name>.bottom_m`) seen at the distances within `range_m` that
    /// its width allows (`classes.<name>.box_m`), give or take `pipeline::BAND_SLACK` of the
    /// window height.
    pub ground_band: bool,
    /// Drop a box of a class standing on the floor in its own colour (obstacles) whose middle
    /// has the chromaticity of the floor just in front of it, only darker or brighter: a
    /// shadow or a sun patch (src/ranging/refine.rs `floor_coloured`). The largest difference
    /// of any channel's chromaticity `c / (r + g + b)` that counts as the same colour, 0..0.2;
    /// 0 = off.
    pub shadow_tolerance: f64,
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size_px: 0,
            range_m: [0.2, 1.6],
            every_n_frames: 2,
            ground_band: true,
            shadow_tolerance: 0.02,
        }
    }
}

impl DetectConfig {
    /// Checks of `[detect]`: scan parameters, an ordered distance range.
    pub(super) fn check(&self, c: &mut Checker) {
        let d = self;
        c.range("detect.scale_factor", d.scale_factor, 1.01, 2.0);
        c.range("detect.min_neighbors", d.min_neighbors, 0, 100);
        c.range("detect.min_size_px", d.min_size_px, 0, 4096);
        c.range("detect.shadow_tolerance", d.shadow_tolerance, 0.0, 0.2);
        if !(d.range_m[0] >= 0.05 && d.range_m[0] < d.range_m[1] && d.range_m[1] <= 20.0) {
            c.fail(
                "detect.range_m",
                format!("{:?}", d.range_m),
                "[near, far] metres, 0.05 <= near < far <= 20",
            );
        }
        c.range("detect.every_n_frames", d.every_n_frames, 1, 30);
    }
}

impl From<&DetectConfig> for DetectParams {
    /// The cascade scan's parameters of `[detect]` (the same for every class; each class's
    /// region and sizes, `[classes.<name>]`, are set per cascade by the pipeline,
    /// `pipeline::detect_limits`).
    fn from(d: &DetectConfig) -> Self {
        DetectParams {
            scale_factor: d.scale_factor,
            min_neighbors: d.min_neighbors,
            min_size: (d.min_size_px, d.min_size_px),
            ..Default::default()
        }
    }
}
