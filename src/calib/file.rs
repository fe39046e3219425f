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
    /// One line of the calibration (`label`: which camera): focal lengths, principal point,
    /// the lens coefficients and the RMS reprojection error.
    pub fn summary_line(&self, label: &str) -> String {
        let (k, d) = (&self.intrinsics, &self.distortion.0);
        format!(
            "{label}: fx {:.3} fy {:.3} cx {:.3} cy {:.3} px; k1 {:.5} k2 {:.5} p1 {:.6} p2 {:.6} k3 {:.5}; RMS {:.4} px",
            k.fx, k.fy, k.cx, k.cy, d[0], d[1], d[2], d[3], d[4], self.rms_px
        )
    }

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

/// Largest calibration results file read, bytes (100 photo pairs write about 50 kB).
pub const MAX_FILE_BYTES: u64 = 16 << 20;

/// Shortest stereo baseline a calibration may have, metres. The project's pairs are 6–12 cm
/// apart (`stereo.base_m` is 0.01..=2); a shorter one is a calibration made from the same
/// photos given as left and right (|T| ≈ 1e-17 m), and ranges by b·f/d would be noise.
pub const MIN_BASELINE_M: f64 = 0.01;
/// Longest stereo baseline, metres (the bound of `stereo.base_m`).
pub const MAX_BASELINE_M: f64 = 2.0;
/// Smallest share of the baseline along the cameras' x axis, |T.x| / |T|: a side-by-side pair
/// (cos 25° ≈ 0.906). Rows can only be rectified level for a pair that stands side by side.
pub const MIN_BASELINE_ALONG_X: f64 = 0.9;
/// Largest stereo reprojection rms a calibration file may hold, pixels (`rccar calibrate
/// stereo --max-rms-px` refuses above 1 px by default and accepts at most this).
pub const MAX_STEREO_RMS_PX: f64 = 5.0;

/// Why a stereo calibration cannot be used for ranging (its geometry, not its file).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StereoGeometryError {
    /// A number is NaN or infinite.
    #[error("{what} is {value}: every number must be finite")]
    NotFinite {
        /// Which value.
        what: &'static str,
        /// The value.
        value: f64,
    },
    /// The baseline is shorter than [`MIN_BASELINE_M`] or longer than [`MAX_BASELINE_M`].
    #[error(
        "baseline |T| = {baseline_m:.3e} m is outside {MIN_BASELINE_M}..={MAX_BASELINE_M} m{}",
        if *baseline_m < MIN_BASELINE_M {
            ": the left and right photos show the board from the same place (the same photos given twice?); photograph the board with both cameras of the pair, --left from the left camera, --right from the right"
        } else {
            ": check --square (the board's square size in metres)"
        }
    )]
    Baseline {
        /// |T|, metres.
        baseline_m: f64,
    },
    /// The baseline is not mostly along x (a pair one above the other, or a bad fit).
    #[error("T = [{:.4}, {:.4}, {:.4}] m is not a side-by-side pair (|T.x| is {:.0} % of |T|, at least {:.0} % needed): mount the cameras side by side, level, and calibrate again", t[0], t[1], t[2], 100.0 * along, 100.0 * MIN_BASELINE_ALONG_X)]
    NotSideBySide {
        /// T, metres.
        t: [f64; 3],
        /// |T.x| / |T|.
        along: f64,
    },
    /// T.x > 0: the "right" camera sits left of the "left" one (OpenCV's convention,
    /// X_r = R·X_l + T, gives T.x < 0 for a right camera on the right).
    #[error("T.x = {tx:+.4} m > 0: the right camera is to the LEFT of the left one, so the two cameras are swapped; calibrate again with the --left and --right photos exchanged (or swap the cameras' cables)")]
    Swapped {
        /// T.x, metres.
        tx: f64,
    },
    /// R is not a rotation.
    #[error("R is not a rotation matrix (|RᵀR − I| = {err:.2e}, det {det:.4})")]
    NotRotation {
        /// Largest entry of |RᵀR − I|.
        err: f64,
        /// det R.
        det: f64,
    },
    /// The stereo reprojection error is too large to trust.
    #[error("stereo rms {rms_px:.3} px is above {max_px} px: the corners of the two views do not fit one rigid pair (a moved camera, a mislabelled pair, a blurred photo); check the per-pair rms and retake the worst pairs")]
    Rms {
        /// The file's rms, pixels.
        rms_px: f64,
        /// The bound, pixels.
        max_px: f64,
    },
    /// The rectified camera is unusable (focal length not positive).
    #[error("rectified focal length {f} px must be > 0")]
    Focal {
        /// f, pixels.
        f: f64,
    },
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

    /// Whether this pair's geometry can range: a finite R (a rotation) and T, a baseline of
    /// [`MIN_BASELINE_M`]..=[`MAX_BASELINE_M`] mostly along x ([`MIN_BASELINE_ALONG_X`]), the
    /// right camera on the right (T.x < 0), an rms of at most `max_rms_px` and a positive
    /// rectified focal length.
    pub fn check(&self, max_rms_px: f64) -> Result<(), StereoGeometryError> {
        let finite = |what, value: f64| {
            if value.is_finite() {
                Ok(())
            } else {
                Err(StereoGeometryError::NotFinite { what, value })
            }
        };
        for v in self.t {
            finite("T", v)?;
        }
        for v in self.r.iter().flatten() {
            finite("R", *v)?;
        }
        finite("rms_px", self.rms_px)?;
        finite("rectification.f", self.rectification.f)?;
        let [tx, ty, tz] = self.t;
        let baseline_m = (tx * tx + ty * ty + tz * tz).sqrt();
        if !(MIN_BASELINE_M..=MAX_BASELINE_M).contains(&baseline_m) {
            return Err(StereoGeometryError::Baseline { baseline_m });
        }
        let along = tx.abs() / baseline_m;
        if along < MIN_BASELINE_ALONG_X {
            return Err(StereoGeometryError::NotSideBySide { t: self.t, along });
        }
        if tx > 0.0 {
            return Err(StereoGeometryError::Swapped { tx });
        }
        let r = nalgebra::Matrix3::from_fn(|i, j| self.r[i][j]);
        let err = (r.transpose() * r - nalgebra::Matrix3::identity()).abs().max();
        let det = r.determinant();
        if err > 1e-6 || det <= 0.0 {
            return Err(StereoGeometryError::NotRotation { err, det });
        }
        if self.rms_px > max_rms_px {
            return Err(StereoGeometryError::Rms {
                rms_px: self.rms_px,
                max_px: max_rms_px,
            });
        }
        if self.rectification.f <= 0.0 {
            return Err(StereoGeometryError::Focal {
                f: self.rectification.f,
            });
        }
        Ok(())
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
    /// The stereo pair's geometry cannot range (see [`StereoCalibration::check`]).
    #[error("{path}: {err}")]
    Geometry {
        /// The file.
        path: String,
        /// What is wrong.
        err: StereoGeometryError,
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
        use std::io::Read;
        let io = |err| FileError::Io { path: p.clone(), err };
        let mut text = String::new();
        std::fs::File::open(path)
            .map_err(io)?
            .take(MAX_FILE_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(io)?;
        if text.len() as u64 > MAX_FILE_BYTES {
            return Err(FileError::Parse {
                path: p,
                msg: format!("larger than a calibration file may be ({MAX_FILE_BYTES} bytes)"),
            });
        }
        serde_json::from_str(&text).map_err(|e| FileError::Parse {
            path: p,
            msg: e.to_string(),
        })
    }

    /// Reads a stereo results file whose images are `width`×`height`, and refuses one whose
    /// geometry cannot range ([`StereoCalibration::check`] with [`MAX_STEREO_RMS_PX`]).
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
                stereo
                    .check(MAX_STEREO_RMS_PX)
                    .map_err(|err| FileError::Geometry { path: p, err })?;
                Ok(stereo)
            }
            CalibrationFile::Camera { .. } => Err(FileError::Kind {
                path: p,
                got: "single-camera",
                want: "stereo",
            }),
        }
    }

    /// Reads a single camera's results file (`rccar calibrate camera`) as the lens of
    /// `width`×`height` frames (its pinhole and distortion): the pinhole scaled from the calibrated image size (the frames
    /// are resized to `width`×`height`, so the shape must be the same; pixel centres at
    /// integers, so c' = (c + ½)·s − ½) and its distortion (dimensionless, unchanged).
    pub fn load_camera(path: &Path, width: u32, height: u32) -> Result<(crate::lens::Pinhole, Distortion), FileError> {
        let p = path.display().to_string();
        match Self::load(path)? {
            CalibrationFile::Camera { camera, .. } => {
                let [cw, ch] = camera.image_size;
                // Same shape: cw/ch = w/h, to a pixel of rounding either way.
                let (sx, sy) = (width as f64 / cw.max(1) as f64, height as f64 / ch.max(1) as f64);
                if cw == 0 || ch == 0 || (sx - sy).abs() * (cw.max(ch) as f64) > 1.0 {
                    return Err(FileError::Size {
                        path: p,
                        cw,
                        ch,
                        w: width,
                        h: height,
                    });
                }
                let k = camera.intrinsics;
                let pin = crate::lens::Pinhole {
                    fx: k.fx * sx,
                    fy: k.fy * sy,
                    cx: (k.cx + 0.5) * sx - 0.5,
                    cy: (k.cy + 0.5) * sy - 0.5,
                };
                let nums = [pin.fx, pin.fy, pin.cx, pin.cy];
                if !nums.iter().chain(&camera.distortion.0).all(|v| v.is_finite()) || pin.fx <= 0.0 || pin.fy <= 0.0 {
                    return Err(FileError::Parse {
                        path: p,
                        msg: "the focal lengths must be > 0 and every number finite".into(),
                    });
                }
                Ok((pin, camera.distortion))
            }
            CalibrationFile::Stereo { .. } => Err(FileError::Kind {
                path: p,
                got: "stereo",
                want: "single-camera",
            }),
        }
    }

    /// JSON text of the file.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("calibration results serialise")
    }
}
