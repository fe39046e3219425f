//! Ctrl-C (SIGINT) and SIGTERM for every long command: the first one raises the run's
//! [`StopSignal`], so the loop ends at the next frame boundary — neutral first, then telemetry,
//! summary and plots for what ran. A second one means "now": the emergency hooks run (neutral
//! straight to the link from this thread, even if the main thread is stuck) and the process
//! exits with 130 (SIGINT) or 143 (SIGTERM).
//!
//! The handler only stores to atomics (async-signal-safe); a small watcher thread does the
//! rest. A panic in any thread also raises the stop signal (as a fault). SIGUSR1 is the
//! start/stop button at the desk (`kill -USR1 <pid>`): `rccar drive` arms or disarms on it.

use rccar::drive::{StopReason, StopSignal};
use std::sync::atomic::{AtomicU32, AtomicU8, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

static COUNT: AtomicU32 = AtomicU32::new(0);
/// SIGUSR1 presses (the start/stop button at the desk: `kill -USR1 PID`).
static BUTTON: AtomicU32 = AtomicU32::new(0);

extern "C" fn on_usr1(_: libc::c_int) {
    BUTTON.fetch_add(1, Ordering::SeqCst);
}

/// Makes SIGUSR1 the desk's start/stop button (`rccar drive` only: other commands keep the
/// default action).
pub fn install_button() {
    // SAFETY: the handler only touches an atomic.
    unsafe {
        libc::signal(libc::SIGUSR1, on_usr1 as *const () as libc::sighandler_t);
    }
}

/// How many times SIGUSR1 (the desk's start/stop button) arrived so far.
pub fn button_presses() -> u32 {
    BUTTON.load(Ordering::SeqCst)
}
static LAST: AtomicU8 = AtomicU8::new(0);

type Hook = Box<dyn Fn() + Send + Sync>;
fn hooks() -> &'static Mutex<Vec<Hook>> {
    static H: OnceLock<Mutex<Vec<Hook>>> = OnceLock::new();
    H.get_or_init(|| Mutex::new(Vec::new()))
}

extern "C" fn on_signal(sig: libc::c_int) {
    LAST.store(if sig == libc::SIGTERM { 2 } else { 1 }, Ordering::SeqCst);
    COUNT.fetch_add(1, Ordering::SeqCst);
}

/// Installs the handlers (once per process) and returns the stop signal they raise.
pub fn install() -> StopSignal {
    static STOP: OnceLock<StopSignal> = OnceLock::new();
    STOP.get_or_init(|| {
        let stop = StopSignal::new();
        let s = stop.clone();
        let watcher = std::thread::Builder::new().name("rccar-signals".into()).spawn(move || {
            let mut seen = 0;
            loop {
                std::thread::sleep(Duration::from_millis(10));
                let n = COUNT.load(Ordering::SeqCst);
                if n == seen {
                    continue;
                }
                seen = n;
                let why = if LAST.load(Ordering::SeqCst) == 2 {
                    StopReason::Terminate
                } else {
                    StopReason::Interrupt
                };
                s.request(why);
                if n >= 2 {
                    eprintln!("second {}: stopping now", if why == StopReason::Terminate { "SIGTERM" } else { "Ctrl-C" });
                    emergency();
                    std::process::exit(why.exit_code().into());
                }
                eprintln!(
                    "{}: stopping at the next frame (again to stop at once)",
                    if why == StopReason::Terminate { "SIGTERM" } else { "Ctrl-C" }
                );
            }
        });
        // The handlers only count; the watcher acts. Catch the signals only once the watcher
        // runs: a process that cannot start a thread keeps the default actions, so Ctrl-C and
        // SIGTERM still end it instead of being counted by nobody.
        match watcher {
            // SAFETY: the handler only touches atomics, which is async-signal-safe.
            Ok(_) => unsafe {
                libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
                libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
            },
            Err(e) => eprintln!("warning: no signal thread ({e}): Ctrl-C and SIGTERM end the process at once"),
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

#[cfg_attr(not(feature = "serial"), allow(dead_code))]
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
