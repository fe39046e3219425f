//! The wall clock and stage timer the binary hands to the library (which reads no clock
//! itself), and the session environment made of them ([`session_env`]).

use rccar::drive::{Clock, NoClock, StopSignal};
use rccar::session::SessionEnv;
use rccar::timing::{NoTimer, StageTimer};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A session's environment: the wall clock and stage timer (none with `no_timing`: zeros,
/// reproducible telemetry), the run's `stop` signal, and the terminal for the library's lines
/// ([`super::signals::sayer`]).
pub fn session_env(no_timing: bool, stop: StopSignal) -> SessionEnv {
    let (clock, timer): (Arc<dyn Clock + Send + Sync>, Box<dyn StageTimer + Send>) = if no_timing {
        (Arc::new(NoClock), Box::new(NoTimer))
    } else {
        (Arc::new(WallClock::new()), Box::new(WallTimer::new()))
    };
    SessionEnv { clock, stop, timer, say: super::signals::sayer() }
}

/// Laps measured with `Instant`.
pub struct WallTimer(Instant);

impl WallTimer {
    /// Starts now.
    pub fn new() -> Self {
        Self(Instant::now())
    }
}

impl StageTimer for WallTimer {
    fn lap_us(&mut self) -> u32 {
        let now = Instant::now();
        let us = now.duration_since(self.0).as_micros().min(u32::MAX as u128) as u32;
        self.0 = now;
        us
    }

    fn beside(&self) -> Box<dyn StageTimer> {
        Box::new(WallTimer::new())
    }
}

/// The wall clock the binary hands to the loop (latency, loop period, pacing); seconds since
/// creation.
pub struct WallClock(Instant);

impl WallClock {
    /// Starts now.
    pub fn new() -> Self {
        Self(Instant::now())
    }
}

impl rccar::drive::Clock for WallClock {
    fn now_s(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
    fn sleep_s(&self, s: f64) {
        if s.is_finite() && s > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(s.min(3600.0)));
        }
    }
}
