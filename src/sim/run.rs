//! [`Simulation`]: the simulated car built by the library's session builder
//! ([`crate::session::Session`]: the simulator's lock-step camera, its vehicle behind the one
//! gate, the score) stepped frame by frame — one call of [`Simulation::step`] is one turn of
//! the car's own loop. Tests, benchmarks, sweeps and the labs use it; `rccar sim` builds the
//! same session with its telemetry, dashboard and report.
//!
//! Units: metres, seconds, radians.

pub use super::world::{roi_rows, EndReason, Summary};
use super::render::Renderer;
use super::scene::Scene;
use super::track::Track;
use super::truth::FrameTruth;
use super::vehicle::Vehicle;
use super::world::{lock, SharedWorld};
use crate::config::Config;
use crate::drive::{Flow, FrameContext, Level, LoopError, NoClock, NoObserver, Observer, Step, StopSignal};
use crate::pipeline::{FrameOutput, PipelineError};
use crate::session::{DetectorSpec, SceneSpec, Session, SessionEnv, SessionError, SessionSpec, SinkSpec, SourceSpec, Timing};
use crate::telemetry::FrameRecord;
use crate::timing::NoTimer;
use image::RgbImage;
use std::sync::Arc;

/// Why a simulation cannot start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The pipeline cannot be built from the configuration.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// The ROI gives no bird's-eye view.
    #[error("warp.src: {0}")]
    Warp(crate::lane::warp::WarpError),
    /// The session cannot be built (anything else).
    #[error(transparent)]
    Session(Box<SessionError>),
}

// By hand, not `#[from]`: a `source` would print the cause a second time after the message.
impl From<crate::lane::warp::WarpError> for SimError {
    fn from(e: crate::lane::warp::WarpError) -> Self {
        SimError::Warp(e)
    }
}

impl From<SessionError> for SimError {
    fn from(e: SessionError) -> Self {
        match e {
            SessionError::Pipeline(p) => SimError::Pipeline(p),
            SessionError::Warp(w) => SimError::Warp(w),
            e => SimError::Session(Box::new(e)),
        }
    }
}

/// What one step produced.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// The pipeline's output.
    pub out: FrameOutput,
    /// Ground truth of the frame.
    pub truth: FrameTruth,
    /// Frame number.
    pub frame: u64,
    /// Time of the frame, seconds.
    pub time_s: f64,
    /// The behaviour transition made in this frame.
    pub transition: Option<crate::control::behaviour::Transition>,
    /// The objects the pipeline ranged this frame.
    pub objects: Vec<crate::pipeline::RangedObject>,
    /// The loop's telemetry record of the frame.
    pub record: FrameRecord,
}

impl StepOutput {
    /// The telemetry record of this step, named `file`.
    pub fn record(&self, file: &str) -> FrameRecord {
        let mut r = self.record.clone();
        r.file = file.to_string();
        r
    }
}

/// A running simulation: the session of a simulated car, stepped by the caller.
pub struct Simulation {
    session: Session,
    world: SharedWorld,
    cfg: Config,
    full_frames: bool,
    truth_boxes: bool,
    detector: Option<Option<crate::detect::DetectStage>>,
    /// The last frame (kept while `full_frames`: a partial frame is nobody's picture).
    last: RgbImage,
}

/// Keeps a copy of each frame's image (one buffer, reused).
struct KeepImage<'a>(&'a mut RgbImage);

impl Observer for KeepImage<'_> {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let img = &ctx.frame.image;
        if self.0.dimensions() == img.dimensions() {
            self.0.copy_from_slice(img.as_raw());
        } else {
            *self.0 = img.clone();
        }
        Ok(Flow::Continue)
    }
}

impl Simulation {
    /// A car at rest at the start of `track`, centred in its lane, under `cfg`.
    pub fn new(cfg: &Config, track: &Track) -> Result<Simulation, SimError> {
        Self::with_scene(cfg, Arc::new(Scene::new(track)))
    }

    /// Like [`Simulation::new`] with a scene built once and shared (gain sweeps).
    pub fn with_scene(cfg: &Config, scene: Arc<Scene>) -> Result<Simulation, SimError> {
        let session = Self::session(cfg, scene, true, false)?;
        let world = session.world().expect("a simulation has a world").clone();
        Ok(Simulation {
            session,
            world,
            cfg: cfg.clone(),
            full_frames: true,
            truth_boxes: false,
            detector: None,
            last: RgbImage::new(cfg.camera.width, cfg.camera.height),
        })
    }

    /// The session of a simulated car: lock-step, armed from the start, no detector (the
    /// caller installs one), stepping on past the world's end (the caller decides when to
    /// stop).
    fn session(cfg: &Config, scene: Arc<Scene>, full_frames: bool, truth_boxes: bool) -> Result<Session, SessionError> {
        let mut spec = SessionSpec::new(
            SourceSpec::Sim {
                scene: SceneSpec::Shared(scene),
                timing: Timing::LockStep,
                stall: None,
                start_offset_m: None,
            },
            SinkSpec::DryRun,
        );
        spec.detector = DetectorSpec::Off;
        spec.operator_ends_run = true;
        spec.frames_viewed = full_frames;
        spec.truth_boxes = truth_boxes;
        Session::build(
            cfg,
            spec,
            SessionEnv {
                clock: Arc::new(NoClock),
                stop: StopSignal::new(),
                timer: Box::new(NoTimer),
                say: Arc::new(|_: Level, _: &str| {}),
            },
        )
    }

    /// Builds the session again with the current settings (before the first step).
    fn rebuild(&mut self) {
        let scene = lock(&self.world).scene().clone();
        // The settings were valid when the simulation was built: the same config again.
        // The camera's row plan is made from the pipeline as it is built, before the detector
        // is installed: with a detector, render whole frames (else its rows would be black).
        let whole = self.full_frames || self.detector.as_ref().is_some_and(|d| d.is_some());
        let mut s = Self::session(&self.cfg, scene, whole, self.truth_boxes)
            .expect("a simulation's session builds again with the same configuration");
        if let Some(d) = self.detector.clone() {
            s.pipeline_mut().set_detector(d);
        }
        self.world = s.world().expect("a simulation has a world").clone();
        self.session = s;
    }

    /// The shared world (for a dashboard, a stereo camera, or tests).
    pub fn world(&self) -> &SharedWorld {
        &self.world
    }

    /// Puts the car, at rest, on the lane centre at `s` metres along the track (before the
    /// first step; laps are then counted from there).
    pub fn place_at(&mut self, s: f64) {
        lock(&self.world).place_at(s);
    }

    /// Renders only the image rows the pipeline reads on each frame when `false` (the lane
    /// ROI, plus the detectors' rows on detection frames, plus the blur's reach; see
    /// [`super::camera::SimCamera::set_row_plan`]); the pipeline then decides exactly as on
    /// full frames, at a fraction of the cost. [`Simulation::image`] then shows only those
    /// rows. Default `true`. Set it before the first step. With a detector installed
    /// ([`Simulation::set_detector`]) whole frames are rendered regardless.
    pub fn set_full_frames(&mut self, full: bool) {
        if full != self.full_frames {
            self.full_frames = full;
            self.rebuild();
        }
    }

    /// Installs the pipeline's detector (see [`crate::pipeline::load_detector`]). Set it
    /// before the first step.
    pub fn set_detector(&mut self, detect: Option<crate::detect::DetectStage>) {
        self.detector = Some(detect);
        self.rebuild();
    }

    /// `true`: the pipeline gets the objects' true image boxes instead of its detector's
    /// (see [`super::camera::SimCamera::set_truth_boxes`]). Set it before the first step.
    pub fn set_truth_boxes(&mut self, on: bool) {
        self.truth_boxes = on;
        self.rebuild();
    }

    /// The pipeline.
    pub fn pipeline(&self) -> &crate::pipeline::Pipeline {
        self.session.pipeline()
    }

    /// The frame rendered by the last step (with [`Simulation::set_full_frames`] `false`, a
    /// black frame: only the rows the pipeline reads are rendered, and nobody keeps them).
    pub fn image(&self) -> &RgbImage {
        &self.last
    }

    /// A copy of the vehicle's state.
    pub fn vehicle(&self) -> Vehicle {
        lock(&self.world).vehicle().clone()
    }

    /// The scene (track and objects).
    pub fn scene(&self) -> Arc<Scene> {
        lock(&self.world).scene().clone()
    }

    /// The renderer (to render extra views, e.g. a stereo camera or object crops).
    pub fn renderer(&self) -> Renderer {
        lock(&self.world).renderer().clone()
    }

    /// Why the run has ended, once it has.
    pub fn ended(&self) -> Option<EndReason> {
        lock(&self.world).ended()
    }

    /// One turn of the car's loop (see [`crate::drive`]).
    pub fn step(&mut self) -> StepOutput {
        loop {
            let r = if self.full_frames {
                self.session.step(&mut KeepImage(&mut self.last))
            } else {
                self.session.step(&mut NoObserver)
            };
            match r {
                Ok(Step::Frame(b)) => {
                    let (out, record) = *b;
                    let truth = lock(&self.world).last_truth().cloned().expect("a rendered frame has truth");
                    return StepOutput {
                        out,
                        frame: record.frame,
                        time_s: record.time_s,
                        transition: record.transition.clone(),
                        objects: record.objects.clone(),
                        truth,
                        record,
                    };
                }
                // The facade's camera and score never end the loop (a test may step on past
                // the world's end: the world keeps going), and never fail.
                Ok(_) => {}
                Err(e) => unreachable!("the simulator's vehicle and score never fail: {e}"),
            }
        }
    }

    /// Steps until the run ends, handing every step to `each`.
    pub fn run<E>(&mut self, mut each: impl FnMut(&Simulation, &StepOutput) -> Result<(), E>) -> Result<Summary, E> {
        while self.ended().is_none() {
            let s = self.step();
            each(self, &s)?;
        }
        Ok(self.summary())
    }

    /// The score so far.
    pub fn summary(&self) -> Summary {
        lock(&self.world).summary()
    }
}
