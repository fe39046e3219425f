//! The whole frame with detection in the loop (issue 7): lane, the classes' Haar cascades (five since issue 27), ranging,
//! behaviour and control per 320×240 frame, side by side with the same work in OpenCV in the
//! same run.
//!
//! `cargo bench --bench full_frame [-- --reps N] [--parallel]`
//!
//! `--parallel` spreads our pyramid levels over rayon's threads (`RAYON_NUM_THREADS=2` for two);
//! OpenCV stays on one thread, so that ratio is against the same one-thread reference.
//! Besides wall time, both sides report this thread's CPU time per frame (ours from
//! `clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, OpenCV's from `time.thread_time`), which other jobs on a busy
//! machine do not inflate; the one-thread ratio is quoted on both.
//!
//! 1. Frames: 24 simulator frames of config/tracks/scenarios.toml, taken on the approaches to
//!    the stop sign, the traffic light and the obstacle (so the cascades have something to find),
//!    written as PNG for the OpenCV side.
//! 2. Cascades: every class's config/cascades/<name>.xml when all exist (stop_sign,
//!    traffic_light, obstacle, yield_sign, turn_sign), else three stock OpenCV cascades from /usr/share/opencv4/haarcascades (frontalface_default,
//!    eye, fullbody) on both sides: the work per window is similar, the boxes are not meaningful.
//! 3. Ours: `Pipeline::step` on one thread (the detector's `parallel` off).
//!    OpenCV (`$RCCAR_PYTHON`, else `python3`; `cv2.setNumThreads(1)`): warpPerspective → grey →
//!    GaussianBlur → Canny → the configured threshold (threshold, or adaptiveThreshold; then
//!    morphologyEx MORPH_OPEN with `lane.opening`) | edges → column histogram, then grey of the frame and
//!    one `detectMultiScale(gray, scale_factor, min_neighbors, minSize)` per cascade (ranging and the
//!    behaviour machine are a few µs and have no OpenCV counterpart).
//! 4. Prints median and min per frame of both, and the ratios (ours / OpenCV).

use rccar::classes::ObjectClass;
use rccar::config::Config;
use rccar::pipeline::Pipeline;
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use rccar::timing::NoTimer;
use std::path::{Path, PathBuf};
use std::time::Instant;

const STOCK: [&str; 3] = [
    "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml",
    "/usr/share/opencv4/haarcascades/haarcascade_eye.xml",
    "/usr/share/opencv4/haarcascades/haarcascade_fullbody.xml",
];

const PY: &str = r#"
import cv2, json, sys, time
import numpy as np
a = json.loads(sys.argv[1])
cv2.setNumThreads(1)
W, H, band = a["out_w"], a["out_h"], a["band_rows"]
M = np.array(a["bird_to_camera"], dtype=np.float64).reshape(3, 3)
frames = [cv2.cvtColor(cv2.imread(p, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for p in a["frames"]]
ccs = [cv2.CascadeClassifier(p) for p in a["cascades"]]
ms = a["min_size"]
flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
open_k = np.ones((max(1, a["opening"]),) * 2, np.uint8)
lane_t, total_t, cpu_t = [], [], []
def frame(rgb):
    c0 = time.thread_time()
    t0 = time.perf_counter()
    bird = cv2.cvtColor(cv2.warpPerspective(rgb, M, (W, H), flags=flags), cv2.COLOR_RGB2GRAY)
    edges = cv2.Canny(cv2.GaussianBlur(bird, (5, 5), 0), a["canny_low"], a["canny_high"], L2gradient=False)
    if a["mode"] == "adaptive":
        thr = cv2.adaptiveThreshold(bird, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, a["block"], a["c"])
    elif a["mode"] == "otsu":
        _, thr = cv2.threshold(bird, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    else:
        _, thr = cv2.threshold(bird, a["threshold"], 255, cv2.THRESH_BINARY)
    if a["opening"] > 1:
        thr = cv2.morphologyEx(thr, cv2.MORPH_OPEN, open_k)
    binary = cv2.bitwise_or(thr, edges)
    hist = cv2.reduce((binary[H - band:] > 0).view(np.uint8), 0, cv2.REDUCE_SUM, dtype=cv2.CV_32S)
    t1 = time.perf_counter()
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    for cc in ccs:
        cc.detectMultiScale(gray, a["scale_factor"], a["min_neighbors"], minSize=(ms, ms))
    t2 = time.perf_counter()
    return t1 - t0, t2 - t0, time.thread_time() - c0
for rgb in frames:
    frame(rgb)
for _ in range(a["reps"]):
    for rgb in frames:
        l, t, c = frame(rgb)
        lane_t.append(l); total_t.append(t); cpu_t.append(c)
print(json.dumps({"opencv": cv2.__version__, "lane": lane_t, "total": total_t, "cpu": cpu_t}))
"#;

#[path = "support/cpu.rs"]
mod cpu;

/// This thread's CPU time, seconds ([`cpu::thread_cpu_ns`]).
fn cpu_s() -> Option<f64> {
    cpu::thread_cpu_ns().map(|ns| ns as f64 * 1e-9)
}

fn median_min(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

/// rayon's thread count (1 without the `parallel` feature).
fn rayon_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = args
        .iter()
        .position(|a| a == "--reps")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let parallel = args.iter().any(|a| a == "--parallel");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cfg = Config::default();
    cfg.sim.noise_sigma = 2.0;
    // Detection on every frame, as the OpenCV side (the car's default detects on every 2nd
    // frame, which would halve our figure without like work on the other side).
    cfg.detect.every_n_frames = 1;
    // 1. Frames on the three approaches.
    let track = Track::load(&root.join("config/tracks/scenarios.toml")).expect("scenarios track");
    let dir = std::env::temp_dir().join("rccar_full_frame_bench");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut paths = vec![];
    let mut frames = vec![];
    for (k, s) in [
        2.6, 2.8, 3.0, 3.2, 3.4, 3.6, 3.8, 4.0, 35.0, 35.2, 35.4, 35.6, 35.8, 36.0, 36.2, 36.4, 36.8, 37.0, 37.2, 37.4,
        37.6, 37.8, 20.0, 28.0,
    ]
    .iter()
    .enumerate()
    {
        let mut sim = Simulation::new(&cfg, &track).unwrap();
        sim.place_at(*s);
        sim.step();
        let p = dir.join(format!("frame_{k:02}.png"));
        sim.image().save(&p).unwrap();
        paths.push(p);
        frames.push(sim.image().clone());
    }
    // 2. Cascades.
    let shipped: Vec<PathBuf> = cfg
        .classes
        .iter()
        .map(|(_, k)| root.join("config").join(&k.model))
        .collect();
    let cascades: Vec<PathBuf> = if shipped.iter().all(|p| p.is_file()) {
        shipped
    } else {
        STOCK.iter().map(PathBuf::from).collect()
    };
    let stock = cascades[0].starts_with("/usr");
    for (class, file) in ObjectClass::ALL.into_iter().zip(&cascades) {
        cfg.classes[class].model = file.display().to_string();
    }
    let (det, missing) = rccar::pipeline::load_detector(&cfg, &root.join("config")).expect("cascades load");
    assert!(missing.is_empty(), "missing cascades {missing:?}");
    let mut det = det;
    if let Some(d) = &mut det {
        d.set_parallel(parallel);
    }
    let mut pipe = Pipeline::new(&cfg).unwrap();
    pipe.set_detector(det);
    // 3. Ours.
    let dt = 1.0 / cfg.camera.fps;
    for f in &frames {
        pipe.step(f, dt, &mut NoTimer);
    }
    let mut ours = vec![];
    let mut ours_cpu = vec![];
    let mut found = 0usize;
    for _ in 0..reps {
        for f in &frames {
            let c0 = cpu_s();
            let t0 = Instant::now();
            std::hint::black_box(pipe.step(f, dt, &mut NoTimer));
            ours.push(t0.elapsed().as_secs_f64());
            if let (Some(a), Some(b)) = (c0, cpu_s()) {
                ours_cpu.push(b - a);
            }
            found += pipe.objects().len();
        }
    }
    let mut lane_only = Pipeline::new(&cfg).unwrap();
    let mut ours_lane = vec![];
    for _ in 0..reps {
        for f in &frames {
            let t0 = Instant::now();
            std::hint::black_box(lane_only.step(f, dt, &mut NoTimer));
            ours_lane.push(t0.elapsed().as_secs_f64());
        }
    }
    // OpenCV.
    let m = pipe.lane().warp_map().homography().inverse().unwrap().0;
    let inv: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
    let req = serde_json::json!({
        "frames": paths, "cascades": cascades, "bird_to_camera": inv,
        "out_w": cfg.warp.out_width, "out_h": cfg.warp.out_height,
        "band_rows": pipe.lane().images().band_rows, "reps": reps,
        "canny_low": cfg.lane.canny_low, "canny_high": cfg.lane.canny_high, "threshold": cfg.lane.threshold,
        "mode": match cfg.lane.threshold_mode {
            rccar::config::ThresholdMode::Adaptive => "adaptive",
            rccar::config::ThresholdMode::Otsu => "otsu",
            rccar::config::ThresholdMode::Fixed => "fixed",
        },
        "block": cfg.lane.adaptive_block, "c": cfg.lane.adaptive_c, "opening": cfg.lane.opening,
        "scale_factor": cfg.detect.scale_factor, "min_neighbors": cfg.detect.min_neighbors,
        "min_size": cfg.detect.min_size_px,
    });
    let py = std::env::var("RCCAR_PYTHON").unwrap_or_else(|_| "python3".into());
    let cv = std::process::Command::new(&py)
        .arg("-c")
        .arg(PY)
        .arg(req.to_string())
        .output();
    let cv: Option<serde_json::Value> = cv
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| serde_json::from_slice(&o.stdout).ok());
    // 4. Report.
    println!(
        "full frame: {} frames of {}x{}, {} reps, {}; cascades: {} ({})",
        frames.len(),
        cfg.camera.width,
        cfg.camera.height,
        reps,
        if parallel {
            format!("ours on {} threads (OpenCV on one)", rayon_threads())
        } else {
            "one thread".to_string()
        },
        if stock {
            "STOCK OpenCV (shipped ones missing)"
        } else {
            "shipped config/cascades"
        },
        cascades
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let (om, on) = median_min(&mut ours);
    let (lm, ln) = median_min(&mut ours_lane);
    println!(
        "  ours   lane only (+behaviour)          median {:8.3} ms  min {:8.3} ms",
        lm * 1e3,
        ln * 1e3
    );
    println!(
        "  ours   lane + {} cascades + ranging + behaviour: median {:8.3} ms  min {:8.3} ms ({} boxes over the reps)",
        cascades.len(),
        om * 1e3,
        on * 1e3,
        found
    );
    match cv {
        Some(cv) => {
            let get = |k: &str| -> Vec<f64> { cv[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect() };
            let (cm, cn) = median_min(&mut get("total"));
            let (clm, cln) = median_min(&mut get("lane"));
            println!(
                "  opencv {} lane ops                     median {:8.3} ms  min {:8.3} ms",
                cv["opencv"],
                clm * 1e3,
                cln * 1e3
            );
            println!(
                "  opencv lane + {} detectMultiScale           median {:8.3} ms  min {:8.3} ms",
                cascades.len(),
                cm * 1e3,
                cn * 1e3
            );
            println!(
                "ratio ours/OpenCV (full frame): median {:.2}, min {:.2}",
                om / cm,
                on / cn
            );
            let cv_cpu: Vec<f64> = cv["cpu"]
                .as_array()
                .map_or(vec![], |a| a.iter().filter_map(|x| x.as_f64()).collect());
            if !parallel && !ours_cpu.is_empty() && !cv_cpu.is_empty() {
                let (ocm, ocn) = median_min(&mut ours_cpu);
                let (ccm, ccn) = median_min(&mut cv_cpu.clone());
                println!(
                    "  CPU time per frame: ours median {:.3} ms min {:.3} ms; opencv median {:.3} ms min {:.3} ms",
                    ocm * 1e3,
                    ocn * 1e3,
                    ccm * 1e3,
                    ccn * 1e3
                );
                println!(
                    "ratio ours/OpenCV (full frame, CPU time): median {:.2}, min {:.2}",
                    ocm / ccm,
                    ocn / ccn
                );
            }
            println!(
                "ratio ours/OpenCV (lane only):  median {:.2}, min {:.2}",
                lm / clm,
                ln / cln
            );
            println!(
                "frame budget at {} fps: {:.1} ms; ours uses {:.0}%",
                cfg.camera.fps,
                1e3 / cfg.camera.fps,
                100.0 * om * cfg.camera.fps
            );
        }
        None => println!("OpenCV reference not available ({py} with cv2 failed)"),
    }
}
