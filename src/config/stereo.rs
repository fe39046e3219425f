//! `[stereo]`: a second camera for stereo ranging: the base between the lenses (metres), which
//! camera is the reference, the calibration file, the matcher's thresholds (correlation,
//! pixels) and how far apart in time two frames may be paired (milliseconds).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[stereo]`: a second camera for stereo ranging (src/stereo/, docs/stereo.md; Zaarane et
/// al. 2020, Abdollahi 2011).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StereoConfig {
    /// Distance between the two lenses, metres (used when `calibration` is empty).
    pub base_m: f64,
    /// Which camera detection runs on: `left` or `right`.
    pub reference: String,
    /// Results file of `rccar calibrate stereo` (JSON); empty = an ideal pair of `[camera]`.
    pub calibration: String,
    /// Lowest normalised cross-correlation that counts as a match (-1..1).
    pub min_ncc: f64,
    /// Largest disparity searched, pixels.
    pub max_disparity_px: u32,
    /// Of the correlation peaks scoring at least this fraction of the best, the nearest is
    /// taken (an object hides what is behind it); 1 = always the best.
    pub near_peak_ratio: f64,
    /// A box that matches a copy of itself along its own rows as well as it matches the other
    /// image (wallpaper, tiles) gets no range (`stereo::NoRange::Repeated`).
    pub reject_repeats: bool,
    /// Largest time between the two cameras' frames paired as one stereo frame, milliseconds.
    pub max_skew_ms: f64,
}

impl Default for StereoConfig {
    fn default() -> Self {
        Self {
            base_m: 0.06,
            reference: "left".into(),
            calibration: String::new(),
            min_ncc: 0.6,
            max_disparity_px: 120,
            near_peak_ratio: 0.9,
            reject_repeats: true,
            max_skew_ms: 20.0,
        }
    }
}

impl StereoConfig {
    /// Checks of `[stereo]`; the disparity search is bounded by the frame width `frame_width`
    /// (`camera.width`), pixels.
    pub(super) fn check(&self, c: &mut Checker, frame_width: u32) {
        let st = self;
        c.range("stereo.base_m", st.base_m, 0.01, 2.0);
        if st.reference != "left" && st.reference != "right" {
            c.fail(
                "stereo.reference",
                format!("{:?}", st.reference),
                "\"left\" or \"right\"",
            );
        }
        c.range("stereo.min_ncc", st.min_ncc, -1.0, 1.0);
        c.range("stereo.max_disparity_px", st.max_disparity_px, 1, frame_width.max(1));
        c.range("stereo.max_skew_ms", st.max_skew_ms, 0.0, 1000.0);
        c.range("stereo.near_peak_ratio", st.near_peak_ratio, 0.5, 1.0);
    }
}
