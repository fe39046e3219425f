//! Camera calibration from checkerboard photos (Abdollahi 2011, Sec. on calibration; the method
//! is Zhang 2000 with OpenCV's lens model): find the inner corners of a printed checkerboard
//! ([`corners`]), fit each camera's intrinsics and lens distortion by Levenberg–Marquardt
//! ([`intrinsics`], [`lm`]), then the pair's rotation R and translation T and the
//! rectifying rotations and maps (Bouguet's method, as `cv2.stereoRectify`) ([`stereo`]).
//! Results are written to and read from a JSON file ([`file`]).
//!
//! Conventions follow OpenCV so numbers can be compared with `cv2.calibrateCamera`: pixel (i, j)
//! has its centre at (u, v) = (i, j); the camera looks along +z with x right and y down; a
//! point X_l in the left camera's frame is X_r = R·X_l + T in the right one's. Lengths of the
//! board (and so T) are in the unit of the square size given, metres in this project.

pub mod corners;
pub mod file;
pub mod intrinsics;
pub mod lm;
pub mod photos;
pub mod stereo;
pub mod tilt;

pub use corners::{corner_subpix, find_chessboard, BoardSize, CornerOptions};
pub use file::{CalibrationFile, CameraCalibration, StereoCalibration};
pub use intrinsics::{calibrate_camera, project_point, Distortion, Intrinsics, Pose};
pub use stereo::{stereo_calibrate, stereo_rectify, Rectification, RectifyMaps};

/// What can go wrong while calibrating.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// Too few views with a board to calibrate from.
    #[error("need at least {need} images with the board found, got {got}")]
    TooFewViews {
        /// Minimum number of views.
        need: usize,
        /// Views available.
        got: usize,
    },
    /// The views do not all have the same image size.
    #[error("image {name} is {got_w}x{got_h}, the first one is {want_w}x{want_h}")]
    SizeMismatch {
        /// The image that differs.
        name: String,
        /// Its width, pixels.
        got_w: u32,
        /// Its height, pixels.
        got_h: u32,
        /// Expected width.
        want_w: u32,
        /// Expected height.
        want_h: u32,
    },
    /// The left and right lists pair up differently.
    #[error("{left} left images but {right} right images: they must pair up one to one")]
    PairCount {
        /// Number of left images.
        left: usize,
        /// Number of right images.
        right: usize,
    },
    /// The closed-form start or the fit broke down (degenerate views, e.g. all fronto-parallel).
    #[error("calibration failed: {0}")]
    Degenerate(String),
}
