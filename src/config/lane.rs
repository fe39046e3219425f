//! `[lane]`: extracting the lane lines from the bird's-eye image: grey threshold (0..=255),
//! Canny thresholds (gradient magnitude), the histogram band (a fraction of the image height),
//! the lane width and the car's centre offset (bird's-eye pixels).

use super::check::Checker;
use super::Config;
pub use crate::lane::lines::PeakMode;
use crate::lane::lines::LineOptions;
pub use crate::lane::threshold::ThresholdMode;
use crate::lane::warp::WarpError;
use crate::lane::{CannyOptions, LaneDetector, LaneOptions};
use serde::{Deserialize, Serialize};

/// `[lane]`: extracting the lane lines from the bird's-eye image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaneConfig {
    /// `fixed`, `otsu` or `adaptive`.
    pub threshold_mode: ThresholdMode,
    /// Grey level, 0..=255: pixels strictly brighter are "line".
    pub threshold: u8,
    /// `adaptive`: side of the square round each pixel whose mean it is compared with, odd,
    /// 3..=127 pixels.
    pub adaptive_block: u32,
    /// `adaptive`: a pixel is "line" when brighter than that mean − C (OpenCV's C), grey
    /// levels −255..=255; negative = brighter than the mean by that much.
    pub adaptive_c: i32,
    /// Side of the square the threshold image is opened with (eroded, then dilated) before
    /// the edges are added, pixels: 0 or 1 = not opened, else odd 3..=15. Removes white specks
    /// narrower than the square (a mottled floor passing the adaptive threshold); the tape is
    /// wider and stays.
    pub opening: u32,
    /// Canny hysteresis low threshold (L1 gradient magnitude of the 3x3 Sobel).
    pub canny_low: u16,
    /// Canny hysteresis high threshold.
    pub canny_high: u16,
    /// Run a 5x5 Gaussian blur before Canny.
    pub blur: bool,
    /// Fraction of the bird's-eye height, from the bottom, summed by the histogram, 0..1.
    pub band: f64,
    /// A line is found only where its histogram peak reaches this fraction of the band height.
    pub min_peak: f64,
    /// `centroid` or `argmax`: how a line's column is read from its peak.
    pub peak: PeakMode,
    /// Lane width between the two line centres in the bird's-eye image, pixels; used to
    /// estimate a lost line from the other.
    pub lane_width_px: f64,
    /// Two lines whose distance differs from `lane_width_px` by more than this fraction are
    /// implausible: the weaker is dropped and estimated from the stronger.
    pub width_tolerance: f64,
    /// L_F, the car's centre in the bird's-eye image, as an offset from the image centre,
    /// pixels (positive = right). Non-zero when the camera is mounted off-centre.
    pub center_offset_px: f64,
}

impl Default for LaneConfig {
    fn default() -> Self {
        Self {
            threshold_mode: ThresholdMode::Adaptive,
            threshold: 170,
            adaptive_block: 41,
            adaptive_c: -5,
            opening: 3,
            canny_low: 100,
            canny_high: 200,
            blur: true,
            band: 0.4,
            min_peak: 0.3,
            peak: PeakMode::Centroid,
            lane_width_px: 191.4,
            width_tolerance: 0.35,
            center_offset_px: 0.0,
        }
    }
}

impl LaneConfig {
    /// Range checks of `[lane]`; the width and centre offset are bounded by the bird's-eye
    /// image's width `bird_width` (`warp.out_width`), pixels.
    pub(super) fn check(&self, c: &mut Checker, bird_width: u32) {
        let l = self;
        if l.adaptive_block.is_multiple_of(2) || !(3..=127).contains(&l.adaptive_block) {
            c.fail(
                "lane.adaptive_block",
                l.adaptive_block.to_string(),
                "an odd number 3 ..= 127",
            );
        }
        c.range("lane.adaptive_c", l.adaptive_c, -255, 255);
        if l.opening > 1 && (l.opening.is_multiple_of(2) || l.opening > 15) {
            c.fail("lane.opening", l.opening.to_string(), "0, 1 or an odd number 3 ..= 15");
        }
        c.range("lane.canny_low", l.canny_low, 0, 2040);
        c.range("lane.canny_high", l.canny_high, 0, 2040);
        if l.canny_low > l.canny_high {
            c.fail("lane.canny_low", l.canny_low.to_string(), "<= lane.canny_high");
        }
        c.range("lane.band", l.band, 0.01, 1.0);
        c.range("lane.min_peak", l.min_peak, 0.0, 1.0);
        c.range("lane.lane_width_px", l.lane_width_px, 1.0, bird_width as f64);
        c.range("lane.width_tolerance", l.width_tolerance, 0.05, 1.0);
        c.range(
            "lane.center_offset_px",
            l.center_offset_px,
            -(bird_width as f64) / 2.0,
            bird_width as f64 / 2.0,
        );
    }
}

impl From<&LaneConfig> for LaneOptions {
    /// The lane stage's options of `[lane]`.
    fn from(l: &LaneConfig) -> Self {
        Self {
            threshold_mode: l.threshold_mode,
            threshold: l.threshold,
            adaptive: (l.adaptive_block, l.adaptive_c),
            opening: l.opening,
            canny: CannyOptions {
                low: l.canny_low,
                high: l.canny_high,
                blur: l.blur,
            },
            lines: LineOptions {
                band: l.band,
                min_peak: l.min_peak,
                peak: l.peak,
                lane_width_px: l.lane_width_px,
                width_tolerance: l.width_tolerance,
                center_offset_px: l.center_offset_px,
            },
        }
    }
}

/// Why the lane detector of a configuration cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum LaneSetupError {
    /// The ROI does not define a bird's-eye view.
    #[error(transparent)]
    Warp(WarpError),
    /// The camera's lens (`camera.distortion`, `camera.calibration`) cannot be used.
    #[error(transparent)]
    Lens(super::camera::LensError),
}

impl Config {
    /// The lane detector of `[camera]` (frame size and lens: `camera.distortion` or the file
    /// `camera.calibration` names, read here), `[warp]` and `[lane]`.
    pub fn lane_detector(&self) -> Result<LaneDetector, LaneSetupError> {
        let mut warp: crate::lane::WarpOptions = (&self.warp).into();
        warp.lens = self.camera_lens().map_err(LaneSetupError::Lens)?;
        LaneDetector::new(self.camera.width, self.camera.height, &warp, (&self.lane).into()).map_err(LaneSetupError::Warp)
    }
}
