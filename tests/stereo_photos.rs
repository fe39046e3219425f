//! Stereo matching on photographs someone else took, against their ground truth: the
//! Middlebury "Aloe" pair that ships with OpenCV's samples (Debian `opencv-doc`:
//! `aloeL.jpg`, `aloeR.jpg` and `aloeGT.png`, the true disparity of every left pixel in
//! pixels, 0 = unknown; read from the system, never copied into the repository).
//!
//! The car's matcher (`Matcher::match_box`, NCC of a box along the same rows, sub-pixel
//! peak, the shipped `min_ncc` and `near_peak_ratio`; src/stereo/matching.rs) is run on a grid
//! of boxes over the left image, once at the photo's size (1282×1110, disparities up to 211 px)
//! and once at the car's scale (the pair resized to 320×277, disparities up to 53 px). A box
//! is compared with the median true disparity inside it when the truth is known on ≥ 95 % of
//! it and spreads ≤ 2 px (at 320 px: ≤ 0.5 px) between its 10th and 90th percentile — one
//! surface, nearly facing the camera, as a detector box on a sign is. Asserted:
//! - boxes with a range: ≥ 95 % within 1 px of the truth (the truth is in whole pixels at the
//!   photo's size) and a median error ≤ 0.5 px (0.25 px at 320 px);
//! - a wrong range (more than 3 px off, 1 px at 320 px) on ≤ 1 % of the boxes: a box the
//!   matcher cannot place should give "no range", not a number;
//! - at least 80 % of the boxes get a range (the leaves, pot and cloth are well textured).
//!
//! The wrong ones are printed with why. Without `stereo.reject_repeats` there were 3 of 208
//! and 1 of 70: the background cloth is a periodic wallpaper, and where the leaf hides the
//! true match in the right view (the score at the truth 0.14 and 0.34) a copy of the pattern
//! one period away passed `min_ncc`; one was the occlusion prior (`near_peak_ratio`) taking a
//! nearer peak of 0.815 over the true 0.897. Those boxes match a copy of themselves along
//! their own rows as well as the other image, and are now refused (`NoRange::Repeated`);
//! what remains is one tie (0.764 against 0.756 at the truth) at the photo's size.
//!
//!     cargo test --release --test it stereo_photos -- --nocapture
//!
//! Without opencv-doc the test says so and passes, unless `RCCAR_OPENCV_DOC` is set (as
//! tests/all.sh does, after installing the package): then the photos must be there.

use image::{GrayImage, RgbImage};
use rccar::config::Config;
use rccar::stereo::matching::Matcher;
use rccar::stereo::{MatchOptions, NoRange};
use std::path::PathBuf;

/// The folder of OpenCV's sample data, and whether it must exist.
fn doc_dir() -> (PathBuf, bool) {
    match std::env::var_os("RCCAR_OPENCV_DOC") {
        Some(d) => (PathBuf::from(d), true),
        None => (PathBuf::from("/usr/share/doc/opencv-doc/examples/data"), false),
    }
}

/// What one size of the pair gave.
struct Outcome {
    boxes: usize,
    ranged: usize,
    within_1px: usize,
    wrong: usize,
    /// Boxes refused as a repeated pattern (`NoRange::Repeated`).
    repeated: usize,
    median_err: f64,
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The grid of boxes compared at one size of the pair.
struct Grid {
    /// Box side and step between boxes, pixels.
    size: u32,
    step: u32,
    /// Largest spread (90th − 10th percentile) of the truth inside a box, pixels.
    max_spread: f64,
    /// An error above this is a wrong range, pixels.
    wrong_px: f64,
}

/// Matches the grid's boxes of the grey pair against the truth `gt` (disparity in pixels of
/// this size, `None` = unknown).
fn run(
    left: &GrayImage,
    right: &GrayImage,
    gt: &dyn Fn(u32, u32) -> Option<f64>,
    grid: Grid,
    opts: &MatchOptions,
) -> Outcome {
    let Grid {
        size,
        step,
        max_spread,
        wrong_px,
    } = grid;
    let mut m = Matcher::new();
    let (w, h) = left.dimensions();
    let (mut boxes, mut ranged, mut within, mut wrong, mut repeated, mut errs) = (0, 0, 0, 0, 0, vec![]);
    let mut y = 0;
    while y + size <= h {
        let mut x = 0;
        while x + size <= w {
            let mut truth: Vec<f64> = (y..y + size)
                .flat_map(|v| (x..x + size).map(move |u| (u, v)))
                .filter_map(|(u, v)| gt(u, v))
                .collect();
            let known = truth.len() as f64 / (size * size) as f64;
            if known >= 0.95 {
                let (lo, hi) = (percentile(&mut truth, 0.1), percentile(&mut truth, 0.9));
                let d_true = percentile(&mut truth, 0.5);
                // The box's match must stay inside the right image.
                if hi - lo <= max_spread && x as f64 >= hi + 2.0 && d_true <= opts.max_disparity as f64 - 2.0 {
                    boxes += 1;
                    let found = m.match_box(left, right, [x as i64, y as i64, size as i64, size as i64], opts);
                    repeated += matches!(found, Err(NoRange::Repeated { .. })) as usize;
                    if let Ok(r) = found {
                        ranged += 1;
                        let e = (r.disparity - d_true).abs();
                        errs.push(e);
                        within += (e <= 1.0) as usize;
                        wrong += (e > wrong_px) as usize;
                        if e > wrong_px {
                            let (at_truth, other) = peaks(m.scores(), opts.min_disparity, d_true, r.disparity);
                            println!(
                                "  wrong: box ({x}, {y}) {size} px: {:.2} px for {d_true:.2} px, score {:.3}; at the truth {at_truth:.3}, best other peak {other:.3}",
                                r.disparity, r.score
                            );
                        }
                    }
                }
            }
            x += step;
        }
        y += step;
    }
    let median_err = if errs.is_empty() {
        f64::NAN
    } else {
        percentile(&mut errs, 0.5)
    };
    Outcome {
        boxes,
        ranged,
        within_1px: within,
        wrong,
        repeated,
        median_err,
    }
}

/// The NCC score at the true disparity and the best local maximum more than 3 px from the
/// chosen one (to say why a box went wrong: the truth scored low, or two peaks tied).
fn peaks(scores: &[f64], dmin: u32, truth: f64, chosen: f64) -> (f64, f64) {
    let at = |d: f64| {
        scores
            .get((d.round() as i64 - dmin as i64).max(0) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let other = (1..scores.len().saturating_sub(1))
        .filter(|&k| scores[k] >= scores[k - 1] && scores[k] >= scores[k + 1])
        .filter(|&k| ((k + dmin as usize) as f64 - chosen).abs() > 3.0)
        .map(|k| scores[k])
        .fold(f64::NEG_INFINITY, f64::max);
    (at(truth), other)
}

#[test]
fn the_matcher_finds_the_true_disparity_on_middlebury_aloe() {
    let (dir, required) = doc_dir();
    let paths = ["aloeL.jpg", "aloeR.jpg", "aloeGT.png"].map(|n| dir.join(n));
    if let Some(p) = paths.iter().find(|p| !p.is_file()) {
        assert!(
            !required,
            "{} is missing (RCCAR_OPENCV_DOC is set: apt-get install opencv-doc)",
            p.display()
        );
        eprintln!("skipped: {} not installed (apt-get install opencv-doc)", p.display());
        return;
    }
    let read = |p: &PathBuf| rccar::imageio::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let (l, r) = (read(&paths[0]).to_rgb8(), read(&paths[1]).to_rgb8());
    let gt = read(&paths[2]).to_luma8();
    assert_eq!(l.dimensions(), gt.dimensions());
    let cfg = Config::default();
    let base = MatchOptions {
        min_score: cfg.stereo.min_ncc,
        near_peak_ratio: cfg.stereo.near_peak_ratio,
        reject_repeats: cfg.stereo.reject_repeats,
        reference_left: true,
        ..MatchOptions::default()
    };
    let grey = |img: &RgbImage| {
        let mut g = GrayImage::new(img.width(), img.height());
        rccar::lane::warp::rgb_to_gray(img, &mut g);
        g
    };
    // 1. The photo's own size: disparities up to 211 px.
    let full = run(
        &grey(&l),
        &grey(&r),
        &|u, v| Some(gt.get_pixel(u, v)[0] as f64).filter(|&d| d > 0.0),
        Grid {
            size: 64,
            step: 48,
            max_spread: 2.0,
            wrong_px: 3.0,
        },
        &MatchOptions {
            max_disparity: 230,
            ..base
        },
    );
    // 2. The car's scale: the pair resized to 320 px wide (truth scaled with it).
    let (w, h) = (320, (l.height() as f64 * 320.0 / l.width() as f64).round() as u32);
    let small = |img: &RgbImage| image::imageops::resize(img, w, h, image::imageops::FilterType::Triangle);
    let (ls, rs) = (small(&l), small(&r));
    let k = l.width() as f64 / w as f64;
    let gt_small = |u: u32, v: u32| {
        // The truth of the photo's pixels under this one (all known), in this size's pixels.
        let (x0, y0) = ((u as f64 * k) as u32, (v as f64 * k) as u32);
        let mut s = vec![];
        for y in y0..((y0 as f64 + k).ceil() as u32).min(gt.height()) {
            for x in x0..((x0 as f64 + k).ceil() as u32).min(gt.width()) {
                let d = gt.get_pixel(x, y)[0];
                if d == 0 {
                    return None;
                }
                s.push(d as f64 / k);
            }
        }
        (!s.is_empty()).then(|| s.iter().sum::<f64>() / s.len() as f64)
    };
    let car = run(
        &grey(&ls),
        &grey(&rs),
        &gt_small,
        Grid {
            size: 24,
            step: 12,
            max_spread: 0.5,
            wrong_px: 1.0,
        },
        &MatchOptions {
            max_disparity: cfg.stereo.max_disparity_px,
            ..base
        },
    );
    for (name, o, med_max) in [
        ("1282x1110, 64 px boxes", &full, 0.5),
        ("320x277, 24 px boxes", &car, 0.25),
    ] {
        println!(
            "aloe {name}: {} boxes on one surface, {} ranged ({:.1} %), {:.1} % of them within 1 px, median |error| {:.2} px, wrong {} ({:.1} %), no range {} ({} of them a repeated pattern)",
            o.boxes,
            o.ranged,
            100.0 * o.ranged as f64 / o.boxes as f64,
            100.0 * o.within_1px as f64 / o.ranged as f64,
            o.median_err,
            o.wrong,
            100.0 * o.wrong as f64 / o.boxes as f64,
            o.boxes - o.ranged,
            o.repeated
        );
        assert!(o.boxes >= 40, "{name}: only {} boxes to compare", o.boxes);
        assert!(
            o.ranged as f64 >= 0.8 * o.boxes as f64,
            "{name}: {} of {} ranged",
            o.ranged,
            o.boxes
        );
        assert!(
            o.within_1px as f64 >= 0.95 * o.ranged as f64,
            "{name}: {} of {} within 1 px",
            o.within_1px,
            o.ranged
        );
        assert!(o.median_err <= med_max, "{name}: median error {:.2} px", o.median_err);
        assert!(
            o.wrong as f64 <= 0.01 * o.boxes as f64,
            "{name}: {} wrong ranges",
            o.wrong
        );
    }
}
