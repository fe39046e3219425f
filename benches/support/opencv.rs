//! The OpenCV side of a benchmark: a Python helper (`$RCCAR_PYTHON`, else `python3`, with
//! cv2 4.x) that stays up for the whole run, so both sides are timed in the same run and, in
//! alternating rounds, under the same machine load. The helper prints one line when it is
//! ready (JSON or a word), then answers each request line with one line (by convention a JSON
//! array of milliseconds). Shared by benches/detect.rs and benches/stereo.rs.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

/// The Python to run: `$RCCAR_PYTHON`, else `python3`.
pub fn python() -> String {
    std::env::var("RCCAR_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// A running helper.
pub struct OpenCv {
    child: Child,
    to: Option<ChildStdin>,
    from: BufReader<ChildStdout>,
}

impl OpenCv {
    /// Starts `python -c script args…` and returns it with its first line (trimmed).
    pub fn start<S: AsRef<std::ffi::OsStr>>(python: &str, script: &str, args: &[S]) -> (OpenCv, String) {
        let mut child = Command::new(python)
            .arg("-c")
            .arg(script)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("running the OpenCV helper ($RCCAR_PYTHON with cv2 4.x)");
        let to = child.stdin.take();
        let from = BufReader::new(child.stdout.take().expect("helper stdout"));
        let mut cv = OpenCv { child, to, from };
        let first = cv.read();
        (cv, first)
    }

    fn read(&mut self) -> String {
        let mut line = String::new();
        self.from.read_line(&mut line).expect("helper output");
        assert!(!line.is_empty(), "the OpenCV helper ended early (is cv2 4.x installed?)");
        line.trim().to_string()
    }

    /// Sends one request line and returns the answer line.
    pub fn ask(&mut self, request: &str) -> String {
        writeln!(self.to.as_mut().expect("helper stdin"), "{request}").expect("helper stdin");
        self.read()
    }

    /// Sends one request line and parses the answer as a JSON array of milliseconds.
    pub fn times(&mut self, request: &str) -> Vec<f64> {
        serde_json::from_str(&self.ask(request)).expect("helper JSON")
    }
}

impl Drop for OpenCv {
    /// Closes its input (the helper's loop ends) and waits for it.
    fn drop(&mut self) {
        drop(self.to.take());
        let _ = self.child.wait();
    }
}
