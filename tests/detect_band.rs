//! The ground-plane band (`detect.ground_band`, `pipeline::detect_bands`) loses no object in
//! range: on simulator frames of a stop sign, a traffic light and an obstacle seen from
//! 0.3 to 1.5 m, the shipped cascades give the same boxes around the object with the band as
//! without it (both with the `[detect]` regions and size limits), while the band skips most
//! windows. A box "around the object" overlaps the object's true image box (IoU > 0.2).
//!
//! Units: metres, pixels. Run: `cargo test --release --test it detect_band:: -- --nocapture`.

use rccar::config::Config;
use rccar::detect::{DetectStage, Rect};
use rccar::pipeline::{detect_bands, detect_limits, load_detector};
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use std::path::Path;
use std::time::Instant;

/// A straight with one object of `kind` on the driven lane, 3 m ahead of the start (the
/// track of tests/ranging_sim.rs).
fn track(kind: &str) -> Track {
    rccar::sim::scenario_lab::straight_with_object(kind).unwrap()
}

fn iou(a: Rect, b: [f64; 4]) -> f64 {
    let (ax0, ay0, ax1, ay1) = (a.x as f64, a.y as f64, (a.x + a.width) as f64, (a.y + a.height) as f64);
    let (bx0, by0, bx1, by1) = (b[0], b[1], b[2] + 1.0, b[3] + 1.0);
    let iw = (ax1.min(bx1) - ax0.max(bx0)).max(0.0);
    let ih = (ay1.min(by1) - ay0.max(by0)).max(0.0);
    let i = iw * ih;
    i / ((ax1 - ax0) * (ay1 - ay0) + (bx1 - bx0) * (by1 - by0) - i)
}

#[test]
fn the_band_keeps_every_object_box_in_range() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cfg = Config::default();
    assert!(cfg.detect.ground_band, "shipped on");
    let (Some(stage), missing) = load_detector(&cfg, &root.join("config")).unwrap() else {
        panic!("no cascades");
    };
    assert!(missing.is_empty(), "the shipped cascades are missing: {missing:?}");
    let limits = detect_limits(&cfg);
    let bands = detect_bands(&cfg);
    let mut plain: DetectStage = stage.clone();
    let mut banded: DetectStage = stage;
    for (l, b) in limits.iter().zip(bands.iter()) {
        plain.set_limits(l.class.name(), Some(l.region), l.min_size, l.max_size);
        banded.set_limits(l.class.name(), Some(l.region), l.min_size, l.max_size);
        assert!(b.is_some());
        banded.set_band(l.class.name(), b.clone());
    }
    let lens_ahead = cfg.vehicle.camera_x_m - cfg.vehicle.wheelbase_m / 2.0;
    let (mut t_plain, mut t_band) = (0.0, 0.0);
    let mut failed = vec![];
    for (kind, label) in [
        ("stop_sign", "stop_sign"),
        ("traffic_light", "traffic_light"),
        ("obstacle", "obstacle"),
    ] {
        let t = track(kind);
        let (mut frames, mut found) = (0, 0);
        for k in 0..=24 {
            let d = 0.3 + 0.05 * k as f64;
            let mut sim = Simulation::new(&cfg, &t).unwrap();
            sim.set_truth_boxes(true);
            sim.place_at(3.0 - d - lens_ahead);
            let step = sim.step();
            let Some(truth) = step.truth.objects.first() else {
                continue;
            };
            let img = sim.image().clone();
            let s = Instant::now();
            let a = plain.run_rgb(&img).unwrap();
            t_plain += s.elapsed().as_secs_f64();
            let s = Instant::now();
            let b = banded.run_rgb(&img).unwrap();
            t_band += s.elapsed().as_secs_f64();
            let near = |v: &[rccar::detect::DetectedObject]| {
                let mut r: Vec<(i32, i32, i32, i32, u32)> = v
                    .iter()
                    .filter(|o| o.label == label && iou(o.rect, truth.bbox) > 0.2)
                    .map(|o| (o.rect.x, o.rect.y, o.rect.width, o.rect.height, o.neighbors))
                    .collect();
                r.sort();
                r
            };
            let (na, nb) = (near(&a), near(&b));
            frames += 1;
            if !na.is_empty() {
                found += 1;
            }
            if na != nb {
                failed.push(format!("{kind} at {d:.2} m: without band {na:?}, with band {nb:?}"));
            }
        }
        println!("{kind:>13}: {frames} frames 0.30..1.50 m, object boxed on {found}; boxes identical with the band");
    }
    println!(
        "detection time over all frames: {:.1} ms without the band, {:.1} ms with it ({:.2}x)",
        1e3 * t_plain,
        1e3 * t_band,
        t_band / t_plain
    );
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A simulator frame of the stop sign 1 m ahead of the lens, and the sign's true image box.
fn stop_sign_at_1m(cfg: &Config) -> (image::RgbImage, [f64; 4]) {
    let lens_ahead = cfg.vehicle.camera_x_m - cfg.vehicle.wheelbase_m / 2.0;
    let mut sim = Simulation::new(cfg, &track("stop_sign")).unwrap();
    sim.set_truth_boxes(true);
    sim.place_at(3.0 - 1.0 - lens_ahead);
    let truth = sim.step().truth.objects.first().expect("the sign in view").bbox;
    (sim.image().clone(), truth)
}

/// `classes.<name>.min_neighbors` sets that class's grouping threshold only: on a simulator
/// frame of the stop sign 1 m ahead, the shipped stop-sign cascade boxes it with `n` merged
/// hits at `detect.min_neighbors` 3; set `classes.stop_sign.min_neighbors = n` (a box needs
/// more than `n`) and the box is gone, while the same value for another class, or 0 (= the
/// `[detect]` value), leaves the stop sign's boxes as they were.
#[test]
fn a_class_min_neighbors_applies_to_that_class_only() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let base = Config::default();
    let (img, truth) = stop_sign_at_1m(&base);
    let signs = |cfg: &Config| -> Vec<(i32, i32, i32, i32, u32)> {
        let (Some(mut stage), missing) = load_detector(cfg, &root.join("config")).unwrap() else {
            panic!("no cascades");
        };
        assert!(missing.is_empty(), "{missing:?}");
        stage.set_parallel(false);
        let mut v: Vec<_> = stage
            .run_rgb(&img)
            .unwrap()
            .into_iter()
            .filter(|o| o.label == "stop_sign" && iou(o.rect, truth) > 0.2)
            .map(|o| (o.rect.x, o.rect.y, o.rect.width, o.rect.height, o.neighbors))
            .collect();
        v.sort();
        v
    };
    assert_eq!(base.detect.min_neighbors, 3);
    let at_default = signs(&base);
    let n = at_default.iter().map(|b| b.4).max().expect("the stop sign boxed at 1 m");
    assert!(n > 3, "{at_default:?}");
    let with = |key: &str| signs(&base.with_override(key).unwrap());
    assert_eq!(with(&format!("classes.stop_sign.min_neighbors={n}")), vec![], "more than {n} hits needed: no box");
    assert_eq!(with("classes.stop_sign.min_neighbors=0"), at_default, "0 = detect.min_neighbors");
    assert_eq!(with(&format!("classes.traffic_light.min_neighbors={n}")), at_default, "another class's value");
    let e = base.with_override("classes.stop_sign.min_neighbors=101").unwrap_err().to_string();
    assert!(e.contains("classes.stop_sign.min_neighbors"), "{e}");
    println!("stop sign at 1 m: {at_default:?} at detect.min_neighbors 3; none at classes.stop_sign.min_neighbors {n}");
}

/// `rccar detect` without `--cascade` runs what the car runs, each class at its own grouping
/// threshold: on the same frame of the stop sign 1 m ahead (whole image, as the command scans
/// it), the stop-sign box has `m` merged hits at the default; with
/// `classes.stop_sign.min_neighbors = m` it is gone, another class's value leaves it, and an
/// explicit `--min-neighbors` overrides the class's value.
#[test]
fn rccar_detect_uses_each_class_min_neighbors_from_the_configuration() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (img, truth) = stop_sign_at_1m(&Config::default());
    let dir = tempfile::tempdir().unwrap();
    let frame = dir.path().join("sign.png");
    img.save(&frame).unwrap();
    // The stop-sign boxes on the sign, (x, y, w, h, neighbours), and the stderr line naming the
    // cascades.
    type Boxes = Vec<(i64, i64, i64, i64, u64)>;
    let run = |extra: &[&str]| -> (Boxes, String) {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_rccar"))
            .current_dir(root)
            .args(["detect", "--no-annotate", "--no-local"])
            .args(extra)
            .arg(&frame)
            .output()
            .unwrap();
        let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "{extra:?}: {out}{err}");
        let line: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
        let mut v: Vec<_> = line["boxes"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|b| b["cascade"].as_str().unwrap().ends_with("stop_sign.xml"))
            .map(|b| {
                let n = |k: &str| b[k].as_i64().unwrap();
                (n("x"), n("y"), n("width"), n("height"), b["neighbors"].as_u64().unwrap())
            })
            .filter(|b| {
                let r = Rect { x: b.0 as i32, y: b.1 as i32, width: b.2 as i32, height: b.3 as i32 };
                iou(r, truth) > 0.2
            })
            .collect();
        v.sort();
        let named = err.lines().find(|l| l.starts_with("detect: the configuration's cascades: ")).unwrap_or_default();
        (v, named.to_string())
    };
    let (at_default, named) = run(&[]);
    assert!(named.contains("stop_sign.xml (min_neighbors 3)"), "{named}");
    let m = at_default.iter().map(|b| b.4).max().expect("the stop sign boxed at 1 m");
    assert!(m > 3, "{at_default:?}");
    let set = format!("classes.stop_sign.min_neighbors={m}");
    let (strict, named) = run(&["--set", &set]);
    assert_eq!(strict, vec![], "more than {m} hits needed: no box");
    assert!(named.contains(&format!("stop_sign.xml (min_neighbors {m})")), "{named}");
    let other = format!("classes.traffic_light.min_neighbors={m}");
    assert_eq!(run(&["--set", &other]).0, at_default, "another class's value");
    assert_eq!(run(&["--set", &set, "--min-neighbors", "3"]).0, at_default, "the flag wins");
    println!("rccar detect, stop sign at 1 m: {at_default:?}; none at classes.stop_sign.min_neighbors {m}");
}
