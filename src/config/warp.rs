//! `[warp]`: the region of interest in the camera frame (pixel corners) and the size of the
//! bird's-eye image it is warped to (pixels).

use super::check::Checker;
use crate::lane::WarpOptions;
use serde::{Deserialize, Serialize};

/// `[warp]`: the region of interest and its bird's-eye (top-down) view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WarpConfig {
    /// The ROI's four corners in the camera frame, pixels, in the order
    /// top-left, top-right, bottom-right, bottom-left.
    pub src: [[f64; 2]; 4],
    /// Width of the bird's-eye image, pixels.
    pub out_width: u32,
    /// Height of the bird's-eye image, pixels.
    pub out_height: u32,
    /// Interpolate each colour channel and then convert to grey, exactly as OpenCV's
    /// `warpPerspective` + `cvtColor` (bit-identical), instead of grey first (3× faster, within
    /// one grey level).
    pub exact: bool,
}

impl Default for WarpConfig {
    fn default() -> Self {
        // The ground rectangle 0.40..1.00 m ahead, 0.25 m either side, seen by the default
        // camera (see `camera::PinholeCamera`); regenerate with `rccar config roi`.
        Self {
            src: [[93.72, 78.96], [225.28, 78.96], [308.75, 150.02], [10.25, 150.02]],
            out_width: 320,
            out_height: 240,
            exact: false,
        }
    }
}

impl WarpConfig {
    /// Range checks of `[warp]`: finite corners, sizes, and a quad that gives a bird's-eye view
    /// of the floor the right way up.
    pub(super) fn check(&self, c: &mut Checker) {
        let w = self;
        for (i, p) in w.src.iter().enumerate() {
            c.finite(&format!("warp.src[{i}]"), p[0]);
            c.finite(&format!("warp.src[{i}]"), p[1]);
        }
        c.range("warp.out_width", w.out_width, 16, 4096);
        c.range("warp.out_height", w.out_height, 16, 4096);
        if let Err(e) = crate::lane::warp::Homography::from_quad_to_rect(&w.src, w.out_width, w.out_height) {
            c.fail("warp.src", format!("{:?}", w.src), &e.to_string());
        } else {
            // The bird's-eye image puts src[0..2] (the far edge) at its top: a quad whose far
            // edge is below its near edge warps the floor upside down (and mirrored when left
            // and right are swapped); the histogram band then reads the wrong end of the lane.
            let [tl, tr, br, bl] = w.src;
            if !(tl[1] < bl[1] && tr[1] < br[1]) {
                c.fail(
                    "warp.src",
                    format!("{:?}", w.src),
                    "top corners [0], [1] (far edge) above the bottom corners [3], [2] (near edge); this ROI looks at the floor upside down (make one with `rccar config roi`)",
                );
            }
            if !(tl[0] < tr[0] && bl[0] < br[0]) {
                c.fail(
                    "warp.src",
                    format!("{:?}", w.src),
                    "left corners [0], [3] left of the right corners [1], [2]; this ROI is mirrored (make one with `rccar config roi`)",
                );
            }
        }
    }
}

impl From<&WarpConfig> for WarpOptions {
    /// The lane stage's bird's-eye view of `[warp]`, for an ideal lens
    /// (`Config::lane_detector` adds `[camera]`'s).
    fn from(w: &WarpConfig) -> Self {
        Self {
            src: w.src,
            out_width: w.out_width,
            out_height: w.out_height,
            exact: w.exact,
            lens: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::PinholeCamera;

    /// The default ROI is the ground rectangle 0.40..1.00 m ahead, 0.25 m either side, seen by
    /// the default camera (`rccar config roi`).
    #[test]
    fn default_roi_matches_config() {
        let cam = PinholeCamera::from(&crate::config::CameraConfig::default());
        let roi = cam.roi_of_ground_rect(0.40, 1.00, 0.25).unwrap();
        let cfg = WarpConfig::default().src;
        for (a, b) in roi.iter().zip(cfg.iter()) {
            assert!((a[0] - b[0]).abs() < 0.01 && (a[1] - b[1]).abs() < 0.01, "{roi:?}");
        }
    }
}

/// Why no `[warp] src` can be made for a floor rectangle.
#[derive(Debug, thiserror::Error)]
pub enum RoiError {
    /// A corner is behind or above the camera.
    #[error("the rectangle is behind or above the camera")]
    Behind,
    /// The quad does not pass the configuration's checks.
    #[error("the ROI of this rectangle is not usable:\n{0}")]
    Unusable(super::ConfigError),
}

impl super::Config {
    /// The `[warp] src` quad that sees the floor rectangle `near`..`far` metres ahead and
    /// `half_width` metres either side, through `[camera]`; checked as a file's would be
    /// (ordering, not degenerate).
    pub fn roi_of_ground_rect(&self, near: f64, far: f64, half_width: f64) -> Result<[[f64; 2]; 4], RoiError> {
        let cam = crate::camera::PinholeCamera::from(&self.camera);
        let roi = cam.roi_of_ground_rect(near, far, half_width).ok_or(RoiError::Behind)?;
        let mut check = self.clone();
        check.warp.src = roi;
        check.validate().map_err(RoiError::Unusable)?;
        Ok(roi)
    }
}
