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
//! Abdollahi's stop-sign path: [`crate::detect::colour_sign`] (HSV threshold + template matching),
//! [`meanshift`] (colour-histogram mean-shift tracking between detections) and [`speed`]
//! (relative speed from 5-frame averaged disparities).
//!
//! Depths are along the optical axis; [`geometry::StereoGeometry::forward_of_depth`] turns
//! them into the forward distance on the floor the monocular ranging reports (the camera is
//! tilted). Units: metres, pixels, radians.

pub mod geometry;
pub mod matching;
pub mod meanshift;
pub mod ranging;
pub mod rectify;
pub mod source;
pub mod speed;
pub mod still;

pub use geometry::{StereoGeometry, StereoRange};
pub use matching::{match_box, MatchOptions, NoRange, StereoMatch};
pub use source::{StereoFrame, StereoSource};
