//! The session's own small parts of the loop: the camera's health, the car's status in each
//! record, the status line on the car's terminal, and real-time pacing of a watched
//! simulation.

use crate::drive::{Arming, Clock, Flow, FrameContext, Level, LoopError, LoopStats, Observer, Say, StopReason, StopSignal};
use crate::health::{CarStatus, Part, PartState};
use crate::pipeline::Pipeline;
use crate::source::FrameError;
use crate::telemetry::FrameRecord;
use std::sync::Arc;

/// The frame source's health: waiting until the first frame, lost while stalled, ok when
/// frames come.
pub struct CameraHealth(pub Arc<Arming>);

impl Observer for CameraHealth {
    /// A frame arrived: the camera is up (before anyone reads the status of this frame).
    fn decorate(&mut self, _r: &mut FrameRecord) {
        self.0.health().set(Part::Camera, PartState::Ok, "");
    }
    fn on_stall(&mut self, e: &FrameError) {
        self.0.health().set(Part::Camera, PartState::Lost, &e.to_string());
    }
}

/// Puts the car's status (waiting, disarmed, driving, fault…) into every record of a car run.
pub struct CarState(pub Arc<Arming>);

impl CarState {
    /// The status now.
    pub fn status(arming: &Arming) -> CarStatus {
        let h = arming.health();
        CarStatus::of(
            &h.snapshot(),
            h.interlock().is_some(),
            arming.is_armed(),
            arming.is_estopped(),
            arming.is_braking(),
        )
    }
}

impl Observer for CarState {
    fn decorate(&mut self, r: &mut FrameRecord) {
        r.car = Some(Self::status(&self.0));
    }
}

/// One status line every few seconds on the clock, every event as it happens, and the end of
/// the run at the deadline (`--seconds`).
pub struct StatusLine {
    pub(crate) every_s: f64,
    pub(crate) last_print: f64,
    pub(crate) clock: Arc<dyn Clock + Send + Sync>,
    pub(crate) window: LoopStats,
    pub(crate) deadline: Option<f64>,
    pub(crate) started: f64,
    pub(crate) stop: StopSignal,
    pub(crate) arming: Arc<Arming>,
    pub(crate) say: Say,
    /// Whether records carry the car's status (a car run) for the line.
    pub(crate) car: bool,
}

impl StatusLine {
    fn t(&self) -> f64 {
        self.clock.now_s() - self.started
    }
}

impl Observer for StatusLine {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let r = ctx.record;
        let t = self.t();
        for e in &r.events {
            let warn = e.starts_with("fault") || e.starts_with("link lost") || e.contains("refused");
            (self.say)(if warn { Level::Warn } else { Level::Info }, &format!("t={t:6.1} s  {e}"));
        }
        self.window.frames += 1;
        if let Some(l) = r.latency_ms {
            self.window.latency_ms.push(l);
        }
        self.window.dropped = r.dropped.unwrap_or(0);
        if t - self.last_print >= self.every_s {
            let fps = self.window.frames as f64 / (t - self.last_print).max(1e-6);
            let lat = LoopStats::median_max(&self.window.latency_ms);
            let car = if self.car { CarState::status(&self.arming).name() } else { "" };
            let sent = r.sent.map_or(String::new(), |s| format!(" (sent {:+.2}/{:+.2})", s.steer, s.throttle));
            (self.say)(
                Level::Info,
                &format!(
                    "t={:6.1} s  {:5.1} fps  dropped {}  latency {}  {}  {}  error {}  steer {:+.2}  throttle {:+.2}{}",
                    t,
                    fps,
                    self.window.dropped,
                    lat.map_or("-".into(), |(m, x)| format!("{m:.1}/{x:.1} ms")),
                    car,
                    r.behaviour.map_or("-".into(), |m| m.name().to_string()),
                    r.error.map_or("-".into(), |e| format!("{e:+.3}")),
                    r.steer,
                    r.throttle,
                    sent
                ),
            );
            self.window = LoopStats::default();
            self.last_print = t;
        }
        if self.deadline.is_some_and(|d| t >= d) {
            self.stop.request(StopReason::Requested);
        }
        Ok(Flow::Continue)
    }

    fn on_stall(&mut self, e: &FrameError) {
        (self.say)(Level::Info, &format!("t={:6.1} s  camera stalled: {e}; neutral sent, waiting for frames", self.t()));
        if self.deadline.is_some_and(|d| self.t() >= d) {
            self.stop.request(StopReason::Requested);
        }
    }

    fn on_skip(&mut self, e: &FrameError) {
        (self.say)(Level::Warn, &format!("t={:6.1} s  skipped {e}", self.t()));
        // A camera that delivers only unusable frames still ends at the deadline.
        if self.deadline.is_some_and(|d| self.t() >= d) {
            self.stop.request(StopReason::Requested);
        }
    }
}

/// Holds a lock-step run back to real time between frames (a simulation watched on a
/// dashboard); after a pause the schedule restarts from now (no catching up).
pub struct Pacer {
    pub(crate) clock: Arc<dyn Clock + Send + Sync>,
    pub(crate) period_s: f64,
    pub(crate) next: Option<f64>,
}

impl Observer for Pacer {
    fn before_frame(&mut self, _p: &mut Pipeline) -> Flow {
        let now = self.clock.now_s();
        if let Some(t) = self.next {
            if t > now {
                self.clock.sleep_s(t - now);
            }
        }
        let base = self.next.map_or(now, |t| t.max(now));
        self.next = Some(base + self.period_s);
        Flow::Continue
    }
}
