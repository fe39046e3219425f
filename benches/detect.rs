//! Haar detection speed, side by side with OpenCV in one run (issue 4).
//!
//! `cargo bench --bench detect [-- --runs N]`
//!
//! 1. A Python helper (`$RCCAR_PYTHON`, else `python3`, with cv2 4.x and scikit-image) writes
//!    the grey test images (scikit-image's astronaut at 512×512, resized to 320×240 and
//!    640×480) and, on request, times `cv2.CascadeClassifier.detectMultiScale(img, 1.1, 3)`
//!    with `cv2.setNumThreads(1)`.
//! 2. Rounds alternate: 3 OpenCV runs, 3 of rccar's [`Detector`] on one thread, 3 with
//!    `parallel = true` (all cores), so all three see the same machine load.
//! 3. For each image: median and minimum of ours and OpenCV's in ms, and the ratio of the
//!    minima (ours / OpenCV; below 1 means faster). Also checks the boxes are the same.

use rccar::detect::{Cascade, DetectParams, Detector};
use std::time::Instant;

#[path = "support/opencv.rs"]
mod opencv;
use opencv::{python, OpenCv};

const CASCADE: &str = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";

const PY: &str = r#"
import cv2, json, sys, time, skimage.data as d
cv2.setNumThreads(1)
out = sys.argv[1]
g = cv2.cvtColor(d.astronaut(), cv2.COLOR_RGB2GRAY)
imgs = {"320x240": cv2.resize(g, (320, 240), interpolation=cv2.INTER_AREA),
        "512x512": g,
        "640x480": cv2.resize(g, (640, 480), interpolation=cv2.INTER_AREA)}
cc = cv2.CascadeClassifier(sys.argv[2])
info = {}
for k, im in imgs.items():
    p = f"{out}/bench_{k}.png"
    cv2.imwrite(p, im)
    r = cc.detectMultiScale(im, 1.1, 3)
    info[k] = {"path": p, "boxes": sorted(map(list, r.tolist())) if len(r) else []}
print(json.dumps(info), flush=True)
for line in sys.stdin:  # "KEY N": time N runs on image KEY, print the times in ms
    k, n = line.split()
    t = []
    for _ in range(int(n)):
        t0 = time.perf_counter(); cc.detectMultiScale(imgs[k], 1.1, 3); t.append((time.perf_counter() - t0) * 1e3)
    print(json.dumps(t), flush=True)
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
        .unwrap_or(15);
    let python = python();
    let dir = std::env::temp_dir().join("rccar_detect_bench");
    std::fs::create_dir_all(&dir).expect("temp dir");
    // 1. The OpenCV helper stays up; we alternate rounds of it and of ours, so that both see
    //    the same machine load (the cores are shared).
    let (mut helper, first) = OpenCv::start(&python, PY, &[dir.to_str().unwrap(), CASCADE]);
    let cv: serde_json::Value =
        serde_json::from_str(&first).expect("helper JSON (is cv2 4.x with scikit-image installed?)");
    let cascade = Cascade::from_file(CASCADE).expect("cascade");
    let mut det = Detector::new(cascade);
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    println!("frontalface_default, scaleFactor 1.1, minNeighbors 3, {runs} runs each, alternating rounds; ms");
    println!(
        "{:>8} | {:>15} | {:>15} | {:>7} | {:>20} | boxes",
        "image",
        "ours med/min",
        "OpenCV med/min",
        "ratio",
        format!("ours {threads} threads")
    );
    for key in ["320x240", "512x512", "640x480"] {
        let c = &cv[key];
        let img = image::open(c["path"].as_str().unwrap()).expect("image").to_luma8();
        let (mut ours, mut par, mut theirs) = (Vec::new(), Vec::new(), Vec::new());
        let mut boxes = Vec::new();
        for p in [false, true] {
            let params = DetectParams {
                parallel: p,
                ..Default::default()
            };
            det.detect(&img, &params).unwrap(); // warm-up: buffers sized once
        }
        // 2. Rounds of 3: OpenCV, ours on one thread, ours on all cores.
        for _ in 0..runs.div_ceil(3) {
            theirs.extend(helper.times(&format!("{key} 3")));
            for (parallel, out) in [(false, &mut ours), (true, &mut par)] {
                let params = DetectParams {
                    parallel,
                    ..Default::default()
                };
                for _ in 0..3 {
                    let t0 = Instant::now();
                    boxes = det.detect(&img, &params).unwrap();
                    out.push(t0.elapsed().as_secs_f64() * 1e3);
                }
            }
        }
        let (om, on) = stats(&mut ours);
        let (pm, pn) = stats(&mut par);
        let (cm, cn) = stats(&mut theirs);
        let mut ob: Vec<Vec<i64>> = boxes
            .iter()
            .map(|d| {
                vec![
                    d.rect.x as i64,
                    d.rect.y as i64,
                    d.rect.width as i64,
                    d.rect.height as i64,
                ]
            })
            .collect();
        ob.sort();
        let cb: Vec<Vec<i64>> = serde_json::from_value(c["boxes"].clone()).unwrap();
        // 3. Report.
        println!(
            "{key:>8} | {om:>7.2}/{on:>7.2} | {cm:>7.2}/{cn:>7.2} | {:>7.3} | {pm:>9.2}/{pn:>9.2} | {}",
            on / cn,
            if ob == cb {
                "same".to_string()
            } else {
                format!("DIFFER: ours {ob:?} OpenCV {cb:?}")
            }
        );
    }
    drop(helper);
}
