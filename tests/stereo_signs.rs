//! Abdollahi's stop-sign detector (HSV threshold + template matching, `detect::colour_sign`)
//! against the shipped Haar cascade (config/cascades/stop_sign.xml, or `RCCAR_CASCADES`) on
//! the same simulated frames (issue 12): the default track with its red-orange obstacle
//! switched on (a red object that is not a sign) and the traffic light cycling through red,
//! the car placed on the driven lane every 2 cm around the whole loop, camera noise on.
//!
//! Scored from the renderer's true boxes: a sign counts (for recall) when it is whole in the
//! image and at least 12 px tall; it is found when a detection overlaps it with IoU ≥ 0.5.
//! A detection overlapping no stop sign (IoU < 0.3 with every one, however small or clipped)
//! is a false positive. Prints the table docs/stereo.md quotes (time per frame is measured
//! here too, median and minimum over the frames, one thread; benches/stereo.rs has the
//! careful timing). A third row: the pipeline's `classes.stop_sign.detect = "colour_template"`
//! (templates from `colour_sign::octagon_model`, options of `[colour_template]`).
//!
//!     cargo test --release --test it stereo_signs:: -- --nocapture

use rccar::config::Config;
use rccar::detect::{CascadeSpec, DetectParams, DetectStage, Rect};
use rccar::ranging::track::iou;
use rccar::sim::render::{CameraMount, RenderOptions, Renderer};
use rccar::sim::scenario_lab::{pose_before_object, stop_sign_picture, straight_with_object};
use rccar::sim::scene::Scene;
use rccar::sim::stereo::sign_face_box;
use rccar::sim::track::Track;
use rccar::sim::vehicle::Pose;
use rccar::detect::colour_sign::{HsvSignDetector, HsvSignOptions};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

fn rect_box(r: Rect) -> [f64; 4] {
    [
        r.x as f64 - 0.5,
        r.y as f64 - 0.5,
        (r.x + r.width) as f64 - 0.5,
        (r.y + r.height) as f64 - 0.5,
    ]
}

#[derive(Default)]
struct Score {
    signs: usize,
    found: usize,
    false_pos: usize,
    frames: usize,
    ms: Vec<f64>,
    ious: Vec<f64>,
}

impl Score {
    fn add(&mut self, truth: &[([f64; 4], bool)], found: &[Rect], ms: f64) {
        self.frames += 1;
        self.ms.push(ms);
        for (t, counts) in truth {
            if !counts {
                continue;
            }
            self.signs += 1;
            let best = found.iter().map(|r| iou(*t, rect_box(*r))).fold(0.0, f64::max);
            if best >= 0.5 {
                self.found += 1;
                self.ious.push(best);
            }
        }
        for r in found {
            if truth.iter().all(|(t, _)| iou(*t, rect_box(*r)) < 0.3) {
                self.false_pos += 1;
                if std::env::var("RCCAR_SIGNS_DUMP").is_ok() {
                    println!("false positive at frame {}: {r:?}", self.frames - 1);
                }
            }
        }
    }
    fn recall(&self) -> f64 {
        self.found as f64 / self.signs.max(1) as f64
    }
    fn fp_per_frame(&self) -> f64 {
        self.false_pos as f64 / self.frames.max(1) as f64
    }
    fn times(&self) -> (f64, f64) {
        let mut v = self.ms.clone();
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[0])
    }
    fn mean_iou(&self) -> f64 {
        self.ious.iter().sum::<f64>() / self.ious.len().max(1) as f64
    }
}

#[test]
fn hsv_template_detector_against_the_cascade_on_the_same_frames() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cfg = Config::default();
    let dir = std::env::var("RCCAR_CASCADES").map_or(root.join("config/cascades"), PathBuf::from);
    let mut cascade = DetectStage::load(&[CascadeSpec {
        label: "stop_sign".into(),
        path: dir.join("stop_sign.xml"),
        traffic_light: false,
        params: DetectParams::default(),
    }])
    .expect("the shipped stop-sign cascade");
    let opts = HsvSignOptions {
        min_score: std::env::var("RCCAR_SIGNS_MIN_SCORE")
            .map_or(HsvSignOptions::default().min_score, |v| v.parse().unwrap()),
        ..HsvSignOptions::default()
    };
    let mut hsv = HsvSignDetector::new(opts, &stop_sign_picture(&cfg)).unwrap();
    // The pipeline's option (`classes.stop_sign.detect = "colour_template"`): templates from
    // the octagon model, not this sign's picture; options of `[colour_template]`, chosen on
    // real photos.
    let mut pipe = HsvSignDetector::with_octagon_model(HsvSignOptions::from(&cfg.colour_template)).unwrap();

    // The default track with its red-orange obstacle in the lane switched on, every 8 cm
    // around the loop; then the straight road with a sign in the lane, 2.5 to 0.3 m away
    // every 2 cm.
    let text = std::fs::read_to_string(root.join("config/tracks/default.toml")).unwrap();
    let text = text.replace("enabled = false", "enabled = true");
    let loop_track = Track::from_toml_str(&text, "default + obstacle").unwrap();
    let straight = straight_with_object("stop_sign").unwrap();
    let mut views: Vec<(Arc<Track>, Pose)> = vec![];
    let lt = Arc::new(loop_track);
    let step = 0.08;
    let n_loop = (lt.length / step) as usize;
    for k in 0..n_loop {
        let (p, yaw) = lt.lane_pose_at(k as f64 * step);
        views.push((lt.clone(), Pose { x: p[0], y: p[1], yaw }));
    }
    let st = Arc::new(straight);
    for k in 0..=110 {
        let d = 2.5 - 0.02 * k as f64;
        views.push((st.clone(), pose_before_object(&cfg, &st, d).unwrap()));
    }
    let mount = CameraMount {
        camera: rccar::camera::PinholeCamera::from(&cfg.camera),
        x_m: cfg.vehicle.camera_x_m,
    };
    let ropts = RenderOptions::from_config(&cfg.sim);
    let mut renderers = [
        Renderer::new(Arc::new(Scene::new(&lt)), mount, ropts.clone()),
        Renderer::new(Arc::new(Scene::new(&st)), mount, ropts),
    ];

    let (mut sc, mut sh, mut sp) = (Score::default(), Score::default(), Score::default());
    let mut frames_with_sign = 0;
    let n = views.len();
    for (k, (track, pose)) in views.iter().enumerate() {
        let r = &mut renderers[(k >= n_loop) as usize];
        let t_s = k as f64 / cfg.camera.fps;
        let img = r.render_new(pose, t_s, k as u64);
        let truth: Vec<([f64; 4], bool)> = track
            .enabled_objects()
            .filter_map(|ob| sign_face_box(r, pose, ob))
            .map(|(b, clipped)| (b, !clipped && b[3] - b[1] >= 12.0))
            .collect();
        frames_with_sign += truth.iter().any(|t| t.1) as usize;
        let t0 = Instant::now();
        let found: Vec<Rect> = cascade.run_rgb(&img).unwrap().into_iter().map(|d| d.rect).collect();
        sc.add(&truth, &found, t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        let dets = hsv.detect(&img);
        let found: Vec<Rect> = dets.iter().map(|d| d.rect).collect();
        sh.add(&truth, &found, t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        let found: Vec<Rect> = pipe.detect(&img).iter().map(|d| d.rect).collect();
        sp.add(&truth, &found, t0.elapsed().as_secs_f64() * 1e3);
        if std::env::var("RCCAR_SIGNS_DUMP").is_ok() && truth.iter().any(|t| t.1) {
            let c: Vec<Rect> = cascade.run_rgb(&img).unwrap().into_iter().map(|d| d.rect).collect();
            println!("frame {k}: truth {truth:?} hsv {dets:?} cascade {c:?}");
        }
    }
    println!(
        "{n} frames: {n_loop} every {step} m around the {:.1} m default loop (its red-orange obstacle on), 111 approaching a sign in the lane 2.5..0.3 m; {frames_with_sign} with a countable sign",
        lt.length
    );
    println!(
        "| detector | recall (IoU ≥ 0.5) | mean IoU of hits | false positives / frame | ms / frame median | min |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, s) in [
        ("Haar cascade (stop_sign.xml)", &sc),
        ("HSV + template (Abdollahi)", &sh),
        ("HSV + octagon model, [colour_template] (the pipeline's)", &sp),
    ] {
        let (med, min) = s.times();
        println!(
            "| {name} | {}/{} = {:.1} % | {:.2} | {:.3} ({} in all) | {med:.2} | {min:.2} |",
            s.found,
            s.signs,
            100.0 * s.recall(),
            s.mean_iou(),
            s.fp_per_frame(),
            s.false_pos
        );
    }
    assert!(frames_with_sign >= 20, "too few frames with a sign: {frames_with_sign}");
    assert!(sh.recall() >= 0.9, "HSV recall {:.3}", sh.recall());
    // The pipeline's option on these held-out renders (its template is not this sign's
    // picture, its options were chosen on real photos): 132/132 at 0 measured.
    assert!(sp.recall() >= 0.9, "octagon model recall {:.3}", sp.recall());
    assert!(
        sp.fp_per_frame() <= 0.01,
        "octagon model false positives per frame {:.3}",
        sp.fp_per_frame()
    );
    assert!(
        sh.fp_per_frame() <= 0.01,
        "HSV false positives per frame {:.3}",
        sh.fp_per_frame()
    );
}
