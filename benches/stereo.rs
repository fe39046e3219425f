//! Stereo matching speed (issue 12, "must show" 5): one detector-sized box found in the other
//! image of a 320×240 pair and ranged (NCC along the rows + sub-pixel peak + the three
//! distances), side by side with OpenCV's `cv2.matchTemplate(strip, box, TM_CCOEFF_NORMED)` +
//! `cv2.minMaxLoc` on the same search strip, in one run.
//!
//! `cargo bench --bench stereo [-- --runs N]`
//!
//! 1. The simulator's stereo rig (base 0.06 m) renders a stop sign 1 m ahead; its true box in
//!    the left image is the template; the strip is the right image's rows of the box over the
//!    disparity range 0..max_disparity_px (config default 120).
//! 2. A Python helper (`$RCCAR_PYTHON`, else `python3`, with cv2 4.x) loads the same grey
//!    images and times its call with `cv2.setNumThreads(1)`; rounds alternate (20 OpenCV
//!    calls, 20 of ours) so both see the same machine load.
//! 3. Median and minimum in ms of each, their ratio, and both peaks (they must agree).
//!
//! Then tracking versus detection (issue 12, "must show" 3): 30 left frames of the approach
//! to a stop sign of tests/stereo_track.rs (1.5 → 1.3 m); per frame, the stop-sign cascade on
//! the whole frame (detection every frame) against one mean-shift step (`stereo::meanshift`,
//! back-projection of the window's neighbourhood, and of the whole frame), and OpenCV's
//! camshiftdemo recipe `cvtColor(HSV)` + `inRange` + `calcBackProject` + `meanShift` on the
//! whole frame, started from the same box. Also Abdollahi's HSV + template detector per frame.

#[path = "support/opencv.rs"]
mod opencv;

use rccar::classes::ObjectClass;
use rccar::config::Config;
use rccar::detect::gray_from_rgb;
use rccar::sim::render::RenderOptions;
use rccar::sim::scene::Scene;
use rccar::sim::stereo::StereoRig;
use rccar::sim::track::Track;
use rccar::sim::vehicle::Pose;
use rccar::stereo::matching::Matcher;
use rccar::stereo::{MatchOptions, StereoGeometry};
use std::sync::Arc;
use opencv::{python, OpenCv};
use std::time::Instant;

const PY: &str = r#"
import cv2, json, sys, time
cv2.setNumThreads(1)
l = cv2.imread(sys.argv[1], 0); r = cv2.imread(sys.argv[2], 0)
x, y, w, h, dmax = map(int, sys.argv[3:8])
t = l[y:y+h, x:x+w]
x0 = max(0, x - dmax)
strip = r[y:y+h, x0:x+w]
res = cv2.matchTemplate(strip, t, cv2.TM_CCOEFF_NORMED)
_, best, _, loc = cv2.minMaxLoc(res)
print(json.dumps({"disparity": x - (x0 + loc[0]), "score": best}), flush=True)
for line in sys.stdin:
    n = int(line)
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        res = cv2.matchTemplate(r[y:y+h, x0:x+w], t, cv2.TM_CCOEFF_NORMED)
        cv2.minMaxLoc(res)
        ts.append((time.perf_counter() - t0) * 1e3)
    print(json.dumps(ts), flush=True)
"#;

fn stats(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(|a, b| a.total_cmp(b));
    (v[v.len() / 2], v[0])
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(400);
    // 1. The pair and the box.
    let cfg = Config::default();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let track = Track::load(&root.join("config/tracks/default.toml")).expect("default track");
    let scene = Arc::new(Scene::new(&track));
    let mut rig = StereoRig::new(&cfg, scene, 0.06, RenderOptions::from_config(&cfg.sim));
    // The default track's stop sign (x 4.5, y −0.48) about 1 m ahead, on the right.
    let pose = Pose {
        x: 3.26,
        y: -0.15,
        yaw: 0.0,
    };
    let (l, r) = rig.render(&pose, 0.0, 0);
    let truth = rig.truth(&pose, true);
    let b = truth
        .iter()
        .find(|t| t.bbox.kind == ObjectClass::StopSign)
        .expect("stop sign in view")
        .bbox
        .bbox;
    let bx = [
        b[0].round() as i64,
        b[1].round() as i64,
        (b[2] - b[0]).round() as i64,
        (b[3] - b[1]).round() as i64,
    ];
    let (mut gl, mut gr) = (image::GrayImage::new(0, 0), image::GrayImage::new(0, 0));
    gray_from_rgb(&l, &mut gl);
    gray_from_rgb(&r, &mut gr);
    let dir = std::env::temp_dir().join("rccar_stereo_bench");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (pl, pr) = (dir.join("left.png"), dir.join("right.png"));
    gl.save(&pl).expect("write left");
    gr.save(&pr).expect("write right");
    let dmax = cfg.stereo.max_disparity_px;
    let opts = MatchOptions {
        max_disparity: dmax,
        min_score: cfg.stereo.min_ncc,
        near_peak_ratio: 1.0,
        ..MatchOptions::default()
    };
    let geo = StereoGeometry::ideal(&rig.left.mount().camera, 0.06);
    let mut m = Matcher::new();
    let first = m.match_box(&gl, &gr, bx, &opts).expect("match");
    // 2. The helper.
    let python = python();
    let mut args = vec![pl.to_str().unwrap().to_string(), pr.to_str().unwrap().to_string()];
    args.extend(bx.iter().map(|v| v.to_string()));
    args.push(dmax.to_string());
    let (mut helper, cv_first) = OpenCv::start(&python, PY, &args);
    let cv: serde_json::Value = serde_json::from_str(&cv_first).expect("helper JSON (is cv2 4.x installed?)");
    let (mut ours, mut theirs) = (vec![], vec![]);
    let round = 20;
    let mut sink = 0.0;
    while ours.len() < runs {
        theirs.extend(helper.times(&round.to_string()));
        for _ in 0..round {
            let t0 = Instant::now();
            let mm = m.match_box(&gl, &gr, bx, &opts).expect("match");
            let v = bx[1] as f64 + (bx[3] as f64 - 1.0) / 2.0;
            let rg = geo.range(&mm, v, true).expect("range");
            ours.push(t0.elapsed().as_secs_f64() * 1e3);
            sink += rg.depth_bfd;
        }
    }
    drop(helper);
    let (om, omin) = stats(&mut ours);
    let (cm, cmin) = stats(&mut theirs);
    println!(
        "box {}x{} px, search 0..{dmax} px in a 320x240 pair, {} runs each, alternating rounds; ms",
        bx[2],
        bx[3],
        ours.len()
    );
    println!("  rccar match + sub-pixel + 3 ranges: median {om:.4}, min {omin:.4}");
    println!("  cv2.matchTemplate + minMaxLoc:      median {cm:.4}, min {cmin:.4}");
    println!("  ratio of minima (ours / OpenCV): {:.2}", omin / cmin);
    println!(
        "  peak: ours {:.2} px (integer {}), score {:.4}; OpenCV {} px, score {:.4}",
        first.disparity,
        first.disparity.round(),
        first.score,
        cv["disparity"],
        cv["score"].as_f64().unwrap_or(f64::NAN)
    );
    assert!(sink > 0.0);
    for dist in [0.3, 1.0, 2.0] {
        bench_obstacle(&python, runs, dist);
    }
    bench_tracking(&python, runs / 20);
    bench_rectify(&python, &l, &r, runs / 4);
}

const PY_REMAP: &str = r#"
import cv2, json, sys, time
import numpy as np
cv2.setNumThreads(1)
c = json.loads(sys.argv[1])
l = cv2.imread(sys.argv[2]); r = cv2.imread(sys.argv[3])
maps = []
for cam in ("left", "right"):
    k = np.array(c[cam]["k"], dtype=np.float64); d = np.array(c[cam]["d"], dtype=np.float64)
    rr = np.array(c[cam]["r"], dtype=np.float64)
    p = np.array([[c["f"], 0, c["c"][0]], [0, c["f"], c["c"][1]], [0, 0, 1]], dtype=np.float64)
    maps.append(cv2.initUndistortRectifyMap(k, d, rr, p, (l.shape[1], l.shape[0]), cv2.CV_32FC1))
print("ready", flush=True)
for line in sys.stdin:
    # "N" (whole images) or "N y0 y1" (only the output rows y0..y1: the maps' rows sliced).
    n, *band = [int(v) for v in line.split()]
    y0, y1 = band if band else (0, l.shape[0])
    m = [(mx[y0:y1], my[y0:y1]) for mx, my in maps]
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        cv2.remap(l, m[0][0], m[0][1], cv2.INTER_LINEAR)
        cv2.remap(r, m[1][0], m[1][1], cv2.INTER_LINEAR)
        ts.append((time.perf_counter() - t0) * 1e3)
    print(json.dumps(ts), flush=True)
"#;

/// Rectification in the drive loop (`stereo.calibration`, src/stereo/rectify.rs): both colour
/// images of a 320×240 pair remapped through maps built once, against OpenCV's `cv2.remap`
/// (INTER_LINEAR, float maps from `initUndistortRectifyMap` of the same calibration) on the
/// same pair, alternating rounds. The rig: 1° yaw, 0.5° pitch, 0.2° roll, a barrel lens on the
/// right (as tests/stereo_loop.rs).
fn bench_rectify(python: &str, l: &image::RgbImage, r: &image::RgbImage, runs: usize) {
    use rccar::calib::file::{CameraCalibration, StereoCalibration};
    use rccar::calib::intrinsics::{rodrigues, Distortion, Intrinsics};
    use rccar::calib::stereo::{stereo_rectify, to_rows};
    use rccar::stereo::rectify::PairRectifier;
    let cam = |k1: f64| CameraCalibration {
        image_size: [l.width(), l.height()],
        intrinsics: Intrinsics {
            fx: 265.0,
            fy: 265.0,
            cx: 159.5,
            cy: 119.5,
        },
        distortion: Distortion([k1, 0.0, 0.0, 0.0, 0.0]),
        rms_px: 0.0,
        per_image_rms_px: vec![],
        board_not_found: vec![],
    };
    let (cl, cr) = (cam(0.0), cam(-0.05));
    let rot = rodrigues([0.5f64.to_radians(), 1.0f64.to_radians(), 0.2f64.to_radians()]);
    let t = nalgebra::Vector3::new(-0.06, 0.0, 0.0);
    let rc = stereo_rectify(&cl.intrinsics, &cl.distortion, &cr.intrinsics, &cr.distortion, &rot, &t, l.width(), l.height());
    let st = StereoCalibration {
        left: cl.clone(),
        right: cr.clone(),
        r: to_rows(&rot),
        t: [t[0], t[1], t[2]],
        baseline_m: 0.06,
        rms_px: 0.0,
        per_pair_rms_px: vec![],
        pairs_not_used: vec![],
        rectification: rc,
    };
    let t0 = Instant::now();
    let mut rect = PairRectifier::new(&st, true);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let k = |c: &CameraCalibration| {
        let i = c.intrinsics;
        serde_json::json!([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
    };
    let spec = serde_json::json!({
        "left": {"k": k(&cl), "d": cl.distortion.0, "r": rc.r1},
        "right": {"k": k(&cr), "d": cr.distortion.0, "r": rc.r2},
        "f": rc.f, "c": rc.c,
    });
    let dir = std::env::temp_dir().join("rccar_stereo_bench");
    let (pl, pr) = (dir.join("left_rgb.png"), dir.join("right_rgb.png"));
    l.save(&pl).expect("write left");
    r.save(&pr).expect("write right");
    let args = [spec.to_string(), pl.to_str().unwrap().to_string(), pr.to_str().unwrap().to_string()];
    let (mut helper, first) = OpenCv::start(python, PY_REMAP, &args);
    assert_eq!(first, "ready", "OpenCV helper: {first}");
    // The whole pair, then the 40 rows of a stop sign's box at ~0.8 m (what the drive loop
    // rectifies on a frame with one box: `StereoRanging::set_pair_for`).
    let band = 100..140u32;
    let (mut ours, mut theirs, mut ours_band, mut theirs_band) = (vec![], vec![], vec![], vec![]);
    let round = 10;
    while ours.len() < runs.max(round) {
        theirs.extend(helper.times(&round.to_string()));
        theirs_band.extend(helper.times(&format!("{round} {} {}", band.start, band.end)));
        for _ in 0..round {
            let t0 = Instant::now();
            rect.rectify(l, r);
            ours.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        for _ in 0..round {
            let t0 = Instant::now();
            rect.rectify_rows(l, r, band.clone());
            ours_band.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    drop(helper);
    println!();
    println!(
        "rectifying a {}x{} colour pair (stereo.calibration), {} runs each, alternating rounds; ms",
        l.width(),
        l.height(),
        ours.len()
    );
    println!("  maps built once at start-up: {build_ms:.1}");
    for (what, o, c) in [("whole pair", &mut ours, &mut theirs), ("rows 100..140", &mut ours_band, &mut theirs_band)] {
        let (om, omin) = stats(o);
        let (cm, cmin) = stats(c);
        println!("  {what}: rccar PairRectifier median {om:.4}, min {omin:.4}; cv2.remap x 2 (INTER_LINEAR, float maps) median {cm:.4}, min {cmin:.4}; ratio of minima (ours / OpenCV) {:.2}", omin / cmin);
    }
}

/// The obstacle path (`stereo::ranging::match_for_class`): the blue box of
/// tests/stereo_sim.rs 1 m ahead (base 0.06 m), its true box grown by 8 px each way as the
/// detector's are; two opponent planes, the whole box, every row on its own, the vertical
/// face, the three ranges. The pair's conversion (grey + opponent planes, once per frame, not
/// per box) is timed apart.
fn bench_obstacle(python: &str, runs: usize, dist: f64) {
    use rccar::ranging::ObjectClass;
    use rccar::stereo::ranging::{match_for_class, PairPlanes};
    let cfg = Config::default();
    let track = rccar::sim::scenario_lab::straight_with_object("obstacle").expect("road");
    let scene = Arc::new(Scene::new(&track));
    let mut rig = StereoRig::new(&cfg, scene.clone(), 0.06, RenderOptions::from_config(&cfg.sim));
    let pose = rccar::sim::scenario_lab::pose_before_object(&cfg, &scene.track, dist).expect("pose");
    let (l, r) = rig.render(&pose, 0.0, 1000);
    let b = rig.truth(&pose, true)[0].bbox.bbox;
    let (x0, y0) = ((b[0].round() as i64 - 8).max(0), (b[1].round() as i64 - 8).max(0));
    let bx = [
        x0,
        y0,
        ((b[2].round() as i64 + 8).min(l.width() as i64) - x0),
        ((b[3].round() as i64 + 8).min(l.height() as i64) - y0),
    ];
    let opts = MatchOptions {
        max_disparity: cfg.stereo.max_disparity_px,
        min_score: cfg.stereo.min_ncc,
        near_peak_ratio: cfg.stereo.near_peak_ratio,
        ..MatchOptions::default()
    };
    let geo = StereoGeometry::ideal(&rig.left.mount().camera, 0.06);
    let mut planes = PairPlanes::default();
    let mut m = Matcher::new();
    let (mut per_box, mut per_pair) = (vec![], vec![]);
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        planes.set(&l, &r);
        per_pair.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        let (mm, face) = match_for_class(&mut m, &geo, &planes, ObjectClass::Obstacle, bx, &opts).expect("match");
        let v = bx[1] as f64 + (bx[3] as f64 - 1.0) / 2.0;
        let rg = geo.range(&mm, v, true).expect("range");
        per_box.push(t0.elapsed().as_secs_f64() * 1e3);
        last = Some((rg.forward_m[2], face));
    }
    let (bm, bmin) = stats(&mut per_box);
    let (pm, pmin) = stats(&mut per_pair);
    // OpenCV on the same search strip (grey: one plane where ours correlates two).
    let (mut gl, mut gr) = (image::GrayImage::new(0, 0), image::GrayImage::new(0, 0));
    gray_from_rgb(&l, &mut gl);
    gray_from_rgb(&r, &mut gr);
    let dir = std::env::temp_dir().join(format!("rccar_bench_obstacle_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (pl, pr) = (dir.join("left.png"), dir.join("right.png"));
    gl.save(&pl).expect("write left");
    gr.save(&pr).expect("write right");
    let mut args = vec![pl.to_str().unwrap().to_string(), pr.to_str().unwrap().to_string()];
    args.extend(bx.iter().map(|v| v.to_string()));
    args.push(cfg.stereo.max_disparity_px.to_string());
    let (mut helper, _) = OpenCv::start(python, PY, &args);
    let mut theirs = helper.times(&runs.to_string());
    drop(helper);
    let _ = std::fs::remove_dir_all(&dir);
    let (cm, cmin) = stats(&mut theirs);
    println!();
    println!(
        "obstacle box {}x{} px {dist} m ahead (base 0.06 m), opponent planes + rows + vertical face + 3 ranges, {runs} runs; ms",
        bx[2], bx[3]
    );
    println!("  per box:  median {bm:.4}, min {bmin:.4}");
    println!("  cv2.matchTemplate(TM_CCOEFF_NORMED) + minMaxLoc, same strip (grey): median {cm:.4}, min {cmin:.4}");
    println!("  per pair (grey + opponent planes of both images): median {pm:.4}, min {pmin:.4}");
    if let Some((f, face)) = last {
        println!("  forward {:.3} m (truth {dist:.3}), face {face:?}", f.unwrap_or(f64::NAN));
    }
}

const PY_TRACK: &str = r#"
import cv2, json, sys, time, glob
cv2.setNumThreads(1)
files = sorted(glob.glob(sys.argv[1] + "/f*.png"))
frames = [cv2.imread(f) for f in files]
x, y, w, h = map(int, sys.argv[2:6])
hsv = cv2.cvtColor(frames[0], cv2.COLOR_BGR2HSV)
mask = cv2.inRange(hsv, (0, 60, 32), (180, 255, 255))
hist = cv2.calcHist([hsv[y:y+h, x:x+w]], [0], mask[y:y+h, x:x+w], [16], [0, 180])
cv2.normalize(hist, hist, 0, 255, cv2.NORM_MINMAX)
crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 10, 1)
print("ready", flush=True)
for line in sys.stdin:
    n = int(line)
    ts = []
    wins = []
    for _ in range(n):
        win = (x, y, w, h)
        for f in frames[1:]:
            t0 = time.perf_counter()
            hsv = cv2.cvtColor(f, cv2.COLOR_BGR2HSV)
            mask = cv2.inRange(hsv, (0, 60, 32), (180, 255, 255))
            bp = cv2.calcBackProject([hsv], [0], hist, [0, 180], 1)
            bp &= mask
            _, win = cv2.meanShift(bp, win, crit)
            ts.append((time.perf_counter() - t0) * 1e3)
            wins.append(list(win))
    print(json.dumps({"ms": ts, "last": wins[-1]}), flush=True)
"#;

/// Tracking versus detection per frame, with OpenCV's mean shift side by side.
fn bench_tracking(python: &str, rounds: usize) {
    use rccar::detect::{CascadeSpec, DetectParams, DetectStage, Rect};
    use rccar::sim::scenario_lab::{pose_before_object, stop_sign_picture, straight_with_object};
    use rccar::sim::stereo::sign_face_box;
    use rccar::detect::colour_sign::{HsvSignDetector, HsvSignOptions};
    use rccar::stereo::meanshift::{MeanShiftOptions, MeanShiftTracker};
    let cfg = Config::default();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let track = straight_with_object("stop_sign").expect("road");
    let sign = track.enabled_objects().next().expect("sign").clone();
    let mut rig = StereoRig::new(
        &cfg,
        Arc::new(Scene::new(&track)),
        0.06,
        RenderOptions::from_config(&cfg.sim),
    );
    let dir = std::env::temp_dir().join("rccar_track_bench");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut frames = vec![];
    let mut first = Rect::default();
    for k in 0..30 {
        let d = 1.5 - 0.2 * k as f64 / 29.0;
        let pose = pose_before_object(&cfg, &track, d).expect("pose");
        let (l, _) = rig.render(&pose, k as f64 / 30.0, k);
        if k == 0 {
            let (b, _) = sign_face_box(&rig.left, &pose, &sign).expect("sign in view");
            first = Rect::new(
                (b[0] + 0.5).round() as i32,
                (b[1] + 0.5).round() as i32,
                (b[2] - b[0]).round() as i32,
                (b[3] - b[1]).round() as i32,
            );
        }
        l.save(dir.join(format!("f{k:02}.png"))).expect("write frame");
        frames.push(l);
    }
    let mut cascade = DetectStage::load(&[CascadeSpec {
        label: "stop_sign".into(),
        path: root.join("config/cascades/stop_sign.xml"),
        traffic_light: false,
        params: DetectParams::default(),
    }])
    .expect("stop-sign cascade");
    let mut hsv = HsvSignDetector::new(HsvSignOptions::default(), &stop_sign_picture(&cfg)).expect("templates");
    let mut args = vec![dir.to_str().unwrap().to_string()];
    args.extend([first.x, first.y, first.width, first.height].iter().map(|v| v.to_string()));
    let (mut helper, ready) = OpenCv::start(python, PY_TRACK, &args);
    assert_eq!(ready, "ready", "OpenCV helper: {ready}");
    let (mut det, mut ms_local, mut ms_full, mut cv, mut hsv_ms) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut ours_last, mut cv_last) = (first, serde_json::Value::Null);
    for _ in 0..rounds.max(1) {
        let v: serde_json::Value = serde_json::from_str(&helper.ask("1")).expect("helper JSON (is cv2 4.x installed?)");
        cv.extend(v["ms"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()));
        cv_last = v["last"].clone();
        for (search, out) in [(1.0, &mut ms_local), (1e4, &mut ms_full)] {
            let opts = MeanShiftOptions {
                search,
                ..MeanShiftOptions::default()
            };
            let mut tr = MeanShiftTracker::start(&frames[0], first, opts).expect("model");
            for f in &frames[1..] {
                let t0 = Instant::now();
                let w = tr.track(f);
                out.push(t0.elapsed().as_secs_f64() * 1e3);
                ours_last = w;
            }
        }
        for f in &frames[1..] {
            let t0 = Instant::now();
            let n = cascade.run_rgb(f).expect("detect").len();
            det.push(t0.elapsed().as_secs_f64() * 1e3);
            assert!(n < 100);
            let t0 = Instant::now();
            let n = hsv.detect(f).len();
            hsv_ms.push(t0.elapsed().as_secs_f64() * 1e3);
            assert!(n < 100);
        }
    }
    drop(helper);
    let (dm, dmin) = stats(&mut det);
    let (lm, lmin) = stats(&mut ms_local);
    let (fm, fmin) = stats(&mut ms_full);
    let (cm, cmin) = stats(&mut cv);
    let (hm, hmin) = stats(&mut hsv_ms);
    println!();
    println!(
        "tracking vs detection, 29 frames x {} rounds of the approach 1.5 -> 1.3 m (box {}x{} px at the start); ms per frame",
        rounds.max(1),
        first.width,
        first.height
    );
    println!("  stop-sign cascade, whole frame:           median {dm:.4}, min {dmin:.4}");
    println!("  HSV + template detector, whole frame:     median {hm:.4}, min {hmin:.4}");
    println!("  mean shift (window neighbourhood):        median {lm:.4}, min {lmin:.4}");
    println!("  mean shift (whole-frame back-projection): median {fm:.4}, min {fmin:.4}");
    println!("  cv2 cvtColor+inRange+calcBackProject+meanShift, whole frame: median {cm:.4}, min {cmin:.4}");
    let every5 = (dm + 4.0 * lm) / 5.0;
    println!(
        "  detection every 5th frame + mean shift between: {every5:.4} ms/frame on median = {:.1}x less than detection every frame",
        dm / every5
    );
    println!("  last window: ours {ours_last:?}, OpenCV {cv_last}");
}
