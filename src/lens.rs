//! OpenCV's lens model (radial–tangential, "plumb bob"), shared by the calibration that
//! measures it (`calib::intrinsics`), the bird's-eye map that folds it in (`lane::warp`) and
//! the simulator that renders through it (`sim::stereo::LensWarp`). It stands below all three
//! so none of them imports another for it.
//!
//! ```text
//! x, y normalised (x = (u − cx)/fx, y = (v − cy)/fy), r² = x² + y²
//! x_d = x(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²)
//! y_d = y(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y
//! u_d = fx x_d + cx,  v_d = fy y_d + cy            (pixels)
//! ```
//!
//! Units: pixels for (u, v), fx, fy, cx, cy; the coefficients are dimensionless.

use serde::{Deserialize, Serialize};

/// Lens distortion in OpenCV's order (k1, k2, p1, p2, k3); dimensionless.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion(pub [f64; 5]);

impl Distortion {
    /// Applies the distortion to a normalised point (x', y') → (x'', y'').
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.0;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Inverts [`Distortion::distort`] by fixed-point iteration (as `cv2.undistortPoints`,
    /// with more iterations).
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.0;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let r2 = x * x + y * y;
            let icdist = 1.0 / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            x = (xd - dx) * icdist;
            y = (yd - dy) * icdist;
        }
        (x, y)
    }

    /// No distortion at all (every coefficient exactly 0).
    pub fn is_zero(&self) -> bool {
        self.0.iter().all(|&v| v == 0.0)
    }

    /// d r_d / d r of the radial part at radius² `r2`: `1 + 3k1 r² + 5k2 r⁴ + 7k3 r⁶`. Where
    /// it is ≤ 0 the model folds back (two rays land on one pixel) and cannot be a lens.
    pub fn radial_slope(&self, r2: f64) -> f64 {
        let [k1, k2, _, _, k3] = self.0;
        1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
    }
}

/// Focal lengths and principal point, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
}

/// A real camera against the ideal one the rest of the pipeline assumes: a ray seen at pixel
/// (u, v) of the `ideal` pinhole lands, bent by `distortion`, on the `real` camera's pixel.
/// For a lens given by its coefficients alone both pinholes are the same; a calibration's own
/// pinhole (`real`) may differ a little from the configured one (`ideal`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lens {
    /// The pinhole of the ideal (undistorted) image.
    pub ideal: Pinhole,
    /// The real camera's pinhole.
    pub real: Pinhole,
    /// k1, k2, p1, p2, k3.
    pub distortion: Distortion,
}

impl Lens {
    /// A lens of distortion `d` on the pinhole `k` (ideal and real alike).
    pub fn on(k: Pinhole, d: Distortion) -> Lens {
        Lens {
            ideal: k,
            real: k,
            distortion: d,
        }
    }

    /// The pixel of the real (distorted) image that the ray of the ideal pixel (u, v) lands on.
    pub fn distort_pixel(&self, u: f64, v: f64) -> (f64, f64) {
        let (i, r) = (&self.ideal, &self.real);
        let (xd, yd) = self.distortion.distort((u - i.cx) / i.fx, (v - i.cy) / i.fy);
        (r.fx * xd + r.cx, r.fy * yd + r.cy)
    }

    /// The ideal pixel whose ray the real image shows at (u, v) (inverse of
    /// [`Lens::distort_pixel`]).
    pub fn undistort_pixel(&self, u: f64, v: f64) -> (f64, f64) {
        let (i, r) = (&self.ideal, &self.real);
        let (x, y) = self.distortion.undistort((u - r.cx) / r.fx, (v - r.cy) / r.fy);
        (i.fx * x + i.cx, i.fy * y + i.cy)
    }

    /// Whether the model is monotonic (does not fold back) out to the ideal pixel (u, v).
    pub fn unfolded_at(&self, u: f64, v: f64) -> bool {
        let i = &self.ideal;
        let (x, y) = ((u - i.cx) / i.fx, (v - i.cy) / i.fy);
        let r2 = x * x + y * y;
        // Monotonic on the whole segment 0..r: sample it (the slope is a cubic in r²).
        (0..=32).all(|i| self.distortion.radial_slope(r2 * i as f64 / 32.0) > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistort_inverts_distort() {
        let d = Distortion([-0.28, 0.1, 0.001, -0.0005, -0.02]);
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (0.6, 0.45)] {
            let (xd, yd) = d.distort(x, y);
            let (bx, by) = d.undistort(xd, yd);
            assert!((bx - x).abs() < 1e-9 && (by - y).abs() < 1e-9, "({x}, {y})");
        }
        let k = Pinhole {
            fx: 265.0,
            fy: 265.0,
            cx: 159.5,
            cy: 119.5,
        };
        let lens = Lens {
            real: Pinhole { cx: 161.0, ..k },
            ..Lens::on(k, d)
        };
        let (u, v) = lens.distort_pixel(10.0, 200.0);
        let (bu, bv) = lens.undistort_pixel(u, v);
        assert!((bu - 10.0).abs() < 1e-6 && (bv - 200.0).abs() < 1e-6);
        assert!(lens.unfolded_at(0.0, 0.0));
        let folded = Lens {
            distortion: Distortion([-1.0, 0.0, 0.0, 0.0, 0.0]),
            ..lens
        };
        assert!(!folded.unfolded_at(0.0, 0.0), "k1 = -1 folds at r = 0.58");
    }
}
