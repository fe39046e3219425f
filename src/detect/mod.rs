//! Object detection with OpenCV's Haar and LBP cascades, in pure Rust (issue 4; Rivera &
//! Andaluz 2021 detect stop signs and traffic lights with OpenCV's `CascadeClassifier`).
//!
//! ```text
//! Cascade::from_file(xml)            load once (current or old OpenCV XML format)
//!   -> Detector::new(cascade)        keeps pyramid, integral and scratch buffers
//!   -> Detector::detect(&gray, &DetectParams) -> Vec<Detection>   every frame
//!   -> light_state(&rgb, rect)       traffic-light colour inside a box
//!   -> arrow::read_arrow(&rgb, rect) a turn sign's arrow inside a box
//! ```
//!
//! [`DetectStage`] bundles labelled cascades (stop, light, obstacle) for the pipeline and runs
//! them on one shared image pyramid ([`pyramid`]), each in its own region of the frame and
//! size range.
//!
//! The boxes are OpenCV 4's `detectMultiScale` boxes for the same grey image (see
//! `docs/detect.md` and `tests/parity/detect_parity.py` for the measured agreement).

pub mod annotate;
pub mod arrow;
pub mod cascade;
pub mod colour_sign;
pub mod detector;
pub mod group;
pub mod integral;
pub mod light;
pub mod pyramid;
pub mod resize;
pub mod scan;
pub mod stage;

pub use cascade::{Cascade, CascadeError, FeatureType};
pub use detector::{DetectError, DetectParams, Detection, Detector};
pub use group::{group_rectangles, Rect};
pub use light::{light_state, LightReading, LightState};
pub use pyramid::RowBand;
pub use stage::{gray_from_rgb, CascadeSpec, DetectStage, DetectedObject};
