//! The signals that can end a long command — SIGINT (Ctrl-C), SIGTERM (systemd, `kill`),
//! SIGHUP (the SSH session a student started the car from closed) and SIGQUIT (Ctrl-\) — all
//! do the same: the first one raises the run's [`StopSignal`], so the loop ends at the next
//! frame boundary with neutral sent first, then telemetry, summary and plots for what ran. A
//! second one means "now": the emergency hooks run (neutral straight to the link from this
//! thread, even if the main thread is stuck) and the process exits with 128 + the signal.
//!
//! SIGUSR1 is the start/stop button at the desk (`kill -USR1 <pid>`): `rccar drive` arms or
//! disarms on it through the car's one arming state ([`on_button`]).
//!
//! The signals are received by `signal-hook`'s iterator on a thread of its own (no hand-written
//! handler); a panic in any thread also raises the stop signal (as a fault). After SIGHUP the
//! terminal is gone: everything the commands print goes through [`say`], which never panics on
//! a closed stdout or stderr.
//!
//! SIGPIPE (the reader of a pipe went away, `rccar sim | head -1`): Rust ignores it, so the
//! next `println!` would panic. Commands that move nothing and serve no socket let it end the
//! process, as it ends any Unix filter ([`let_sigpipe_end_the_process`]); `drive`, `link` and
//! `sim --dashboard` keep ignoring it (a reader or a viewer that goes away must never end a run
//! before neutral is sent, and a write to a socket can raise it too) and print through [`say`].

use rccar::drive::{Level, Say, StopReason, StopSignal};
use rccar::session::Session;
use signal_hook::consts::{SIGHUP, SIGINT, SIGQUIT, SIGTERM, SIGUSR1};
use std::io::Write;
use std::sync::{Mutex, OnceLock};

type Hook = Box<dyn Fn() + Send + Sync>;

fn hooks() -> &'static Mutex<Vec<Hook>> {
    static H: OnceLock<Mutex<Vec<Hook>>> = OnceLock::new();
    H.get_or_init(|| Mutex::new(Vec::new()))
}

fn button() -> &'static Mutex<Option<Hook>> {
    static B: OnceLock<Mutex<Option<Hook>>> = OnceLock::new();
    B.get_or_init(|| Mutex::new(None))
}

/// The stop reason of a terminating signal.
fn reason(sig: i32) -> StopReason {
    match sig {
        SIGTERM => StopReason::Terminate,
        SIGHUP => StopReason::Hangup,
        SIGQUIT => StopReason::Quit,
        _ => StopReason::Interrupt,
    }
}

/// Installs the handling (once per process) and returns the stop signal it raises.
pub fn install() -> StopSignal {
    static STOP: OnceLock<StopSignal> = OnceLock::new();
    STOP.get_or_init(|| {
        let stop = StopSignal::new();
        match signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1]) {
            Ok(mut signals) => {
                let s = stop.clone();
                let spawned = std::thread::Builder::new()
                    .name("rccar-signals".into())
                    .spawn(move || watch(&mut signals, &s));
                if let Err(e) = spawned {
                    say_err(&format!("warning: no signal thread ({e}): signals end the process at once"));
                }
            }
            Err(e) => say_err(&format!("warning: cannot catch signals ({e}): they end the process at once")),
        }
        // A panic anywhere stops the run (the main thread's unwinding sends neutral too).
        let p = stop.clone();
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            p.request(StopReason::Fault);
            prev(info);
        }));
        stop
    })
    .clone()
}

fn watch(signals: &mut signal_hook::iterator::Signals, stop: &StopSignal) {
    let mut count = 0;
    for sig in signals.forever() {
        if sig == SIGUSR1 {
            if let Some(b) = button().lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
                b();
            }
            continue;
        }
        count += 1;
        let why = reason(sig);
        let name = why.said();
        stop.request(why);
        if count >= 2 {
            say_err(&format!("second {name}: stopping now"));
            emergency();
            std::process::exit(why.exit_code().into());
        }
        say_err(&format!("{name}: stopping at the next frame (again to stop at once)"));
    }
}

/// What SIGUSR1 (the desk's start/stop button) does from now on.
pub fn on_button(f: impl Fn() + Send + Sync + 'static) {
    *button().lock().unwrap_or_else(|e| e.into_inner()) = Some(Box::new(f));
}

/// Registers something that brings the car to rest from any thread (e.g. neutral through the
/// link). Run on the second signal, before the process exits.
pub fn on_emergency(f: impl Fn() + Send + Sync + 'static) {
    hooks().lock().unwrap_or_else(|e| e.into_inner()).push(Box::new(f));
}

/// Runs the emergency hooks (also used when the main thread gives up).
pub fn emergency() {
    for h in hooks().lock().unwrap_or_else(|e| e.into_inner()).iter() {
        h();
    }
}

/// The library's way to print ([`Say`]): information through [`say`], warnings through
/// [`say_err`].
pub fn sayer() -> Say {
    std::sync::Arc::new(|level, line: &str| match level {
        Level::Info => say(line),
        Level::Warn => say_err(line),
    })
}

/// The session's notes: information as `command: line` on stdout, warnings as they are on
/// stderr.
pub fn notes(command: &str, session: &Session) {
    for (level, line) in session.notes() {
        match level {
            Level::Info => say(&format!("{command}: {line}")),
            Level::Warn => say_err(line),
        }
    }
}

/// Lets SIGPIPE end the process without a word (the shell sees 128 + 13), as for any Unix
/// filter: for the commands that move nothing and serve no socket (see the module notes).
pub fn let_sigpipe_end_the_process() {
    // SAFETY: sets one signal's disposition back to the default, before any thread is started.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// One line on stdout; a closed terminal (after SIGHUP) is not an error.
pub fn say(line: &str) {
    let mut o = std::io::stdout().lock();
    let _ = writeln!(o, "{line}");
    let _ = o.flush();
}

/// One line on stderr; a closed terminal is not an error.
pub fn say_err(line: &str) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}
