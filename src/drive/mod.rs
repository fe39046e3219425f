//! The one loop: the car, replay and the simulator all run [`Driver`].
//!
//! ```text
//!   &mut dyn FrameSource  ──frame──►  Pipeline  ──Command──►  &mut dyn CommandSink
//!   (camera | folder | simulator camera)          (serial link | simulator vehicle | nothing)
//!                     │                                   │
//!                     └──────► one FrameRecord ◄──────────┘  ──►  &mut dyn Observer
//!                                                                 (telemetry file, scoring,
//!                                                                  recording, dashboard)
//! ```
//!
//! One turn of the loop (the donkeycar vehicle loop, with one part of each kind):
//! 1. stop requested (Ctrl-C, SIGTERM, a fault, the button)? → end;
//! 2. the observer may change the pipeline between frames (gains from a dashboard);
//! 3. `source.next_frame()`: a frame; an unusable frame is skipped and counted; a *stalled*
//!    source (no frame for the stall time) gets neutral sent at once and the loop waits on;
//! 4. `dt` = this frame's time − the previous frame's (the loop owns dt: frames the source
//!    dropped or could not read still count as time passed);
//! 5. `Pipeline::step` → command → chosen by the driving mode ([`manual`]: the pipeline's, the
//!    human's, or the pipeline's steering with the human's throttle) → `sink.send` (the gate);
//! 6. the one telemetry record of the frame, with the capture→command latency and the loop
//!    period measured on the [`Clock`] the caller passes in (the library reads no clock);
//! 7. the observer sees the frame, the record and the pipeline; it may end the run.
//!
//! The sink is wrapped in [`NeutralOnDrop`] for the whole run: every way out of [`Driver::run`]
//! — the end of the source, a stop request, an error, a panic unwinding — sends neutral before
//! the caller gets control back, so files are flushed *after* the motor is safe.

pub mod actor;
pub mod arming;
pub mod manual;

pub mod slot;
pub mod stereo;
pub mod stop;

pub use crate::sink::{Actuators, Connection};
pub use arming::{Actor, Arming, Gate, GateOptions, Refused, Sent};
pub use manual::{Controls, DriveMode, NoRecorder, Pilot, RecordSwitch};
pub use crate::health::{CarStatus, Fault, Health, HealthSnapshot, Part, PartState};
pub use slot::Latest;
pub use stop::{StopReason, StopSignal};

use crate::control::Command;
use crate::pipeline::{FrameOutput, Pipeline};
use crate::sink::{CommandSink, NeutralOnDrop, SinkError};
use crate::source::{Frame, FrameError, FrameSource};
use crate::telemetry::FrameRecord;
pub use crate::timing::{Clock, NoClock};
use crate::timing::StageTimer;
use serde::Serialize;

/// How a line a run reports should be shown (status lines, events, warnings).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Information (stdout).
    Info,
    /// A warning or fault (stderr).
    Warn,
}

/// Where a run's lines go (status lines, events, warnings): the binary prints them.
pub type Say = std::sync::Arc<dyn Fn(Level, &str) + Send + Sync>;

/// What the observer wants after a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Continue,
    /// End the run (the simulator: laps done; a test: enough frames).
    Stop,
}

/// Why the loop failed (the sink or an observer reported an error).
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// The command sink failed.
    #[error("command sink: {0}")]
    Sink(SinkError),
    /// An observer (telemetry writer, recorder…) failed; the message names the file.
    #[error("{0}")]
    Observer(String),
}

// By hand, not `#[from]`: a `source` would print the sink's message a second time.
impl From<SinkError> for LoopError {
    fn from(e: SinkError) -> Self {
        LoopError::Sink(e)
    }
}

/// Everything about one processed frame, handed to the observer.
pub struct FrameContext<'a> {
    /// The frame as the source delivered it.
    pub frame: &'a Frame,
    /// What the pipeline made of it.
    pub output: &'a FrameOutput,
    /// The telemetry record (already complete).
    pub record: &'a FrameRecord,
    /// The pipeline after the frame (lane images for annotation, behaviour, objects).
    pub pipeline: &'a Pipeline,
}

/// Watches the loop: writes telemetry, scores a simulation, records frames, feeds a
/// dashboard. Every method has a do-nothing default.
pub trait Observer {
    /// Before each frame is read: the one place where the pipeline may be changed during a run
    /// (a dashboard's new gains act on the next frame).
    fn before_frame(&mut self, _pipeline: &mut Pipeline) -> Flow {
        Flow::Continue
    }
    /// Adds what this observer knows to the frame's record before anyone sees it (a sensor
    /// reading, an operator's change): the record stays the one record of the frame.
    fn decorate(&mut self, _record: &mut FrameRecord) {}
    /// A processed frame.
    fn on_frame(&mut self, _ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        Ok(Flow::Continue)
    }
    /// A frame that could not be used (skipped and counted).
    fn on_skip(&mut self, _err: &FrameError) {}
    /// The source stalled (no frame within its stall time); neutral was just sent.
    fn on_stall(&mut self, _err: &FrameError) {}
}

/// The telemetry file: one line per processed frame (here, not in `telemetry`, so that the
/// record's module does not depend on the loop).
impl<W: std::io::Write> Observer for crate::telemetry::JsonlWriter<W> {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.write(ctx.record)
            .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", self.label())))?;
        Ok(Flow::Continue)
    }
}

/// Observer for an optional part: nothing when absent.
impl<T: Observer> Observer for Option<T> {
    fn before_frame(&mut self, p: &mut Pipeline) -> Flow {
        self.as_mut().map_or(Flow::Continue, |o| o.before_frame(p))
    }
    fn decorate(&mut self, r: &mut FrameRecord) {
        if let Some(o) = self.as_mut() {
            o.decorate(r)
        }
    }
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.as_mut().map_or(Ok(Flow::Continue), |o| o.on_frame(ctx))
    }
    fn on_skip(&mut self, e: &FrameError) {
        if let Some(o) = self.as_mut() {
            o.on_skip(e)
        }
    }
    fn on_stall(&mut self, e: &FrameError) {
        if let Some(o) = self.as_mut() {
            o.on_stall(e)
        }
    }
}

/// An observer that does nothing.
#[derive(Debug, Default)]
pub struct NoObserver;
impl Observer for NoObserver {}

/// Several observers, called in order (the first `Stop` wins, all still see the frame).
impl<const N: usize> Observer for [&mut dyn Observer; N] {
    fn before_frame(&mut self, pipeline: &mut Pipeline) -> Flow {
        self.as_mut_slice().before_frame(pipeline)
    }
    fn decorate(&mut self, record: &mut FrameRecord) {
        self.as_mut_slice().decorate(record)
    }
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.as_mut_slice().on_frame(ctx)
    }
    fn on_skip(&mut self, err: &FrameError) {
        self.as_mut_slice().on_skip(err)
    }
    fn on_stall(&mut self, err: &FrameError) {
        self.as_mut_slice().on_stall(err)
    }
}

/// Any number of observers, called in order (the first `Stop` wins, all still see the frame).
impl Observer for [&mut dyn Observer] {
    fn before_frame(&mut self, pipeline: &mut Pipeline) -> Flow {
        let mut f = Flow::Continue;
        for o in self.iter_mut() {
            if o.before_frame(pipeline) == Flow::Stop {
                f = Flow::Stop;
            }
        }
        f
    }
    fn decorate(&mut self, record: &mut FrameRecord) {
        for o in self.iter_mut() {
            o.decorate(record);
        }
    }
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let mut f = Flow::Continue;
        for o in self.iter_mut() {
            if o.on_frame(ctx)? == Flow::Stop {
                f = Flow::Stop;
            }
        }
        Ok(f)
    }
    fn on_skip(&mut self, err: &FrameError) {
        for o in self.iter_mut() {
            o.on_skip(err);
        }
    }
    fn on_stall(&mut self, err: &FrameError) {
        for o in self.iter_mut() {
            o.on_stall(err);
        }
    }
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LoopEnd {
    /// The source has no more frames (the end of a folder, the simulator's end).
    SourceEnded,
    /// A stop was requested from outside (signal, button, fault).
    Stopped(StopReason),
    /// An observer ended the run (laps done, frame limit).
    ObserverStopped,
}

/// Loop statistics (also printed as the periodic status line).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LoopStats {
    /// Frames processed.
    pub frames: u64,
    /// Frames the source could not deliver (named by `on_skip`).
    pub skipped: u64,
    /// Frames the source produced but the loop never saw (it always takes the newest).
    pub dropped: u64,
    /// Times the source stalled (neutral sent each time).
    pub stalls: u64,
    /// Capture → command latency per frame, milliseconds (as measured by the clock).
    pub latency_ms: Vec<f64>,
    /// Time between successive frames' commands, milliseconds.
    pub period_ms: Vec<f64>,
}

impl LoopStats {
    /// (median, max) of a series, `None` when empty.
    pub fn median_max(v: &[f64]) -> Option<(f64, f64)> {
        if v.is_empty() {
            return None;
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        Some((s[s.len() / 2], s[s.len() - 1]))
    }

    /// The counters and the latency and period figures in one line (the end of a run).
    pub fn line(&self) -> String {
        let lat = LoopStats::median_max(&self.latency_ms);
        let per = LoopStats::median_max(&self.period_ms);
        format!(
            "{} frames, {} dropped, {} skipped, {} stalls; latency capture->command {}; period {}",
            self.frames,
            self.dropped,
            self.skipped,
            self.stalls,
            lat.map_or("-".into(), |(m, x)| format!("median {m:.1} ms, max {x:.1} ms")),
            per.map_or("-".into(), |(m, x)| format!("median {m:.1} ms, max {x:.1} ms")),
        )
    }
}

/// What one call of [`Driver::step`] did.
#[derive(Debug)]
pub enum Step {
    /// A frame was processed; here is its output and record.
    Frame(Box<(FrameOutput, FrameRecord)>),
    /// A frame could not be used (skipped).
    Skipped,
    /// The source stalled; neutral was sent.
    Stalled,
    /// The run is over.
    End(LoopEnd),
}

/// What one run of the loop connects: where frames come from, what turns them into commands,
/// where the commands go, and who watches. [`Driver::step`] and [`Driver::run`] take these
/// together, so every caller (car, replay, simulator) wires the same seven parts.
pub struct Parts<'a> {
    /// The camera, a folder of frames or the simulator's camera.
    pub source: &'a mut dyn FrameSource,
    /// Lane keeping, detection, ranging, behaviour and control.
    pub pipeline: &'a mut Pipeline,
    /// The serial link, the simulator's vehicle, or nothing.
    pub sink: &'a mut dyn CommandSink,
    /// Ctrl-C, SIGTERM, a fault or the button ends the run at the next turn.
    pub stop: &'a StopSignal,
    /// Only for reporting latency and loop period ([`NoClock`] for reproducible telemetry).
    pub clock: &'a dyn Clock,
    /// Measures the pipeline's stages.
    pub timer: &'a mut dyn StageTimer,
    /// Telemetry, scoring, recording, dashboard (several as `[&mut dyn Observer; N]`).
    pub observer: &'a mut dyn Observer,
    /// The driving mode and the human's input (the arming state's); `None`: the pipeline
    /// always drives.
    pub controls: Option<&'a Controls>,
}

/// The loop's state between frames: the previous frame's time (for dt), counters, and the
/// period measurement. The car, replay, the simulator and the firmware-in-the-loop test all go
/// through [`Driver::step`].
#[derive(Debug)]
pub struct Driver {
    fps: f64,
    last_time_s: Option<f64>,
    next_index: u64,
    last_cmd_clock: Option<f64>,
    stats: LoopStats,
    ended: Option<LoopEnd>,
    resync: bool,
    /// The mode changes already turned into events.
    mode_seen: u64,
    /// The mode version the steering method was last reset at.
    mode_reset: u64,
    /// Record-switch changes already noted as events.
    record_seen: u64,
}

impl Driver {
    /// A driver for a source nominally running at `fps` (used for the first frame's dt).
    pub fn new(fps: f64) -> Self {
        Self {
            fps: if fps.is_finite() && fps > 0.0 { fps } else { 30.0 },
            last_time_s: None,
            next_index: 0,
            last_cmd_clock: None,
            stats: LoopStats::default(),
            ended: None,
            resync: false,
            mode_seen: 0,
            mode_reset: 0,
            record_seen: 0,
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> &LoopStats {
        &self.stats
    }

    /// Why the run ended, once it has.
    pub fn ended(&self) -> Option<LoopEnd> {
        self.ended
    }

    /// One turn of the loop (see the module notes). `parts.sink` should already be wrapped in
    /// [`NeutralOnDrop`] by the caller that owns the run ([`Driver::run`] does it).
    pub fn step(&mut self, parts: &mut Parts<'_>) -> Result<Step, LoopError> {
        let (source, pipeline, sink) = (&mut *parts.source, &mut *parts.pipeline, &mut *parts.sink);
        let (stop, clock, timer, observer) = (parts.stop, parts.clock, &mut *parts.timer, &mut *parts.observer);
        let controls = parts.controls;
        if let Some(e) = self.ended {
            return Ok(Step::End(e));
        }
        // 1. A stop request ends the run before anything else moves.
        if let Some(r) = stop.reason() {
            return Ok(self.end(LoopEnd::Stopped(r)));
        }
        // 2. Between frames: the only time the pipeline may be changed.
        if observer.before_frame(pipeline) == Flow::Stop {
            return Ok(self.end(LoopEnd::ObserverStopped));
        }
        // 3. The next frame.
        let frame = match source.next_frame() {
            None => return Ok(self.end(LoopEnd::SourceEnded)),
            Some(Err(e)) if e.stalled => {
                // A camera that stalls or is unplugged: the car must not drive blind.
                let sent = sink.send(Command::NEUTRAL, self.last_time_s.unwrap_or(0.0))?;
                pipeline.note_sent(sent);
                self.stats.stalls += 1;
                self.last_cmd_clock = None;
                // frames missing after a stall were never made: not dropped
                self.resync = true;
                observer.on_stall(&e);
                return Ok(Step::Stalled);
            }
            Some(Err(e)) => {
                self.stats.skipped += 1;
                self.next_index = self.next_index.max(e.index + 1);
                observer.on_skip(&e);
                return Ok(Step::Skipped);
            }
            Some(Ok(f)) => f,
        };
        let captured = frame.captured_s.unwrap_or_else(|| clock.now_s());
        self.count_index(frame.index);
        // 4. dt from the frames' own times: skipped and dropped frames still count as time.
        let dt = self.last_time_s.map_or(1.0 / self.fps, |t| frame.time_s - t);
        self.last_time_s = Some(frame.time_s);
        // 5. Pipeline → command → sink. A mode change starts the steering method afresh: a PID
        // that kept integrating the lane error while a human steered would kick on handover.
        if let Some(c) = controls {
            let v = c.mode_version();
            if v != self.mode_reset {
                self.mode_reset = v;
                pipeline.controller_mut().steering_mut().reset();
            }
        }
        // A stereo pair (src/drive/stereo.rs) is ranged by stereo; given boxes win.
        let counts_before = pipeline.stereo().map(|s| s.counts);
        let out = match (&frame.other, &frame.given) {
            (Some(o), None) => pipeline.step_stereo(&frame.image, &o.image, dt, timer),
            _ => pipeline.step_with(&frame.image, dt, timer, frame.given.as_deref()),
        };
        // The driving mode picks the command before the gate: disarmed, e-stop, brake and
        // interlocks hold a human back exactly as they hold the pipeline.
        let choice = controls.map(|c| c.choose(out.command));
        let sent_cmd = sink.send(choice.map_or(out.command, |ch| ch.command), frame.time_s)?;
        // Dead reckoning integrates what the motors were told, not what the pipeline wanted.
        pipeline.note_sent(sent_cmd);
        let sent = clock.now_s();
        // 6. The one telemetry record.
        let (latency_ms, period_ms) = self.count_frame(captured, sent);
        let mut record = FrameRecord::new(
            frame.index,
            &frame.name,
            frame.time_s,
            &out.lane,
            &out.command,
            out.stage_us,
        )
        .with_pipeline(&out, pipeline);
        record.truth = frame.truth.clone();
        if let Some(o) = &frame.other {
            let rectified = pipeline.stereo().is_some_and(|s| s.rectified());
            record.stereo = Some(stereo::record(o, counts_before, pipeline.stereo().map(|s| s.counts), rectified));
        }
        if clock.is_real() {
            record.latency_ms = Some(latency_ms);
            record.period_ms = period_ms;
        }
        if self.stats.dropped > 0 {
            record.dropped = Some(self.stats.dropped);
        }
        if sent_cmd != out.command {
            record.sent = Some(sent_cmd);
        }
        if let (Some(c), Some(ch)) = (controls, choice) {
            self.note_mode(c, ch, clock.is_real(), &mut record);
        }
        sink.drain_events(&mut record.events);
        observer.decorate(&mut record);
        // 7. Observers.
        let flow = observer.on_frame(&FrameContext {
            frame: &frame,
            output: &out,
            record: &record,
            pipeline,
        })?;
        if flow == Flow::Stop {
            self.ended = Some(LoopEnd::ObserverStopped);
        }
        Ok(Step::Frame(Box::new((out, record))))
    }

    /// The mode and who drove into the record (once a human input is attached to the run),
    /// and a mode change as an event naming who and when.
    fn note_mode(&mut self, c: &Controls, ch: manual::Choice, real_clock: bool, record: &mut FrameRecord) {
        let v = c.mode_version();
        if v != self.mode_seen {
            self.mode_seen = v;
            let (before, by, at) = c.last_change();
            record.events.push(format!(
                "mode {} (was {}) by {} at wall {at:.3} s",
                ch.mode.name(),
                before.name(),
                by.name()
            ));
        }
        let rs = c.record();
        if rs.version() != self.record_seen {
            self.record_seen = rs.version();
            let (on, by, at) = rs.last_change();
            record.events.push(format!(
                "recording {} by {} at wall {at:.3} s",
                if on { "on" } else { "paused" },
                by.name()
            ));
        }
        if c.reported() {
            record.drive_mode = Some(ch.mode);
            record.pilot = Some(ch.pilot);
            record.human = ch.human;
            if real_clock {
                record.input_age_ms = ch.input_age_ms;
            }
        }
    }

    /// Frames the source numbered but never gave are dropped (not those missing after a
    /// stall: never made).
    fn count_index(&mut self, index: u64) {
        if index > self.next_index && !self.resync {
            self.stats.dropped += index - self.next_index;
        }
        self.resync = false;
        self.next_index = index + 1;
    }

    /// Counts a processed frame with its latency (capture at `captured` → command `sent`,
    /// clock seconds) and the period since the last command; returns both in ms.
    fn count_frame(&mut self, captured: f64, sent: f64) -> (f64, Option<f64>) {
        let latency_ms = (sent - captured) * 1e3;
        let period_ms = self.last_cmd_clock.map(|t| (sent - t) * 1e3);
        self.last_cmd_clock = Some(sent);
        self.stats.frames += 1;
        self.stats.latency_ms.push(latency_ms);
        if let Some(p) = period_ms {
            self.stats.period_ms.push(p);
        }
        (latency_ms, period_ms)
    }

    fn end(&mut self, why: LoopEnd) -> Step {
        self.ended = Some(why);
        Step::End(why)
    }

    /// Runs until the source ends, a stop is requested or an observer ends the run. The sink
    /// gets neutral on every way out (see the module notes).
    pub fn run(&mut self, parts: Parts<'_>) -> Result<LoopEnd, LoopError> {
        let Parts { source, pipeline, sink, stop, clock, timer, observer, controls } = parts;
        let mut guard = NeutralOnDrop::new(sink);
        let mut parts = Parts { source, pipeline, sink: &mut guard, stop, clock, timer, observer, controls };
        let why = loop {
            match self.step(&mut parts)? {
                Step::End(why) => break why,
                _ => {
                    if let Some(why) = self.ended {
                        break why;
                    }
                }
            }
        };
        // Neutral now (and exactly once), before the caller flushes files (`parts` borrowed
        // the guard; that borrow has ended).
        guard.into_inner();
        Ok(why)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::sink::RecordingSink;
    use crate::timing::NoTimer;
    use image::RgbImage;

    /// Frames from a list; `None` entries are unusable frames, `Stall` a stalled camera.
    struct Scripted {
        items: Vec<Option<Result<u64, bool>>>,
        i: usize,
        size: (u32, u32),
    }
    impl FrameSource for Scripted {
        fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
            let it = *self.items.get(self.i)?;
            self.i += 1;
            Some(match it {
                Some(Ok(index)) => Ok(Frame::new(
                    index,
                    index as f64 / 30.0,
                    format!("f{index}"),
                    RgbImage::new(self.size.0, self.size.1),
                )),
                Some(Err(stalled)) => Err(FrameError {
                    index: self.i as u64,
                    name: "cam".into(),
                    reason: "x".into(),
                    stalled,
                }),
                None => return None,
            })
        }
    }

    fn pipeline() -> Pipeline {
        let mut cfg = Config::default();
        cfg.detect.enabled = false;
        Pipeline::new(&cfg).unwrap()
    }

    #[test]
    fn counts_drops_skips_stalls_and_ends_with_neutral() {
        let mut p = pipeline();
        let (w, h) = p.frame_size();
        let mut src = Scripted {
            items: vec![
                Some(Ok(0)),
                Some(Ok(1)),
                Some(Ok(4)), // 2, 3 dropped by the source
                Some(Err(false)),
                Some(Err(true)),
                Some(Ok(7)),
            ],
            i: 0,
            size: (w, h),
        };
        let mut sink = RecordingSink::default();
        let stop = StopSignal::new();
        let mut d = Driver::new(30.0);
        let end = d
            .run(Parts {
                source: &mut src,
                pipeline: &mut p,
                sink: &mut sink,
                stop: &stop,
                clock: &NoClock,
                timer: &mut NoTimer,
                observer: &mut NoObserver,
                controls: None,
            })
            .unwrap();
        assert_eq!(end, LoopEnd::SourceEnded);
        let s = d.stats();
        assert_eq!((s.frames, s.skipped, s.stalls), (4, 1, 1));
        // 2, 3 dropped; the skipped frame names index 4; after the stall the gap to 7 is not
        // counted (a stalled camera made no frames)
        assert_eq!(s.dropped, 2);
        // frames 0, 1, 4, the stall's neutral, frame 7, the final neutral
        assert_eq!(sink.log.len(), 6);
        assert_eq!(sink.log[3].1, Command::NEUTRAL, "stall sends neutral");
        assert_eq!(sink.log.last().unwrap().1, Command::NEUTRAL);
    }

    #[test]
    fn a_stop_request_ends_before_the_next_frame_and_sends_neutral() {
        let mut p = pipeline();
        let (w, h) = p.frame_size();
        let mut src = Scripted {
            items: (0..100).map(|i| Some(Ok(i))).collect(),
            i: 0,
            size: (w, h),
        };
        struct StopAt(u64, StopSignal);
        impl Observer for StopAt {
            fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
                if ctx.frame.index == self.0 {
                    self.1.request(StopReason::Interrupt);
                }
                Ok(Flow::Continue)
            }
        }
        let stop = StopSignal::new();
        let mut obs = StopAt(9, stop.clone());
        let mut sink = RecordingSink::default();
        let end = Driver::new(30.0)
            .run(Parts {
                source: &mut src,
                pipeline: &mut p,
                sink: &mut sink,
                stop: &stop,
                clock: &NoClock,
                timer: &mut NoTimer,
                observer: &mut obs,
                controls: None,
            })
            .unwrap();
        assert_eq!(end, LoopEnd::Stopped(StopReason::Interrupt));
        assert_eq!(sink.log.len(), 11, "10 frames + neutral");
        assert_eq!(sink.log[10].1, Command::NEUTRAL);
    }

    #[test]
    fn an_observer_error_still_sends_neutral() {
        let mut p = pipeline();
        let (w, h) = p.frame_size();
        let mut src = Scripted {
            items: (0..10).map(|i| Some(Ok(i))).collect(),
            i: 0,
            size: (w, h),
        };
        struct Fails;
        impl Observer for Fails {
            fn on_frame(&mut self, _: &FrameContext<'_>) -> Result<Flow, LoopError> {
                Err(LoopError::Observer("telemetry.jsonl: disk full".into()))
            }
        }
        let log = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
        struct Shared(std::rc::Rc<std::cell::RefCell<Vec<Command>>>);
        impl CommandSink for Shared {
            fn send(&mut self, c: Command, _: f64) -> Result<Command, SinkError> {
                self.0.borrow_mut().push(c);
                Ok(c)
            }
        }
        let mut sink = Shared(log.clone());
        let r = Driver::new(30.0).run(Parts {
            source: &mut src,
            pipeline: &mut p,
            sink: &mut sink,
            stop: &StopSignal::new(),
            clock: &NoClock,
            timer: &mut NoTimer,
            observer: &mut Fails,
            controls: None,
        });
        assert!(r.is_err());
        assert_eq!(log.borrow().last(), Some(&Command::NEUTRAL));
    }

    /// Issue 26, through the loop and the gate: a recorded sequence of human inputs, mode
    /// changes, arming and the e-stop, one entry per frame.
    #[test]
    fn human_inputs_pass_the_same_gate_and_go_stale() {
        use crate::drive::arming::AtomicF64;
        use crate::sink::Actuators;
        struct At(Arc<AtomicF64>);
        impl Clock for At {
            fn now_s(&self) -> f64 {
                self.0.get()
            }
        }
        #[derive(Default)]
        struct Motors(Vec<Command>);
        impl CommandSink for Motors {
            fn send(&mut self, c: Command, _: f64) -> Result<Command, SinkError> {
                self.0.push(c);
                Ok(c)
            }
            // Only the frames' commands are logged (not the neutral of a disarm).
            fn stop(&mut self) -> Result<(), SinkError> {
                Ok(())
            }
        }
        impl Actuators for Motors {}
        use std::sync::Arc;
        let mut p = pipeline();
        let (w, h) = p.frame_size();
        let mut src = Scripted {
            items: (0..20).map(|i| Some(Ok(i))).collect(),
            i: 0,
            size: (w, h),
        };
        let now = Arc::new(AtomicF64::new(0.0));
        let arming = Arming::new(crate::health::Health::new());
        let c = arming.controls();
        c.configure(0.25, 0.5);
        // The human's clock is the test's, so the recorded sequence is exact.
        assert!(c.use_clock(Arc::new(At(now.clone()))));
        let stop = StopSignal::new();
        let mut gate = Gate::new(
            Motors::default(),
            GateOptions { arming: arming.clone(), stop: stop.clone(), clock: Arc::new(At(now.clone())), give_up_s: 3.0 },
        );
        let clock = At(now.clone());
        let mut d = Driver::new(30.0);
        let mut records = Vec::new();
        for k in 0..20u64 {
            let t = k as f64 / 30.0;
            now.set(t);
            // What happened before frame k (the recorded sequence).
            match k {
                0 => {
                    c.set_mode(DriveMode::Manual, Actor::Page, t);
                    c.set_input(0.5, 1.0).unwrap();
                }
                1 => c.set_input(0.5, 1.0).unwrap(),
                2 => {
                    arming.arm(Actor::Page).unwrap();
                    c.set_input(0.5, 1.0).unwrap();
                }
                4 => {
                    arming.estop(Actor::Page);
                    c.set_input(1.0, 1.0).unwrap();
                }
                5 => c.set_input(1.0, 1.0).unwrap(),
                6 => {
                    arming.release(Actor::Page);
                    arming.arm(Actor::Page).unwrap();
                    c.set_input(-0.25, 0.5).unwrap();
                }
                15 => {
                    c.set_mode(DriveMode::Assisted, Actor::Pad, t);
                    c.set_input(0.9, 0.75).unwrap();
                }
                _ => {}
            }
            let step = d
                .step(&mut Parts {
                    source: &mut src,
                    pipeline: &mut p,
                    sink: &mut gate,
                    stop: &stop,
                    clock: &clock,
                    timer: &mut NoTimer,
                    observer: &mut NoObserver,
                    controls: Some(c),
                })
                .unwrap();
            let Step::Frame(b) = step else { panic!("frame {k}: {step:?}") };
            records.push(b.1);
        }
        let sent = &gate.inner_mut().0;
        let cmd = |steer: f64, throttle: f64| Command { steer, throttle };
        assert_eq!(&sent[..2], &[Command::NEUTRAL; 2], "disarmed: never moves whatever the input");
        assert_eq!(&sent[2..4], &[cmd(0.5, 0.5); 2], "armed: the human's steer, throttle under the ceiling");
        assert_eq!(&sent[4..6], &[Command::NEUTRAL; 2], "e-stopped: never moves whatever the input");
        // The input of frame 6 (t = 0.2 s) holds for 250 ms: frames up to t = 0.45 s.
        for (k, s) in sent.iter().enumerate().take(15).skip(6) {
            let want = if (k as f64 / 30.0) - 0.2 <= 0.25 { cmd(-0.25, 0.25) } else { Command::NEUTRAL };
            assert_eq!(*s, want, "frame {k}");
        }
        assert_eq!(sent[14], Command::NEUTRAL, "stale on the first frame past the deadline");
        // Assisted: the pipeline's steering, the human's throttle.
        assert_eq!(sent[15], cmd(records[15].steer, 0.375));
        assert_eq!(records[15].pilot, Some(Pilot::Shared));
        assert_eq!(records[0].drive_mode, Some(DriveMode::Manual));
        assert_eq!(records[3].pilot, Some(Pilot::Human));
        assert_eq!(records[3].human, Some(cmd(0.5, 0.5)));
        assert!(records[0].events.iter().any(|e| e == "mode manual (was autopilot) by page at wall 0.000 s"), "{:?}", records[0].events);
        assert!(records[15].events.iter().any(|e| e.starts_with("mode assisted (was manual) by pad")), "{:?}", records[15].events);
        assert!(records[1].events.is_empty(), "a change is noted once: {:?}", records[1].events);
    }

    /// Issue 26's safety hole: under `--no-timing` the run's clock reads nothing (always 0),
    /// so an input timed on it never went stale and a page that went away left the car
    /// driving. Inputs are timed on the wall clock: stale after the deadline whatever the
    /// run's clock says.
    #[test]
    fn an_input_goes_stale_on_the_wall_clock_when_the_run_clock_reads_nothing() {
        let mut p = pipeline();
        let (w, h) = p.frame_size();
        let mut src = Scripted {
            items: (0..3).map(|i| Some(Ok(i))).collect(),
            i: 0,
            size: (w, h),
        };
        let arming = Arming::new(crate::health::Health::new());
        arming.arm(crate::drive::Actor::Page).unwrap();
        let c = arming.controls();
        c.configure(0.1, 1.0);
        c.set_mode(DriveMode::Manual, crate::drive::Actor::Page, 0.0);
        let mut sink = RecordingSink::default();
        let stop = StopSignal::new();
        let mut d = Driver::new(30.0);
        let step = |d: &mut Driver, src: &mut Scripted, p: &mut Pipeline, sink: &mut RecordingSink| {
            let s = d
                .step(&mut Parts {
                    source: src,
                    pipeline: p,
                    sink,
                    stop: &stop,
                    clock: &NoClock,
                    timer: &mut NoTimer,
                    observer: &mut NoObserver,
                    controls: Some(c),
                })
                .unwrap();
            assert!(matches!(s, Step::Frame(_)), "{s:?}");
        };
        c.set_input(0.5, 0.8).unwrap();
        step(&mut d, &mut src, &mut p, &mut sink);
        assert_eq!(sink.log.last().unwrap().1, Command { steer: f64::from(0.5f32), throttle: f64::from(0.8f32) });
        // 250 ms of wall time with no new input, the run's clock still at 0.
        std::thread::sleep(std::time::Duration::from_millis(250));
        step(&mut d, &mut src, &mut p, &mut sink);
        assert_eq!(sink.log.last().unwrap().1, Command::NEUTRAL, "stale input is neutral");
    }

    /// A mode change starts the steering method afresh (a PID must not carry the integral it
    /// gathered while a human steered into the handover).
    #[test]
    fn a_mode_change_resets_the_steering_method() {
        use crate::control::params::{ParamInfo, Tunable};
        use crate::control::steering::{Steering, SteeringInput, SteeringMethod};
        use std::sync::atomic::{AtomicUsize, Ordering};
        #[derive(Debug, Clone)]
        struct Counting(Arc<AtomicUsize>);
        impl Tunable for Counting {
            fn params(&self) -> Vec<ParamInfo> {
                Vec::new()
            }
            fn get_param(&self, _: &str) -> Option<f64> {
                None
            }
            fn set_param(&mut self, _: &str, _: f64) -> bool {
                false
            }
        }
        impl Steering for Counting {
            fn method(&self) -> SteeringMethod {
                SteeringMethod::Pid
            }
            fn steer(&mut self, _: &SteeringInput<'_>, _: f64) -> f64 {
                0.0
            }
            fn reset(&mut self) {
                self.0.fetch_add(1, Ordering::SeqCst);
            }
            fn clone_box(&self) -> Box<dyn Steering> {
                Box::new(self.clone())
            }
        }
        use std::sync::Arc;
        // Resets over 8 frames, with a mode change before the frames in `changes`.
        let resets = |changes: &[(u64, DriveMode)]| {
            let mut p = pipeline();
            let n = Arc::new(AtomicUsize::new(0));
            let throttle = (&Config::default().throttle).into();
            *p.controller_mut() = crate::control::Controller::new(Box::new(Counting(n.clone())), throttle);
            let (w, h) = p.frame_size();
            let mut src = Scripted {
                items: (0..8).map(|i| Some(Ok(i))).collect(),
                i: 0,
                size: (w, h),
            };
            let arming = Arming::new(crate::health::Health::new());
            let c = arming.controls();
            let mut sink = RecordingSink::default();
            let stop = StopSignal::new();
            let mut d = Driver::new(30.0);
            for k in 0..8u64 {
                if let Some((_, m)) = changes.iter().find(|(at, _)| *at == k) {
                    c.set_mode(*m, crate::drive::Actor::Page, 0.0);
                }
                d.step(&mut Parts {
                    source: &mut src,
                    pipeline: &mut p,
                    sink: &mut sink,
                    stop: &stop,
                    clock: &NoClock,
                    timer: &mut NoTimer,
                    observer: &mut NoObserver,
                    controls: Some(c),
                })
                .unwrap();
            }
            n.load(Ordering::SeqCst)
        };
        let base = resets(&[]);
        let with = resets(&[(2, DriveMode::Manual), (5, DriveMode::Autopilot)]);
        assert_eq!(with, base + 2, "one reset per mode change (base {base})");
    }
}
