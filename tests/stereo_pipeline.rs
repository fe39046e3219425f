//! `ranging.method = "stereo"` in the pipeline (issue 12): the stop-sign scenario of
//! tests/behaviour_scenarios.rs (config/tracks/scenarios.toml, the light switched off, start
//! 1 m along the track, the shipped cascades) driven in a closed loop by the simulator's
//! stereo rig (base `[stereo] base_m`, camera noise on): each frame the pair is rendered from
//! the car's pose, `Pipeline::step_stereo` decides, and the simulated vehicle follows the
//! command. The same loop with `ranging.method = "mono"` (`Pipeline::step` on the left image)
//! is the reference. Asserted for both: one stop, at rest within `behaviour.stop_window_m` of
//! the sign (true distance from the lens); for stereo, most sign boxes got a stereo range.
//!
//!     cargo test --release --test it stereo_pipeline:: -- --nocapture

use rccar::classes::ObjectClass;
use rccar::config::{Config, RangingMethod};
use rccar::control::behaviour::Mode;
use rccar::pipeline::Pipeline;
use rccar::sim::render::RenderOptions;
use rccar::sim::scene::Scene;
use rccar::sim::stereo::StereoRig;
use rccar::sim::track::Track;
use rccar::sim::vehicle::{Pose, Vehicle};
use rccar::timing::NoTimer;
use std::path::Path;
use std::sync::Arc;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

struct Run {
    /// True distance lens → sign at the first standstill, metres.
    stopped_at: Option<f64>,
    /// Frames spent in the stop-sign hold.
    hold_frames: usize,
    /// Stereo boxes matched / not matched.
    stereo_counts: (u64, u64),
}

fn run(method: RangingMethod) -> Run {
    let mut cfg = Config::default().with_override("steering.ki=0").unwrap();
    cfg.resolve_paths(&Path::new(ROOT).join("config"));
    cfg.ranging.method = method;
    cfg.validate().unwrap();
    let text = std::fs::read_to_string(Path::new(ROOT).join("config/tracks/scenarios.toml")).unwrap();
    let text = text.replace(
        "cycle_s = [4.0, 1.0, 4.0]",
        "cycle_s = [4.0, 1.0, 4.0]\nenabled = false",
    );
    let track = Track::from_toml_str(&text, "scenarios.toml").unwrap();
    let mut pipeline = Pipeline::new(&cfg).unwrap();
    let (det, missing) = rccar::pipeline::load_detector(&cfg, Path::new(ROOT)).unwrap();
    assert!(missing.is_empty(), "cascades missing: {missing:?}");
    pipeline.set_detector(det);
    let mut rig = StereoRig::new(
        &cfg,
        Arc::new(Scene::new(&track)),
        cfg.stereo.base_m,
        RenderOptions::from_config(&cfg.sim),
    );
    // The car at rest on the lane centre 1 m along the track (as Simulation::place_at).
    let (p, yaw) = track.lane_pose_at(1.0);
    let half = cfg.vehicle.wheelbase_m / 2.0;
    let pose = Pose {
        x: p[0] - half * yaw.cos(),
        y: p[1] - half * yaw.sin(),
        yaw,
    };
    let substeps = cfg.sim.substeps.max(1);
    let dt = 1.0 / cfg.camera.fps;
    let mut car = Vehicle::new(&cfg.vehicle, pose, dt / substeps as f64);
    let mut out = Run {
        stopped_at: None,
        hold_frames: 0,
        stereo_counts: (0, 0),
    };
    let mut moved = false;
    for k in 0..(12.0 * cfg.camera.fps) as usize {
        let t = k as f64 * dt;
        let (l, r) = rig.render(&car.pose, t, k as u64);
        let o = if method == RangingMethod::Stereo {
            pipeline.step_stereo(&l, &r, dt, &mut NoTimer)
        } else {
            pipeline.step(&l, dt, &mut NoTimer)
        };
        for _ in 0..substeps {
            car.step(o.command);
        }
        if o.mode == Mode::StopSign {
            out.hold_frames += 1;
        }
        if std::env::var("RCCAR_STEREO_PIPELINE_DUMP").is_ok() {
            if let Some(s) = o.observations.stop_sign {
                let truth = rig
                    .left
                    .object_boxes(&car.pose)
                    .iter()
                    .filter(|b| b.kind == ObjectClass::StopSign)
                    .map(|b| b.distance_m)
                    .reduce(f64::min);
                println!(
                    "{method} frame {k}: stop sign ranged {:.3} m, truth {truth:?}, mode {:?}, speed {:.3}",
                    s.distance_m, o.mode, car.speed
                );
            }
        }
        moved |= car.speed > 0.2;
        if moved && out.stopped_at.is_none() && car.speed.abs() < cfg.behaviour.standstill_mps {
            out.stopped_at = rig
                .left
                .object_boxes(&car.pose)
                .iter()
                .filter(|b| b.kind == ObjectClass::StopSign)
                .map(|b| b.distance_m)
                .reduce(f64::min);
            // Hold a second, then stop the run.
        }
        if out.stopped_at.is_some() && out.hold_frames as f64 > cfg.camera.fps {
            break;
        }
    }
    out.stereo_counts = pipeline.stereo().map_or((0, 0), |s| s.counts);
    out
}

#[test]
fn stereo_ranging_stops_at_the_sign_like_mono() {
    let cfg = Config::default();
    let w = cfg.behaviour.stop_window_m;
    let mut failures = vec![];
    for method in [RangingMethod::Mono, RangingMethod::Stereo] {
        let r = run(method);
        println!(
            "ranging.method = {method}: at rest {} m from the sign (window {w:?}); stereo boxes matched {} / unmatched {}",
            r.stopped_at.map_or("never".into(), |d| format!("{d:.3}")),
            r.stereo_counts.0,
            r.stereo_counts.1
        );
        match r.stopped_at {
            Some(d) if d >= w[0] && d <= w[1] => {}
            other => failures.push(format!("{method}: stopped at {other:?}")),
        }
        if method == RangingMethod::Stereo && r.stereo_counts.0 < 3 * r.stereo_counts.1.max(1) {
            failures.push(format!("stereo: only {:?} boxes matched / unmatched", r.stereo_counts));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// `ranging.method` is read as one of its spellings; another names the key, the value and the
/// allowed ones.
#[test]
fn ranging_method_is_validated() {
    let e = Config::default()
        .with_override("ranging.method=laser")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "config + command line: `ranging.method` = \"laser\": unknown variant `laser`, expected `mono` or `stereo`"
    );
    let c = Config::default().with_override("ranging.method=stereo").unwrap();
    assert_eq!(c.ranging.method, RangingMethod::Stereo);
    c.validate().unwrap();
}
