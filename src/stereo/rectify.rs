//! Rectification of a calibrated camera pair in the drive loop (Bouguet's method as in
//! `rccar calibrate stereo`, src/calib/stereo.rs; Abdollahi 2011, ch. 3: calibrate, then
//! rectify, then match along rows).
//!
//! Two real webcams are never parallel: a degree of yaw between them moves every object by
//! f·tan(1°) ≈ 4.6 px of disparity at 320×240 (30 % of the disparity of an object at 1 m with
//! a 6 cm base), a little pitch puts it on different rows, and their lenses bend straight
//! lines. The calibration file holds what it takes to undo that: each camera's intrinsics K
//! and distortion, and the rotations R₁, R₂ that turn both into one rectified camera (focal
//! length f, principal point c) whose image rows are the epipolar lines.
//!
//! The drive loop keeps lane keeping and detection on the raw reference image (their ROI,
//! warp and regions are set up for it). Only stereo ranging works in rectified coordinates:
//! - both images of a pair are remapped through maps built once ([`RectifyMaps`] →
//!   [`FixedMaps`], OpenCV's `initUndistortRectifyMap` + `remap`, bilinear in fixed point as
//!   OpenCV does it), on a frame with boxes and only in the rectified rows the boxes cover
//!   ([`PairRectifier::rectify_rows`], called by `StereoRanging::set_pair_for`);
//! - a detector box of the raw reference image is carried into the rectified one by the
//!   inverse map of points on its outline (undistort → R → project; [`rectified_point`]) and
//!   the box that bounds them;
//! - the distance then comes from the rectified camera (f, c, base |T|) and the point is
//!   turned back by Rᵀ into the real reference camera before its tilt is applied
//!   ([`super::StereoGeometry::from_calibration`]).
//!
//! Units: pixels; the base in the calibration's length unit (metres).

use crate::calib::file::StereoCalibration;
use crate::calib::stereo::{rectified_point, FixedMaps, RectifyMaps};
use crate::detect::Rect;
use image::RgbImage;

/// Rectification of the pair, reference camera first, with its scratch images.
#[derive(Debug, Clone)]
pub struct PairRectifier {
    /// Maps of the reference and of the other camera, in fixed point.
    maps: [FixedMaps; 2],
    /// The reference camera's intrinsics, distortion and rectifying rotation, and the
    /// rectified camera (f, c): for carrying boxes over.
    reference: (crate::calib::intrinsics::Intrinsics, crate::calib::intrinsics::Distortion, [[f64; 3]; 3]),
    f: f64,
    c: [f64; 2],
    /// The rectified pair of the last [`PairRectifier::rectify`].
    images: [RgbImage; 2],
}

impl PairRectifier {
    /// The maps of `st` (built once: 2 × width × height rays through the distortion model);
    /// `reference_left` says which camera detection runs on.
    pub fn new(st: &StereoCalibration, reference_left: bool) -> Self {
        let r = &st.rectification;
        let [w, h] = st.left.image_size;
        let map = |cam: &crate::calib::file::CameraCalibration, rot: &[[f64; 3]; 3]| {
            FixedMaps::new(&RectifyMaps::new(&cam.intrinsics, &cam.distortion, rot, r.f, r.c, w, h), w, h)
        };
        let (left, right) = (map(&st.left, &r.r1), map(&st.right, &r.r2));
        let (maps, reference) = if reference_left {
            ([left, right], (st.left.intrinsics, st.left.distortion, r.r1))
        } else {
            ([right, left], (st.right.intrinsics, st.right.distortion, r.r2))
        };
        Self {
            maps,
            reference,
            f: r.f,
            c: r.c,
            images: [RgbImage::new(0, 0), RgbImage::new(0, 0)],
        }
    }

    /// Rectifies a pair (reference first); the result is [`PairRectifier::images`]. `false`
    /// when an image is not of the calibrated size (the pair then has no stereo range).
    pub fn rectify(&mut self, reference: &RgbImage, other: &RgbImage) -> bool {
        self.rectify_rows(reference, other, 0..u32::MAX)
    }

    /// [`PairRectifier::rectify`] for the rectified rows `rows` only (clipped to the image);
    /// the other rows of [`PairRectifier::images`] keep what they held.
    pub fn rectify_rows(&mut self, reference: &RgbImage, other: &RgbImage, rows: std::ops::Range<u32>) -> bool {
        let [a, b] = &mut self.images;
        self.maps[0].remap_rgb_rows(reference, a, rows.clone()) && self.maps[1].remap_rgb_rows(other, b, rows)
    }

    /// The rectified reference and other image of the last pair.
    pub fn images(&self) -> (&RgbImage, &RgbImage) {
        (&self.images[0], &self.images[1])
    }

    /// The box ([x, y, w, h]) in the rectified reference image that holds the raw reference
    /// box `rect`: 5 points along each edge carried over ([`rectified_point`]) and bounded.
    /// `None` if a point falls behind the rectified camera (a box at the edge of a very wide lens).
    pub fn map_box(&self, rect: Rect) -> Option<[i64; 4]> {
        let (k, d, r) = &self.reference;
        let (x0, y0) = (rect.x as f64 - 0.5, rect.y as f64 - 0.5);
        let (x1, y1) = (x0 + rect.width as f64, y0 + rect.height as f64);
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for i in 0..=4 {
            let t = i as f64 / 4.0;
            let (xs, ys) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
            for (u, v) in [(xs, y0), (xs, y1), (x0, ys), (x1, ys)] {
                let (ur, vr) = rectified_point(k, d, r, self.f, self.c, u, v)?;
                lo = [lo[0].min(ur), lo[1].min(vr)];
                hi = [hi[0].max(ur), hi[1].max(vr)];
            }
        }
        // Back from pixel edges to the first and last pixel centres inside.
        let (bx, by) = ((lo[0] + 0.5).round(), (lo[1] + 0.5).round());
        let (ex, ey) = ((hi[0] + 0.5).round(), (hi[1] + 0.5).round());
        Some([bx as i64, by as i64, (ex - bx) as i64, (ey - by) as i64])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::file::CameraCalibration;
    use crate::calib::intrinsics::{Distortion, Intrinsics};
    use crate::calib::intrinsics::rodrigues;
    use crate::calib::stereo::{from_rows, stereo_rectify};

    fn cam(fx: f64, k1: f64) -> CameraCalibration {
        CameraCalibration {
            image_size: [320, 240],
            intrinsics: Intrinsics {
                fx,
                fy: fx,
                cx: 160.0,
                cy: 118.0,
            },
            distortion: Distortion([k1, 0.0, 0.0, 0.0, 0.0]),
            rms_px: 0.1,
            per_image_rms_px: vec![],
            board_not_found: vec![],
        }
    }

    /// A calibrated pair of the cameras `l`, `r`: the right camera turned by `angles_deg`
    /// (Rodrigues vector, degrees) and placed at `t` (metres), rectified.
    fn rig(l: &CameraCalibration, r: &CameraCalibration, angles_deg: [f64; 3], t: [f64; 3]) -> StereoCalibration {
        let rot = rodrigues(angles_deg.map(f64::to_radians));
        let tv = nalgebra::Vector3::from(t);
        let rc = stereo_rectify(&l.intrinsics, &l.distortion, &r.intrinsics, &r.distortion, &rot, &tv, 320, 240);
        StereoCalibration {
            left: l.clone(),
            right: r.clone(),
            r: crate::calib::stereo::to_rows(&rot),
            t,
            baseline_m: tv.norm(),
            rms_px: 0.1,
            per_pair_rms_px: vec![],
            pairs_not_used: vec![],
            rectification: rc,
        }
    }

    /// The fixed-point remap (OpenCV's recipe) agrees with the float one within a grey level
    /// on a smoothly textured image.
    #[test]
    fn fixed_point_remap_matches_the_float_remap() {
        let (l, r) = (cam(265.0, 0.0), cam(270.0, -0.08));
        let rot = rodrigues([0.5f64.to_radians(), 1.0f64.to_radians(), 0.2f64.to_radians()]);
        let t = nalgebra::Vector3::new(-0.06, 0.0, 0.0);
        let rc = stereo_rectify(&l.intrinsics, &l.distortion, &r.intrinsics, &r.distortion, &rot, &t, 320, 240);
        let m = RectifyMaps::new(&r.intrinsics, &r.distortion, &rc.r2, rc.f, rc.c, 320, 240);
        // Texture with gradients up to ~30 grey levels per pixel (1/32 px of position is then
        // under one level; a steeper edge differs by up to gradient/64 as in OpenCV).
        let img = RgbImage::from_fn(320, 240, |x, y| {
            let (x, y) = (x as f64, y as f64);
            let v = |a: f64, b: f64| (127.5 + 120.0 * (a * x + b * y).sin()) as u8;
            image::Rgb([v(0.25, 0.1), v(0.05, 0.22), v(0.13, -0.17)])
        });
        let (mut a, mut b) = (RgbImage::new(0, 0), RgbImage::new(0, 0));
        m.remap_rgb(&img, &mut a);
        assert!(FixedMaps::new(&m, 320, 240).remap_rgb(&img, &mut b));
        // Inside the image (at the border the 0 outside is a 240-level step: 1/32 px of
        // position is then up to 4 levels, in OpenCV as here).
        let inside = |i: usize| (1.0..318.0).contains(&m.map_x[i]) && (1.0..238.0).contains(&m.map_y[i]);
        let (mut worst, mut n) = (0, 0);
        for (_, (p, q)) in a.pixels().zip(b.pixels()).enumerate().filter(|(i, _)| inside(*i)) {
            n += 1;
            for c in 0..3 {
                worst = worst.max((p[c] as i32 - q[c] as i32).abs());
            }
        }
        assert!(n > 60_000 && worst <= 1, "max difference {worst} over {n} pixels");
        // Another size is refused, not read out of bounds.
        assert!(!FixedMaps::new(&m, 320, 240).remap_rgb(&RgbImage::new(160, 120), &mut b));
    }

    /// Remapping a band of rows gives those rows' bytes of the whole remap, border path
    /// included, and leaves the other rows alone.
    #[test]
    fn a_band_of_rows_is_remapped_as_in_the_whole_image() {
        let r = cam(270.0, -0.08);
        let rot = rodrigues([0.5f64.to_radians(), 1.0f64.to_radians(), 0.2f64.to_radians()]);
        let m = RectifyMaps::new(&r.intrinsics, &r.distortion, &crate::calib::stereo::to_rows(&rot), 268.0, [158.0, 119.0], 320, 240);
        let fixed = FixedMaps::new(&m, 320, 240);
        let img = RgbImage::from_fn(320, 240, |x, y| image::Rgb([(x * 7 + y) as u8, (y * 5) as u8, (x ^ y) as u8]));
        let mut whole = RgbImage::new(0, 0);
        assert!(fixed.remap_rgb(&img, &mut whole));
        for rows in [0..1, 0..17, 100..140, 230..240, 239..400, 50..50] {
            let mut band = RgbImage::from_pixel(320, 240, image::Rgb([1, 2, 3]));
            assert!(fixed.remap_rgb_rows(&img, &mut band, rows.clone()));
            for (y, (a, b)) in whole.rows().zip(band.rows()).enumerate() {
                let (a, b): (Vec<_>, Vec<_>) = (a.collect(), b.collect());
                if rows.contains(&(y as u32)) {
                    assert_eq!(a, b, "row {y} of {rows:?}");
                } else {
                    assert!(b.iter().all(|p| p.0 == [1, 2, 3]), "row {y} outside {rows:?} was written");
                }
            }
        }
    }

    /// The drive loop's shortcut: ranging boxes after converting only their rows
    /// (`set_pair_for`) gives what converting the whole pair gives, calibrated or ideal.
    #[test]
    fn ranging_after_the_boxes_rows_only_equals_the_whole_pair() {
        use crate::ranging::ObjectClass;
        use crate::stereo::ranging::StereoRanging;
        let st = rig(&cam(265.0, 0.0), &cam(270.0, -0.08), [0.2, 0.5, 0.1], [-0.06, 0.0, 0.0]);
        // Grey floor with a coloured block, both with aperiodic texture (a periodic one is
        // refused as a repeated pattern); the right camera sees it 14 px left.
        let noise = |x: i64, y: i64| {
            let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            z ^= z >> 29;
            z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            ((z >> 32) % 256) as i64
        };
        // Value noise on a 3 px lattice, bilinear (smooth enough for sub-pixel peaks).
        let smooth = move |x: i64, y: i64| {
            let (i, j, a, b) = (x.div_euclid(3), y.div_euclid(3), x.rem_euclid(3), y.rem_euclid(3));
            let top = noise(i, j) * (3 - a) + noise(i + 1, j) * a;
            let bot = noise(i, j + 1) * (3 - a) + noise(i + 1, j + 1) * a;
            ((top * (3 - b) + bot * b) / 9) as u8
        };
        let scene = |shift: i64| {
            RgbImage::from_fn(320, 240, move |x, y| {
                let (x, y) = (x as i64 + shift, y as i64);
                let v = smooth(x, y);
                if (120..200).contains(&x) && (90..160).contains(&y) {
                    image::Rgb([v, 40, 255 - v])
                } else {
                    let g = 100 + v / 4;
                    image::Rgb([g, g, g])
                }
            })
        };
        let (left, right) = (scene(0), scene(14));
        let boxes = [
            (ObjectClass::StopSign, Rect { x: 125, y: 95, width: 40, height: 40 }),
            (ObjectClass::Obstacle, Rect { x: 118, y: 88, width: 84, height: 74 }),
            (ObjectClass::TrafficLight, Rect { x: 140, y: 30, width: 20, height: 30 }),
        ];
        let rects: Vec<Rect> = boxes.iter().map(|b| b.1).collect();
        // The shipped camera (`[camera]`: 62.2° across 320 px, tilted 20°) and `[stereo]`.
        let (opts, tilt) = (crate::stereo::MatchOptions::default(), 20f64.to_radians());
        let camera = crate::camera::PinholeCamera::new(320, 240, 62.2, 0.20, 20.0);
        let ideal = crate::stereo::StereoGeometry::ideal(&camera, 0.06);
        let mut ranged = 0;
        for calibrated in [false, true] {
            let new = || match calibrated {
                true => StereoRanging::with_calibration(&st, tilt, opts),
                false => StereoRanging::new(ideal, opts),
            };
            let (mut whole, mut rows) = (new(), new());
            whole.set_pair(&left, &right);
            rows.set_pair_for(&left, &right, rects.iter().copied());
            for &(class, rect) in &boxes {
                let a = whole.range(class, rect);
                assert_eq!(a, rows.range(class, rect), "{class:?} calibrated {calibrated}, all boxes");
                // Each box on its own (a fresh ranging: nothing left from another pair).
                let mut alone = new();
                alone.set_pair_for(&left, &right, [rect]);
                assert_eq!(a, alone.range(class, rect), "{class:?} calibrated {calibrated}, alone");
                ranged += a.is_some() as usize;
            }
        }
        assert!(ranged >= 4, "only {ranged} of 6 boxes ranged: the test would compare too little");
    }

    /// A pair with 1° of yaw, 0.5° of pitch and a barrel lens on the right: a point seen by
    /// both lands on the same rectified row, and a box carried over holds the point's image.
    #[test]
    fn a_point_lands_on_the_same_row_in_both_rectified_images() {
        let (l, r) = (cam(265.0, 0.0), cam(270.0, -0.08));
        let st = rig(&l, &r, [0.5, 1.0, 0.2], [-0.06, 0.001, 0.0005]);
        let (rot, t, rc) = (from_rows(&st.r), nalgebra::Vector3::from(st.t), st.rectification);
        let rect = PairRectifier::new(&st, true);
        for &(x, y, z) in &[(0.1, -0.05, 1.0), (-0.2, 0.1, 0.6), (0.0, 0.0, 1.5)] {
            let pl = nalgebra::Vector3::new(x, y, z);
            let pr = rot * pl + t;
            let raw = |c: &CameraCalibration, p: nalgebra::Vector3<f64>| {
                let (xd, yd) = c.distortion.distort(p[0] / p[2], p[1] / p[2]);
                (c.intrinsics.fx * xd + c.intrinsics.cx, c.intrinsics.fy * yd + c.intrinsics.cy)
            };
            let (ul, vl) = raw(&l, pl);
            let (ur, vr) = raw(&r, pr);
            let a = rectified_point(&l.intrinsics, &l.distortion, &rc.r1, rc.f, rc.c, ul, vl).unwrap();
            let b = rectified_point(&r.intrinsics, &r.distortion, &rc.r2, rc.f, rc.c, ur, vr).unwrap();
            assert!((a.1 - b.1).abs() < 1e-6, "rows {} {}", a.1, b.1);
            // Depth from the disparity is the rectified depth of the point.
            let z_rect = (from_rows(&rc.r1) * pl)[2];
            let d = a.0 - b.0;
            assert!((rc.tx.abs() * rc.f / d - z_rect).abs() < 1e-6, "{} {}", rc.tx.abs() * rc.f / d, z_rect);
            let bx = rect
                .map_box(Rect {
                    x: ul.round() as i32 - 3,
                    y: vl.round() as i32 - 3,
                    width: 7,
                    height: 7,
                })
                .unwrap();
            assert!(
                (bx[0] as f64) <= a.0 && a.0 <= (bx[0] + bx[2]) as f64 && (bx[1] as f64) <= a.1 && a.1 <= (bx[1] + bx[3]) as f64,
                "{bx:?} {a:?}"
            );
            assert!((6..=9).contains(&bx[2]) && (6..=9).contains(&bx[3]), "{bx:?}");
        }
    }
}
