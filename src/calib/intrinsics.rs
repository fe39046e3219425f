//! One camera's intrinsics from views of a planar board (Zhang 2000, the method OpenCV's
//! `calibrateCamera` implements), with OpenCV's lens model (and [`CalibError`], why a
//! calibration of one camera or a pair fails):
//!
//! ```text
//! x' = X/Z, y' = Y/Z, r² = x'² + y'²
//! x'' = x'(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x'y' + p2 (r² + 2x'²)
//! y'' = y'(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y'²) + 2 p2 x'y'
//! u = fx x'' + cx,  v = fy y'' + cy            (pixels)
//! ```
//!
//! 1. A homography board → image per view (normalised DLT).
//! 2. Focal lengths in closed form with the principal point at the image centre (OpenCV's
//!    start, `cvInitIntrinsicParams2D`): r1 ⟂ r2 and |r1| = |r2| give two linear equations
//!    in 1/fx², 1/fy² per view.
//! 3. Each view's pose from its homography: r1, r2, t ∝ K⁻¹h1, K⁻¹h2, K⁻¹h3.
//! 4. Levenberg–Marquardt over fx, fy, cx, cy, k1, k2, p1, p2, k3 and every pose, minimising
//!    the reprojection error (pixels). RMS = √(Σ|e|² / points), as OpenCV reports it.

use super::lm::{minimize, view_blocks, LmOptions};
use nalgebra::{DMatrix, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// What can go wrong while calibrating.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// Too few views with a board to calibrate from.
    #[error("need at least {need} images with the board found, got {got}")]
    TooFewViews {
        /// Minimum number of views.
        need: usize,
        /// Views available.
        got: usize,
    },
    /// The views do not all have the same image size.
    #[error("image {name} is {got_w}x{got_h}, the first one is {want_w}x{want_h}")]
    SizeMismatch {
        /// The image that differs.
        name: String,
        /// Its width, pixels.
        got_w: u32,
        /// Its height, pixels.
        got_h: u32,
        /// Expected width.
        want_w: u32,
        /// Expected height.
        want_h: u32,
    },
    /// The left and right lists pair up differently.
    #[error("{left} left images but {right} right images: they must pair up one to one")]
    PairCount {
        /// Number of left images.
        left: usize,
        /// Number of right images.
        right: usize,
    },
    /// The closed-form start or the fit broke down (degenerate views, e.g. all fronto-parallel).
    #[error("calibration failed: {0}")]
    Degenerate(String),
}

/// Focal lengths and principal point, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// The 3×3 camera matrix K.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }
}

/// Lens distortion in OpenCV's order (k1, k2, p1, p2, k3): the model lives below the
/// calibration, in [`crate::lens`], so the lane warp and the simulator use it without
/// importing the calibration.
pub use crate::lens::Distortion;

/// A board's pose in a camera: X_cam = R(rvec)·X_board + t. `rvec` is a Rodrigues vector
/// (radians), `t` in the board's length unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Rotation as axis × angle, radians.
    pub rvec: [f64; 3],
    /// Translation.
    pub t: [f64; 3],
}

/// Rodrigues vector → rotation matrix.
pub fn rodrigues(r: [f64; 3]) -> Matrix3<f64> {
    let v = Vector3::from(r);
    let th = v.norm();
    if th < 1e-12 {
        // First order: I + [r]x
        return Matrix3::new(1.0, -r[2], r[1], r[2], 1.0, -r[0], -r[1], r[0], 1.0);
    }
    let k = v / th;
    let kx = Matrix3::new(0.0, -k[2], k[1], k[2], 0.0, -k[0], -k[1], k[0], 0.0);
    Matrix3::identity() + kx * th.sin() + kx * kx * (1.0 - th.cos())
}

/// Rotation matrix → Rodrigues vector (as OpenCV: first order near 0, the axis from R + I
/// near π).
pub fn rodrigues_inv(m: &Matrix3<f64>) -> [f64; 3] {
    let v = [m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]];
    let s = 0.5 * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let c = (0.5 * (m.trace() - 1.0)).clamp(-1.0, 1.0);
    if s < 1e-5 {
        if c > 0.0 {
            return [v[0] / 2.0, v[1] / 2.0, v[2] / 2.0];
        }
        // θ ≈ π: the axis is a column of (R + I)/2.
        let t = (m + Matrix3::identity()) * 0.5;
        let k = (0..3).max_by(|&a, &b| t[(a, a)].total_cmp(&t[(b, b)])).unwrap_or(0);
        let axis = t.column(k) / t[(k, k)].max(1e-300).sqrt();
        let a = axis.normalize() * std::f64::consts::PI;
        return [a[0], a[1], a[2]];
    }
    let th = s.atan2(c);
    let k = th / (2.0 * s);
    [v[0] * k, v[1] * k, v[2] * k]
}

/// Projects a point given in a board frame through `pose`, the lens and `k`; pixels.
pub fn project_point(k: &Intrinsics, d: &Distortion, pose: &Pose, p: [f64; 3]) -> (f64, f64) {
    project_with(k, d, &rodrigues(pose.rvec), &pose.t, p)
}

/// [`project_point`] with the rotation as a matrix (R·p + t, then the lens, then `k`); pixels.
pub(crate) fn project_with(k: &Intrinsics, d: &Distortion, r: &Matrix3<f64>, t: &[f64; 3], p: [f64; 3]) -> (f64, f64) {
    let x = r[(0, 0)] * p[0] + r[(0, 1)] * p[1] + r[(0, 2)] * p[2] + t[0];
    let y = r[(1, 0)] * p[0] + r[(1, 1)] * p[1] + r[(1, 2)] * p[2] + t[1];
    let z = r[(2, 0)] * p[0] + r[(2, 1)] * p[1] + r[(2, 2)] * p[2] + t[2];
    let (xd, yd) = d.distort(x / z, y / z);
    (k.fx * xd + k.cx, k.fy * yd + k.cy)
}

/// Homography H (3×3, h33 = 1) with image ≅ H·(X, Y, 1) from ≥ 4 planar correspondences
/// (normalised DLT: both point sets centred and scaled to mean distance √2).
pub fn homography(obj: &[[f64; 2]], img: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = obj.len();
    if n < 4 || img.len() != n {
        return None;
    }
    let norm = |pts: &[[f64; 2]]| -> Matrix3<f64> {
        let (mx, my) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]));
        let (mx, my) = (mx / n as f64, my / n as f64);
        let md = pts.iter().map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n as f64;
        let s = if md > 1e-12 { 2f64.sqrt() / md } else { 1.0 };
        Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
    };
    let (to, ti) = (norm(obj), norm(img));
    let mut a = DMatrix::<f64>::zeros(2 * n, 9);
    for k in 0..n {
        let o = to * Vector3::new(obj[k][0], obj[k][1], 1.0);
        let i = ti * Vector3::new(img[k][0], img[k][1], 1.0);
        let (x, y, u, v) = (o[0], o[1], i[0], i[1]);
        let r1 = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u];
        let r2 = [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, -v];
        for c in 0..9 {
            a[(2 * k, c)] = r1[c];
            a[(2 * k + 1, c)] = r2[c];
        }
    }
    // The null vector of A: the eigenvector of AᵀA with the smallest eigenvalue.
    let ata = a.tr_mul(&a);
    let eig = ata.symmetric_eigen();
    let (imin, _) = eig.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let hm = ti.try_inverse()? * hn * to;
    if hm[(2, 2)].abs() < 1e-300 {
        return None;
    }
    Some(hm / hm[(2, 2)])
}

/// A view's pose from its homography and K (step 3), before refinement.
pub fn pose_from_homography(h: &Matrix3<f64>, k: &Intrinsics) -> Option<Pose> {
    let ki = k.matrix().try_inverse()?;
    let h1 = ki * h.column(0);
    let h2 = ki * h.column(1);
    let h3 = ki * h.column(2);
    let mut lam = 1.0 / h1.norm();
    // The board is in front of the camera.
    if (h3 * lam)[2] < 0.0 {
        lam = -lam;
    }
    let r1 = h1 * lam;
    let r2 = h2 * lam;
    let r3 = r1.cross(&r2);
    let m = Matrix3::from_columns(&[r1, r2, r3]);
    // Nearest rotation (SVD).
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        r = -r;
    }
    let t = h3 * lam;
    Some(Pose {
        rvec: rodrigues_inv(&r),
        t: [t[0], t[1], t[2]],
    })
}

/// Refines one view's pose with the intrinsics fixed (a planar `solvePnP`).
pub fn refine_pose(k: &Intrinsics, d: &Distortion, obj: &[[f64; 3]], img: &[[f64; 2]], start: Pose) -> Pose {
    let mut p = [
        start.rvec[0],
        start.rvec[1],
        start.rvec[2],
        start.t[0],
        start.t[1],
        start.t[2],
    ];
    let m = 2 * obj.len();
    let f = |p: &[f64], out: &mut [f64]| {
        let r = rodrigues([p[0], p[1], p[2]]);
        let t = [p[3], p[4], p[5]];
        for (i, (o, im)) in obj.iter().zip(img).enumerate() {
            let (u, v) = project_with(k, d, &r, &t, *o);
            out[2 * i] = u - im[0];
            out[2 * i + 1] = v - im[1];
        }
    };
    minimize(
        &mut p,
        m,
        &f,
        &|_| 0..m,
        LmOptions {
            max_iter: 100,
            tol: 1e-14,
        },
    );
    Pose {
        rvec: [p[0], p[1], p[2]],
        t: [p[3], p[4], p[5]],
    }
}

/// The result of [`calibrate_camera`].
#[derive(Debug, Clone)]
pub struct CameraFit {
    /// Focal lengths and principal point.
    pub k: Intrinsics,
    /// Lens distortion.
    pub dist: Distortion,
    /// Each view's board pose.
    pub poses: Vec<Pose>,
    /// RMS reprojection error over all points, pixels.
    pub rms: f64,
    /// RMS reprojection error of each view, pixels.
    pub per_view_rms: Vec<f64>,
}

/// Zhang's closed-form focal lengths from the views' homographies `hs`, the principal
/// point taken at (`cx`, `cy`) (step 2 of the module doc).
fn focal_lengths(hs: &[Matrix3<f64>], cx: f64, cy: f64) -> Result<(f64, f64), CalibError> {
    let mut a = DMatrix::<f64>::zeros(2 * hs.len(), 2);
    let mut b = nalgebra::DVector::<f64>::zeros(2 * hs.len());
    for (i, h) in hs.iter().enumerate() {
        let sh = Matrix3::new(1.0, 0.0, -cx, 0.0, 1.0, -cy, 0.0, 0.0, 1.0) * h;
        let c1 = Vector3::new(sh[(0, 0)], sh[(1, 0)], sh[(2, 0)]);
        let c2 = Vector3::new(sh[(0, 1)], sh[(1, 1)], sh[(2, 1)]);
        let d1 = (c1 + c2) * 0.5;
        let d2 = (c1 - c2) * 0.5;
        let (c1, c2, d1, d2) = (c1.normalize(), c2.normalize(), d1.normalize(), d2.normalize());
        a[(2 * i, 0)] = c1[0] * c2[0];
        a[(2 * i, 1)] = c1[1] * c2[1];
        b[2 * i] = -c1[2] * c2[2];
        a[(2 * i + 1, 0)] = d1[0] * d2[0];
        a[(2 * i + 1, 1)] = d1[1] * d2[1];
        b[2 * i + 1] = -d1[2] * d2[2];
    }
    let sol = a
        .clone()
        .svd(true, true)
        .solve(&b, 1e-15)
        .map_err(|e| CalibError::Degenerate(e.to_string()))?;
    let (fx, fy) = ((1.0 / sol[0]).abs().sqrt(), (1.0 / sol[1]).abs().sqrt());
    if !(fx.is_finite() && fy.is_finite() && fx > 1.0 && fy > 1.0) {
        return Err(CalibError::Degenerate(
            "no focal length from the views (are they all parallel to the image?)".into(),
        ));
    }
    Ok((fx, fy))
}

/// The intrinsics and distortion held in the first 9 entries of the joint fit's parameters.
fn intrinsics_of(p: &[f64]) -> (Intrinsics, Distortion) {
    let k = Intrinsics {
        fx: p[0],
        fy: p[1],
        cx: p[2],
        cy: p[3],
    };
    (k, Distortion([p[4], p[5], p[6], p[7], p[8]]))
}

/// Calibrates one camera from `views` (each: board points with z = 0, and their image
/// points) of an image `width`×`height` (steps 1–4 of the module doc).
pub fn calibrate_camera(
    obj: &[[f64; 3]],
    views: &[Vec<[f64; 2]>],
    width: u32,
    height: u32,
) -> Result<CameraFit, CalibError> {
    if views.len() < 3 {
        return Err(CalibError::TooFewViews {
            need: 3,
            got: views.len(),
        });
    }
    let obj2: Vec<[f64; 2]> = obj.iter().map(|p| [p[0], p[1]]).collect();
    // 1. Homographies.
    let hs: Vec<Matrix3<f64>> = views
        .iter()
        .enumerate()
        .map(|(i, v)| homography(&obj2, v).ok_or_else(|| CalibError::Degenerate(format!("no homography for view {i}"))))
        .collect::<Result<_, _>>()?;
    // 2. Focal lengths with the principal point at the centre.
    let (cx, cy) = ((width as f64 - 1.0) * 0.5, (height as f64 - 1.0) * 0.5);
    let (fx, fy) = focal_lengths(&hs, cx, cy)?;
    let k0 = Intrinsics { fx, fy, cx, cy };
    // 3. Poses.
    let d0 = Distortion::default();
    let poses0: Vec<Pose> = hs
        .iter()
        .zip(views)
        .enumerate()
        .map(|(i, (h, v))| {
            let p =
                pose_from_homography(h, &k0).ok_or_else(|| CalibError::Degenerate(format!("no pose for view {i}")))?;
            Ok(refine_pose(&k0, &d0, obj, v, p))
        })
        .collect::<Result<_, CalibError>>()?;
    // 4. Joint refinement.
    let np = obj.len();
    let nv = views.len();
    let mut p = vec![k0.fx, k0.fy, k0.cx, k0.cy, 0.0, 0.0, 0.0, 0.0, 0.0];
    for ps in &poses0 {
        p.extend_from_slice(&ps.rvec);
        p.extend_from_slice(&ps.t);
    }
    let m = 2 * np * nv;
    let f = |p: &[f64], out: &mut [f64]| {
        let (k, d) = intrinsics_of(p);
        for (vi, v) in views.iter().enumerate() {
            let q = &p[9 + 6 * vi..15 + 6 * vi];
            let r = rodrigues([q[0], q[1], q[2]]);
            let t = [q[3], q[4], q[5]];
            for (i, (o, im)) in obj.iter().zip(v).enumerate() {
                let (u, w) = project_with(&k, &d, &r, &t, *o);
                out[2 * (vi * np + i)] = u - im[0];
                out[2 * (vi * np + i) + 1] = w - im[1];
            }
        }
    };
    let dep = view_blocks(9, 6, 2 * np, m);
    let res = minimize(
        &mut p,
        m,
        &f,
        &dep,
        LmOptions {
            max_iter: 300,
            tol: 1e-15,
        },
    );
    let (k, dist) = intrinsics_of(&p);
    let poses: Vec<Pose> = (0..nv)
        .map(|vi| {
            let q = &p[9 + 6 * vi..15 + 6 * vi];
            Pose {
                rvec: [q[0], q[1], q[2]],
                t: [q[3], q[4], q[5]],
            }
        })
        .collect();
    let mut r = vec![0.0; m];
    f(&p, &mut r);
    let per_view_rms = (0..nv)
        .map(|vi| (r[2 * np * vi..2 * np * (vi + 1)].iter().map(|e| e * e).sum::<f64>() / np as f64).sqrt())
        .collect();
    Ok(CameraFit {
        k,
        dist,
        poses,
        rms: (res.cost / (np * nv) as f64).sqrt(),
        per_view_rms,
    })
}

/// The inner corners of a `cols`×`rows` board with squares of `square` (length unit), in
/// OpenCV's order: row by row, x along a row, z = 0.
pub fn board_points(cols: usize, rows: usize, square: f64) -> Vec<[f64; 3]> {
    let mut v = Vec::with_capacity(cols * rows);
    for r in 0..rows {
        for c in 0..cols {
            v.push([c as f64 * square, r as f64 * square, 0.0]);
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn synth(k: &Intrinsics, d: &Distortion) -> (Vec<[f64; 3]>, Vec<Vec<[f64; 2]>>) {
        let obj = board_points(9, 6, 0.025);
        let mut views = vec![];
        for (i, (rx, ry)) in [
            (0.3, 0.1),
            (-0.25, 0.3),
            (0.1, -0.35),
            (0.4, 0.4),
            (-0.3, -0.2),
            (0.05, 0.25),
        ]
        .iter()
        .enumerate()
        {
            let pose = Pose {
                rvec: [*rx, *ry, 0.1 * i as f64],
                t: [-0.1 + 0.01 * i as f64, -0.06, 0.45 + 0.03 * i as f64],
            };
            views.push(
                obj.iter()
                    .map(|&p| {
                        let (u, v) = project_point(k, d, &pose, p);
                        [u, v]
                    })
                    .collect(),
            );
        }
        (obj, views)
    }

    #[test]
    fn rodrigues_round_trip() {
        for r in [[0.1, -0.2, 0.3], [1.0, 2.0, -0.5], [0.0, 0.0, 1e-9]] {
            let back = rodrigues_inv(&rodrigues(r));
            for k in 0..3 {
                assert!((back[k] - r[k]).abs() < 1e-9, "{r:?} {back:?}");
            }
        }
    }

    #[test]
    fn undistort_inverts_distort() {
        let d = Distortion([-0.28, 0.1, 0.001, -0.0005, -0.02]);
        for (x, y) in [(0.1, 0.2), (-0.4, 0.3), (0.5, -0.35)] {
            let (xd, yd) = d.distort(x, y);
            let (ux, uy) = d.undistort(xd, yd);
            assert!((ux - x).abs() < 1e-9 && (uy - y).abs() < 1e-9);
        }
    }

    /// Exact synthetic corners: the fit recovers the camera to 1e-6 and the RMS is ~0.
    #[test]
    fn recovers_a_synthetic_camera() {
        let k = Intrinsics {
            fx: 530.0,
            fy: 532.0,
            cx: 330.0,
            cy: 245.0,
        };
        let d = Distortion([-0.28, 0.09, 0.001, -0.0008, 0.0]);
        let (obj, views) = synth(&k, &d);
        let fit = calibrate_camera(&obj, &views, 640, 480).unwrap();
        assert!(
            (fit.k.fx - k.fx).abs() < 1e-4 && (fit.k.cy - k.cy).abs() < 1e-4,
            "{:?}",
            fit.k
        );
        assert!((fit.dist.0[0] - d.0[0]).abs() < 1e-5, "{:?}", fit.dist);
        assert!(fit.rms < 1e-6, "rms {}", fit.rms);
    }

    #[test]
    fn too_few_views_is_an_error() {
        let k = Intrinsics {
            fx: 530.0,
            fy: 532.0,
            cx: 330.0,
            cy: 245.0,
        };
        let (obj, views) = synth(&k, &Distortion::default());
        let e = calibrate_camera(&obj, &views[..1], 640, 480).unwrap_err();
        assert!(e.to_string().contains("at least 3"), "{e}");
    }
}
