//! A reader that goes away (`rccar sim | head -1`): the commands that print a line per frame,
//! per image or per box end quietly, as any Unix filter does (killed by SIGPIPE, no panic
//! message), instead of panicking on the next `println!`. The pipe is closed before the
//! command prints anything, so its first line already meets it.

use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::{Command, Stdio};

const EXE: &str = env!("CARGO_BIN_EXE_rccar");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `rccar ARGS` from the repository root with its stdout a pipe nobody reads (the read
/// end closed at once); returns (exit code, signal, stderr).
fn closed_stdout(args: &[&str]) -> (Option<i32>, Option<i32>, String) {
    let mut child = Command::new(EXE)
        .current_dir(root())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    (o.status.code(), o.status.signal(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// Ended quietly: no panic, and either done (0, or 1 for "some input was bad") or ended by
/// SIGPIPE.
fn quiet(what: &str, (code, signal, err): (Option<i32>, Option<i32>, String)) {
    assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{what}: {err}");
    assert!(
        signal == Some(libc::SIGPIPE) || matches!(code, Some(0 | 1)),
        "{what}: exit {code:?}, signal {signal:?}: {err}"
    );
}

#[test]
fn filters_end_quietly_when_their_reader_goes_away() {
    let t = tempfile::tempdir().unwrap();
    let out = |n: &str| t.path().join(n).to_string_lossy().into_owned();
    let frames = root().join("tests/data/lane_sample");
    let frame = frames.join("frame_000.png").to_string_lossy().into_owned();
    let frames = frames.to_string_lossy().into_owned();
    let (sim, replay, stages) = (out("sim"), out("replay"), out("stages"));
    quiet("sim", closed_stdout(&["sim", "--no-local", "--no-timing", "--seconds", "2", "-o", &sim]));
    quiet("replay", closed_stdout(&["replay", &frames, "--no-local", "--no-timing", "-o", &replay]));
    quiet(
        "detect",
        closed_stdout(&["detect", "--cascade", "config/cascades/stop_sign.xml", "--no-annotate", &frame, &frame]),
    );
    quiet("stages", closed_stdout(&["stages", &frame, "--no-local", "-o", &stages]));
    quiet("config check", closed_stdout(&["config", "check", "--no-local"]));
}
