//! `cargo bench --bench lane`: the lane pipeline per stage on 320×240 frames, side by side
//! with OpenCV 4.x doing the same stages (single-threaded, same frames, same run), and the
//! ratio ours / OpenCV's. Also checks that steady state allocates nothing per frame.
//!
//! The OpenCV side runs tests/parity/lane_bench.py with `$RCCAR_PYTHON` (or `python3`).
//! Flags after `--`: `--reps N` (default 30), `--quick` (5 reps).

use rccar::config::Config;
use rccar::timing::{StageTimer, StageTimes};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Counts allocations, to prove the steady state allocates nothing.
struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

struct Warm;
impl StageTimer for Warm {
    fn lap_us(&mut self) -> u32 {
        0
    }
    fn beside(&self) -> Box<dyn StageTimer> {
        Box::new(Warm)
    }
}

fn median_min(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps = if args.iter().any(|a| a == "--quick") {
        5
    } else {
        args.iter()
            .position(|a| a == "--reps")
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(30)
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cfg_path = root.join("config/car.toml");
    let cfg = Config::load(&cfg_path, &[], &[]).expect("config/car.toml loads");
    let mut frames_paths: Vec<_> = std::fs::read_dir(root.join("tests/data/lane_sample"))
        .expect("sample frames")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    frames_paths.sort();
    let frames: Vec<_> = frames_paths.iter().map(|p| image::open(p).unwrap().to_rgb8()).collect();
    let mut det = cfg.lane_detector().unwrap();

    // Ours: each stage timed separately with a real clock, averaged over all frames per rep.
    struct Clock(Instant);
    impl StageTimer for Clock {
        fn lap_us(&mut self) -> u32 {
            let n = Instant::now();
            let d = n.duration_since(self.0).as_nanos() as u32;
            self.0 = n;
            d // nanoseconds, despite the name: the bench wants finer than µs
        }
        fn beside(&self) -> Box<dyn StageTimer> {
            Box::new(Clock(Instant::now()))
        }
    }
    let names = [
        "warp+gray",
        "canny (blur+sobel+nms+hyst)",
        "threshold|edges",
        "histogram",
        "lines",
    ];
    let mut ours: Vec<Vec<f64>> = (0..=names.len()).map(|_| Vec::with_capacity(reps)).collect();
    let mut times = StageTimes::default();
    for f in &frames {
        det.measure(f, &mut Warm, &mut times); // warm up
    }
    let allocs_before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..reps {
        let mut acc = [0f64; 6];
        for f in &frames {
            let mut clock = Clock(Instant::now());
            let t0 = Instant::now();
            det.measure(f, &mut clock, &mut times);
            acc[5] += t0.elapsed().as_secs_f64();
            for (k, v) in [
                times.warp_us,
                times.canny_us,
                times.threshold_us,
                times.histogram_us,
                times.lines_us,
            ]
            .iter()
            .enumerate()
            {
                acc[k] += *v as f64 * 1e-9;
            }
        }
        for k in 0..6 {
            ours[k].push(acc[k] / frames.len() as f64);
        }
    }
    let allocs = ALLOCS.load(Ordering::Relaxed) - allocs_before;
    // The adaptive threshold's stage (lane.threshold_mode = "adaptive"), beside the fixed one.
    let mut adet = cfg
        .with_override("lane.threshold_mode=adaptive")
        .unwrap()
        .lane_detector()
        .unwrap();
    for f in &frames {
        adet.measure(f, &mut Warm, &mut times);
    }
    let mut adaptive: Vec<f64> = (0..reps)
        .map(|_| {
            let mut acc = 0.0;
            for f in &frames {
                adet.measure(f, &mut Clock(Instant::now()), &mut times);
                acc += times.threshold_us as f64 * 1e-9;
            }
            acc / frames.len() as f64
        })
        .collect();

    // OpenCV: the same stages in Python, same frames.
    let m = det.warp_map().homography().inverse().unwrap().0;
    let inv: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
    let req = serde_json::json!({
        "config": cfg_path, "frames": frames_paths, "bird_to_camera": inv,
        "band_rows": det.images().band_rows, "reps": reps,
    });
    let py = std::env::var("RCCAR_PYTHON").unwrap_or_else(|_| "python3".into());
    let cv = std::process::Command::new(&py)
        .arg(root.join("tests/parity/lane_bench.py"))
        .arg(req.to_string())
        .output();
    let cv: Option<serde_json::Value> = cv
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| serde_json::from_slice(&o.stdout).ok());

    println!(
        "lane pipeline, {} frames of {}x{}, {} reps, single thread (µs per frame: median / min)",
        frames.len(),
        cfg.camera.width,
        cfg.camera.height,
        reps
    );
    for (k, n) in names.iter().enumerate() {
        let (med, min) = median_min(&mut ours[k]);
        println!("  ours   {n:30} {:8.1} / {:8.1}", med * 1e6, min * 1e6);
    }
    let (a_med, a_min) = median_min(&mut adaptive);
    println!(
        "  ours   {:30} {:8.1} / {:8.1}",
        "adaptive threshold|edges",
        a_med * 1e6,
        a_min * 1e6
    );
    let (our_med, our_min) = median_min(&mut ours[5]);
    println!(
        "  ours   {:30} {:8.1} / {:8.1}",
        "TOTAL warp -> lanes",
        our_med * 1e6,
        our_min * 1e6
    );
    println!(
        "  steady-state allocations in {} measured frames: {allocs}",
        reps * frames.len()
    );
    match cv {
        Some(cv) => {
            let stages = &cv["stages"];
            println!("OpenCV {} (cv2.setNumThreads(1)):", cv["opencv"].as_str().unwrap_or("?"));
            for k in ["warp", "gray", "blur", "canny", "threshold", "histogram", "adaptive"] {
                let mut v: Vec<f64> = stages[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
                let (med, min) = median_min(&mut v);
                println!("  opencv {k:30} {:8.1} / {:8.1}", med * 1e6, min * 1e6);
            }
            let mut v: Vec<f64> = stages["total"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            let (cv_med, cv_min) = median_min(&mut v);
            println!("  opencv {:30} {:8.1} / {:8.1}", "TOTAL warp -> lanes", cv_med * 1e6, cv_min * 1e6);
            println!("ratio ours/OpenCV: median {:.2}, min {:.2} (target <= 0.5)", our_med / cv_med, our_min / cv_min);
        }
        None => println!("OpenCV reference not available ({py} tests/parity/lane_bench.py failed): install tests/parity/requirements.txt"),
    }
}
