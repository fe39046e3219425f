//! The pipeline's detection stage: several labelled cascades (stop sign, traffic light,
//! obstacle, …) run on one frame, with the traffic-light state read inside the boxes of the
//! cascades marked as lights (Rivera & Andaluz 2021, Sec. 3.2 iii–iv).
//!
//! Cascades are loaded once ([`DetectStage::load`]); [`DetectStage::run`] is called per frame
//! and builds one image pyramid for all of them ([`super::pyramid`]): each scale is resized and
//! integrated once, and every cascade scans it in its own region of the frame
//! ([`DetectStage::set_region`]). Units: pixels of the frame.

use super::cascade::{Cascade, CascadeError};
use super::scan::{DetectError, DetectParams, Scanner};
use super::group::Rect;
use super::light::{light_state, LightReading};
use super::pyramid::{Pyramid, RowBand};
use image::{GrayImage, RgbImage};
use std::ops::Range;
use std::path::PathBuf;

/// One cascade to run: what it finds and how.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CascadeSpec {
    /// Label of the objects it finds, e.g. `stop`, `light`, `obstacle`.
    pub label: String,
    /// The cascade XML file.
    pub path: PathBuf,
    /// Read the traffic-light state inside its boxes.
    pub traffic_light: bool,
    /// Detection options.
    pub params: DetectParams,
}

/// One object found in a frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetectedObject {
    /// The label of the cascade that found it.
    pub label: String,
    /// Box in frame pixels.
    pub rect: Rect,
    /// Raw hits merged into the box.
    pub neighbors: u32,
    /// Traffic-light reading, for cascades marked `traffic_light` when a colour frame was given.
    pub light: Option<LightReading>,
}

/// Labelled detectors, loaded once and run on every frame.
#[derive(Debug, Clone)]
pub struct DetectStage {
    specs: Vec<CascadeSpec>,
    dets: Vec<Scanner>,
    /// Per cascade: where in the frame its boxes may lie (`None` = anywhere).
    regions: Vec<Option<Rect>>,
    /// Per cascade: its options (the spec's, with the size limits set by the pipeline).
    params: Vec<DetectParams>,
    pyramid: Pyramid,
    /// Per cascade: the rows its boxes' bottoms may lie in, per box width (`None` = anywhere
    /// in the region).
    bands: Vec<Option<RowBand>>,
    /// Grey copy of the last colour frame (reused).
    gray: GrayImage,
}

/// Grey from RGB as OpenCV's `cvtColor(RGB2GRAY)` computes it for 8-bit images
/// (`Y = (9798 R + 19235 G + 3735 B + 2^14) >> 15`, the same conversion the lane stage uses),
/// into a buffer reused across frames.
pub fn gray_from_rgb(rgb: &RgbImage, gray: &mut GrayImage) {
    if gray.dimensions() != rgb.dimensions() {
        *gray = GrayImage::new(rgb.width(), rgb.height());
    }
    crate::lane::warp::rgb_to_gray(rgb, gray);
}

impl DetectStage {
    /// Loads every cascade (the only filesystem access of the stage).
    pub fn load(specs: &[CascadeSpec]) -> Result<Self, CascadeError> {
        let entries = specs
            .iter()
            .map(|s| Ok((s.clone(), Cascade::from_file(&s.path)?)))
            .collect::<Result<_, CascadeError>>()?;
        Ok(Self::from_cascades(entries))
    }

    /// A stage from cascades already in memory (tests, the simulator).
    pub fn from_cascades(entries: Vec<(CascadeSpec, Cascade)>) -> Self {
        let n = entries.len();
        let (specs, dets): (Vec<_>, Vec<_>) = entries.into_iter().map(|(s, c)| (s, Scanner::new(c))).unzip();
        Self {
            params: specs.iter().map(|s| s.params).collect(),
            specs,
            dets,
            regions: vec![None; n],
            bands: vec![None; n],
            pyramid: Pyramid::new(),
            gray: GrayImage::new(0, 0),
        }
    }

    /// Restricts cascade `label` to boxes lying inside `region` (frame pixels; `None` = the
    /// whole frame), and sets its smallest and largest window (width, height; `(0, 0)` = no
    /// limit, as [`DetectParams`]). Windows outside are never scanned, and the pyramid is
    /// only built where some cascade looks. Returns false when no cascade has that label.
    pub fn set_limits(
        &mut self,
        label: &str,
        region: Option<Rect>,
        min_size: (u32, u32),
        max_size: (u32, u32),
    ) -> bool {
        let mut found = false;
        for (i, s) in self.specs.iter().enumerate() {
            if s.label == label {
                self.regions[i] = region;
                self.params[i].min_size = min_size;
                self.params[i].max_size = max_size;
                found = true;
            }
        }
        found
    }

    /// Restricts cascade `label` to boxes whose bottom edge lies, for their width, in `band`
    /// (within its region; `None` = no such limit). Windows outside are never scanned. Returns
    /// false when no cascade has that label.
    pub fn set_band(&mut self, label: &str, band: Option<RowBand>) -> bool {
        let mut found = false;
        for (i, s) in self.specs.iter().enumerate() {
            if s.label == label {
                self.bands[i] = band.clone();
                found = true;
            }
        }
        self.pyramid.set_bands(self.bands.clone());
        found
    }

    /// Restricts cascade `label` to boxes inside `region` (see [`DetectStage::set_limits`]).
    pub fn set_region(&mut self, label: &str, region: Option<Rect>) -> bool {
        let mut found = false;
        for (i, s) in self.specs.iter().enumerate() {
            if s.label == label {
                self.regions[i] = region;
                found = true;
            }
        }
        found
    }

    /// Spread the pyramid levels over threads (feature `parallel`) for every cascade.
    pub fn set_parallel(&mut self, parallel: bool) {
        for p in &mut self.params {
            p.parallel = parallel;
        }
    }

    /// The region, minimum and maximum window of each cascade, in run order.
    pub fn limits(&self) -> impl Iterator<Item = (&str, Option<Rect>, (u32, u32), (u32, u32))> {
        self.specs
            .iter()
            .zip(&self.regions)
            .zip(&self.params)
            .map(|((s, r), p)| (s.label.as_str(), *r, p.min_size, p.max_size))
    }

    /// The frame rows a `width` × `height` frame must have filled in for [`DetectStage::run`]
    /// to see what it would see in the whole frame: sorted, disjoint half-open ranges (the
    /// pyramid levels' rows, mapped back through the resize). A renderer may leave every
    /// other row unset.
    pub fn rows_needed(&mut self, width: u32, height: u32) -> Vec<Range<usize>> {
        let (w, h) = (width as usize, height as usize);
        match self.pyramid.plan(w, h, &self.dets, &self.params, &self.regions) {
            Ok(()) => self.pyramid.source_rows(),
            Err(_) => Vec::new(),
        }
    }

    /// Runs every cascade on a colour frame (the pipeline's input): grey conversion of the rows
    /// the pyramid reads ([`DetectStage::rows_needed`]) into a reused buffer, then
    /// [`DetectStage::run`] with the light reading enabled.
    pub fn run_rgb(&mut self, rgb: &RgbImage) -> Result<Vec<DetectedObject>, DetectError> {
        let mut gray = std::mem::take(&mut self.gray);
        if gray.dimensions() != rgb.dimensions() {
            gray = GrayImage::new(rgb.width(), rgb.height());
        }
        let spans = self.rows_needed(rgb.width(), rgb.height());
        for r in spans {
            crate::lane::warp::rgb_to_gray_rows(rgb, &mut gray, r.start as u32..r.end as u32);
        }
        let out = self.run(&gray, Some(rgb));
        self.gray = gray;
        out
    }

    /// Runs every cascade on the grey frame; `rgb` (the same frame in colour) enables the
    /// traffic-light reading.
    pub fn run(&mut self, gray: &GrayImage, rgb: Option<&RgbImage>) -> Result<Vec<DetectedObject>, DetectError> {
        let (w, h) = (gray.width() as usize, gray.height() as usize);
        let parallel = self.params.iter().any(|p| p.parallel);
        self.pyramid.run(
            gray.as_raw(),
            w,
            h,
            &mut self.dets,
            &self.params,
            &self.regions,
            parallel,
        )?;
        let mut out = Vec::new();
        for ((spec, det), params) in self.specs.iter().zip(&self.dets).zip(&self.params) {
            for d in det.grouped(w, h, params.min_neighbors) {
                out.push(DetectedObject {
                    label: spec.label.clone(),
                    rect: d.rect,
                    neighbors: d.neighbors,
                    light: match rgb {
                        Some(img) if spec.traffic_light => Some(light_state(img, d.rect)),
                        _ => None,
                    },
                });
            }
        }
        Ok(out)
    }

    /// The labels, in run order.
    pub fn labels(&self) -> impl Iterator<Item = &str> {
        self.specs.iter().map(|s| s.label.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×4 cascade that fires on windows whose top half is darker than the bottom half.
    const BRIGHT_BELOW: &str = r#"<opencv_storage><cascade><stageType>BOOST</stageType>
        <featureType>HAAR</featureType><height>4</height><width>4</width>
        <featureParams><maxCatCount>0</maxCatCount></featureParams>
        <stages><_><stageThreshold>0</stageThreshold><weakClassifiers>
          <_><internalNodes>0 -1 0 0.1</internalNodes><leafValues>-1 1</leafValues></_>
        </weakClassifiers></_></stages>
        <features><_><rects><_>0 0 4 4 -1.</_><_>0 2 4 2 2.</_></rects><tilted>0</tilted></_></features>
        </cascade></opencv_storage>"#;

    #[test]
    fn grey_conversion_is_opencvs() {
        // cv2.cvtColor(..., COLOR_RGB2GRAY) on these pixels gives 76, 150, 29, 130.
        let rgb = RgbImage::from_fn(4, 1, |x, _| {
            image::Rgb([[255, 0, 0], [0, 255, 0], [0, 0, 255], [12, 200, 77]][x as usize])
        });
        let mut g = GrayImage::new(0, 0);
        gray_from_rgb(&rgb, &mut g);
        assert_eq!(g.as_raw(), &vec![76, 150, 29, 130]);
    }

    #[test]
    fn labels_boxes_and_reads_lights_only_where_asked() {
        let c = Cascade::from_xml_str(BRIGHT_BELOW, "t").unwrap();
        let spec = |label: &str, light| CascadeSpec {
            label: label.into(),
            path: PathBuf::new(),
            traffic_light: light,
            params: DetectParams {
                min_neighbors: 0,
                max_size: (4, 4),
                ..Default::default()
            },
        };
        let mut stage = DetectStage::from_cascades(vec![(spec("edge", false), c.clone()), (spec("light", true), c)]);
        assert_eq!(stage.labels().collect::<Vec<_>>(), ["edge", "light"]);
        // Dark above, bright below, with a little texture so no window is flat.
        let gray = GrayImage::from_fn(8, 8, |x, y| {
            image::Luma([if y < 4 { 10 + x as u8 } else { 200 + x as u8 }])
        });
        let rgb = RgbImage::from_fn(8, 8, |x, y| {
            let v = gray.get_pixel(x, y).0[0];
            image::Rgb([v, v, v])
        });
        let found = stage.run(&gray, Some(&rgb)).unwrap();
        // The colour entry point converts to the same grey (a grey RGB image stays itself).
        assert_eq!(stage.run_rgb(&rgb).unwrap(), found);
        let edge: Vec<_> = found.iter().filter(|o| o.label == "edge").collect();
        let light: Vec<_> = found.iter().filter(|o| o.label == "light").collect();
        assert!(!edge.is_empty());
        assert_eq!(edge.len(), light.len());
        assert!(edge.iter().all(|o| o.light.is_none()));
        assert!(light.iter().all(|o| o.light.is_some()));
        // Every hit straddles the dark/bright boundary at row 4.
        assert!(
            edge.iter().all(|o| o.rect.y < 4 && o.rect.y + o.rect.height > 4),
            "{edge:?}"
        );
    }
}
