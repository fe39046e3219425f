//! `rccar stereo LEFT RIGHT` end to end (issue 12): a pair rendered by the simulator's stereo
//! rig (base 0.06 m, a stop sign about 1 m ahead) is ranged from the sign's true box, first as
//! an ideal pair of `[camera]`, then through a calibration file made by `rccar calibrate
//! stereo` from checkerboards rendered by the same cameras (rectification maps in the loop).
//! Bad input: a pair of different sizes, a calibration file made for another image size.

use rccar::calib::corners::BoardSize;
use rccar::camera::PinholeCamera;
use rccar::config::Config;
use rccar::sim::board::Board;
use rccar::sim::render::RenderOptions;
use rccar::sim::scene::Scene;
use rccar::sim::stereo::StereoRig;
use rccar::sim::track::{ObjectKind, Track};
use rccar::sim::vehicle::Pose;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;

fn rccar(args: &[&str], dir: &Path) -> (i32, String, String) {
    let root = env!("CARGO_MANIFEST_DIR");
    let out = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(args)
        .args(["--config", &format!("{root}/config/car.toml")])
        .current_dir(dir)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn stereo_command_ranges_a_rendered_pair_with_and_without_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cfg = Config::default();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let track = Track::load(&root.join("config/tracks/default.toml")).unwrap();
    let mut rig = StereoRig::new(
        &cfg,
        Arc::new(Scene::new(&track)),
        0.06,
        RenderOptions::from_config(&cfg.sim),
    );
    let pose = Pose {
        x: 3.26,
        y: -0.15,
        yaw: 0.0,
    };
    let (l, r) = rig.render(&pose, 0.0, 0);
    l.save(d.join("l.png")).unwrap();
    r.save(d.join("r.png")).unwrap();
    let t = rig
        .truth(&pose, true)
        .into_iter()
        .find(|t| t.bbox.kind == ObjectKind::StopSign)
        .unwrap();
    let b = t.bbox.bbox;
    let bx = format!(
        "{},{},{},{}",
        b[0].round(),
        b[1].round(),
        (b[2] - b[0]).round(),
        (b[3] - b[1]).round()
    );
    let forward = |out: &str| -> f64 {
        let v: serde_json::Value = serde_json::from_str(out.lines().next().unwrap()).unwrap();
        v["forward_m"]["bfd"].as_f64().unwrap_or_else(|| panic!("{out}"))
    };
    // 1. Ideal pair.
    let (code, out, err) = rccar(&["stereo", "l.png", "r.png", "--box", &bx], d);
    assert_eq!(code, 0, "{err}");
    let f_ideal = forward(&out);
    let out_ideal = out.clone();
    // 2. Through a calibration made from rendered boards.
    let cam = PinholeCamera::from(&cfg.camera);
    let board = Board {
        size: BoardSize { cols: 9, rows: 6 },
        square_m: 0.025,
    };
    let mut args: Vec<String> = ["calibrate", "stereo", "--out", "st.json", "--left"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let mut rights = vec![];
    for (i, p) in board.calibration_poses(&cam, 0.45, 10).iter().enumerate() {
        let mut pr = *p;
        pr.t[0] -= 0.06;
        board
            .render(&cam, p, 2.0, 10 + i as u64)
            .save(d.join(format!("bl{i}.png")))
            .unwrap();
        board
            .render(&cam, &pr, 2.0, 50 + i as u64)
            .save(d.join(format!("br{i}.png")))
            .unwrap();
        args.push(format!("bl{i}.png"));
        rights.push(format!("br{i}.png"));
    }
    args.push("--right".into());
    args.extend(rights);
    let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let out = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(&a)
        .current_dir(d)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (code, out, err) = rccar(
        &[
            "stereo",
            "l.png",
            "r.png",
            "--box",
            &bx,
            "--set",
            "stereo.calibration=\"st.json\"",
        ],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let f_cal = forward(&out);
    println!("ideal: {out_ideal}calibrated: {out}");
    println!(
        "stop sign: true forward {:.4} m; ideal pair {:.4} m ({:+.2} %); calibrated + rectified {:.4} m ({:+.2} %)",
        t.forward_m,
        f_ideal,
        100.0 * (f_ideal / t.forward_m - 1.0),
        f_cal,
        100.0 * (f_cal / t.forward_m - 1.0)
    );
    assert!((f_ideal / t.forward_m - 1.0).abs() < 0.03, "{f_ideal}");
    assert!((f_cal / t.forward_m - 1.0).abs() < 0.03, "{f_cal}");

    // Bad input: pair sizes differ; calibration made for another size; a broken box.
    image::RgbImage::new(160, 120).save(d.join("small.png")).unwrap();
    let (code, _, err) = rccar(&["stereo", "l.png", "small.png", "--box", &bx], d);
    assert_ne!(code, 0);
    assert!(err.contains("l.png is 320x240 but small.png is 160x120"), "{err}");
    let big = |img: &image::RgbImage| image::imageops::resize(img, 640, 480, image::imageops::FilterType::Triangle);
    big(&l).save(d.join("L.png")).unwrap();
    big(&r).save(d.join("R.png")).unwrap();
    let (code, _, err) = rccar(
        &[
            "stereo",
            "L.png",
            "R.png",
            "--box",
            "10,10,20,20",
            "--set",
            "stereo.calibration=\"st.json\"",
        ],
        d,
    );
    assert_ne!(code, 0);
    assert!(
        err.contains("st.json: calibrated for 320x240 images, but the frames are 640x480"),
        "{err}"
    );
    let (code, _, err) = rccar(&["stereo", "l.png", "r.png", "--box", "1,2,3"], d);
    assert_ne!(code, 0);
    assert!(err.contains("--box 1,2,3: needs exactly four integers"), "{err}");
    // A box with nothing to match in the other image: a "no range" line, not a number.
    let (code, out, _) = rccar(&["stereo", "l.png", "small.png", "--box", &bx], d);
    assert_ne!(code, 0, "{out}");
    let (code, out, _) = rccar(&["stereo", "l.png", "l.png", "--box", &bx], d);
    assert_eq!(code, 0);
    assert!(out.contains("no_range"), "{out}");
}

/// OpenCV's sample stereo pairs (Debian `opencv-doc`, left01..14 / right01..14 without 10),
/// or None when they are missing and not required (`RCCAR_OPENCV_DOC` unset, as in
/// tests/stereo_photos.rs).
fn opencv_pairs() -> Option<(Vec<String>, Vec<String>)> {
    let (dir, required) = match std::env::var_os("RCCAR_OPENCV_DOC") {
        Some(d) => (std::path::PathBuf::from(d), true),
        None => (
            std::path::PathBuf::from("/usr/share/doc/opencv-doc/examples/data"),
            false,
        ),
    };
    let mut l = vec![];
    let mut r = vec![];
    for i in [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14] {
        let (a, b) = (
            dir.join(format!("left{i:02}.jpg")),
            dir.join(format!("right{i:02}.jpg")),
        );
        if !(a.exists() && b.exists()) {
            assert!(!required, "{} missing (RCCAR_OPENCV_DOC is set)", a.display());
            println!("opencv-doc's stereo photos not found in {}: skipped", dir.display());
            return None;
        }
        l.push(a.display().to_string());
        r.push(b.display().to_string());
    }
    Some((l, r))
}

/// `rccar calibrate stereo` with `--left L... --right R... -o OUT` and `extra` flags.
fn calibrate(d: &Path, l: &[String], r: &[String], out: &str, extra: &[&str]) -> (i32, String, String) {
    let mut args = vec!["calibrate", "stereo", "-o", out];
    args.extend_from_slice(extra);
    args.push("--left");
    args.extend(l.iter().map(|s| s.as_str()));
    args.push("--right");
    args.extend(r.iter().map(|s| s.as_str()));
    let out = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(&args)
        .current_dir(d)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// Issue 24: a stereo calibration that cannot range is never written, and one made by hand (or
/// by an older rccar) is refused by `config check`, `rccar stereo` and `Pipeline::new`. Before:
/// the same photos as left and right wrote baseline 7.8e-18 m, `config check` passed and
/// `rccar stereo` exited 0; swapped cameras wrote T.x = +0.0836 m without a word.
#[test]
fn degenerate_or_swapped_stereo_calibrations_are_refused() {
    let Some((l, r)) = opencv_pairs() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 1. The real pair: written, T.x < 0, baseline 8.4 cm.
    let (code, out, err) = calibrate(d, &l, &r, "good.json", &[]);
    assert_eq!(code, 0, "{out}{err}");
    let good: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("good.json")).unwrap()).unwrap();
    let t = good["stereo"]["t"][0].as_f64().unwrap();
    assert!((t + 0.0836).abs() < 0.001, "T.x {t}");
    // 2. The same photos as left and right; left and right swapped; a stricter rms bound.
    type Case<'a> = (&'a [String], &'a [String], &'a [&'a str], &'a [&'a str]);
    let cases: [Case; 3] = [
        (&l, &l, &[], &["baseline", "same photos", "--left from the left camera"]),
        (
            &r,
            &l,
            &[],
            &["T.x = +0.08", "swapped", "--left and --right photos exchanged"],
        ),
        (
            &l,
            &r,
            &["--max-rms-px", "0.3"],
            &["stereo rms 0.448 px is above 0.3 px"],
        ),
    ];
    for (i, (left, right, extra, want)) in cases.iter().enumerate() {
        let out_name = format!("bad{i}.json");
        let (code, out, err) = calibrate(d, left, right, &out_name, extra);
        println!("case {i}: {}", err.trim());
        assert_eq!(code, 2, "case {i}: {out}{err}");
        assert!(err.contains(&format!("{out_name} is not written")), "case {i}: {err}");
        for w in *want {
            assert!(err.contains(w), "case {i}: no {w:?} in {err}");
        }
        assert!(!d.join(&out_name).exists(), "case {i}: a file was written");
    }
    // 3. Files edited into each bad geometry: refused by every reader, naming the file.
    let edits: [(&str, serde_json::Value, &str); 5] = [
        (
            "same.json",
            serde_json::json!([7.8e-18, 0.0, 0.0]),
            "baseline |T| = 7.800e-18 m",
        ),
        (
            "swapped.json",
            serde_json::json!([0.0836, -0.0007, -0.001]),
            "cameras are swapped",
        ),
        (
            "stacked.json",
            serde_json::json!([-0.01, -0.08, 0.0]),
            "not a side-by-side pair",
        ),
        ("far.json", serde_json::json!([-8.4, 0.0, 0.0]), "check --square"),
        ("rms.json", serde_json::json!(null), "stereo rms 6.000 px is above 5 px"),
    ];
    let cfg_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/car.toml");
    let size = ["--set", "camera.width=640", "--set", "camera.height=480"];
    let set = format!("stereo.calibration={}", d.join("good.json").display());
    let (code, out, err) = rccar(
        &[&["config", "check", "--no-local", "--set", &set][..], &size].concat(),
        d,
    );
    assert_eq!(code, 0, "config check good.json: {out}{err}");
    for (name, t, want) in edits {
        let mut v = good.clone();
        if t.is_null() {
            v["stereo"]["rms_px"] = serde_json::json!(6.0);
        } else {
            v["stereo"]["t"] = t;
        }
        let file = d.join(name);
        std::fs::write(&file, v.to_string()).unwrap();
        let set = format!("stereo.calibration={}", file.display());
        let (code, out, err) = rccar(
            &[&["config", "check", "--no-local", "--set", &set][..], &size].concat(),
            d,
        );
        assert_ne!(code, 0, "config check {name}: {out}{err}");
        assert!(err.contains(name) && err.contains(want), "config check {name}: {err}");
        let (code, out, err) = rccar(
            &[
                "stereo",
                "--no-local",
                &l[0],
                &r[0],
                "--box",
                "240,80,280,190",
                "--set",
                &set,
            ],
            d,
        );
        assert_ne!(code, 0, "stereo {name}: {out}{err}");
        assert!(
            out.is_empty() && err.contains(name) && err.contains(want),
            "stereo {name}: {out}{err}"
        );
        let sets = [
            set.clone(),
            "ranging.method=stereo".into(),
            "camera.width=640".into(),
            "camera.height=480".into(),
        ];
        let cfg = rccar::config::Config::load(&cfg_path, &[], &sets).unwrap();
        let e = rccar::pipeline::Pipeline::new(&cfg)
            .err()
            .unwrap_or_else(|| panic!("Pipeline::new took {name}"));
        assert!(e.to_string().contains(want), "Pipeline::new {name}: {e}");
    }
}

/// `rccar stereo` never ends with exit 0 having printed nothing: a pair where the detector
/// finds no box is an error that says so and names the way out (`--box`).
#[test]
fn stereo_with_nothing_to_range_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let grey = image::RgbImage::from_pixel(320, 240, image::Rgb([128, 128, 128]));
    grey.save(d.join("l.png")).unwrap();
    grey.save(d.join("r.png")).unwrap();
    let (code, out, err) = rccar(&["stereo", "--no-local", "l.png", "r.png"], d);
    assert_ne!(code, 0, "{out}{err}");
    assert!(err.contains("no boxes") && err.contains("--box"), "{out}{err}");
}
