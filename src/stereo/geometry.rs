//! Distance from a disparity, three ways (Zaarane et al. 2020, Eq. 1–16; Abdollahi 2011).
//!
//! Two parallel cameras A metres apart (the base); an object's centroid at column x_l in the
//! left and x_r in the right rectified image (pixel centres at integers, the image's left
//! edge at −0.5, W pixels wide, horizontal field of view ω).
//!
//! (a) Eq. 16 as written, angles linear in the column:
//!     P1 = (W − 0.5) − x_l, P2 = x_r + 0.5, β = (180° − ω)/2,
//!     φ = P1·ω/W + β (Eq. 13), θ = P2·ω/W + β (Eq. 14), α = 180° − (φ + θ) (Eq. 15),
//!     h = A·sin θ·sin φ / sin α (Eq. 5).
//! (b) The same triangle with the pinhole's exact angles:
//!     φ = 90° − atan((x_l − c_x)/f), θ = 90° + atan((x_r − c_x)/f).
//! (c) D = b·f/d with d = x_l − x_r (Abdollahi 2011). Since h = A/(cot φ + cot θ) and
//!     cot φ + cot θ = (x_l − x_r)/f, (b) and (c) are the same number.
//!
//! (a) is biased because ω/W is not the angle of one pixel everywhere: the true angle per
//! pixel is f/(f² + (x − c_x)²), larger than ω/W near the centre and smaller near the edges.
//! To first order in d, (a)/(c) = 2·tan(ω/2) / (ω·(1 + tan²ψ)), ψ = (x − c_x)·ω/W the linear
//! angle of the object: +11 % at the centre and −18 % at the edge for ω = 62.2°
//! (see [`StereoGeometry::eq16_bias`] and docs/stereo.md).
//!
//! All three give the depth along the optical axis (the distance from the base line). The
//! cameras look down by the tilt α_t, so the forward distance on the floor of the point at
//! pixel (u, v) is Z·(cos α_t − ((v − c_y)/f)·sin α_t) and its lateral offset −Z·(u − c_x)/f
//! (left positive), as monocular ranging reports them. Units: metres, pixels, radians.
//!
//! A calibrated pair is rectified first (src/stereo/rectify.rs): the rectified reference
//! camera is the real one turned by Bouguet's rotation R₁ (a degree or two), so a point
//! found at rectified (u, v) and depth Z is turned back by R₁ᵀ into the reference camera
//! before the tilt is applied ([`StereoGeometry::rect_to_cam`]; the identity for an ideal pair).
//!
//! A vertical face (an obstacle's near side) at forward distance F therefore has, at row v,
//! the disparity d(v) = b·f·(cos α_t − ((v − c_y)/f)·sin α_t)/F: it changes along the face
//! (by 10 % over a 0.10 m box at 0.3 m), while every row gives back the same F. The top of
//! a box, farther back row by row, gives a larger F in each row. [`StereoGeometry::vertical_face`]
//! takes the forward distance most rows agree on (the face), not the box's mean disparity.

use super::matching::{RowMatch, StereoMatch};
use crate::calib::file::StereoCalibration;
use crate::camera::PinholeCamera;

/// A rectified stereo pair's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoGeometry {
    /// Image width W, pixels.
    pub width: u32,
    /// Focal length of the rectified images, pixels.
    pub f: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Base A (distance between the lenses), metres.
    pub base_m: f64,
    /// Horizontal field of view ω used by Eq. 16, radians (2·atan(W/2f) for a pinhole).
    pub hfov_rad: f64,
    /// Downward tilt of both optical axes, radians.
    pub tilt_rad: f64,
    /// Rotation from the rectified reference camera back to the real one (R₁ᵀ, or R₂ᵀ when the
    /// right camera is the reference), row-major; the identity for an ideal pair.
    pub rect_to_cam: [[f64; 3]; 3],
}

/// The 3×3 identity, row-major.
pub const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The vertical face found among a box's rows ([`StereoGeometry::vertical_face`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceFit {
    /// Forward distance on the floor of the face, metres (the median of its rows).
    pub forward_m: f64,
    /// Rows that agree on it.
    pub rows: usize,
    /// Rows with a match.
    pub of: usize,
}

/// One object's distance by the three methods.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRange {
    /// Disparity, pixels.
    pub disparity: f64,
    /// Depth by (a) Eq. 16 with linear angles, metres (`None` when its triangle does not close).
    pub depth_eq16: Option<f64>,
    /// Depth by (b) exact angles, metres.
    pub depth_exact: Option<f64>,
    /// Depth by (c) b·f/d, metres.
    pub depth_bfd: f64,
    /// Forward distance on the floor by (a), (b), (c), metres.
    pub forward_m: [Option<f64>; 3],
    /// Lateral offset of the object from the reference lens (left positive), by (c), metres.
    pub lateral_m: f64,
}

impl StereoGeometry {
    /// An ideal pair of the configured camera (`[camera]`) with base `base_m`: what the
    /// simulator renders, and the default when no calibration file is given.
    pub fn ideal(cam: &PinholeCamera, base_m: f64) -> Self {
        Self {
            width: cam.width,
            f: cam.f_px,
            cx: cam.u0,
            cy: cam.v0,
            base_m,
            hfov_rad: 2.0 * (cam.width as f64 / (2.0 * cam.f_px)).atan(),
            tilt_rad: cam.tilt_rad,
            rect_to_cam: IDENTITY,
        }
    }

    /// From a stereo calibration (rectified camera, |T| and the reference camera's
    /// rectifying rotation); the tilt comes from `[camera]`.
    pub fn from_calibration(st: &StereoCalibration, tilt_rad: f64, reference_left: bool) -> Self {
        let r = &st.rectification;
        let w = st.left.image_size[0];
        let rr = if reference_left { &r.r1 } else { &r.r2 };
        Self {
            width: w,
            f: r.f,
            cx: r.c[0],
            cy: r.c[1],
            base_m: r.tx.abs(),
            hfov_rad: 2.0 * (w as f64 / (2.0 * r.f)).atan(),
            tilt_rad,
            rect_to_cam: std::array::from_fn(|i| std::array::from_fn(|j| rr[j][i])),
        }
    }

    /// (a) Zaarane's Eq. 16 with the left column `xl` and the right column `xr`; metres.
    pub fn depth_eq16(&self, xl: f64, xr: f64) -> Option<f64> {
        let w = self.width as f64;
        let ap = self.hfov_rad / w; // Eq. 11/12
        let beta = (std::f64::consts::PI - self.hfov_rad) / 2.0;
        let p1 = (w - 0.5) - xl;
        let p2 = xr + 0.5;
        let phi = p1 * ap + beta; // Eq. 13
        let theta = p2 * ap + beta; // Eq. 14
        let alpha = std::f64::consts::PI - (phi + theta); // Eq. 15
        (alpha > 1e-12).then(|| self.base_m * theta.sin() * phi.sin() / alpha.sin())
        // Eq. 16
    }

    /// (b) The same triangle with exact angles; metres.
    pub fn depth_exact(&self, xl: f64, xr: f64) -> Option<f64> {
        let phi = std::f64::consts::FRAC_PI_2 - ((xl - self.cx) / self.f).atan();
        let theta = std::f64::consts::FRAC_PI_2 + ((xr - self.cx) / self.f).atan();
        let alpha = std::f64::consts::PI - (phi + theta);
        (alpha > 1e-12).then(|| self.base_m * theta.sin() * phi.sin() / alpha.sin())
    }

    /// (c) D = b·f/d; metres (`None` for d ≤ 0).
    pub fn depth_bfd(&self, d: f64) -> Option<f64> {
        (d > 0.0).then(|| self.base_m * self.f / d)
    }

    /// Forward distance on the floor and lateral offset (left positive) of the point at depth
    /// `z` seen at pixel (u, v) of the reference camera; metres.
    pub fn forward_of_depth(&self, z: f64, u: f64, v: f64) -> (f64, f64) {
        let (fw, lat) = self.per_depth(u, v);
        (z * fw, z * lat)
    }

    /// Forward distance and lateral offset per metre of depth of the rectified pixel (u, v):
    /// its ray (x, y, 1) turned into the reference camera ([`StereoGeometry::rect_to_cam`]),
    /// then z·cos α_t − y·sin α_t forward and −x lateral.
    fn per_depth(&self, u: f64, v: f64) -> (f64, f64) {
        let p = [(u - self.cx) / self.f, (v - self.cy) / self.f, 1.0];
        let m = &self.rect_to_cam;
        let q: [f64; 3] = std::array::from_fn(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2]);
        let (s, c) = self.tilt_rad.sin_cos();
        (q[2] * c - q[1] * s, -q[0])
    }

    /// Forward distance on the floor of a point at row `v` with disparity `d` (by (c));
    /// `None` for d ≤ 0.
    pub fn forward_of_disparity(&self, d: f64, v: f64) -> Option<f64> {
        self.depth_bfd(d).map(|z| self.forward_of_depth(z, self.cx, v).0)
    }

    /// The disparity at row `v` of a point at forward distance `forward_m` (the inverse of
    /// [`StereoGeometry::forward_of_disparity`]), pixels.
    pub fn disparity_of_forward(&self, forward_m: f64, v: f64) -> f64 {
        self.base_m * self.f * self.per_depth(self.cx, v).0 / forward_m
    }

    /// The vertical face among the rows of a box matched on their own: each row's forward
    /// distance F_i (its disparity at its row); of the windows [F_i, F_i·(1 + `tol`)], the one
    /// holding most rows (on a tie the nearest) is the face, its median F the answer. A
    /// vertical face gives every row the same F; a box's top face (farther row by row) and
    /// the floor (every row another distance) spread out and do not gather. `None` with
    /// fewer than 3 rows in the window.
    pub fn vertical_face(&self, rows: &[RowMatch], tol: f64) -> Option<FaceFit> {
        let mut f: Vec<f64> = rows
            .iter()
            .filter_map(|r| self.forward_of_disparity(r.disparity, r.row as f64))
            .collect();
        f.sort_by(f64::total_cmp);
        let mut best = (0usize, 0usize);
        let mut j = 0;
        for i in 0..f.len() {
            j = j.max(i);
            while j + 1 < f.len() && f[j + 1] <= f[i] * (1.0 + tol) {
                j += 1;
            }
            if j + 1 - i > best.1 {
                best = (i, j + 1 - i);
            }
        }
        let (i, n) = best;
        (n >= 3).then(|| {
            let w = &f[i..i + n];
            let forward_m = if n % 2 == 1 {
                w[n / 2]
            } else {
                (w[n / 2 - 1] + w[n / 2]) / 2.0
            };
            FaceFit {
                forward_m,
                rows: n,
                of: f.len(),
            }
        })
    }

    /// First-order ratio (a)/(c) for an object whose linear angle puts it at column `x`.
    pub fn eq16_bias(&self, x: f64) -> f64 {
        let w = self.width as f64;
        let psi = (x - (w - 1.0) / 2.0) * self.hfov_rad / w;
        2.0 * (self.hfov_rad / 2.0).tan() / (self.hfov_rad * (1.0 + psi.tan().powi(2)))
    }

    /// All three distances of a match whose box centre row is `v` (reference image).
    pub fn range(&self, m: &StereoMatch, v: f64, reference_left: bool) -> Option<StereoRange> {
        let (xl, xr) = if reference_left {
            (m.x_ref, m.x_other)
        } else {
            (m.x_other, m.x_ref)
        };
        let depth_bfd = self.depth_bfd(m.disparity)?;
        let a = self.depth_eq16(xl, xr);
        let b = self.depth_exact(xl, xr);
        let fwd = |z: Option<f64>| z.map(|z| self.forward_of_depth(z, m.x_ref, v).0);
        Some(StereoRange {
            disparity: m.disparity,
            depth_eq16: a,
            depth_exact: b,
            depth_bfd,
            forward_m: [fwd(a), fwd(b), fwd(Some(depth_bfd))],
            lateral_m: self.forward_of_depth(depth_bfd, m.x_ref, v).1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped camera (`[camera]`) with the shipped base.
    fn geo() -> StereoGeometry {
        StereoGeometry::ideal(&PinholeCamera::new(320, 240, 62.2, 0.20, 20.0), 0.06)
    }

    /// A point at depth Z and lateral X projects to x = c + f·X/Z in the left camera and
    /// c + f·(X − A)/Z in the right: (b) and (c) give Z back exactly, (a) within its bias.
    #[test]
    fn exact_angles_and_bfd_agree_and_eq16_is_biased_as_predicted() {
        let g = geo();
        for &(x, z) in &[(0.0, 1.0), (0.2, 0.8), (-0.3, 1.5), (0.03, 0.4)] {
            let xl = g.cx + g.f * x / z;
            let xr = g.cx + g.f * (x - g.base_m) / z;
            let b = g.depth_exact(xl, xr).unwrap();
            let c = g.depth_bfd(xl - xr).unwrap();
            assert!((b - z).abs() < 1e-9 && (c - z).abs() < 1e-9, "{b} {c} {z}");
            let a = g.depth_eq16(xl, xr).unwrap();
            let predicted = g.eq16_bias((xl + xr) / 2.0);
            assert!(
                (a / z - predicted).abs() < 0.01,
                "x {x} z {z}: (a)/true {} predicted {predicted}",
                a / z
            );
        }
        // On the axis the bias is 2 tan(ω/2)/ω: +11 % for 62.2°.
        let centre = g.eq16_bias(g.cx);
        assert!((centre - 1.1104).abs() < 0.002, "{centre}");
    }

    /// Rows of a vertical face 0.30 m ahead (disparity changing with the row) and of the
    /// box's top behind it (0.31..0.44 m): the face wins and its distance comes back.
    #[test]
    fn vertical_face_is_the_rows_that_agree() {
        let g = geo();
        let mut rows: Vec<RowMatch> = (112..185)
            .map(|v| RowMatch {
                row: v,
                disparity: g.disparity_of_forward(0.30, v as f64) + if v % 2 == 0 { 0.05 } else { -0.05 },
                score: 0.9,
            })
            .collect();
        for v in 85..112 {
            let f = 0.44 - (v - 85) as f64 * (0.13 / 27.0);
            rows.push(RowMatch {
                row: v,
                disparity: g.disparity_of_forward(f, v as f64),
                score: 0.9,
            });
        }
        let d_first = rows[0].disparity;
        let d_last = rows[72].disparity;
        assert!(
            d_first / d_last > 1.08,
            "the face's disparity changes along it: {d_first} {d_last}"
        );
        let fit = g.vertical_face(&rows, 0.03).unwrap();
        assert!((fit.forward_m - 0.30).abs() < 0.002, "{fit:?}");
        assert!(fit.rows >= 73 && fit.of == rows.len(), "{fit:?}");
        // The mean disparity at the middle row reads long (the top face pulls it).
        let mean = rows.iter().map(|r| r.disparity).sum::<f64>() / rows.len() as f64;
        let naive = g.forward_of_disparity(mean, (85.0 + 184.0) / 2.0).unwrap();
        assert!(naive > 0.31, "{naive}");
        assert!(g.vertical_face(&rows[..2], 0.03).is_none());
        for v in [20.0, 119.5, 200.0] {
            let d = g.disparity_of_forward(1.3, v);
            assert!((g.forward_of_disparity(d, v).unwrap() - 1.3).abs() < 1e-12);
        }
    }

    #[test]
    fn zero_disparity_has_no_distance() {
        let g = geo();
        assert!(g.depth_bfd(0.0).is_none());
        assert!(g.depth_exact(100.0, 100.0).is_none());
    }
}
