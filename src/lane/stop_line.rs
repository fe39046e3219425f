//! Stop and give-way lines painted across the lane, found in the bird's-eye image (issue 27:
//! "a stop line across the lane, found in the bird's-eye image, not by a cascade").
//!
//! **What it measures:** the forward distance along the floor from the camera lens (the floor
//! point below it) to the line's **near edge**, metres, and whether the line is dashed (a
//! give-way line) or solid (a stop line).
//!
//! 1. **Columns.** Only the lane between its two lines counts: the lane centre the lane
//!    measurement found (`L_c`, else the image's centre column) ± `interior` × the configured
//!    lane width in pixels (`lane.lane_width_px`), which keeps the lane lines and the dashed
//!    centre line out even when the lane is off centre.
//! 2. **Rows.** For each bird's-eye row, the fraction of those columns that are white in the
//!    binary image (threshold ∪ edges). A transverse line fills its rows (a yield line's dashes
//!    about 60 % of them); a lane line, a dash of the centre line or a line slanting through the
//!    far rows in a curve fills a few percent, the Canny edge of a shadow one or two rows.
//! 3. **Band.** The nearest run of consecutive rows with a fraction ≥ `min_fill`, at least
//!    `min_width_m` and at most `max_width_m` thick on the floor, whose near edge is not cut
//!    off by the image's bottom row (then its distance is unknown).
//! 4. **Near edge, sub-pixel.** On the grey bird's-eye image: the mean grey of the columns per
//!    row, and the row `v_e` between the band's last row and the first floor row below it
//!    where it crosses half-way between the line's and the floor's grey (linear interpolation).
//! 5. **Distance.** The bird's-eye image is a homography of the floor (`[warp] src` is a floor
//!    rectangle, [`super::warp::bird_to_floor`] from `[camera]`), so a row is a line across
//!    the floor at a fixed distance: `(x, y) = H (u, v_e)`, `x` metres ahead of the lens. With
//!    the shipped ROI (a floor rectangle 0.40–1.00 m ahead, 240 rows) that is the affine map
//!    `x = 1.00 − 0.60 · v_e / 239` (2.5 mm a row).
//! 6. **Dashed.** In the band's middle row, the white runs across the columns: three or more
//!    runs (dashes with gaps) = a give-way line; one run filling most of the width = solid.
//!
//! Units: metres on the floor, bird's-eye pixels; allocates only when built.

use super::lines::LaneMeasurement;
use super::warp::Homography;
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// A line across the lane, as seen in one frame (`Observations::stop_line`, telemetry's
/// `stop_line`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StopLineSeen {
    /// Forward distance along the floor from the lens to the line's near edge, metres.
    pub distance_m: f64,
    /// A dashed give-way (yield) line; `false` = a solid stop line.
    pub dashed: bool,
    /// The near edge's bird's-eye row (sub-pixel), for drawing.
    pub row: f64,
}

/// The detector's thresholds (fixed; documented in docs/lane.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopLineOptions {
    /// Half the columns looked at, as a fraction of the lane width (0.35: the middle 70 %).
    pub interior: f64,
    /// A row belongs to a line when at least this fraction of the columns is white.
    pub min_fill: f64,
    /// Thinnest line accepted, metres along the road.
    pub min_width_m: f64,
    /// Thickest line accepted, metres along the road.
    pub max_width_m: f64,
}

impl Default for StopLineOptions {
    fn default() -> Self {
        Self {
            interior: 0.35,
            min_fill: 0.4,
            min_width_m: 0.015,
            max_width_m: 0.20,
        }
    }
}

/// Finds lines across the lane in the bird's-eye images of one configuration.
#[derive(Debug, Clone)]
pub struct StopLineDetector {
    /// Bird's-eye pixel → floor point (x forward from the lens, y left), metres.
    to_floor: Homography,
    lane_width_px: f64,
    opts: StopLineOptions,
    /// White fraction per row (one buffer, reused).
    fill: Vec<f32>,
}

impl StopLineDetector {
    /// For bird's-eye images mapped to the floor by `to_floor` (x forward from the lens),
    /// a lane `lane_width_px` wide between its line centres.
    pub fn new(to_floor: Homography, lane_width_px: f64, opts: StopLineOptions) -> Self {
        Self {
            to_floor,
            lane_width_px,
            opts,
            fill: Vec::new(),
        }
    }

    /// Forward distance of bird's-eye row `v` (at column `u`) from the lens, metres.
    pub fn row_distance(&self, u: f64, v: f64) -> Option<f64> {
        self.to_floor.apply(u, v).map(|p| p.0)
    }

    /// The nearest line across the lane in this frame's `binary` (threshold ∪ edges) and
    /// `bird` (grey) images, with the lane `lane` measured in them.
    pub fn find(&mut self, binary: &GrayImage, bird: &GrayImage, lane: &LaneMeasurement) -> Option<StopLineSeen> {
        let (w, h) = (binary.width() as usize, binary.height() as usize);
        if w < 4 || h < 4 || bird.dimensions() != binary.dimensions() {
            return None;
        }
        // 1. Columns.
        let centre = lane.lane_center.unwrap_or(lane.frame_center);
        let half = self.opts.interior * self.lane_width_px;
        let c0 = (centre - half).round().max(0.0) as usize;
        let c1 = ((centre + half).round().max(0.0) as usize).min(w);
        if c1 < c0 + 8 {
            return None;
        }
        let cols = (c1 - c0) as f32;
        // 2. White fraction per row.
        let (bin, grey) = (binary.as_raw(), bird.as_raw());
        self.fill.clear();
        self.fill.extend((0..h).map(|v| {
            let row = &bin[v * w + c0..v * w + c1];
            row.iter().filter(|&&p| p > 127).count() as f32 / cols
        }));
        // 3. Bands from the bottom (nearest) up; the first that qualifies.
        let uc = (c0 + c1) as f64 / 2.0;
        let min_fill = self.opts.min_fill as f32;
        let mut v = h;
        while v > 0 {
            v -= 1;
            if self.fill[v] < min_fill {
                continue;
            }
            let bottom = v;
            while v > 0 && self.fill[v - 1] >= min_fill {
                v -= 1;
            }
            let top = v;
            // Cut off by the bottom row: its near edge is not in view.
            if bottom + 1 >= h {
                continue;
            }
            let (Some(near), Some(far)) = (
                self.row_distance(uc, bottom as f64 + 0.5),
                self.row_distance(uc, top as f64 - 0.5),
            ) else {
                continue;
            };
            let thick = far - near;
            if thick < self.opts.min_width_m || (thick > self.opts.max_width_m && top > 0) {
                continue;
            }
            // 4. Near edge on the grey image.
            let mean = |r: usize| grey[r * w + c0..r * w + c1].iter().map(|&p| p as f64).sum::<f64>() / cols as f64;
            let line = mean((top + bottom) / 2);
            let below = (bottom + 3..(bottom + 8).min(h)).map(mean).collect::<Vec<_>>();
            let floor = if below.is_empty() {
                mean(h - 1)
            } else {
                below.iter().sum::<f64>() / below.len() as f64
            };
            let mid = (line + floor) / 2.0;
            let mut edge = bottom as f64 + 0.5;
            for r in top.max(bottom.saturating_sub(3))..(bottom + 3).min(h - 1) {
                let (a, b) = (mean(r), mean(r + 1));
                if (a - mid) * (b - mid) <= 0.0 && (a - b).abs() > 1e-9 {
                    edge = r as f64 + (a - mid) / (a - b);
                    break;
                }
            }
            // 5. Distance; 6. dashed.
            let distance_m = self.row_distance(uc, edge)?;
            let row = &bin[(top + bottom) / 2 * w + c0..(top + bottom) / 2 * w + c1];
            let runs = row.windows(2).filter(|p| p[0] <= 127 && p[1] > 127).count() + (row[0] > 127) as usize;
            return Some(StopLineSeen {
                distance_m,
                dashed: runs >= 3,
                row: edge,
            });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lane::lines::LaneStatus;

    fn lane(centre: f64) -> LaneMeasurement {
        LaneMeasurement {
            p_left: None,
            p_right: None,
            left_estimated: false,
            right_estimated: false,
            lane_center: Some(centre),
            frame_center: 160.0,
            error_px: None,
            error: None,
            status: LaneStatus::Both,
        }
    }

    /// A 320 × 240 bird's-eye image of 1.00 − 0.60 v / 239 m: floor 110, white 235 rows
    /// `rows`, columns `cols` (dashes if any).
    fn image(rows: std::ops::Range<u32>, white: impl Fn(u32) -> bool) -> GrayImage {
        GrayImage::from_fn(320, 240, |u, v| {
            image::Luma([if rows.contains(&v) && white(u) { 235 } else { 110 }])
        })
    }

    fn detector() -> StopLineDetector {
        let src = crate::lane::warp::rect_corners(320, 240);
        let dst = [[1.0, 0.25], [1.0, -0.25], [0.4, -0.25], [0.4, 0.25]];
        StopLineDetector::new(
            Homography::from_points(&src, &dst).unwrap(),
            191.4,
            StopLineOptions::default(),
        )
    }

    #[test]
    fn solid_and_dashed_lines_are_found_at_their_row() {
        let mut d = detector();
        // Rows 100..120 white across: near edge between rows 119 and 120.
        let img = image(100..120, |_| true);
        let s = d.find(&img, &img, &lane(160.0)).unwrap();
        let want = 1.0 - 0.6 * 119.5 / 239.0;
        assert!((s.distance_m - want).abs() < 0.003, "{s:?} vs {want}");
        assert!(!s.dashed);
        // Dashes of 26 px with 19 px gaps.
        let img = image(100..120, |u| u % 45 < 26);
        let s = d.find(&img, &img, &lane(160.0)).unwrap();
        assert!(s.dashed && (s.distance_m - want).abs() < 0.003, "{s:?}");
    }

    #[test]
    fn lane_lines_a_thin_edge_and_a_line_cut_off_are_not_lines() {
        let mut d = detector();
        // Two lane lines and a dashed centre line: columns only.
        let img = GrayImage::from_fn(320, 240, |u, v| {
            let l = (60..72).contains(&u) || (250..262).contains(&u) || ((155..165).contains(&u) && v % 40 < 28);
            image::Luma([if l { 235 } else { 110 }])
        });
        assert_eq!(d.find(&img, &img, &lane(160.0)), None);
        // Two rows (an edge), and a band running into the bottom row.
        for rows in [100..102, 225..240] {
            let img = image(rows, |_| true);
            assert_eq!(d.find(&img, &img, &lane(160.0)), None);
        }
    }
}
