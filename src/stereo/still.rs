//! One still stereo pair, as `rccar stereo LEFT RIGHT` ranges it: rectified with the maps of a
//! calibration file (which must be for the images' size), or taken as an ideal rectified pair
//! of the configured camera; then each box of the reference image is matched along the rows of
//! the other image and ranged ([`StillPair::range_record`]: one JSON line per box). The
//! configuration converts into [`PairSetup`]
//! (`Config::still_pair_setup`), so this module reads no configuration.

use super::geometry::{StereoGeometry, StereoRange};
use super::matching::{MatchOptions, Matcher, StereoMatch};
use super::NoRange;
use crate::calib::file::{CalibrationFile, FileError};
use crate::calib::stereo::RectifyMaps;
use crate::camera::PinholeCamera;
use crate::detect::gray_from_rgb;
use image::{GrayImage, RgbImage};
use std::path::PathBuf;

/// How a still pair is made ready for matching.
#[derive(Debug, Clone)]
pub struct PairSetup {
    /// The stereo calibration file; `None`: an ideal rectified pair of `camera`.
    pub calibration: Option<PathBuf>,
    /// The configured camera, at the images' size (the ideal pair's intrinsics).
    pub camera: PinholeCamera,
    /// Base between the lenses of the ideal pair, metres.
    pub base_m: f64,
    /// The camera's tilt, radians (of a calibrated pair).
    pub tilt_rad: f64,
    /// The matcher's thresholds and reference camera.
    pub matching: MatchOptions,
}

/// A pair ready for matching: grey, rectified when calibrated, and its geometry.
#[derive(Debug, Clone)]
pub struct StillPair {
    /// The left image, grey (rectified when calibrated).
    pub left: GrayImage,
    /// The right image, likewise.
    pub right: GrayImage,
    /// The pair's geometry.
    pub geometry: StereoGeometry,
    /// The matcher's options.
    pub matching: MatchOptions,
}

impl StillPair {
    /// Greys (and with a calibration file, rectifies) the pair `l`, `r` of one size; the
    /// calibration file is read here and must be for that size.
    pub fn new(setup: &PairSetup, l: &RgbImage, r: &RgbImage) -> Result<Self, FileError> {
        let (w, h) = l.dimensions();
        let (mut gl, mut gr) = (GrayImage::new(0, 0), GrayImage::new(0, 0));
        gray_from_rgb(l, &mut gl);
        gray_from_rgb(r, &mut gr);
        let reference_left = setup.matching.reference_left;
        let geometry = match &setup.calibration {
            None => StereoGeometry::ideal(&setup.camera, setup.base_m),
            Some(path) => {
                let st = CalibrationFile::load_stereo(path, w, h)?;
                let rc = &st.rectification;
                let ml = RectifyMaps::new(&st.left.intrinsics, &st.left.distortion, &rc.r1, rc.f, rc.c, w, h);
                let mr = RectifyMaps::new(&st.right.intrinsics, &st.right.distortion, &rc.r2, rc.f, rc.c, w, h);
                let (mut a, mut b) = (GrayImage::new(0, 0), GrayImage::new(0, 0));
                ml.remap_gray(&gl, &mut a);
                mr.remap_gray(&gr, &mut b);
                (gl, gr) = (a, b);
                StereoGeometry::from_calibration(&st, setup.tilt_rad, reference_left)
            }
        };
        Ok(Self { left: gl, right: gr, geometry, matching: setup.matching })
    }

    /// The reference image (detection runs on it).
    pub fn reference(&self) -> &GrayImage {
        if self.matching.reference_left {
            &self.left
        } else {
            &self.right
        }
    }

    /// Matches box `b` (`[x, y, w, h]` in the reference image) in the other image and ranges
    /// it at its centre row; `None` range: a match whose disparity gives no range.
    pub fn range_box(&self, m: &mut Matcher, b: [i64; 4]) -> Result<(StereoMatch, Option<StereoRange>), NoRange> {
        let other = if self.matching.reference_left { &self.right } else { &self.left };
        let v = b[1] as f64 + (b[3] as f64 - 1.0) / 2.0;
        let mm = m.match_box(self.reference(), other, b, &self.matching)?;
        Ok((mm, self.geometry.range(&mm, v, self.matching.reference_left)))
    }

    /// [`StillPair::range_box`] as `rccar stereo`'s JSON line of box `b` labelled `label`:
    /// the disparity, the match score, the depth and forward distance by Eq. 16, exact angles
    /// and b·f/d, and the lateral offset; or `no_range` saying why there is none.
    pub fn range_record(&self, m: &mut Matcher, label: &str, b: [i64; 4]) -> serde_json::Value {
        match self.range_box(m, b) {
            Ok((mm, Some(rg))) => serde_json::json!({
                "label": label, "box": b, "disparity_px": mm.disparity, "ncc": mm.score,
                "depth_m": {"eq16": rg.depth_eq16, "exact": rg.depth_exact, "bfd": rg.depth_bfd},
                "forward_m": {"eq16": rg.forward_m[0], "exact": rg.forward_m[1], "bfd": rg.forward_m[2]},
                "lateral_m": rg.lateral_m,
            }),
            Ok((mm, None)) => {
                serde_json::json!({"label": label, "box": b, "no_range": format!("disparity {:.3} px", mm.disparity)})
            }
            Err(e) => serde_json::json!({"label": label, "box": b, "no_range": e.to_string()}),
        }
    }
}
