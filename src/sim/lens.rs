//! A simulated camera's lens and mounting error: the renderer draws an ideal pinhole camera,
//! and [`LensWarp`] bends its image into the real camera's (OpenCV's lens model,
//! [`crate::lens`]). The car's own camera through `sim.lens_distortion` (a wide-angle lens
//! whose bent lines the lane map must undo), a stereo pair's second camera through
//! `sim.stereo_error_deg` / `sim.stereo_error_k1`; both rendered by [`render_through`]. The
//! ground truth stays the ideal camera's: the lens changes the image only. Units: pixels,
//! radians.

use super::render::Renderer;
use super::vehicle::Pose;
use crate::calib::stereo::{FixedMaps, RectifyMaps};
use crate::camera::PinholeCamera;
use crate::config::Config;
use crate::lens::Distortion;
use image::RgbImage;
use std::ops::Range;

/// How a simulated camera differs from the ideal one it is rendered as: turned by yaw, pitch
/// and roll (`sim.stereo_error_deg`) about its own centre and with a lens distortion (OpenCV's
/// model, [`Distortion`]: `sim.stereo_error_k1` or `sim.lens_distortion`). A camera turned about its
/// centre sees the same rays, so its image is exactly the ideal image resampled: for each of
/// its pixels, undistort → turn the ray back (Rᵀ) → project into the ideal camera → bilinear
/// sample (black outside the ideal view). The map is built once. Units: pixels, radians.
#[derive(Debug, Clone)]
pub struct LensWarp {
    maps: RectifyMaps,
    fixed: FixedMaps,
    /// For each real row: the ideal rows its pixels read (`first..end`, clipped).
    reads: Vec<Range<usize>>,
}

impl LensWarp {
    /// The warp of `cfg`'s other camera, `None` when it is ideal (all errors zero).
    pub fn from_config(cfg: &Config) -> Option<LensWarp> {
        let [yaw, pitch, roll] = cfg.sim.stereo_error_deg;
        let k1 = cfg.sim.stereo_error_k1;
        if [yaw, pitch, roll, k1].iter().all(|&v| v == 0.0) {
            return None;
        }
        Some(Self::new(&PinholeCamera::from(&cfg.camera), [yaw, pitch, roll], k1))
    }

    /// The lens of `cfg`'s own camera (`sim.lens_distortion` on `[camera]`'s pinhole), `None`
    /// for an ideal lens (all zero).
    pub fn main_camera(cfg: &Config) -> Option<LensWarp> {
        let d = Distortion(cfg.sim.lens_distortion);
        (!d.is_zero()).then(|| Self::with_distortion(&PinholeCamera::from(&cfg.camera), [0.0; 3], d))
    }

    /// The warp of `cam` turned by `[yaw, pitch, roll]` degrees (about the camera's y, x and
    /// z axes: x right, y down, z forward; R = R_z(roll)·R_y(yaw)·R_x(pitch), X_real = R·X_ideal)
    /// with radial distortion `k1`.
    pub fn new(cam: &PinholeCamera, deg: [f64; 3], k1: f64) -> LensWarp {
        Self::with_distortion(cam, deg, Distortion([k1, 0.0, 0.0, 0.0, 0.0]))
    }

    /// [`LensWarp::new`] with every coefficient of OpenCV's model, `d`.
    pub fn with_distortion(cam: &PinholeCamera, deg: [f64; 3], d: Distortion) -> LensWarp {
        use crate::calib::intrinsics::Intrinsics;
        let [yaw, pitch, roll] = deg.map(f64::to_radians);
        let (rx, ry, rz) = (
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::x_axis(), pitch),
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), yaw),
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), roll),
        );
        let r = (rz * ry * rx).into_inner();
        // RectifyMaps: output pixel → ray (f, c) → Rᵀ → distortion → K. Here the output is
        // the real camera and the source the ideal one: a real pixel's ray is undistort(pixel),
        // so the "rectified" side is the real camera's distorted plane and the source has no
        // distortion; built directly below.
        let k = Intrinsics {
            fx: cam.f_px,
            fy: cam.f_px,
            cx: cam.u0,
            cy: cam.v0,
        };
        let (w, h) = (cam.width, cam.height);
        let n = (w * h) as usize;
        let (mut map_x, mut map_y) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let rt = r.transpose();
        for v in 0..h {
            for u in 0..w {
                let (x, y) = d.undistort((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy);
                let q = rt * nalgebra::Vector3::new(x, y, 1.0);
                let (sx, sy) = if q[2] > 1e-9 {
                    (k.fx * q[0] / q[2] + k.cx, k.fy * q[1] / q[2] + k.cy)
                } else {
                    (-10.0, -10.0)
                };
                map_x.push(sx as f32);
                map_y.push(sy as f32);
            }
        }
        // The ideal rows each real row reads: its bilinear taps' rows, and one more for the
        // fixed-point rounding.
        let reads = map_y
            .chunks_exact(w as usize)
            .map(|row| {
                let lo = row.iter().fold(f32::INFINITY, |m, &y| m.min(y));
                let hi = row.iter().fold(f32::NEG_INFINITY, |m, &y| m.max(y));
                let a = (lo.floor() as f64 - 1.0).clamp(0.0, h as f64) as usize;
                let b = (hi.floor() as f64 + 3.0).clamp(0.0, h as f64) as usize;
                a..b.max(a)
            })
            .collect();
        let maps = RectifyMaps {
            width: w,
            height: h,
            map_x,
            map_y,
        };
        LensWarp {
            fixed: FixedMaps::new(&maps, w, h),
            maps,
            reads,
        }
    }

    /// The ideal rows the real rows `rows` are bent from (empty when `rows` is).
    pub fn reads(&self, rows: Range<usize>) -> Range<usize> {
        let rs = &self.reads[rows.start.min(self.reads.len())..rows.end.min(self.reads.len())];
        let lo = rs.iter().map(|r| r.start).min();
        let hi = rs.iter().map(|r| r.end).max();
        match (lo, hi) {
            (Some(a), Some(b)) => a..b,
            _ => 0..0,
        }
    }

    /// The real camera's colour image from the ideal one.
    pub fn apply_rgb(&self, ideal: &RgbImage, out: &mut RgbImage) {
        if !self.fixed.remap_rgb(ideal, out) {
            self.maps.remap_rgb(ideal, out);
        }
    }

    /// [`LensWarp::apply_rgb`] for the real rows `rows` only (the others keep what they held).
    pub fn apply_rgb_rows(&self, ideal: &RgbImage, out: &mut RgbImage, rows: Range<u32>) {
        if !self.fixed.remap_rgb_rows(ideal, out, rows) {
            self.maps.remap_rgb(ideal, out);
        }
    }

    /// The real camera's grey image from the ideal one (e.g. a rendered checkerboard).
    pub fn apply_gray(&self, ideal: &image::GrayImage, out: &mut image::GrayImage) {
        self.maps.remap_gray(ideal, out);
    }
}

/// The spans (sorted, disjoint) widened by the blur's reach (`3·blur_px`) and merged where
/// they meet; with blur, one range from the first to the last (the blur runs over the whole
/// image on each render call).
pub fn widen_spans(spans: &[Range<usize>], blur_px: f64) -> Vec<Range<usize>> {
    let reach = if blur_px > 0.0 {
        (3.0 * blur_px).ceil() as usize + 1
    } else {
        0
    };
    let mut merged: Vec<Range<usize>> = Vec::with_capacity(spans.len());
    for s in spans.iter().filter(|s| !s.is_empty()) {
        let s = s.start.saturating_sub(reach)..s.end + reach;
        match merged.last_mut() {
            Some(m) if s.start <= m.end => m.end = m.end.max(s.end),
            _ => merged.push(s),
        }
    }
    if reach > 0 && merged.len() > 1 {
        let all = merged[0].start..merged[merged.len() - 1].end;
        merged = vec![all];
    }
    merged
}

/// Renders the rows `spans` (sorted, disjoint) of `r`'s view from `pose` into `img`, each
/// widened by the blur's reach ([`widen_spans`]), so every row in `spans` comes out as in a
/// full frame. Through `lens` (and its ideal image): the ideal rows those rows are bent from
/// are rendered (widened the same way), then the rows of `spans` are bent into `img`.
#[allow(clippy::too_many_arguments)]
pub fn render_through(
    r: &mut Renderer,
    lens: Option<&mut (LensWarp, RgbImage)>,
    pose: &Pose,
    t_s: f64,
    frame: u64,
    img: &mut RgbImage,
    spans: &[Range<usize>],
    blur_px: f64,
) {
    let Some((lens, ideal)) = lens else {
        for m in widen_spans(spans, blur_px) {
            r.render_rows(pose, t_s, frame, img, m);
        }
        return;
    };
    let cam = r.mount().camera;
    if ideal.dimensions() != (cam.width, cam.height) {
        *ideal = RgbImage::new(cam.width, cam.height);
    }
    let h = cam.height as usize;
    let mut reads: Vec<Range<usize>> = spans
        .iter()
        .map(|s| lens.reads(s.start.min(h)..s.end.min(h)))
        .filter(|s| !s.is_empty())
        .collect();
    reads.sort_by_key(|s| s.start);
    for m in widen_spans(&reads, blur_px) {
        r.render_rows(pose, t_s, frame, ideal, m.start.min(h)..m.end.min(h));
    }
    for s in spans {
        lens.apply_rgb_rows(ideal, img, s.start.min(h) as u32..s.end.min(h) as u32);
    }
}
