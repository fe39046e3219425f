//! [`Simulation`]: the simulator's camera, vehicle and score ([`super::world`]) wired to the
//! car's own loop ([`crate::drive::Driver`]) — one call of [`Simulation::step`] is one turn of
//! that loop. Tests, benchmarks, sweeps and the labs step it frame by frame; `rccar sim` runs
//! the same parts through the loop in `src/cli/sim.rs`.
//!
//! Units: metres, seconds, radians.

pub use super::world::{roi_rows, EndReason, Summary};
use super::render::Renderer;
use super::scene::Scene;
use super::track::Track;
use super::truth::FrameTruth;
use super::vehicle::Vehicle;
use super::world::{lock, SharedWorld, SimCamera, SimScore, SimVehicle, World};
use crate::config::Config;
use crate::drive::{Driver, NoClock, Parts, Step, StopSignal};
use crate::pipeline::{FrameOutput, Pipeline, PipelineError};
use crate::telemetry::FrameRecord;
use crate::timing::StageTimer;
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
    Warp(#[from] crate::lane::warp::WarpError),
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

/// A running simulation: world, camera, vehicle, score, the pipeline and the loop.
pub struct Simulation {
    world: SharedWorld,
    camera: SimCamera,
    vehicle: SimVehicle,
    score: SimScore,
    pipeline: Pipeline,
    driver: Driver,
    stop: StopSignal,
    full_frames: bool,
    truth_boxes: bool,
}

impl Simulation {
    /// A car at rest at the start of `track`, centred in its lane, under `cfg`.
    pub fn new(cfg: &Config, track: &Track) -> Result<Simulation, SimError> {
        Self::with_scene(cfg, Arc::new(Scene::new(track)))
    }

    /// Like [`Simulation::new`] with a scene built once and shared (gain sweeps).
    pub fn with_scene(cfg: &Config, scene: Arc<Scene>) -> Result<Simulation, SimError> {
        let world = World::new(cfg, scene)?.shared();
        let pipeline = Pipeline::new(cfg)?;
        let mut s = Simulation {
            camera: SimCamera::new(world.clone()).ending_with_world(false),
            vehicle: SimVehicle::new(world.clone()),
            score: SimScore::new(world.clone()).ending_the_run(false),
            world,
            pipeline,
            driver: Driver::new(cfg.camera.fps),
            stop: StopSignal::new(),
            full_frames: true,
            truth_boxes: false,
        };
        s.update_rows();
        Ok(s)
    }

    /// Renders all rows, or only those the pipeline reads on each frame when nobody looks at
    /// the frames (the same decisions, faster).
    fn update_rows(&mut self) {
        if self.full_frames {
            self.camera.set_rows(None);
        } else {
            // The lane's rows, and the detection rows on frames where detection runs.
            self.camera.set_row_plan(Some(self.pipeline.row_plan()));
        }
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
    /// [`SimCamera::set_row_plan`]); the pipeline then decides exactly as on full frames, at
    /// a fraction of the cost. [`Simulation::image`] then shows only those rows. Default `true`.
    pub fn set_full_frames(&mut self, full: bool) {
        self.full_frames = full;
        self.update_rows();
    }

    /// Installs the pipeline's detector (see [`crate::pipeline::load_detector`]).
    pub fn set_detector(&mut self, detect: Option<crate::detect::DetectStage>) {
        self.pipeline.set_detector(detect);
        self.update_rows();
    }

    /// `true`: the pipeline gets the objects' true image boxes instead of its detector's
    /// (see [`SimCamera::set_truth_boxes`]).
    pub fn set_truth_boxes(&mut self, on: bool) {
        self.truth_boxes = on;
        self.camera.set_truth_boxes(on);
        self.update_rows();
    }

    /// The pipeline.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The frame rendered by the last step.
    pub fn image(&self) -> &RgbImage {
        self.camera.image()
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

    /// One turn of the car's loop (see [`crate::drive`]). `timer` measures the pipeline's
    /// stages.
    pub fn step(&mut self, timer: &mut dyn StageTimer) -> StepOutput {
        loop {
            let r = self.driver.step(&mut Parts {
                source: &mut self.camera,
                pipeline: &mut self.pipeline,
                sink: &mut self.vehicle,
                stop: &self.stop,
                clock: &NoClock,
                timer,
                observer: &mut self.score,
            });
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
    pub fn run<E>(
        &mut self,
        timer: &mut dyn StageTimer,
        mut each: impl FnMut(&Simulation, &StepOutput) -> Result<(), E>,
    ) -> Result<Summary, E> {
        while self.ended().is_none() {
            let s = self.step(timer);
            each(self, &s)?;
        }
        Ok(self.summary())
    }

    /// The score so far.
    pub fn summary(&self) -> Summary {
        lock(&self.world).summary()
    }
}
