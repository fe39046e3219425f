//! `rccar calibrate ranging` end to end: the simulator's lab with the camera's true tilt 2°
//! off the configured one; the written override must hold the true tilt within 0.5°, keep the
//! file's other keys, and a CSV with a bad line is refused naming the line.

use std::process::Command;

fn rccar() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rccar"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

#[test]
fn lab_pairs_fit_and_merge_into_the_override() {
    let dir = std::env::temp_dir().join(format!("rccar_calib_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let local = dir.join("local.toml");
    std::fs::write(&local, "[steering]\nkp = 0.9\n").unwrap();
    let csv = dir.join("lab.csv");
    let o = rccar()
        .args([
            "calibrate",
            "ranging",
            "--from-sim",
            "10",
            "--sim-tilt-error-deg",
            "2",
            "--write",
        ])
        .arg(&local)
        .arg("--sim-pairs-out")
        .arg(&csv)
        .arg("--no-local")
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}\n{}", String::from_utf8_lossy(&o.stderr));
    let t: toml::Table = std::fs::read_to_string(&local).unwrap().parse().unwrap();
    let tilt = t["camera"]["tilt_deg"].as_float().unwrap();
    println!("{out}");
    assert!((tilt - 22.0).abs() < 0.5, "tilt {tilt}");
    assert_eq!(t["steering"]["kp"].as_float(), Some(0.9), "other keys kept");
    // The written pairs read back and fit the same way (dry run).
    let o = rccar()
        .args(["calibrate", "ranging", "--dry-run", "--no-local"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(o.status.success());
    // A bad line is named.
    std::fs::write(&csv, "row_px,distance_m\n120,0.5\n130,abc\n").unwrap();
    let o = rccar()
        .args(["calibrate", "ranging", "--dry-run", "--no-local"])
        .arg(&csv)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains(":3:"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
