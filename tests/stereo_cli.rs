//! `rccar stereo LEFT RIGHT` end to end (issue 12): a pair rendered by the simulator's stereo
//! rig (base 0.06 m, a stop sign about 1 m ahead) is ranged from the sign's true box, first as
//! an ideal pair of `[camera]`, then through a calibration file made by `rccar calibrate
//! stereo` from checkerboards rendered by the same cameras (rectification maps in the loop).
//! Bad input: a pair of different sizes, a calibration file made for another image size.

use rccar::calib::corners::BoardSize;
use rccar::camera::PinholeCamera;
use rccar::classes::ObjectClass;
use rccar::config::Config;
use rccar::sim::board::Board;
use rccar::sim::render::RenderOptions;
use rccar::sim::scene::Scene;
use rccar::sim::stereo::StereoRig;
use rccar::sim::track::Track;
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
        .find(|t| t.bbox.kind == ObjectClass::StopSign)
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
