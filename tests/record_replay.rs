//! A recording made by `record::Recorder` replays with `rccar replay DIR`: the shipped sample
//! frames (PNG) are recorded as JPEG segments with their telemetry, then both folders are
//! replayed by the real binary and the steering is compared frame by frame.
//!
//! JPEG changes pixels by a few grey levels; the tolerance on steer below is what that costs
//! on the sample (measured: mean 0.0002, max 0.0016 at quality 90; values are printed).

use image::RgbImage;
use rccar::record::{frame_name, segment_name, RecordOptions, Recorder, TELEMETRY_FILE};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/lane_sample")
}

/// `rccar replay DIR` with the shipped config, run from a folder outside the repository.
fn replay(dir: &Path, out: &Path, cwd: &Path) -> Vec<Value> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let o = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(cwd)
        .arg("replay")
        .arg(dir)
        .arg("--out")
        .arg(out)
        .args(["--no-annotate", "--no-timing", "--config"])
        .arg(root.join("config/car.toml"))
        // Detection off: the cascade paths in car.toml are relative to the repository root.
        .args(["--set", "detect.enabled=false"])
        .output()
        .expect("rccar runs");
    assert!(
        o.status.success(),
        "replay {}: {}{}",
        dir.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read_to_string(out.join("telemetry.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn steer(rec: &Value) -> f64 {
    rec["steer"]
        .as_f64()
        .or_else(|| rec["command"]["steer"].as_f64())
        .unwrap_or_else(|| panic!("no steer in {rec}"))
}

#[test]
fn recording_replays_with_the_same_steering() {
    let tmp = tempfile::tempdir().unwrap();
    let rec_dir = tmp.path().join("rec");
    let opts = RecordOptions {
        jpeg_quality: 90,
        max_bytes: 100_000_000,
        segment_frames: 10,
    };
    let mut rec = Recorder::create(&rec_dir, opts).unwrap();
    let mut names: Vec<PathBuf> = std::fs::read_dir(sample())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    names.sort();
    for (i, p) in names.iter().enumerate() {
        let img: RgbImage = image::open(p).unwrap().to_rgb8();
        rec.write_frame(i as u64, &img).unwrap();
        rec.write_telemetry_line(&format!("{{\"frame\":{i}}}")).unwrap();
    }
    let stats = rec.finish().unwrap();
    assert_eq!(stats.frames_written as usize, names.len());
    // 32 frames in segments of 10: seg_000000 .. seg_000003.
    assert_eq!(names.len(), 32);
    assert!(rec_dir.join(segment_name(3)).join(frame_name(31)).is_file());
    assert!(rec_dir.join(TELEMETRY_FILE).is_file());

    let png = replay(&sample(), &tmp.path().join("out_png"), tmp.path());
    let jpg = replay(&rec_dir, &tmp.path().join("out_jpg"), tmp.path());
    assert_eq!(png.len(), names.len());
    assert_eq!(jpg.len(), png.len(), "every recorded frame replays");
    let mut worst: f64 = 0.0;
    let mut sum = 0.0;
    for (a, b) in png.iter().zip(&jpg) {
        let d = (steer(a) - steer(b)).abs();
        worst = worst.max(d);
        sum += d;
    }
    eprintln!(
        "steer PNG vs JPEG q90 recording over {} frames: mean |diff| {:.4}, max {:.4}",
        png.len(),
        sum / png.len() as f64,
        worst
    );
    assert!(worst <= 0.01, "JPEG recording changed a steer by {worst:.4} (> 0.01)");
}
