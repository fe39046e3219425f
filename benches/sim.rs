//! Simulator benchmark: rendering one 320×240 frame, the pipeline on a rendered frame, and
//! one whole closed-loop step (render + truth + pipeline + vehicle), on one core.
//!
//! Target (issue 5): the full loop at ≥ 20× real time at 30 fps, i.e. ≤ 1.67 ms per step.
//! There is no OpenCV counterpart to compare with (OpenCV renders nothing), so the table
//! compares against that budget instead. Run: `cargo bench --bench sim`.

use rccar::config::Config;
use rccar::pipeline::Pipeline;
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use rccar::timing::NoTimer;
use std::path::Path;
use std::time::Instant;

/// Median and min of `reps` timings of `f`, microseconds.
fn time<F: FnMut()>(reps: usize, mut f: F) -> (f64, f64) {
    for _ in 0..reps / 10 + 1 {
        f();
    }
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    t.sort_by(|a, b| a.total_cmp(b));
    (t[t.len() / 2], t[0])
}

fn main() {
    let cfg = Config::default();
    let track =
        Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).expect("default track");
    let mut sim = Simulation::new(&cfg, &track).expect("sim");
    // Drive a little so the view is a typical one (and warm the caches).
    for _ in 0..60 {
        sim.step(&mut NoTimer);
    }
    let pose = sim.vehicle().pose;
    let mut renderer = sim.renderer().clone();
    let mut img = image::RgbImage::new(cfg.camera.width, cfg.camera.height);
    let mut frame = 0u64;
    let render = time(300, || {
        renderer.render(&pose, 2.0, frame, &mut img);
        frame += 1;
    });
    let mut pipeline = Pipeline::new(&cfg).expect("pipeline");
    let pipe = time(300, || {
        std::hint::black_box(pipeline.step(&img, 1.0 / 30.0, &mut NoTimer));
    });
    let step = time(600, || {
        std::hint::black_box(sim.step(&mut NoTimer));
    });
    let budget = 1e6 / (30.0 * 20.0);
    println!("simulator, 320x240, one core; budget for 20x real time at 30 fps: {budget:.0} us/step");
    println!("{:<28} {:>10} {:>10}", "", "median us", "min us");
    for (name, (med, min)) in [
        ("render one frame", render),
        ("pipeline on a frame", pipe),
        ("closed-loop step", step),
    ] {
        println!("{name:<28} {med:>10.0} {min:>10.0}");
    }
    println!(
        "closed loop: {:.1}x real time at 30 fps (median), target 20x: {}",
        1e6 / (30.0 * step.0),
        if step.0 <= budget { "met" } else { "NOT met" }
    );
}
