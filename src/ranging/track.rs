//! Object tracks across frames: association of detector boxes to tracks, and a constant-
//! velocity Kalman filter in distance with the car's own odometry as the control input.
//!
//! Every object is assumed to stand still or move slowly along the car's line of sight. Its
//! state is `x = [d, u]`: forward distance from the lens d (metres) and the object's own
//! velocity along the line of sight u (m/s, positive away from the car). Between two frames
//! `dt` seconds apart in which the car's dead reckoning (src/control/behaviour.rs,
//! `DeadReckoning`) advanced `Δs` metres,
//!
//! ```text
//!     predict:  d ← d + u·dt − Δs,   u ← u,          P ← F P Fᵀ + Q
//!               F = [[1, dt], [0, 1]],
//!               Q = σ_a²·[[dt⁴/4, dt³/2], [dt³/2, dt²]] + diag((σ_odo·Δs)², 0)
//!     update:   z = d_box (src/ranging.rs, `BoxRange`), R = σ_box²
//!               K = P Hᵀ / (H P Hᵀ + R),  H = [1, 0];  x ← x + K (z − H x),  P ← (I − K H) P
//! ```
//!
//! (the Kalman filter with a control input, Bar-Shalom et al., *Estimation with Applications
//! to Tracking and Navigation*, 2001, §5.2; the white-noise-acceleration model of §6.3.2).
//! Odometry carries the distance between detection frames, so the filter averages box noise
//! over many frames without lagging behind the approach, and a detection every Nth frame
//! is enough: between detections a track's box is reprojected through the camera to its
//! predicted distance.
//!
//! Association (per class): greedy on the intersection over union of a track's predicted
//! box and a detection's box (≥ `min_iou`), or, failing that, a distance innovation within
//! `gate_sigma` standard deviations and a lateral offset within `gate_lateral_m`. Units:
//! metres, seconds, pixels.

use super::{BoxRange, ObjectClass};
use crate::camera::PinholeCamera;

/// Tracker options (from `[ranging]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerOptions {
    /// σ of an object's own acceleration along the line of sight, m/s² (process noise).
    pub accel_sigma: f64,
    /// σ of the odometry's distance per frame, relative (0.1 = 10% of the distance driven).
    pub odometry_sigma: f64,
    /// A track not matched on this many detection frames in a row is dropped.
    pub max_missed: u32,
    /// Smallest IoU of a predicted and a detected box that associates them.
    pub min_iou: f64,
    /// Without box overlap, largest distance innovation that associates, in σ.
    pub gate_sigma: f64,
    /// Without box overlap, largest lateral difference that associates, metres.
    pub gate_lateral_m: f64,
}

impl Default for TrackerOptions {
    fn default() -> Self {
        Self {
            accel_sigma: 0.5,
            odometry_sigma: 0.1,
            max_missed: 3,
            min_iou: 0.2,
            gate_sigma: 4.0,
            gate_lateral_m: 0.1,
        }
    }
}

/// One detection as the tracker takes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement<T: Copy> {
    /// Its class.
    pub class: ObjectClass,
    /// Its box, [left, top, right, bottom], pixel-centre coordinates.
    pub bbox: [f64; 4],
    /// The box's range.
    pub range: BoxRange,
    /// Whatever the caller keeps with the object (e.g. a light's colour).
    pub extra: T,
}

/// One object followed across frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track<T: Copy> {
    /// Unique within a tracker's life.
    pub id: u32,
    /// Its class.
    pub class: ObjectClass,
    /// Forward distance, metres (filtered).
    pub distance_m: f64,
    /// Own velocity along the line of sight, m/s (positive away from the car).
    pub velocity_mps: f64,
    /// Covariance of [distance, velocity].
    pub cov: [[f64; 2]; 2],
    /// Lateral offset, metres, left positive (the latest measurement's, no filter).
    pub lateral_m: f64,
    /// The latest box: detected on a detection frame, reprojected in between.
    pub bbox: [f64; 4],
    /// The latest measured (unfiltered) distance, metres.
    pub measured_m: f64,
    /// The latest measurement's caller data.
    pub extra: T,
    /// Detections matched so far.
    pub hits: u32,
    /// Detection frames in a row without a match.
    pub missed: u32,
    /// Matched in this frame (false on frames between detections and when missed).
    pub matched_now: bool,
}

impl<T: Copy> Track<T> {
    /// σ of the filtered distance, metres.
    pub fn sigma_m(&self) -> f64 {
        self.cov[0][0].max(0.0).sqrt()
    }
}

/// The tracks of all objects in view.
#[derive(Debug, Clone)]
pub struct Tracker<T: Copy> {
    opts: TrackerOptions,
    camera: PinholeCamera,
    tracks: Vec<Track<T>>,
    next_id: u32,
    // Scratch for association, reused.
    used: Vec<bool>,
}

impl<T: Copy> Tracker<T> {
    /// An empty tracker; `camera` reprojects boxes between detections.
    pub fn new(opts: TrackerOptions, camera: PinholeCamera) -> Self {
        Self {
            opts,
            camera,
            tracks: Vec::with_capacity(8),
            next_id: 1,
            used: Vec::with_capacity(8),
        }
    }

    /// The live tracks.
    pub fn tracks(&self) -> &[Track<T>] {
        &self.tracks
    }

    /// Forgets every track.
    pub fn clear(&mut self) {
        self.tracks.clear();
    }

    /// The prediction step: `dt_s` seconds passed and the car drove `odometry_m` metres
    /// forward (negative = reversing). Boxes are reprojected to the predicted distances.
    pub fn predict(&mut self, dt_s: f64, odometry_m: f64) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 { dt_s } else { 0.0 };
        let ds = if odometry_m.is_finite() { odometry_m } else { 0.0 };
        let q = self.opts.accel_sigma * self.opts.accel_sigma;
        let so = self.opts.odometry_sigma * ds;
        for t in &mut self.tracks {
            t.matched_now = false;
            let before = t.distance_m;
            // 1. State: x ← F x + B u, u = −Δs.
            t.distance_m += t.velocity_mps * dt - ds;
            // 2. Covariance: P ← F P Fᵀ + Q.
            let p = t.cov;
            let p00 = p[0][0] + dt * (p[1][0] + p[0][1]) + dt * dt * p[1][1];
            let p01 = p[0][1] + dt * p[1][1];
            let p11 = p[1][1];
            t.cov = [
                [p00 + q * dt.powi(4) / 4.0 + so * so, p01 + q * dt.powi(3) / 2.0],
                [p01 + q * dt.powi(3) / 2.0, p11 + q * dt * dt],
            ];
            // 3. The box, moved with the object in the camera's view.
            if t.distance_m > 0.02 {
                t.bbox = reproject(&self.camera, t.bbox, before, t.distance_m);
            }
        }
        // An object the car has driven through (or one far behind) is gone.
        self.tracks.retain(|t| t.distance_m > 0.02 && t.distance_m.is_finite());
    }

    /// The update step of a detection frame: associates `found` with the tracks, updates the
    /// matched ones, counts a miss on the others (dropping those missed too often) and starts
    /// a track for each unmatched detection.
    pub fn update(&mut self, found: &[Measurement<T>]) {
        self.used.clear();
        self.used.resize(found.len(), false);
        // 1. Greedy association: repeatedly the best (track, detection) pair left.
        let mut assigned: Vec<Option<usize>> = vec![None; self.tracks.len()];
        loop {
            let mut best: Option<(f64, usize, usize)> = None;
            for (ti, t) in self.tracks.iter().enumerate() {
                if assigned[ti].is_some() {
                    continue;
                }
                for (mi, m) in found.iter().enumerate() {
                    if self.used[mi] || m.class != t.class {
                        continue;
                    }
                    let score = self.score(t, m);
                    if score > 0.0 && best.is_none_or(|b| score > b.0) {
                        best = Some((score, ti, mi));
                    }
                }
            }
            let Some((_, ti, mi)) = best else { break };
            assigned[ti] = Some(mi);
            self.used[mi] = true;
        }
        // 2. Kalman update of the matched tracks; misses counted on the others.
        for (t, a) in self.tracks.iter_mut().zip(&assigned) {
            match a {
                Some(mi) => {
                    let m = &found[*mi];
                    let r = m.range.sigma_m * m.range.sigma_m;
                    let p = t.cov;
                    let s = p[0][0] + r;
                    let (k0, k1) = (p[0][0] / s, p[1][0] / s);
                    let innov = m.range.distance_m - t.distance_m;
                    t.distance_m += k0 * innov;
                    t.velocity_mps += k1 * innov;
                    t.cov = [
                        [(1.0 - k0) * p[0][0], (1.0 - k0) * p[0][1]],
                        [p[1][0] - k1 * p[0][0], p[1][1] - k1 * p[0][1]],
                    ];
                    t.lateral_m = m.range.lateral_m;
                    t.bbox = m.bbox;
                    t.measured_m = m.range.distance_m;
                    t.extra = m.extra;
                    t.hits += 1;
                    t.missed = 0;
                    t.matched_now = true;
                }
                None => {
                    t.missed += 1;
                    t.matched_now = false;
                }
            }
        }
        let max_missed = self.opts.max_missed;
        self.tracks.retain(|t| t.missed <= max_missed);
        // 3. New tracks: distance as measured, velocity 0 ± 0.5 m/s (a slow object).
        for (m, used) in found.iter().zip(&self.used) {
            if *used {
                continue;
            }
            let s = m.range.sigma_m;
            self.tracks.push(Track {
                id: self.next_id,
                class: m.class,
                distance_m: m.range.distance_m,
                velocity_mps: 0.0,
                cov: [[s * s, 0.0], [0.0, 0.25]],
                lateral_m: m.range.lateral_m,
                bbox: m.bbox,
                measured_m: m.range.distance_m,
                extra: m.extra,
                hits: 1,
                missed: 0,
                matched_now: true,
            });
            self.next_id = self.next_id.wrapping_add(1).max(1);
        }
    }

    /// How well detection `m` fits track `t`: 1 + IoU when the boxes overlap enough, else
    /// a value in (0, 1) when the distance and side agree, else 0 (no match).
    fn score(&self, t: &Track<T>, m: &Measurement<T>) -> f64 {
        let iou = iou(t.bbox, m.bbox);
        if iou >= self.opts.min_iou {
            return 1.0 + iou;
        }
        let s = (t.cov[0][0] + m.range.sigma_m * m.range.sigma_m).sqrt().max(1e-6);
        let nis = (m.range.distance_m - t.distance_m).abs() / s;
        if nis <= self.opts.gate_sigma && (m.range.lateral_m - t.lateral_m).abs() <= self.opts.gate_lateral_m {
            return 1.0 / (1.0 + nis);
        }
        0.0
    }
}

/// Intersection over union of two boxes [left, top, right, bottom].
pub fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    let area = |r: [f64; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let uni = area(a) + area(b) - inter;
    if uni > 0.0 {
        inter / uni
    } else {
        0.0
    }
}

/// The box of an object that moved from forward distance `d0` to `d1` (the car drove
/// towards it): each corner's ray is cut at forward distance `d0` from the lens, moved by
/// `d1 − d0` along the car's axis, and projected again.
pub fn reproject(cam: &PinholeCamera, bbox: [f64; 4], d0: f64, d1: f64) -> [f64; 4] {
    let o = cam.origin();
    let mv = |u: f64, v: f64| -> Option<(f64, f64)> {
        let r = cam.ray(u, v);
        if r[0] <= 1e-9 {
            return None;
        }
        let t = d0 / r[0];
        cam.project([o[0] + d1, o[1] + t * r[1], o[2] + t * r[2]])
    };
    match (mv(bbox[0], bbox[1]), mv(bbox[2], bbox[3])) {
        (Some((l, t)), Some((r, b))) => [l, t, r, b],
        _ => bbox,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lane::synth::SplitMix;

    fn range(d: f64, s: f64) -> BoxRange {
        BoxRange {
            distance_m: d,
            sigma_m: s,
            lateral_m: -0.15,
            by_size: None,
            by_row: None,
        }
    }

    /// The shipped camera (`[camera]`).
    fn cam() -> PinholeCamera {
        PinholeCamera::new(320, 240, 62.2, 0.20, 20.0)
    }

    /// The box of a 0.1 m square face centred 0.17 m up, 0.15 m right, `d` ahead.
    fn face_box(d: f64) -> [f64; 4] {
        let c = cam();
        let (l, t) = c.project([d, 0.2, 0.22]).unwrap();
        let (r, b) = c.project([d, 0.1, 0.12]).unwrap();
        [l, t, r, b]
    }

    #[test]
    fn reprojection_matches_projection_at_the_new_distance() {
        let c = cam();
        let got = reproject(&c, face_box(1.2), 1.2, 0.7);
        let want = face_box(0.7);
        for k in 0..4 {
            assert!((got[k] - want[k]).abs() < 1e-9, "{got:?} vs {want:?}");
        }
    }

    #[test]
    fn odometry_carries_the_distance_and_noise_averages_out() {
        // The car approaches a still object at 0.5 m/s, 30 fps; box ranges carry 5% noise.
        let mut tr: Tracker<()> = Tracker::new(TrackerOptions::default(), cam());
        let mut rng = SplitMix::new(11);
        let (dt, v) = (1.0 / 30.0, 0.5);
        let mut d = 1.6;
        let (mut sq, mut n, mut sig) = (0.0, 0.0, 0.0);
        for k in 0..80 {
            if k > 0 {
                d -= v * dt;
                tr.predict(dt, v * dt);
            }
            let s = 0.05 * d;
            let m = Measurement {
                class: ObjectClass::StopSign,
                bbox: face_box(d),
                range: range(d + s * rng.normal(), s),
                extra: (),
            };
            tr.update(&[m]);
            assert_eq!(tr.tracks().len(), 1, "one object, one track (frame {k})");
            let t = &tr.tracks()[0];
            if k >= 20 {
                sq += ((t.distance_m - d) / d).powi(2);
                sig += t.sigma_m() / d;
                n += 1.0;
            }
        }
        // A single box is ±5% (1σ); twenty frames in, the track's rms error is under half that,
        // and the σ it claims is the right size (within a factor 1.5 of the rms error).
        let (rms, sig) = ((sq / n).sqrt(), sig / n);
        assert!(rms < 0.025, "tracked rms error {rms}");
        assert!(sig / rms > 0.67 && sig / rms < 1.5, "claimed σ {sig} vs rms error {rms}");
    }

    #[test]
    fn between_detections_the_prediction_follows_odometry() {
        let mut tr: Tracker<u8> = Tracker::new(TrackerOptions::default(), cam());
        let m = |d: f64| Measurement {
            class: ObjectClass::Obstacle,
            bbox: face_box(d),
            range: range(d, 0.01),
            extra: 7u8,
        };
        tr.update(&[m(1.0)]);
        tr.predict(0.1, 0.05);
        let t = tr.tracks()[0];
        assert!((t.distance_m - 0.95).abs() < 1e-9);
        assert!(!t.matched_now && t.extra == 7);
        let want = face_box(0.95);
        assert!((t.bbox[3] - want[3]).abs() < 1e-6 && (t.bbox[0] - want[0]).abs() < 1e-6);
        // Missed detections: dropped after max_missed + 1 detection frames without a match.
        for _ in 0..=TrackerOptions::default().max_missed {
            assert_eq!(tr.tracks().len(), 1);
            tr.update(&[]);
        }
        assert!(tr.tracks().is_empty());
    }

    #[test]
    fn two_objects_keep_their_tracks_and_classes_do_not_mix() {
        let mut tr: Tracker<()> = Tracker::new(TrackerOptions::default(), cam());
        let a = |d: f64| Measurement {
            class: ObjectClass::StopSign,
            bbox: face_box(d),
            range: range(d, 0.02),
            extra: (),
        };
        let mut b = a(0.8);
        b.class = ObjectClass::TrafficLight;
        tr.update(&[a(1.0), b]);
        let ids: Vec<u32> = tr.tracks().iter().map(|t| t.id).collect();
        tr.predict(1.0 / 30.0, 0.0);
        tr.update(&[b, a(1.0)]);
        assert_eq!(tr.tracks().len(), 2);
        let now: Vec<u32> = tr.tracks().iter().map(|t| t.id).collect();
        assert_eq!(ids, now);
        assert_eq!(tr.tracks()[0].class, ObjectClass::StopSign);
        // A far-away second sign (no overlap, distance outside the gate) starts its own track.
        tr.update(&[a(1.0), b, a(2.5)]);
        assert_eq!(tr.tracks().len(), 3);
    }

    #[test]
    fn iou_of_boxes() {
        assert!((iou([0.0, 0.0, 2.0, 2.0], [1.0, 1.0, 3.0, 3.0]) - 1.0 / 7.0).abs() < 1e-12);
        assert_eq!(iou([0.0, 0.0, 1.0, 1.0], [2.0, 2.0, 3.0, 3.0]), 0.0);
    }
}
