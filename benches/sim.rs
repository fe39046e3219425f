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

#[path = "support/cpu.rs"]
mod cpu;
use cpu::thread_cpu_ns as cpu_ns;

/// Median and min of `reps` wall-clock timings of `f`, and the mean CPU time, microseconds.
fn time<F: FnMut()>(reps: usize, mut f: F) -> (f64, f64, Option<f64>) {
    for _ in 0..reps / 10 + 1 {
        f();
    }
    let cpu0 = cpu_ns();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    let cpu = cpu0.zip(cpu_ns()).map(|(a, b)| (b - a) as f64 / 1e3 / reps as f64);
    t.sort_by(|a, b| a.total_cmp(b));
    (t[t.len() / 2], t[0], cpu)
}

fn main() {
    let cfg = Config::default();
    let track =
        Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).expect("default track");
    let mut sim = Simulation::new(&cfg, &track).expect("sim");
    // Drive a little so the view is a typical one (and warm the caches).
    for _ in 0..60 {
        sim.step();
    }
    let pose = sim.vehicle().pose;
    let mut renderer = sim.renderer().clone();
    let mut img = image::RgbImage::new(cfg.camera.width, cfg.camera.height);
    let mut frame = 0u64;
    let render = time(300, || {
        renderer.render(&pose, 2.0, frame, &mut img);
        frame += 1;
    });
    // A view with no object in it: the floor and walls alone.
    let (p, yaw) = track.lane_pose_at(20.0);
    let bare = rccar::sim::vehicle::Pose { x: p[0], y: p[1], yaw };
    let render_bare = time(300, || {
        renderer.render(&bare, 2.0, frame, &mut img);
        frame += 1;
    });
    renderer.render(&pose, 2.0, frame, &mut img);
    let mut pipeline = Pipeline::new(&cfg).expect("pipeline");
    let pipe = time(300, || {
        std::hint::black_box(pipeline.step(&img, 1.0 / 30.0, &mut NoTimer));
    });
    // Detection on (issue 13): the pipeline with the shipped cascades (regions and size
    // limits from [detect]), and the render of only the rows it reads (`rows_needed`).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (det, _) = rccar::pipeline::load_detector(&cfg, &root.join("config")).expect("cascades");
    let mut pipeline_det = Pipeline::new(&cfg).expect("pipeline");
    pipeline_det.set_detector(det);
    let has_det = pipeline_det.has_detector();
    let pipe_det = time(300, || {
        std::hint::black_box(pipeline_det.step(&img, 1.0 / 30.0, &mut NoTimer));
    });
    let spans = pipeline_det.rows_needed(0);
    let lane_spans = {
        let r = pipeline_det.lane().warp_map().src_rows();
        let r = r.start as usize..r.end as usize;
        vec![r]
    };
    let mut img2 = img.clone();
    let render_needed = time(300, || {
        for r in &spans {
            renderer.render_rows(&pose, 2.0, frame, &mut img2, r.clone());
        }
        frame += 1;
    });
    let render_lane = time(300, || {
        for r in &lane_spans {
            renderer.render_rows(&pose, 2.0, frame, &mut img2, r.clone());
        }
        frame += 1;
    });
    let step = time(600, || {
        std::hint::black_box(sim.step());
    });
    sim.set_full_frames(false);
    let step_roi = time(600, || {
        std::hint::black_box(sim.step());
    });
    // The closed loop as `rccar sim` runs it (issue 13): the shipped cascades on every
    // `detect.every_n_frames`-th frame, only the rows the pipeline reads rendered on each frame
    // (`Pipeline::row_plan`). 900 steps (30 s) from the start of the default track, past the
    // stop sign; the mean over them (detection and lane-only frames alternate).
    let (det2, _) = rccar::pipeline::load_detector(&cfg, &root.join("config")).expect("cascades");
    let mut sim_det = Simulation::new(&cfg, &track).expect("sim");
    sim_det.set_detector(det2);
    sim_det.set_full_frames(false);
    let (cpu0, t0) = (cpu_ns(), Instant::now());
    let n_det = 900;
    for _ in 0..n_det {
        std::hint::black_box(sim_det.step());
    }
    let wall_det = t0.elapsed().as_secs_f64() * 1e6 / n_det as f64;
    let cpu_det = cpu0.zip(cpu_ns()).map(|(a, b)| (b - a) as f64 / 1e3 / n_det as f64);
    let budget = 1e6 / (30.0 * 20.0);
    println!("simulator, 320x240, one core; budget for 20x real time at 30 fps: {budget:.0} us/step");
    println!("{:<28} {:>10} {:>10} {:>12}", "", "median us", "min us", "mean CPU us");
    let rows: usize = spans.iter().map(|r| r.len()).sum();
    for (name, (med, min, cpu)) in [
        ("render one frame", render),
        ("render, no object in view", render_bare),
        ("render rows_needed (detect)", render_needed),
        ("render lane ROI rows only", render_lane),
        ("pipeline on a frame", pipe),
        ("pipeline + 3 cascades", pipe_det),
        ("closed-loop step", step),
        ("step, only the ROI's rows", step_roi),
    ] {
        let cpu = cpu.map_or("-".to_string(), |c| format!("{c:.0}"));
        println!("{name:<28} {med:>10.0} {min:>10.0} {cpu:>12}");
    }
    // With detection: render what the pipeline reads + pipeline with cascades + the rest of a
    // step (truth, vehicle: a full step minus its render and lane-only pipeline).
    let cpu_or = |t: (f64, f64, Option<f64>)| t.2.unwrap_or(t.0);
    let rest = (cpu_or(step) - cpu_or(render) - cpu_or(pipe)).max(0.0);
    let with_det = cpu_or(render_needed) + cpu_or(pipe_det) + rest;
    println!(
        "detection {}: rows_needed = {spans:?} ({rows} of {} rows); step estimate {with_det:.0} us = render {:.0} + pipeline {:.0} + rest {rest:.0}: {:.1}x real time at 30 fps (target 10x: {})",
        if has_det { "on" } else { "OFF (cascades missing)" },
        cfg.camera.height,
        cpu_or(render_needed),
        cpu_or(pipe_det),
        1e6 / (30.0 * with_det),
        if 1e6 / (30.0 * with_det) >= 10.0 { "met" } else { "NOT met" }
    );
    let per = cpu_det.unwrap_or(wall_det);
    println!(
        "closed loop with detection (every {} frames, rows per frame), {n_det} steps: mean {wall_det:.0} us wall, {} us CPU per step = {:.1}x real time by wall, {:.1}x by CPU time; target 10x: {}",
        cfg.detect.every_n_frames,
        cpu_det.map_or("-".to_string(), |c| format!("{c:.0}")),
        1e6 / (30.0 * wall_det),
        1e6 / (30.0 * per),
        if 1e6 / (30.0 * per) >= 10.0 { "met" } else { "NOT met" }
    );
    // CPU time is what one core spends; wall time also counts waiting for a busy machine.
    for (name, st) in [("full frames", step), ("ROI rows only", step_roi)] {
        let per_step = st.2.unwrap_or(st.0);
        println!(
            "closed loop, {name}: {:.1}x real time at 30 fps (median wall), {:.1}x by CPU time; target 20x: {}",
            1e6 / (30.0 * st.0),
            1e6 / (30.0 * per_step),
            if per_step <= budget { "met" } else { "NOT met" }
        );
    }
}
