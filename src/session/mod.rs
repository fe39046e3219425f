//! The car assembled in the library: a [`Session`] is built from a configuration, a
//! [`SessionSpec`] (where frames come from, where commands go, what is kept) and what the
//! caller lends ([`SessionEnv`]: clock, stop signal, timer, where lines go); it returns a
//! runnable loop and its notes. `rccar drive`, `replay` and `sim`, the simulator facade
//! ([`crate::sim::run::Simulation`]) and the tests all build the car here.
//!
//! ```text
//!  SourceSpec ──► frame source ─┐                          ┌─► Gate ─► actuators (link |
//!  (cameras | folder | sim)     │    Driver::step          │   (one     simulated car |
//!                               ├──► pipeline ──command────┘   arming)  nothing)
//!  observers: camera health,    │
//!  GPIO, score, car status,  ◄──┘ one record per frame
//!  telemetry, recorder, status line, pulse latency, pacer, + the caller's own
//! ```
//!
//! Every way out of [`Session::run`] — the end of the source, a stop request, an error, a
//! panic unwinding through it — ends with neutral sent through the gate (once), before the
//! caller flushes any file.
//!
//! [`camera_check`] is `rccar camera check`: a session with a camera and no sink, measured.

mod build;
pub mod camera_check;
pub mod observers;
pub mod replay;
pub mod spec;

pub use spec::{ArmAt, CameraSpec, DetectorSpec, Level, SceneSpec, Say, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};

use crate::config::Config;
use crate::drive::{Arming, Driver, Gate, LoopEnd, LoopError, LoopStats, NoObserver, Observer, Parts, Sent, Step};
use crate::health::{Fault, Health, Part};
use crate::pipeline::Pipeline;
use crate::record::observer::{RecordObserver, Recorded};
use crate::sim::world::{lock, SharedWorld, SimScore, Summary};
use crate::sink::{Actuators, CommandSink};
use crate::source::FrameSource;
use crate::telemetry::JsonlWriter;
use observers::{CameraHealth, CarState, Pacer, StatusLine};
use std::fs::File;
use std::path::PathBuf;
use std::sync::Arc;

/// Why a session cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The spec asks for something that cannot work together (names the flags or keys).
    #[error("{0}")]
    Invalid(String),
    /// The two folders of a camera pair do not pair up (names the frame).
    #[error("{0}")]
    Pair(String),
    /// The pipeline cannot be built from the configuration.
    #[error(transparent)]
    Pipeline(#[from] crate::pipeline::PipelineError),
    /// The track file.
    #[error(transparent)]
    Track(#[from] crate::sim::track::TrackError),
    /// The simulator's camera cannot see the road (warp).
    #[error("warp.src: {0}")]
    Warp(crate::lane::warp::WarpError),
    /// A folder of frames.
    #[error(transparent)]
    Source(#[from] crate::source::SourceError),
    /// A cascade file.
    #[error("detect: {0}")]
    Cascade(crate::detect::cascade::CascadeError),
    /// The recording folder.
    #[error(transparent)]
    Record(#[from] crate::record::RecordError),
    /// A file (names it).
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        error: std::io::Error,
    },
    /// The camera.
    #[error("{0}")]
    Camera(String),
    /// The serial link.
    #[cfg(feature = "serial")]
    #[error(transparent)]
    Link(#[from] crate::link::sink::LinkOpenError),
    /// The Pi's GPIO.
    #[cfg(feature = "gpio")]
    #[error(transparent)]
    Gpio(#[from] crate::gpio::pi::GpioError),
}

// By hand, not `#[from]`: a `source` would print the cause a second time after the message.
impl From<crate::lane::warp::WarpError> for SessionError {
    fn from(e: crate::lane::warp::WarpError) -> Self {
        SessionError::Warp(e)
    }
}

impl From<crate::detect::cascade::CascadeError> for SessionError {
    fn from(e: crate::detect::cascade::CascadeError) -> Self {
        SessionError::Cascade(e)
    }
}

/// The session's own parts of the loop, each present or not.
struct Own {
    camera: CameraHealth,
    gpio: Option<Box<dyn Observer>>,
    score: Option<SimScore>,
    car: Option<CarState>,
    telemetry: Option<(JsonlWriter<File>, PathBuf)>,
    recorder: Option<RecordObserver>,
    status: Option<StatusLine>,
    pulse: Option<crate::sim::pwm::PulseLatency>,
    pacer: Option<Pacer>,
}

/// The serial link's handles kept for the run's end.
#[cfg(feature = "serial")]
struct LinkHandles {
    link: Arc<crate::link::transport::Link>,
    flipped: Arc<std::sync::atomic::AtomicU64>,
    noisy: bool,
}

/// A car, ready to run (see the module notes).
pub struct Session {
    cfg: Config,
    source: Box<dyn FrameSource>,
    pipeline: Pipeline,
    gate: Gate<Box<dyn Actuators>>,
    arming: Arc<Arming>,
    world: Option<SharedWorld>,
    /// A device camera (not a folder or the simulator): its end is a fault.
    device: bool,
    own: Own,
    pwm: Option<crate::sim::pwm::PwmWatcher>,
    #[cfg(feature = "serial")]
    link: Option<LinkHandles>,
    driver: Driver,
    env: SessionEnv,
    notes: Vec<(Level, String)>,
    /// Neutral went out after the last command (no second one on drop).
    neutral_sent: bool,
}

/// What a finished session wrote and measured.
#[derive(Debug)]
pub struct Outcome {
    /// Loop counters (frames, skipped, dropped, stalls, latency, period).
    pub stats: LoopStats,
    /// The first fatal fault, if any (the run must exit non-zero and name it).
    pub fault: Option<Fault>,
    /// The simulator's score.
    pub summary: Option<Summary>,
    /// The telemetry file and the lines written.
    pub telemetry: Option<(PathBuf, u64)>,
    /// The recording(s).
    pub recorded: Option<Recorded>,
    /// Capture → servo pulse latency (firmware in the loop): median, max, ms.
    pub pulse_latency_ms: Option<(f64, f64)>,
    /// Bits flipped by the link's noise test hook.
    pub bits_flipped: Option<u64>,
}

impl Outcome {
    /// The run's summary.json: the simulator's score (when there is one) and the loop's
    /// counters and fault under `drive`.
    pub fn summary_json(&self) -> Result<serde_json::Value, serde_json::Error> {
        let mut json = match &self.summary {
            Some(s) => serde_json::to_value(s)?,
            None => serde_json::json!({}),
        };
        json["drive"] = serde_json::json!({
            "frames": self.stats.frames, "skipped": self.stats.skipped, "dropped": self.stats.dropped,
            "stalls": self.stats.stalls, "fault": self.fault.as_ref().map(|f| f.to_string()),
            "bits_flipped": self.bits_flipped,
        });
        Ok(json)
    }

    /// What became of the recording(s), a line each, with the command that replays them.
    pub fn recording_lines(&self) -> Vec<(Level, String)> {
        let Some(rec) = &self.recorded else {
            return Vec::new();
        };
        let (dir, st) = &rec.main;
        let mut out = vec![match st {
            Ok(st) => (Level::Info, format!("  recording: {}/ ({st:?}); replay with `rccar replay {}`", dir.display(), dir.display())),
            Err(e) => (Level::Warn, format!("  recording: {}: {e}", dir.display())),
        }];
        if let Some((d2, st)) = &rec.right {
            out.push(match st {
                Ok(st) => (
                    Level::Info,
                    format!(
                        "  recording, other camera: {}/ ({st:?}); replay the pair with `rccar replay {} --right {} --set ranging.method=stereo`",
                        d2.display(),
                        dir.display(),
                        d2.display()
                    ),
                ),
                Err(e) => (Level::Warn, format!("  recording: {}: {e}", d2.display())),
            });
        }
        out
    }

    /// The end of a wall-clock run, a line each: the recordings, the telemetry, the capture to
    /// pulse latency, the link noise and the simulator's score (what `rccar drive` prints).
    pub fn end_lines(&self) -> Vec<(Level, String)> {
        let mut out = self.recording_lines();
        if let Some((p, n)) = &self.telemetry {
            out.push((Level::Info, format!("  telemetry: {} ({n} frames)", p.display())));
        }
        if let Some((med, max)) = self.pulse_latency_ms {
            out.push((Level::Info, format!("  capture -> pulse latency: median {med:.1} ms, max {max:.1} ms")));
        }
        if let Some(n) = self.bits_flipped {
            out.push((Level::Info, format!("  link noise: {n} bits flipped")));
        }
        if let Some(sum) = &self.summary {
            out.push((
                Level::Info,
                format!(
                    "  sim: {} laps, RMS cross-track {:.4} m, max {:.4} m, departures {}, ended {:?}",
                    sum.laps, sum.xte_rms_m, sum.xte_max_m, sum.lane_departures, sum.end
                ),
            ));
        }
        out
    }
}

impl Session {
    /// Builds a car from `cfg` and `spec` with what `env` lends (see [`spec`]). Everything
    /// that can fail is checked before anything can move, and before any output file is
    /// created.
    pub fn build(cfg: &Config, spec: SessionSpec, env: SessionEnv) -> Result<Session, SessionError> {
        build::build(cfg, spec, env)
    }

    /// Lines the build wants shown (what was set up, warnings), in order.
    pub fn notes(&self) -> &[(Level, String)] {
        &self.notes
    }

    /// The one arming state (the button, a page, a pad arm and stop through it).
    pub fn arming(&self) -> &Arc<Arming> {
        &self.arming
    }

    /// The health of the car's parts.
    pub fn health(&self) -> &Arc<Health> {
        self.arming.health()
    }

    /// What the gate really sent, and when.
    pub fn sent(&self) -> Arc<Sent> {
        self.gate.sent()
    }

    /// The simulated world, when the camera is the simulator's.
    pub fn world(&self) -> Option<&SharedWorld> {
        self.world.as_ref()
    }

    /// The pipeline.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The pipeline, to change between runs (a detector, a setting).
    pub fn pipeline_mut(&mut self) -> &mut Pipeline {
        &mut self.pipeline
    }

    /// The configuration the car was built from.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Replaces the frame source by one the spec cannot name (a test's scripted camera, a
    /// tool's own source); `device`: its end is a fault, as a camera's is.
    pub fn set_source(&mut self, source: Box<dyn FrameSource>, device: bool) {
        self.source = source;
        self.device = device;
    }

    /// The frame source (how many frames to expect, for a progress bar).
    pub fn source(&self) -> &dyn FrameSource {
        self.source.as_ref()
    }

    /// The serial link, when there is one (an emergency hook may send neutral through it
    /// from another thread).
    #[cfg(feature = "serial")]
    pub fn link(&self) -> Option<Arc<crate::link::transport::Link>> {
        self.link.as_ref().map(|l| l.link.clone())
    }

    /// Loop counters so far.
    pub fn stats(&self) -> &LoopStats {
        self.driver.stats()
    }

    /// One turn of the loop with `extra` watching after the session's own parts. No neutral
    /// is sent on the way out of a turn: [`Session::run`] (or dropping the session) does.
    pub fn step(&mut self, extra: &mut dyn Observer) -> Result<Step, LoopError> {
        let o = &mut self.own;
        let mut none = [NoObserver, NoObserver, NoObserver];
        let [n0, n1, n2] = &mut none;
        let gpio: &mut dyn Observer = match o.gpio.as_mut() {
            Some(g) => g.as_mut(),
            None => n0,
        };
        let tel: &mut dyn Observer = match o.telemetry.as_mut() {
            Some((t, _)) => t,
            None => n1,
        };
        let pulse: &mut dyn Observer = match o.pulse.as_mut() {
            Some(p) => p,
            None => n2,
        };
        let mut chain: [&mut dyn Observer; 10] = [
            &mut o.camera,
            gpio,
            &mut o.score,
            &mut o.car,
            tel,
            &mut o.recorder,
            &mut o.status,
            pulse,
            extra,
            &mut o.pacer,
        ];
        self.neutral_sent = false;
        let r = self.driver.step(&mut Parts {
            source: self.source.as_mut(),
            pipeline: &mut self.pipeline,
            sink: &mut self.gate,
            stop: &self.env.stop,
            clock: self.env.clock.as_ref(),
            timer: self.env.timer.as_mut(),
            observer: &mut chain,
            controls: Some(self.arming.controls()),
        });
        if let Some(rec) = self.own.recorder.as_mut() {
            if let Some(w) = rec.take_warning() {
                (self.env.say)(Level::Warn, &w);
            }
        }
        if let Ok(Step::End(LoopEnd::SourceEnded)) = r {
            self.source_ended();
        }
        r
    }

    /// The source ended: a camera that cannot be used, or a device that stopped delivering,
    /// is a fault; the end of a folder or of a simulation is not.
    fn source_ended(&mut self) {
        let h = self.arming.health();
        if let Some(why) = self.source.fatal() {
            h.fail(Part::Camera, why);
        } else if self.device {
            h.fail(Part::Camera, "the camera stopped delivering frames");
        }
    }

    /// Runs until the source ends, a stop is requested or an observer ends the run; neutral
    /// goes out on every way out (see the module notes).
    pub fn run(&mut self, extra: &mut dyn Observer) -> Result<LoopEnd, LoopError> {
        let r = loop {
            match self.step(extra) {
                Ok(Step::End(why)) => break Ok(why),
                Ok(_) => {
                    if let Some(why) = self.driver.ended() {
                        break Ok(why);
                    }
                }
                Err(e) => break Err(e),
            }
        };
        self.send_neutral();
        r
    }

    /// Neutral through the gate now (the actuators disarmed), once.
    pub fn send_neutral(&mut self) {
        if !self.neutral_sent {
            self.neutral_sent = true;
            if let Err(e) = self.gate.stop() {
                (self.env.say)(Level::Warn, &format!("neutral: {e} (the firmware's failsafe stops the car)"));
            }
        }
    }

    /// Closes everything (neutral first if not yet sent), flushes the telemetry and the
    /// recording, and reports what the run did.
    pub fn finish(mut self) -> Result<Outcome, SessionError> {
        self.send_neutral();
        let own = std::mem::replace(
            &mut self.own,
            Own {
                camera: CameraHealth(self.arming.clone()),
                gpio: None,
                score: None,
                car: None,
                telemetry: None,
                recorder: None,
                status: None,
                pulse: None,
                pacer: None,
            },
        );
        // The GPIO threads stop (LED off) before the files are closed.
        drop(own.gpio);
        let telemetry = match own.telemetry {
            Some((t, path)) => {
                let n = t.lines();
                t.finish().map_err(|error| SessionError::Io { path: path.clone(), error })?;
                Some((path, n))
            }
            None => None,
        };
        let recorded = own.recorder.map(RecordObserver::finish);
        let summary = self.world.as_ref().map(|w| lock(w).summary());
        #[cfg(feature = "serial")]
        let bits_flipped = self
            .link
            .as_ref()
            .filter(|l| l.noisy)
            .map(|l| l.flipped.load(std::sync::atomic::Ordering::SeqCst));
        #[cfg(not(feature = "serial"))]
        let bits_flipped = None;
        Ok(Outcome {
            stats: self.driver.stats().clone(),
            fault: self.arming.health().fatal(),
            summary,
            telemetry,
            recorded,
            pulse_latency_ms: self.pwm.as_ref().and_then(|p| p.latency_ms()),
            bits_flipped,
        })
    }
}

impl Drop for Session {
    /// A panic unwinding through the run, or a session dropped without [`Session::run`]'s
    /// end: neutral all the same.
    fn drop(&mut self) {
        self.send_neutral();
    }
}
