//! Stereo ranging after Zaarane et al. (2020) and Abdollahi (2011): an object detected in the
//! reference camera is found again in the other (rectified) image by normalised
//! cross-correlation along the same rows ([`matching`]); its disparity gives the distance by
//! three formulas side by side ([`geometry`]):
//!
//! - (a) Zaarane's Eq. 16 as written: angles taken linearly from pixel columns
//!   (ω/H per pixel), `h = A·sin θ·sin φ / sin(180° − (θ + φ))`;
//! - (b) the same triangle with exact pinhole angles atan((x − c_x)/f);
//! - (c) D = b·f/d (Abdollahi's thesis), algebraically identical to (b) for a rectified pair.
//!
//! Abdollahi's stop-sign path: [`hsv_sign`] (HSV threshold + template matching),
//! [`meanshift`] (colour-histogram mean-shift tracking between detections) and [`speed`]
//! (relative speed from 5-frame averaged disparities).
//!
//! Depths are along the optical axis; [`geometry::StereoGeometry::forward_of_depth`] turns
//! them into the forward distance on the floor the monocular ranging reports (the camera is
//! tilted). Units: metres, pixels, radians.

pub mod geometry;
pub mod hsv_sign;
pub mod matching;
pub mod meanshift;
pub mod ranging;
pub mod rectify;
pub mod source;
pub mod speed;
pub mod still;

pub use geometry::{StereoGeometry, StereoRange};
pub use matching::{match_box, MatchOptions, StereoMatch};
pub use source::{StereoFrame, StereoSource};

/// Why a box got no stereo range (never a wrong number).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoRange {
    /// The two images differ in size.
    #[error("the pair's images differ in size: {left_w}x{left_h} and {right_w}x{right_h}")]
    SizeMismatch {
        /// Reference image width.
        left_w: u32,
        /// Reference image height.
        left_h: u32,
        /// Other image width.
        right_w: u32,
        /// Other image height.
        right_h: u32,
    },
    /// The box is empty, too small to correlate, or outside the image.
    #[error("box {0:?} is too small or outside the image")]
    BadBox([i64; 4]),
    /// The template is flat (no texture to correlate).
    #[error("the box has no texture to match (flat grey)")]
    Flat,
    /// The best correlation is below the threshold: the object is not in the other image.
    #[error("best match {score:.3} is below the threshold {min:.3}")]
    BelowThreshold {
        /// Best normalised correlation found.
        score: f64,
        /// The threshold.
        min: f64,
    },
    /// Disparity zero or negative: the object is at infinity or the match is wrong.
    #[error("disparity {0:.3} px: no distance (at infinity or a wrong match)")]
    NonPositiveDisparity(f64),
    /// The disparity search range holds no position (box at the image edge).
    #[error("no room to search: the box is at the image edge")]
    NoSearchRoom,
    /// The box is a repeated pattern: it matches a copy of itself along its own rows as well
    /// as it matches the other image, so the match may be a copy (`reject_repeats`).
    #[error("the box repeats along its rows (a copy of it scores {copy:.3}, the match {score:.3}): no unique match")]
    Repeated {
        /// Best correlation of the box with a shifted copy of itself.
        copy: f64,
        /// Correlation of the match in the other image.
        score: f64,
    },
}
