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
//! the floor (a homography maps lines to lines). For every band row, that floor line is
//! intersected with the lane line (secant iteration on its lateral offset), and the point is
//! mapped through the camera and the pipeline's own homography. From these row columns come
//! the mean column, the column nearest the car, and the peak of an ideal column histogram of
//! the painted line (what a perfect detector measures; see `FrameTruth::center_col_hist`).
//!
//! Units: metres, radians, bird's-eye pixels.

use super::render::{CameraMount, ObjectBox};
use super::scene::Scene;
use super::track::{wrap_pi, Track};
use super::vehicle::Pose;
use crate::config::Config;
use crate::lane::warp::{Homography, WarpError};
use serde::{Deserialize, Serialize};

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
    /// Left line: peak of the ideal column histogram of the painted line over the band (what
    /// a perfect detector reports as P_left; differs from `left_col` on curves).
    pub left_col_hist: Option<f64>,
    /// Right line: the same for P_right.
    pub right_col_hist: Option<f64>,
    /// The ideal L_c, the mean of the two ideal peaks: scores the pipeline's `lane_center`.
    pub center_col_hist: Option<f64>,
    /// Every drawn object in view: distance and image box (occlusion not considered).
    pub objects: Vec<ObjectBox>,
    /// The next floor mark (`[[marks]]`) ahead in the car's lane: its forward distance from
    /// the lens to the line's near edge (absent on tracks without marks, or none ahead).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mark_ahead: Option<super::track::MarkAhead>,
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
    /// The histogram band's rows, top and bottom (inclusive).
    band_top: u32,
    band_bottom: u32,
}

impl TruthModel {
    /// For the camera `mount` and the pipeline configured by `cfg`.
    pub fn new(cfg: &Config, mount: CameraMount) -> Result<TruthModel, WarpError> {
        let h = Homography::from_quad_to_rect(&cfg.warp.src, cfg.warp.out_width, cfg.warp.out_height)?;
        let h_inv = h.inverse().ok_or(WarpError::Singular)?;
        let out_h = cfg.warp.out_height;
        let band = crate::lane::lines::band_rows(out_h, cfg.lane.band);
        Ok(TruthModel {
            mount,
            h,
            h_inv,
            out_w: cfg.warp.out_width as f64,
            band_top: out_h - band,
            band_bottom: out_h - 1,
        })
    }

    /// Offset and heading error of the car at `pose` (centre `wheelbase/2` ahead of the axle).
    pub fn lane_pose(track: &Track, pose: &Pose, wheelbase: f64) -> (f64, f64, f64) {
        let c = pose.to_world([wheelbase / 2.0, 0.0]);
        let pr = track.project(c);
        (pr.lateral - track.drive_offset, wrap_pi(pose.yaw - pr.heading), pr.s)
    }

    /// Where the line at lateral `offset` (from the road's centre line) crosses band row
    /// `row`: (bird's-eye column, world point, bird's-eye pixels per metre along the row).
    /// `guess` is where along the row to start (0 = left edge, 1 = right edge); the answer's
    /// position along the row is returned in it. `None` when the row does not see the floor.
    fn crossing(
        &self,
        scene: &Scene,
        pose: &Pose,
        offset: f64,
        row: f64,
        guess: &mut f64,
    ) -> Option<(f64, [f64; 2], f64)> {
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
        // Secant iteration from the guess and a point 5% of the row away.
        let (mut l0, mut l1) = (*guess, *guess + 0.05);
        let (mut f0, mut f1) = (f(l0), f(l1));
        for _ in 0..8 {
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
        *guess = l1;
        // Back through the camera and the pipeline's homography.
        let p = at(l1);
        let (s, c) = pose.yaw.sin_cos();
        let (dx, dy) = (p[0] - pose.x, p[1] - pose.y);
        let local = [c * dx + s * dy - self.mount.x_m, -s * dx + c * dy, 0.0];
        let (u, v) = cam.project(local)?;
        let col = self.h.apply(u, v)?.0;
        let len = (gb[0] - ga[0]).hypot(gb[1] - ga[1]);
        Some((col, p, (self.out_w - 1.0) / len.max(1e-9)))
    }

    /// One line over the band: (mean column over all band rows, column on the bottom row,
    /// peak of an ideal column histogram of the painted line).
    ///
    /// The ideal histogram counts, row by row, the bird's-eye pixels whose centres lie on
    /// the paint (dashes included), and its peak is found by the pipeline's own
    /// [`crate::lane::lines::peak`]. On a curve a line crosses the band slanted, and the
    /// histogram peak lies nearer the car than the mean column; this is the number a perfect
    /// detector would report, so it scores the detector and not the definition.
    fn line_truth(
        &self,
        scene: &Scene,
        pose: &Pose,
        offset: f64,
        dashed: bool,
    ) -> (Option<f64>, Option<f64>, Option<f64>) {
        let track = &scene.track;
        let road = &track.spec.road;
        let hw = road.line_width_m / 2.0;
        let w = self.out_w as usize;
        let mut hist = vec![0u16; w];
        let (mut sum, mut n, mut near, mut all) = (0.0, 0usize, None, true);
        let mut guess = 0.5;
        for r in self.band_top..=self.band_bottom {
            let Some((col, p, ppm)) = self.crossing(scene, pose, offset, r as f64, &mut guess) else {
                all = false;
                continue;
            };
            if r == self.band_bottom {
                near = Some(col);
            }
            sum += col;
            n += 1;
            if dashed {
                let s = track.project(p).s;
                let period = road.dash_m + road.gap_m;
                if s.rem_euclid(period) >= road.dash_m {
                    continue;
                }
            }
            let (a, b) = ((col - hw * ppm).ceil(), (col + hw * ppm).floor());
            let (a, b) = (a.max(0.0) as usize, b.min(w as f64 - 1.0));
            if b >= 0.0 {
                for c in hist.iter_mut().take(b as usize + 1).skip(a) {
                    *c += 1;
                }
            }
        }
        let mean = (all && n > 0).then(|| sum / n as f64);
        let peak = crate::lane::lines::peak(&hist, 0..w, 1);
        (mean, near, peak)
    }

    /// Everything about the lane for the car at `pose` (objects are filled in by the caller,
    /// who has the renderer).
    pub fn frame(&self, scene: &Scene, pose: &Pose, speed: f64, wheel_angle: f64, wheelbase: f64) -> FrameTruth {
        let track = &scene.track;
        let (offset, heading, s) = Self::lane_pose(track, pose, wheelbase);
        let half = track.half_lane();
        // The lane's lines; the one at the road's centre line (offset 0) may be dashed.
        let dashed = |o: f64| track.lines.iter().any(|&(lo, d)| d && (lo - o).abs() < 1e-9);
        let (lo, ro) = (track.drive_offset + half, track.drive_offset - half);
        let (l, ln, lh) = self.line_truth(scene, pose, lo, dashed(lo));
        let (r, rn, rh) = self.line_truth(scene, pose, ro, dashed(ro));
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
            left_col_hist: lh,
            right_col_hist: rh,
            center_col_hist: lh.zip(rh).map(|(a, b)| (a + b) / 2.0),
            objects: Vec::new(),
            mark_ahead: track.mark_ahead(pose.to_world([self.mount.x_m, 0.0]), pose.yaw),
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
            camera: PinholeCamera::from(&cfg.camera),
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
