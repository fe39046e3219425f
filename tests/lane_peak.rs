//! `lane.peak = "centroid" | "argmax"` measured (issue 13): which way of reading a line's
//! column from its histogram peak gives the better lane centre, on
//!
//! 1. clean synthetic frames (the project's renderer, random offsets, headings, curves);
//! 2. the same frames with a wide bright patch on the floor just outside the right line (a
//!    sunlit strip, bright concrete: above the grey threshold, so white in the binary image);
//! 3. "photographed" floors: the same lines drawn over OpenCV's sample photos (Debian
//!    opencv-doc, resized to the frame; never copied into the repository) as floor texture,
//!    whose bright areas become blobs of every shape.
//!
//! Error = |L_c − truth| in bird's-eye pixels over the frames where both lines were seen;
//! medians and maxima are printed per set and mode. Asserted: the default mode keeps issue 2's
//! bound on clean frames (median ≤ 1 px, max ≤ 3 px), and argmax beats the centroid on the
//! bright strip (the reason it is offered). Figures and the choice: docs/lane.md.

use image::RgbImage;
use rccar::camera::PinholeCamera;
use rccar::config::{Config, PeakMode};
use rccar::lane::synth::{LaneScene, SplitMix};
use rccar::lane::LaneStatus;
use rccar::timing::{NoTimer, StageTimes};

const DOC: &str = "/usr/share/doc/opencv-doc/examples/data/";

fn scenes(n: usize) -> Vec<LaneScene> {
    let mut rng = SplitMix::new(77);
    (0..n)
        .map(|i| {
            let curve = rng.uniform();
            let radius = if curve < 0.4 {
                f64::INFINITY
            } else {
                (3.0 + 4.0 * rng.uniform()) * if curve < 0.7 { 1.0 } else { -1.0 }
            };
            LaneScene {
                offset_m: 0.05 * (rng.uniform() - 0.5),
                heading_rad: 0.04 * (rng.uniform() - 0.5),
                radius_m: radius,
                noise: 2.0 + 4.0 * rng.uniform(),
                seed: 500 + i as u64,
                ..Default::default()
            }
        })
        .collect()
}

fn stats(mut v: Vec<f64>) -> (f64, f64, usize) {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return (f64::NAN, f64::NAN, 0);
    }
    (v[v.len() / 2], v[v.len() - 1], v.len())
}

#[test]
fn peak_mode_default_is_the_better_one() {
    let cfg = Config::default();
    let cam = PinholeCamera::from(&cfg.camera);
    let h = *cfg.lane_detector().unwrap().warp_map().homography();
    let photos: Vec<RgbImage> = [
        "baboon.jpg",
        "fruits.jpg",
        "building.jpg",
        "home.jpg",
        "lena.jpg",
        "board.jpg",
    ]
    .iter()
    .filter_map(|n| image::open(format!("{DOC}{n}")).ok())
    .map(|im| {
        image::imageops::resize(
            &im.to_rgb8(),
            cfg.camera.width,
            cfg.camera.height,
            image::imageops::FilterType::Triangle,
        )
    })
    .collect();
    // (set, mode) -> errors
    let mut errs: std::collections::BTreeMap<(&str, &str), Vec<f64>> = Default::default();
    let mut seen: std::collections::BTreeMap<(&str, &str), (usize, usize)> = Default::default();
    for (k, scene) in scenes(30).iter().enumerate() {
        let on = scene.render(&cam, &h, cfg.warp.out_height, cfg.lane.band);
        let off = LaneScene {
            left_visible: false,
            right_visible: false,
            ..*scene
        }
        .render(&cam, &h, cfg.warp.out_height, cfg.lane.band);
        let truth = on.truth_center();
        let is_line = |x: u32, y: u32| {
            let (a, b) = (on.image.get_pixel(x, y).0, off.image.get_pixel(x, y).0);
            (a[0] as i32 - b[0] as i32).abs() > 30
        };
        // 2. A bright strip outside the right line, 25 px wide, over the lower rows.
        let mut blob = on.image.clone();
        for y in 100..cfg.camera.height {
            if let Some(c) = (0..cfg.camera.width).rev().find(|&x| is_line(x, y)) {
                for x in c + 1..(c + 26).min(cfg.camera.width) {
                    blob.put_pixel(x, y, image::Rgb([228, 226, 220]));
                }
            }
        }
        // 3. A photo as the floor under the lines.
        let photo = photos.get(k % photos.len().max(1)).map(|p| {
            RgbImage::from_fn(cfg.camera.width, cfg.camera.height, |x, y| {
                if is_line(x, y) {
                    *on.image.get_pixel(x, y)
                } else {
                    *p.get_pixel(x, y)
                }
            })
        });
        let mut sets = vec![("clean", on.image.clone()), ("bright strip", blob)];
        if let Some(p) = photo {
            sets.push(("photo floor", p));
        }
        for (set, img) in &sets {
            for (mode, pm) in [("centroid", PeakMode::Centroid), ("argmax", PeakMode::Argmax)] {
                let mut c = cfg.clone();
                c.lane.peak = pm;
                let mut det = c.lane_detector().unwrap();
                let m = det.measure(img, &mut NoTimer, &mut StageTimes::default());
                let e = seen.entry((set, mode)).or_default();
                e.1 += 1;
                if m.status == LaneStatus::Both {
                    e.0 += 1;
                    errs.entry((set, mode))
                        .or_default()
                        .push((m.lane_center.unwrap() - truth).abs());
                }
            }
        }
    }
    println!("lane.peak: |L_c - truth|, bird's-eye px, frames with both lines seen");
    let mut med = std::collections::BTreeMap::new();
    for ((set, mode), v) in &errs {
        let (m, mx, n) = stats(v.clone());
        let (both, all) = seen[&(*set, *mode)];
        println!("  {set:>12} {mode:>8}: median {m:6.2}  max {mx:7.2}  ({n} frames; both lines in {both}/{all})");
        med.insert((*set, *mode), m);
    }
    // The default must keep issue 2's bound on clean frames (median <= 1 px, max <= 3 px);
    // argmax, offered for floors with bright patches, must beat the centroid there.
    let default = match Config::default().lane.peak {
        PeakMode::Centroid => "centroid",
        PeakMode::Argmax => "argmax",
    };
    let (dm, dx, _) = stats(errs[&("clean", default)].clone());
    assert!(
        dm <= 1.0 && dx <= 3.0,
        "default {default} on clean frames: median {dm:.2}, max {dx:.2}"
    );
    assert!(
        med[&("bright strip", "argmax")] < med[&("bright strip", "centroid")],
        "argmax should not be dragged by the bright strip"
    );
}
