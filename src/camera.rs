//! The pinhole camera on the car: where a point on the floor appears in the image, and which
//! floor point a pixel sees.
//!
//! This is the geometry behind monocular tilt ranging (Rivera & Andaluz 2021, Eq. 5, after
//! Chu et al. 2004): a camera at height `h` tilted down by `α` sees a floor point at distance
//! `d` on image row `v` with `d = h / tan(α + atan((v − v0) / a_y))`, `a_y = f / d_y`. The same
//! model places the default ROI (see `rccar config roi`), draws the sample frames and renders
//! the simulator's view, so all of them agree by construction (the bird's-eye view's map to
//! the floor through it is `lane::warp::bird_to_floor`).
//!
//! Frames: the car frame has x forward, y left, z up, metres, origin on the floor below the
//! lens. Pixels follow OpenCV: pixel (i, j) has its centre at (u, v) = (i, j), so the principal
//! point of a W×H image is ((W − 1)/2, (H − 1)/2). Square pixels (a_x = a_y = f).

/// A pinhole camera mounted on the car, looking forward and tilted down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length in pixels (a_x = a_y).
    pub f_px: f64,
    /// Principal point column u0, pixels.
    pub u0: f64,
    /// Principal point row v0, pixels.
    pub v0: f64,
    /// Lens height above the floor h, metres.
    pub height_m: f64,
    /// Downward tilt α, radians.
    pub tilt_rad: f64,
    /// Lateral offset of the lens from the car's centre line, metres (left positive).
    pub lateral_m: f64,
}

/// A 3-D point or direction in the car frame (x forward, y left, z up), metres.
pub type Vec3 = [f64; 3];

impl PinholeCamera {
    /// A `width`×`height` camera (pixels) with a horizontal field of view of `hfov_deg`
    /// degrees, its lens `height_m` metres above the floor on the car's centre line and tilted
    /// `tilt_deg` degrees down; the principal point in the image centre. `[camera]` of car.toml
    /// converts into it (`PinholeCamera::from(&cfg.camera)`).
    pub fn new(width: u32, height: u32, hfov_deg: f64, height_m: f64, tilt_deg: f64) -> Self {
        let f_px = (width as f64 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        Self {
            width,
            height,
            f_px,
            u0: (width as f64 - 1.0) / 2.0,
            v0: (height as f64 - 1.0) / 2.0,
            height_m,
            tilt_rad: tilt_deg.to_radians(),
            lateral_m: 0.0,
        }
    }

    /// The optical axis, image-right and image-down unit vectors in the car frame.
    fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let (s, c) = self.tilt_rad.sin_cos();
        ([c, 0.0, -s], [0.0, -1.0, 0.0], [-s, 0.0, -c])
    }

    /// The lens position in the car frame.
    pub fn origin(&self) -> Vec3 {
        [0.0, self.lateral_m, self.height_m]
    }

    /// Projects a point in the car frame to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(f64, f64)> {
        let o = self.origin();
        let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        let (fwd, right, down) = self.basis();
        let zc = dot(d, fwd);
        if zc <= 1e-9 {
            return None;
        }
        Some((
            self.u0 + self.f_px * dot(d, right) / zc,
            self.v0 + self.f_px * dot(d, down) / zc,
        ))
    }

    /// The (unnormalised) direction of the ray through pixel (u, v), car frame.
    pub fn ray(&self, u: f64, v: f64) -> Vec3 {
        let (fwd, right, down) = self.basis();
        let a = (u - self.u0) / self.f_px;
        let b = (v - self.v0) / self.f_px;
        [
            fwd[0] + a * right[0] + b * down[0],
            fwd[1] + a * right[1] + b * down[1],
            fwd[2] + a * right[2] + b * down[2],
        ]
    }

    /// The floor point (x forward, y left) seen at pixel (u, v); `None` at or above the horizon.
    pub fn ground_of_pixel(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let r = self.ray(u, v);
        if r[2] >= -1e-12 {
            return None;
        }
        let t = self.height_m / -r[2];
        let o = self.origin();
        Some((o[0] + t * r[0], o[1] + t * r[1]))
    }

    /// Eq. 5 of Rivera & Andaluz: ground distance to a floor point seen on row `v`,
    /// `d = h / tan(α + atan((v − v0)/a_y))`, measured along the optical axis' ground track.
    /// `None` when the ray does not hit the floor.
    pub fn distance_of_row(&self, v: f64) -> Option<f64> {
        let angle = self.tilt_rad + ((v - self.v0) / self.f_px).atan();
        (angle > 1e-9 && angle < std::f64::consts::FRAC_PI_2 + 1e-9).then(|| self.height_m / angle.tan())
    }

    /// The ROI corners (top-left, top-right, bottom-right, bottom-left, pixels) of the floor
    /// rectangle `near..far` metres ahead and `half_width` metres either side.
    pub fn roi_of_ground_rect(&self, near: f64, far: f64, half_width: f64) -> Option<[[f64; 2]; 4]> {
        let p = |x: f64, y: f64| self.project([x, y, 0.0]).map(|(u, v)| [u, v]);
        Some([
            p(far, half_width)?,
            p(far, -half_width)?,
            p(near, -half_width)?,
            p(near, half_width)?,
        ])
    }
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped camera (`[camera]` of car.toml).
    fn cam() -> PinholeCamera {
        PinholeCamera::new(320, 240, 62.2, 0.20, 20.0)
    }

    #[test]
    fn project_and_back_round_trip() {
        let c = cam();
        for &(x, y) in &[(0.3, 0.0), (0.5, 0.2), (1.2, -0.3), (3.0, 0.5)] {
            let (u, v) = c.project([x, y, 0.0]).unwrap();
            let (gx, gy) = c.ground_of_pixel(u, v).unwrap();
            assert!(
                (gx - x).abs() < 1e-9 && (gy - y).abs() < 1e-9,
                "({x},{y}) -> ({gx},{gy})"
            );
        }
    }

    #[test]
    fn eq5_matches_projection_on_the_centre_column() {
        let c = cam();
        for &d in &[0.2, 0.5, 1.0, 1.5] {
            let (_, v) = c.project([d, 0.0, 0.0]).unwrap();
            assert!((c.distance_of_row(v).unwrap() - d).abs() < 1e-9);
        }
        // Above the horizon the ray never reaches the floor.
        assert!(c.distance_of_row(0.0 - 200.0).is_none());
    }
}
