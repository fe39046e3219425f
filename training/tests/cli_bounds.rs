//! Every size and count a user gives `rccar-train` has a stated bound, enforced with an error
//! that names the flag and the bound (issue 24). Each case runs the binary with a deadline: a
//! command that spins (before: `gen --window 0x0`, `16x0` or `100000x100000` placed scenes
//! forever at 100 % CPU) fails the test instead of hanging it.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs `rccar-train ARGS` in `dir`; (exit code, stderr). Killed after `secs`.
fn run(dir: &Path, args: &[&str], secs: u64) -> (Option<i32>, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rccar-train"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rccar-train runs");
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            assert!(!err.contains("panicked"), "rccar-train {args:?} panicked:\n{err}");
            return (status.code(), err);
        }
        if Instant::now() > deadline {
            child.kill().ok();
            child.wait().ok();
            panic!("rccar-train {args:?} still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn track() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/tracks/default.toml")
        .display()
        .to_string()
}

/// `gen`: the window, count, scenes and distances, each refused by name and bound; a window
/// that fits the bounds but no view at those distances gives up after 20 placements.
#[test]
fn gen_refuses_every_size_out_of_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let t = track();
    let base = [
        "gen",
        "--kind",
        "stop_sign",
        "--split",
        "positives",
        "--out",
        "o",
        "--track",
        &t,
    ];
    let cases: [(&[&str], &str); 10] = [
        (&["--window", "0x0"], "--window 0x0: each side must be 3..=256 px"),
        (&["--window", "16x0"], "--window 16x0: each side must be 3..=256 px"),
        (
            &["--window", "100000x100000"],
            "--window 100000x100000: each side must be 3..=256 px",
        ),
        (
            &["--window", "250x250"],
            "--window 250x250: larger than the 320x240 camera image",
        ),
        (&["--count", "0"], "--count 0: must be 1..=1000000"),
        (&["--count", "99999999"], "--count 99999999: must be 1..=1000000"),
        (&["--scenes", "0"], "--scenes 0: must be 1..=10000"),
        (&["--min-distance", "0"], "each must be 0.05..=20 m, min < max"),
        (
            &["--min-distance", "2", "--max-distance", "1"],
            "each must be 0.05..=20 m, min < max",
        ),
        (&["--max-distance", "1e9"], "each must be 0.05..=20 m, min < max"),
    ];
    for (extra, want) in cases {
        let args: Vec<&str> = base.iter().copied().chain(extra.iter().copied()).collect();
        let (code, err) = run(d, &args, 60);
        assert_eq!(code, Some(2), "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: no {want:?} in {err}");
    }
    // In bounds, but no stop sign 0.2..1.5 m away is 200 px wide.
    let args: Vec<&str> = base
        .iter()
        .copied()
        .chain(["--window", "200x200", "--count", "5"])
        .collect();
    let (code, err) = run(d, &args, 120);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("no view of the StopSign") && err.contains("smaller --window"),
        "{err}"
    );
}
