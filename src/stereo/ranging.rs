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
//! monocular ranges. Obstacles (plain coloured boxes) are matched on grey checked against
//! chroma (`matching::match_box_chroma_checked`), so the floor's lines inside their box do not
//! win. A box without a match gives `None` (the caller decides what to fall back on). Units:
//! metres, pixels.

use super::{MatchOptions, StereoGeometry};
use crate::config::Config;
use crate::detect::{gray_from_rgb, Rect};
use crate::ranging::{BoxRange, ObjectClass};
use image::{GrayImage, RgbImage};

/// Largest disagreement of the grey and the chroma disparity of an obstacle, relative, before
/// chroma overrules grey (measured in tests/stereo_sim.rs).
pub const CHROMA_GAP: f64 = 0.1;

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
    matcher: super::matching::Matcher,
    gray_ref: GrayImage,
    gray_other: GrayImage,
    chroma_ref: GrayImage,
    chroma_other: GrayImage,
    /// Boxes matched and boxes without a match since the start.
    pub counts: (u64, u64),
}

impl StereoRanging {
    /// For an ideal, rectified pair of `cfg`'s camera with `[stereo]`'s base and reference.
    pub fn from_config(cfg: &Config) -> Self {
        let cam = crate::camera::PinholeCamera::from_config(&cfg.camera);
        Self::with_geometry(cfg, StereoGeometry::ideal(&cam, cfg.stereo.base_m))
    }

    /// With the geometry of a calibration (`StereoGeometry::from_calibration`).
    pub fn with_geometry(cfg: &Config, geometry: StereoGeometry) -> Self {
        let left = cfg.stereo.reference != "right";
        Self {
            options: MatchOptions {
                max_disparity: cfg.stereo.max_disparity_px,
                min_score: cfg.stereo.min_ncc,
                near_peak_ratio: cfg.stereo.near_peak_ratio,
                reference_left: left,
                ..MatchOptions::default()
            },
            disparity_sigma_px: 0.25,
            reference_lateral_m: if left { 1.0 } else { -1.0 } * geometry.base_m / 2.0,
            geometry,
            matcher: super::matching::Matcher::new(),
            gray_ref: GrayImage::new(0, 0),
            gray_other: GrayImage::new(0, 0),
            chroma_ref: GrayImage::new(0, 0),
            chroma_other: GrayImage::new(0, 0),
            counts: (0, 0),
        }
    }

    /// Converts a new pair to grey (once per frame, before [`StereoRanging::range`]).
    pub fn set_pair(&mut self, reference: &RgbImage, other: &RgbImage) {
        gray_from_rgb(reference, &mut self.gray_ref);
        gray_from_rgb(other, &mut self.gray_other);
        super::matching::chroma_from_rgb(reference, &mut self.chroma_ref);
        super::matching::chroma_from_rgb(other, &mut self.chroma_other);
    }

    /// The range of the box `rect` of an object of `class` in the reference image of the
    /// last pair; `None` when it has no match (see [`super::NoRange`]).
    pub fn range(&mut self, class: ObjectClass, rect: Rect) -> Option<BoxRange> {
        let bx = [rect.x as i64, rect.y as i64, rect.width as i64, rect.height as i64];
        let m = if class == ObjectClass::Obstacle {
            super::matching::match_box_chroma_checked(
                &mut self.matcher,
                (&self.gray_ref, &self.gray_other),
                (&self.chroma_ref, &self.chroma_other),
                bx,
                &self.options,
                CHROMA_GAP,
            )
            .0
        } else {
            self.matcher
                .match_box(&self.gray_ref, &self.gray_other, bx, &self.options)
        };
        let Ok(m) = m else {
            self.counts.1 += 1;
            return None;
        };
        let v = rect.y as f64 + (rect.height as f64 - 1.0) / 2.0;
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
