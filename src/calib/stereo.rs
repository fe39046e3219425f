//! The stereo pair: R and T between the cameras (as `cv2.stereoCalibrate` with
//! `CALIB_FIX_INTRINSIC`), the rectifying rotations and new camera matrices (Bouguet's
//! method, as `cv2.stereoRectify` with `CALIB_ZERO_DISPARITY` and no scaling), and the
//! per-pixel maps that make a rectified pair (as `cv2.initUndistortRectifyMap` + `remap`).
//!
//! 1. Each view's board pose in both cameras (homography start, then refined with the
//!    intrinsics fixed); R_i = R_r,i·R_l,iᵀ, T_i = t_r,i − R_i·t_l,i; the start is the median.
//! 2. Levenberg–Marquardt over (R, T) and every left pose, minimising the reprojection error
//!    of both cameras; RMS = √(Σ|e|² / (2·points per camera)), as OpenCV reports it.
//! 3. Rectification: rotate each camera half of R's angle (r = rodrigues(−om/2)), then about
//!    the axis t × e_x so the baseline becomes the x axis: R1 = W·rᵀ, R2 = W·r. Both get
//!    f_new = (fy1 + fy2)/2 and the same principal point (the mean of the centres that keep
//!    each image's undistorted corners centred); P2's x translation is f_new·T'_x, so a point
//!    at depth Z has disparity d = −f_new·T'_x / Z (T'_x < 0 for a right camera on the right).

use super::intrinsics::{
    homography, pose_from_homography, refine_pose, rodrigues, rodrigues_inv, Distortion, Intrinsics, Pose,
};
use super::lm::{minimize, view_blocks, LmOptions};
use super::intrinsics::CalibError;
use image::{GrayImage, RgbImage};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// The result of [`stereo_calibrate`].
#[derive(Debug, Clone)]
pub struct StereoFit {
    /// Rotation left → right (X_r = R·X_l + T), row-major.
    pub r: Matrix3<f64>,
    /// Translation left → right, board length unit.
    pub t: Vector3<f64>,
    /// RMS reprojection error over both cameras, pixels.
    pub rms: f64,
    /// RMS of each view (both cameras), pixels.
    pub per_view_rms: Vec<f64>,
}

fn project(k: &Intrinsics, d: &Distortion, r: &Matrix3<f64>, t: &Vector3<f64>, p: &[f64; 3]) -> (f64, f64) {
    super::intrinsics::project_with(k, d, r, &[t[0], t[1], t[2]], *p)
}

fn start_pose(
    k: &Intrinsics,
    d: &Distortion,
    obj: &[[f64; 3]],
    img: &[[f64; 2]],
    view: usize,
) -> Result<Pose, CalibError> {
    let obj2: Vec<[f64; 2]> = obj.iter().map(|p| [p[0], p[1]]).collect();
    // Undistort the image points first, so the homography is that of a pinhole.
    let und: Vec<[f64; 2]> = img
        .iter()
        .map(|p| {
            let (x, y) = d.undistort((p[0] - k.cx) / k.fx, (p[1] - k.cy) / k.fy);
            [k.fx * x + k.cx, k.fy * y + k.cy]
        })
        .collect();
    let h = homography(&obj2, &und).ok_or_else(|| CalibError::Degenerate(format!("no homography for view {view}")))?;
    let p = pose_from_homography(&h, k).ok_or_else(|| CalibError::Degenerate(format!("no pose for view {view}")))?;
    Ok(refine_pose(k, d, obj, img, p))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Fits R and T with both cameras' intrinsics fixed (steps 1–2).
#[allow(clippy::too_many_arguments)]
pub fn stereo_calibrate(
    obj: &[[f64; 3]],
    left: &[Vec<[f64; 2]>],
    right: &[Vec<[f64; 2]>],
    kl: &Intrinsics,
    dl: &Distortion,
    kr: &Intrinsics,
    dr: &Distortion,
) -> Result<StereoFit, CalibError> {
    if left.len() != right.len() {
        return Err(CalibError::PairCount {
            left: left.len(),
            right: right.len(),
        });
    }
    if left.is_empty() {
        return Err(CalibError::TooFewViews { need: 1, got: 0 });
    }
    let nv = left.len();
    let np = obj.len();
    // 1. Per-view poses and the median relative pose.
    let mut pl = vec![];
    let (mut oms, mut ts) = (vec![vec![]; 3], vec![vec![]; 3]);
    for i in 0..nv {
        let a = start_pose(kl, dl, obj, &left[i], i)?;
        let b = start_pose(kr, dr, obj, &right[i], i)?;
        let (ra, rb) = (rodrigues(a.rvec), rodrigues(b.rvec));
        let r = rb * ra.transpose();
        let t = Vector3::from(b.t) - r * Vector3::from(a.t);
        let om = rodrigues_inv(&r);
        for k in 0..3 {
            oms[k].push(om[k]);
            ts[k].push(t[k]);
        }
        pl.push(a);
    }
    let mut p: Vec<f64> = (0..3).map(|k| median(oms[k].clone())).collect();
    p.extend((0..3).map(|k| median(ts[k].clone())));
    for a in &pl {
        p.extend_from_slice(&a.rvec);
        p.extend_from_slice(&a.t);
    }
    // 2. Joint refinement: residuals of view i are [left points, right points].
    let m = 4 * np * nv;
    let f = |p: &[f64], out: &mut [f64]| {
        let r = rodrigues([p[0], p[1], p[2]]);
        let t = Vector3::new(p[3], p[4], p[5]);
        for vi in 0..nv {
            let q = &p[6 + 6 * vi..12 + 6 * vi];
            let ra = rodrigues([q[0], q[1], q[2]]);
            let ta = Vector3::new(q[3], q[4], q[5]);
            let rb = r * ra;
            let tb = r * ta + t;
            let base = 4 * np * vi;
            for (i, o) in obj.iter().enumerate() {
                let (u, v) = project(kl, dl, &ra, &ta, o);
                out[base + 2 * i] = u - left[vi][i][0];
                out[base + 2 * i + 1] = v - left[vi][i][1];
                let (u, v) = project(kr, dr, &rb, &tb, o);
                out[base + 2 * np + 2 * i] = u - right[vi][i][0];
                out[base + 2 * np + 2 * i + 1] = v - right[vi][i][1];
            }
        }
    };
    let dep = view_blocks(6, 6, 4 * np, m);
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
    let mut r = vec![0.0; m];
    f(&p, &mut r);
    let per_view_rms = (0..nv)
        .map(|vi| (r[4 * np * vi..4 * np * (vi + 1)].iter().map(|e| e * e).sum::<f64>() / (2 * np) as f64).sqrt())
        .collect();
    Ok(StereoFit {
        r: rodrigues([p[0], p[1], p[2]]),
        t: Vector3::new(p[3], p[4], p[5]),
        rms: (res.cost / (2 * np * nv) as f64).sqrt(),
        per_view_rms,
    })
}

/// Rectifying rotations and projections of a pair (step 3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rectification {
    /// Rotation of the left camera into the rectified frame, row-major.
    pub r1: [[f64; 3]; 3],
    /// Rotation of the right camera into the rectified frame, row-major.
    pub r2: [[f64; 3]; 3],
    /// Focal length of both rectified images, pixels.
    pub f: f64,
    /// Principal point of both rectified images (column, row), pixels.
    pub c: [f64; 2],
    /// Baseline in the rectified frame: x of the right camera's P2 translation divided by f
    /// (negative when the right camera is to the right), board length unit.
    pub tx: f64,
}

/// Matrix to rows (the file's row-major form).
pub fn to_rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
    ]
}

/// Matrix from rows.
pub fn from_rows(m: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::new(
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
    )
}

/// Bouguet's rectification (step 3) for images of `width`×`height`.
#[allow(clippy::too_many_arguments)]
pub fn stereo_rectify(
    kl: &Intrinsics,
    dl: &Distortion,
    kr: &Intrinsics,
    dr: &Distortion,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    width: u32,
    height: u32,
) -> Rectification {
    let om = rodrigues_inv(r);
    let rr = rodrigues([-0.5 * om[0], -0.5 * om[1], -0.5 * om[2]]);
    let tt = rr * t;
    let idx = if tt[0].abs() > tt[1].abs() { 0 } else { 1 };
    let c = tt[idx];
    let nt = tt.norm();
    let mut uu = Vector3::zeros();
    uu[idx] = if c > 0.0 { 1.0 } else { -1.0 };
    let mut ww = tt.cross(&uu);
    let nw = ww.norm();
    if nw > 0.0 {
        ww *= (c.abs() / nt).clamp(-1.0, 1.0).acos() / nw;
    }
    let wr = rodrigues([ww[0], ww[1], ww[2]]);
    let r1 = wr * rr.transpose();
    let r2 = wr * rr;
    let t2 = r2 * t;
    let f = if idx == 0 {
        0.5 * (kl.fy + kr.fy)
    } else {
        0.5 * (kl.fx + kr.fx)
    };
    let (nx, ny) = (width as f64, height as f64);
    let mut cc = [[0.0; 2]; 2];
    for (k, (kk, dd, rk)) in [(kl, dl, &r1), (kr, dr, &r2)].into_iter().enumerate() {
        let mut avg = [0.0; 2];
        for i in 0..4 {
            let (px, py) = ((i % 2) as f64 * (nx - 1.0), (i / 2) as f64 * (ny - 1.0));
            let (x, y) = dd.undistort((px - kk.cx) / kk.fx, (py - kk.cy) / kk.fy);
            let q = rk * Vector3::new(x, y, 1.0);
            avg[0] += f * q[0] / q[2] / 4.0;
            avg[1] += f * q[1] / q[2] / 4.0;
        }
        cc[k] = [(nx - 1.0) / 2.0 - avg[0], (ny - 1.0) / 2.0 - avg[1]];
    }
    let c = [(cc[0][0] + cc[1][0]) * 0.5, (cc[0][1] + cc[1][1]) * 0.5];
    Rectification {
        r1: to_rows(&r1),
        r2: to_rows(&r2),
        f,
        c,
        tx: t2[idx],
    }
}

/// Per-pixel source coordinates of a rectified image (OpenCV's `initUndistortRectifyMap`).
#[derive(Debug, Clone, PartialEq)]
pub struct RectifyMaps {
    /// Width of the rectified image, pixels.
    pub width: u32,
    /// Height of the rectified image, pixels.
    pub height: u32,
    /// Source column of each rectified pixel (row-major).
    pub map_x: Vec<f32>,
    /// Source row of each rectified pixel.
    pub map_y: Vec<f32>,
}

impl RectifyMaps {
    /// Maps for one camera: rectified pixel → ray (f, c) → Rᵀ → distortion → K.
    pub fn new(
        k: &Intrinsics,
        d: &Distortion,
        r: &[[f64; 3]; 3],
        f: f64,
        c: [f64; 2],
        width: u32,
        height: u32,
    ) -> Self {
        let rt = from_rows(r).transpose();
        let n = (width * height) as usize;
        let (mut map_x, mut map_y) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for v in 0..height {
            for u in 0..width {
                let q = rt * Vector3::new((u as f64 - c[0]) / f, (v as f64 - c[1]) / f, 1.0);
                let (xd, yd) = d.distort(q[0] / q[2], q[1] / q[2]);
                map_x.push((k.fx * xd + k.cx) as f32);
                map_y.push((k.fy * yd + k.cy) as f32);
            }
        }
        RectifyMaps {
            width,
            height,
            map_x,
            map_y,
        }
    }

    /// Bilinear remap of a grey image (outside pixels become 0, as OpenCV's constant border).
    pub fn remap_gray(&self, src: &GrayImage, dst: &mut GrayImage) {
        if dst.dimensions() != (self.width, self.height) {
            *dst = GrayImage::new(self.width, self.height);
        }
        self.remap::<1>(src.as_raw(), src.width(), src.height(), dst);
    }

    /// Bilinear remap of a colour image, each channel as [`RectifyMaps::remap_gray`] does it.
    pub fn remap_rgb(&self, src: &RgbImage, dst: &mut RgbImage) {
        if dst.dimensions() != (self.width, self.height) {
            *dst = RgbImage::new(self.width, self.height);
        }
        self.remap::<3>(src.as_raw(), src.width(), src.height(), dst);
    }

    /// The remap of interleaved `C`-channel pixels: each output pixel is the bilinear blend
    /// of the four source pixels around (map_x, map_y), a source pixel outside the image 0.
    fn remap<const C: usize>(&self, s: &[u8], sw: u32, sh: u32, out: &mut [u8]) {
        let (sw, sh) = (sw as i64, sh as i64);
        let px = |x: i64, y: i64, ch: usize| -> f32 {
            if x < 0 || y < 0 || x >= sw || y >= sh {
                0.0
            } else {
                s[(y * sw + x) as usize * C + ch] as f32
            }
        };
        for (i, o) in out.chunks_exact_mut(C).enumerate() {
            let (x, y) = (self.map_x[i], self.map_y[i]);
            let (x0, y0) = (x.floor(), y.floor());
            let (ax, ay) = (x - x0, y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            for (ch, o) in o.iter_mut().enumerate() {
                let a = px(x0, y0, ch) * (1.0 - ax) + px(x0 + 1, y0, ch) * ax;
                let b = px(x0, y0 + 1, ch) * (1.0 - ax) + px(x0 + 1, y0 + 1, ch) * ax;
                *o = (a * (1.0 - ay) + b * ay).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

/// [`RectifyMaps`] in fixed point, for remapping every frame: OpenCV's `remap` recipe
/// (INTER_LINEAR): each map position rounded to 1/32 pixel (`INTER_BITS` = 5), the four
/// bilinear weights of that fraction in 15-bit integers summing to exactly 32768, the output
/// (Σ w·p + 2¹⁴) >> 15. One source offset and one fraction per output pixel are stored, so
/// the loop is four loads and multiply-adds per channel; pixels whose 2×2 neighbourhood
/// leaves the source image take the slow path with 0 outside (a constant border).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedMaps {
    width: u32,
    height: u32,
    src_w: u32,
    src_h: u32,
    /// Byte offset in the source (3 bytes a pixel) of each output pixel's top-left
    /// neighbour; `u32::MAX` for a pixel on the border path.
    off: Vec<u32>,
    /// Fraction index fy·32 + fx of each output pixel.
    frac: Vec<u16>,
    /// Border pixels: (output index, source x, source y of the top-left neighbour).
    border: Vec<(u32, i32, i32)>,
    /// The four weights of each of the 32×32 fractions.
    wtab: Vec<[i32; 4]>,
}

impl FixedMaps {
    /// Fixed-point maps of `m` for colour source images of `src_w`×`src_h`.
    pub fn new(m: &RectifyMaps, src_w: u32, src_h: u32) -> Self {
        const TAB: i32 = 32;
        let n = m.map_x.len();
        let (mut off, mut frac, mut border) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::new());
        for (i, (&x, &y)) in m.map_x.iter().zip(&m.map_y).enumerate() {
            // Far outside (or NaN): a pixel that reads only the border.
            let (ix, iy) = if x.is_finite() && y.is_finite() && x.abs() < 1e6 && y.abs() < 1e6 {
                ((x * TAB as f32).round() as i32, (y * TAB as f32).round() as i32)
            } else {
                (-2 * TAB, -2 * TAB)
            };
            let (xi, yi) = (ix >> 5, iy >> 5);
            frac.push((((iy & (TAB - 1)) * TAB) + (ix & (TAB - 1))) as u16);
            if xi >= 0 && yi >= 0 && xi + 1 < src_w as i32 && yi + 1 < src_h as i32 {
                off.push(3 * (yi as u32 * src_w + xi as u32));
            } else {
                off.push(u32::MAX);
                border.push((i as u32, xi, yi));
            }
        }
        let mut wtab = Vec::with_capacity((TAB * TAB) as usize);
        for fy in 0..TAB {
            for fx in 0..TAB {
                let (ax, ay) = (fx as f64 / TAB as f64, fy as f64 / TAB as f64);
                let w = [(1.0 - ax) * (1.0 - ay), ax * (1.0 - ay), (1.0 - ax) * ay, ax * ay];
                let mut q = w.map(|v| (v * 32768.0).round() as i32);
                // Make them sum to exactly 32768 (as OpenCV does): fix the largest.
                let sum: i32 = q.iter().sum();
                let big = (0..4).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
                q[big] += 32768 - sum;
                wtab.push(q);
            }
        }
        FixedMaps {
            width: m.width,
            height: m.height,
            src_w,
            src_h,
            off,
            frac,
            border,
            wtab,
        }
    }

    /// Remaps a colour image into `dst`; `false` (and `dst` untouched) when the image is not
    /// of the size the maps were made for.
    pub fn remap_rgb(&self, src: &RgbImage, dst: &mut RgbImage) -> bool {
        self.remap_rgb_rows(src, dst, 0..self.height)
    }

    /// [`FixedMaps::remap_rgb`] for the output rows `rows` only (clipped to the image); the
    /// other rows of `dst` keep what they held. The drive loop rectifies only the rows its
    /// boxes are matched on (a sign's box is a tenth of the frame's rows).
    pub fn remap_rgb_rows(&self, src: &RgbImage, dst: &mut RgbImage, rows: std::ops::Range<u32>) -> bool {
        if src.dimensions() != (self.src_w, self.src_h) {
            return false;
        }
        if dst.dimensions() != (self.width, self.height) {
            *dst = RgbImage::new(self.width, self.height);
        }
        let width = self.width as usize;
        let (r0, r1) = (rows.start.min(self.height) as usize, rows.end.min(self.height) as usize);
        if r0 >= r1 {
            return true;
        }
        let (i0, i1) = (r0 * width, r1 * width);
        let s = src.as_raw();
        let row = 3 * self.src_w as usize;
        let blend = |v: i32| ((v + (1 << 14)) >> 15).clamp(0, 255) as u8;
        let out: &mut [u8] = &mut (**dst)[3 * i0..3 * i1];
        for (o, (&off, &fr)) in out.chunks_exact_mut(3).zip(self.off[i0..i1].iter().zip(&self.frac[i0..i1])) {
            if off == u32::MAX {
                continue;
            }
            let w = &self.wtab[fr as usize];
            let p = &s[off as usize..off as usize + row + 6];
            let (a, b) = (&p[..6], &p[row..row + 6]);
            for c in 0..3 {
                o[c] = blend(a[c] as i32 * w[0] + a[3 + c] as i32 * w[1] + b[c] as i32 * w[2] + b[3 + c] as i32 * w[3]);
            }
        }
        let (sw, sh) = (self.src_w as i32, self.src_h as i32);
        let px = |x: i32, y: i32, c: usize| -> i32 {
            if x < 0 || y < 0 || x >= sw || y >= sh {
                0
            } else {
                s[3 * (y as usize * sw as usize + x as usize) + c] as i32
            }
        };
        let out: &mut [u8] = dst;
        // `border` is in output order: the entries of these rows are one run of it.
        let (b0, b1) = (
            self.border.partition_point(|b| (b.0 as usize) < i0),
            self.border.partition_point(|b| (b.0 as usize) < i1),
        );
        for &(i, x, y) in &self.border[b0..b1] {
            let w = &self.wtab[self.frac[i as usize] as usize];
            for c in 0..3 {
                let v = px(x, y, c) * w[0] + px(x + 1, y, c) * w[1] + px(x, y + 1, c) * w[2] + px(x + 1, y + 1, c) * w[3];
                out[3 * i as usize + c] = blend(v);
            }
        }
        true
    }
}

/// Where the raw pixel (u, v) of a camera (`k`, `d`) lands in its rectified image (rotation
/// `r` into the rectified frame, focal length `f`, principal point `c`): the inverse of the
/// per-pixel map of [`RectifyMaps::new`] (undistort → R → project). `None` behind the camera.
pub fn rectified_point(
    k: &Intrinsics,
    d: &Distortion,
    r: &[[f64; 3]; 3],
    f: f64,
    c: [f64; 2],
    u: f64,
    v: f64,
) -> Option<(f64, f64)> {
    let (x, y) = d.undistort((u - k.cx) / k.fx, (v - k.cy) / k.fy);
    let q = from_rows(r) * Vector3::new(x, y, 1.0);
    (q[2] > 1e-9).then(|| (f * q[0] / q[2] + c[0], f * q[1] / q[2] + c[1]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::intrinsics::{board_points, project_point};

    /// A synthetic rig: 6 cm baseline, small rotation; the fit recovers R and T exactly, and
    /// rectification puts corresponding points on the same row.
    #[test]
    fn recovers_a_synthetic_rig_and_rectifies_rows() {
        let kl = Intrinsics {
            fx: 530.0,
            fy: 531.0,
            cx: 322.0,
            cy: 241.0,
        };
        let kr = Intrinsics {
            fx: 528.0,
            fy: 529.0,
            cx: 318.0,
            cy: 239.0,
        };
        let dl = Distortion([-0.2, 0.05, 0.0, 0.0, 0.0]);
        let dr = Distortion([-0.21, 0.06, 0.0, 0.0, 0.0]);
        let r = rodrigues([0.01, -0.02, 0.005]);
        let t = Vector3::new(-0.06, 0.001, 0.002);
        let obj = board_points(9, 6, 0.025);
        let (mut left, mut right) = (vec![], vec![]);
        for i in 0..5 {
            let a = Pose {
                rvec: [0.2 - 0.1 * i as f64, 0.3 * (i as f64 - 2.0) / 2.0, 0.05],
                t: [-0.1, -0.06, 0.5 + 0.05 * i as f64],
            };
            let ra = rodrigues(a.rvec);
            let rb = r * ra;
            let tb = r * Vector3::from(a.t) + t;
            let b = Pose {
                rvec: rodrigues_inv(&rb),
                t: [tb[0], tb[1], tb[2]],
            };
            left.push(
                obj.iter()
                    .map(|&p| {
                        let (u, v) = project_point(&kl, &dl, &a, p);
                        [u, v]
                    })
                    .collect::<Vec<_>>(),
            );
            right.push(
                obj.iter()
                    .map(|&p| {
                        let (u, v) = project_point(&kr, &dr, &b, p);
                        [u, v]
                    })
                    .collect::<Vec<_>>(),
            );
        }
        let fit = stereo_calibrate(&obj, &left, &right, &kl, &dl, &kr, &dr).unwrap();
        assert!((fit.t - t).norm() < 1e-7, "{:?}", fit.t);
        assert!(fit.rms < 1e-6);
        let rect = stereo_rectify(&kl, &dl, &kr, &dr, &fit.r, &fit.t, 640, 480);
        assert!((rect.tx.abs() - t.norm()).abs() < 1e-6, "{}", rect.tx);
        // A 3-D point in the left frame lands on the same rectified row in both.
        let (r1, r2) = (from_rows(&rect.r1), from_rows(&rect.r2));
        for p in [Vector3::new(0.1, 0.05, 0.8), Vector3::new(-0.2, -0.1, 1.5)] {
            let a = r1 * p;
            let b = r2 * (r * p + t);
            let (ya, yb) = (rect.f * a[1] / a[2], rect.f * b[1] / b[2]);
            assert!((ya - yb).abs() < 1e-9);
            let disp = rect.f * a[0] / a[2] - rect.f * b[0] / b[2];
            assert!((disp - rect.f * -rect.tx / a[2]).abs() < 1e-9);
        }
    }
}
