//! The pipeline's detection stage: several labelled cascades (stop sign, traffic light,
//! obstacle, …) run on one frame, with the traffic-light state read inside the boxes of the
//! cascades marked as lights (Rivera & Andaluz 2021, Sec. 3.2 iii–iv).
//!
//! Cascades are loaded once ([`DetectStage::load`]); [`DetectStage::run`] is called per frame
//! and builds one image pyramid for all of them ([`super::pyramid`]): each scale is resized and
//! integrated once, and every cascade scans it in its own region of the frame
//! ([`DetectStage::set_region`]). Units: pixels of the frame.
//!
//! A class may be found by a colour detector instead of a cascade
//! ([`DetectStage::add_colour_sign`]: Abdollahi's HSV threshold + template matching,
//! `detect::colour_sign`); it runs on the colour frame inside its region and its boxes join the
//! cascades' in the same list, with the same label, so ranging and the behaviours take them
//! as they take a cascade's.

use super::cascade::{Cascade, CascadeError};
use super::scan::{DetectError, DetectParams, Scanner};
use super::group::Rect;
use super::light::{light_state, LightReading};
use super::pyramid::{Pyramid, RowBand};
use crate::detect::colour_sign::HsvSignDetector;
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
    /// Colour detectors, run after the cascades (`classes.<name>.detect = "colour_template"`).
    colour: Vec<ColourSign>,
}

/// A class found by colour and shape rather than by a cascade.
#[derive(Debug, Clone)]
struct ColourSign {
    label: String,
    det: HsvSignDetector,
    /// Where its boxes may lie (`None` = anywhere).
    region: Option<Rect>,
    /// Smallest and largest box (width, height; 0 = no limit), as a cascade's window.
    min_size: (u32, u32),
    max_size: (u32, u32),
}

impl ColourSign {
    /// Its boxes in `rgb`: the detector on the region's pixels, boxes moved back to frame
    /// pixels and kept when they lie inside the region and within the size limits.
    fn run(&mut self, rgb: &RgbImage) -> Vec<Rect> {
        let frame = Rect::new(0, 0, rgb.width() as i32, rgb.height() as i32);
        let region = self.region.map_or(frame, |r| r.intersect(&frame));
        if region.area() <= 0 {
            return Vec::new();
        }
        let crop;
        let img = if region == frame {
            rgb
        } else {
            crop = image::imageops::crop_imm(
                rgb,
                region.x as u32,
                region.y as u32,
                region.width as u32,
                region.height as u32,
            )
            .to_image();
            &crop
        };
        let within = |v: i32, lo: u32, hi: u32| {
            let v = v.max(0) as u32;
            v >= lo && (hi == 0 || v <= hi)
        };
        self.det
            .detect(img)
            .into_iter()
            .map(|d| Rect::new(d.rect.x + region.x, d.rect.y + region.y, d.rect.width, d.rect.height))
            .filter(|r| r.intersect(&region) == *r)
            .filter(|r| {
                within(r.width, self.min_size.0, self.max_size.0) && within(r.height, self.min_size.1, self.max_size.1)
            })
            .collect()
    }
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
            colour: Vec::new(),
        }
    }

    /// Adds a colour detector whose boxes are labelled `label` (run on colour frames only:
    /// [`DetectStage::run_rgb`], or [`DetectStage::run`] with the colour frame). Its region and
    /// size limits are set by label like a cascade's ([`DetectStage::set_limits`]); row bands do
    /// not apply to it (it reads its whole region).
    pub fn add_colour_sign(&mut self, label: &str, det: HsvSignDetector) {
        self.colour.push(ColourSign {
            label: label.into(),
            det,
            region: None,
            min_size: (0, 0),
            max_size: (0, 0),
        });
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
        for c in self.colour.iter_mut().filter(|c| c.label == label) {
            c.region = region;
            c.min_size = min_size;
            c.max_size = max_size;
            found = true;
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
        for c in self.colour.iter_mut().filter(|c| c.label == label) {
            c.region = region;
            found = true;
        }
        found
    }

    /// Spread the pyramid levels over threads (feature `parallel`) for every cascade; the
    /// pipeline then also runs this stage beside its lane stage.
    pub fn set_parallel(&mut self, parallel: bool) {
        for p in &mut self.params {
            p.parallel = parallel;
        }
    }

    /// Whether any cascade spreads its levels over threads ([`DetectStage::set_parallel`]).
    pub fn is_parallel(&self) -> bool {
        self.params.iter().any(|p| p.parallel)
    }

    /// The region, minimum and maximum window of each cascade, then of each colour detector,
    /// in run order.
    pub fn limits(&self) -> impl Iterator<Item = (&str, Option<Rect>, (u32, u32), (u32, u32))> {
        self.specs
            .iter()
            .zip(&self.regions)
            .zip(&self.params)
            .map(|((s, r), p)| (s.label.as_str(), *r, p.min_size, p.max_size))
            .chain(
                self.colour
                    .iter()
                    .map(|c| (c.label.as_str(), c.region, c.min_size, c.max_size)),
            )
    }

    /// The frame rows a `width` × `height` frame must have filled in for [`DetectStage::run`]
    /// to see what it would see in the whole frame: sorted, disjoint half-open ranges (the
    /// pyramid levels' rows, mapped back through the resize). A renderer may leave every
    /// other row unset.
    pub fn rows_needed(&mut self, width: u32, height: u32) -> Vec<Range<usize>> {
        let (w, h) = (width as usize, height as usize);
        let mut rows = if self.dets.is_empty() {
            Vec::new()
        } else {
            match self.pyramid.plan(w, h, &self.dets, &self.params, &self.regions) {
                Ok(()) => self.pyramid.source_rows(),
                Err(_) => Vec::new(),
            }
        };
        if self.colour.is_empty() {
            return rows;
        }
        // A colour detector reads every row of its region.
        let frame = Rect::new(0, 0, width as i32, height as i32);
        for c in &self.colour {
            let r = c.region.map_or(frame, |r| r.intersect(&frame));
            if r.area() > 0 {
                rows.push(r.y as usize..(r.y + r.height) as usize);
            }
        }
        rows.sort_by_key(|r| r.start);
        let mut out: Vec<Range<usize>> = Vec::with_capacity(rows.len());
        for r in rows {
            match out.last_mut() {
                Some(l) if r.start <= l.end => l.end = l.end.max(r.end),
                _ => out.push(r),
            }
        }
        out
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
    /// traffic-light reading and the colour detectors.
    pub fn run(&mut self, gray: &GrayImage, rgb: Option<&RgbImage>) -> Result<Vec<DetectedObject>, DetectError> {
        let (w, h) = (gray.width() as usize, gray.height() as usize);
        let parallel = self.is_parallel();
        if !self.dets.is_empty() {
            self.pyramid.run(
                gray.as_raw(),
                w,
                h,
                &mut self.dets,
                &self.params,
                &self.regions,
                parallel,
            )?;
        }
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
        if let Some(img) = rgb {
            for c in &mut self.colour {
                for rect in c.run(img) {
                    out.push(DetectedObject {
                        label: c.label.clone(),
                        rect,
                        neighbors: 0,
                        light: None,
                    });
                }
            }
        }
        Ok(out)
    }

    /// The labels, in run order (the cascades', then the colour detectors').
    pub fn labels(&self) -> impl Iterator<Item = &str> {
        self.specs
            .iter()
            .map(|s| s.label.as_str())
            .chain(self.colour.iter().map(|c| c.label.as_str()))
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

    /// A colour detector's boxes come out of the stage with its label, only from colour
    /// frames, only inside its region and size limits; its region's rows are read.
    #[test]
    fn a_colour_detector_joins_the_cascades_boxes() {
        use crate::detect::colour_sign::{octagon_model, HsvSignDetector, HsvSignOptions};
        let c = Cascade::from_xml_str(BRIGHT_BELOW, "t").unwrap();
        let spec = CascadeSpec {
            label: "edge".into(),
            path: PathBuf::new(),
            traffic_light: false,
            params: DetectParams {
                min_neighbors: 0,
                max_size: (4, 4),
                ..Default::default()
            },
        };
        let mut stage = DetectStage::from_cascades(vec![(spec, c)]);
        let det = HsvSignDetector::with_octagon_model(HsvSignOptions::default()).unwrap();
        stage.add_colour_sign("stop_sign", det);
        assert_eq!(stage.labels().collect::<Vec<_>>(), ["edge", "stop_sign"]);
        let mut rgb = RgbImage::from_pixel(160, 120, image::Rgb([110, 110, 110]));
        image::imageops::overlay(&mut rgb, &octagon_model(30), 100, 20);
        let stops = |st: &mut DetectStage, rgb: &RgbImage| -> Vec<Rect> {
            st.run_rgb(rgb)
                .unwrap()
                .into_iter()
                .filter(|o| o.label == "stop_sign")
                .map(|o| o.rect)
                .collect()
        };
        let found = stops(&mut stage, &rgb);
        assert_eq!(found.len(), 1, "{found:?}");
        let r = found[0];
        assert!(
            (r.x - 100).abs() <= 2 && (r.y - 20).abs() <= 2 && (r.width - 30).abs() <= 3,
            "{r:?}"
        );
        // No colour frame: no colour boxes.
        let mut gray = GrayImage::new(0, 0);
        gray_from_rgb(&rgb, &mut gray);
        assert!(stage.run(&gray, None).unwrap().iter().all(|o| o.label != "stop_sign"));
        // A region that holds the sign keeps it (and its rows are read); one that cuts it does not.
        assert!(stage.set_limits("stop_sign", Some(Rect::new(80, 0, 80, 60)), (0, 0), (0, 0)));
        assert_eq!(stops(&mut stage, &rgb), found);
        assert!(stage.rows_needed(160, 120).iter().any(|r| r.start == 0 && r.end >= 60));
        stage.set_region("stop_sign", Some(Rect::new(0, 0, 110, 120)));
        assert!(stops(&mut stage, &rgb).is_empty());
        // Size limits as a cascade's window.
        stage.set_limits("stop_sign", None, (0, 0), (20, 20));
        assert!(stops(&mut stage, &rgb).is_empty());
        stage.set_limits("stop_sign", None, (20, 20), (0, 0));
        assert_eq!(stops(&mut stage, &rgb), found);
        // The pipeline's limits: widths only, no height limit (`u32::MAX`).
        stage.set_limits("stop_sign", None, (18, 0), (213, u32::MAX));
        assert_eq!(stops(&mut stage, &rgb), found);
        // A stage of colour detectors only.
        let mut only = DetectStage::from_cascades(vec![]);
        only.add_colour_sign(
            "stop_sign",
            HsvSignDetector::with_octagon_model(HsvSignOptions::default()).unwrap(),
        );
        assert_eq!(stops(&mut only, &rgb), found);
        assert_eq!(only.rows_needed(160, 120), vec![0..120]);
    }
}
