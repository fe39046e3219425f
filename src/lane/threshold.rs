//! Grey threshold (Rivera & Andaluz 2021, Sec. 3.2 iii: "extract the region determined by an
//! appropriate threshold value"), Otsu's automatic level, and the union with the edges
//! ("the threshold image is matched with the edge detection").
//!
//! Semantics follow OpenCV's `threshold(..., THRESH_BINARY)`: a pixel becomes 255 when it is
//! *strictly* brighter than the level, else 0. Otsu (1979) picks the level that maximises the
//! between-class variance of the grey histogram, computed as OpenCV's `getThreshVal_Otsu_8u`.

use image::GrayImage;
use serde::{Deserialize, Serialize};

/// How the binary image is thresholded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ThresholdMode {
    /// Fixed grey level (`lane.threshold`).
    Fixed,
    /// Otsu's method picks the level per frame.
    Otsu,
}

/// Otsu's threshold level for `img` (0..=255).
pub fn otsu_level(img: &GrayImage) -> u8 {
    // 1. Histogram of grey levels.
    let mut hist = [0u32; 256];
    for &p in img.as_raw() {
        hist[p as usize] += 1;
    }
    let n = img.as_raw().len() as f64;
    if n == 0.0 {
        return 0;
    }
    // 2. Mean grey level of the whole image.
    let mu: f64 = hist.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum::<f64>() / n;
    // 3. Sweep the split, keeping the level of largest between-class variance q1 q2 (mu1 - mu2)^2.
    let (mut q1, mut mu1, mut best_sigma, mut best) = (0.0f64, 0.0f64, 0.0f64, 0u8);
    for (i, &c) in hist.iter().enumerate() {
        let p_i = c as f64 / n;
        mu1 *= q1;
        q1 += p_i;
        let q2 = 1.0 - q1;
        if q1.min(q2) < f32::EPSILON as f64 || q1.max(q2) > 1.0 - f32::EPSILON as f64 {
            continue;
        }
        mu1 = (mu1 + i as f64 * p_i) / q1;
        let mu2 = (mu - q1 * mu1) / q2;
        let sigma = q1 * q2 * (mu1 - mu2) * (mu1 - mu2);
        if sigma > best_sigma {
            best_sigma = sigma;
            best = i as u8;
        }
    }
    best
}

/// Binary threshold of `src` at `level` united with `edges`: 255 where the pixel is brighter
/// than `level` or is an edge, else 0. `out` may not alias the inputs.
pub fn threshold_or_edges(src: &GrayImage, level: u8, edges: &GrayImage, out: &mut GrayImage) {
    assert_eq!(src.dimensions(), out.dimensions());
    assert_eq!(edges.dimensions(), out.dimensions());
    let o: &mut [u8] = out;
    for ((o, &s), &e) in o.iter_mut().zip(src.as_raw()).zip(edges.as_raw()) {
        *o = if s > level { 255 } else { e };
    }
}

/// Plain binary threshold (for annotation and tests): 255 where brighter than `level`.
pub fn threshold(src: &GrayImage, level: u8, out: &mut GrayImage) {
    assert_eq!(src.dimensions(), out.dimensions());
    let o: &mut [u8] = out;
    for (o, &s) in o.iter_mut().zip(src.as_raw()) {
        *o = if s > level { 255 } else { 0 };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_is_strictly_greater() {
        let img = GrayImage::from_raw(4, 1, vec![169, 170, 171, 255]).unwrap();
        let mut out = GrayImage::new(4, 1);
        threshold(&img, 170, &mut out);
        assert_eq!(out.as_raw(), &vec![0, 0, 255, 255]);
    }

    #[test]
    fn otsu_splits_two_populations() {
        // 70% floor around 40, 30% tape around 210: the level falls between them.
        let img = GrayImage::from_fn(100, 10, |x, y| {
            image::Luma([if x < 70 {
                35 + ((x + y) % 10) as u8
            } else {
                205 + (x % 10) as u8
            }])
        });
        let t = otsu_level(&img);
        assert!((44..205).contains(&t), "level {t}");
        // matches imageproc's Otsu within one grey level
        let r = imageproc::contrast::otsu_level(&img);
        assert!(t.abs_diff(r) <= 1, "{t} vs imageproc {r}");
    }

    #[test]
    fn union_keeps_edges_below_the_level() {
        let img = GrayImage::from_raw(3, 1, vec![10, 200, 10]).unwrap();
        let edges = GrayImage::from_raw(3, 1, vec![255, 0, 0]).unwrap();
        let mut out = GrayImage::new(3, 1);
        threshold_or_edges(&img, 100, &edges, &mut out);
        assert_eq!(out.as_raw(), &vec![255, 255, 0]);
    }
}
