//! Issue 15: nothing a student does loses their work or leaves a wrong number. Every case of
//! the issue (except Ctrl-C/SIGTERM, which the drive loop's tests cover) as the exact command
//! a student would type, run on a copy of the project in a temporary folder: the exit code,
//! the message, and that no file the student had was changed or lost.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const OPENCV_DATA: &str = "/usr/share/doc/opencv-doc/examples/data";

/// A copy of the project's config folder (car.toml, tracks, cascades) in a temporary folder.
fn project() -> tempfile::TempDir {
    let t = tempfile::tempdir().unwrap();
    let cfg = t.path().join("config");
    for sub in ["tracks", "cascades"] {
        std::fs::create_dir_all(cfg.join(sub)).unwrap();
        for e in std::fs::read_dir(Path::new(ROOT).join("config").join(sub)).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), cfg.join(sub).join(e.file_name())).unwrap();
        }
    }
    std::fs::copy(Path::new(ROOT).join("config/car.toml"), cfg.join("car.toml")).unwrap();
    t
}

struct Out {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

impl Out {
    fn all(&self) -> String {
        format!("{}{}", self.stdout, self.stderr)
    }
}

fn rccar(cwd: &Path, args: &[&str]) -> Out {
    rccar_env(cwd, args, &[])
}

fn rccar_env(cwd: &Path, args: &[&str], env: &[(&str, &str)]) -> Out {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rccar"));
    c.current_dir(cwd).args(args).env_remove("RCCAR_CONFIG");
    for (k, v) in env {
        c.env(k, v);
    }
    let o = c.output().unwrap();
    let out = Out {
        code: o.status.code(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    assert!(
        !out.stderr.contains("panicked"),
        "rccar {args:?} panicked:\n{}",
        out.stderr
    );
    out
}

/// Every file under `dir` (except `skip` folders) with its bytes.
fn snapshot(dir: &Path, skip: &[&str]) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut m = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            if skip.iter().any(|s| rel.starts_with(s)) {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
            } else {
                m.insert(rel, std::fs::read(&p).unwrap_or_default());
            }
        }
    }
    m
}

fn assert_unchanged(before: &BTreeMap<PathBuf, Vec<u8>>, dir: &Path, skip: &[&str], what: &str) {
    let after = snapshot(dir, skip);
    let b: Vec<_> = before.keys().collect();
    let a: Vec<_> = after.keys().collect();
    assert_eq!(b, a, "{what}: files were added or removed");
    for (k, v) in before {
        assert!(after[k] == *v, "{what}: {} changed", k.display());
    }
}

const LOCAL: &str = "# Maria's settings (keep these comments!)\n[steering]\nkp = 1.2  # tuned on the long straight\n\n[camera]\n# measured with a protractor\ntilt_deg = 20.0 # was 19\n";

// ---------------------------------------------------------------------------------------
// Calibration writes nothing it cannot stand behind.

/// `rccar calibrate ranging FILE.csv` on bad data: exit 2, the reason, local.toml untouched.
#[test]
fn calibration_refuses_degenerate_pairs_and_leaves_local_toml_alone() {
    let p = project();
    let dir = p.path();
    std::fs::write(dir.join("config/local.toml"), LOCAL).unwrap();
    let cases: [(&str, &str, &str); 5] = [
        (
            "same.csv",
            "row_px,distance_m\n150,0.8\n150,0.8\n150,0.8\n150,0.8\n",
            "4 pair(s) on only 1 distinct row(s)",
        ),
        (
            "outside.csv",
            "150,0.8\n400,0.5\n120,1.0\n",
            "pair 2: row 400 px is outside the image",
        ),
        (
            "high.csv",
            "150,0.8,0.3\n100,1.0\n120,1.1\n",
            "pair 1: height 0.3 m must be >= 0 and below the camera",
        ),
        ("nan.csv", "150,nan\n100,1.0\n120,1.1\n", "NaN and inf are not allowed"),
        // Rows and distances that belong to no camera: the fit's rms row error is ~55 px.
        (
            "bad_rms.csv",
            "200,0.3\n150,2.5\n120,0.4\n100,3.0\n",
            "is above the bound 2 px (--max-rms-px)",
        ),
    ];
    for (name, text, want) in cases {
        std::fs::write(dir.join(name), text).unwrap();
        let before = snapshot(dir, &[]);
        let o = rccar(dir, &["calibrate", "ranging", name]);
        assert_eq!(o.code, Some(2), "{name}: {}", o.all());
        assert!(
            o.stderr.contains(want) && o.stderr.contains("nothing written"),
            "{name}: {}",
            o.stderr
        );
        assert!(
            o.stderr.starts_with(&format!("error: {name}: ")),
            "{name}: {}",
            o.stderr
        );
        assert_unchanged(&before, dir, &[], name);
    }
}

/// `--fit-ay` on pairs from a much longer lens: the fitted a_y scale (2.7) is out of range, so
/// the merged configuration is checked first and nothing is written (before issue 15 it was
/// written, and every later command failed).
#[test]
fn calibration_validates_the_merged_config_before_writing() {
    let p = project();
    let dir = p.path();
    std::fs::write(dir.join("config/local.toml"), LOCAL).unwrap();
    let o = rccar(
        dir,
        &[
            "calibrate",
            "ranging",
            "--from-sim",
            "12",
            "--set",
            "camera.hfov_deg=25",
            "--sim-pairs-out",
            "narrow.csv",
            "--dry-run",
        ],
    );
    assert_eq!(o.code, Some(0), "{}", o.all());
    let before = snapshot(dir, &[]);
    let o = rccar(
        dir,
        &["calibrate", "ranging", "narrow.csv", "--fit-ay", "--v0-sigma-px", "0"],
    );
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(
        o.stderr.contains("does not validate") && o.stderr.contains("ranging.a_y_scale = 2.69"),
        "{}",
        o.stderr
    );
    assert_unchanged(&before, dir, &[], "--fit-ay out of range");
    // Every later command still works.
    assert_eq!(rccar(dir, &["config", "check"]).code, Some(0));
}

/// A good calibration edits local.toml in place: the student's comments and keys stay, the old
/// file is kept as local.toml.bak, and `--dry-run` shows the diff and writes nothing.
#[test]
fn calibration_keeps_comments_makes_a_backup_and_dry_run_shows_the_diff() {
    let p = project();
    let dir = p.path();
    let local = dir.join("config/local.toml");
    std::fs::write(&local, LOCAL).unwrap();
    let args = [
        "calibrate",
        "ranging",
        "--from-sim",
        "12",
        "--sim-tilt-error-deg",
        "1.5",
    ];
    let before = snapshot(dir, &[]);
    let mut dry: Vec<&str> = args.to_vec();
    dry.push("--dry-run");
    let o = rccar(dir, &dry);
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert!(o.stdout.contains("- tilt_deg = 20.0 # was 19"), "{}", o.stdout);
    assert!(o.stdout.contains("+ tilt_deg = 21.5"), "{}", o.stdout);
    assert!(o.stdout.contains("+ [ranging]") && o.stdout.contains("dry run: nothing written"));
    assert_unchanged(&before, dir, &[], "--dry-run");

    let o = rccar(dir, &args);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let new = std::fs::read_to_string(&local).unwrap();
    for kept in [
        "# Maria's settings (keep these comments!)",
        "kp = 1.2  # tuned on the long straight",
        "# measured with a protractor",
        " # was 19",
    ] {
        assert!(new.contains(kept), "lost `{kept}`:\n{new}");
    }
    let t: toml::Table = new.parse().unwrap();
    let tilt = t["camera"]["tilt_deg"].as_float().unwrap();
    assert!((tilt - 21.5).abs() < 0.3, "tilt {tilt} (true 21.5)");
    assert_eq!(
        std::fs::read_to_string(dir.join("config/local.toml.bak")).unwrap(),
        LOCAL
    );
    // A second calibration keeps the first backup and makes another.
    assert_eq!(rccar(dir, &args).code, Some(0));
    assert_eq!(
        std::fs::read_to_string(dir.join("config/local.toml.bak")).unwrap(),
        LOCAL
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("config/local.toml.bak2")).unwrap(),
        new
    );
}

// ---------------------------------------------------------------------------------------
// Paths and where the config lives.

/// `cd /tmp && rccar sim`: no project here; the message says how to point at one, once.
#[test]
fn outside_the_project_it_uses_the_source_tree_config_and_says_so() {
    let t = tempfile::tempdir().unwrap();
    // No config/car.toml in the temporary folder or above it: the binary falls back to the
    // config of the source tree it was built from (this checkout), and names the file.
    let o = rccar(t.path(), &["config", "check"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let ours = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/car.toml");
    assert!(
        o.stderr.contains(&format!("using {} (the source tree rccar was built from", ours.display())),
        "{}",
        o.stderr
    );
    assert_eq!(o.stderr.matches("no config/car.toml here or above").count(), 1, "said once: {}", o.stderr);
    let o = rccar(t.path(), &["sim", "--config", "nope/car.toml"]);
    assert_eq!(o.code, Some(2));
    assert_eq!(o.stderr.matches("No such file or directory").count(), 1, "{}", o.stderr);
    assert!(o.stderr.contains("nope/car.toml: cannot read") && o.stderr.contains("--config FILE"));
    let o = rccar_env(t.path(), &["config", "check"], &[("RCCAR_CONFIG", "/nope/car.toml")]);
    assert_eq!(o.code, Some(1));
    assert_eq!(o.stderr.matches("No such file or directory").count(), 1, "{}", o.stderr);
    assert_eq!(snapshot(t.path(), &[]).len(), 0, "nothing written");
}

/// `--config /abs/car.toml` from elsewhere: the track and cascades come from the config's
/// folder, so the simulator runs (with the detectors) from any working directory.
#[test]
fn paths_in_a_config_resolve_against_its_folder() {
    let p = project();
    let elsewhere = tempfile::tempdir().unwrap();
    let car = p.path().join("config/car.toml");
    let o = rccar(
        elsewhere.path(),
        &["config", "check", "--config", car.to_str().unwrap()],
    );
    assert_eq!(o.code, Some(0), "{}", o.all());
    let want = p.path().join("config/tracks/default.toml");
    assert!(
        o.stdout.contains(&format!("track = \"{}\"", want.display())),
        "{}",
        o.stdout
    );
    let o = rccar(
        elsewhere.path(),
        &[
            "sim",
            "--config",
            car.to_str().unwrap(),
            "--seconds",
            "0.3",
            "--no-timing",
            "-o",
            "out",
        ],
    );
    // `--seconds` without `--laps` is a timed run: it ran, stayed in the lane, exit 0
    assert_eq!(o.code, Some(0), "a 0.3 s timed run: {}", o.all());
    assert!(
        o.stdout.contains("sim: 9 frames") && !o.stderr.contains("detect: missing"),
        "{}",
        o.all()
    );
    // A relative path in local.toml resolves against local.toml's folder, one given with
    // --set against the working directory.
    let sub = p.path().join("mine");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::copy(p.path().join("config/tracks/default.toml"), sub.join("t.toml")).unwrap();
    std::fs::write(sub.join("local.toml"), "[sim]\ntrack = \"t.toml\"\n").unwrap();
    let o = rccar(p.path(), &["config", "check", "--local", "mine/local.toml"]);
    assert!(
        o.stdout
            .contains(&format!("track = \"{}\"", sub.join("t.toml").display())),
        "{}",
        o.all()
    );
    let o = rccar(&sub, &["config", "check", "--set", "sim.track=t.toml"]);
    assert!(
        o.stdout
            .contains(&format!("track = \"{}\"", sub.join("t.toml").display())),
        "{}",
        o.all()
    );
}

/// Found from a subfolder, or from RCCAR_CONFIG.
#[test]
fn the_config_is_found_from_a_subfolder_or_rccar_config() {
    let p = project();
    let deep = p.path().join("labs/week3");
    std::fs::create_dir_all(&deep).unwrap();
    let o = rccar(&deep, &["config", "check"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert!(
        o.stderr
            .contains(&format!("config OK: {}", p.path().join("config/car.toml").display())),
        "{}",
        o.stderr
    );
    let other = tempfile::tempdir().unwrap();
    let car = p.path().join("config/car.toml");
    let o = rccar_env(
        other.path(),
        &["config", "check"],
        &[("RCCAR_CONFIG", car.to_str().unwrap())],
    );
    assert_eq!(o.code, Some(0), "{}", o.all());
}

/// A mistyped `--local` is an error, not silently ignored.
#[test]
fn a_named_local_that_does_not_exist_is_an_error() {
    let p = project();
    let o = rccar(p.path(), &["config", "check", "--local", "config/locl.toml"]);
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr.contains("--local config/locl.toml: no such file"),
        "{}",
        o.stderr
    );
    let o = rccar(p.path(), &["sim", "--local", "config/locl.toml"]);
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr.contains("--local config/locl.toml: no such file"),
        "{}",
        o.stderr
    );
}

/// An empty config passes `config check` and says every value is a default.
#[test]
fn an_empty_config_says_every_value_is_a_default() {
    let p = project();
    std::fs::write(p.path().join("empty.toml"), "").unwrap();
    let o = rccar(p.path(), &["config", "check", "empty.toml"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert!(
        o.stderr
            .contains("note: no values are set in empty.toml: every value is a default"),
        "{}",
        o.stderr
    );
    let o = rccar(p.path(), &["config", "check"]);
    assert!(!o.stderr.contains("every value is a default"), "{}", o.stderr);
}

// ---------------------------------------------------------------------------------------
// Damaged and clashing files.

fn sample_png(i: usize) -> PathBuf {
    Path::new(ROOT).join(format!("tests/data/lane_sample/frame_{i:03}.png"))
}

fn jpeg_of(png: &Path) -> Vec<u8> {
    let img = image::open(png).unwrap().to_rgb8();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Jpeg).unwrap();
    out.into_inner()
}

/// `rccar replay DIR` with a JPEG cut in half (ours, and OpenCV's baboon.jpg when installed):
/// a named, counted skip, not a grey frame.
#[test]
fn a_jpeg_cut_in_half_is_a_named_skip_in_replay_and_stages() {
    let p = project();
    let frames = p.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    std::fs::copy(sample_png(0), frames.join("a_good.png")).unwrap();
    let j = jpeg_of(&sample_png(1));
    std::fs::write(frames.join("b_half.jpg"), &j[..j.len() / 2]).unwrap();
    let baboon = Path::new(OPENCV_DATA).join("baboon.jpg");
    let mut halves = 1;
    if let Ok(b) = std::fs::read(&baboon) {
        std::fs::write(frames.join("c_baboon_half.jpg"), &b[..b.len() / 2]).unwrap();
        halves += 1;
    }
    let before = snapshot(p.path(), &["out"]);
    let o = rccar(p.path(), &["replay", "frames", "-o", "out", "--no-timing"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert!(o.stdout.contains("replayed 1 frames"), "{}", o.stdout);
    assert!(o.stdout.contains(&format!("skipped {halves} frame(s)")), "{}", o.stdout);
    assert!(
        o.all().contains("b_half.jpg: damaged JPEG") && o.all().contains("cut short"),
        "{}",
        o.all()
    );
    let tel = std::fs::read_to_string(p.path().join("out/telemetry.jsonl")).unwrap();
    assert_eq!(tel.lines().count(), 1);
    // stages: the same frames, and a 1×1 image that replay would refuse too.
    image::RgbImage::new(1, 1).save(frames.join("d_tiny.png")).unwrap();
    let before = {
        let mut b = before;
        b.insert(
            PathBuf::from("frames/d_tiny.png"),
            std::fs::read(frames.join("d_tiny.png")).unwrap(),
        );
        b
    };
    let o = rccar(
        p.path(),
        &[
            "stages",
            "frames/a_good.png",
            "frames/b_half.jpg",
            "frames/d_tiny.png",
            "-o",
            "out/st",
        ],
    );
    assert_eq!(o.code, Some(1), "{}", o.all());
    assert!(
        o.stderr.contains("skipped frames/b_half.jpg: damaged JPEG"),
        "{}",
        o.stderr
    );
    assert!(
        o.stderr
            .contains("skipped frames/d_tiny.png: 1×1 is smaller than the ROI"),
        "{}",
        o.stderr
    );
    assert!(o.stderr.contains("2 of 3 image(s) skipped"), "{}", o.stderr);
    assert!(p.path().join("out/st/a_good.png.bird.png").is_file());
    assert_unchanged(&before, p.path(), &["out"], "replay/stages");
}

/// `a.jpg` and `a.png` in one folder: two frames, two annotated files (`a.jpg.png`, `a.png.png`).
#[test]
fn same_stem_frames_get_distinct_outputs() {
    let p = project();
    let frames = p.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    std::fs::copy(sample_png(2), frames.join("a.png")).unwrap();
    std::fs::write(frames.join("a.jpg"), jpeg_of(&sample_png(3))).unwrap();
    let o = rccar(p.path(), &["replay", "frames", "-o", "out", "--no-timing"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let mut names: Vec<String> = std::fs::read_dir(p.path().join("out/annotated"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a.jpg.png", "a.png.png"]);
    let o = rccar(p.path(), &["stages", "frames/a.png", "frames/a.jpg", "-o", "out/st"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert!(p.path().join("out/st/a.png.bird.png").is_file() && p.path().join("out/st/a.jpg.bird.png").is_file());
}

/// A non-UTF-8 frame name: the same escaped name in telemetry and on disk.
#[test]
fn a_non_utf8_frame_name_is_kept_lossless() {
    use std::os::unix::ffi::OsStrExt;
    let p = project();
    let frames = p.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let name = std::ffi::OsStr::from_bytes(b"fr\xFFame.png");
    std::fs::copy(sample_png(4), frames.join(name)).unwrap();
    let o = rccar(p.path(), &["replay", "frames", "-o", "out", "--no-timing"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let tel = std::fs::read_to_string(p.path().join("out/telemetry.jsonl")).unwrap();
    let rec: serde_json::Value = serde_json::from_str(tel.lines().next().unwrap()).unwrap();
    let escaped = rec["file"].as_str().unwrap();
    assert_eq!(escaped, "fr\\xFFame.png");
    assert!(p.path().join("out/annotated").join(format!("{escaped}.png")).is_file());
}

fn cascade_path(p: &Path) -> String {
    p.join("config/cascades/stop_sign.xml").display().to_string()
}

/// `rccar detect` with an unreadable image in the middle: the others still run; exit 1.
#[test]
fn detect_goes_on_after_a_bad_image_and_fails_at_the_end() {
    let p = project();
    let d = p.path();
    std::fs::copy(sample_png(5), d.join("one.png")).unwrap();
    std::fs::write(d.join("two.png"), b"not an image at all").unwrap();
    let j = jpeg_of(&sample_png(6));
    std::fs::write(d.join("three.jpg"), &j[..j.len() * 2 / 3]).unwrap();
    std::fs::copy(sample_png(7), d.join("four.png")).unwrap();
    let c = cascade_path(d);
    let o = rccar(
        d,
        &[
            "detect",
            "--cascade",
            &c,
            "one.png",
            "two.png",
            "three.jpg",
            "four.png",
            "--out",
            "out",
        ],
    );
    assert_eq!(o.code, Some(1), "{}", o.all());
    let lines: Vec<&str> = o.stdout.lines().collect();
    assert_eq!(lines.len(), 2, "{}", o.stdout);
    assert!(
        lines[0].contains("\"one.png\"") && lines[1].contains("\"four.png\""),
        "{}",
        o.stdout
    );
    assert!(
        o.stderr.contains("skipped two.png: not a readable image"),
        "{}",
        o.stderr
    );
    assert!(o.stderr.contains("skipped three.jpg: damaged JPEG"), "{}", o.stderr);
    assert!(o.stderr.contains("2 of 4 image(s) failed"), "{}", o.stderr);
    assert!(d.join("out/one.png.detect.png").is_file() && d.join("out/four.png.detect.png").is_file());
}

/// `detect --scale-factor 1.0000001` is refused at once instead of running 10,000 levels.
#[test]
fn detect_refuses_a_scale_factor_that_means_a_huge_pyramid() {
    let p = project();
    std::fs::copy(sample_png(8), p.path().join("one.png")).unwrap();
    let c = cascade_path(p.path());
    let t = std::time::Instant::now();
    let o = rccar(
        p.path(),
        &["detect", "--cascade", &c, "--scale-factor", "1.0000001", "one.png"],
    );
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr.contains("--scale-factor 1.0000001: must be 1.01..=4"),
        "{}",
        o.stderr
    );
    assert!(t.elapsed().as_secs_f64() < 2.0);
}

/// Disk full (/dev/full): the error names the file, and the old local.toml survives.
#[test]
fn disk_full_errors_name_the_file() {
    let p = project();
    let d = p.path();
    std::fs::copy(sample_png(9), d.join("one.png")).unwrap();
    let c = cascade_path(d);
    std::fs::create_dir_all(d.join("out")).unwrap();
    std::os::unix::fs::symlink("/dev/full", d.join("out/one.png.detect.png")).unwrap();
    let o = rccar(d, &["detect", "--cascade", &c, "one.png", "--out", "out"]);
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(
        o.stderr.contains("out/one.png.detect.png: cannot write") && o.stderr.contains("No space left on device"),
        "{}",
        o.stderr
    );
    std::fs::create_dir_all(d.join("st")).unwrap();
    std::os::unix::fs::symlink("/dev/full", d.join("st/stages.jsonl")).unwrap();
    let o = rccar(d, &["stages", "one.png", "-o", "st"]);
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(
        o.stderr.contains("st/stages.jsonl: cannot write") && o.stderr.contains("No space left"),
        "{}",
        o.stderr
    );
    // calibrate: the new local.toml cannot be written; the old one is intact.
    std::fs::write(d.join("config/local.toml"), LOCAL).unwrap();
    std::os::unix::fs::symlink("/dev/full", d.join("config/local.toml.tmp")).unwrap();
    let o = rccar(d, &["calibrate", "ranging", "--from-sim", "8"]);
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(
        o.stderr
            .contains("config/local.toml: cannot write: No space left on device"),
        "{}",
        o.stderr
    );
    assert_eq!(std::fs::read_to_string(d.join("config/local.toml")).unwrap(), LOCAL);
    let o = rccar(
        d,
        &[
            "calibrate",
            "ranging",
            "--from-sim",
            "8",
            "--dry-run",
            "--sim-pairs-out",
            "/dev/full",
        ],
    );
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(o.stderr.contains("/dev/full: cannot write"), "{}", o.stderr);
}

// ---------------------------------------------------------------------------------------
// Sizes nobody checked.

/// A closed track with `radius_m = 1000` (1.6 GB) or `1e6`: refused before any allocation,
/// naming the key and the bound.
#[test]
fn a_huge_track_is_refused_before_allocation() {
    let p = project();
    for r in ["1000", "1e6"] {
        let text = format!(
            "name = \"huge\"\n[road]\nlane_width_m = 0.3\n[[segments]]\ntype = \"arc\"\nradius_m = {r}\nangle_deg = 360\n"
        );
        std::fs::write(p.path().join("huge.toml"), text).unwrap();
        let t = std::time::Instant::now();
        let o = rccar(p.path(), &["sim", "--track", "huge.toml", "--seconds", "0.1"]);
        assert_eq!(o.code, Some(2), "{}", o.all());
        assert!(
            o.stderr.contains("huge.toml: `segments[0].radius_m`") && o.stderr.contains("at most 20 m"),
            "{}",
            o.stderr
        );
        assert!(t.elapsed().as_secs_f64() < 2.0);
    }
    // A long straight, and a floor too large for the scene's grid.
    let text = "[road]\nlane_width_m = 0.3\n[[segments]]\ntype = \"straight\"\nlength_m = 1e9\n";
    std::fs::write(p.path().join("long.toml"), text).unwrap();
    let o = rccar(p.path(), &["sim", "--track", "long.toml"]);
    assert!(
        o.code == Some(2) && o.stderr.contains("segments[0].length_m") && o.stderr.contains("at most 50 m"),
        "{}",
        o.all()
    );
    let text = "[road]\nlane_width_m = 0.3\n[floor]\nmargin_m = 30\n[[segments]]\ntype = \"arc\"\nradius_m = 1\nangle_deg = 360\n";
    std::fs::write(p.path().join("wide.toml"), text).unwrap();
    let o = rccar(p.path(), &["sim", "--track", "wide.toml"]);
    assert!(
        o.code == Some(2) && o.stderr.contains("floor.margin_m") && o.stderr.contains("at most 50 × 50 m"),
        "{}",
        o.all()
    );
}

/// `config roi --near 1.0 --far 0.4` and `--half-width 0` are refused; `config check` refuses
/// an upside-down ROI.
#[test]
fn roi_upside_down_or_degenerate_is_refused() {
    let p = project();
    let d = p.path();
    let o = rccar(d, &["config", "roi", "--near", "1.0", "--far", "0.4"]);
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr.contains("--near 1 must be less than --far 0.4"),
        "{}",
        o.stderr
    );
    assert!(o.stdout.is_empty());
    let o = rccar(d, &["config", "roi", "--half-width", "0"]);
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr.contains("--half-width 0: must be a distance in metres, > 0"),
        "{}",
        o.stderr
    );
    let o = rccar(
        d,
        &["config", "roi", "--near", "0.4", "--far", "1.0", "--half-width", "0.25"],
    );
    assert_eq!(o.code, Some(0));
    assert!(
        o.stdout
            .contains("[[93.72, 78.96], [225.28, 78.96], [308.75, 150.02], [10.25, 150.02]]"),
        "{}",
        o.stdout
    );
    // What `config roi --near 1.0 --far 0.4` used to print, pasted into local.toml.
    std::fs::write(
        d.join("config/local.toml"),
        "[warp]\nsrc = [[10.25, 150.02], [308.75, 150.02], [225.28, 78.96], [93.72, 78.96]]\n",
    )
    .unwrap();
    let o = rccar(d, &["config", "check"]);
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr.contains("warp.src") && o.stderr.contains("looks at the floor upside down"),
        "{}",
        o.stderr
    );
    let o = rccar(d, &["replay", "frames"]);
    assert_eq!(o.code, Some(2));
    assert!(o.stderr.contains("upside down"), "{}", o.stderr);
}

/// Numbers: `--set steering.kp=1e309`, `--seconds nan`, inf: the key, what was typed, and
/// that inf/NaN are not allowed. `--laps 0` means "no lap target": the run ends by time.
#[test]
fn numbers_name_the_key_and_what_was_typed() {
    let p = project();
    let d = p.path();
    let o = rccar(d, &["sim", "--set", "steering.kp=1e309"]);
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr
            .contains("`steering.kp` = `1e309` is not a finite number (inf and NaN are not allowed)"),
        "{}",
        o.stderr
    );
    let o = rccar(d, &["sim", "--seconds", "nan"]);
    assert_eq!(o.code, Some(2));
    assert!(
        o.stderr.contains("`sim.max_seconds` = `NaN` is not a finite number"),
        "{}",
        o.stderr
    );
    let o = rccar(d, &["config", "check", "--set", "steering.kp=-inf"]);
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr.contains("`steering.kp` = `-inf` is not a finite number"),
        "{}",
        o.stderr
    );
    std::fs::write(d.join("config/local.toml"), "[steering]\nkd = nan\n").unwrap();
    let o = rccar(d, &["config", "check"]);
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr
            .contains("local.toml: `steering.kd` = `NaN` is not a finite number"),
        "{}",
        o.stderr
    );
    std::fs::remove_file(d.join("config/local.toml")).unwrap();
    let o = rccar(d, &["config", "check", "--set", "steering.kp=fast"]);
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr
            .contains("`steering.kp` = \"fast\": invalid type: string \"fast\", expected f64"),
        "{}",
        o.stderr
    );
    let o = rccar(
        d,
        &["sim", "--laps", "0", "--seconds", "0.2", "--no-timing", "-o", "out"],
    );
    assert!(
        o.stdout.contains("ended: TimeUp") && o.stdout.contains("laps completed:   0"),
        "{}",
        o.all()
    );
    let car = std::fs::read_to_string(d.join("config/car.toml")).unwrap();
    assert!(car.contains("0 = no lap target: drive until\n# max_seconds"));
}

/// Other sizes a flag controls: the camera (render size), a sweep's count, the lab's pairs,
/// and an image whose header claims 100000 × 100000 pixels.
#[test]
fn every_size_a_flag_or_file_controls_is_bounded() {
    let p = project();
    let d = p.path();
    let o = rccar(d, &["config", "check", "--set", "camera.width=100000"]);
    assert!(
        o.code == Some(1)
            && o.stderr
                .contains("camera.width = 100000 is out of range (allowed: 16 ..= 4096)"),
        "{}",
        o.all()
    );
    let o = rccar(d, &["sim", "--sweep", "steering.kp=0:1:100000"]);
    assert!(
        o.code == Some(2) && o.stderr.contains("N must be 1..=1000"),
        "{}",
        o.all()
    );
    let o = rccar(d, &["calibrate", "ranging", "--from-sim", "100000000"]);
    assert!(
        o.code == Some(2) && o.stderr.contains("--from-sim 100000000: must be 3..=10000"),
        "{}",
        o.all()
    );
    std::fs::write(d.join("big.png"), png_claiming(100_000, 100_000)).unwrap();
    let o = rccar(d, &["stages", "big.png", "-o", "out"]);
    assert!(
        o.code == Some(1) && o.stderr.contains("100000×100000 pixels is outside the image limit"),
        "{}",
        o.all()
    );
}

/// Issue 24: a configured cascade that is missing is an error naming the key, the file and the
/// fix, for every command that runs the detector; before, `sim` warned and ran on without the
/// stop-sign detector (exit 0). An empty path switches one class off on purpose, and the
/// shipped configuration's cascades are there (the default runs).
#[test]
fn a_missing_cascade_is_an_error_naming_the_key_and_the_fix() {
    let p = project();
    let d = p.path();
    let set = "classes.stop_sign.model=/nonexistent.xml";
    std::fs::create_dir_all(d.join("frames")).unwrap();
    std::fs::copy(sample_png(0), d.join("frames/a.png")).unwrap();
    let runs: [&[&str]; 5] = [
        &["sim", "--seconds", "1", "--no-timing", "-o", "out/sim", "--set", set],
        &["detect", "frames/a.png", "--out", "out/det0", "--set", set],
        &["replay", "frames", "-o", "out/replay", "--no-timing", "--set", set],
        &["drive", "--camera", "sim", "--dry-run", "--seconds", "1", "-o", "out/drive", "--set", set],
        &["stereo", "frames/a.png", "frames/a.png", "--set", set],
    ];
    for args in runs {
        let o = rccar(d, args);
        assert_eq!(o.code, Some(2), "{args:?}: {}", o.all());
        assert!(
            o.stderr.contains("classes.stop_sign.model = \"/nonexistent.xml\": no such cascade file")
                && o.stderr.contains("classes.stop_sign.model = \"\" to run without that detector")
                && o.stderr.contains("detect.enabled = false"),
            "{args:?}: {}",
            o.stderr
        );
    }
    // rccar detect names its --cascade file.
    let o = rccar(d, &["detect", "--cascade", "/nonexistent.xml", "frames/a.png", "--out", "out/det"]);
    assert_eq!(o.code, Some(2), "{}", o.all());
    assert!(o.stderr.contains("/nonexistent.xml"), "{}", o.stderr);
    // Without --cascade, rccar detect runs the configured classes' cascades (one switched off
    // on purpose is left out).
    let o = rccar(d, &["detect", "frames/a.png", "--out", "out/det1", "--set", "classes.obstacle.model="]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let line = o.stderr.lines().find(|l| l.starts_with("detect: the configuration's cascades: ")).unwrap_or_default();
    for kind in ["stop_sign", "traffic_light", "yield_sign", "turn_sign"] {
        assert!(line.contains(&format!("config/cascades/{kind}.xml")), "{kind}: {}", o.all());
    }
    assert!(!line.contains("obstacle"), "{}", o.all());
    assert!(o.stdout.contains("\"image\""), "{}", o.all());
    // The shipped cascades, and one class switched off on purpose: the run goes on.
    for (extra, out) in [(None, "out/sim2"), (Some("classes.stop_sign.model="), "out/sim3")] {
        let mut args = vec!["sim", "--seconds", "1", "--no-timing", "-o", out];
        if let Some(e) = extra {
            args.extend(["--set", e]);
        }
        let o = rccar(d, &args);
        assert_eq!(o.code, Some(0), "{extra:?}: {}", o.all());
        assert!(!o.stderr.contains("missing"), "{extra:?}: {}", o.stderr);
    }
}

/// Issue 24: `rccar plot` bounds its fields (16 panels), files (8, one colour each), points
/// (10 million over all of them) and line length (1 MiB). Before: 5,600 fields panicked
/// (exit 101) and 1,500 aborted under a memory cap (a 1000 × 390,040 px image).
/// `rccar sim`'s speed line says what the run cost beside the real-time factor: its CPU time
/// and how many of the cores it may use it had on average (on a shared machine the factor
/// falls while the CPU time stays).
#[test]
fn the_sim_speed_line_says_its_cpu_time_and_cores() {
    let p = project();
    let o = rccar(p.path(), &["sim", "--seconds", "2", "--no-timing", "-o", "out/s"]);
    assert_eq!(o.code, Some(0), "{}", o.all());
    let speed = o.all().lines().find(|l| l.contains("x real time")).map(str::to_string).unwrap_or_default();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    assert!(
        speed.starts_with("  2.0 s simulated in ") && speed.ends_with(&format!(" of {cores} cores)")),
        "{speed}"
    );
    let cpu: f64 = speed
        .split(" (")
        .nth(1)
        .and_then(|r| r.split(" s CPU: ").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(-1.0);
    assert!(cpu > 0.0 && cpu < 60.0, "{speed}");
}

#[test]
fn plot_bounds_its_fields_files_points_and_lines() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tel: String = (0..50).map(|i| format!("{{\"time_s\":{i},\"steer\":0.1}}\n")).collect();
    std::fs::write(d.join("t.jsonl"), &tel).unwrap();
    let many = vec!["steer"; 5600].join(",");
    let sixteen = vec!["steer"; 16].join(",");
    let nine: Vec<&str> = vec!["t.jsonl"; 9];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["plot", "t.jsonl", "--y", &many], "--y: 5600 fields; at most 16"),
        (vec!["plot", "t.jsonl", "--y", "steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer,steer"], "--y: 17 fields; at most 16"),
        ([&["plot"][..], &nine, &["--y", "steer"]].concat(), "9 telemetry files; at most 8"),
    ];
    for (args, want) in cases {
        let o = rccar(d, &args);
        assert_eq!(o.code, Some(2), "{want}: {}", o.all());
        assert!(o.stderr.contains(want), "{want}: {}", o.stderr);
    }
    // At the bounds: 16 fields, 8 files.
    let eight: Vec<&str> = vec!["t.jsonl"; 8];
    let o = rccar(d, &[&["plot"][..], &eight, &["--y", &sixteen, "-o", "p.png"]].concat());
    assert_eq!(o.code, Some(0), "{}", o.all());
    assert_eq!(image::image_dimensions(d.join("p.png")).unwrap(), (1000, 40 + 260 * 16));
    // A 2 MiB line, and 625,001 records × 16 fields = 10,000,016 points.
    std::fs::write(d.join("long.jsonl"), format!("{{\"time_s\":1,\"s\":\"{}\"}}\n", "x".repeat(2 << 20))).unwrap();
    let o = rccar(d, &["plot", "long.jsonl", "--y", "steer"]);
    assert!(o.code == Some(2) && o.stderr.contains("long.jsonl:1: line longer than 1048576 bytes"), "{}", o.all());
    let big: String = (0..625_001).map(|i| format!("{{\"time_s\":{i},\"steer\":1}}\n")).collect();
    std::fs::write(d.join("big.jsonl"), big).unwrap();
    let o = rccar(d, &["plot", "big.jsonl", "--y", &sixteen]);
    assert!(
        o.code == Some(2) && o.stderr.contains("big.jsonl:625001: more than 10000000 points"),
        "{}",
        o.all()
    );
}

/// Issue 24: every size and count a flag of `rccar` controls has a stated bound (in `--help`),
/// enforced with an error naming the flag (or file) and the bound. One case per bound class:
/// counts of things (files, boxes, pairs, pings, jobs), sizes in pixels, lengths and times,
/// and files read whole (a cascade, a calibration, a pairs CSV given as /dev/zero, an image
/// whose header claims 100000 × 100000 pixels). Before: `stereo --box 9223372036854775807,0,5,5`
/// panicked, `link --latency 18446744073709551615` would ask for that many slots, `/dev/zero`
/// as a cascade or calibration was read until memory ran out; the rest were taken silently.
#[test]
fn every_flag_names_its_bound() {
    let p = project();
    let d = p.path();
    std::fs::write(d.join("big.png"), png_claiming(100_000, 100_000)).unwrap();
    let img = sample_png(0).display().to_string();
    let cascade = cascade_path(d);
    let mut many_pairs = String::from("row_px,distance_m\n");
    for i in 0..10_001 {
        many_pairs += &format!("{},{}\n", 100 + i % 100, 0.5 + i as f64 * 1e-5);
    }
    std::fs::write(d.join("many.csv"), many_pairs).unwrap();
    let boxes: Vec<String> = (0..1001).map(|_| "--box=1,1,5,5".to_string()).collect();
    let imgs_101: Vec<&str> = vec![img.as_str(); 101];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        // detect
        (vec!["detect", "--cascade", &cascade, &img, "--min-neighbors", "101"], "--min-neighbors 101: must be 0..=100"),
        (vec!["detect", "--cascade", &cascade, &img, "--min-size", "16385x5"], "--min-size 16385x5: each side must be 0..=16384"),
        (vec!["detect", "--cascade", &cascade, &img, "--max-size", "5x99999"], "--max-size 5x99999: each side must be 0..=16384"),
        ([&["detect"][..], &["--cascade", &cascade].repeat(17), &[img.as_str()]].concat(), "17 --cascade files: at most 16"),
        (vec!["detect", "--cascade", "/dev/zero", &img], "/dev/zero: larger than a cascade file may be (33554432 bytes)"),
        // calibrate camera / stereo
        (vec!["calibrate", "camera", &img, "--square", "2"], "--square 2 must be a length in metres, > 0 and <= 1"),
        (vec!["calibrate", "camera", &img, "--subpix-win", "0"], "--subpix-win 0: must be 1..=32"),
        (vec!["calibrate", "camera", &img, "--subpix-win", "1000"], "--subpix-win 1000: must be 1..=32"),
        ([&["calibrate", "camera"][..], &imgs_101].concat(), "101 images: at most 100"),
        (vec!["calibrate", "camera", "big.png", "big.png", "big.png"], "big.png: 100000×100000 pixels is outside the image limit"),
        (vec!["calibrate", "stereo", "--left", &img, "--right", &img, "--max-rms-px", "6"], "--max-rms-px 6: must be > 0 and <= 5"),
        // calibrate ranging
        (vec!["calibrate", "ranging", "--from-sim", "10", "--max-rms-px", "1000"], "--max-rms-px 1000: must be > 0 and <= 100"),
        (vec!["calibrate", "ranging", "--from-sim", "10", "--v0-sigma-px", "1e9"], "--v0-sigma-px 1000000000: must be 0..=1000"),
        (vec!["calibrate", "ranging", "many.csv"], "many.csv: 10001 pairs; at most 10000"),
        (vec!["calibrate", "ranging", "/dev/zero"], "/dev/zero: larger than 1048576 bytes"),
        // stereo
        (vec!["stereo", &img, &img, "--box", "9223372036854775807,0,5,5"], "X and Y must be 0..=16384, W and H 1..=16384"),
        (vec!["stereo", &img, &img, "--box", "0,0,0,5"], "X and Y must be 0..=16384, W and H 1..=16384"),
        ([&["stereo", &img, &img][..], &boxes.iter().map(String::as_str).collect::<Vec<_>>()].concat(), "1001 --box flags: at most 1000"),
        (vec!["stereo", "big.png", "big.png", "--box", "1,1,5,5"], "big.png: 100000×100000 pixels is outside the image limit"),
        (vec!["stereo", &img, &img, "--box", "1,1,5,5", "--set", "stereo.calibration=/dev/zero"], "larger than a calibration file may be (16777216 bytes)"),
        // link (checked before the port is opened)
        (vec!["link", "--port", "/nonexistent", "--latency", "18446744073709551615"], "--latency 18446744073709551615: must be 1..=10000"),
        (vec!["link", "--port", "/nonexistent", "--seconds", "1e9"], "--seconds 1000000000: must be > 0 and <= 86400"),
        // drive
        (vec!["drive", "--camera", "sim", "--dry-run", "--seconds", "1e20"], "--seconds 100000000000000000000: must be > 0 and <= 86400"),
        (vec!["drive", "--camera", "sim", "--dry-run", "--seconds", "1", "--status-every", "NaN"], "--status-every NaN: must be 0.2..=3600"),
        (vec!["drive", "--camera", "sim", "--dry-run", "--seconds", "1", "--record-max-mb", "1e300"], "must be 1..=1000000 megabytes (as record.max_mb)"),
        // sim
        (vec!["sim", "--sweep", "steering.kp=0.5:1:2", "--jobs", "0"], "--jobs 0: must be 1..=256"),
        (vec!["sim", "--sweep", "steering.kp=0.5:1:2", "--jobs", "100000"], "--jobs 100000: must be 1..=256"),
        (vec!["sim", "--kick", "1e9:0.01"], "--kick `1e9:0.01`: expected T:DY (seconds 0..=36000 : metres)"),
        (vec!["sim", "--sweep", "steering.kp=0:1:1000", "--sweep", "steering.kd=0:1:2"], "at most 1000"),
    ];
    let mut failed = Vec::new();
    for (args, want) in &cases {
        let o = rccar_lenient(d, args);
        if !(o.code == Some(2) && o.stderr.contains(want)) {
            let shown: Vec<&str> = args.iter().take(8).copied().collect();
            failed.push(format!("{shown:?}: want exit 2 and {want:?}, got {:?}: {}", o.code, o.stderr.trim()));
        }
    }
    assert!(failed.is_empty(), "{} of {} cases:\n{}", failed.len(), cases.len(), failed.join("\n"));
}

/// [`rccar`] without its panic check (the panic is reported as a failed case instead).
fn rccar_lenient(cwd: &Path, args: &[&str]) -> Out {
    let o = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(cwd)
        .args(args)
        .env_remove("RCCAR_CONFIG")
        .output()
        .unwrap();
    Out {
        code: o.status.code(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).chars().take(300).collect(),
    }
}

/// A structurally whole PNG whose header claims `w × h` (one tiny IDAT).
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    fn crc(data: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in data {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc(&body).to_be_bytes());
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &[0x78, 0x9C, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(&mut out, b"IEND", &[]);
    out
}
