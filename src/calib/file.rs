//! The calibration results file (JSON) that `rccar calibrate camera|stereo` writes and the
//! stereo ranging reads: intrinsics, distortion, per-image errors, the pair's R and T and
//! the rectification. Lengths in the unit of the board's square size (metres here), angles
//! in radians, image quantities in pixels.

use super::corners::BoardSize;
use super::intrinsics::{CameraFit, Distortion, Intrinsics};
use super::stereo::{Rectification, StereoFit};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One camera's calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraCalibration {
    /// Image size the calibration holds for, [width, height] pixels.
    pub image_size: [u32; 2],
    /// Focal lengths and principal point.
    pub intrinsics: Intrinsics,
    /// k1, k2, p1, p2, k3.
    pub distortion: Distortion,
    /// RMS reprojection error over all views, pixels.
    pub rms_px: f64,
    /// (image, RMS reprojection error in pixels) of each image used.
    pub per_image_rms_px: Vec<(String, f64)>,
    /// Images where the board was not found.
    pub board_not_found: Vec<String>,
}

impl CameraCalibration {
    /// The results of `fit` over the images `names` (in the fit's order) of `size`
    /// (width, height); `not_found`: the images without a board.
    pub fn from_fit(fit: &CameraFit, names: &[String], size: (u32, u32), not_found: Vec<String>) -> CameraCalibration {
        CameraCalibration {
            image_size: [size.0, size.1],
            intrinsics: fit.k,
            distortion: fit.dist,
            rms_px: fit.rms,
            per_image_rms_px: names.iter().cloned().zip(fit.per_view_rms.iter().copied()).collect(),
            board_not_found: not_found,
        }
    }
}

/// A stereo pair's calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StereoCalibration {
    /// Left camera.
    pub left: CameraCalibration,
    /// Right camera.
    pub right: CameraCalibration,
    /// Rotation left → right (X_r = R·X_l + T), row-major.
    pub r: [[f64; 3]; 3],
    /// Translation left → right, metres.
    pub t: [f64; 3],
    /// Baseline length |T|, metres.
    pub baseline_m: f64,
    /// RMS reprojection error of the stereo fit over both cameras, pixels.
    pub rms_px: f64,
    /// (left image, right image, RMS) of each pair used.
    pub per_pair_rms_px: Vec<(String, String, f64)>,
    /// Pairs left out because the board was not found in one or both images.
    pub pairs_not_used: Vec<String>,
    /// Rectifying rotations and the rectified camera.
    pub rectification: Rectification,
}

impl StereoCalibration {
    /// The pair's results: both cameras, the stereo fit `st` over the image pairs
    /// `names` (left, right; in the fit's order), its rectification, and the pairs not used.
    pub fn from_fit(
        left: CameraCalibration,
        right: CameraCalibration,
        st: &StereoFit,
        names: &[(String, String)],
        pairs_not_used: Vec<String>,
        rectification: Rectification,
    ) -> StereoCalibration {
        let m = st.r;
        StereoCalibration {
            left,
            right,
            r: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
            ],
            t: [st.t[0], st.t[1], st.t[2]],
            baseline_m: st.t.norm(),
            rms_px: st.rms,
            per_pair_rms_px: names
                .iter()
                .zip(&st.per_view_rms)
                .map(|((l, r), e)| (l.clone(), r.clone(), *e))
                .collect(),
            pairs_not_used,
            rectification,
        }
    }
}

/// What a results file holds.
#[allow(clippy::large_enum_variant)] // read once per run
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CalibrationFile {
    /// `rccar calibrate camera`.
    Camera {
        /// The board used.
        board: BoardSize,
        /// Square size, metres.
        square_m: f64,
        /// The result.
        camera: CameraCalibration,
    },
    /// `rccar calibrate stereo`.
    Stereo {
        /// The board used.
        board: BoardSize,
        /// Square size, metres.
        square_m: f64,
        /// The result.
        stereo: StereoCalibration,
    },
}

/// Reading a results file failed.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be read.
    #[error("{path}: {err}")]
    Io {
        /// The file.
        path: String,
        /// Why (in the message, not a `source`: the error is said once).
        err: std::io::Error,
    },
    /// The file is not a calibration results file.
    #[error("{path}: not a calibration file: {msg}")]
    Parse {
        /// The file.
        path: String,
        /// serde's message (line and column).
        msg: String,
    },
    /// A camera file where a stereo one is needed, or the other way round.
    #[error("{path}: holds a {got} calibration, {want} needed")]
    Kind {
        /// The file.
        path: String,
        /// What it holds.
        got: &'static str,
        /// What was needed.
        want: &'static str,
    },
    /// The calibration was made for another image size.
    #[error("{path}: calibrated for {cw}x{ch} images, but the frames are {w}x{h}")]
    Size {
        /// The file.
        path: String,
        /// Calibrated width.
        cw: u32,
        /// Calibrated height.
        ch: u32,
        /// Frame width.
        w: u32,
        /// Frame height.
        h: u32,
    },
}

impl CalibrationFile {
    /// Reads a results file.
    pub fn load(path: &Path) -> Result<CalibrationFile, FileError> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|err| FileError::Io { path: p.clone(), err })?;
        serde_json::from_str(&text).map_err(|e| FileError::Parse {
            path: p,
            msg: e.to_string(),
        })
    }

    /// Reads a stereo results file whose images are `width`×`height`.
    pub fn load_stereo(path: &Path, width: u32, height: u32) -> Result<StereoCalibration, FileError> {
        let p = path.display().to_string();
        match Self::load(path)? {
            CalibrationFile::Stereo { stereo, .. } => {
                let [cw, ch] = stereo.left.image_size;
                if (cw, ch) != (width, height) {
                    return Err(FileError::Size {
                        path: p,
                        cw,
                        ch,
                        w: width,
                        h: height,
                    });
                }
                Ok(stereo)
            }
            CalibrationFile::Camera { .. } => Err(FileError::Kind {
                path: p,
                got: "single-camera",
                want: "stereo",
            }),
        }
    }

    /// JSON text of the file.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("calibration results serialise")
    }
}
