//! The car's camera (V4L2 through nokhwa), behind the `camera` cargo feature.
//!
//! [`V4l2Grabber`] opens `/dev/videoN` at the configured size and frame rate, asking for MJPEG
//! first (what USB webcams deliver at 30 fps) and YUYV otherwise, and decodes each frame to
//! RGB. [`open`] runs it on a capture thread ([`crate::capture::CaptureSource`]): the newest
//! frame only, a stall or unplug detected within the stall time, the device reopened until it
//! comes back, a wrong frame size a clear error.

use crate::capture::{CaptureSource, GrabError, Grabber};
use crate::drive::Clock;
use image::RgbImage;
use nokhwa::pixel_format::RgbFormat;
use nokhwa::utils::{CameraFormat, CameraIndex, FrameFormat, RequestedFormat, RequestedFormatType, Resolution};
use std::sync::Arc;
use std::time::Duration;

/// Why the camera could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("camera {index}: {reason}")]
pub struct CameraError {
    /// The device index asked for.
    pub index: u32,
    /// What went wrong (no such device, no permission, no usable format…).
    pub reason: String,
}

/// A V4L2 camera delivering `width × height` frames at `fps`.
pub struct V4l2Grabber {
    index: u32,
    fps: u32,
    width: u32,
    height: u32,
    cam: Option<nokhwa::Camera>,
}

impl V4l2Grabber {
    /// Camera `index` (0 = /dev/video0); nothing is opened yet.
    pub fn new(index: u32, fps: f64, width: u32, height: u32) -> Self {
        Self {
            index,
            fps: fps.round().clamp(1.0, 240.0) as u32,
            width,
            height,
            cam: None,
        }
    }

    fn try_open(&self, format: FrameFormat) -> Result<nokhwa::Camera, nokhwa::NokhwaError> {
        let want = CameraFormat::new(Resolution::new(self.width, self.height), format, self.fps);
        let req = RequestedFormat::new::<RgbFormat>(RequestedFormatType::Closest(want));
        let mut cam = nokhwa::Camera::new(CameraIndex::Index(self.index), req)?;
        cam.open_stream()?;
        Ok(cam)
    }
}

impl Grabber for V4l2Grabber {
    fn open(&mut self) -> Result<(), GrabError> {
        if self.cam.is_some() {
            return Ok(());
        }
        let cam = self
            .try_open(FrameFormat::MJPEG)
            .or_else(|_| self.try_open(FrameFormat::YUYV))
            .map_err(|e| e.to_string())?;
        self.cam = Some(cam);
        Ok(())
    }

    fn grab(&mut self) -> Result<RgbImage, GrabError> {
        let cam = self.cam.as_mut().ok_or_else(|| GrabError::Lost("not open".into()))?;
        cam.frame()
            .and_then(|b| b.decode_image::<RgbFormat>())
            .map_err(|e| GrabError::Lost(e.to_string()))
    }

    fn close(&mut self) {
        if let Some(mut c) = self.cam.take() {
            let _ = c.stop_stream();
        }
    }

    fn label(&self) -> String {
        format!("/dev/video{}", self.index)
    }
}

/// Opens camera `index` once to check it exists (a missing camera is an error before the car
/// does anything), then captures on a thread.
pub fn open(
    index: u32,
    fps: f64,
    width: u32,
    height: u32,
    clock: Arc<dyn Clock + Send + Sync>,
    stall_after: Duration,
) -> Result<CaptureSource, CameraError> {
    let mut g = V4l2Grabber::new(index, fps, width, height);
    g.open().map_err(|e| CameraError {
        index,
        reason: match e {
            GrabError::Lost(r) | GrabError::Bad(r) | GrabError::Fatal(r) => r,
        },
    })?;
    let label = g.label();
    g.close();
    drop(g);
    Ok(CaptureSource::start(
        move || Box::new(V4l2Grabber::new(index, fps, width, height)),
        label,
        (width, height),
        clock,
        stall_after,
        Duration::from_millis(250),
    ))
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
        struct Zero;
        impl Clock for Zero {
            fn now_s(&self) -> f64 {
                0.0
            }
        }
        let e = open(250, 30.0, 320, 240, Arc::new(Zero), Duration::from_millis(500))
            .err()
            .expect("no camera 250 here");
        assert!(e.to_string().starts_with("camera 250:"), "{e}");
    }
}
