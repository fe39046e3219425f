//! Runs the lane detector over the sample frames many times: a target for profilers
//! (`valgrind --tool=callgrind target/release/examples/lane_profile`).
use rccar::config::Config;
use rccar::timing::{NoTimer, StageTimes};

fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let cfg = Config::default();
    let f = image::open(root.join("tests/data/lane_sample/frame_000.png"))
        .unwrap()
        .to_rgb8();
    let mut det = cfg.lane_detector().unwrap();
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(20);
    let mut t = StageTimes::default();
    let mut acc = 0.0;
    for _ in 0..n {
        acc += det.measure(&f, &mut NoTimer, &mut t).lane_center.unwrap_or(0.0);
    }
    println!("{acc}");
}
