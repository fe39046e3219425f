//! A checkerboard in front of the simulated camera, for calibrating it like a real one
//! (`rccar calibrate camera|stereo` on rendered photos; issue 12). The camera is the
//! simulator's pinhole ([`PinholeCamera`]: focal length from `camera.hfov_deg`, principal
//! point at the image centre, no lens distortion), so calibration must give those values back.
//!
//! Rendering: every pixel is ray-cast at 4×4 sub-samples onto the board's plane (OpenCV camera
//! frame: x right, y down, z forward; board pose X_cam = R·X_board + t, metres); squares
//! alternate black/white with a white margin one square wide, a textured grey wall behind;
//! then seeded triangular noise (grey levels).

use super::rng::SplitMix64;
use crate::calib::corners::BoardSize;
use crate::calib::intrinsics::{rodrigues, Pose};
use crate::camera::PinholeCamera;
use image::GrayImage;
use nalgebra::Vector3;

/// A board to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Board {
    /// Inner corners.
    pub size: BoardSize,
    /// Square side, metres.
    pub square_m: f64,
}

impl Board {
    /// The board's centre in its own frame (the middle inner corner), metres.
    pub fn centre(&self) -> [f64; 3] {
        [
            (self.size.cols - 1) as f64 * self.square_m / 2.0,
            (self.size.rows - 1) as f64 * self.square_m / 2.0,
            0.0,
        ]
    }

    /// The pose that puts the board's centre at `c` (camera frame, metres) turned by `rvec`.
    pub fn pose_centred(&self, rvec: [f64; 3], c: [f64; 3]) -> Pose {
        let r = rodrigues(rvec);
        let m = r * Vector3::from(self.centre());
        Pose {
            rvec,
            t: [c[0] - m[0], c[1] - m[1], c[2] - m[2]],
        }
    }

    /// A set of `n` (≤ 12) varied views filling the image of `cam` at about `dist` metres:
    /// the board turned up to ±0.45 rad about both axes and moved about the field of view.
    pub fn calibration_poses(&self, cam: &PinholeCamera, dist: f64, n: usize) -> Vec<Pose> {
        let tilts = [
            (0.35, 0.0),
            (-0.35, 0.0),
            (0.0, 0.4),
            (0.0, -0.4),
            (0.3, 0.3),
            (-0.3, 0.3),
            (0.3, -0.3),
            (-0.3, -0.3),
            (0.45, 0.1),
            (-0.1, 0.45),
            (0.15, -0.45),
            (-0.45, -0.15),
        ];
        // Off-centre by up to a sixth of the image.
        let shift = [
            (0.0, 0.0),
            (1.0, 0.5),
            (-1.0, -0.5),
            (0.5, -1.0),
            (-0.5, 1.0),
            (1.0, -1.0),
        ];
        (0..n.min(tilts.len()))
            .map(|i| {
                let (rx, ry) = tilts[i];
                let (sx, sy) = shift[i % shift.len()];
                let dx = sx * dist * cam.width as f64 / 6.0 / cam.f_px;
                let dy = sy * dist * cam.height as f64 / 6.0 / cam.f_px;
                self.pose_centred([rx, ry, 0.05 * i as f64 - 0.2], [dx, dy, dist])
            })
            .collect()
    }

    /// Renders the board at `pose` through `cam` (lens at the camera origin), with triangular
    /// noise of standard deviation `noise_sigma` grey levels (seeded by `seed`).
    pub fn render(&self, cam: &PinholeCamera, pose: &Pose, noise_sigma: f64, seed: u64) -> GrayImage {
        let r = rodrigues(pose.rvec);
        let t = Vector3::from(pose.t);
        let n = r.column(2).into_owned();
        let nt = n.dot(&t);
        let rt = r.transpose();
        let sq = self.square_m;
        let (cols, rows) = (self.size.cols as i64, self.size.rows as i64);
        let mut rng = SplitMix64::new(seed ^ 0xB0A2D);
        let a = noise_sigma * 6f64.sqrt();
        GrayImage::from_fn(cam.width, cam.height, |x, y| {
            let mut acc = 0.0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let u = x as f64 + (sx as f64 + 0.5) / 4.0 - 0.5;
                    let v = y as f64 + (sy as f64 + 0.5) / 4.0 - 0.5;
                    let ray = Vector3::new((u - cam.u0) / cam.f_px, (v - cam.v0) / cam.f_px, 1.0);
                    let den = n.dot(&ray);
                    let mut val = None;
                    if den.abs() > 1e-12 {
                        let s = nt / den;
                        if s > 0.0 {
                            let b = rt * (ray * s - t);
                            let (i, j) = ((b[0] / sq).floor() as i64, (b[1] / sq).floor() as i64);
                            if i >= -1 && i < cols && j >= -1 && j < rows {
                                val = Some(if (i + j).rem_euclid(2) == 0 { 35.0 } else { 215.0 });
                            } else if i >= -2 && i <= cols && j >= -2 && j <= rows {
                                val = Some(215.0);
                            }
                        }
                    }
                    // The wall: a soft grey pattern.
                    acc += val.unwrap_or_else(|| 120.0 + 25.0 * ((u * 0.05).sin() * (v * 0.07).cos()));
                }
            }
            let noise = if noise_sigma > 0.0 {
                let q = rng.next_u64();
                ((q & 0xFF) as f64 + ((q >> 8) & 0xFF) as f64 - 255.0) / 255.0 * a
            } else {
                0.0
            };
            image::Luma([(acc / 16.0 + noise).round().clamp(0.0, 255.0) as u8])
        })
    }
}
