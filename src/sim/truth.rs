//! Ground truth for a simulated frame: where the car really is relative to its lane, where
//! the lane lines really are in the pipeline's bird's-eye image, and where each object really
//! is in the camera image. Later features are scored against these numbers.
//!
//! Signs follow the pipeline's error so the two can be compared directly: a positive
//! `offset_m` means the car is left of the lane centre (the lane lies to its right, the
//! pipeline's error should be positive and the car should steer right); a positive
//! `heading_error_rad` means the car points left of the lane direction.
//!
//! Bird's-eye columns: each histogram-band row of the bird's-eye image is a straight line on
//! the floor (a homography maps lines to lines). For sampled rows, that floor line is
//! intersected with the lane line (secant iteration on its lateral offset), and the point is
//! mapped through the camera and the pipeline's own homography; the row columns are averaged
//! over the band, as the column histogram sums over it.
//!
//! Units: metres, radians, bird's-eye pixels.

use super::render::{CameraMount, ObjectBox};
use super::scene::Scene;
use super::track::{wrap_pi, Track};
use super::vehicle::Pose;
use crate::config::Config;
use crate::lane::warp::{Homography, WarpError};
use serde::{Deserialize, Serialize};

/// Rows of the band sampled for the true columns.
const ROW_SAMPLES: usize = 13;

/// The truth of one frame (the `truth` field of a telemetry record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameTruth {
    /// Signed distance of the car's centre from the lane centre, metres, positive = car left
    /// of centre.
    pub offset_m: f64,
    /// Car heading minus lane heading, radians, positive = car points left of the lane.
    pub heading_error_rad: f64,
    /// Distance along the track's centre line, metres (0 at the start line).
    pub s_m: f64,
    /// Rear-axle pose: x, y (metres), yaw (radians).
    pub pose: [f64; 3],
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Front-wheel angle, degrees (positive = left).
    pub wheel_deg: f64,
    /// True bird's-eye column of the lane's left line, averaged over the histogram band.
    pub left_col: Option<f64>,
    /// True bird's-eye column of the lane's right line, averaged over the band.
    pub right_col: Option<f64>,
    /// True lane centre column, the mean of the two.
    pub center_col: Option<f64>,
    /// True lane-centre column on the band's bottom row (nearest the car).
    pub center_col_near: Option<f64>,
    /// Every drawn object in view: distance and image box (occlusion not considered).
    pub objects: Vec<ObjectBox>,
}

/// Computes ground truth for one camera and one pipeline configuration.
#[derive(Debug, Clone)]
pub struct TruthModel {
    mount: CameraMount,
    /// Camera pixels -> bird's-eye pixels, the pipeline's homography.
    h: Homography,
    /// Bird's-eye -> camera pixels.
    h_inv: Homography,
    out_w: f64,
    rows: Vec<f64>,
}

impl TruthModel {
    /// For the camera `mount` and the pipeline configured by `cfg`.
    pub fn new(cfg: &Config, mount: CameraMount) -> Result<TruthModel, WarpError> {
        let h = Homography::from_quad_to_rect(&cfg.warp.src, cfg.warp.out_width, cfg.warp.out_height)?;
        let h_inv = h.inverse().ok_or(WarpError::Singular)?;
        let out_h = cfg.warp.out_height;
        let band = crate::lane::lines::band_rows(out_h, cfg.lane.band) as f64;
        let (top, bottom) = (out_h as f64 - band, out_h as f64 - 1.0);
        let rows = (0..ROW_SAMPLES)
            .map(|i| bottom - (bottom - top) * i as f64 / (ROW_SAMPLES - 1) as f64)
            .collect();
        Ok(TruthModel {
            mount,
            h,
            h_inv,
            out_w: cfg.warp.out_width as f64,
            rows,
        })
    }

    /// Offset and heading error of the car at `pose` (centre `wheelbase/2` ahead of the axle).
    pub fn lane_pose(track: &Track, pose: &Pose, wheelbase: f64) -> (f64, f64, f64) {
        let c = pose.to_world([wheelbase / 2.0, 0.0]);
        let pr = track.project(c);
        (pr.lateral - track.drive_offset, wrap_pi(pose.yaw - pr.heading), pr.s)
    }

    /// The bird's-eye column of the line at lateral `offset` (from the road's centre line) on
    /// band row `row`, or `None` when the row does not see the floor.
    fn column(&self, scene: &Scene, pose: &Pose, offset: f64, row: f64) -> Option<f64> {
        let cam = &self.mount.camera;
        let a = self.h_inv.apply(0.0, row)?;
        let b = self.h_inv.apply(self.out_w - 1.0, row)?;
        let ga = self.mount.to_world(pose, {
            let g = cam.ground_of_pixel(a.0, a.1)?;
            [g.0, g.1]
        });
        let gb = self.mount.to_world(pose, {
            let g = cam.ground_of_pixel(b.0, b.1)?;
            [g.0, g.1]
        });
        let at = |l: f64| [ga[0] + l * (gb[0] - ga[0]), ga[1] + l * (gb[1] - ga[1])];
        let f = |l: f64| scene.lateral(at(l)) - offset;
        // Secant iteration from the row's two ends.
        let (mut l0, mut l1) = (0.0, 1.0);
        let (mut f0, mut f1) = (f(l0), f(l1));
        for _ in 0..6 {
            if (f1 - f0).abs() < 1e-12 {
                break;
            }
            let l2 = l1 - f1 * (l1 - l0) / (f1 - f0);
            (l0, f0) = (l1, f1);
            l1 = l2.clamp(-3.0, 4.0);
            f1 = f(l1);
            if f1.abs() < 1e-7 {
                break;
            }
        }
        if f1.abs() > 1e-4 {
            return None;
        }
        // Back through the camera and the pipeline's homography.
        let p = at(l1);
        let (s, c) = pose.yaw.sin_cos();
        let (dx, dy) = (p[0] - pose.x, p[1] - pose.y);
        let local = [c * dx + s * dy - self.mount.x_m, -s * dx + c * dy, 0.0];
        let (u, v) = cam.project(local)?;
        self.h.apply(u, v).map(|q| q.0)
    }

    /// Mean true column of a line over the band, and its column on the bottom row.
    fn line_columns(&self, scene: &Scene, pose: &Pose, offset: f64) -> (Option<f64>, Option<f64>) {
        let mut sum = 0.0;
        let mut near = None;
        for (i, &r) in self.rows.iter().enumerate() {
            let c = match self.column(scene, pose, offset, r) {
                Some(c) => c,
                None => return (None, None),
            };
            if i == 0 {
                near = Some(c);
            }
            sum += c;
        }
        (Some(sum / self.rows.len() as f64), near)
    }

    /// Everything about the lane for the car at `pose` (objects are filled in by the caller,
    /// who has the renderer).
    pub fn frame(&self, scene: &Scene, pose: &Pose, speed: f64, wheel_angle: f64, wheelbase: f64) -> FrameTruth {
        let track = &scene.track;
        let (offset, heading, s) = Self::lane_pose(track, pose, wheelbase);
        let half = track.half_lane();
        let (l, ln) = self.line_columns(scene, pose, track.drive_offset + half);
        let (r, rn) = self.line_columns(scene, pose, track.drive_offset - half);
        FrameTruth {
            offset_m: offset,
            heading_error_rad: heading,
            s_m: s,
            pose: [pose.x, pose.y, pose.yaw],
            speed_mps: speed,
            wheel_deg: wheel_angle.to_degrees(),
            left_col: l,
            right_col: r,
            center_col: l.zip(r).map(|(a, b)| (a + b) / 2.0),
            center_col_near: ln.zip(rn).map(|(a, b)| (a + b) / 2.0),
            objects: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::PinholeCamera;
    use std::path::Path;

    /// Centred in the lane on a straight, the lines are half a lane width (0.15 m × 638 px/m)
    /// either side of the image centre.
    #[test]
    fn centred_on_a_straight_sees_the_configured_lane_width() {
        let cfg = Config::default();
        let track = Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).unwrap();
        let mount = CameraMount {
            camera: PinholeCamera::from_config(&cfg.camera),
            x_m: cfg.vehicle.camera_x_m,
        };
        let tm = TruthModel::new(&cfg, mount).unwrap();
        let scene = Scene::new(&track);
        let (p, yaw) = track.lane_pose_at(0.3);
        let pose = Pose { x: p[0], y: p[1], yaw };
        let t = tm.frame(&scene, &pose, 0.0, 0.0, cfg.vehicle.wheelbase_m);
        assert!(t.offset_m.abs() < 1e-9 && t.heading_error_rad.abs() < 1e-9);
        let (l, r) = (t.left_col.unwrap(), t.right_col.unwrap());
        assert!((r - l - cfg.lane.lane_width_px).abs() < 0.2, "{l} {r}");
        assert!((t.center_col.unwrap() - 159.5).abs() < 0.05, "{:?}", t.center_col);
        // 2 cm left of centre: the lane moves right by 0.02 × 638 px.
        let pose2 = Pose {
            x: pose.x,
            y: pose.y + 0.02,
            yaw,
        };
        let t2 = tm.frame(&scene, &pose2, 0.0, 0.0, cfg.vehicle.wheelbase_m);
        assert!((t2.offset_m - 0.02).abs() < 1e-9);
        assert!(
            (t2.center_col.unwrap() - 159.5 - 0.02 * 638.0).abs() < 0.2,
            "{:?}",
            t2.center_col
        );
    }
}
