//! The learned pilot (issue 29, must-show 1): the shipped weights (config/pilot.safetensors,
//! trained by `rccar-train pilot` on simulator drives of the PID only; docs/pilot.md) drive
//! the default track with the behaviours on top, and a bad weights file is one clear error.

use rccar::config::Config;
use rccar::control::behaviour::Mode;
use rccar::sim::run::{EndReason, Simulation, StepOutput, Summary};
use rccar::sim::track::Track;
use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Three laps of the default track with the objects' true boxes (the behaviours see every stop
/// sign and light; no cascades, so the run is quick), only the rows the pipeline reads rendered.
fn three_laps(method: &str) -> (Summary, Vec<StepOutput>) {
    let mut cfg = Config::default()
        .with_override("sim.laps=3")
        .unwrap()
        .with_override(&format!("steering.method={method}"))
        .unwrap();
    cfg.resolve_paths(&Path::new(ROOT).join("config"));
    let track = Track::load(&Path::new(ROOT).join("config/tracks/default.toml")).unwrap();
    let mut sim = Simulation::new(&cfg, &track).unwrap();
    sim.set_truth_boxes(true);
    sim.set_full_frames(false);
    let mut steps = Vec::new();
    let s = sim
        .run(|_, st| {
            steps.push(st.clone());
            Ok::<(), ()>(())
        })
        .unwrap();
    (s, steps)
}

/// How often the behaviour machine entered `m`.
fn entered(steps: &[StepOutput], m: Mode) -> usize {
    steps.windows(2).filter(|w| w[0].out.mode != m && w[1].out.mode == m).count()
}

/// Must-show 1: 3 laps, 0 departures, cross-track RMS within 2× the PID's (both measured
/// here, same set-up), the car stands at the stop sign every lap and stops for a red light.
/// Measured with the shipped weights: RMS 0.0079 m (PID 0.0081 m), docs/pilot.md.
#[test]
fn learned_pilot_drives_three_clean_laps_and_obeys_signs_and_lights() {
    let (pid, pid_steps) = three_laps("pid");
    let (nn, nn_steps) = three_laps("learned");
    eprintln!("pid: {pid:?}\nlearned: {nn:?}");
    let (stops, reds) = (entered(&nn_steps, Mode::StopSign), entered(&nn_steps, Mode::RedLight));
    eprintln!(
        "stop-sign stops pid {} learned {stops}; red-light stops pid {} learned {reds}",
        entered(&pid_steps, Mode::StopSign),
        entered(&pid_steps, Mode::RedLight)
    );
    assert_eq!(nn.end, EndReason::LapsDone, "{nn:?}");
    assert!(nn.laps >= 3 && nn.lane_departures == 0, "{nn:?}");
    assert!(
        nn.xte_rms_m <= 2.0 * pid.xte_rms_m,
        "learned RMS {:.4} m, PID {:.4} m",
        nn.xte_rms_m,
        pid.xte_rms_m
    );
    assert_eq!(stops, 3, "one stop at the stop sign per lap");
    // How often the light is red on arrival depends on when the car arrives: the car must
    // stop for it, and a wait ends on green or by the behaviour machine's own rule for a
    // light it no longer sees (`behaviour.light_lost_s`; measured with the shipped weights:
    // 2 waits, one ended on green, one when the standing car's view lost the light's box).
    let after_red: Vec<&str> = nn_steps
        .iter()
        .filter_map(|s| s.transition.as_ref())
        .filter(|t| t.from == Mode::RedLight)
        .map(|t| t.reason.as_str())
        .collect();
    assert!(reds >= 1 && after_red.len() == reds, "red-light stops {reds}, ended {after_red:?}");
    assert!(
        after_red.iter().all(|r| r.contains("green") || r.starts_with("no light seen"))
            && after_red.iter().any(|r| r.contains("green")),
        "{after_red:?}"
    );
    // The car stood still at each stop sign (the hold is the behaviour's, on top of any method).
    let still_at_stop = nn_steps
        .iter()
        .filter(|s| s.out.mode == Mode::StopSign && s.truth.speed_mps.abs() < 0.01)
        .count();
    assert!(still_at_stop as f64 >= 3.0 * 4.0 * 30.0, "{still_at_stop} frames standing at stop signs");
}

/// A missing file, a file that is not a pilot's, and the CLI's message: each names the file.
#[test]
fn a_bad_weights_file_is_one_clear_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let learned = |model: &Path| {
        Config::default()
            .with_override("steering.method=learned")
            .unwrap()
            .with_override(&format!("steering.model={}", model.display()))
            .unwrap()
    };
    let missing = dir.path().join("nope.safetensors");
    let e = learned(&missing).controller().unwrap_err().to_string();
    assert!(e.contains(&missing.display().to_string()) && e.contains("No such file"), "{e}");
    let junk = dir.path().join("junk.safetensors");
    std::fs::write(&junk, b"\x10\0\0\0\0\0\0\0{\"a\": 1}        ").unwrap();
    let e = learned(&junk).controller().unwrap_err().to_string();
    assert!(
        e.starts_with("steering.method = learned: steering.model = ")
            && e.contains(&junk.display().to_string())
            && e.contains("not a pilot written by `rccar-train pilot`"),
        "{e}"
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(["sim", "--seconds", "1", "--set", "steering.method=learned", "--set"])
        .arg(format!("steering.model={}", missing.display()))
        .arg("-o")
        .arg(dir.path().join("run"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains(&missing.display().to_string()) && err.contains("No such file"), "{err}");
}
