//! Per-stage timing and the run's clock, without reading the clock in the library.
//!
//! The library only calls [`StageTimer::lap_us`] between stages; the binary passes a timer
//! built on `std::time::Instant`, tests pass [`NoTimer`] so their output is deterministic.

use serde::{Deserialize, Serialize};

/// Something that measures the time since it was last asked, in microseconds.
pub trait StageTimer: Send {
    /// Microseconds since the previous lap (or since creation).
    fn lap_us(&mut self) -> u32;

    /// A second timer of the same kind, started now, for a stage that runs beside the ones
    /// this timer laps (the pipeline's detector runs beside its lane stage).
    fn beside(&self) -> Box<dyn StageTimer>;
}

/// A timer that always answers 0 (deterministic tests, golden files).
#[derive(Debug, Default, Clone, Copy)]
pub struct NoTimer;

impl StageTimer for NoTimer {
    fn lap_us(&mut self) -> u32 {
        0
    }

    fn beside(&self) -> Box<dyn StageTimer> {
        Box::new(NoTimer)
    }
}

/// Microseconds spent in each stage of one frame.
#[derive(Debug, Default, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// ROI + bird's-eye warp + grey.
    pub warp_us: u32,
    /// Blur + Canny.
    pub canny_us: u32,
    /// Threshold ∪ edges.
    pub threshold_us: u32,
    /// Column histogram.
    pub histogram_us: u32,
    /// Peaks, centre, error.
    pub lines_us: u32,
    /// PID + throttle.
    pub control_us: u32,
    /// Sum of the above.
    pub total_us: u32,
}

impl StageTimes {
    /// Fills `total_us` with the sum of the stages.
    pub fn sum(&mut self) {
        self.total_us =
            self.warp_us + self.canny_us + self.threshold_us + self.histogram_us + self.lines_us + self.control_us;
    }
}

/// A clock the caller hands in (the library reads none). Only used for *reporting* latency and
/// loop period; decisions use the frames' own timestamps, so replay and the simulator stay
/// deterministic.
pub trait Clock {
    /// Seconds since some fixed start.
    fn now_s(&self) -> f64;
    /// `false` for a clock that measures nothing ([`NoClock`]): latency and period are then
    /// left out of the telemetry, so it stays reproducible.
    fn is_real(&self) -> bool {
        true
    }
    /// Waits `s` seconds on this clock (pacing a source on the wall clock). The default waits
    /// not at all: a clock that measures nothing has nothing to wait for.
    fn sleep_s(&self, _s: f64) {}
}

/// A clock that always reads 0: latency and period are then reported as 0 (tests, golden
/// files).
#[derive(Debug, Default, Clone, Copy)]
pub struct NoClock;

impl Clock for NoClock {
    fn now_s(&self) -> f64 {
        0.0
    }
    fn is_real(&self) -> bool {
        false
    }
}
