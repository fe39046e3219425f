//! Lane detection after Rivera & Andaluz (2021), Sec. 3.2: ROI and bird's-eye warp
//! ([`warp`]), grey threshold ([`threshold`]) and Canny edges ([`edges`]), column histogram,
//! the two lines, the lane centre (Eq. 3) and the error (Eq. 2) ([`lines`]); stop and give-way
//! lines across the lane ([`stop_line`]).
//!
//! [`LaneDetector`] owns the precomputed warp map and every buffer, so measuring a frame
//! allocates nothing. Each stage is also a plain function that tests and the OpenCV parity
//! script can call on its own.

pub mod edges;
pub mod junction;
pub mod lines;
pub mod stop_line;
pub mod synth;
pub mod threshold;
pub mod warp;

pub use edges::CannyOptions;
pub use lines::{LaneMeasurement, LaneStatus, LineOptions, PeakMode};
pub use threshold::ThresholdMode;

use crate::timing::{StageTimer, StageTimes};
use edges::CannyScratch;
use image::{GrayImage, RgbImage};
use warp::{WarpError, WarpMap};

/// The bird's-eye view the lane is measured in (`[warp]` of car.toml converts into it).
#[derive(Debug, Clone, PartialEq)]
pub struct WarpOptions {
    /// The ROI's corners in the camera frame, pixels: top-left, top-right, bottom-right,
    /// bottom-left.
    pub src: [[f64; 2]; 4],
    /// Width of the bird's-eye image, pixels.
    pub out_width: u32,
    /// Height of the bird's-eye image, pixels.
    pub out_height: u32,
    /// Warp each colour channel, then convert to grey (OpenCV's exact order) instead of grey
    /// first.
    pub exact: bool,
    /// The camera's lens (pinhole and distortion) folded into the warp's table
    /// ([`WarpMap::with_lens`]); `None` (or zero distortion) for an ideal pinhole camera.
    pub lens: Option<crate::lens::Lens>,
}

/// Options of the lane measurement in the bird's-eye image (`[lane]` of car.toml converts
/// into them).
#[derive(Debug, Clone, PartialEq)]
pub struct LaneOptions {
    /// Fixed level or Otsu.
    pub threshold_mode: ThresholdMode,
    /// Fixed grey level (0..=255).
    pub threshold: u8,
    /// Adaptive threshold: side of the square the mean is taken over (odd), pixels, and C (a
    /// pixel is line when brighter than the mean − C), grey levels.
    pub adaptive: (u32, i32),
    /// Side of the square the threshold image is opened with before the edges are added
    /// (odd; 0 or 1: not opened): white specks narrower than this are removed.
    pub opening: u32,
    /// Canny thresholds and blur.
    pub canny: CannyOptions,
    /// Histogram band and line finding.
    pub lines: LineOptions,
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
    /// Threshold level used (fixed or Otsu's; 0 for the adaptive threshold).
    pub level: u8,
}

impl LaneImages {
    /// The stage images by name, as `rccar stages` writes them (`<name>.bird.png` …): the grey
    /// bird's-eye view, the edges and threshold ∪ edges.
    pub fn stages(&self) -> [(&'static str, &GrayImage); 3] {
        [("bird", &self.bird), ("edges", &self.edges), ("binary", &self.binary)]
    }

    /// The frame's record of `rccar stages` (one JSON line per image, for the OpenCV parity
    /// script): the threshold level, the histogram band's rows, the histogram, the
    /// bird's-eye → camera matrix (row-major, so another tool can warp identically) and the
    /// lane measured; the caller adds the image's names.
    pub fn stage_record(&self, bird_to_camera: &[f64; 9], lane: &LaneMeasurement) -> serde_json::Value {
        serde_json::json!({
            "level": self.level, "band_rows": self.band_rows, "hist": self.hist,
            "bird_to_camera": bird_to_camera, "lane": lane,
        })
    }
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
    box_scratch: threshold::BoxScratch,
    open_scratch: Vec<u8>,
}

impl LaneDetector {
    /// Precomputes the warp map for `frame_w × frame_h` frames and allocates the buffers
    /// (`Config::lane_detector` builds the one of car.toml).
    pub fn new(frame_w: u32, frame_h: u32, warp: &WarpOptions, opts: LaneOptions) -> Result<Self, WarpError> {
        let (out_w, out_h) = (warp.out_width, warp.out_height);
        let map = WarpMap::with_lens(frame_w, frame_h, &warp.src, out_w, out_h, warp.lens.as_ref())?;
        let band_rows = lines::band_rows(out_h, opts.lines.band);
        Ok(Self {
            map,
            opts,
            scratch: CannyScratch::new(out_w, out_h),
            gray_frame: GrayImage::new(frame_w, frame_h),
            exact_warp: warp.exact,
            images: LaneImages {
                bird: GrayImage::new(out_w, out_h),
                edges: GrayImage::new(out_w, out_h),
                binary: GrayImage::new(out_w, out_h),
                hist: vec![0; out_w as usize],
                band_rows,
                level: 0,
            },
            box_scratch: threshold::BoxScratch::default(),
            open_scratch: Vec::new(),
        })
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
        let (block, c) = self.opts.adaptive;
        im.level = match self.opts.threshold_mode {
            ThresholdMode::Fixed => self.opts.threshold,
            ThresholdMode::Otsu => threshold::otsu_level(&im.bird),
            ThresholdMode::Adaptive => 0,
        };
        let open = self.opts.opening > 1;
        match (self.opts.threshold_mode, open) {
            (ThresholdMode::Fixed | ThresholdMode::Otsu, false) => {
                threshold::threshold_or_edges(&im.bird, im.level, &im.edges, &mut im.binary)
            }
            (ThresholdMode::Adaptive, false) => {
                threshold::adaptive_or_edges(&im.bird, block, c, &im.edges, &mut self.box_scratch, &mut im.binary)
            }
            (ThresholdMode::Fixed | ThresholdMode::Otsu, true) => {
                threshold::threshold(&im.bird, im.level, &mut im.binary)
            }
            (ThresholdMode::Adaptive, true) => {
                threshold::adaptive(&im.bird, block, c, &mut self.box_scratch, &mut im.binary)
            }
        }
        if open {
            // Specks out of the threshold image, then the edges in.
            threshold::open_square(&mut im.binary, self.opts.opening, &mut self.open_scratch);
            threshold::or_edges(&mut im.binary, &im.edges);
        }
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

    /// The bird's-eye → camera pixel matrix, row-major; zeros when the warp cannot be
    /// inverted.
    pub fn bird_to_camera(&self) -> [f64; 9] {
        let m = self.map.homography().inverse().map(|h| h.0).unwrap_or_default();
        std::array::from_fn(|k| m[(k / 3, k % 3)])
    }

    /// The options in use.
    pub fn options(&self) -> &LaneOptions {
        &self.opts
    }
}
