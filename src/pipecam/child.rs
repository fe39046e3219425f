//! The camera program as a child process, ended on every way out.
//!
//! - **Its own process group** (`setpgid(0, 0)` through [`CommandExt::process_group`]): the
//!   terminal's Ctrl-C reaches rccar only (rccar stops at a frame boundary, sends neutral, then
//!   ends the program itself), and ending the group ends everything the command started (a
//!   `sh -c 'a | b'` pipeline too).
//! - **[`Producer::stop`]** (also its `Drop`): SIGTERM and SIGCONT to the group (a stopped
//!   program handles the TERM too), up to 0.5 s to exit, then SIGKILL; a last SIGKILL to the
//!   group for members that ignored the TERM, sent while the leader is still unreaped (so the
//!   group id cannot have been reused); then the leader is reaped.
//! - **`prctl(PR_SET_PDEATHSIG, SIGKILL)`** in the child before exec (Linux): if rccar itself
//!   dies without running any of this (SIGKILL, a second Ctrl-C's immediate exit), the kernel
//!   kills the program, so nothing is left holding the camera. The signal is tied to the
//!   *thread* that spawned the child: the reader thread spawns it and outlives it. It covers
//!   the direct child only: in a `sh -c '...'` pipeline the shell dies and the others get
//!   SIGPIPE (or EOF) at their next write; run one program directly when that matters (the
//!   `picam:` source does).
//! - A registry of live groups: [`kill_all`] SIGKILLs them from any thread (the binary's
//!   emergency exit on a second signal).
//!
//! The program's stdin is /dev/null (a background group reading the terminal would be
//! stopped), its stdout is the frame pipe, and the last lines of its stderr are kept (bounded:
//! 20 lines of at most 300 bytes) for the error message when it fails.

use std::collections::{BTreeSet, VecDeque};
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Lines of the program's stderr kept for messages.
const TAIL_LINES: usize = 20;
/// Bytes kept of one stderr line.
const TAIL_LINE_BYTES: usize = 300;
/// How long a program gets to exit after SIGTERM before SIGKILL.
const TERM_GRACE: Duration = Duration::from_millis(500);

fn groups() -> &'static Mutex<BTreeSet<i32>> {
    static G: OnceLock<Mutex<BTreeSet<i32>>> = OnceLock::new();
    G.get_or_init(|| Mutex::new(BTreeSet::new()))
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// SIGKILLs every camera program's process group still running (for an emergency exit that
/// skips the destructors; each is also killed by its parent-death signal).
pub fn kill_all() {
    for &pg in lock(groups()).iter() {
        // SAFETY: kill(2) with a negative pid signals that process group; no memory involved.
        unsafe {
            libc::kill(-pg, libc::SIGKILL);
        }
    }
}

/// A running camera program (see the module notes).
pub struct Producer {
    child: Mutex<Option<Child>>,
    pid: u32,
    program: String,
    tail: Arc<Mutex<VecDeque<String>>>,
    status: Mutex<Option<ExitStatus>>,
}

impl Producer {
    /// Starts `argv` (program and arguments, no shell) with its stdout piped; returns the
    /// producer and the pipe's read end. Call from the thread that reads it (see the module
    /// notes on the parent-death signal).
    pub fn spawn(argv: &[String]) -> Result<(Arc<Producer>, ChildStdout), String> {
        let (program, args) = argv.split_first().ok_or("an empty command")?;
        let mut cmd = Command::new(program);
        cmd.args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0);
        #[cfg(target_os = "linux")]
        {
            let parent = std::process::id() as libc::pid_t;
            // SAFETY: between fork and exec only async-signal-safe calls (prctl, getppid) and
            // no allocation (errors from raw OS codes).
            unsafe {
                cmd.pre_exec(move || {
                    if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong, 0, 0, 0) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    // The parent died before the prctl: it would never fire.
                    if libc::getppid() != parent {
                        return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
                    }
                    Ok(())
                });
            }
        }
        let mut child = cmd.spawn().map_err(|e| format!("cannot start `{program}`: {e}"))?;
        let pid = child.id();
        lock(groups()).insert(pid as i32);
        let stdout = child.stdout.take().ok_or("no stdout pipe")?;
        let tail = Arc::new(Mutex::new(VecDeque::new()));
        if let Some(err) = child.stderr.take() {
            let t = tail.clone();
            let _ = std::thread::Builder::new()
                .name("rccar-cam-stderr".into())
                .spawn(move || keep_tail(err, &t));
        }
        Ok((
            Arc::new(Producer {
                child: Mutex::new(Some(child)),
                pid,
                program: program.clone(),
                tail,
                status: Mutex::new(None),
            }),
            stdout,
        ))
    }

    /// The program's process id (also its process group id).
    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// The program's name.
    pub fn program(&self) -> &str {
        &self.program
    }

    /// The last lines it wrote to stderr, joined with " | " (empty when it said nothing).
    pub fn stderr_tail(&self) -> String {
        lock(&self.tail).iter().cloned().collect::<Vec<_>>().join(" | ")
    }

    /// How it ended, once [`Producer::stop`] has reaped it.
    pub fn status(&self) -> Option<ExitStatus> {
        *lock(&self.status)
    }

    /// Ends the program and everything in its process group, and reaps it (see the module
    /// notes); returns its exit status. Idempotent.
    pub fn stop(&self) -> Option<ExitStatus> {
        let mut g = lock(&self.child);
        let Some(mut child) = g.take() else {
            return self.status();
        };
        let pg = -(self.pid as i32);
        // SAFETY: kill(2) on our own child's group, which cannot be reused before the reap
        // below (the unreaped leader holds the id).
        unsafe {
            libc::kill(pg, libc::SIGTERM);
            libc::kill(pg, libc::SIGCONT);
        }
        if !exited(self.pid, TERM_GRACE) {
            unsafe {
                libc::kill(pg, libc::SIGKILL);
            }
            exited(self.pid, Duration::from_secs(2));
        }
        unsafe {
            libc::kill(pg, libc::SIGKILL);
        }
        let status = match child.try_wait() {
            Ok(Some(st)) => Some(st),
            // Not gone even after SIGKILL (a driver call that does not return): reaped later
            // by a thread of its own rather than blocking the car's shutdown.
            Ok(None) => {
                let _ = std::thread::Builder::new()
                    .name("rccar-cam-reap".into())
                    .spawn(move || {
                        let _ = child.wait();
                    });
                None
            }
            Err(_) => None,
        };
        lock(groups()).remove(&(self.pid as i32));
        *lock(&self.status) = status;
        status
    }

    /// How it ended, in words, with its last stderr lines: for the error that ends a source.
    /// It gets `grace` to exit by itself (it closed its stdout) before [`Producer::stop`].
    pub fn ended_line(&self, grace: Duration) -> String {
        exited(self.pid, grace);
        let st = self
            .stop()
            .map_or("still running after SIGKILL".to_string(), |s| s.to_string());
        let tail = self.stderr_tail();
        if tail.is_empty() {
            format!("`{}` ended ({st})", self.program)
        } else {
            format!("`{}` ended ({st}); it said: {tail}", self.program)
        }
    }
}

impl Drop for Producer {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Waits up to `timeout` for the child `pid` to exit, without reaping it (`WNOWAIT`).
fn exited(pid: u32, timeout: Duration) -> bool {
    let t0 = Instant::now();
    loop {
        // SAFETY: waitid(2) writes into the zeroed siginfo we own.
        let done = unsafe {
            let mut info: libc::siginfo_t = std::mem::zeroed();
            let r = libc::waitid(
                libc::P_PID,
                pid as libc::id_t,
                &mut info,
                libc::WEXITED | libc::WNOHANG | libc::WNOWAIT,
            );
            r != 0 || info.si_pid() != 0
        };
        if done {
            return true;
        }
        if t0.elapsed() >= timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Keeps the last [`TAIL_LINES`] lines of `r` (each cut to [`TAIL_LINE_BYTES`]).
fn keep_tail(mut r: impl Read, tail: &Mutex<VecDeque<String>>) {
    let mut buf = [0u8; 4096];
    let mut line: Vec<u8> = Vec::new();
    let push = |line: &mut Vec<u8>| {
        let text = String::from_utf8_lossy(line).trim().to_string();
        line.clear();
        if text.is_empty() {
            return;
        }
        let mut t = lock(tail);
        if t.len() == TAIL_LINES {
            t.pop_front();
        }
        t.push_back(text);
    };
    loop {
        let n = match r.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        for &b in &buf[..n] {
            if b == b'\n' || b == b'\r' {
                push(&mut line);
            } else if line.len() < TAIL_LINE_BYTES {
                line.push(b);
            }
        }
    }
    push(&mut line);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn alive(pid: u32) -> bool {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .map(|s| !s.rsplit(')').next().unwrap_or("").trim_start().starts_with('Z'))
            .unwrap_or(false)
    }

    fn sh(script: &str) -> Vec<String> {
        vec!["sh".into(), "-c".into(), script.into()]
    }

    #[test]
    fn stop_ends_a_program_that_ignores_term_and_its_group() {
        // The shell ignores TERM and starts a sleeper in the background (same group).
        let (p, mut out) = Producer::spawn(&sh("trap '' TERM; sleep 30 & echo $!; wait")).unwrap();
        let mut line = String::new();
        let mut b = [0u8; 1];
        while out.read(&mut b).unwrap() == 1 && b[0] != b'\n' {
            line.push(b[0] as char);
        }
        let sleeper: u32 = line.trim().parse().unwrap();
        assert!(alive(p.pid()) && alive(sleeper));
        let t0 = Instant::now();
        let st = p.stop();
        println!("stopped in {:?}: {st:?}", t0.elapsed());
        assert!(t0.elapsed() < Duration::from_secs(2));
        assert!(!alive(p.pid()), "the leader is gone");
        // the sleeper was in the group: killed too (reaped by init, or a zombie at worst)
        std::thread::sleep(Duration::from_millis(50));
        assert!(!alive(sleeper), "the group member is gone");
        assert!(!lock(groups()).contains(&(p.pid() as i32)));
    }

    #[test]
    fn a_stopped_program_is_ended_too() {
        let (p, _out) = Producer::spawn(&sh("exec sleep 30")).unwrap();
        unsafe { libc::kill(p.pid() as i32, libc::SIGSTOP) };
        let st = p.stop().expect("reaped");
        assert!(!alive(p.pid()));
        println!("{st}");
    }

    #[test]
    fn a_missing_program_is_named_and_stderr_is_kept() {
        let e = Producer::spawn(&["no-such-camera-program-here".to_string()])
            .err()
            .unwrap();
        assert!(e.contains("no-such-camera-program-here"), "{e}");
        let (p, _out) = Producer::spawn(&sh("echo 'ERROR: no cameras available' >&2; exit 3")).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        let line = p.ended_line(Duration::from_secs(1));
        assert!(
            line.contains("exit status: 3") && line.contains("no cameras available"),
            "{line}"
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_parent_death_signal_is_set() {
        // /proc shows no PDEATHSIG; a child that reports its own setting does.
        let (p, mut out) = Producer::spawn(&[
            "python3".into(),
            "-c".into(),
            "import ctypes,sys; l=ctypes.CDLL(None); v=ctypes.c_int(); l.prctl(2, ctypes.byref(v)); print(v.value)"
                .into(),
        ])
        .unwrap();
        let mut s = String::new();
        out.read_to_string(&mut s).unwrap();
        p.stop();
        assert_eq!(s.trim(), libc::SIGKILL.to_string(), "PR_GET_PDEATHSIG in the child");
    }
}
