//! Column histogram, the two lane lines, the lane centre and the error
//! (Rivera & Andaluz 2021, Sec. 3.2 iv–v, Eq. 2 and 3).
//!
//! 1. Histogram: for each column of the binary bird's-eye image, the number of white pixels in
//!    a band at the bottom (nearest the car).
//! 2. Lines: P_left is the peak of the left half, P_right the peak of the right half, each only
//!    when the peak covers at least `min_peak` of the band height. A peak's position is the
//!    centroid of the run of columns around the highest one that reach half its height, so a
//!    tape line several pixels wide is located at its middle, to a fraction of a pixel.
//! 3. Lane centre (Eq. 3): `L_c = (P_right − P_left)/2 + P_left`.
//! 4. Error (Eq. 2): `error = L_c − L_F`, L_F the car's centre column (the image centre plus a
//!    configured offset). Positive error = the lane is to the right of the car. Normalised by
//!    half the image width to [−1, 1].
//! 5. A lost line is estimated from the other and the configured lane width (flagged); with both
//!    lost the measurement is [`LaneStatus::Lost`] and carries no error at all.
//!
//! Units: bird's-eye pixels (columns), counts of pixels.

use image::GrayImage;
use serde::{Deserialize, Serialize};

/// How a line's column is read from its histogram peak (`lane.peak`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PeakMode {
    /// Centroid of the run of columns around the highest that reach half its height
    /// (sub-pixel; a wide bright blob next to the line drags it).
    #[default]
    Centroid,
    /// The highest column (the paper's argmax; the middle of a flat top), whole pixels.
    Argmax,
}

/// Options of the line finder, all in bird's-eye pixels unless stated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineOptions {
    /// Fraction of the image height, from the bottom, that the histogram sums (0..1].
    pub band: f64,
    /// Minimum peak height as a fraction of the band height (0..1).
    pub min_peak: f64,
    /// How a peak's column is read (half-height centroid or argmax).
    pub peak: PeakMode,
    /// Distance between the two line centres, pixels.
    pub lane_width_px: f64,
    /// A pair of lines whose distance differs from `lane_width_px` by more than this fraction
    /// is implausible: the weaker one is dropped and re-estimated.
    pub width_tolerance: f64,
    /// L_F offset from the image centre, pixels (positive = right).
    pub center_offset_px: f64,
}

/// Which lines were seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaneStatus {
    /// Both lines seen.
    Both,
    /// Only the left line seen; the right one is estimated.
    LeftOnly,
    /// Only the right line seen; the left one is estimated.
    RightOnly,
    /// Neither line seen: no lane centre, no error.
    Lost,
}

/// The lane as measured in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LaneMeasurement {
    /// P_left, column of the left line (seen or estimated), pixels.
    pub p_left: Option<f64>,
    /// P_right, column of the right line (seen or estimated), pixels.
    pub p_right: Option<f64>,
    /// P_left was estimated from P_right and the lane width.
    pub left_estimated: bool,
    /// P_right was estimated from P_left and the lane width.
    pub right_estimated: bool,
    /// L_c (Eq. 3), pixels.
    pub lane_center: Option<f64>,
    /// L_F, the car's centre column, pixels.
    pub frame_center: f64,
    /// Eq. 2, `L_c − L_F`, pixels.
    pub error_px: Option<f64>,
    /// Error normalised by half the image width, −1..1.
    pub error: Option<f64>,
    /// Which lines were seen.
    pub status: LaneStatus,
}

/// Step 1: counts white pixels per column over the bottom `band_rows` rows into `hist`.
pub fn column_histogram(binary: &GrayImage, band_rows: u32, hist: &mut [u16]) {
    let h = binary.height() as usize;
    column_histogram_rows(binary, h - (band_rows as usize).min(h)..h, hist);
}

/// Step 1 for any band: counts white pixels per column over `rows` (clipped to the image)
/// into `hist` (e.g. a band around a look-ahead distance, src/control/pure_pursuit.rs).
pub fn column_histogram_rows(binary: &GrayImage, rows: std::ops::Range<usize>, hist: &mut [u16]) {
    let (w, h) = (binary.width() as usize, binary.height() as usize);
    assert_eq!(hist.len(), w, "histogram length must equal the image width");
    hist.fill(0);
    let (r0, r1) = (rows.start.min(h), rows.end.min(h));
    for row in binary.as_raw()[r0 * w..r1.max(r0) * w].chunks_exact(w) {
        for (c, &p) in hist.iter_mut().zip(row) {
            *c += (p != 0) as u16;
        }
    }
}

/// The number of histogram rows for a band fraction of an image `height` pixels tall.
pub fn band_rows(height: u32, band: f64) -> u32 {
    ((height as f64 * band).round() as u32).clamp(1, height)
}

/// Step 2 with the configured [`PeakMode`]: [`peak`] (centroid) or [`peak_argmax`].
pub fn peak_with(mode: PeakMode, hist: &[u16], range: std::ops::Range<usize>, min_count: u16) -> Option<f64> {
    match mode {
        PeakMode::Centroid => peak(hist, range, min_count),
        PeakMode::Argmax => peak_argmax(hist, range, min_count),
    }
}

/// The first maximum of `hist[range]` (the range clipped to the histogram): `(start, end,
/// index, value)`, or `None` when the range is empty or the maximum is 0 or below `min_count`.
fn first_max(hist: &[u16], range: std::ops::Range<usize>, min_count: u16) -> Option<(usize, usize, usize, u16)> {
    let (start, end) = (range.start, range.end.min(hist.len()));
    if start >= end {
        return None;
    }
    let mut imax = start;
    for i in start..end {
        if hist[i] > hist[imax] {
            imax = i;
        }
    }
    let max = hist[imax];
    if max == 0 || max < min_count {
        return None;
    }
    Some((start, end, imax, max))
}

/// Step 2, the paper's way: the column of the highest histogram value (the first maximum; when
/// neighbouring columns share that value, the middle of their run, so a flat-topped line is
/// located at its middle). Not moved by a wide bright blob beside the line unless the blob is
/// higher. `None` when the maximum is below `min_count`.
pub fn peak_argmax(hist: &[u16], range: std::ops::Range<usize>, min_count: u16) -> Option<f64> {
    let (_, end, imax, max) = first_max(hist, range, min_count)?;
    let mut r = imax;
    while r + 1 < end && hist[r + 1] == max {
        r += 1;
    }
    Some((imax + r) as f64 / 2.0)
}

/// Step 2: the peak of `hist[range]`: centroid of the half-height run around the first
/// maximum. `None` when the maximum is below `min_count`.
pub fn peak(hist: &[u16], range: std::ops::Range<usize>, min_count: u16) -> Option<f64> {
    let (start, end, imax, max) = first_max(hist, range, min_count)?;
    let half = max.div_ceil(2);
    let (mut l, mut r) = (imax, imax);
    while l > start && hist[l - 1] >= half {
        l -= 1;
    }
    while r + 1 < end && hist[r + 1] >= half {
        r += 1;
    }
    let (mut sum, mut wsum) = (0.0, 0.0);
    for (i, &c) in hist.iter().enumerate().take(r + 1).skip(l) {
        sum += c as f64;
        wsum += i as f64 * c as f64;
    }
    Some(wsum / sum)
}

/// Steps 2–5: the lane measurement from the column histogram of an image `width` wide, the
/// left line searched in its left half and the right line in its right half.
pub fn measure(hist: &[u16], band_rows: u32, opts: &LineOptions) -> LaneMeasurement {
    let (w, mid) = (hist.len(), hist.len() / 2);
    measure_in(hist, band_rows, opts, 0..mid, mid..w)
}

/// Steps 2–5 with the left line searched in the columns `left` and the right one in `right`
/// (e.g. either side of where the lane centre is expected, when the lane may have moved off
/// the image centre: a band far ahead in a curve).
pub fn measure_in(
    hist: &[u16],
    band_rows: u32,
    opts: &LineOptions,
    left: std::ops::Range<usize>,
    right: std::ops::Range<usize>,
) -> LaneMeasurement {
    let w = hist.len();
    let min_count = (opts.min_peak * band_rows as f64).ceil().max(1.0) as u16;
    let mut left = peak_with(opts.peak, hist, left, min_count);
    let mut right = peak_with(opts.peak, hist, right, min_count);
    // Two peaks at an implausible distance: keep the stronger, estimate the other.
    if let (Some(l), Some(r)) = (left, right) {
        if ((r - l) - opts.lane_width_px).abs() > opts.width_tolerance * opts.lane_width_px {
            let height = |p: f64| hist[(p.round() as usize).min(w - 1)];
            if height(l) >= height(r) {
                right = None;
            } else {
                left = None;
            }
        }
    }
    let frame_center = (w as f64 - 1.0) / 2.0 + opts.center_offset_px;
    let (p_left, p_right, status) = match (left, right) {
        (Some(l), Some(r)) => (Some(l), Some(r), LaneStatus::Both),
        (Some(l), None) => (Some(l), Some(l + opts.lane_width_px), LaneStatus::LeftOnly),
        (None, Some(r)) => (Some(r - opts.lane_width_px), Some(r), LaneStatus::RightOnly),
        (None, None) => (None, None, LaneStatus::Lost),
    };
    // Eq. 3 and Eq. 2.
    let lane_center = match (p_left, p_right) {
        (Some(l), Some(r)) => Some((r - l) / 2.0 + l),
        _ => None,
    };
    let error_px = lane_center.map(|c| c - frame_center);
    let half = (w as f64 - 1.0) / 2.0;
    LaneMeasurement {
        p_left,
        p_right,
        left_estimated: status == LaneStatus::RightOnly,
        right_estimated: status == LaneStatus::LeftOnly,
        lane_center,
        frame_center,
        error_px,
        error: error_px.map(|e| (e / half).clamp(-1.0, 1.0)),
        status,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const OPTS: LineOptions = LineOptions {
        band: 0.4,
        min_peak: 0.3,
        peak: PeakMode::Centroid,
        lane_width_px: 190.0,
        width_tolerance: 0.35,
        center_offset_px: 0.0,
    };

    /// A binary image with vertical lines `[x0, x1)` drawn over the whole height.
    fn lines(w: u32, h: u32, bars: &[(u32, u32)]) -> GrayImage {
        GrayImage::from_fn(w, h, |x, _| {
            image::Luma([if bars.iter().any(|&(a, b)| x >= a && x < b) {
                255
            } else {
                0
            }])
        })
    }

    fn hist_of(img: &GrayImage, rows: u32) -> Vec<u16> {
        let mut h = vec![0; img.width() as usize];
        column_histogram(img, rows, &mut h);
        h
    }

    #[test]
    fn histogram_peaks_on_drawn_lines() {
        let img = lines(320, 240, &[(60, 70), (250, 260)]);
        let rows = band_rows(240, 0.4);
        let h = hist_of(&img, rows);
        assert_eq!(rows, 96);
        assert_eq!(h[65], 96);
        assert_eq!(h[100], 0);
        let m = measure(&h, rows, &OPTS);
        assert_eq!(m.status, LaneStatus::Both);
        assert!((m.p_left.unwrap() - 64.5).abs() < 1e-9);
        assert!((m.p_right.unwrap() - 254.5).abs() < 1e-9);
        assert!((m.lane_center.unwrap() - 159.5).abs() < 1e-9);
        assert!(m.error_px.unwrap().abs() < 1e-9);
    }

    #[test]
    fn histogram_only_counts_the_band() {
        // A line only in the top half is outside the bottom 40 % band.
        let img = GrayImage::from_fn(100, 100, |x, y| {
            image::Luma([if (20..25).contains(&x) && y < 50 { 255 } else { 0 }])
        });
        let h = hist_of(&img, 40);
        assert!(h.iter().all(|&c| c == 0));
    }

    #[test]
    fn one_line_lost_is_estimated_and_flagged() {
        let img = lines(320, 240, &[(250, 260)]);
        let h = hist_of(&img, 96);
        let m = measure(&h, 96, &OPTS);
        assert_eq!(m.status, LaneStatus::RightOnly);
        assert!(m.left_estimated && !m.right_estimated);
        assert!((m.p_left.unwrap() - (254.5 - 190.0)).abs() < 1e-9);
        let img = lines(320, 240, &[(60, 70)]);
        let m = measure(&hist_of(&img, 96), 96, &OPTS);
        assert_eq!(m.status, LaneStatus::LeftOnly);
        assert!((m.p_right.unwrap() - (64.5 + 190.0)).abs() < 1e-9);
    }

    #[test]
    fn both_lost_gives_no_error() {
        let m = measure(&vec![0; 320], 96, &OPTS);
        assert_eq!(m.status, LaneStatus::Lost);
        assert_eq!((m.lane_center, m.error_px, m.error), (None, None, None));
        // Specks below min_peak do not count as a line.
        let mut h = vec![0u16; 320];
        h[50] = 20; // < 0.3 * 96
        assert_eq!(measure(&h, 96, &OPTS).status, LaneStatus::Lost);
    }

    #[test]
    fn implausible_pair_keeps_the_stronger_line() {
        let mut h = vec![0u16; 320];
        h[150] = 96; // a line just left of the middle
        h[170] = 50; // and noise just right of it: 20 px apart, lane is 190
        let m = measure(&h, 96, &OPTS);
        assert_eq!(m.status, LaneStatus::LeftOnly);
        assert!((m.p_left.unwrap() - 150.0).abs() < 1e-9);
    }

    #[test]
    fn error_sign_and_offset() {
        // Lane shifted right by 20 px: positive error (steer right).
        let img = lines(320, 240, &[(80, 90), (270, 280)]);
        let m = measure(&hist_of(&img, 96), 96, &OPTS);
        assert!((m.error_px.unwrap() - 20.0).abs() < 1e-9);
        assert!((m.error.unwrap() - 20.0 / 159.5).abs() < 1e-9);
        let m = measure(
            &hist_of(&img, 96),
            96,
            &LineOptions {
                center_offset_px: 20.0,
                ..OPTS
            },
        );
        assert!(m.error_px.unwrap().abs() < 1e-9);
    }

    #[test]
    fn argmax_is_not_dragged_by_a_wide_blob() {
        // A 6 px line (height 40) with a 30 px blob of height 25 beside it: the half-height
        // run takes the blob in, the argmax does not.
        let mut h = vec![0u16; 160];
        h[50..56].fill(40);
        h[56..86].fill(25);
        let c = peak(&h, 0..160, 1).unwrap();
        let a = peak_argmax(&h, 0..160, 1).unwrap();
        assert!((a - 52.5).abs() < 1e-9, "{a}");
        assert!(c > 60.0, "{c}");
        assert_eq!(peak_with(PeakMode::Argmax, &h, 0..160, 41), None);
    }

    proptest! {
        #[test]
        fn peak_is_the_centre_of_a_drawn_line(x0 in 10u32..140, width in 2u32..20) {
            let img = lines(320, 100, &[(x0, x0 + width)]);
            let h = hist_of(&img, 40);
            let p = peak(&h, 0..160, 1).unwrap();
            prop_assert!((p - (x0 as f64 + (width as f64 - 1.0) / 2.0)).abs() < 1e-9);
        }

        #[test]
        fn lane_centre_is_midway(l in 20.0f64..120.0, lw in 150.0f64..230.0) {
            let mut h = vec![0u16; 320];
            let r = (l + lw).min(315.0);
            h[l as usize] = 90;
            h[r as usize] = 90;
            let m = measure(&h, 96, &LineOptions { lane_width_px: r.floor() - l.floor(), ..OPTS });
            prop_assert_eq!(m.status, LaneStatus::Both);
            prop_assert!((m.lane_center.unwrap() - (l.floor() + r.floor()) / 2.0).abs() < 1e-9);
        }
    }
}
