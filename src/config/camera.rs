//! `[camera]`: the frames the pipeline works on (pixels, frames per second) and how the camera
//! is mounted on the car (lens height in metres, tilt and field of view in degrees).

use super::check::Checker;
use crate::camera::PinholeCamera;
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
}
