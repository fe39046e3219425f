//! `[camera]`: the frames the pipeline works on (pixels, frames per second) and how the camera
//! is mounted on the car (lens height in metres, tilt and field of view in degrees).

use super::check::Checker;
use crate::camera::PinholeCamera;
use crate::lens::{Distortion, Lens, Pinhole};
use serde::{Deserialize, Serialize};

/// `[camera]`: the image the pipeline works on and the camera's pose on the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Width of the frames the pipeline processes, pixels (frames are resized to it).
    pub width: u32,
    /// Height of the frames the pipeline processes, pixels.
    pub height: u32,
    /// Frames per second; the controller's time step is 1/fps.
    pub fps: f64,
    /// Height of the lens above the floor, metres.
    pub height_m: f64,
    /// Downward tilt of the optical axis below horizontal, degrees.
    pub tilt_deg: f64,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// The camera module (`--camera picam:N`): a fixed exposure time, microseconds; 0 =
    /// automatic exposure. Auto-exposure flicker moves the fixed lane threshold.
    pub shutter_us: u32,
    /// The camera module: a fixed analogue gain (1.0 ..= 16); 0 = automatic.
    pub gain: f64,
    /// The camera module: fixed white balance, [red gain, blue gain]; [0, 0] = automatic.
    pub awb_gains: [f64; 2],
    /// The lens's distortion, OpenCV's order [k1, k2, p1, p2, k3] (dimensionless; `rccar
    /// calibrate camera` measures them), on the pinhole of `hfov_deg` with the principal
    /// point in the image centre; folded into the bird's-eye map. All zero = an ideal lens.
    pub distortion: [f64; 5],
    /// Results file of `rccar calibrate camera` (JSON): its pinhole and distortion, scaled to
    /// `width`×`height`, are folded into the bird's-eye map instead of `distortion`; empty =
    /// none.
    pub calibration: String,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width: 320,
            height: 240,
            fps: 30.0,
            height_m: 0.20,
            tilt_deg: 20.0,
            hfov_deg: 62.2,
            shutter_us: 0,
            gain: 0.0,
            awb_gains: [0.0, 0.0],
            distortion: [0.0; 5],
            calibration: String::new(),
        }
    }
}

impl CameraConfig {
    /// Range checks of `[camera]`.
    pub(super) fn check(&self, c: &mut Checker) {
        c.range("camera.width", self.width, 16, 4096);
        c.range("camera.height", self.height, 16, 4096);
        c.range("camera.fps", self.fps, 1.0, 240.0);
        c.range("camera.height_m", self.height_m, 0.01, 5.0);
        c.range("camera.tilt_deg", self.tilt_deg, -10.0, 89.0);
        c.range("camera.hfov_deg", self.hfov_deg, 10.0, 170.0);
        c.range("camera.shutter_us", self.shutter_us, 0, 1_000_000);
        c.range("camera.gain", self.gain, 0.0, 16.0);
        c.range("camera.awb_gains[0]", self.awb_gains[0], 0.0, 8.0);
        c.range("camera.awb_gains[1]", self.awb_gains[1], 0.0, 8.0);
        for (i, (v, bound)) in self.distortion.iter().zip(DISTORTION_BOUNDS).enumerate() {
            c.range(&format!("camera.distortion[{i}]"), *v, -bound, bound);
        }
        if !self.calibration.is_empty() && self.distortion.iter().any(|&v| v != 0.0) {
            c.fail(
                "camera.distortion",
                format!("{:?}", self.distortion),
                "all zero when camera.calibration names a file (the file's coefficients are used); set one of the two",
            );
        }
    }
}

/// Largest |value| of each of `camera.distortion`'s k1, k2, p1, p2, k3 (calibrated wide-angle
/// lenses stay well inside; the fold check below is the real bound).
const DISTORTION_BOUNDS: [f64; 5] = [2.0, 5.0, 0.2, 0.2, 10.0];

/// Why the lane pipeline cannot use the camera's lens.
#[derive(Debug, thiserror::Error)]
pub enum LensError {
    /// `camera.calibration` names a file that cannot be read, is not a single camera's
    /// calibration, or was made for frames of another shape.
    #[error("camera.calibration: {0}")]
    File(crate::calib::file::FileError),
    /// The lens model folds back (two rays on one pixel) inside the ROI.
    #[error("{key}: {why}")]
    Folds {
        /// The key that gave the lens.
        key: &'static str,
        /// Where and why.
        why: String,
    },
}

impl From<crate::calib::file::FileError> for LensError {
    fn from(e: crate::calib::file::FileError) -> Self {
        LensError::File(e)
    }
}

impl super::Config {
    /// The lens of `[camera] distortion` on `[camera]`'s pinhole; `None` for an ideal lens.
    /// (`camera.calibration` is read by [`super::Config::camera_lens`].)
    pub fn inline_lens(&self) -> Option<Lens> {
        let d = Distortion(self.camera.distortion);
        (!d.is_zero()).then(|| Lens::on(self.camera.pinhole(), d))
    }

    /// The lens the bird's-eye map folds in: `camera.calibration`'s file (read here; its pinhole
    /// scaled to `camera.width`×`height`, which must have the calibration's shape, is the real
    /// camera; the ideal image stays `[camera]`'s pinhole, which the ROI, the truth and the
    /// ranging use) or `camera.distortion` on `[camera]`'s pinhole; `None` for an ideal lens.
    /// Refused when the model folds back inside `[warp] src`.
    pub fn camera_lens(&self) -> Result<Option<Lens>, LensError> {
        let (lens, key) = if self.camera.calibration.is_empty() {
            (self.inline_lens(), "camera.distortion")
        } else {
            let path = std::path::Path::new(&self.camera.calibration);
            let (real, d) = crate::calib::file::CalibrationFile::load_camera(path, self.camera.width, self.camera.height)?;
            let lens = Lens {
                ideal: self.camera.pinhole(),
                real,
                distortion: d,
            };
            (Some(lens), "camera.calibration")
        };
        if let Some(l) = &lens {
            if let Some(p) = self.warp.src.iter().find(|p| !l.unfolded_at(p[0], p[1])) {
                return Err(LensError::Folds {
                    key,
                    why: format!(
                        "the lens model {:?} folds back (1 + 3k1 r² + 5k2 r⁴ + 7k3 r⁶ ≤ 0) before the ROI corner {p:?} of warp.src: not a lens the bird's-eye map can undo",
                        l.distortion.0
                    ),
                });
            }
        }
        Ok(lens)
    }

    /// The check of `camera.distortion` against `[warp] src` (a model that folds back inside
    /// the ROI is no lens).
    pub(super) fn check_lens(&self, c: &mut Checker) {
        let in_range = self.camera.distortion.iter().zip(DISTORTION_BOUNDS).all(|(v, b)| v.abs() <= b);
        if let Some(l) = self.inline_lens().filter(|_| in_range) {
            if let Some(p) = self.warp.src.iter().find(|p| !l.unfolded_at(p[0], p[1])) {
                c.fail(
                    "camera.distortion",
                    format!("{:?}", self.camera.distortion),
                    &format!("a lens model that does not fold back (1 + 3k1 r² + 5k2 r⁴ + 7k3 r⁶ > 0) out to every warp.src corner; this one folds back before {p:?}"),
                );
            }
        }
    }
}

impl CameraConfig {
    /// The focal lengths and principal point of [`PinholeCamera::from`] this camera.
    pub fn pinhole(&self) -> Pinhole {
        let cam = PinholeCamera::from(self);
        Pinhole {
            fx: cam.f_px,
            fy: cam.f_px,
            cx: cam.u0,
            cy: cam.v0,
        }
    }
}

impl From<&CameraConfig> for PinholeCamera {
    /// The camera described by `[camera]`.
    fn from(c: &CameraConfig) -> Self {
        PinholeCamera::new(c.width, c.height, c.hfov_deg, c.height_m, c.tilt_deg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The camera tests of src/camera.rs use the shipped camera by its numbers.
    #[test]
    fn default_is_the_camera_the_stage_tests_use() {
        assert_eq!(
            PinholeCamera::from(&CameraConfig::default()),
            PinholeCamera::new(320, 240, 62.2, 0.20, 20.0)
        );
    }

    use crate::config::Config;

    fn refused(assignment: &str) -> String {
        Config::default().with_override(assignment).unwrap_err().to_string()
    }

    /// Issue 26: a lens that is out of range, folds back inside the ROI, or is given twice is
    /// refused naming the key; a good one is folded into the lane detector's map.
    #[test]
    fn bad_lenses_are_refused_naming_the_key() {
        let e = refused("camera.distortion=[-3.0, 0.0, 0.0, 0.0, 0.0]");
        assert!(e.contains("camera.distortion[0] = -3 is out of range (allowed: -2 ..= 2)"), "{e}");
        assert!(!e.contains("camera.distortion ="), "one error for one value: {e}");
        let e = refused("camera.distortion=[0.0, 0.0, 0.0, 0.0, nan]");
        assert!(e.contains("camera.distortion[4]"), "{e}");
        // k1 = -1.5 folds at r = 0.47; the ROI's near corners are at r = 0.57.
        let e = refused("camera.distortion=[-1.5, 0.0, 0.0, 0.0, 0.0]");
        assert!(e.contains("camera.distortion = [-1.5") && e.contains("folds back"), "{e}");
        let mut c = Config::default();
        c.camera.calibration = "lens.json".into();
        c.camera.distortion = [-0.3, 0.0, 0.0, 0.0, 0.0];
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("camera.distortion = [-0.3") && e.contains("camera.calibration"), "{e}");
        let e = refused("sim.lens_distortion=[-0.9, 0.0, 0.0, 0.0, 0.0]");
        assert!(e.contains("sim.lens_distortion = [-0.9") && e.contains("folds back"), "{e}");
        let e = refused("sim.lens_distortion=[-0.5, 0.2, 0.0, 0.5, 0.0]");
        assert!(e.contains("sim.lens_distortion[3] = 0.5"), "{e}");
        let ok = Config::default()
            .with_override("camera.distortion=[-0.5, 0.2, 0.0, 0.0, 0.0]")
            .unwrap();
        assert!(ok.camera_lens().unwrap().is_some());
        assert!(Config::default().camera_lens().unwrap().is_none());
    }

    /// `camera.calibration` reads `rccar calibrate camera`'s file: its pinhole scaled to the
    /// frames, its distortion; a stereo file, a missing file or another shape is refused
    /// naming the key.
    #[test]
    fn the_calibration_file_of_rccar_calibrate_camera_is_the_lens() {
        use crate::calib::file::{CalibrationFile, CameraCalibration};
        use crate::calib::intrinsics::Intrinsics;
        let dir = std::env::temp_dir().join(format!("rccar-lens-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let d = Distortion([-0.3, 0.09, 0.001, -0.0008, 0.0]);
        let write = |name: &str, size: [u32; 2], k: Intrinsics| {
            let file = CalibrationFile::Camera {
                board: crate::calib::corners::BoardSize { cols: 9, rows: 6 },
                square_m: 0.025,
                camera: CameraCalibration {
                    image_size: size,
                    intrinsics: k,
                    distortion: d,
                    rms_px: 0.2,
                    per_image_rms_px: vec![],
                    board_not_found: vec![],
                },
            };
            let p = dir.join(name);
            std::fs::write(&p, file.to_json()).unwrap();
            p.display().to_string()
        };
        // Photos at 640×480: the pinhole halves (pixel centres at integers).
        let k = Intrinsics {
            fx: 530.0,
            fy: 532.0,
            cx: 321.0,
            cy: 241.0,
        };
        let mut c = Config::default();
        c.camera.calibration = write("vga.json", [640, 480], k);
        c.validate().unwrap();
        let lens = c.camera_lens().unwrap().unwrap();
        assert_eq!(lens.distortion, d);
        assert_eq!(lens.ideal, c.camera.pinhole());
        let r = lens.real;
        assert!((r.fx - 265.0).abs() < 1e-9 && (r.fy - 266.0).abs() < 1e-9, "{r:?}");
        assert!((r.cx - 160.25).abs() < 1e-9 && (r.cy - 120.25).abs() < 1e-9, "{r:?}");
        assert!(c.lane_detector().is_ok());
        // Another shape, a missing file, a stereo file.
        c.camera.calibration = write("wide.json", [640, 360], k);
        let e = c.lane_detector().unwrap_err().to_string();
        assert!(e.starts_with("camera.calibration: ") && e.contains("640x360"), "{e}");
        c.camera.calibration = dir.join("none.json").display().to_string();
        let e = c.lane_detector().unwrap_err().to_string();
        assert!(e.starts_with("camera.calibration: "), "{e}");
        let e = crate::pipeline::Pipeline::new(&c).err().unwrap().to_string();
        assert!(e.starts_with("camera.calibration: "), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
