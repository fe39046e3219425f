//! Stereo ranges for the pipeline (`ranging.method = "stereo"`): a detector box of the
//! reference image is found in the other image ([`super::matching`], NCC along the rows) and
//! ranged by D = b·f/d (Abdollahi's Eq. 12, method (c) of [`super::geometry`]), then turned
//! into the forward distance on the floor and the lateral offset from the car's centre line
//! that the monocular ranging reports, with a σ from the disparity's noise:
//!
//! ```text
//!     σ_D = D² / (b·f) · σ_d          (∂D/∂d; σ_d = `disparity_sigma_px`)
//! ```
//!
//! so the object tracker (src/ranging/track.rs) weighs stereo and odometry as it weighs the
//! monocular ranges. Obstacles (plain coloured boxes) are matched on the two linear
//! colour-opponent planes (`matching::opponent_from_rgb`), where the grey floor and its lines
//! inside their box vanish, and then row by row: the distance is the vertical face's, the one
//! most rows agree on (`StereoGeometry::vertical_face`), not that of the box's mean
//! disparity, which the box's top (farther back) pulls long ([`match_for_class`]). A grey
//! obstacle (no colour) is matched on grey. A box without a match gives `None` (the caller
//! decides what to fall back on). With a calibration file (`stereo.calibration`) the pair is
//! rectified first and the box carried into the rectified image ([`super::rectify`]).
//! Units: metres, pixels.

use super::matching::{opponent_from_rgb_rows, Matcher, StereoMatch};
use super::{MatchOptions, NoRange, StereoGeometry};
use crate::detect::Rect;
use crate::lane::warp::rgb_to_gray_rows;
use crate::ranging::{BoxRange, ObjectClass};
use image::{GrayImage, RgbImage};
use std::ops::Range;

/// Relative spread of the rows' forward distances taken as one vertical face
/// ([`StereoGeometry::vertical_face`]); measured in tests/stereo_sim.rs (2 %…5 % give the
/// same table within 0.2 %).
pub const FACE_TOL: f64 = 0.03;

/// The images of one pair as the matcher needs them: grey, and for obstacles the two
/// colour-opponent planes.
#[derive(Debug, Clone)]
pub struct PairPlanes {
    /// Grey reference and other image.
    pub gray: [GrayImage; 2],
    /// Opponent planes of the reference and of the other image.
    pub opponent: [[GrayImage; 2]; 2],
}

impl Default for PairPlanes {
    fn default() -> Self {
        let e = || GrayImage::new(0, 0);
        Self {
            gray: [e(), e()],
            opponent: [[e(), e()], [e(), e()]],
        }
    }
}

impl PairPlanes {
    /// Converts a pair (reference first).
    pub fn set(&mut self, reference: &RgbImage, other: &RgbImage) {
        self.set_rows(reference, other, 0..reference.height().max(other.height()));
    }

    /// Converts the rows `rows` of a pair only (the rows a box is matched on: the matcher
    /// reads nothing outside a box's rows); the other rows keep what they held.
    pub fn set_rows(&mut self, reference: &RgbImage, other: &RgbImage, rows: Range<u32>) {
        for (img, gray) in [reference, other].into_iter().zip(&mut self.gray) {
            if gray.dimensions() != img.dimensions() {
                *gray = GrayImage::new(img.width(), img.height());
            }
            rgb_to_gray_rows(img, gray, rows.clone());
        }
        opponent_from_rgb_rows(reference, &mut self.opponent[0], rows.clone());
        opponent_from_rgb_rows(other, &mut self.opponent[1], rows);
    }
}

/// Matches the box `bbox` ([x, y, w, h]) of an object of `class`, the way the pipeline does.
/// Signs and lights: grey, the whole box. Obstacles: the opponent planes, the whole box (the
/// occlusion prior, threshold and "no range" rules as for grey), then the rows on their own;
/// when at least 3 rows agree on a vertical face its forward distance replaces the box's,
/// given back as the disparity that distance has at the box's centre row, so that all three
/// methods of [`StereoGeometry::range`] (called with that row) use it. A grey obstacle
/// (`Flat` opponent planes) falls back to grey. Returns the match and the face, if one was
/// found.
pub fn match_for_class(
    m: &mut Matcher,
    geometry: &StereoGeometry,
    planes: &PairPlanes,
    class: ObjectClass,
    bbox: [i64; 4],
    opts: &MatchOptions,
) -> Result<(StereoMatch, Option<super::geometry::FaceFit>), NoRange> {
    let grey = |m: &mut Matcher| m.match_box(&planes.gray[0], &planes.gray[1], bbox, opts);
    if class != ObjectClass::Obstacle {
        return grey(m).map(|g| (g, None));
    }
    let [r, o] = &planes.opponent;
    let whole = match m.match_planes(&[&r[0], &r[1]], &[&o[0], &o[1]], bbox, opts) {
        Err(NoRange::Flat) => return grey(m).map(|g| (g, None)),
        other => other?,
    };
    let Some(face) = geometry.vertical_face(m.rows(), FACE_TOL) else {
        return Ok((whole, None));
    };
    let v = bbox[1] as f64 + (bbox[3] as f64 - 1.0) / 2.0;
    let disparity = geometry.disparity_of_forward(face.forward_m, v);
    let x_other = if opts.reference_left {
        whole.x_ref - disparity
    } else {
        whole.x_ref + disparity
    };
    Ok((
        StereoMatch {
            disparity,
            x_other,
            ..whole
        },
        Some(face),
    ))
}

/// Stereo ranging of detector boxes, with its scratch buffers.
#[derive(Debug, Clone)]
pub struct StereoRanging {
    /// The pair's geometry (ideal from `[camera]` + `[stereo] base_m`, or a calibration's).
    pub geometry: StereoGeometry,
    /// How boxes are matched.
    pub options: MatchOptions,
    /// σ of a disparity, pixels (sub-pixel peak noise).
    pub disparity_sigma_px: f64,
    /// Lateral position of the reference lens from the car's centre line, metres (left +).
    pub reference_lateral_m: f64,
    matcher: Matcher,
    planes: PairPlanes,
    /// Rectification of a calibrated pair (`None`: the pair is taken as ideal).
    rectifier: Option<super::rectify::PairRectifier>,
    /// Whether the last pair could be rectified (its images are of the calibrated size).
    pair_ok: bool,
    /// Boxes matched and boxes without a match since the start.
    pub counts: (u64, u64),
}

impl StereoRanging {
    /// For a pair of `geometry` (e.g. `StereoGeometry::ideal`, taken as rectified), matched
    /// with `options`, whose `reference_left` says which camera is the reference
    /// (`Config::stereo_ranging` builds the one of car.toml).
    pub fn new(geometry: StereoGeometry, options: MatchOptions) -> Self {
        let left = options.reference_left;
        Self {
            options,
            disparity_sigma_px: 0.25,
            reference_lateral_m: if left { 1.0 } else { -1.0 } * geometry.base_m / 2.0,
            geometry,
            matcher: Matcher::new(),
            planes: PairPlanes::default(),
            rectifier: None,
            pair_ok: true,
            counts: (0, 0),
        }
    }

    /// For a calibrated pair: the geometry of the rectified camera and the rectification of
    /// every pair ([`super::rectify::PairRectifier`]), from the file `rccar calibrate stereo`
    /// wrote (loaded by the caller, e.g. [`crate::pipeline::Pipeline::new`]); the cameras are
    /// tilted down by `tilt_rad`, and matched with `options`.
    pub fn with_calibration(st: &crate::calib::file::StereoCalibration, tilt_rad: f64, options: MatchOptions) -> Self {
        let left = options.reference_left;
        let geometry = StereoGeometry::from_calibration(st, tilt_rad, left);
        let mut s = Self::new(geometry, options);
        s.rectifier = Some(super::rectify::PairRectifier::new(st, left));
        s
    }

    /// Whether pairs are rectified (a calibration is applied) or taken as ideal.
    pub fn rectified(&self) -> bool {
        self.rectifier.is_some()
    }

    /// Converts a new pair to grey (once per frame, before [`StereoRanging::range`]),
    /// rectifying it first when a calibration is applied.
    pub fn set_pair(&mut self, reference: &RgbImage, other: &RgbImage) {
        self.set_pair_rows(reference, other, 0..reference.height().max(other.height()));
    }

    /// [`StereoRanging::set_pair`] for the boxes `boxes` of the reference image only: the
    /// rows they are matched on (in the rectified image when a calibration is applied) are
    /// rectified and converted, the rest of the pair is not touched. [`StereoRanging::range`]
    /// then gives for these boxes exactly what it gives after `set_pair`; a frame without a
    /// box costs nothing. Call it once per pair with every box that will be ranged.
    pub fn set_pair_for(&mut self, reference: &RgbImage, other: &RgbImage, boxes: impl IntoIterator<Item = Rect>) {
        let (mut lo, mut hi) = (i64::MAX, i64::MIN);
        for rect in boxes {
            let bx = match &self.rectifier {
                None => Some([0, rect.y as i64, 0, rect.height as i64]),
                Some(r) => r.map_box(rect),
            };
            if let Some([_, y, _, h]) = bx {
                (lo, hi) = (lo.min(y), hi.max(y + h));
            }
        }
        let clip = |v: i64| v.clamp(0, u32::MAX as i64) as u32;
        let rows = if lo < hi { clip(lo)..clip(hi) } else { 0..0 };
        self.set_pair_rows(reference, other, rows);
    }

    /// Rectifies (when calibrated) and converts the rows `rows` of the pair.
    fn set_pair_rows(&mut self, reference: &RgbImage, other: &RgbImage, rows: Range<u32>) {
        match &mut self.rectifier {
            Some(r) => {
                self.pair_ok = r.rectify_rows(reference, other, rows.clone());
                if self.pair_ok {
                    let (a, b) = r.images();
                    self.planes.set_rows(a, b, rows);
                }
            }
            None => self.planes.set_rows(reference, other, rows),
        }
    }

    /// The range of the box `rect` of an object of `class` in the reference image of the
    /// last pair; `None` when it has no match (see [`super::NoRange`]).
    pub fn range(&mut self, class: ObjectClass, rect: Rect) -> Option<BoxRange> {
        let bx = match &self.rectifier {
            None => Some([rect.x as i64, rect.y as i64, rect.width as i64, rect.height as i64]),
            Some(r) if self.pair_ok => r.map_box(rect),
            Some(_) => None,
        };
        let Some(bx) = bx else {
            self.counts.1 += 1;
            return None;
        };
        let m = match_for_class(
            &mut self.matcher,
            &self.geometry,
            &self.planes,
            class,
            bx,
            &self.options,
        )
        .map(|(m, _)| m);
        let Ok(m) = m else {
            self.counts.1 += 1;
            return None;
        };
        let v = bx[1] as f64 + (bx[3] as f64 - 1.0) / 2.0;
        let Some(r) = self.geometry.range(&m, v, self.options.reference_left) else {
            self.counts.1 += 1;
            return None;
        };
        let fwd = r.forward_m[2]?;
        self.counts.0 += 1;
        let g = &self.geometry;
        let sigma = r.depth_bfd * r.depth_bfd / (g.base_m * g.f) * self.disparity_sigma_px;
        Some(BoxRange {
            distance_m: fwd,
            sigma_m: sigma * fwd / r.depth_bfd,
            lateral_m: r.lateral_m + self.reference_lateral_m,
            by_size: None,
            by_row: None,
        })
    }
}
