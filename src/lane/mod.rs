//! Lane detection after Rivera & Andaluz (2021), Sec. 3.2: ROI and bird's-eye warp
//! ([`warp`]), grey threshold ([`threshold`]) and Canny edges ([`edges`]), column histogram,
//! the two lines, the lane centre (Eq. 3) and the error (Eq. 2) ([`lines`]).
//!
//! [`LaneDetector`] owns the precomputed warp map and every buffer, so measuring a frame
//! allocates nothing. Each stage is also a plain function that tests and the OpenCV parity
//! script can call on its own.

pub mod edges;
pub mod lines;
pub mod synth;
pub mod threshold;
pub mod warp;

pub use lines::{LaneMeasurement, LaneStatus, LineOptions};

use crate::config::{Config, ThresholdMode};
use crate::timing::{StageTimer, StageTimes};
use edges::{CannyOptions, CannyScratch};
use image::{GrayImage, RgbImage};
use warp::{WarpError, WarpMap};

/// Options of the whole lane stage, from `[warp]` and `[lane]` of car.toml.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneOptions {
    /// Fixed level or Otsu.
    pub threshold_mode: ThresholdMode,
    /// Fixed grey level (0..=255).
    pub threshold: u8,
    /// Canny thresholds and blur.
    pub canny: CannyOptions,
    /// Histogram band and line finding.
    pub lines: LineOptions,
}

impl LaneOptions {
    /// The options configured in `cfg`.
    pub fn from_config(cfg: &Config) -> Self {
        let l = &cfg.lane;
        Self {
            threshold_mode: l.threshold_mode,
            threshold: l.threshold,
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

/// The intermediate images of the last frame, for annotation and parity checks.
#[derive(Debug, Clone)]
pub struct LaneImages {
    /// Grey bird's-eye view.
    pub bird: GrayImage,
    /// Canny edges (255 = edge).
    pub edges: GrayImage,
    /// Threshold ∪ edges, the image the histogram counts.
    pub binary: GrayImage,
    /// Column histogram of the band.
    pub hist: Vec<u16>,
    /// Rows in the histogram band.
    pub band_rows: u32,
    /// Threshold level used (fixed or Otsu's).
    pub level: u8,
}

/// Measures the lane in camera frames of one size: ROI → bird's-eye → threshold + Canny →
/// histogram → lines → centre → error.
#[derive(Debug, Clone)]
pub struct LaneDetector {
    map: WarpMap,
    opts: LaneOptions,
    scratch: CannyScratch,
    gray_frame: GrayImage,
    exact_warp: bool,
    images: LaneImages,
}

impl LaneDetector {
    /// Precomputes the warp map for `frame_w × frame_h` frames and allocates the buffers.
    pub fn new(
        frame_w: u32,
        frame_h: u32,
        roi: &[[f64; 2]; 4],
        out_w: u32,
        out_h: u32,
        opts: LaneOptions,
    ) -> Result<Self, WarpError> {
        let map = WarpMap::new(frame_w, frame_h, roi, out_w, out_h)?;
        let band_rows = lines::band_rows(out_h, opts.lines.band);
        Ok(Self {
            map,
            opts,
            scratch: CannyScratch::new(out_w, out_h),
            gray_frame: GrayImage::new(frame_w, frame_h),
            exact_warp: false,
            images: LaneImages {
                bird: GrayImage::new(out_w, out_h),
                edges: GrayImage::new(out_w, out_h),
                binary: GrayImage::new(out_w, out_h),
                hist: vec![0; out_w as usize],
                band_rows,
                level: 0,
            },
        })
    }

    /// The detector configured in `cfg` (frames of `[camera]` size).
    pub fn from_config(cfg: &Config) -> Result<Self, WarpError> {
        let mut d = Self::new(
            cfg.camera.width,
            cfg.camera.height,
            &cfg.warp.src,
            cfg.warp.out_width,
            cfg.warp.out_height,
            LaneOptions::from_config(cfg),
        )?;
        d.exact_warp = cfg.warp.exact;
        Ok(d)
    }

    /// Measures the lane in one frame (of the size given to [`LaneDetector::new`]).
    /// `timer` is lapped after each stage and the laps are written into `times`.
    pub fn measure(&mut self, frame: &RgbImage, timer: &mut dyn StageTimer, times: &mut StageTimes) -> LaneMeasurement {
        let im = &mut self.images;
        // 1. Grey, then ROI + bird's-eye (one channel to interpolate instead of three), or
        //    OpenCV's exact order (colour warp, then grey).
        if self.exact_warp {
            self.map.warp_rgb_to_gray(frame, &mut im.bird);
        } else {
            warp::rgb_to_gray_rows(frame, &mut self.gray_frame, self.map.src_rows());
            self.map.warp(&self.gray_frame, &mut im.bird);
        }
        times.warp_us = timer.lap_us();
        // 2. Canny on the grey bird's-eye image.
        edges::canny(&im.bird, &self.opts.canny, &mut self.scratch, &mut im.edges);
        times.canny_us = timer.lap_us();
        // 3. Threshold, united with the edges.
        im.level = match self.opts.threshold_mode {
            ThresholdMode::Fixed => self.opts.threshold,
            ThresholdMode::Otsu => threshold::otsu_level(&im.bird),
        };
        threshold::threshold_or_edges(&im.bird, im.level, &im.edges, &mut im.binary);
        times.threshold_us = timer.lap_us();
        // 4. Column histogram of the band nearest the car.
        lines::column_histogram(&im.binary, im.band_rows, &mut im.hist);
        times.histogram_us = timer.lap_us();
        // 5. Lines, centre, error.
        let m = lines::measure(&im.hist, im.band_rows, &self.opts.lines);
        times.lines_us = timer.lap_us();
        m
    }

    /// The intermediate images of the last measured frame.
    pub fn images(&self) -> &LaneImages {
        &self.images
    }

    /// The warp map (its homography relates camera and bird's-eye pixels).
    pub fn warp_map(&self) -> &WarpMap {
        &self.map
    }

    /// The options in use.
    pub fn options(&self) -> &LaneOptions {
        &self.opts
    }
}
