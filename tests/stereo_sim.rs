//! Stereo ranging in the simulator, scored from ground truth (issue 12, "must show" 1): for
//! each object class, distances 0.3–2.0 m and bases 0.06 m and 0.12 m, the shipped cascade
//! (config/cascades, or `RCCAR_CASCADES`) finds the object in the reference (left) image;
//! that detector box is matched along the rows of the right image (NCC) and ranged by
//! (a) Zaarane's Eq. 16 as written, (b) exact angles, (c) b·f/d, next to the monocular tilt
//! ranging of the same box. The truth is the forward distance from the lenses to the face
//! of the object a camera sees. Prints the summary table and one in the form of Zaarane's
//! Table 1 (docs/stereo.md quotes both).
//!
//! Asserted (targets of issue 12, on detector boxes up to 1.5 m): (b) and (c) median
//! relative error ≤ 2 %, max ≤ 5 %; (b) = (c); the object found at ≥ 75 % of the distances.
//! Every class and base is held to those targets. Obstacles (plain coloured boxes) are
//! matched as the pipeline does (`stereo::ranging::match_for_class`): on the two linear
//! colour-opponent planes, then row by row, the distance being the vertical face's
//! (docs/stereo.md: the grey floor's lines, the chroma's whole-pixel edges and the box's top
//! face were the three biases). `RCCAR_STEREO_WHOLE_BOX=1` ranges obstacles by the whole box
//! on the opponent planes (the top face's bias; it is then not within the targets at
//! 0.3–0.5 m). `RCCAR_STEREO_DUMP=dir` writes the pairs and the correlation curves.
//!
//!     cargo test --release --test it stereo_sim:: -- --nocapture

use rccar::config::Config;
use rccar::detect::{CascadeSpec, DetectParams, DetectStage};
use rccar::ranging::ObjectClass;
use rccar::sim::render::RenderOptions;
use rccar::sim::scene::Scene;
use rccar::sim::stereo::StereoRig;
use rccar::sim::track::Track;
use rccar::stereo::matching::Matcher;
use rccar::stereo::ranging::{match_for_class, PairPlanes};
use rccar::stereo::{MatchOptions, StereoGeometry};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The straight of tests/ranging_sim.rs with one object of `kind` 3 m ahead of the start.
fn track(kind: &str) -> Track {
    rccar::sim::scenario_lab::straight_with_object(kind).unwrap()
}

/// One measurement: true forward distance; (a), (b), (c), mono (None = no range).
struct Row {
    truth: f64,
    base: f64,
    est: [Option<f64>; 4],
}

struct Setup {
    cfg: Config,
    stage: DetectStage,
    scene: Arc<Scene>,
    class: ObjectClass,
}

fn setup(kind: &str, class: ObjectClass) -> Option<Setup> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::var("RCCAR_CASCADES").map_or(root.join("config/cascades"), PathBuf::from);
    let path = dir.join(format!("{kind}.xml"));
    if !path.is_file() {
        println!("{kind}: no cascade at {}", path.display());
        return None;
    }
    let stage = DetectStage::load(&[CascadeSpec {
        label: kind.into(),
        path,
        traffic_light: false,
        params: DetectParams::default(),
    }])
    .unwrap();
    let t = track(kind);
    Some(Setup {
        cfg: Config::default(),
        stage,
        scene: Arc::new(Scene::new(&t)),
        class,
    })
}

/// Renders the pair with the lenses `d` metres before the object's face, detects, matches, ranges.
fn measure(s: &mut Setup, base: f64, d: f64, matcher: &mut Matcher) -> Option<Row> {
    let cfg = &s.cfg;
    let mut rig = StereoRig::new(cfg, s.scene.clone(), base, RenderOptions::from_config(&cfg.sim));
    let pose = rccar::sim::scenario_lab::pose_before_object(cfg, &s.scene.track, d).unwrap();
    let (l, r) = rig.render(&pose, 0.0, (1000.0 * d) as u64);
    let truth = rig.truth(&pose, true).into_iter().next()?;
    let found = s.stage.run_rgb(&l).unwrap();
    let tb = truth.bbox.bbox;
    let uc = (tb[0] + tb[2]) / 2.0;
    // The detector's box nearest the true one that overlaps it.
    let b = found
        .iter()
        .filter(|b| {
            let r = b.rect;
            let ix = (tb[2].min((r.x + r.width) as f64) - tb[0].max(r.x as f64)).max(0.0);
            let iy = (tb[3].min((r.y + r.height) as f64) - tb[1].max(r.y as f64)).max(0.0);
            ix * iy > 0.0
        })
        .min_by(|a, b| {
            let ca = (a.rect.x as f64 + a.rect.width as f64 / 2.0 - uc).abs();
            let cb = (b.rect.x as f64 + b.rect.width as f64 / 2.0 - uc).abs();
            ca.total_cmp(&cb)
        })?;
    let rect = b.rect;
    let bbox = [
        rect.x as f64 - 0.5,
        rect.y as f64 - 0.5,
        (rect.x + rect.width) as f64 - 0.5,
        (rect.y + rect.height) as f64 - 0.5,
    ];
    let mono = cfg.box_ranging().range(s.class, bbox).map(|r| r.0);
    let mut planes = PairPlanes::default();
    planes.set(&l, &r);
    let geo = StereoGeometry::ideal(&rig.left.mount().camera, base);
    let opts = MatchOptions {
        max_disparity: cfg.stereo.max_disparity_px,
        min_score: cfg.stereo.min_ncc,
        near_peak_ratio: cfg.stereo.near_peak_ratio,
        ..MatchOptions::default()
    };
    let bx = [rect.x as i64, rect.y as i64, rect.width as i64, rect.height as i64];
    // As the pipeline does (src/stereo/ranging.rs): obstacles on the opponent planes, row by row.
    let found = if std::env::var("RCCAR_STEREO_WHOLE_BOX").is_ok() && s.class == ObjectClass::Obstacle {
        // The whole box on the opponent planes, without the rows (docs/stereo.md: the top face).
        let [a, b] = &planes.opponent;
        matcher.match_planes(&[&a[0], &a[1]], &[&b[0], &b[1]], bx, &opts)
    } else {
        match_for_class(matcher, &geo, &planes, s.class, bx, &opts).map(|(m, face)| {
            if let (Some(f), true) = (face, std::env::var("RCCAR_STEREO_DUMP").is_ok()) {
                println!(
                    "  face base {base} d {d:.1}: {:.3} m from {}/{} rows",
                    f.forward_m, f.rows, f.of
                );
            }
            m
        })
    };
    let est = match found {
        Ok(m) => {
            if let Ok(dir) = std::env::var("RCCAR_STEREO_DUMP") {
                let k = format!("{:?}", s.class);
                l.save(format!("{dir}/l_{k}_{base}_{d}.png")).unwrap();
                r.save(format!("{dir}/r_{k}_{base}_{d}.png")).unwrap();
                println!(
                    "dump {k} base {base} d {d}: rect {rect:?} disparity {:.2} score {:.3} truth box {:?}",
                    m.disparity, m.score, tb
                );
                println!(
                    "scores {:?}",
                    matcher
                        .scores()
                        .iter()
                        .map(|v| (v * 100.0).round() / 100.0)
                        .collect::<Vec<_>>()
                );
            }
            let v = rect.y as f64 + (rect.height as f64 - 1.0) / 2.0;
            let sr = geo.range(&m, v, true).unwrap();
            [sr.forward_m[0], sr.forward_m[1], sr.forward_m[2], mono]
        }
        Err(e) => {
            println!("  base {base} d {d:.1}: no stereo range: {e}");
            [None, None, None, mono]
        }
    };
    Some(Row {
        truth: truth.forward_m,
        base,
        est,
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// (median, max) of |relative error| of method `k` over rows with truth ≤ `upto`.
fn stats(rows: &[Row], k: usize, upto: f64) -> (f64, f64, usize) {
    let e: Vec<f64> = rows
        .iter()
        .filter(|r| r.truth <= upto + 1e-9)
        .filter_map(|r| r.est[k].map(|x| ((x - r.truth) / r.truth).abs()))
        .collect();
    let max = e.iter().copied().fold(f64::NAN, f64::max);
    (median(e.clone()), max, e.len())
}

#[test]
fn stereo_ranging_on_detector_boxes_in_the_simulator() {
    let ds: Vec<f64> = (3..=20).map(|k| k as f64 / 10.0).collect();
    let mut failures = vec![];
    let mut matcher = Matcher::new();
    println!("| class | base m | found | (a) Eq. 16 med/max | (b) exact med/max | (c) b·f/d med/max | mono tilt med/max | (b)/(c) ≤1.5 m med/max |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut table1 = vec![];
    for (kind, class) in [
        ("stop_sign", ObjectClass::StopSign),
        ("traffic_light", ObjectClass::TrafficLight),
        ("obstacle", ObjectClass::Obstacle),
    ] {
        let Some(mut s) = setup(kind, class) else { continue };
        for base in [0.06, 0.12] {
            let rows: Vec<Row> = ds
                .iter()
                .filter_map(|&d| measure(&mut s, base, d, &mut matcher))
                .collect();
            let pct = |x: (f64, f64, usize)| format!("{:.1} / {:.1} %", 100.0 * x.0, 100.0 * x.1);
            let (a, b, c, m) = (
                stats(&rows, 0, 9.0),
                stats(&rows, 1, 9.0),
                stats(&rows, 2, 9.0),
                stats(&rows, 3, 9.0),
            );
            let near_c = stats(&rows, 2, 1.5);
            let near_b = stats(&rows, 1, 1.5);
            let stereo_n = c.2;
            println!(
                "| {kind} | {base:.2} | {}/{} ({} stereo) | {} | {} | {} | {} | {} |",
                rows.len(),
                ds.len(),
                stereo_n,
                pct(a),
                pct(b),
                pct(c),
                pct(m),
                pct(near_c)
            );
            for r in &rows {
                if let (Some(b), Some(c)) = (r.est[1], r.est[2]) {
                    assert!((b - c).abs() < 1e-9 * c, "(b) {b} != (c) {c}");
                }
            }
            let n_near = ds.iter().filter(|&&d| d <= 1.5 + 1e-9).count();
            if (near_c.2 as f64) < 0.75 * n_near as f64 {
                failures.push(format!(
                    "{kind} base {base}: stereo range at {}/{n_near} distances ≤ 1.5 m",
                    near_c.2
                ));
            }
            for (name, st) in [("(b)", near_b), ("(c)", near_c)] {
                if !(st.0 <= 0.02 && st.1 <= 0.05) {
                    failures.push(format!(
                        "{kind} base {base} {name}: median {:.2} %, max {:.2} %",
                        100.0 * st.0,
                        100.0 * st.1
                    ));
                }
            }
        }
        // Zaarane's Table 1: measured (c) at several bases for a few scenes.
        for d in [0.5, 1.0, 1.5, 2.0] {
            let mut cells = vec![];
            let mut truth = f64::NAN;
            for base in [0.03, 0.06, 0.09, 0.12] {
                match measure(&mut s, base, d, &mut matcher) {
                    Some(r) => {
                        truth = r.truth;
                        cells.push(r.est[2].map_or("–".to_string(), |x| format!("{x:.3}")));
                        let _ = r.base;
                    }
                    None => cells.push("not detected".into()),
                }
            }
            table1.push(format!("| {kind} | {} | {truth:.3} |", cells.join(" | ")));
        }
    }
    println!();
    println!("Table 1 form: measured distance (c) b·f/d, metres, by base");
    println!("| scene | 0.03 m | 0.06 m | 0.09 m | 0.12 m | real distance (m) |");
    println!("|---|---|---|---|---|---|");
    for l in &table1 {
        println!("{l}");
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// `[stereo]` is validated like the rest of the configuration.
#[test]
fn stereo_config_is_validated() {
    let mut c = Config::default();
    c.validate().unwrap();
    c.stereo.base_m = 0.0;
    c.stereo.max_disparity_px = 0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("stereo.base_m = 0"), "{e}");
    assert!(e.contains("stereo.max_disparity_px = 0"), "{e}");
    let e = Config::from_toml_str("[stereo]\nreference = \"middle\"\n", "t.toml")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "t.toml: `stereo.reference` = \"middle\": unknown variant `middle`, expected `left` or `right`"
    );
}
