//! Issue 29, must-shows 2 and 4: a simulator drive with steering noise is recorded, cut,
//! trained on with `rccar-train pilot --recording` (read through `rccar::dataset`), the
//! weights drive the simulator, and the cut is exported as a Donkey tub v2 that
//! tests/data_cmd.rs's own reader reads back; a tub made here (a bright column whose x is
//! the steering) is trained on and the held-out table beats the training-mean predictor.

use crate::data_cmd::text;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Folder of the `rccar` binary under test (and of `rccar-train`, built beside it).
fn bin_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_rccar")).parent().unwrap().to_path_buf()
}

/// Runs `rccar` or `rccar-train`. `rccar-train` is another workspace member: cargo builds it
/// for `cargo test --workspace` only, so it is brought up to date here once per test run (a
/// stale binary would test old code). Not when `RCCAR_TRAINER_BUILT=1`: tests/all.sh sets it,
/// having built the whole workspace beside this binary; a `cargo build -p rccar-train` of its
/// own resolves the dependencies' features differently and compiled rccar again mid-suite
/// (~2 min of CPU).
fn run(bin: &str, args: &[&str], paths: &[&Path]) -> Output {
    static ONCE: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    let built = std::env::var("RCCAR_TRAINER_BUILT").is_ok_and(|v| v == "1");
    if bin == "rccar-train" && !built {
        ONCE.get_or_init(|| {
            let mut c = Command::new(env!("CARGO"));
            c.args(["build", "-p", "rccar-train", "--bin", "rccar-train"]);
            if bin_dir().ends_with("release") {
                c.arg("--release");
            }
            let st = c
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .status()
                .expect("cargo build -p rccar-train");
            assert!(st.success(), "cargo build -p rccar-train failed");
        });
    }
    let mut c = Command::new(bin_dir().join(bin));
    c.current_dir(env!("CARGO_MANIFEST_DIR")).args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().expect("runs")
}

fn json_lines(p: &Path) -> Vec<Value> {
    std::fs::read_to_string(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// One row of the held-out table: (name, frames, RMSE, MAE).
type Row = (String, usize, f64, f64);

/// The held-out table of NAME.report.txt, and the classical row's "not run: why" if it was
/// not run.
fn report(p: &Path) -> (Vec<Row>, Option<String>) {
    let t = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut rows = Vec::new();
    let mut not_run = None;
    for l in t.lines().skip(1) {
        if let Some(i) = l.find("not run: ") {
            not_run = Some(l[i..].to_string());
            continue;
        }
        let w: Vec<&str> = l.split_whitespace().collect();
        let n = w.len();
        assert!(n >= 4, "{l}");
        rows.push((
            w[..n - 3].join(" "),
            w[n - 3].parse().unwrap(),
            w[n - 2].parse().unwrap(),
            w[n - 1].parse().unwrap(),
        ));
    }
    (rows, not_run)
}

/// The loss.csv's (train, val) per epoch.
fn losses(p: &Path) -> Vec<(f64, f64)> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let w: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (w[1], w[2])
        })
        .collect()
}

#[test]
fn sim_recording_cut_trained_driven_and_exported() {
    let tmp = tempfile::tempdir().unwrap();
    let t = |n: &str| tmp.path().join(n);
    // 1. 12 s of the simulator with steering noise, detection off, its frames recorded.
    let o = run(
        "rccar",
        &[
            "sim",
            "--seconds",
            "12",
            "--no-timing",
            "--set",
            "detect.enabled=false",
            "--set",
            "sim.steer_noise=0.15",
            "--record",
        ],
        &[&t("frames"), Path::new("-o"), &t("run")],
    );
    assert!(o.status.code().is_some(), "{}", text(&o));
    let run_tel = t("run").join("telemetry.jsonl");
    assert_eq!(json_lines(&run_tel).len(), 360);

    // 2. Frames 300.. cut off: 300 left.
    let o = run(
        "rccar",
        &["data", "cut", "--drop", "300..", "--telemetry"],
        &[&run_tel, &t("frames"), Path::new("-o"), &t("cut")],
    );
    assert!(o.status.success(), "{}", text(&o));
    let cut_tel = json_lines(&t("cut").join("telemetry.jsonl"));
    assert_eq!(cut_tel.len(), 300);

    // 3. Trained on the cut for 3 epochs; the held-out table has all three rows.
    let model = t("pilot.safetensors");
    let o = run(
        "rccar-train",
        &[
            "pilot",
            "--epochs",
            "3",
            "--patience",
            "3",
            "--threads",
            "2",
            "--recording",
        ],
        &[&t("cut"), Path::new("--out"), &model],
    );
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    eprintln!("{out}");
    assert!(out.contains("(rccar recording): 300 frames"), "{out}");
    let (rows, not_run) = report(&t("pilot.report.txt"));
    assert_eq!(not_run, None, "the classical pipeline ran on the held-out frames");
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert!(
        rows[0].0 == "learned pilot" && rows[1].0.starts_with("training mean"),
        "{rows:?}"
    );
    assert!(rows[2].0.starts_with("classical pipeline"), "{rows:?}");
    for r in &rows {
        assert!(
            r.1 == 60 && r.2.is_finite() && r.3.is_finite() && r.3 <= r.2 + 1e-9,
            "{r:?}"
        );
    }
    // The labels are the classical controller's clean commands (the noise is the car's,
    // not the label's): the pipeline run again over the same frames gives them back, up to
    // its filters' start from nothing on the first held-out frame.
    assert!(rows[2].3 < 0.05, "classical MAE {:?}", rows[2]);
    // A 3-epoch net is not a driver; honest: its training loss fell.
    let l = losses(&t("pilot.loss.csv"));
    assert_eq!(l.len(), 3);
    assert!(l[2].0 < l[0].0, "training loss {l:?}");

    // 3b. The same frames read as a sim frames folder with the run's telemetry.
    let o = run(
        "rccar-train",
        &["pilot", "--epochs", "1", "--threads", "2", "--telemetry"],
        &[
            &run_tel,
            Path::new("--recording"),
            &t("frames"),
            Path::new("--out"),
            &t("p2.safetensors"),
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("(frames + telemetry): "),
        "{}",
        text(&o)
    );

    // 4. The weights drive the simulator for 3 s.
    let o = run(
        "rccar",
        &[
            "sim",
            "--seconds",
            "3",
            "--no-timing",
            "--set",
            "detect.enabled=false",
            "--set",
            "steering.method=learned",
            "--set",
        ],
        &[
            Path::new(&format!("steering.model={}", model.display())),
            Path::new("-o"),
            &t("drive"),
        ],
    );
    assert!(o.status.code().is_some(), "{}", text(&o));
    let drive = json_lines(&t("drive").join("telemetry.jsonl"));
    assert_eq!(drive.len(), 90, "{}", text(&o));
    assert!(drive.iter().all(|l| l["steer"].as_f64().is_some_and(f64::is_finite)));
    // The run steered with those weights (a file that does not load is an error: tests/pilot.rs).
    let cfg: Value = serde_json::from_str(&std::fs::read_to_string(t("drive").join("config.json")).unwrap()).unwrap();
    assert_eq!(cfg["steering"]["method"], "learned");
    assert_eq!(cfg["steering"]["model"].as_str(), model.to_str());

    // 5. The cut exported as a tub v2, read back by tests/data_cmd.rs's own reader.
    let o = run("rccar", &["data", "export", "--tub"], &[&t("tub"), &t("cut")]);
    assert!(o.status.success(), "{}", text(&o));
    let recs = crate::data_cmd::read_tub_independently(&t("tub"));
    assert_eq!(recs.len(), 300);
    for ((_, r), l) in recs.iter().zip(&cut_tel) {
        assert_eq!(r["user/angle"].as_f64(), l["steer"].as_f64());
    }
}

/// 320 × 240 (the pilot's frame size): dark, with a bright column whose x encodes `steer`.
fn column(steer: f64) -> image::RgbImage {
    let x0 = ((steer + 1.0) / 2.0 * 300.0) as u32 + 4;
    image::RgbImage::from_fn(320, 240, |x, _| {
        let v = if x.abs_diff(x0) <= 6 { 230 } else { 40 };
        image::Rgb([v, v, v])
    })
}

/// A tub v2 of `n` records, written here as Donkey does (catalogs of 100), its steering
/// `0.8 sin(0.37 k)` (both halves see the whole range).
fn make_column_tub(dir: &Path, n: usize) {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut cats: Vec<String> = Vec::new();
    for k in 0..n {
        let angle = ((k as f64) * 0.37).sin() * 0.8;
        let name = format!("{k}_cam_image_array_.jpg");
        column(angle).save(dir.join("images").join(&name)).unwrap();
        let rec = serde_json::json!({
            "_index": k, "_session_id": "26-11-28_0", "_timestamp_ms": 1_700_000_000_000i64 + 50 * k as i64,
            "cam/image_array": name, "user/angle": angle, "user/mode": "user", "user/throttle": 0.3,
        });
        if k % 100 == 0 {
            cats.push(String::new());
        }
        let c = cats.last_mut().unwrap();
        c.push_str(&rec.to_string());
        c.push('\n');
    }
    let mut paths = Vec::new();
    for (i, c) in cats.iter().enumerate() {
        std::fs::write(dir.join(format!("catalog_{i}.catalog")), c).unwrap();
        let lens: Vec<usize> = c.split_inclusive('\n').map(str::len).collect();
        let cm = serde_json::json!({"created_at": 1.5, "line_lengths": lens, "path": format!("catalog_{i}.catalog_manifest"), "start_index": i * 100});
        std::fs::write(dir.join(format!("catalog_{i}.catalog_manifest")), format!("{cm}\n")).unwrap();
        paths.push(format!("catalog_{i}.catalog"));
    }
    let manifest = format!(
        "[\"cam/image_array\", \"user/angle\", \"user/throttle\", \"user/mode\"]\n[\"image_array\", \"float\", \"float\", \"str\"]\n{{}}\n{{\"created_at\": 1.5, \"sessions\": {{\"all_full_ids\": [\"26-11-28_0\"], \"last_id\": 0, \"last_full_id\": \"26-11-28_0\"}}}}\n{}\n",
        serde_json::json!({"paths": paths, "current_index": n, "max_len": 100, "deleted_indexes": []})
    );
    std::fs::write(dir.join("manifest.json"), manifest).unwrap();
}

#[test]
fn a_tub_made_here_trains_a_pilot_that_beats_the_mean() {
    let tmp = tempfile::tempdir().unwrap();
    let tub = tmp.path().join("tub");
    make_column_tub(&tub, 250);
    let model = tmp.path().join("col.safetensors");
    let o = run(
        "rccar-train",
        &[
            "pilot",
            "--epochs",
            "12",
            "--patience",
            "12",
            "--threads",
            "2",
            "--no-light",
            "--recording",
        ],
        &[&tub, Path::new("--out"), &model],
    );
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    eprintln!("{out}");
    assert!(out.contains("(Donkey tub v2): 250 frames"), "{out}");
    let (rows, not_run) = report(&tmp.path().join("col.report.txt"));
    eprintln!("{rows:?} {not_run:?}");
    assert!(rows.len() >= 2, "{rows:?}");
    let (learned, mean) = (&rows[0], &rows[1]);
    assert!(
        learned.0 == "learned pilot" && mean.0.starts_with("training mean"),
        "{rows:?}"
    );
    for r in &rows {
        assert!(r.1 == 50 && r.2.is_finite() && r.3.is_finite(), "{r:?}");
    }
    assert!(
        learned.2 < 0.5 * mean.2,
        "learned RMSE {} vs the mean's {}",
        learned.2,
        mean.2
    );
    // The table on stdout is the file's.
    let file = std::fs::read_to_string(tmp.path().join("col.report.txt")).unwrap();
    assert!(out.contains(&file), "{out}");
}
