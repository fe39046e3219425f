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
pub use intrinsics::{calibrate_camera, project_point, CalibError, Distortion, Intrinsics, Pose};
pub use stereo::{stereo_calibrate, stereo_rectify, Rectification, RectifyMaps};
