//! Frames from the car's camera (V4L2 through nokhwa), behind the `camera` cargo feature.
//!
//! A [`CameraSource`] is a [`FrameSource`] like a replay folder or the simulator: the pipeline
//! does not know which it is given. Frames are converted to RGB and resized to the configured
//! camera size; a frame that fails to arrive or decode is reported for that frame only.
//! Time stamps come from the frame counter and the configured fps (the library reads no clock).

use crate::source::{Frame, FrameError, FrameSource};
use nokhwa::pixel_format::RgbFormat;
use nokhwa::utils::{CameraIndex, RequestedFormat, RequestedFormatType};

/// Why the camera could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("camera {index}: {reason}")]
pub struct CameraError {
    /// The device index asked for.
    pub index: u32,
    /// What went wrong (no such device, no permission, no usable format…).
    pub reason: String,
}

/// A V4L2 camera delivering frames at the configured size.
pub struct CameraSource {
    cam: nokhwa::Camera,
    index: u64,
    fps: f64,
    width: u32,
    height: u32,
}

impl CameraSource {
    /// Opens camera `index` (0 = /dev/video0) and starts streaming at the highest frame rate it
    /// offers; frames are resized to `width × height`.
    pub fn open(index: u32, fps: f64, width: u32, height: u32) -> Result<Self, CameraError> {
        let err = |e: nokhwa::NokhwaError| CameraError {
            index,
            reason: e.to_string(),
        };
        let req = RequestedFormat::new::<RgbFormat>(RequestedFormatType::AbsoluteHighestFrameRate);
        let mut cam = nokhwa::Camera::new(CameraIndex::Index(index), req).map_err(err)?;
        cam.open_stream().map_err(err)?;
        Ok(Self {
            cam,
            index: 0,
            fps,
            width,
            height,
        })
    }
}

impl FrameSource for CameraSource {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let index = self.index;
        self.index += 1;
        let name = format!("camera_{index:06}");
        let decoded = self.cam.frame().and_then(|b| b.decode_image::<RgbFormat>());
        Some(match decoded {
            Ok(img) => {
                let img = if img.dimensions() == (self.width, self.height) {
                    img
                } else {
                    image::imageops::resize(&img, self.width, self.height, image::imageops::FilterType::Triangle)
                };
                Ok(Frame {
                    index,
                    time_s: index as f64 / self.fps,
                    name,
                    image: img,
                })
            }
            Err(e) => Err(FrameError {
                index,
                name,
                reason: e.to_string(),
            }),
        })
    }
}

impl Drop for CameraSource {
    fn drop(&mut self) {
        let _ = self.cam.stop_stream();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_camera_is_a_clean_error() {
        // CI machines have no /dev/video*: opening must fail with an error naming the index.
        if std::path::Path::new("/dev/video250").exists() {
            return;
        }
        let e = CameraSource::open(250, 30.0, 320, 240)
            .err()
            .expect("no camera 250 here");
        assert!(e.to_string().starts_with("camera 250:"), "{e}");
    }
}
