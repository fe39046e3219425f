//! Synthetic camera frames of a taped lane with known line positions: the project's own test
//! data for the lane pipeline (no photos committed).
//!
//! The floor is a plane; each tape line is a curve of constant lateral offset from a lane
//! centre line that is straight or a circular arc (radius in metres, positive = turning left).
//! Every camera pixel is traced to the floor with the pinhole model of [`crate::camera`]
//! (4×4 supersampling, so line edges are anti-aliased as a real lens blurs them), then a seeded
//! floor texture and sensor noise are added. Because the scene is analytic, the true bird's-eye
//! column of each line is known exactly ([`SynthFrame::truth_left`], [`SynthFrame::truth_right`]).
//!
//! Units: metres on the floor, pixels in images. Car frame: x forward, y left.

use crate::camera::PinholeCamera;
use crate::lane::warp::Homography;
use image::{Rgb, RgbImage};

/// One lane scene as the camera sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneScene {
    /// Lateral offset of the car from the lane centre, metres (positive = car left of centre).
    pub offset_m: f64,
    /// Heading of the car relative to the lane, radians (positive = car turned left).
    pub heading_rad: f64,
    /// Radius of the lane's centre line, metres; positive turns left, `f64::INFINITY` straight.
    pub radius_m: f64,
    /// Distance between the two line centres, metres.
    pub lane_width_m: f64,
    /// Tape width, metres.
    pub line_width_m: f64,
    /// Draw the left line.
    pub left_visible: bool,
    /// Draw the right line.
    pub right_visible: bool,
    /// Standard deviation of per-pixel sensor noise, grey levels.
    pub noise: f64,
    /// Seed of the floor texture and the noise.
    pub seed: u64,
}

impl Default for LaneScene {
    fn default() -> Self {
        Self {
            offset_m: 0.0,
            heading_rad: 0.0,
            radius_m: f64::INFINITY,
            lane_width_m: 0.30,
            line_width_m: 0.02,
            left_visible: true,
            right_visible: true,
            noise: 4.0,
            seed: 1,
        }
    }
}

/// A rendered frame and the truth about it.
#[derive(Debug, Clone)]
pub struct SynthFrame {
    /// What the camera sees.
    pub image: RgbImage,
    /// True bird's-eye column of the left line's centre, averaged over the histogram band (NaN
    /// when the band does not look at the floor).
    pub truth_left: f64,
    /// True bird's-eye column of the right line's centre, averaged over the histogram band.
    pub truth_right: f64,
}

impl SynthFrame {
    /// True lane centre, Eq. 3 applied to the true lines.
    pub fn truth_center(&self) -> f64 {
        (self.truth_right - self.truth_left) / 2.0 + self.truth_left
    }
}

/// SplitMix64: a tiny seeded generator, enough for textures and noise.
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    /// A generator for `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Hash of an integer lattice point to [0, 1): a stateless texture.
fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut g =
        SplitMix::new(seed ^ (ix as u64).wrapping_mul(0x9E37_79B9) ^ (iy as u64).wrapping_mul(0x85EB_CA6B) << 1);
    g.uniform()
}

/// Smooth value noise on a grid of `cell` metres.
fn value_noise(x: f64, y: f64, cell: f64, seed: u64) -> f64 {
    let (gx, gy) = (x / cell, y / cell);
    let (ix, iy) = (gx.floor() as i64, gy.floor() as i64);
    let (fx, fy) = (gx - ix as f64, gy - iy as f64);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = lattice(ix, iy, seed) * (1.0 - sx) + lattice(ix + 1, iy, seed) * sx;
    let b = lattice(ix, iy + 1, seed) * (1.0 - sx) + lattice(ix + 1, iy + 1, seed) * sx;
    a * (1.0 - sy) + b * sy
}

impl LaneScene {
    /// Lateral distance (metres, in the lane's frame) of the car-frame floor point (x, y) from
    /// the lane's centre line; positive = left of the centre line.
    fn lateral_of(&self, x: f64, y: f64) -> f64 {
        // Car frame -> lane frame: the car sits at lateral `offset_m`, turned by `heading_rad`.
        let (s, c) = self.heading_rad.sin_cos();
        let lx = c * x - s * y;
        let ly = s * x + c * y + self.offset_m;
        if self.radius_m.is_infinite() {
            ly
        } else {
            // Centre of the arc at (0, R) in the lane frame; left of the line = nearer the centre
            // for a left turn.
            let r = self.radius_m;
            r - r.signum() * (lx * lx + (ly - r) * (ly - r)).sqrt()
        }
    }

    /// Renders the scene through `cam`. `homography` maps camera pixels to the bird's-eye image
    /// in which the truth is wanted; `band` is the histogram band (fraction of `bird_h` rows).
    pub fn render(&self, cam: &PinholeCamera, homography: &Homography, bird_h: u32, band: f64) -> SynthFrame {
        let (w, h) = (cam.width, cam.height);
        let mut img = RgbImage::new(w, h);
        let mut rng = SplitMix::new(self.seed.wrapping_mul(7919).wrapping_add(13));
        let half_line = self.line_width_m / 2.0;
        let half_lane = self.lane_width_m / 2.0;
        const SS: usize = 4;
        for v in 0..h {
            for u in 0..w {
                let mut acc = [0.0f64; 3];
                for k in 0..SS * SS {
                    let su = u as f64 + ((k % SS) as f64 + 0.5) / SS as f64 - 0.5;
                    let sv = v as f64 + ((k / SS) as f64 + 0.5) / SS as f64 - 0.5;
                    let c = match cam.ground_of_pixel(su, sv) {
                        Some((x, y)) if x < 20.0 => {
                            let lat = self.lateral_of(x, y);
                            let on_left = self.left_visible && (lat - half_lane).abs() <= half_line;
                            let on_right = self.right_visible && (lat + half_lane).abs() <= half_line;
                            // Dark grey floor with a blotchy texture; white tape, slightly uneven.
                            let tex = value_noise(x, y, 0.05, self.seed) * 0.6
                                + value_noise(x, y, 0.013, self.seed + 1) * 0.4;
                            if on_left || on_right {
                                let t = 225.0 + 20.0 * tex;
                                [t, t, t - 5.0]
                            } else {
                                let f = 55.0 + 35.0 * tex;
                                [f + 4.0, f, f - 6.0]
                            }
                        }
                        // Above the horizon or very far: a wall.
                        _ => [150.0, 155.0, 165.0],
                    };
                    for ch in 0..3 {
                        acc[ch] += c[ch];
                    }
                }
                let n = self.noise * rng.normal();
                let px = acc.map(|a| (a / (SS * SS) as f64 + n).round().clamp(0.0, 255.0) as u8);
                img.put_pixel(u, v, Rgb(px));
            }
        }
        let (truth_left, truth_right) = self
            .truth(cam, homography, bird_h, band)
            .unwrap_or((f64::NAN, f64::NAN));
        SynthFrame {
            image: img,
            truth_left,
            truth_right,
        }
    }

    /// True bird's-eye columns of both line centres, averaged over the band's rows; `None` when
    /// part of the band does not look at the floor (an ROI reaching above the horizon).
    fn truth(&self, cam: &PinholeCamera, homography: &Homography, bird_h: u32, band: f64) -> Option<(f64, f64)> {
        let rows = crate::lane::lines::band_rows(bird_h, band);
        let inv = homography.inverse()?;
        let mut sums = [0.0f64; 2];
        for r in (bird_h - rows)..bird_h {
            for (side, target) in [(0usize, self.lane_width_m / 2.0), (1, -self.lane_width_m / 2.0)] {
                // Along bird's-eye row r, find the column where the line's lateral equals target
                // (bisection on the floor point under each column).
                let lat_at = |bx: f64| -> Option<f64> {
                    let (u, v) = inv.apply(bx, r as f64)?;
                    let (x, y) = cam.ground_of_pixel(u, v)?;
                    Some(self.lateral_of(x, y) - target)
                };
                let (mut a, mut b) = (-400.0, 800.0);
                let fa = lat_at(a)?;
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if (lat_at(m)? > 0.0) == (fa > 0.0) {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                sums[side] += 0.5 * (a + b);
            }
        }
        Some((sums[0] / rows as f64, sums[1] / rows as f64))
    }
}

/// The sample sequence shipped in `tests/data/lane_sample/`: a straight with a slow drift, a
/// left curve, a right curve, a stretch where the left line is missing, and noise throughout.
pub fn sample_sequence() -> Vec<LaneScene> {
    let mut v = Vec::new();
    for i in 0..10 {
        let t = i as f64 / 9.0;
        v.push(LaneScene {
            offset_m: 0.04 * (t - 0.5),
            heading_rad: 0.03 * (0.5 - t),
            seed: 100 + i,
            ..Default::default()
        });
    }
    for i in 0..8 {
        v.push(LaneScene {
            radius_m: 3.5 - 0.12 * i as f64,
            offset_m: -0.01,
            heading_rad: -0.03,
            seed: 200 + i,
            ..Default::default()
        });
    }
    for i in 0..8 {
        v.push(LaneScene {
            radius_m: -3.5 + 0.12 * i as f64,
            offset_m: 0.01,
            heading_rad: 0.03,
            seed: 300 + i,
            ..Default::default()
        });
    }
    for i in 0..4 {
        v.push(LaneScene {
            left_visible: false,
            offset_m: 0.01 * i as f64 - 0.02,
            seed: 400 + i,
            ..Default::default()
        });
    }
    for i in 0..2 {
        v.push(LaneScene {
            noise: 12.0,
            offset_m: -0.02,
            heading_rad: 0.01,
            seed: 500 + i,
            ..Default::default()
        });
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped camera (`[camera]`) and its ROI (`[warp] src`: 0.40..1.00 m ahead, 0.25 m
    /// either side).
    fn camera_and_roi() -> (PinholeCamera, [[f64; 2]; 4]) {
        let cam = PinholeCamera::new(320, 240, 62.2, 0.20, 20.0);
        (cam, cam.roi_of_ground_rect(0.40, 1.00, 0.25).unwrap())
    }

    #[test]
    fn straight_centred_lane_truth_is_the_image_centre() {
        let (cam, roi) = camera_and_roi();
        let h = Homography::from_quad_to_rect(&roi, 320, 240).unwrap();
        let scene = LaneScene::default();
        let (l, r) = scene.truth(&cam, &h, 240, 0.4).unwrap();
        // 0.15 m either side at 638 px/m around the centre column 159.5.
        assert!((l - (159.5 - 0.15 * 638.0)).abs() < 0.05, "{l}");
        assert!((r - (159.5 + 0.15 * 638.0)).abs() < 0.05, "{r}");
    }

    #[test]
    fn rendering_is_deterministic_for_a_seed() {
        let (_, roi) = camera_and_roi();
        let cam = PinholeCamera::new(64, 48, 62.2, 0.20, 20.0);
        let h = Homography::from_quad_to_rect(&roi, 320, 240).unwrap();
        let a = LaneScene::default().render(&cam, &h, 240, 0.4);
        let b = LaneScene::default().render(&cam, &h, 240, 0.4);
        assert_eq!(a.image, b.image);
        let c = LaneScene {
            seed: 2,
            ..Default::default()
        }
        .render(&cam, &h, 240, 0.4);
        assert_ne!(a.image, c.image);
    }
}
