//! `[stereo]`: a second camera for stereo ranging: the base between the lenses (metres), which
//! camera is the reference, the calibration file, the matcher's thresholds (correlation,
//! pixels) and how far apart in time two frames may be paired (milliseconds).

use super::check::Checker;
use super::Config;
use crate::calib::file::StereoCalibration;
use crate::camera::PinholeCamera;
use crate::stereo::ranging::StereoRanging;
use crate::stereo::still::PairSetup;
use crate::stereo::{MatchOptions, StereoGeometry};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::PathBuf;

/// `stereo.reference`: the camera of the pair that lane keeping and detection run on (the
/// other is only searched for matches). A value other than these is refused when the
/// configuration is read, naming the key, the value and the allowed ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StereoReference {
    /// `left`: the left camera (the other is to its right).
    #[default]
    Left,
    /// `right`: the right camera (the other is to its left).
    Right,
}

impl StereoReference {
    /// The spelling in car.toml.
    pub fn name(self) -> &'static str {
        match self {
            StereoReference::Left => "left",
            StereoReference::Right => "right",
        }
    }

    /// Whether the reference is the left camera.
    pub fn is_left(self) -> bool {
        self == StereoReference::Left
    }

    /// The other camera of the pair.
    pub fn other(self) -> StereoReference {
        match self {
            StereoReference::Left => StereoReference::Right,
            StereoReference::Right => StereoReference::Left,
        }
    }
}

impl fmt::Display for StereoReference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// `[stereo]`: a second camera for stereo ranging (src/stereo/, docs/stereo.md; Zaarane et
/// al. 2020, Abdollahi 2011).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StereoConfig {
    /// Distance between the two lenses, metres (used when `calibration` is empty).
    pub base_m: f64,
    /// Which camera detection runs on: `left` or `right` ([`StereoReference`]).
    pub reference: StereoReference,
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
            reference: StereoReference::Left,
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
        c.range("stereo.min_ncc", st.min_ncc, -1.0, 1.0);
        c.range("stereo.max_disparity_px", st.max_disparity_px, 1, frame_width.max(1));
        c.range("stereo.max_skew_ms", st.max_skew_ms, 0.0, 1000.0);
        c.range("stereo.near_peak_ratio", st.near_peak_ratio, 0.5, 1.0);
    }
}

impl From<&StereoConfig> for MatchOptions {
    /// The box matcher's thresholds and reference camera of `[stereo]`.
    fn from(st: &StereoConfig) -> Self {
        MatchOptions {
            max_disparity: st.max_disparity_px,
            min_score: st.min_ncc,
            near_peak_ratio: st.near_peak_ratio,
            reject_repeats: st.reject_repeats,
            reference_left: st.reference.is_left(),
            ..MatchOptions::default()
        }
    }
}

impl Config {
    /// How `rccar stereo` readies a still pair of `width`×`height` images: `[stereo]`'s
    /// calibration file (none: an ideal pair of `[camera]` at that size with `[stereo]`'s base),
    /// `[camera]`'s tilt and `[stereo]`'s matcher.
    pub fn still_pair_setup(&self, width: u32, height: u32) -> PairSetup {
        let mut cam = self.camera.clone();
        cam.width = width;
        cam.height = height;
        PairSetup {
            calibration: (!self.stereo.calibration.is_empty()).then(|| PathBuf::from(&self.stereo.calibration)),
            camera: PinholeCamera::from(&cam),
            base_m: self.stereo.base_m,
            tilt_rad: self.camera.tilt_deg.to_radians(),
            matching: (&self.stereo).into(),
        }
    }

    /// Stereo ranging of an ideal, rectified pair of `[camera]` with `[stereo]`'s base and
    /// reference.
    pub fn stereo_ranging(&self) -> StereoRanging {
        let cam = PinholeCamera::from(&self.camera);
        StereoRanging::new(StereoGeometry::ideal(&cam, self.stereo.base_m), (&self.stereo).into())
    }

    /// Stereo ranging of the calibrated pair `st` (the file `stereo.calibration` names), with
    /// `[camera]`'s tilt and `[stereo]`'s matcher.
    pub fn stereo_ranging_calibrated(&self, st: &StereoCalibration) -> StereoRanging {
        StereoRanging::with_calibration(st, self.camera.tilt_deg.to_radians(), (&self.stereo).into())
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, StereoReference};

    /// The TOML spellings are today's; another value names the key, the value and the
    /// allowed ones.
    #[test]
    fn reference_reads_its_spellings_and_names_a_wrong_one() {
        for (text, want) in [("left", StereoReference::Left), ("right", StereoReference::Right)] {
            let c = Config::default()
                .with_override(&format!("stereo.reference={text}"))
                .unwrap();
            assert_eq!(
                (c.stereo.reference, c.stereo.reference.to_string()),
                (want, text.to_string())
            );
            assert_eq!(c.stereo.reference.is_left(), text == "left");
            assert_ne!(c.stereo.reference.other(), want);
            assert!(c.to_toml().contains(&format!("reference = \"{text}\"")));
        }
        let e = Config::from_toml_str("[stereo]\nreference = \"middle\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: `stereo.reference` = \"middle\": unknown variant `middle`, expected `left` or `right`"
        );
    }
}
