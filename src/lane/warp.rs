//! Region of interest and bird's-eye view (Rivera & Andaluz 2021, Sec. 3.2 ii: "Region of
//! interest (ROI) and Bird's eye view", done there with OpenCV's `warpPerspective`).
//!
//! 1. A homography `H` maps the ROI's four corners in the camera frame onto the corners of the
//!    bird's-eye image; it is found by solving the 8×8 linear system of the direct linear
//!    transform with `h33 = 1` (nalgebra's LU).
//! 2. Sampling runs the other way: each bird's-eye pixel asks which camera pixel it came
//!    from, `H⁻¹ (x, y, 1)`. That answer never changes for a given config, so [`WarpMap`]
//!    computes it once, in OpenCV's fixed point (1/32 pixel; bilinear weights in 1/32768), and
//!    a frame then costs one table walk.
//! 3. [`WarpMap::warp_gray`] fuses the bilinear sample of R, G and B with the grey conversion
//!    (`Y = (9798 R + 19235 G + 3735 B + 2^14) >> 15`, OpenCV's integer BT.601), so the
//!    colour bird's-eye image is never stored.
//!
//! 4. A wide-angle lens bends straight tape into curves. [`WarpMap::with_lens`] folds the lens
//!    model that `rccar calibrate camera` measures into the same table: OpenCV's
//!    radial–tangential model ([`crate::lens`]), on normalised ideal coordinates
//!    x = (u − cx)/fx, y = (v − cy)/fy (ideal pinhole), r² = x² + y²,
//!    x_d = x(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²),
//!    y_d = y(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y,
//!    u_d = fx x_d + cx, v_d = fy y_d + cy (real pinhole). The homography gives each bird's-eye pixel its
//!    ideal (undistorted) camera pixel, the model where that ray lands in the real frame, and
//!    the table samples there: undistortion costs nothing per frame, and the ROI and the
//!    homography stay in the ideal image (the one `rccar config roi` computes). With all
//!    coefficients zero the table is the one without a lens, bit for bit.
//!
//! Units: pixels everywhere. Pixel (i, j) has its centre at (i, j) (OpenCV's convention); the
//! ROI corners map onto the centres of the bird's-eye image's corner pixels.

use crate::camera::PinholeCamera;
use crate::lens::Lens;
use image::{GrayImage, RgbImage};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Why four points cannot define a bird's-eye view.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WarpError {
    /// Three of the four corners lie on one line (or two coincide).
    #[error("corners {0}, {1} and {2} are collinear: the ROI must be a proper quadrilateral")]
    Collinear(usize, usize, usize),
    /// The corners are not in order (the quadrilateral crosses itself or is not convex).
    #[error(
        "the corners do not form a convex quadrilateral in the order top-left, top-right, bottom-right, bottom-left"
    )]
    NotConvex,
    /// A coordinate is NaN or infinite.
    #[error("a corner is not a finite number")]
    NotFinite,
    /// The linear system is singular.
    #[error("the homography is singular")]
    Singular,
}

/// A plane-to-plane projective map, `p' ~ H p`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography(pub Matrix3<f64>);

impl Homography {
    /// The homography taking `src[k]` to `dst[k]` for k = 0..4 (direct linear transform).
    pub fn from_points(src: &[[f64; 2]; 4], dst: &[[f64; 2]; 4]) -> Result<Self, WarpError> {
        check_quad(src)?;
        check_quad(dst)?;
        // Each pair gives two rows of A h = b, h = (h11 .. h32), h33 = 1:
        //   x' = (h11 x + h12 y + h13) / (h31 x + h32 y + 1), likewise y'.
        let mut a = SMatrix::<f64, 8, 8>::zeros();
        let mut b = SVector::<f64, 8>::zeros();
        for k in 0..4 {
            let [x, y] = src[k];
            let [u, v] = dst[k];
            let r = 2 * k;
            a.row_mut(r)
                .copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y]);
            a.row_mut(r + 1)
                .copy_from_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y]);
            b[r] = u;
            b[r + 1] = v;
        }
        let h = a.lu().solve(&b).ok_or(WarpError::Singular)?;
        if h.iter().any(|v| !v.is_finite()) {
            return Err(WarpError::Singular);
        }
        Ok(Self(Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0)))
    }

    /// The homography from a camera-frame ROI onto a `width`×`height` bird's-eye image.
    pub fn from_quad_to_rect(src: &[[f64; 2]; 4], width: u32, height: u32) -> Result<Self, WarpError> {
        Self::from_points(src, &rect_corners(width, height))
    }

    /// Applies the map to a point; `None` where it goes to infinity.
    pub fn apply(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let p = self.0 * Vector3::new(x, y, 1.0);
        (p.z.abs() > 1e-12).then(|| (p.x / p.z, p.y / p.z))
    }

    /// The inverse map.
    pub fn inverse(&self) -> Option<Self> {
        self.0.try_inverse().map(|m| Self(m / m[(2, 2)]))
    }
}

/// The map from bird's-eye pixels to the floor seen by camera `cam`: a bird's-eye image
/// `out_w`×`out_h` made from the ROI `roi` (camera pixels, `[warp] src` order) shows the floor
/// point `(x forward, y left)`, metres from the floor point below the lens, at pixel `(u, v)`
/// where `H (u, v) = (x, y)`. Camera pixel → floor is a homography of the plane, and so is the
/// warp, so one homography through the four corners is exact for any ROI. `None` when a
/// corner does not see the floor (at or above the horizon) or the corners are degenerate.
pub fn bird_to_floor(cam: &PinholeCamera, roi: &[[f64; 2]; 4], out_w: u32, out_h: u32) -> Option<Homography> {
    let mut floor = [[0.0; 2]; 4];
    for (f, c) in floor.iter_mut().zip(roi) {
        let (x, y) = cam.ground_of_pixel(c[0], c[1])?;
        *f = [x, y];
    }
    Homography::from_points(&rect_corners(out_w, out_h), &floor).ok()
}

/// The corners of a `width`×`height` image's corner pixel centres, in ROI order.
pub fn rect_corners(width: u32, height: u32) -> [[f64; 2]; 4] {
    let (w, h) = (width as f64 - 1.0, height as f64 - 1.0);
    [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]
}

fn check_quad(p: &[[f64; 2]; 4]) -> Result<(), WarpError> {
    if p.iter().flatten().any(|v| !v.is_finite()) {
        return Err(WarpError::NotFinite);
    }
    let cross = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let scale = p.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
    for (i, j, k) in [(0, 1, 2), (1, 2, 3), (2, 3, 0), (3, 0, 1)] {
        if cross(p[i], p[j], p[k]).abs() <= 1e-9 * scale * scale {
            let mut t = [i, j, k];
            t.sort_unstable();
            return Err(WarpError::Collinear(t[0], t[1], t[2]));
        }
    }
    let signs: Vec<bool> = (0..4)
        .map(|i| cross(p[i], p[(i + 1) % 4], p[(i + 2) % 4]) > 0.0)
        .collect();
    if signs.iter().any(|&s| s != signs[0]) {
        return Err(WarpError::NotConvex);
    }
    Ok(())
}

/// Sub-pixel resolution of the map, as OpenCV's `INTER_BITS`: 1/32 pixel.
const INTER_BITS: u32 = 5;
const INTER_TAB: i32 = 1 << INTER_BITS;
/// Fixed-point scale of the bilinear weights, as OpenCV's `INTER_REMAP_COEF_BITS`.
const COEF_BITS: u32 = 15;

/// The bilinear weights for each of the 32×32 sub-pixel positions, in 1/32768, rounded so
/// that each set sums to exactly 32768 (as OpenCV's `initInterTab2D`).
fn bilinear_table() -> Vec<[i32; 4]> {
    let scale = (1 << COEF_BITS) as f32;
    let mut tab = Vec::with_capacity((INTER_TAB * INTER_TAB) as usize);
    for iy in 0..INTER_TAB {
        for ix in 0..INTER_TAB {
            let (fx, fy) = (ix as f32 / INTER_TAB as f32, iy as f32 / INTER_TAB as f32);
            let f = [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy];
            let mut w = [0i32; 4];
            let mut sum = 0;
            for k in 0..4 {
                w[k] = (f[k] * scale).round_ties_even() as i32;
                sum += w[k];
            }
            // Give the rounding remainder to the largest weight (OpenCV does the same).
            if sum != 1 << COEF_BITS {
                let kmax = (0..4)
                    .max_by(|&a, &b| f[a].total_cmp(&f[b]).then(b.cmp(&a)))
                    .unwrap_or(0);
                w[kmax] += (1 << COEF_BITS) - sum;
            }
            tab.push(w);
        }
    }
    tab
}

/// One bird's-eye pixel whose taps fall partly outside the camera frame.
#[derive(Debug, Clone, Copy)]
struct EdgeTap {
    dst: u32,
    /// Pixel index of each tap in the source, or `u32::MAX` when outside (reads as 0).
    src: [u32; 4],
    w: [i32; 4],
}

/// The bird's-eye warp, precomputed for one camera size and one ROI.
#[derive(Debug, Clone)]
pub struct WarpMap {
    src_w: u32,
    src_h: u32,
    out_w: u32,
    out_h: u32,
    /// For each bird's-eye pixel: index of the top-left tap in the source (0 for pixels
    /// handled by `edges` or entirely outside; their weights are then zero).
    offset: Vec<u32>,
    /// For each bird's-eye pixel: the four bilinear weights (1/32768, so 32768 = 1 needs u16;
    /// all zero when outside).
    weight: Vec<[u16; 4]>,
    edges: Vec<EdgeTap>,
    homography: Homography,
    /// Source rows any tap reads (`first..end`): only these need converting to grey.
    src_rows: std::ops::Range<u32>,
}

impl WarpMap {
    /// Builds the map for `src_w`×`src_h` camera frames and the ROI `roi` (top-left,
    /// top-right, bottom-right, bottom-left) onto an `out_w`×`out_h` bird's-eye image.
    pub fn new(src_w: u32, src_h: u32, roi: &[[f64; 2]; 4], out_w: u32, out_h: u32) -> Result<Self, WarpError> {
        Self::with_lens(src_w, src_h, roi, out_w, out_h, None)
    }

    /// [`WarpMap::new`] for a camera whose lens bends the image: `roi` is then in the ideal
    /// (undistorted) image of `lens`'s pinhole, and each bird's-eye pixel samples the real
    /// frame where its ray lands (`lens.distort_pixel` of the homography's ideal pixel).
    /// Undistortion and warp are one table, so a frame costs what it did without a lens. A
    /// lens without distortion (or `None`) gives exactly the map of [`WarpMap::new`].
    pub fn with_lens(
        src_w: u32,
        src_h: u32,
        roi: &[[f64; 2]; 4],
        out_w: u32,
        out_h: u32,
        lens: Option<&Lens>,
    ) -> Result<Self, WarpError> {
        let lens = lens.filter(|l| !l.distortion.is_zero());
        let homography = Homography::from_quad_to_rect(roi, out_w, out_h)?;
        let inv = homography.inverse().ok_or(WarpError::Singular)?.0;
        let tab = bilinear_table();
        let n = (out_w * out_h) as usize;
        let mut offset = vec![0u32; n];
        let mut weight = vec![[0u16; 4]; n];
        let mut edges = Vec::new();
        let (sw, sh) = (src_w as i64, src_h as i64);
        let m = inv.as_slice(); // column-major
        let (m0, m1, m2, m3, m4, m5, m6, m7, m8) = (m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8]);
        for y in 0..out_h {
            // 1. The source position of each bird's-eye pixel, in 1/32 pixel, as OpenCV's
            //    WarpPerspectiveInvoker computes it.
            let (x0, y0, w0) = (m1 * y as f64 + m2, m4 * y as f64 + m5, m7 * y as f64 + m8);
            for x in 0..out_w {
                let xf = x as f64;
                let w = w0 + m6 * xf;
                let w = if w != 0.0 { INTER_TAB as f64 / w } else { 0.0 };
                let (mut fx, mut fy) = ((x0 + m0 * xf) * w, (y0 + m3 * xf) * w);
                if let Some(l) = lens {
                    // The ideal pixel's ray lands here in the real, distorted frame.
                    let (u, v) = l.distort_pixel(fx / INTER_TAB as f64, fy / INTER_TAB as f64);
                    (fx, fy) = (u * INTER_TAB as f64, v * INTER_TAB as f64);
                    if !(fx.is_finite() && fy.is_finite()) {
                        (fx, fy) = (-4.0 * INTER_TAB as f64, -4.0 * INTER_TAB as f64);
                    }
                }
                let fx = fx.clamp(i32::MIN as f64, i32::MAX as f64);
                let fy = fy.clamp(i32::MIN as f64, i32::MAX as f64);
                let (ix, iy) = (fx.round_ties_even() as i32, fy.round_ties_even() as i32);
                let (sx, sy) = ((ix >> INTER_BITS) as i64, (iy >> INTER_BITS) as i64);
                let a = ((iy & (INTER_TAB - 1)) * INTER_TAB + (ix & (INTER_TAB - 1))) as usize;
                let wts = tab[a];
                let i = (y * out_w + x) as usize;
                // 2. Inside, partly outside or outside the camera frame.
                if sx >= 0 && sy >= 0 && sx + 1 < sw && sy + 1 < sh {
                    offset[i] = (sy * sw + sx) as u32;
                    weight[i] = wts.map(|v| v as u16);
                } else if sx >= -1 && sy >= -1 && sx < sw && sy < sh {
                    let mut src = [u32::MAX; 4];
                    for (k, (dx, dy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                        let (px, py) = (sx + dx, sy + dy);
                        if px >= 0 && py >= 0 && px < sw && py < sh {
                            src[k] = (py * sw + px) as u32;
                        }
                    }
                    edges.push(EdgeTap {
                        dst: i as u32,
                        src,
                        w: wts,
                    });
                }
            }
        }
        // The source rows the taps touch (rows of the top-left tap and the one below it).
        let rows_of = |idx: u32| idx / src_w;
        let mut lo = u32::MAX;
        let mut hi = 0u32;
        for (&o, w) in offset.iter().zip(&weight) {
            if w.iter().any(|&v| v != 0) {
                lo = lo.min(rows_of(o));
                hi = hi.max(rows_of(o) + 1);
            }
        }
        for e in &edges {
            for &t in e.src.iter().filter(|&&t| t != u32::MAX) {
                lo = lo.min(rows_of(t));
                hi = hi.max(rows_of(t));
            }
        }
        let src_rows = if lo == u32::MAX { 0..0 } else { lo..(hi + 1).min(src_h) };
        Ok(Self {
            src_w,
            src_h,
            out_w,
            out_h,
            offset,
            weight,
            edges,
            homography,
            src_rows,
        })
    }

    /// The homography from the camera frame to the bird's-eye image (the ideal, undistorted
    /// frame when the map was built [`WarpMap::with_lens`]).
    pub fn homography(&self) -> &Homography {
        &self.homography
    }

    /// Bird's-eye image size (width, height), pixels.
    pub fn out_size(&self) -> (u32, u32) {
        (self.out_w, self.out_h)
    }

    /// The camera rows the warp reads; [`rgb_to_gray_rows`] needs to convert only these.
    pub fn src_rows(&self) -> std::ops::Range<u32> {
        self.src_rows.clone()
    }

    /// Camera frame size (width, height) this map was built for.
    pub fn src_size(&self) -> (u32, u32) {
        (self.src_w, self.src_h)
    }

    /// Warps an RGB camera frame into the grey bird's-eye image `out`, bilinear per colour
    /// channel and then grey: exactly OpenCV's `warpPerspective` followed by `cvtColor`, pixel
    /// for pixel. The reference path; [`WarpMap::warp`] on a grey frame is 3× cheaper and
    /// differs by at most a grey level or two on a few pixels.
    ///
    /// Panics if the frame or `out` has another size than the map was built for; callers
    /// resize frames first (that is a programming error, not bad input).
    pub fn warp_rgb_to_gray(&self, frame: &RgbImage, out: &mut GrayImage) {
        assert_eq!(
            frame.dimensions(),
            (self.src_w, self.src_h),
            "frame size differs from the warp map"
        );
        assert_eq!(
            out.dimensions(),
            (self.out_w, self.out_h),
            "output size differs from the warp map"
        );
        let src: &[u8] = frame.as_raw();
        let stride = self.src_w as usize * 3;
        let dst: &mut [u8] = out;
        let round = 1u32 << (COEF_BITS - 1);
        // Every offset in `self.offset` was checked in `new` to have all four taps inside a
        // frame of this size (`sx + 1 < w`, `sy + 1 < h`), and the frame size was asserted
        // above, so the six bytes at `o` and at `o + stride` are in bounds.
        for ((d, &off), w) in dst.iter_mut().zip(&self.offset).zip(&self.weight) {
            let o = off as usize * 3;
            // SAFETY: see the comment above the loop; this is the hot loop of the pipeline and
            // the bounds checks cost a third of its time.
            let (top, bot) = unsafe {
                (
                    src.get_unchecked(o..o + 6),
                    src.get_unchecked(o + stride..o + stride + 6),
                )
            };
            let (w0, w1, w2, w3) = (w[0] as u32, w[1] as u32, w[2] as u32, w[3] as u32);
            let r = (top[0] as u32 * w0 + top[3] as u32 * w1 + bot[0] as u32 * w2 + bot[3] as u32 * w3 + round)
                >> COEF_BITS;
            let g = (top[1] as u32 * w0 + top[4] as u32 * w1 + bot[1] as u32 * w2 + bot[4] as u32 * w3 + round)
                >> COEF_BITS;
            let b = (top[2] as u32 * w0 + top[5] as u32 * w1 + bot[2] as u32 * w2 + bot[5] as u32 * w3 + round)
                >> COEF_BITS;
            *d = gray(r as i32, g as i32, b as i32);
        }
        for e in &self.edges {
            let mut rgb = [0i32; 3];
            for (c, v) in rgb.iter_mut().enumerate() {
                let mut s = 0;
                for k in 0..4 {
                    if e.src[k] != u32::MAX {
                        s += src[e.src[k] as usize * 3 + c] as i32 * e.w[k];
                    }
                }
                *v = (s + round as i32) >> COEF_BITS;
            }
            dst[e.dst as usize] = gray(rgb[0], rgb[1], rgb[2]);
        }
    }

    /// Warps a grey camera frame into the bird's-eye image `out` (allocates nothing): one
    /// table walk, four taps per pixel, OpenCV's fixed-point bilinear weights.
    pub fn warp(&self, frame: &GrayImage, out: &mut GrayImage) {
        assert_eq!(
            frame.dimensions(),
            (self.src_w, self.src_h),
            "frame size differs from the warp map"
        );
        assert_eq!(
            out.dimensions(),
            (self.out_w, self.out_h),
            "output size differs from the warp map"
        );
        let src: &[u8] = frame.as_raw();
        let stride = self.src_w as usize;
        let dst: &mut [u8] = out;
        let round = 1u32 << (COEF_BITS - 1);
        for ((d, &off), w) in dst.iter_mut().zip(&self.offset).zip(&self.weight) {
            let o = off as usize;
            // SAFETY: `new` only stores offsets whose four taps lie inside a `src_w × src_h`
            // frame (`sx + 1 < src_w`, `sy + 1 < src_h`), and the frame's size was asserted
            // above, so `o + stride + 1 < src.len()`.
            let (a, b, c, e) = unsafe {
                (
                    *src.get_unchecked(o) as u32,
                    *src.get_unchecked(o + 1) as u32,
                    *src.get_unchecked(o + stride) as u32,
                    *src.get_unchecked(o + stride + 1) as u32,
                )
            };
            *d = ((a * w[0] as u32 + b * w[1] as u32 + c * w[2] as u32 + e * w[3] as u32 + round) >> COEF_BITS) as u8;
        }
        for t in &self.edges {
            let mut s = 0i32;
            for k in 0..4 {
                if t.src[k] != u32::MAX {
                    s += src[t.src[k] as usize] as i32 * t.w[k];
                }
            }
            dst[t.dst as usize] = ((s + round as i32) >> COEF_BITS) as u8;
        }
    }
}

/// OpenCV's `cvtColor(..., COLOR_RGB2GRAY)` on 8-bit data, for a whole frame.
pub fn rgb_to_gray(src: &RgbImage, dst: &mut GrayImage) {
    rgb_to_gray_rows(src, dst, 0..src.height());
}

/// [`rgb_to_gray`] for the rows `rows` only (the rest of `dst` is left as it was).
pub fn rgb_to_gray_rows(src: &RgbImage, dst: &mut GrayImage, rows: std::ops::Range<u32>) {
    assert_eq!(src.dimensions(), dst.dimensions(), "grey image of another size");
    let w = src.width() as usize;
    let (r0, r1) = (
        rows.start.min(src.height()) as usize,
        rows.end.min(src.height()) as usize,
    );
    let out: &mut [u8] = dst;
    for (o, p) in out[r0 * w..r1 * w]
        .iter_mut()
        .zip(src.as_raw()[r0 * w * 3..r1 * w * 3].chunks_exact(3))
    {
        *o = gray(p[0] as i32, p[1] as i32, p[2] as i32);
    }
}

/// OpenCV's integer RGB → grey (`cvtColor(..., COLOR_RGB2GRAY)` on 8-bit data).
#[inline(always)]
pub fn gray(r: i32, g: i32, b: i32) -> u8 {
    ((9798 * r + 19235 * g + 3735 * b + (1 << 14)) >> 15) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ROI: [[f64; 2]; 4] = [[93.72, 78.96], [225.28, 78.96], [308.75, 150.02], [10.25, 150.02]];

    #[test]
    fn homography_maps_the_four_points_exactly_and_round_trips() {
        let h = Homography::from_quad_to_rect(&ROI, 320, 240).unwrap();
        let dst = rect_corners(320, 240);
        let inv = h.inverse().unwrap();
        for k in 0..4 {
            let (u, v) = h.apply(ROI[k][0], ROI[k][1]).unwrap();
            assert!((u - dst[k][0]).abs() < 1e-9 && (v - dst[k][1]).abs() < 1e-9);
            let (x, y) = inv.apply(u, v).unwrap();
            assert!((x - ROI[k][0]).abs() < 1e-9 && (y - ROI[k][1]).abs() < 1e-9);
        }
    }

    #[test]
    fn degenerate_rois_are_rejected() {
        let line = [[0.0, 0.0], [10.0, 10.0], [20.0, 20.0], [30.0, 30.0]];
        assert!(matches!(
            Homography::from_quad_to_rect(&line, 320, 240),
            Err(WarpError::Collinear(..))
        ));
        let twisted = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]];
        assert_eq!(
            Homography::from_quad_to_rect(&twisted, 320, 240),
            Err(WarpError::NotConvex)
        );
        let nan = [[f64::NAN, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        assert_eq!(Homography::from_quad_to_rect(&nan, 320, 240), Err(WarpError::NotFinite));
    }

    #[test]
    fn bilinear_weights_sum_to_one() {
        for w in bilinear_table() {
            assert_eq!(w.iter().sum::<i32>(), 1 << COEF_BITS);
        }
    }

    #[test]
    fn identity_warp_reproduces_the_grey_frame() {
        let frame = RgbImage::from_fn(40, 30, |x, y| {
            image::Rgb([(x * 6) as u8, (y * 8) as u8, ((x + y) * 3) as u8])
        });
        let roi = rect_corners(40, 30);
        let map = WarpMap::new(40, 30, &roi, 40, 30).unwrap();
        let mut out = GrayImage::new(40, 30);
        map.warp_rgb_to_gray(&frame, &mut out);
        for (x, y, p) in out.enumerate_pixels() {
            let c = frame.get_pixel(x, y).0;
            assert_eq!(p.0[0], gray(c[0] as i32, c[1] as i32, c[2] as i32), "at ({x},{y})");
        }
    }

    #[test]
    fn grey_first_warp_is_within_two_levels_of_the_exact_colour_warp() {
        let frame = RgbImage::from_fn(320, 240, |x, y| {
            let v = ((x * 7 + y * 13) % 256) as u8;
            image::Rgb([v, v.wrapping_mul(3), 255 - v])
        });
        let map = WarpMap::new(320, 240, &ROI, 320, 240).unwrap();
        let (mut exact, mut fast, mut g) = (
            GrayImage::new(320, 240),
            GrayImage::new(320, 240),
            GrayImage::new(320, 240),
        );
        map.warp_rgb_to_gray(&frame, &mut exact);
        rgb_to_gray(&frame, &mut g);
        map.warp(&g, &mut fast);
        let max = exact
            .as_raw()
            .iter()
            .zip(fast.as_raw())
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        assert!(max <= 2, "max difference {max}");
    }

    /// The frame a wide-angle lens (`k`) shows of two straight tapes on the floor, 2 cm wide,
    /// 0.18 m either side of the car's axis, and the camera's lens.
    fn bent_tapes(k: [f64; 5]) -> (RgbImage, Lens) {
        let cam = PinholeCamera::new(320, 240, 62.2, 0.20, 20.0);
        let pin = crate::lens::Pinhole {
            fx: cam.f_px,
            fy: cam.f_px,
            cx: cam.u0,
            cy: cam.v0,
        };
        let lens = Lens::on(pin, crate::lens::Distortion(k));
        // 4×4 samples a pixel: each real pixel's ray (undistorted) hits the floor somewhere.
        let img = RgbImage::from_fn(320, 240, |u, v| {
            let mut hits = 0u32;
            for (i, j) in (0..16).map(|n| (n % 4, n / 4)) {
                let (su, sv) = (u as f64 - 0.375 + 0.25 * i as f64, v as f64 - 0.375 + 0.25 * j as f64);
                let (iu, iv) = lens.undistort_pixel(su, sv);
                if let Some((_, y)) = cam.ground_of_pixel(iu, iv) {
                    hits += u32::from((y.abs() - 0.18).abs() < 0.01);
                }
            }
            let g = (30 + hits * 225 / 16) as u8;
            image::Rgb([g, g, g])
        });
        (img, lens)
    }

    /// The tape's centre column on each row of each half of a bird's-eye image.
    fn tape_centres(bird: &GrayImage) -> Vec<Vec<(f64, f64)>> {
        let (w, h) = bird.dimensions();
        [0..w / 2, w / 2..w]
            .into_iter()
            .map(|half| {
                let pts: Vec<(f64, f64)> = (0..h)
                    .filter_map(|y| {
                        let (mut sw, mut sx) = (0.0, 0.0);
                        for x in half.clone() {
                            let v = bird.get_pixel(x, y).0[0] as f64 - 30.0;
                            if v > 20.0 {
                                sw += v;
                                sx += v * x as f64;
                            }
                        }
                        (sw > 0.0).then(|| (y as f64, sx / sw))
                    })
                    .collect();
                assert!(pts.len() as u32 > h * 9 / 10, "the tape is missing on rows: {} of {h}", pts.len());
                pts
            })
            .collect()
    }

    /// The worst distance (px) of the tape's centre from the straight line fitted to it.
    fn fit_residual(tapes: &[Vec<(f64, f64)>]) -> f64 {
        let mut worst = 0.0f64;
        for pts in tapes {
            let n = pts.len() as f64;
            let (my, mx) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
            let b = pts.iter().map(|p| (p.0 - my) * (p.1 - mx)).sum::<f64>() / pts.iter().map(|p| (p.0 - my).powi(2)).sum::<f64>();
            for p in pts {
                worst = worst.max((p.1 - (mx + b * (p.0 - my))).abs());
            }
        }
        worst
    }

    /// The worst distance (px) of the tape's centre from where an ideal lens puts it.
    fn off_truth(tapes: &[Vec<(f64, f64)>], truth: &[Vec<(f64, f64)>]) -> f64 {
        let mut worst = 0.0f64;
        for (a, b) in tapes.iter().zip(truth) {
            for p in a {
                if let Some(q) = b.iter().find(|q| q.0 == p.0) {
                    worst = worst.max((p.1 - q.1).abs());
                }
            }
        }
        worst
    }

    /// Issue 26: straight tape seen through a wide-angle lens stays straight, and where it
    /// is, in the bird's-eye view when the lens is folded into the map, and bends and moves
    /// without it.
    #[test]
    fn a_straight_tape_stays_straight_through_a_wide_angle_lens_only_with_the_lens_model() {
        let k = [-0.5, 0.2, 0.0, 0.0, 0.0];
        let (frame, lens) = bent_tapes(k);
        let mut bird = GrayImage::new(320, 240);
        // An ideal lens's frame through the ideal map: where the tapes belong.
        let without = WarpMap::new(320, 240, &ROI, 320, 240).unwrap();
        without.warp_rgb_to_gray(&bent_tapes([0.0; 5]).0, &mut bird);
        let truth = tape_centres(&bird);
        let with = WarpMap::with_lens(320, 240, &ROI, 320, 240, Some(&lens)).unwrap();
        with.warp_rgb_to_gray(&frame, &mut bird);
        let good = tape_centres(&bird);
        without.warp_rgb_to_gray(&frame, &mut bird);
        let bent = tape_centres(&bird);
        let (gr, go, br, bo) = (
            fit_residual(&good),
            off_truth(&good, &truth),
            fit_residual(&bent),
            off_truth(&bent, &truth),
        );
        eprintln!(
            "tape centre, worst px from a fitted straight line / from the true column: with the lens model {gr:.3} / {go:.3}, without {br:.3} / {bo:.3}, ideal lens {:.3} / 0",
            fit_residual(&truth)
        );
        assert!(gr < 0.5 && go < 0.5, "with the lens model: {gr} px from straight, {go} px off");
        assert!(br > 1.0 && bo > 5.0, "without it: {br} px from straight, {bo} px off");
    }

    /// With zero distortion the table is the one without a lens, bit for bit.
    #[test]
    fn a_lens_without_distortion_leaves_the_map_unchanged() {
        let (_, mut lens) = bent_tapes([0.0; 5]);
        lens.distortion = crate::lens::Distortion::default();
        let a = WarpMap::new(320, 240, &ROI, 320, 240).unwrap();
        let b = WarpMap::with_lens(320, 240, &ROI, 320, 240, Some(&lens)).unwrap();
        assert_eq!((&a.offset, &a.weight, a.src_rows.clone()), (&b.offset, &b.weight, b.src_rows.clone()));
        assert_eq!(a.edges.len(), b.edges.len());
    }

    proptest! {
        #[test]
        fn homography_round_trips_random_points(dx in -30.0f64..30.0, dy in -20.0f64..20.0, px in 0.0f64..319.0, py in 0.0f64..239.0) {
            let mut roi = ROI;
            roi[0][0] += dx;
            roi[1][1] += dy;
            let h = Homography::from_quad_to_rect(&roi, 320, 240).unwrap();
            let (u, v) = h.apply(px, py).unwrap();
            let (x, y) = h.inverse().unwrap().apply(u, v).unwrap();
            prop_assert!((x - px).abs() < 1e-6 && (y - py).abs() < 1e-6);
        }
    }
}
