//! The simulated world, split the way the car is: a **camera** ([`SimCamera`], a
//! [`FrameSource`] rendering what the car's camera sees) and a **vehicle** ([`SimVehicle`], a
//! [`CommandSink`] moving the car), over one shared [`World`]; the **score** ([`SimScore`], an
//! [`Observer`]) watches the run. The loop between them is the car's own
//! ([`crate::drive::Driver`]): nothing below it knows it is simulated.
//!
//! One frame k (lock-step, `t_k = k / fps`, so a recorded run replays with bit-identical
//! time steps):
//! 1. the camera renders the frame from the car's pose and computes its ground truth;
//! 2. the loop runs the pipeline on it (dt from the frames' times);
//! 3. the vehicle executes the command for one frame period (`substeps` fixed steps);
//! 4. the score: cross-track error of the car's centre, lane departures (a wheel's centre
//!    beyond a line's centre), progress along the track and laps.
//!
//! On the wall clock (the firmware in the loop, `rccar drive --camera sim`) the same world is
//! advanced by [`World::advance`] with whatever the actuators do (e.g. the firmware's PWM
//! widths), and rendered by [`World::render`] when the camera is due.
//!
//! The run ends when the laps are done, at `max_seconds`, or early when the car has left the
//! road (more than a lane width off) or stood still for 5 s after starting.
//!
//! Units: metres, seconds, radians.

use super::render::ObjectBox;
use super::render::{CameraMount, RenderOptions, Renderer};
use super::scene::Scene;
use super::track::{LightState as TrackLight, ObjectKind};
use super::truth::{FrameTruth, TruthModel};
use super::vehicle::{Pose, Vehicle};
use crate::camera::PinholeCamera;
use crate::config::Config;
use crate::control::behaviour::LightColor;
use crate::control::Command;
use crate::drive::{Flow, FrameContext, LoopError, Observer};
use crate::pipeline::{FrameOutput, GivenBox, RowPlan};
use crate::ranging::ObjectClass;
use crate::sink::{CommandSink, SinkError};
use crate::source::{Frame, FrameError, FrameSource};
use image::RgbImage;
use serde::Serialize;
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};

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
    /// Stopped from outside (Ctrl-C, SIGTERM, a test) before any other ending.
    Interrupted,
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

/// The camera rows the pipeline's bird's-eye warp reads (its ROI, bilinear taps, and the
/// blur's reach).
pub fn roi_rows(cfg: &Config) -> Range<usize> {
    let ys = cfg.warp.src.iter().map(|p| p[1]);
    let lo = ys.clone().fold(f64::INFINITY, f64::min);
    let hi = ys.fold(f64::NEG_INFINITY, f64::max);
    let blur = (3.0 * cfg.sim.blur_px).ceil() + 2.0;
    let h = cfg.camera.height as f64;
    let a = (lo.floor() - blur).clamp(0.0, h) as usize;
    let b = (hi.ceil() + blur + 1.0).clamp(0.0, h) as usize;
    a..b
}

/// Running totals of the score.
#[derive(Debug, Clone, Default)]
struct Score {
    frames: u64,
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

/// The simulated world: track and objects, the car, its camera's renderer, the truth model and
/// the score. Shared by the camera, the vehicle and the score through [`SharedWorld`].
pub struct World {
    cfg: Config,
    scene: Arc<Scene>,
    renderer: Renderer,
    truth: TruthModel,
    vehicle: Vehicle,
    /// Simulated time of the vehicle, seconds.
    t_s: f64,
    fps: f64,
    sc: Score,
    last_truth: Option<FrameTruth>,
}

/// The world behind a lock, shared by its camera, vehicle and score (and a dashboard).
pub type SharedWorld = Arc<Mutex<World>>;

/// Locks a shared world (a panic elsewhere must not hide the world from the shutdown path).
pub fn lock(w: &SharedWorld) -> MutexGuard<'_, World> {
    w.lock().unwrap_or_else(|e| e.into_inner())
}

impl World {
    /// A car at rest at the start of the scene's track, centred in its lane, under `cfg`.
    pub fn new(cfg: &Config, scene: Arc<Scene>) -> Result<World, crate::lane::warp::WarpError> {
        let mount = CameraMount {
            camera: PinholeCamera::from(&cfg.camera),
            x_m: cfg.vehicle.camera_x_m,
        };
        let renderer = Renderer::new(scene.clone(), mount, RenderOptions::from_config(&cfg.sim));
        let truth = TruthModel::new(cfg, mount)?;
        let dt = 1.0 / (cfg.camera.fps * cfg.sim.substeps as f64);
        let vehicle = Vehicle::new(
            &cfg.vehicle,
            Pose {
                x: 0.0,
                y: 0.0,
                yaw: 0.0,
            },
            dt,
        );
        let mut w = World {
            cfg: cfg.clone(),
            scene,
            renderer,
            truth,
            vehicle,
            t_s: 0.0,
            fps: cfg.camera.fps,
            sc: Score::default(),
            last_truth: None,
        };
        w.place_at(0.0);
        Ok(w)
    }

    /// This world behind a lock, to hand to its camera, vehicle and score.
    pub fn shared(self) -> SharedWorld {
        Arc::new(Mutex::new(self))
    }

    /// Puts the car, at rest, on the lane centre at `s` metres along the track; laps are then
    /// counted from there. (Also the dashboard's "move the car here" and "reset".)
    pub fn place_at(&mut self, s: f64) {
        let track = &self.scene.track;
        let (p, yaw) = track.lane_pose_at(s);
        // Rear axle on the lane centre, half a wheelbase behind `s`, so the car's centre is on it.
        let half = self.cfg.vehicle.wheelbase_m / 2.0;
        let pose = Pose {
            x: p[0] - half * yaw.cos(),
            y: p[1] - half * yaw.sin(),
            yaw,
        };
        let dt = 1.0 / (self.cfg.camera.fps * self.cfg.sim.substeps as f64);
        self.vehicle = Vehicle::new(&self.cfg.vehicle, pose, dt);
        self.sc.last_s = TruthModel::lane_pose(track, &pose, self.cfg.vehicle.wheelbase_m).2;
    }

    /// Moves the car sideways by `dy` metres (positive = left) and turns it by `dyaw` radians,
    /// keeping its speed: a kick for step-response experiments.
    pub fn kick(&mut self, dy: f64, dyaw: f64) {
        let p = &mut self.vehicle.pose;
        p.x -= dy * p.yaw.sin();
        p.y += dy * p.yaw.cos();
        p.yaw += dyaw;
    }

    /// The car.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The scene (track and objects).
    pub fn scene(&self) -> &Arc<Scene> {
        &self.scene
    }

    /// The camera's renderer (for extra views: a stereo pair, object crops).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The configuration the world was built with.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Simulated time of the vehicle, seconds.
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// The truth of the last rendered frame.
    pub fn last_truth(&self) -> Option<&FrameTruth> {
        self.last_truth.as_ref()
    }

    /// Why the run has ended, once it has.
    pub fn ended(&self) -> Option<EndReason> {
        self.sc.end
    }

    /// Ends the run from outside (an interrupted run still gets its summary).
    pub fn interrupt(&mut self) {
        self.sc.end.get_or_insert(EndReason::Interrupted);
    }

    /// Renders frame `frame` at time `t_s` into `img` (only `rows` when given: the rest keeps
    /// what it had) and returns its ground truth, which is also kept as [`World::last_truth`].
    pub fn render(&mut self, frame: u64, t_s: f64, img: &mut RgbImage, rows: Option<Range<usize>>) -> FrameTruth {
        let rows = rows.unwrap_or(0..img.height() as usize);
        self.render_spans(frame, t_s, img, std::slice::from_ref(&rows))
    }

    /// Like [`World::render`] with several row ranges (sorted, disjoint), each widened by the
    /// blur's reach (`3·sim.blur_px`, so every row in `spans` comes out as in a full frame;
    /// with blur, one range from the first span to the last).
    pub fn render_spans(&mut self, frame: u64, t_s: f64, img: &mut RgbImage, spans: &[Range<usize>]) -> FrameTruth {
        let pose = self.vehicle.pose;
        let reach = if self.cfg.sim.blur_px > 0.0 {
            (3.0 * self.cfg.sim.blur_px).ceil() as usize + 1
        } else {
            0
        };
        let mut merged: Vec<Range<usize>> = Vec::with_capacity(spans.len());
        for r in spans.iter().filter(|r| !r.is_empty()) {
            let r = r.start.saturating_sub(reach)..r.end + reach;
            match merged.last_mut() {
                Some(m) if r.start <= m.end => m.end = m.end.max(r.end),
                _ => merged.push(r),
            }
        }
        if reach > 0 && merged.len() > 1 {
            // The blur runs over the whole image on each call: one call for every span.
            let all = merged[0].start..merged[merged.len() - 1].end;
            merged = vec![all];
        }
        for m in merged {
            self.renderer.render_rows(&pose, t_s, frame, img, m);
        }
        let v = &self.vehicle;
        let wb = self.cfg.vehicle.wheelbase_m;
        let mut truth = self.truth.frame(&self.scene, &pose, v.speed, v.wheel_angle, wb);
        truth.objects = self.renderer.object_boxes(&pose);
        self.last_truth = Some(truth.clone());
        truth
    }

    /// The boxes a perfect detector would report for the objects of `truth` at time `t_s`.
    pub fn given_boxes(&self, truth: &FrameTruth, t_s: f64) -> Vec<GivenBox> {
        let pose = Pose {
            x: truth.pose[0],
            y: truth.pose[1],
            yaw: truth.pose[2],
        };
        truth.objects.iter().filter_map(|b| self.given_box(&pose, b, t_s)).collect()
    }

    /// One frame period under `cmd` (`substeps` fixed steps): the lock-step vehicle.
    pub fn step_frame(&mut self, cmd: Command) {
        for _ in 0..self.cfg.sim.substeps {
            self.vehicle.step(cmd);
        }
        self.t_s += 1.0 / self.fps;
    }

    /// Advances the car by `dt_s` seconds of wall-clock time under `cmd` (the firmware-in-the-
    /// loop world: `cmd` is what the servo and ESC pulses say). Whole fixed steps only; the
    /// remainder is carried to the next call, so the physics is the lock-step physics.
    pub fn advance(&mut self, dt_s: f64, cmd: Command, carry: &mut f64) {
        let step = 1.0 / (self.cfg.camera.fps * self.cfg.sim.substeps as f64);
        *carry += dt_s.max(0.0);
        while *carry >= step {
            self.vehicle.step(cmd);
            *carry -= step;
            self.t_s += step;
        }
    }

    /// Scores one processed frame (at the pose it was rendered from) and checks the endings.
    /// `time_s` is the frame's time; `dt` its period.
    pub fn score(&mut self, out: &FrameOutput, dt: f64, time_s: f64) {
        let Some(truth) = self.last_truth.clone() else {
            return;
        };
        self.score_frame(&truth, out, dt, time_s);
        self.sc.frames += 1;
        if self.sc.end.is_none() && self.sc.frames as f64 / self.fps >= self.cfg.sim.max_seconds {
            self.sc.end = Some(EndReason::TimeUp);
        }
    }

    /// The score so far.
    pub fn summary(&self) -> Summary {
        let frames = self.sc.frames;
        let n = frames.max(1) as f64;
        let seconds = frames as f64 / self.fps;
        Summary {
            track: self.scene.track.name.clone(),
            frames,
            seconds,
            laps: self.sc.lap_times.len() as u32,
            lap_times_s: self.sc.lap_times.clone(),
            xte_rms_m: (self.sc.sq_sum / n).sqrt(),
            xte_max_m: self.sc.xte_max,
            lane_departures: self.sc.departures,
            departures_at_m: self.sc.departures_at.clone(),
            time_outside_s: self.sc.time_outside,
            steer_reversals_per_s: self.sc.reversals as f64 / seconds.max(1e-9),
            lane_lost_frames: self.sc.lost,
            lane_width_m: self.scene.track.spec.road.lane_width_m,
            end: self.sc.end.unwrap_or(EndReason::TimeUp),
        }
    }

    /// The box a perfect detector would report for `b`: for a sign or light only its face or
    /// housing (the truth box reaches down the post to the floor).
    fn given_box(&self, pose: &Pose, b: &ObjectBox, t: f64) -> Option<GivenBox> {
        let h = self.cfg.camera.height as f64 - 1.0;
        let ob = &self.scene.track.objects.iter().find(|o| o.0.index == b.index)?.0;
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

    fn score_frame(&mut self, truth: &FrameTruth, out: &FrameOutput, dt: f64, t: f64) {
        let track = &self.scene.track;
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
                let lat = self.scene.lateral(pose.to_world(p));
                (lat - lane_centre(lat)).abs() > half
            });
        let e = if passing {
            let lat = self.scene.lateral(pose.to_world([vcfg.wheelbase_m / 2.0, 0.0]));
            lat - lane_centre(lat)
        } else {
            e
        };
        if out_now {
            self.sc.time_outside += dt;
            if !self.sc.outside {
                self.sc.departures += 1;
                self.sc.departures_at.push(truth.s_m);
            }
        }
        self.sc.outside = out_now;
        self.sc.sq_sum += e * e;
        self.sc.xte_max = self.sc.xte_max.max(e.abs());
        // Steering reversals: sign changes beyond a small dead band.
        let s = out.command.steer;
        if s.abs() > 0.05 {
            let sg = s.signum();
            if self.sc.last_steer_sign != 0.0 && sg != self.sc.last_steer_sign {
                self.sc.reversals += 1;
            }
            self.sc.last_steer_sign = sg;
        }
        if out.lane.error.is_none() {
            self.sc.lost += 1;
        }
        // Progress and laps.
        let len = track.length;
        let mut ds = truth.s_m - self.sc.last_s;
        if ds < -len / 2.0 {
            ds += len;
        } else if ds > len / 2.0 {
            ds -= len;
        }
        self.sc.last_s = truth.s_m;
        self.sc.progress += ds;
        let laps_done = (self.sc.progress / len).floor().max(0.0) as usize;
        while self.sc.lap_times.len() < laps_done {
            let t_lap = t + dt;
            self.sc.lap_times.push(t_lap - self.sc.last_lap_t);
            self.sc.last_lap_t = t_lap;
        }
        // Ending conditions.
        if self.cfg.sim.laps > 0 && self.sc.lap_times.len() as u32 >= self.cfg.sim.laps {
            self.sc.end.get_or_insert(EndReason::LapsDone);
        }
        if e.abs() > 2.0 * half {
            self.sc.end.get_or_insert(EndReason::LeftTheRoad);
        }
        // Standing at a stop sign, a red light or an obstacle is the behaviour's choice.
        if self.vehicle.speed.abs() < 0.005 && t > 1.0 && !out.mode.is_waiting() {
            self.sc.still_s += dt;
            if self.sc.still_s >= 5.0 {
                self.sc.end.get_or_insert(EndReason::Stalled);
            }
        } else {
            self.sc.still_s = 0.0;
        }
    }

}

/// The simulated car's camera, lock-step: frame k at `k / fps`, rendered from the car's pose.
pub struct SimCamera {
    world: SharedWorld,
    image: RgbImage,
    frame: u64,
    fps: f64,
    /// Rows to render: `None` = all (recording, viewing, detection).
    rows: Option<Range<usize>>,
    /// Rows to render per frame, from the pipeline (overrides `rows`), and the camera frame
    /// at which the plan was made.
    plan: Option<(RowPlan, u64)>,
    truth_boxes: bool,
    end_with_world: bool,
    /// A stereo pair's other camera and its image (src/sim/stereo.rs `other_camera`).
    other: Option<(super::stereo::OtherCamera, RgbImage)>,
}

impl SimCamera {
    /// The camera of `world`.
    pub fn new(world: SharedWorld) -> SimCamera {
        let (w, h, fps) = {
            let g = lock(&world);
            (g.cfg.camera.width, g.cfg.camera.height, g.fps)
        };
        SimCamera {
            world,
            image: RgbImage::new(w, h),
            frame: 0,
            fps,
            rows: None,
            plan: None,
            truth_boxes: false,
            end_with_world: true,
            other: None,
        }
    }

    /// A second camera (`sim::stereo::other_camera`): each frame then carries its view of
    /// the same moment in [`Frame::other`] (rendered over the same rows as the reference),
    /// for stereo ranging in the drive loop. `None`: one camera (the default).
    pub fn set_other(&mut self, other: Option<super::stereo::OtherCamera>) {
        self.other = other.map(|r| {
            let (w, h) = (self.image.width(), self.image.height());
            (r, RgbImage::new(w, h))
        });
    }

    /// `false`: keep rendering after the world's run has ended (a caller stepping frame by
    /// frame decides when to stop). Default `true`: the source ends with the run.
    pub fn ending_with_world(mut self, on: bool) -> Self {
        self.end_with_world = on;
        self
    }

    /// Renders only `rows` (the rows the pipeline reads, see [`roi_rows`]) or every row
    /// (`None`, the default). The pipeline decides exactly as on full frames when it reads
    /// nothing else.
    pub fn set_rows(&mut self, rows: Option<Range<usize>>) {
        self.rows = rows;
        self.plan = None;
    }

    /// Renders, frame by frame, only the rows the pipeline reads on that frame
    /// ([`crate::pipeline::Pipeline::row_plan`], made just before the pipeline's next step,
    /// which gets this camera's next frame): the lane's rows, plus the detection rows on
    /// frames where detection runs. The pipeline decides exactly as on full frames. `None`:
    /// back to [`SimCamera::set_rows`]'s all rows.
    pub fn set_row_plan(&mut self, plan: Option<RowPlan>) {
        self.rows = None;
        self.plan = plan.map(|p| (p, self.frame));
    }

    /// `true`: each frame carries the objects' true image boxes (a sign's face, a light's
    /// housing, an obstacle's box; bottom-clipped boxes left out) with the true light colour,
    /// for the pipeline to use instead of its detector's.
    pub fn set_truth_boxes(&mut self, on: bool) {
        self.truth_boxes = on;
    }

    /// The last rendered image.
    pub fn image(&self) -> &RgbImage {
        &self.image
    }
}

impl FrameSource for SimCamera {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let mut w = lock(&self.world);
        if self.end_with_world && w.ended().is_some() {
            return None;
        }
        let t = self.frame as f64 / self.fps;
        let truth = match &self.plan {
            Some((plan, base)) => w.render_spans(self.frame, t, &mut self.image, plan.rows(self.frame - base)),
            None => w.render(self.frame, t, &mut self.image, self.rows.clone()),
        };
        let given = self.truth_boxes.then(|| w.given_boxes(&truth, t));
        let other = match &mut self.other {
            Some((r, img)) => {
                let spans = match &self.plan {
                    Some((plan, base)) => plan.rows(self.frame - base).to_vec(),
                    None => vec![self.rows.clone().unwrap_or(0..img.height() as usize)],
                };
                let pose = w.vehicle.pose;
                super::stereo::render_spans(r, &pose, t, self.frame, img, &spans, w.cfg.sim.blur_px);
                Some(img.clone())
            }
            None => None,
        };
        drop(w);
        let mut f = Frame::new(
            self.frame,
            t,
            format!("frame_{:06}.png", self.frame),
            self.image.clone(),
        );
        f.truth = serde_json::to_value(&truth).ok();
        f.given = given;
        f.other = other.map(|image| crate::source::OtherView {
            image,
            name: f.name.clone(),
            skew_s: 0.0,
            pairs_dropped: 0,
        });
        self.frame += 1;
        Some(Ok(f))
    }
}

/// The simulated car's actuators, lock-step: each command drives the car for one frame period.
pub struct SimVehicle {
    world: SharedWorld,
}

impl SimVehicle {
    /// The vehicle of `world`.
    pub fn new(world: SharedWorld) -> SimVehicle {
        SimVehicle { world }
    }
}

impl CommandSink for SimVehicle {
    fn send(&mut self, cmd: Command, _now_s: f64) -> Result<(), SinkError> {
        lock(&self.world).step_frame(cmd);
        Ok(())
    }

    /// Neutral without moving time on: the lock-step car only moves when a frame's command
    /// arrives.
    fn stop(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

/// The score of a run, as an observer of the loop: it ends the run when the world says so.
pub struct SimScore {
    world: SharedWorld,
    ends_run: bool,
}

impl SimScore {
    /// Scores `world`.
    pub fn new(world: SharedWorld) -> SimScore {
        SimScore { world, ends_run: true }
    }

    /// `false`: score but never end the loop (the caller checks [`World::ended`]).
    pub fn ending_the_run(mut self, on: bool) -> Self {
        self.ends_run = on;
        self
    }
}

impl Observer for SimScore {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let mut w = lock(&self.world);
        let dt = 1.0 / w.fps;
        w.score(ctx.output, dt, ctx.frame.time_s);
        Ok(if self.ends_run && w.ended().is_some() {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }
}
