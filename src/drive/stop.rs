//! The one stop signal shared by everything that can end a run: Ctrl-C (SIGINT), SIGTERM,
//! SIGHUP, SIGQUIT, a panic in any thread, a fault (a camera or link lost for good), the
//! deadline.
//!
//! It is a cloneable handle on one atomic: raising it from a signal handler or another thread
//! is safe, and the loop checks it once per frame (see [`super::Driver::step`]). The first
//! reason raised is kept.

use serde::Serialize;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;

/// Why a stop was requested.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// SIGINT (Ctrl-C): exit code 130.
    Interrupt,
    /// SIGTERM: exit code 143.
    Terminate,
    /// SIGHUP (the terminal or SSH session went away): exit code 129.
    Hangup,
    /// SIGQUIT (Ctrl-\\): exit code 131.
    Quit,
    /// A fault: a panic in a thread, the link lost for good, the camera gone for good.
    Fault,
    /// The deadline, a dashboard, or the program itself asked.
    Requested,
}

impl StopReason {
    fn code(self) -> u8 {
        match self {
            StopReason::Interrupt => 1,
            StopReason::Terminate => 2,
            StopReason::Fault => 3,
            StopReason::Requested => 4,
            StopReason::Hangup => 5,
            StopReason::Quit => 6,
        }
    }
    fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            1 => StopReason::Interrupt,
            2 => StopReason::Terminate,
            3 => StopReason::Fault,
            4 => StopReason::Requested,
            5 => StopReason::Hangup,
            6 => StopReason::Quit,
            _ => return None,
        })
    }
    /// How the reason is said on the terminal (`SIGTERM`, `Ctrl-C`, ...).
    pub fn said(self) -> &'static str {
        match self {
            StopReason::Terminate => "SIGTERM",
            StopReason::Hangup => "SIGHUP",
            StopReason::Quit => "SIGQUIT",
            StopReason::Interrupt => "Ctrl-C",
            StopReason::Fault => "a fault",
            StopReason::Requested => "requested",
        }
    }
    /// The conventional exit code of a run ended this way (128 + signal number for signals).
    pub fn exit_code(self) -> u8 {
        match self {
            StopReason::Interrupt => 130,
            StopReason::Terminate => 143,
            StopReason::Fault => 3,
            StopReason::Requested => 0,
            StopReason::Hangup => 129,
            StopReason::Quit => 131,
        }
    }
}

/// A shared stop flag. Cheap to clone; all clones see the same flag.
#[derive(Debug, Clone, Default)]
pub struct StopSignal(Arc<AtomicU8>);

impl StopSignal {
    /// A signal nobody has raised.
    pub fn new() -> Self {
        Self::default()
    }

    /// Raises the signal (the first reason wins). One atomic operation: safe from any thread.
    pub fn request(&self, why: StopReason) {
        let _ = self.0.compare_exchange(0, why.code(), Ordering::SeqCst, Ordering::SeqCst);
    }

    /// The reason, once raised.
    pub fn reason(&self) -> Option<StopReason> {
        StopReason::from_code(self.0.load(Ordering::SeqCst))
    }

    /// Whether a stop was requested.
    pub fn is_set(&self) -> bool {
        self.reason().is_some()
    }

    /// Lowers the signal again (a car that was stopped by its button and is armed again).
    pub fn clear(&self) {
        self.0.store(0, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_reason_wins_and_clones_share() {
        let s = StopSignal::new();
        let c = s.clone();
        assert!(!s.is_set());
        c.request(StopReason::Terminate);
        s.request(StopReason::Interrupt);
        assert_eq!(s.reason(), Some(StopReason::Terminate));
        assert_eq!(s.reason().unwrap().exit_code(), 143);
        s.clear();
        assert!(!c.is_set());
    }
}
