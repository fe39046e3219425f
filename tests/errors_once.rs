//! An error names its cause once: a message that says the cause (the OS's reason, a cascade's
//! XML error) does not also hand it on as the error's `source`, or `rccar` (which prints the
//! chain of causes) printed it twice.

use std::path::PathBuf;
use std::process::{Command, Stdio};

const EXE: &str = env!("CARGO_BIN_EXE_rccar");

/// `rccar ARGS` from the repository root; (exit code, stderr).
fn rccar(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(EXE)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
}

#[test]
fn file_and_cascade_errors_name_their_cause_once() {
    let t = tempfile::tempdir().unwrap();
    let file = t.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    // A run folder inside a file: the run folder's error, with the OS's reason.
    let under: PathBuf = file.join("run");
    let (code, err) = rccar(&["sim", "--no-local", "--seconds", "1", "-o", under.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("a-file/run: cannot "), "{err}");
    assert_eq!(err.matches("Not a directory").count(), 1, "{err}");
    // A cascade that is not XML: the session's error, with the parser's.
    let bad = t.path().join("bad.xml");
    std::fs::write(&bad, "x").unwrap();
    let set = format!("classes.stop_sign.model={}", bad.display());
    let out = t.path().join("out");
    let (code, err) = rccar(&["sim", "--no-local", "--seconds", "1", "--set", &set, "-o", out.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("detect: "), "{err}");
    assert_eq!(err.matches("XML syntax error").count(), 1, "{err}");
}
