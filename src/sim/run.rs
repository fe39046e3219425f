//! The closed loop: render what the camera sees, run the car's own [`Pipeline`] on it, let
//! the vehicle model execute the command, score the result against ground truth.
//!
//! One step, frame k at time `t_k = k / fps` (the replay source's clock, so a recorded run
//! replays with bit-identical time steps):
//! 1. render the frame from the car's pose;
//! 2. compute the frame's ground truth at that pose;
//! 3. `Pipeline::step(frame, t_k − t_{k−1})` → lane measurement and command;
//! 4. the vehicle model executes the command for one frame period (`substeps` fixed steps);
//! 5. score: cross-track error of the car's centre, lane departures (a wheel's centre beyond
//!    a line's centre), progress along the track and laps.
//!
//! The run ends when the laps are done, at `max_seconds`, or early when the car has left the
//! road (more than a lane width off) or stood still for 5 s after starting.
//!
//! Units: metres, seconds, radians.

use super::render::ObjectBox;
use super::render::{CameraMount, RenderOptions, Renderer};
use super::scene::Scene;
use super::track::Track;
use super::track::{LightState as TrackLight, ObjectKind};
use super::truth::{FrameTruth, TruthModel};
use super::vehicle::{Pose, Vehicle};
use crate::camera::PinholeCamera;
use crate::config::Config;
use crate::control::behaviour::LightColor;
use crate::pipeline::{FrameOutput, GivenBox, Pipeline, PipelineError};
use crate::ranging::ObjectClass;
use crate::telemetry::FrameRecord;
use crate::timing::StageTimer;
use image::RgbImage;
use serde::Serialize;
use std::sync::Arc;

/// The camera rows the pipeline's bird's-eye warp reads (its ROI, bilinear taps, and the
/// blur's reach).
fn roi_rows(cfg: &Config) -> std::ops::Range<usize> {
    let ys = cfg.warp.src.iter().map(|p| p[1]);
    let lo = ys.clone().fold(f64::INFINITY, f64::min);
    let hi = ys.fold(f64::NEG_INFINITY, f64::max);
    let blur = (3.0 * cfg.sim.blur_px).ceil() + 2.0;
    let h = cfg.camera.height as f64;
    let a = (lo.floor() - blur).clamp(0.0, h) as usize;
    let b = (hi.ceil() + blur + 1.0).clamp(0.0, h) as usize;
    a..b
}

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

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EndReason {
    /// All laps driven.
    LapsDone,
    /// `max_seconds` reached.
    TimeUp,
    /// More than a lane width off the lane centre.
    LeftTheRoad,
    /// Stood still for 5 s (not counting waits the behaviour chose: stop sign, red light,
    /// obstacle).
    Stalled,
}

/// The score of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// Track name.
    pub track: String,
    /// Frames simulated.
    pub frames: u64,
    /// Simulated time, seconds.
    pub seconds: f64,
    /// Whole laps completed.
    pub laps: u32,
    /// Time of each completed lap, seconds.
    pub lap_times_s: Vec<f64>,
    /// Root mean square of the cross-track error over all frames, metres.
    pub xte_rms_m: f64,
    /// Largest |cross-track error|, metres.
    pub xte_max_m: f64,
    /// Times a wheel crossed out of the lane (each excursion counted once).
    pub lane_departures: u32,
    /// Time with a wheel outside the lane, seconds.
    pub time_outside_s: f64,
    /// Steering reversals per second (sign changes of the steering command beyond ±0.05).
    pub steer_reversals_per_s: f64,
    /// Frames where the pipeline lost the lane.
    pub lane_lost_frames: u64,
    /// Where each departure began, metres along the track's centre line.
    pub departures_at_m: Vec<f64>,
    /// Lane width, metres (to read the RMS against).
    pub lane_width_m: f64,
    /// Why the run ended.
    pub end: EndReason,
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
}

impl StepOutput {
    /// The telemetry record of this step (the pipeline's record plus `truth`).
    pub fn record(&self, file: &str) -> FrameRecord {
        let mut r = FrameRecord::new(
            self.frame,
            file,
            self.time_s,
            &self.out.lane,
            &self.out.command,
            self.out.stage_us,
        );
        r.truth = Some(self.truth.clone());
        r.behaviour = Some(self.out.mode);
        r.transition = self.transition.clone();
        r.objects = self.objects.clone();
        r.speed_est_mps = Some(self.out.observations.speed_mps);
        r.odometry_m = Some(self.out.observations.odometry_m);
        r.detect_us = Some(self.out.detect_us);
        r
    }
}

/// A running simulation.
pub struct Simulation {
    cfg: Config,
    track: Arc<Scene>,
    renderer: Renderer,
    truth: TruthModel,
    pipeline: Pipeline,
    vehicle: Vehicle,
    image: RgbImage,
    /// Render every row (recording, viewing) or only the rows the pipeline reads.
    full_frames: bool,
    roi_rows: std::ops::Range<usize>,
    /// Hand the pipeline the true object boxes instead of running its detector.
    truth_boxes: bool,
    given: Vec<GivenBox>,
    frame: u64,
    fps: f64,
    last_t: Option<f64>,
    // scoring
    progress: f64,
    last_s: f64,
    sq_sum: f64,
    xte_max: f64,
    outside: bool,
    departures: u32,
    departures_at: Vec<f64>,
    time_outside: f64,
    lap_times: Vec<f64>,
    last_lap_t: f64,
    last_steer_sign: f64,
    reversals: u32,
    lost: u64,
    still_s: f64,
    end: Option<EndReason>,
}

impl Simulation {
    /// A car at rest at the start of `track`, centred in its lane, under `cfg`.
    pub fn new(cfg: &Config, track: &Track) -> Result<Simulation, SimError> {
        Self::with_scene(cfg, Arc::new(Scene::new(track)))
    }

    /// Like [`Simulation::new`] with a scene built once and shared (gain sweeps).
    pub fn with_scene(cfg: &Config, scene: Arc<Scene>) -> Result<Simulation, SimError> {
        let mount = CameraMount {
            camera: PinholeCamera::from_config(&cfg.camera),
            x_m: cfg.vehicle.camera_x_m,
        };
        let renderer = Renderer::new(scene.clone(), mount, RenderOptions::from_config(&cfg.sim));
        let truth = TruthModel::new(cfg, mount)?;
        let pipeline = Pipeline::new(cfg)?;
        let track = &scene.track;
        // Rear axle on the lane centre, half a wheelbase behind the start line, so the car's
        // centre starts on it.
        let (p, yaw) = track.lane_pose_at(0.0);
        let half = cfg.vehicle.wheelbase_m / 2.0;
        let pose = Pose {
            x: p[0] - half * yaw.cos(),
            y: p[1] - half * yaw.sin(),
            yaw,
        };
        let dt = 1.0 / (cfg.camera.fps * cfg.sim.substeps as f64);
        let vehicle = Vehicle::new(&cfg.vehicle, pose, dt);
        let (_, _, s0) = TruthModel::lane_pose(track, &pose, cfg.vehicle.wheelbase_m);
        Ok(Simulation {
            cfg: cfg.clone(),
            track: scene,
            renderer,
            truth,
            pipeline,
            vehicle,
            image: RgbImage::new(cfg.camera.width, cfg.camera.height),
            full_frames: true,
            roi_rows: roi_rows(cfg),
            truth_boxes: false,
            given: Vec::new(),
            frame: 0,
            fps: cfg.camera.fps,
            last_t: None,
            progress: 0.0,
            last_s: s0,
            sq_sum: 0.0,
            xte_max: 0.0,
            outside: false,
            departures: 0,
            departures_at: Vec::new(),
            time_outside: 0.0,
            lap_times: Vec::new(),
            last_lap_t: 0.0,
            last_steer_sign: 0.0,
            reversals: 0,
            lost: 0,
            still_s: 0.0,
            end: None,
        })
    }

    /// Puts the car, at rest, on the lane centre at `s` metres along the track (before the
    /// first step; laps are then counted from there).
    pub fn place_at(&mut self, s: f64) {
        let track = &self.track.track;
        let (p, yaw) = track.lane_pose_at(s);
        let half = self.cfg.vehicle.wheelbase_m / 2.0;
        let pose = Pose {
            x: p[0] - half * yaw.cos(),
            y: p[1] - half * yaw.sin(),
            yaw,
        };
        let dt = 1.0 / (self.cfg.camera.fps * self.cfg.sim.substeps as f64);
        self.vehicle = Vehicle::new(&self.cfg.vehicle, pose, dt);
        self.last_s = TruthModel::lane_pose(track, &pose, self.cfg.vehicle.wheelbase_m).2;
    }

    /// Renders only the image rows the lane pipeline reads (its ROI, plus the blur's reach)
    /// when `false`; the pipeline then decides exactly as on full frames, at about half the
    /// cost. [`Simulation::image`] then shows only those rows. Default `true`.
    pub fn set_full_frames(&mut self, full: bool) {
        self.full_frames = full;
    }

    /// Installs the pipeline's detector (see [`crate::pipeline::load_detector`]).
    pub fn set_detector(&mut self, detect: Option<crate::detect::DetectStage>) {
        self.pipeline.set_detector(detect);
    }

    /// `true`: the pipeline gets the objects' true image boxes (a sign's face, a light's
    /// housing, an obstacle's box; bottom-clipped boxes left out) with the true light colour,
    /// instead of its detector's boxes. For testing behaviours without trained cascades.
    /// Objects then need full frames (rendering is not needed for them, but the detector's
    /// absence makes row-limited rendering safe either way).
    pub fn set_truth_boxes(&mut self, on: bool) {
        self.truth_boxes = on;
    }

    /// The pipeline.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The frame rendered by the last step.
    pub fn image(&self) -> &RgbImage {
        &self.image
    }

    /// The vehicle.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The scene (track and objects).
    pub fn scene(&self) -> &Arc<Scene> {
        &self.track
    }

    /// The renderer (to render extra views, e.g. a stereo camera or object crops).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Why the run has ended, once it has.
    pub fn ended(&self) -> Option<EndReason> {
        self.end
    }

    /// One frame of the loop (see the module notes). `timer` measures the pipeline's stages.
    pub fn step(&mut self, timer: &mut dyn StageTimer) -> StepOutput {
        let t = self.frame as f64 / self.fps;
        let pose = self.vehicle.pose;
        // 1. Render (all rows, or only those the pipeline reads: the same decisions, faster).
        let rows = if self.full_frames || (self.pipeline.has_detector() && !self.truth_boxes) {
            0..self.image.height() as usize
        } else {
            self.roi_rows.clone()
        };
        self.renderer.render_rows(&pose, t, self.frame, &mut self.image, rows);
        // 2. Truth.
        let v = &self.vehicle;
        let wb = self.cfg.vehicle.wheelbase_m;
        let mut truth = self.truth.frame(&self.track, &pose, v.speed, v.wheel_angle, wb);
        truth.objects = self.renderer.object_boxes(&pose);
        // 3. Pipeline.
        let dt = self.last_t.map_or(1.0 / self.fps, |lt| t - lt);
        self.last_t = Some(t);
        let out = if self.truth_boxes {
            self.given.clear();
            for b in &truth.objects {
                if let Some(g) = self.given_box(&pose, b, t) {
                    self.given.push(g);
                }
            }
            self.pipeline.step_with(&self.image, dt, timer, Some(&self.given))
        } else {
            self.pipeline.step(&self.image, dt, timer)
        };
        // 4. Vehicle.
        for _ in 0..self.cfg.sim.substeps {
            self.vehicle.step(out.command);
        }
        // 5. Score this frame (at the pose it was rendered from).
        self.score(&truth, &out, 1.0 / self.fps, t);
        let step = StepOutput {
            out,
            truth,
            frame: self.frame,
            time_s: t,
            transition: self.pipeline.behaviour().last_transition().cloned(),
            objects: self.pipeline.objects().to_vec(),
        };
        self.frame += 1;
        if self.end.is_none() && self.frame as f64 / self.fps >= self.cfg.sim.max_seconds {
            self.end = Some(EndReason::TimeUp);
        }
        step
    }

    /// The box a perfect detector would report for `b`: for a sign or light only its face or
    /// housing (the truth box reaches down the post to the floor).
    fn given_box(&self, pose: &Pose, b: &ObjectBox, t: f64) -> Option<GivenBox> {
        let h = self.cfg.camera.height as f64 - 1.0;
        let ob = &self.track.track.objects.iter().find(|o| o.0.index == b.index)?.0;
        let mount = self.renderer.mount();
        let (class, bottom_z) = match b.kind {
            ObjectKind::StopSign => (ObjectClass::StopSign, ob.height - ob.size[0] / 2.0),
            ObjectKind::TrafficLight => (ObjectClass::TrafficLight, ob.height - ob.size[0] / 2.0),
            ObjectKind::Obstacle => (ObjectClass::Obstacle, 0.0),
        };
        let mut bbox = b.bbox;
        if b.kind != ObjectKind::Obstacle {
            let (_, v) = mount.project_world(pose, [ob.pos[0], ob.pos[1], bottom_z])?;
            bbox[3] = v;
        }
        if bbox[3] >= h || bbox[3] <= bbox[1] {
            return None;
        }
        let light = (b.kind == ObjectKind::TrafficLight).then(|| match ob.light_state(t) {
            TrackLight::Red => LightColor::Red,
            TrackLight::Amber => LightColor::Amber,
            TrackLight::Green => LightColor::Green,
        });
        Some(GivenBox { class, bbox, light })
    }

    fn score(&mut self, truth: &FrameTruth, out: &FrameOutput, dt: f64, t: f64) {
        let track = &self.track.track;
        let e = truth.offset_m;
        // Wheels: rebuild them for the rendered pose.
        let half = track.half_lane();
        let vcfg = &self.cfg.vehicle;
        let pose = Pose {
            x: truth.pose[0],
            y: truth.pose[1],
            yaw: truth.pose[2],
        };
        let w = vcfg.track_m / 2.0;
        // While passing an obstacle (behaviour) the car may use the other lane: then only
        // leaving the road counts, and the distance is to the nearer lane's centre.
        let passing = out.mode.is_passing();
        let lane_centre = |lat: f64| {
            if passing && (lat + track.drive_offset).abs() < (lat - track.drive_offset).abs() {
                -track.drive_offset
            } else {
                track.drive_offset
            }
        };
        let out_now = [[0.0, w], [0.0, -w], [vcfg.wheelbase_m, w], [vcfg.wheelbase_m, -w]]
            .iter()
            .any(|&p| {
                let lat = self.track.lateral(pose.to_world(p));
                (lat - lane_centre(lat)).abs() > half
            });
        let e = if passing {
            let lat = self.track.lateral(pose.to_world([vcfg.wheelbase_m / 2.0, 0.0]));
            lat - lane_centre(lat)
        } else {
            e
        };
        if out_now {
            self.time_outside += dt;
            if !self.outside {
                self.departures += 1;
                self.departures_at.push(truth.s_m);
            }
        }
        self.outside = out_now;
        self.sq_sum += e * e;
        self.xte_max = self.xte_max.max(e.abs());
        // Steering reversals: sign changes beyond a small dead band.
        let s = out.command.steer;
        if s.abs() > 0.05 {
            let sg = s.signum();
            if self.last_steer_sign != 0.0 && sg != self.last_steer_sign {
                self.reversals += 1;
            }
            self.last_steer_sign = sg;
        }
        if out.lane.error.is_none() {
            self.lost += 1;
        }
        // Progress and laps.
        let len = track.length;
        let mut ds = truth.s_m - self.last_s;
        if ds < -len / 2.0 {
            ds += len;
        } else if ds > len / 2.0 {
            ds -= len;
        }
        self.last_s = truth.s_m;
        self.progress += ds;
        let laps_done = (self.progress / len).floor().max(0.0) as usize;
        while self.lap_times.len() < laps_done {
            let t_lap = t + dt;
            self.lap_times.push(t_lap - self.last_lap_t);
            self.last_lap_t = t_lap;
        }
        // Ending conditions.
        if self.cfg.sim.laps > 0 && self.lap_times.len() as u32 >= self.cfg.sim.laps {
            self.end.get_or_insert(EndReason::LapsDone);
        }
        if e.abs() > 2.0 * half {
            self.end.get_or_insert(EndReason::LeftTheRoad);
        }
        // Standing at a stop sign, a red light or an obstacle is the behaviour's choice.
        if self.vehicle.speed.abs() < 0.005 && t > 1.0 && !out.mode.is_waiting() {
            self.still_s += dt;
            if self.still_s >= 5.0 {
                self.end.get_or_insert(EndReason::Stalled);
            }
        } else {
            self.still_s = 0.0;
        }
    }

    /// Steps until the run ends, handing every step to `each`.
    pub fn run<E>(
        &mut self,
        timer: &mut dyn StageTimer,
        mut each: impl FnMut(&Simulation, &StepOutput) -> Result<(), E>,
    ) -> Result<Summary, E> {
        while self.end.is_none() {
            let s = self.step(timer);
            each(self, &s)?;
        }
        Ok(self.summary())
    }

    /// The score so far.
    pub fn summary(&self) -> Summary {
        let n = self.frame.max(1) as f64;
        let seconds = self.frame as f64 / self.fps;
        Summary {
            track: self.track.track.name.clone(),
            frames: self.frame,
            seconds,
            laps: self.lap_times.len() as u32,
            lap_times_s: self.lap_times.clone(),
            xte_rms_m: (self.sq_sum / n).sqrt(),
            xte_max_m: self.xte_max,
            lane_departures: self.departures,
            departures_at_m: self.departures_at.clone(),
            time_outside_s: self.time_outside,
            steer_reversals_per_s: self.reversals as f64 / seconds.max(1e-9),
            lane_lost_frames: self.lost,
            lane_width_m: self.track.track.spec.road.lane_width_m,
            end: self.end.unwrap_or(EndReason::TimeUp),
        }
    }
}
