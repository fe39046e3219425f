//! `[colour_template]`: the options of Abdollahi's colour + template stop-sign detector
//! (src/detect/colour_sign.rs) when a class's `detect` is `colour_template`: the red it keeps
//! (hue, saturation, value on OpenCV's 8-bit scales), the candidates' size and shape (pixels),
//! the template score it needs and the face box it reports.

use super::check::Checker;
use crate::detect::colour_sign::HsvSignOptions;
use serde::{Deserialize, Serialize};

/// `[colour_template]` (docs/detect.md, "Colour + template").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ColourTemplateConfig {
    /// Red hues at the low end: H <= this (0..180, OpenCV's scale: degrees / 2).
    pub hue_low_max: u8,
    /// Red hues at the high end: H >= this (0..180).
    pub hue_high_min: u8,
    /// Smallest saturation of a red pixel (0..255).
    pub sat_min: u8,
    /// Smallest value (brightness) of a red pixel (0..255).
    pub val_min: u8,
    /// Smallest candidate width and height, pixels.
    pub min_size_px: u32,
    /// Largest ratio of a candidate's longer side to its shorter one (>= 1).
    pub max_aspect: f64,
    /// Red components within this many pixels of each other are one candidate (0..8).
    pub merge_px: i32,
    /// Lowest correlation of a candidate's red mask with the template (-1..1).
    pub min_score: f64,
    /// The face's size over its red part's: the reported box is the red box grown by this.
    pub face_per_red: f64,
    /// The ring just outside a candidate must be at least this bright relative to its red
    /// (0 = no check; 0..2).
    pub rim_value_ratio: f64,
}

impl Default for ColourTemplateConfig {
    /// Chosen on real photos (training/realsets/tune_colour.py on DeepPiCar's `test` and `ver1`
    /// photos at 320×240; docs/detect.md): a narrower red than the simulator-tuned
    /// [`HsvSignOptions::default`] (wooden floors are orange, hue 9–17), no merging of
    /// touching components, a laxer rim check (a printed sign's rim is thin and JPEG-blurred
    /// into the red; 0.5 is the largest that kept the tuning photos' recall, and it still
    /// rejects a red lamp on a dark housing), a lower template score (real letters are blurred).
    fn default() -> Self {
        Self {
            hue_low_max: 6,
            hue_high_min: 165,
            sat_min: 90,
            val_min: 50,
            min_size_px: 6,
            max_aspect: 1.5,
            merge_px: 0,
            min_score: 0.4,
            face_per_red: 1.1,
            rim_value_ratio: 0.5,
        }
    }
}

impl ColourTemplateConfig {
    /// Checks of `[colour_template]`.
    pub(super) fn check(&self, c: &mut Checker) {
        c.range("colour_template.hue_low_max", self.hue_low_max, 0, 180);
        c.range("colour_template.hue_high_min", self.hue_high_min, 0, 180);
        c.range("colour_template.min_size_px", self.min_size_px, 4, 4096);
        c.range("colour_template.max_aspect", self.max_aspect, 1.0, 10.0);
        c.range("colour_template.merge_px", self.merge_px, 0, 8);
        c.range("colour_template.min_score", self.min_score, -1.0, 1.0);
        c.range("colour_template.face_per_red", self.face_per_red, 0.5, 2.0);
        c.range("colour_template.rim_value_ratio", self.rim_value_ratio, 0.0, 2.0);
    }
}

impl From<&ColourTemplateConfig> for HsvSignOptions {
    /// The detector's options of `[colour_template]` (template sizes and shifts: the detector's
    /// defaults).
    fn from(c: &ColourTemplateConfig) -> Self {
        HsvSignOptions {
            hue_low_max: c.hue_low_max,
            hue_high_min: c.hue_high_min,
            sat_min: c.sat_min,
            val_min: c.val_min,
            min_size_px: c.min_size_px,
            max_aspect: c.max_aspect,
            merge_px: c.merge_px,
            min_score: c.min_score,
            face_per_red: c.face_per_red,
            rim_value_ratio: c.rim_value_ratio,
            ..HsvSignOptions::default()
        }
    }
}
