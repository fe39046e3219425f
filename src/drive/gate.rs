//! Arming and the emergency stop, shared between whoever may arm the car (the `--arm` flag,
//! the start button, a dashboard) and the sink that would move it.
//!
//! [`ArmState`] is a few atomics behind an `Arc`: any thread may arm, disarm or press the
//! emergency stop without waiting for the loop. [`Gate`] wraps the loop's sink and lets a
//! command through only while armed and not e-stopped; otherwise it sends neutral. The
//! emergency stop latches until it is released on purpose.

use crate::control::Command;
use crate::sink::{CommandSink, SinkError};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// Who wants the car armed, and whether the emergency stop is pressed.
#[derive(Debug, Default)]
pub struct ArmState {
    armed: AtomicBool,
    estop: AtomicBool,
    /// Bumped on every change, so a watcher can tell something happened.
    version: AtomicU64,
}

impl ArmState {
    /// Disarmed, e-stop released.
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }
    /// Arms (ignored while the e-stop is pressed). Returns whether the car is now armed.
    pub fn arm(&self) -> bool {
        if self.estop.load(Ordering::SeqCst) {
            return false;
        }
        self.armed.store(true, Ordering::SeqCst);
        self.version.fetch_add(1, Ordering::SeqCst);
        true
    }
    /// Disarms.
    pub fn disarm(&self) {
        self.armed.store(false, Ordering::SeqCst);
        self.version.fetch_add(1, Ordering::SeqCst);
    }
    /// Presses the emergency stop: disarmed, and arming refused until [`ArmState::release`].
    pub fn estop(&self) {
        self.estop.store(true, Ordering::SeqCst);
        self.armed.store(false, Ordering::SeqCst);
        self.version.fetch_add(1, Ordering::SeqCst);
    }
    /// Releases the emergency stop (the car stays disarmed).
    pub fn release(&self) {
        self.estop.store(false, Ordering::SeqCst);
        self.version.fetch_add(1, Ordering::SeqCst);
    }
    /// Whether commands may move the car.
    pub fn is_armed(&self) -> bool {
        self.armed.load(Ordering::SeqCst) && !self.estop.load(Ordering::SeqCst)
    }
    /// Whether the emergency stop is pressed.
    pub fn is_estopped(&self) -> bool {
        self.estop.load(Ordering::SeqCst)
    }
    /// Changes so far.
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::SeqCst)
    }
}

/// A sink that moves the car only while `state` is armed; neutral otherwise.
pub struct Gate<S: CommandSink> {
    inner: S,
    state: Arc<ArmState>,
}

impl<S: CommandSink> Gate<S> {
    /// Gates `inner` by `state`.
    pub fn new(inner: S, state: Arc<ArmState>) -> Self {
        Self { inner, state }
    }
    /// The wrapped sink.
    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }
}

impl<S: CommandSink> CommandSink for Gate<S> {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<(), SinkError> {
        let c = if self.state.is_armed() { cmd } else { Command::NEUTRAL };
        self.inner.send(c, now_s)
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        self.inner.stop()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sink::RecordingSink;

    #[test]
    fn only_armed_commands_pass_and_estop_latches() {
        let st = ArmState::new();
        let mut g = Gate::new(RecordingSink::default(), st.clone());
        let go = Command {
            steer: 0.1,
            throttle: 0.4,
        };
        g.send(go, 0.0).unwrap();
        assert!(st.arm());
        g.send(go, 0.1).unwrap();
        st.estop();
        assert!(!st.arm(), "arming refused while e-stopped");
        g.send(go, 0.2).unwrap();
        st.release();
        g.send(go, 0.3).unwrap();
        assert!(st.arm());
        g.send(go, 0.4).unwrap();
        let got: Vec<Command> = g.inner.log.iter().map(|e| e.1).collect();
        assert_eq!(got, vec![Command::NEUTRAL, go, Command::NEUTRAL, Command::NEUTRAL, go]);
    }
}
