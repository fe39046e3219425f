//! Calibration on the simulator's camera (issue 12): checkerboards rendered through the
//! configured pinhole (src/sim/board.rs) are calibrated by `rccar::calib` exactly as photos
//! are, and must give back the configured intrinsics (focal length within 0.5 %, principal
//! point within 1.5 px, no distortion) and, for a simulated stereo pair, the configured base.
//! Also the bad inputs of the calibration commands: no board, a single image, a pair of
//! different sizes, a results file made for another image size.

use rccar::calib::corners::{find_chessboard, BoardSize, CornerOptions};
use rccar::calib::file::{CalibrationFile, FileError};
use rccar::calib::intrinsics::{board_points, calibrate_camera, rodrigues};
use rccar::calib::stereo::stereo_calibrate;
use rccar::calib::CalibError;
use rccar::camera::PinholeCamera;
use rccar::config::Config;
use rccar::sim::board::Board;
use std::process::Command;

fn board() -> Board {
    Board {
        size: BoardSize { cols: 9, rows: 6 },
        square_m: 0.025,
    }
}

#[test]
fn recovers_the_simulated_cameras_intrinsics() {
    let cam = PinholeCamera::from(&Config::default().camera);
    let b = board();
    let poses = b.calibration_poses(&cam, 0.42, 12);
    let mut views = vec![];
    for (i, p) in poses.iter().enumerate() {
        let img = b.render(&cam, p, 2.0, i as u64);
        match find_chessboard(&img, b.size, &CornerOptions::default()) {
            Some(c) => views.push(c),
            None => println!("view {i}: board not found"),
        }
    }
    assert!(views.len() >= 10, "board found in only {} of 12 views", views.len());
    let obj = board_points(9, 6, b.square_m);
    let fit = calibrate_camera(&obj, &views, cam.width, cam.height).unwrap();
    let k = fit.k;
    println!(
        "simulated camera: configured f {:.3} px, c ({:.2}, {:.2}); calibrated fx {:.3} fy {:.3} cx {:.2} cy {:.2}, k1 {:.4} k2 {:.4}, RMS {:.4} px over {} views",
        cam.f_px, cam.u0, cam.v0, k.fx, k.fy, k.cx, k.cy, fit.dist.0[0], fit.dist.0[1], fit.rms, views.len()
    );
    assert!((k.fx - cam.f_px).abs() / cam.f_px < 0.005, "fx {}", k.fx);
    assert!((k.fy - cam.f_px).abs() / cam.f_px < 0.005, "fy {}", k.fy);
    assert!(
        (k.cx - cam.u0).abs() < 1.5 && (k.cy - cam.v0).abs() < 1.5,
        "c ({}, {})",
        k.cx,
        k.cy
    );
    assert!(fit.dist.0[0].abs() < 0.05, "k1 {}", fit.dist.0[0]);
    assert!(fit.rms < 0.2, "RMS {}", fit.rms);
}

#[test]
fn recovers_the_simulated_stereo_base() {
    let cam = PinholeCamera::from(&Config::default().camera);
    let b = board();
    let base = 0.06;
    let (mut lv, mut rv) = (vec![], vec![]);
    for (i, p) in b.calibration_poses(&cam, 0.45, 12).iter().enumerate() {
        // The right camera sits `base` to the right: X_r = X_l − (base, 0, 0).
        let mut pr = *p;
        pr.t[0] -= base;
        let l = find_chessboard(&b.render(&cam, p, 2.0, 2 * i as u64), b.size, &CornerOptions::default());
        let r = find_chessboard(
            &b.render(&cam, &pr, 2.0, 2 * i as u64 + 1),
            b.size,
            &CornerOptions::default(),
        );
        if let (Some(l), Some(r)) = (l, r) {
            lv.push(l);
            rv.push(r);
        }
    }
    assert!(lv.len() >= 8, "{} pairs", lv.len());
    let obj = board_points(9, 6, b.square_m);
    let fl = calibrate_camera(&obj, &lv, cam.width, cam.height).unwrap();
    let fr = calibrate_camera(&obj, &rv, cam.width, cam.height).unwrap();
    let st = stereo_calibrate(&obj, &lv, &rv, &fl.k, &fl.dist, &fr.k, &fr.dist).unwrap();
    let t = st.t;
    let ang = (-t[0] / t.norm()).clamp(-1.0, 1.0).acos().to_degrees();
    let rot = rccar::calib::intrinsics::rodrigues_inv(&st.r);
    let rot_deg = (rot[0].powi(2) + rot[1].powi(2) + rot[2].powi(2)).sqrt().to_degrees();
    println!(
        "simulated pair: base {base} m; calibrated T = [{:.5}, {:.5}, {:.5}] (|T| {:.5} m, {:.3}° off the x axis), R {:.3}°, RMS {:.4} px, {} pairs",
        t[0], t[1], t[2], t.norm(), ang, rot_deg, st.rms, lv.len()
    );
    assert!((t.norm() - base).abs() / base < 0.01, "|T| {}", t.norm());
    assert!(ang < 0.5, "direction {ang}°");
    assert!(rot_deg < 0.3, "R {rot_deg}°");
    let _ = rodrigues([0.0; 3]);
}

#[test]
fn no_board_and_a_single_image_are_clear_errors() {
    let obj = board_points(9, 6, 0.025);
    let e = calibrate_camera(&obj, &[], 320, 240).unwrap_err();
    assert!(matches!(e, CalibError::TooFewViews { need: 3, got: 0 }), "{e}");
    let blank = image::GrayImage::from_pixel(320, 240, image::Luma([128]));
    assert!(find_chessboard(&blank, BoardSize { cols: 9, rows: 6 }, &CornerOptions::default()).is_none());
}

fn rccar(args: &[&str], dir: &std::path::Path) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// The CLI on rendered boards: a good set calibrates and names the image without a board;
/// a single image, a pair of different sizes and a file for another size are clear errors.
#[test]
fn calibrate_commands_on_rendered_boards_and_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cam = PinholeCamera::from(&Config::default().camera);
    let b = board();
    let mut names = vec![];
    for (i, p) in b.calibration_poses(&cam, 0.42, 8).iter().enumerate() {
        let n = format!("b{i}.png");
        b.render(&cam, p, 2.0, i as u64).save(d.join(&n)).unwrap();
        names.push(n);
    }
    image::GrayImage::from_pixel(320, 240, image::Luma([90]))
        .save(d.join("blank.png"))
        .unwrap();
    names.push("blank.png".into());
    let mut args: Vec<&str> = vec!["calibrate", "camera", "--out", "cam.json"];
    args.extend(names.iter().map(|s| s.as_str()));
    let (code, out, err) = rccar(&args, d);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(err.contains("blank.png: board 9x6 not found"), "{err}");
    let file = CalibrationFile::load(&d.join("cam.json")).unwrap();
    let CalibrationFile::Camera { camera, .. } = file else {
        panic!("not a camera file")
    };
    assert_eq!(camera.board_not_found, vec!["blank.png".to_string()]);
    assert_eq!(camera.per_image_rms_px.len(), 8);
    assert!((camera.intrinsics.fx - cam.f_px).abs() / cam.f_px < 0.005);

    // A single image.
    let (code, _, err) = rccar(&["calibrate", "camera", "--out", "x.json", "b0.png"], d);
    assert_ne!(code, 0);
    assert!(
        err.contains("need at least 3 images with the board found, got 1"),
        "{err}"
    );
    assert!(!d.join("x.json").exists());

    // A pair of different sizes.
    image::GrayImage::from_pixel(640, 480, image::Luma([90]))
        .save(d.join("big.png"))
        .unwrap();
    let (code, _, err) = rccar(&["calibrate", "stereo", "--left", "b0.png", "--right", "big.png"], d);
    assert_ne!(code, 0);
    assert!(
        err.contains("left images are 320x240 but right images are 640x480"),
        "{err}"
    );
    // Unequal counts.
    let (code, _, err) = rccar(
        &["calibrate", "stereo", "--left", "b0.png", "b1.png", "--right", "b0.png"],
        d,
    );
    assert_ne!(code, 0);
    assert!(err.contains("2 left images but 1 right images"), "{err}");

    // A stereo file read for frames of another size; a camera file where a stereo one is needed.
    let mut pose_args: Vec<String> = vec![
        "calibrate".into(),
        "stereo".into(),
        "--out".into(),
        "st.json".into(),
        "--left".into(),
    ];
    let mut rights = vec![];
    for (i, p) in b.calibration_poses(&cam, 0.45, 8).iter().enumerate() {
        let mut pr = *p;
        pr.t[0] -= 0.06;
        b.render(&cam, p, 2.0, 100 + i as u64)
            .save(d.join(format!("l{i}.png")))
            .unwrap();
        b.render(&cam, &pr, 2.0, 200 + i as u64)
            .save(d.join(format!("r{i}.png")))
            .unwrap();
        pose_args.push(format!("l{i}.png"));
        rights.push(format!("r{i}.png"));
    }
    pose_args.push("--right".into());
    pose_args.extend(rights);
    let a: Vec<&str> = pose_args.iter().map(|s| s.as_str()).collect();
    let (code, out, err) = rccar(&a, d);
    assert_eq!(code, 0, "{out}\n{err}");
    let st = CalibrationFile::load_stereo(&d.join("st.json"), 320, 240).unwrap();
    assert!((st.baseline_m - 0.06).abs() < 0.0006, "baseline {}", st.baseline_m);
    let e = CalibrationFile::load_stereo(&d.join("st.json"), 640, 480).unwrap_err();
    assert!(matches!(e, FileError::Size { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("calibrated for 320x240 images, but the frames are 640x480"),
        "{e}"
    );
    let e = CalibrationFile::load_stereo(&d.join("cam.json"), 320, 240).unwrap_err();
    assert!(
        e.to_string().contains("single-camera calibration, stereo needed"),
        "{e}"
    );
    std::fs::write(d.join("junk.json"), "{\"kind\": \"stereo\"").unwrap();
    let e = CalibrationFile::load_stereo(&d.join("junk.json"), 320, 240).unwrap_err();
    assert!(e.to_string().contains("junk.json: not a calibration file"), "{e}");
}
