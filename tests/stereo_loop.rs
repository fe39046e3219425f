//! A camera pair in the one drive loop (issue 12): `rccar sim` with `ranging.method =
//! "stereo"` renders the pair (src/sim/stereo.rs `other_camera`, base `stereo.base_m`) and the
//! loop ranges by stereo (`Pipeline::step_stereo`, src/drive/stereo.rs); the default track's
//! stop sign on A, shipped cascades, camera noise on. Asserted from the telemetry:
//! every frame is a pair, boxes are ranged by stereo, the stop-sign range at the stop
//! decision is within 3 % of the true forward distance, the single-box stereo ranges of the
//! approach (0.3–1.5 m) within 2 % median / 5 % max, and the car comes to rest inside
//! `behaviour.stop_window_m`. The same scenario with `ranging.method = "mono"` is printed
//! beside it. Then the two recorded folders replay (`rccar replay L --right R`) with the same
//! decisions, frame for frame; and bad pairs of folders are refused or skipped by name.
//!
//!     cargo test --release --test it stereo_loop:: -- --nocapture

use rccar::classes::ObjectClass;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rccar-stereo-loop-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Runs rccar from outside the repository (the config named explicitly).
fn rccar(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(std::env::temp_dir())
        .args(args)
        .arg("--config")
        .arg(Path::new(ROOT).join("config/car.toml"))
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn records(p: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The stop sign's true forward distance from the lens (along the car's heading) at the
/// frame's pose, metres.
fn true_forward(rec: &serde_json::Value, sign: [f64; 2], camera_x: f64) -> f64 {
    let p = &rec["truth"]["pose"];
    let (x, y, yaw) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap(), p[2].as_f64().unwrap());
    (sign[0] - x) * yaw.cos() + (sign[1] - y) * yaw.sin() - camera_x
}

struct Stop {
    /// Range of the stop sign at the frame that decided to stop, and the truth then.
    decided: (f64, f64),
    /// True forward distance when the car first stood still.
    rest_m: Option<f64>,
    /// Relative errors of the single-box ranges 0.3–1.5 m.
    errors: Vec<f64>,
}

fn stop_of(recs: &[serde_json::Value], cfg: &serde_json::Value) -> Stop {
    let track = rccar::sim::track::Track::load(&Path::new(ROOT).join("config/tracks/default.toml")).unwrap();
    let sign = track
        .objects
        .iter()
        .map(|o| &o.0)
        .find(|o| o.kind == ObjectClass::StopSign)
        .unwrap()
        .pos;
    let camera_x = cfg["vehicle"]["camera_x_m"].as_f64().unwrap();
    let standstill = cfg["behaviour"]["standstill_mps"].as_f64().unwrap();
    let mut out = Stop {
        decided: (f64::NAN, f64::NAN),
        rest_m: None,
        errors: vec![],
    };
    let mut moved = false;
    for r in recs {
        let truth = true_forward(r, sign, camera_x);
        let sign_obj = r["objects"]
            .as_array()
            .into_iter()
            .flatten()
            .find(|o| o["class"] == "stop_sign");
        if let Some(m) = sign_obj.and_then(|o| o["measured_m"].as_f64()) {
            if (0.3..=1.5).contains(&truth) {
                out.errors.push((m - truth).abs() / truth);
            }
        }
        if r["transition"]["to"] == "stop_sign" && out.decided.0.is_nan() {
            out.decided = (sign_obj.unwrap()["distance_m"].as_f64().unwrap(), truth);
        }
        let v = r["truth"]["speed_mps"].as_f64().unwrap();
        moved |= v > 0.2;
        if moved && out.rest_m.is_none() && v.abs() < standstill {
            out.rest_m = Some(truth);
        }
    }
    out
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

impl Stop {
    /// One line: the range at the stop decision against the truth, where the car came to
    /// rest, and the single-box errors.
    fn print(&self, name: &str) {
        let pct = |v: f64| if v.is_nan() { "none".to_string() } else { format!("{:.2} %", 100.0 * v) };
        println!(
            "{name:>12}: stop decided at range {:.3} m, truth {:.3} m ({:+.1} %); at rest {} m from the sign; single-box ranges 0.3-1.5 m: {} boxes, median error {}, max {}",
            self.decided.0,
            self.decided.1,
            100.0 * (self.decided.0 - self.decided.1) / self.decided.1,
            self.rest_m.map_or("never".into(), |d| format!("{d:.3}")),
            self.errors.len(),
            pct(if self.errors.is_empty() { f64::NAN } else { median(&self.errors) }),
            pct(self.errors.iter().cloned().fold(f64::NAN, f64::max)),
        );
    }

    /// The stereo targets: the range at the stop decision within 3 % of the truth, ≥ 20
    /// single boxes within 2 % median and 5 % max.
    fn assert_accurate(&self, name: &str) {
        let (d, t) = self.decided;
        assert!((d - t).abs() <= 0.03 * t, "{name}: range at the stop decision {d} m, truth {t} m");
        assert!(self.errors.len() >= 20, "{name}: {} boxes", self.errors.len());
        assert!(median(&self.errors) <= 0.02, "{name}: median {}", median(&self.errors));
        let max = self.errors.iter().cloned().fold(0.0, f64::max);
        assert!(max <= 0.05, "{name}: max {max}");
    }
}

#[test]
fn stereo_in_the_drive_loop_sim_and_replay() {
    let (left, right, sim_out, mono_out, rep_out) = (tmp("L"), tmp("R"), tmp("sim"), tmp("mono"), tmp("rep"));
    let s = |p: &PathBuf| p.to_str().unwrap().to_string();
    // 1. The closed loop with a camera pair, both views recorded.
    let (code, out, err) = rccar(&[
        "sim", "--seconds", "10", "--no-timing", "--set", "ranging.method=stereo",
        "--record", &s(&left), "--record-right", &s(&right), "-o", &s(&sim_out),
    ]);
    print!("{out}");
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("stereo pair"), "{out}");
    let cfg: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim_out.join("config.json")).unwrap()).unwrap();
    let recs = records(&sim_out.join("telemetry.jsonl"));
    assert_eq!(recs.len(), 300);
    let pairs = recs.iter().filter(|r| r["stereo"].is_object()).count();
    let ranged: u64 = recs.iter().map(|r| r["stereo"]["ranged"].as_u64().unwrap_or(0)).sum();
    let unmatched: u64 = recs.iter().map(|r| r["stereo"]["unmatched"].as_u64().unwrap_or(0)).sum();
    let st = stop_of(&recs, &cfg);
    // 2. The same scenario by the single camera.
    let (code, out_m, err) = rccar(&["sim", "--seconds", "10", "--no-timing", "-o", &s(&mono_out)]);
    assert_eq!(code, 0, "{out_m}{err}");
    let mono = stop_of(&records(&mono_out.join("telemetry.jsonl")), &cfg);
    let window = [
        cfg["behaviour"]["stop_window_m"][0].as_f64().unwrap(),
        cfg["behaviour"]["stop_window_m"][1].as_f64().unwrap(),
    ];
    println!("stereo loop: {pairs} pairs, boxes ranged by stereo {ranged}, without a match {unmatched}");
    st.print("stereo");
    mono.print("mono");
    println!("(stop window {window:?} m)");
    assert_eq!(pairs, 300, "every frame is a pair");
    assert!(ranged >= 30 && unmatched * 10 <= ranged, "ranged {ranged}, unmatched {unmatched}");
    st.assert_accurate("stereo");
    let rest = st.rest_m.expect("the car never stopped");
    assert!(rest >= window[0] && rest <= window[1], "at rest {rest} m, window {window:?}");

    // 3. The two recorded folders replay with the same decisions.
    let (code, out, err) = rccar(&[
        "replay", &s(&left), "--right", &s(&right), "--set", "ranging.method=stereo",
        "--no-annotate", "--no-timing", "-o", &s(&rep_out),
    ]);
    print!("{out}");
    assert_eq!(code, 0, "{out}{err}");
    let rep = records(&rep_out.join("telemetry.jsonl"));
    assert_eq!(rep.len(), recs.len());
    for (x, y) in recs.iter().zip(&rep) {
        for k in ["file", "time_s", "steer", "throttle", "behaviour", "transition", "objects", "stereo"] {
            assert_eq!(x[k], y[k], "frame {}: {k} differs", x["frame"]);
        }
    }
    println!("replay of the two folders: {} frames, the same decisions", rep.len());

    // 4. Bad pairs of folders (20 frames each, copies).
    let subset = |from: &Path, name: &str, n: usize| {
        let d = tmp(name);
        std::fs::create_dir_all(&d).unwrap();
        for k in 0..n {
            let f = format!("frame_{k:06}.png");
            std::fs::copy(from.join(&f), d.join(&f)).unwrap();
        }
        d
    };
    let replay = |l: &Path, r: &Path, method: &str| {
        rccar(&[
            "replay", &s(&l.to_path_buf()), "--right", &s(&r.to_path_buf()), "--set",
            &format!("ranging.method={method}"), "--no-annotate", "--no-timing", "-o", &s(&tmp("bad-out")),
        ])
    };
    let l20 = subset(&left, "l20", 20);
    // a frame missing on the right
    let r19 = subset(&right, "r19", 20);
    std::fs::remove_file(r19.join("frame_000007.png")).unwrap();
    let (code, out, err) = replay(&l20, &r19, "stereo");
    println!("missing right frame: exit {code}: {}", err.trim());
    assert_ne!(code, 0, "{out}");
    assert!(err.contains("frame_000007.png") && err.contains("no partner"), "{err}");
    // a right frame of another size
    let rbig = subset(&right, "rbig", 20);
    image::RgbImage::new(640, 480).save(rbig.join("frame_000003.png")).unwrap();
    let (code, _, err) = replay(&l20, &rbig, "stereo");
    println!("right frame of another size: exit {code}: {}", err.trim());
    assert_ne!(code, 0);
    assert!(err.contains("frame_000003.png") && err.contains("640x480"), "{err}");
    // an unreadable right frame: skipped, named with its folder; the rest replayed
    let rcut = subset(&right, "rcut", 20);
    let p = rcut.join("frame_000005.png");
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() / 2]).unwrap();
    let (code, out, err) = replay(&l20, &rcut, "stereo");
    println!("unreadable right frame: exit {code}\n{out}");
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("skipped 1 frame(s)"), "{out}");
    assert!(out.contains(&format!("{}/frame_000005.png", rcut.display())), "{out}");
    assert!(out.contains("replayed 19 frames"), "{out}");
    // --right with mono ranging
    let r20 = subset(&right, "r20", 20);
    let (code, _, err) = replay(&l20, &r20, "mono");
    println!("--right with mono: exit {code}: {}", err.trim());
    assert_ne!(code, 0);
    assert!(err.contains("--right") && err.contains("ranging.method"), "{err}");
    // 5. `rccar drive` with a pair: the two recorded folders as left and right cameras, and
    //    the simulator as the camera (it renders its pair itself).
    for cam in [vec!["--camera", &s(&l20), "--camera-right", &s(&r20)], vec!["--camera", "sim"]] {
        let dout = tmp("drive");
        let mut args = vec!["drive", "--dry-run", "--arm", "--seconds", "2", "--set", "ranging.method=stereo", "-o"];
        let d = s(&dout);
        args.push(&d);
        args.extend(cam.iter().copied());
        let (code, out, err) = rccar(&args);
        assert!(code == 0 || code == 130, "{cam:?}: {out}{err}");
        let recs = records(&dout.join("telemetry.jsonl"));
        let pairs = recs.iter().filter(|r| r["stereo"].is_object()).count();
        println!("drive {cam:?}: {} frames, {pairs} of them pairs", recs.len());
        assert!(!recs.is_empty() && pairs == recs.len(), "{cam:?}: {pairs} of {}", recs.len());
        let _ = std::fs::remove_dir_all(dout);
    }
    // `rccar drive` with two folders that do not pair up: refused before the loop starts,
    // naming the frame, as `rccar replay --right` does.
    let (code, out, err) = rccar(&[
        "drive", "--dry-run", "--arm", "--seconds", "2", "--set", "ranging.method=stereo", "-o", &s(&tmp("drive-bad")),
        "--camera", &s(&l20), "--camera-right", &s(&r19),
    ]);
    println!("drive with a missing right frame: exit {code}: {}", err.trim());
    assert_ne!(code, 0, "{out}");
    assert!(err.contains("--camera-right") && err.contains("frame_000007.png") && err.contains("no partner"), "{err}");
    assert!(!out.contains("drive: camera"), "the loop must not start: {out}");
    // `rccar drive --record DIR --record-right DIR2` keeps both cameras (JPEG, the same names
    // and telemetry); `rccar replay DIR --right DIR2` replays them as a pair.
    let (dl, dr, dout, rout) = (tmp("drive-L"), tmp("drive-R"), tmp("drive-out"), tmp("drive-rep"));
    let (code, out, err) = rccar(&[
        "drive", "--dry-run", "--arm", "--seconds", "2", "--set", "ranging.method=stereo", "--camera", "sim",
        "--record", &s(&dl), "--record-right", &s(&dr), "-o", &s(&dout),
    ]);
    assert!(code == 0 || code == 130, "{out}{err}");
    assert!(out.contains("recording, other camera"), "{out}");
    let drove = records(&dout.join("telemetry.jsonl")).len();
    let (code, out, err) = rccar(&[
        "replay", &s(&dl), "--right", &s(&dr), "--set", "ranging.method=stereo", "--no-annotate", "--no-timing",
        "-o", &s(&rout),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let rep = records(&rout.join("telemetry.jsonl"));
    let pairs = rep.iter().filter(|r| r["stereo"].is_object()).count();
    println!("drive --record --record-right: {drove} frames driven, {} replayed, {pairs} of them pairs", rep.len());
    assert!(drove > 10 && rep.len() == drove && pairs == drove, "{drove} driven, {} replayed, {pairs} pairs", rep.len());
    // --record-right without a pair (drive)
    let (code, _, err) = rccar(&[
        "drive", "--dry-run", "--arm", "--seconds", "1", "--camera", "sim", "--record", &s(&tmp("x")),
        "--record-right", &s(&tmp("y")), "-o", &s(&tmp("z")),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("--record-right") && err.contains("ranging.method"), "{err}");
    for d in [dl, dr, dout, rout] {
        let _ = std::fs::remove_dir_all(d);
    }
    // --record-right without a pair
    let (code, _, err) = rccar(&["sim", "--seconds", "1", "--record", &s(&tmp("x")), "--record-right", &s(&tmp("y"))]);
    assert_ne!(code, 0);
    assert!(err.contains("--record-right") && err.contains("ranging.method"), "{err}");
    for d in [left, right, sim_out, mono_out, rep_out, l20, r19, r20, rbig, rcut] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A pair that is not ideal, as two webcams are: the simulator's second camera turned by 1°
/// of yaw, 0.5° of pitch and 0.3° of roll with a barrel lens (`sim.stereo_error_deg`,
/// `sim.stereo_error_k1`). Calibrated by `rccar calibrate stereo` from checkerboard pairs
/// rendered through the same cameras, the drive loop rectifies every pair
/// (`stereo.calibration`) and ranges the stop sign as well as on an ideal pair (decision within
/// 3 %, single-box ranges median ≤ 2 %, max ≤ 5 %); without the calibration the same run is
/// printed beside it (its ranges are far off). Then the calibration files the loop refuses.
#[test]
fn a_calibrated_pair_is_rectified_in_the_drive_loop() {
    use rccar::calib::corners::BoardSize;
    use rccar::camera::PinholeCamera;
    use rccar::sim::board::Board;
    use rccar::sim::stereo::LensWarp;
    let (dir, with_out, without_out) = (tmp("cal"), tmp("with"), tmp("without"));
    std::fs::create_dir_all(&dir).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (err_deg, k1) = ([1.0, 0.5, 0.3], -0.05);
    let error = [
        "--set".to_string(),
        format!("sim.stereo_error_deg=[{}, {}, {}]", err_deg[0], err_deg[1], err_deg[2]),
        "--set".to_string(),
        format!("sim.stereo_error_k1={k1}"),
    ];
    // 1. Checkerboard pairs through the same two cameras: the left ideal, the right `base`
    //    to its right (X_r = X_l − (base, 0, 0)), then turned and bent as in the simulator.
    let cfg = rccar::config::Config::load(&Path::new(ROOT).join("config/car.toml"), &[], &[]).unwrap();
    let cam = PinholeCamera::from(&cfg.camera);
    let warp = LensWarp::new(&cam, err_deg, k1);
    let b = Board {
        size: BoardSize { cols: 9, rows: 6 },
        square_m: 0.025,
    };
    let (mut left, mut right) = (vec![], vec![]);
    for (i, p) in b.calibration_poses(&cam, 0.45, 14).iter().enumerate() {
        let mut pr = *p;
        pr.t[0] -= cfg.stereo.base_m;
        let (l, r) = (format!("l{i:02}.png"), format!("r{i:02}.png"));
        b.render(&cam, p, 2.0, 2 * i as u64).save(dir.join(&l)).unwrap();
        let mut bent = image::GrayImage::new(0, 0);
        warp.apply_gray(&b.render(&cam, &pr, 2.0, 2 * i as u64 + 1), &mut bent);
        bent.save(dir.join(&r)).unwrap();
        left.push(s(&dir.join(l)));
        right.push(s(&dir.join(r)));
    }
    let cal = dir.join("pair.json");
    let mut args = vec!["calibrate".to_string(), "stereo".into(), "--out".into(), s(&cal), "--left".into()];
    args.extend(left);
    args.push("--right".into());
    args.extend(right);
    // (calibrate reads no config: run without rccar()'s --config)
    let o = Command::new(env!("CARGO_BIN_EXE_rccar")).args(&args).output().unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{out}{err}");
    println!("{}", out.lines().filter(|l| l.contains("RMS") || l.contains("T =") || l.contains("base")).collect::<Vec<_>>().join("\n"));

    // 2. The loop with and without the calibration.
    let run = |o: &Path, calibrated: bool| {
        let mut a: Vec<String> = ["sim", "--seconds", "10", "--no-timing", "--set", "ranging.method=stereo"]
            .iter()
            .map(|x| x.to_string())
            .collect();
        a.extend(error.iter().cloned());
        if calibrated {
            a.push("--set".into());
            a.push(format!("stereo.calibration={}", s(&cal)));
        }
        a.push("-o".into());
        a.push(s(o));
        let (code, out, err) = rccar(&a.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(code, 0, "{out}{err}");
        let cfg: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(o.join("config.json")).unwrap()).unwrap();
        let recs = records(&o.join("telemetry.jsonl"));
        (out, stop_of(&recs, &cfg), recs)
    };
    let (out_with, with, recs) = run(&with_out, true);
    let (_, without, _) = run(&without_out, false);
    assert!(out_with.contains("every pair rectified with"), "{out_with}");
    assert!(recs.iter().filter(|r| r["stereo"].is_object()).all(|r| r["stereo"]["rectified"] == true));
    with.print("calibrated");
    without.print("uncalibrated");
    with.assert_accurate("calibrated");
    // Without it the same pair is ranged far off (1° of yaw is ~4.6 px of disparity).
    assert!(
        without.errors.is_empty() || median(&without.errors) > 0.10,
        "uncalibrated median {}",
        median(&without.errors)
    );

    // 3. Calibration files the loop refuses, each naming the file and what is wrong.
    let text = std::fs::read_to_string(&cal).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["stereo"]["left"]["image_size"] = serde_json::json!([640, 480]);
    let other_size = dir.join("other_size.json");
    std::fs::write(&other_size, v.to_string()).unwrap();
    let damaged = dir.join("damaged.json");
    std::fs::write(&damaged, &text[..text.len() / 2]).unwrap();
    let missing = dir.join("missing.json");
    for (file, want) in [
        (&other_size, "calibrated for 640x480 images, but the frames are 320x240"),
        (&damaged, "damaged.json"),
        (&missing, "missing.json"),
    ] {
        let (code, out, err) = rccar(&[
            "sim", "--seconds", "1", "--no-timing", "--set", "ranging.method=stereo", "--set",
            &format!("stereo.calibration={}", s(file)), "-o", &s(&tmp("bad-cal")),
        ]);
        println!("refused: {}", err.trim());
        assert_ne!(code, 0, "{out}{err}");
        assert!(err.contains("stereo.calibration") && err.contains(want), "{err}");
    }
}
