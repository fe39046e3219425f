//! The tools the labs use (issue 14), end to end through the `rccar` binary, run from outside
//! the repository: a 2 × 2 gain grid (`sim --sweep A --sweep B`: sweep.csv and the heat map),
//! a step response from a start offset and from a kick (`--start-offset`, `--kick`), `rccar
//! plot` on their telemetry (and its errors), and `rccar report` on a run's folder.
//!
//! Tolerances: the step response of the default gains from 5 cm off-centre (car starting from
//! rest) rises in 2.4 s with 3 % overshoot and settles in 3.4 s (measured); the test accepts
//! rise 1.5–3.5 s, overshoot 0–15 %, settling 2–6 s, so it catches a broken measure or a
//! broken loop but not a retuned gain. About 25 s in release on 2 cores.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `rccar ARGS` from `dir` with the repository's config and no local overrides.
fn rccar(dir: &Path, args: &[&str]) -> Output {
    let cfg = root().join("config/car.toml");
    Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(dir)
        .env("RCCAR_CONFIG", &cfg)
        .args(args)
        .output()
        .expect("run rccar")
}

fn text(o: &Output) -> String {
    format!(
        "status {:?}\n--- stdout\n{}\n--- stderr\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A PNG that decodes, with its size.
fn png_size(p: &Path) -> (u32, u32) {
    let bytes = std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}: not a PNG", p.display());
    let img = image::load_from_memory(&bytes).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    (img.width(), img.height())
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
}

/// How `rccar report` shows a number (4 decimals, trailing zeros cut).
fn shown(v: f64) -> String {
    let s = format!("{v:.4}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[test]
fn grid_step_plot_and_report() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();

    // 1. A 2 × 2 grid: 4 rows with the right key values, a 1000 × 720 heat map.
    let o = rccar(
        d,
        &[
            "sim", "--no-local", "--seconds", "4", "--jobs", "2", "--out", "grid",
            "--sweep", "steering.kp=0.8:1.2:2", "--sweep", "steering.kd=0:0.1:2",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(d.join("grid/sweep.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&head[..4], &["steering.kp", "steering.kd", "laps", "lap_time_s"], "{csv}");
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines.map(|l| l.split(',').map(String::from).collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let want = [(0.8, 0.0), (0.8, 0.1), (1.2, 0.0), (1.2, 0.1)];
    for (r, (kp, kd)) in rows.iter().zip(want) {
        let f = |i: usize| r[i].parse::<f64>().unwrap();
        assert!((f(0) - kp).abs() < 1e-9 && (f(1) - kd).abs() < 1e-9, "{r:?}");
        // 4 s from rest on the start straight: the car stays within a centimetre.
        let rms = f(col("xte_rms_m"));
        assert!((0.0..0.01).contains(&rms), "{r:?}");
        assert!(f(col("steer_diff_rms")) >= 0.0 && f(col("departures")) == 0.0, "{r:?}");
        assert_eq!(r[col("end")], "time_up");
    }
    assert_eq!(png_size(&d.join("grid/sweep_grid.png")), (1000, 720));

    // 2. Step response from 5 cm left of the lane centre.
    let o = rccar(
        d,
        &[
            "sim", "--no-local", "--no-timing", "--seconds", "10", "--laps", "0", "--set", "detect.enabled=false",
            "--start-offset", "0.05", "--out", "step",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("rise time 10→90 %") && out.contains("settling time"), "{out}");
    let s = json(&d.join("step/summary.json"));
    let st = &s["step"];
    assert!((st["initial_offset_m"].as_f64().unwrap() - 0.05).abs() < 1e-3, "{st}");
    let rise = st["rise_time_s"].as_f64().expect("rise time");
    let over = st["overshoot_pct"].as_f64().unwrap();
    let settle = st["settling_time_s"].as_f64().expect("settled");
    assert!((1.5..3.5).contains(&rise), "rise {rise}");
    assert!((0.0..15.0).contains(&over), "overshoot {over}");
    assert!((2.0..6.0).contains(&settle) && settle > rise, "settling {settle}");
    assert!((st["band_m"].as_f64().unwrap() - 0.0025).abs() < 1e-9);
    assert_eq!(png_size(&d.join("step/step.png")), (1000, 550));

    // ... and from a kick 4 cm to the right at t = 3 s (the car already moving).
    let o = rccar(
        d,
        &[
            "sim", "--no-local", "--no-timing", "--seconds", "13", "--laps", "0", "--set", "detect.enabled=false",
            "--kick", "3:-0.04", "--out", "kick",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let k = &json(&d.join("kick/summary.json"))["step"];
    let t0 = k["t0_s"].as_f64().unwrap();
    assert!((3.0..3.1).contains(&t0), "{k}");
    assert!((k["initial_offset_m"].as_f64().unwrap() + 0.04).abs() < 2e-3, "{k}");
    let kr = k["rise_time_s"].as_f64().expect("kick rise");
    assert!((0.3..3.5).contains(&kr), "{k}");
    assert!(k["settling_time_s"].as_f64().is_some(), "{k}");

    // Bad step flags: one line, exit 2.
    let o = rccar(d, &["sim", "--no-local", "--kick", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--kick `3`: expected T:DY"), "{}", text(&o));
    let o = rccar(d, &["sim", "--no-local", "--start-offset", "-2"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--start-offset: -2 m is off the lane"), "{}", text(&o));

    // 3. `rccar plot`: two runs, three panels (one an alias into the nested truth).
    let o = rccar(
        d,
        &[
            "plot", "step/telemetry.jsonl", "kick/telemetry.jsonl", "--y", "error,steer,xte", "--label", "offset",
            "--label", "kick", "--out", "cmp/plot.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(png_size(&d.join("cmp/plot.png")), (1000, 40 + 3 * 260));
    // A run folder stands for its telemetry.jsonl (labelled by the folder); a folder without
    // one is named in the error.
    let o = rccar(d, &["plot", "step", "--y", "steer", "--out", "cmp/folder.png"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("plot: step/telemetry.jsonl ("), "{}", text(&o));
    assert_eq!(png_size(&d.join("cmp/folder.png")), (1000, 40 + 260));
    std::fs::create_dir_all(d.join("runs")).unwrap();
    std::os::unix::fs::symlink("../step", d.join("runs/latest")).unwrap();
    let o = rccar(d, &["plot", "runs", "--y", "steer", "--out", "cmp/latest.png"]);
    assert!(o.status.success(), "{}", text(&o));
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(said.contains("plot: runs/../step/telemetry.jsonl (") && said.contains("as `step`"), "{}", text(&o));
    let o = rccar(d, &["plot", "cmp", "--y", "steer"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("cmp: a folder without telemetry.jsonl"), "{}", text(&o));
    let o = rccar(d, &["plot", "step/telemetry.jsonl", "--y", "stear"]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2));
    assert!(err.contains("no field `stear`") && err.contains("truth.offset_m") && err.contains("steer,"), "{err}");
    std::fs::write(d.join("bad.jsonl"), "{\"time_s\":0,\"steer\":0}\n{\"time_s\":\n").unwrap();
    let o = rccar(d, &["plot", "bad.jsonl", "--y", "steer"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.jsonl:2: not a JSON record"), "{}", text(&o));

    // 4. `rccar report`: the config difference, the summary and step figures, the plots embedded.
    let o = rccar(d, &["report", "step"]);
    assert!(o.status.success(), "{}", text(&o));
    let html = std::fs::read_to_string(d.join("step/report.html")).unwrap();
    let md = std::fs::read_to_string(d.join("step/report.md")).unwrap();
    for f in ["xte_rms_m", "xte_max_m", "rise_time_s", "overshoot_pct", "settling_time_s"] {
        assert!(html.contains(f) && md.contains(f), "report lacks {f}");
    }
    for v in [s["xte_rms_m"].as_f64().unwrap(), rise, over, settle] {
        assert!(html.contains(&format!("<td>{}</td>", shown(v))), "report lacks the figure {}", shown(v));
    }
    assert!(md.contains("| detect.enabled | true | false |"), "{md}");
    assert!(md.contains("| sim.max_seconds | 600 | 10 |"), "{md}");
    // xte_steer.png, path.png and step.png, embedded; none linked from outside.
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 3);
    assert!(!html.contains("src=\"step.png\""));
    assert!(md.contains("![step.png](step.png)"));
    let o = rccar(d, &["report", "nowhere"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nowhere: not a folder"), "{}", text(&o));
}
