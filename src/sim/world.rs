//! The simulated world, split the way the car is: a **camera** ([`super::camera::SimCamera`], a
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
use super::track::LightState as TrackLight;
use super::truth::{FrameTruth, TruthModel};
use super::vehicle::{Pose, Vehicle};
use crate::camera::PinholeCamera;
use crate::classes::SimShape;
use crate::config::Config;
use crate::control::behaviour::LightColor;
use crate::control::Command;
use crate::drive::{Arming, Flow, FrameContext, LoopError, Observer};
use crate::pipeline::FrameOutput;
use crate::source::GivenBox;
use crate::sink::{CommandSink, SinkError};
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
    /// obstacle; nor the operator's: disarmed, e-stopped, braked, a human at the throttle).
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
    /// On a track with junctions: every junction passed, in order, with the way taken at each
    /// fork (from the car's true position; src/sim/network.rs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub junctions: Vec<super::plan::Passage>,
    /// The track's junctions as the report names them (for [`Summary::lines`]).
    #[serde(skip)]
    pub junction_lines: Vec<String>,
}

impl Summary {
    /// The score as the terminal shows it, a line each.
    pub fn lines(&self) -> Vec<String> {
        let s = self;
        let times: Vec<String> = s.lap_times_s.iter().map(|t| format!("{t:.2}")).collect();
        vec![
            format!("sim: {} frames, {:.1} s, ended: {:?}", s.frames, s.seconds, s.end),
            format!("  laps completed:   {} (lap times s: [{}])", s.laps, times.join(", ")),
            format!(
                "  cross-track error: RMS {:.4} m ({:.1}% of the {:.2} m lane), max {:.4} m",
                s.xte_rms_m,
                100.0 * s.xte_rms_m / s.lane_width_m,
                s.lane_width_m,
                s.xte_max_m
            ),
            format!(
                "  lane departures:  {} ({:.2} s with a wheel outside)",
                s.lane_departures, s.time_outside_s
            ),
            format!(
                "  steering reversals {:.2}/s, lane lost in {} frames",
                s.steer_reversals_per_s, s.lane_lost_frames
            ),
        ]
        .into_iter()
        .chain((!s.junction_lines.is_empty()).then(|| "  route driven:".to_string()))
        .chain(s.junction_lines.iter().map(|l| format!("    {l}")))
        .collect()
    }
}

/// The camera rows the pipeline's bird's-eye warp reads (its ROI, bilinear taps, and the
/// blur's reach).
pub fn roi_rows(cfg: &Config) -> Range<usize> {
    // Through a lens the map reads the bent ROI: its outline, sampled along each edge.
    let lens = cfg.camera_lens().ok().flatten();
    let src = &cfg.warp.src;
    let ys: Vec<f64> = match &lens {
        None => src.iter().map(|p| p[1]).collect(),
        Some(l) => (0..4)
            .flat_map(|k| {
                let (a, b) = (src[k], src[(k + 1) % 4]);
                (0..=32).map(move |i| {
                    let t = i as f64 / 32.0;
                    l.distort_pixel(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])).1
                })
            })
            .collect(),
    };
    let ys = ys.iter().copied();
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
    /// Junctions passed (tracks with junctions only).
    passages: super::plan::PassageLog,
}

/// The simulated world: track and objects, the car, its camera's renderer, the truth model and
/// the score. Shared by the camera, the vehicle and the score through [`SharedWorld`].
pub struct World {
    cfg: Config,
    scene: Arc<Scene>,
    renderer: Renderer,
    /// The camera's lens (`sim.lens_distortion`) and the ideal image it bends, if any.
    lens: Option<(super::lens::LensWarp, RgbImage)>,
    truth: TruthModel,
    vehicle: Vehicle,
    /// Simulated time of the vehicle, seconds.
    t_s: f64,
    fps: f64,
    sc: Score,
    last_truth: Option<FrameTruth>,
    /// The drift added to the steering the car obeys (`sim.steer_noise`).
    steer_noise: SteerNoise,
}

/// Time constant of the steering noise's drift (`sim.steer_noise`), seconds.
pub const STEER_NOISE_TAU_S: f64 = 0.4;

/// A first-order Gauss-Markov drift on the steering command (`sim.steer_noise`): per frame
/// `n ← a·n + σ·√(1−a²)·ξ`, `a = exp(−dt/τ)`, ξ standard normal (Box–Muller on the seeded
/// SplitMix64), so its standard deviation is σ at any frame rate. σ = 0: the command passes
/// untouched and no random number is drawn.
#[derive(Debug, Clone)]
struct SteerNoise {
    sigma: f64,
    a: f64,
    value: f64,
    rng: super::rng::SplitMix64,
}

impl SteerNoise {
    fn new(sigma: f64, fps: f64, seed: i64) -> Self {
        Self {
            sigma,
            a: (-1.0 / (fps * STEER_NOISE_TAU_S)).exp(),
            value: 0.0,
            rng: super::rng::SplitMix64::new(super::rng::mix(seed as u64 ^ 0x5EE7_0015E)),
        }
    }

    /// The command the car obeys this frame.
    fn apply(&mut self, cmd: Command) -> Command {
        if self.sigma <= 0.0 {
            return cmd;
        }
        let (u1, u2) = (self.rng.next_f64().max(1e-300), self.rng.next_f64());
        let xi = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        self.value = self.a * self.value + self.sigma * (1.0 - self.a * self.a).sqrt() * xi;
        Command {
            steer: (cmd.steer + self.value).clamp(-1.0, 1.0),
            ..cmd
        }
    }
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
            lens: super::lens::LensWarp::main_camera(cfg).map(|l| (l, RgbImage::new(0, 0))),
            truth,
            vehicle,
            t_s: 0.0,
            fps: cfg.camera.fps,
            sc: Score::default(),
            last_truth: None,
            steer_noise: SteerNoise::new(cfg.sim.steer_noise, cfg.camera.fps, cfg.sim.seed),
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
    /// with blur, one range from the first span to the last); through the lens of
    /// `sim.lens_distortion` when it has one ([`super::lens::render_through`]).
    pub fn render_spans(&mut self, frame: u64, t_s: f64, img: &mut RgbImage, spans: &[Range<usize>]) -> FrameTruth {
        let pose = self.vehicle.pose;
        let blur = self.cfg.sim.blur_px;
        super::lens::render_through(&mut self.renderer, self.lens.as_mut(), &pose, t_s, frame, img, spans, blur);
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
        truth
            .objects
            .iter()
            .filter_map(|b| self.given_box(&pose, b, t_s))
            .collect()
    }

    /// One frame period under `cmd` (`substeps` fixed steps): the lock-step vehicle.
    /// With `sim.steer_noise` the car obeys the command plus the noise's drift.
    pub fn step_frame(&mut self, cmd: Command) {
        let cmd = self.steer_noise.apply(cmd);
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
        self.score_held(out, dt, time_s, false)
    }

    /// [`World::score`] for a frame on which the car was held still on purpose (`held`:
    /// disarmed, e-stopped, braking, or a human holding the throttle): standing then is not
    /// a stall.
    pub fn score_held(&mut self, out: &FrameOutput, dt: f64, time_s: f64, held: bool) {
        let Some(truth) = self.last_truth.clone() else {
            return;
        };
        self.score_frame(&truth, out, dt, time_s, held);
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
            junctions: self.sc.passages.passages.clone(),
            junction_lines: super::plan::passage_lines(&self.scene.track, &self.sc.passages.passages),
        }
    }

    /// The box a perfect detector would report for `b`: for a sign or light only its face or
    /// housing (the truth box reaches down the post to the floor).
    fn given_box(&self, pose: &Pose, b: &ObjectBox, t: f64) -> Option<GivenBox> {
        let h = self.cfg.camera.height as f64 - 1.0;
        let ob = &self.scene.track.objects.iter().find(|o| o.0.index == b.index)?.0;
        let mount = self.renderer.mount();
        let class = b.kind;
        let on_post = class.info().shape != SimShape::Box;
        let bottom_z = if on_post {
            ob.height - Scene::face_half_height(ob)
        } else {
            0.0
        };
        let mut bbox = b.bbox;
        if on_post {
            let (_, v) = mount.project_world(pose, [ob.pos[0], ob.pos[1], bottom_z])?;
            bbox[3] = v;
        }
        if bbox[3] >= h || bbox[3] <= bbox[1] {
            return None;
        }
        let light = class.info().reads_light.then(|| match ob.light_state(t) {
            TrackLight::Red => LightColor::Red,
            TrackLight::Amber => LightColor::Amber,
            TrackLight::Green => LightColor::Green,
        });
        Some(GivenBox {
            class,
            bbox,
            light,
            arrow: ob.arrow,
        })
    }

    fn score_frame(&mut self, truth: &FrameTruth, out: &FrameOutput, dt: f64, t: f64, held: bool) {
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
        // Progress and laps; with junctions, laps are passes of the main road's start line.
        let len = track.length;
        if !track.junctions.is_empty() {
            let c = pose.to_world([vcfg.wheelbase_m / 2.0, 0.0]);
            let lap = self.sc.passages.update(track, c, self.vehicle.speed * dt);
            if lap {
                let t_lap = t + dt;
                self.sc.lap_times.push(t_lap - self.sc.last_lap_t);
                self.sc.last_lap_t = t_lap;
            }
        }
        let mut ds = truth.s_m - self.sc.last_s;
        if ds < -len / 2.0 {
            ds += len;
        } else if ds > len / 2.0 {
            ds -= len;
        }
        self.sc.last_s = truth.s_m;
        self.sc.progress += ds;
        let laps_done = (self.sc.progress / len).floor().max(0.0) as usize;
        while track.junctions.is_empty() && self.sc.lap_times.len() < laps_done {
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
        // Standing at a stop sign, a red light or an obstacle is the behaviour's choice;
        // standing disarmed, e-stopped, braked or held by a human is the operator's.
        if self.vehicle.speed.abs() < 0.005 && t > 1.0 && !out.mode.is_waiting() && !held {
            self.sc.still_s += dt;
            if self.sc.still_s >= 5.0 {
                self.sc.end.get_or_insert(EndReason::Stalled);
            }
        } else {
            self.sc.still_s = 0.0;
        }
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
    fn send(&mut self, cmd: Command, _now_s: f64) -> Result<Command, SinkError> {
        lock(&self.world).step_frame(cmd);
        Ok(cmd)
    }

    /// Neutral without moving time on: the lock-step car only moves when a frame's command
    /// arrives.
    fn stop(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

/// Nothing to arm: the simulated car moves whenever a command arrives.
impl crate::sink::Actuators for SimVehicle {}

/// The score of a run, as an observer of the loop: it ends the run when the world says so.
pub struct SimScore {
    world: SharedWorld,
    ends_run: bool,
    /// The run's arming: a car held on purpose (disarmed, e-stopped, braked, a human at the
    /// throttle) is not stalled.
    arming: Option<Arc<Arming>>,
}

impl SimScore {
    /// Scores `world`.
    pub fn new(world: SharedWorld) -> SimScore {
        SimScore {
            world,
            ends_run: true,
            arming: None,
        }
    }

    /// Reads `arming` each frame: standing still while it holds the car is not a stall.
    pub fn held_by(mut self, arming: Arc<Arming>) -> Self {
        self.arming = Some(arming);
        self
    }

    /// Whether the car is held still on purpose now.
    fn held(&self) -> bool {
        self.arming.as_ref().is_some_and(|a| {
            !a.is_armed() || a.is_braking() || a.controls().mode() != crate::drive::DriveMode::Autopilot
        })
    }

    /// `false`: score but never end the loop (the caller checks [`World::ended`]).
    pub fn ending_the_run(mut self, on: bool) -> Self {
        self.ends_run = on;
        self
    }
}

impl Observer for SimScore {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let held = self.held();
        let mut w = lock(&self.world);
        let dt = 1.0 / w.fps;
        w.score_held(ctx.output, dt, ctx.frame.time_s, held);
        Ok(if self.ends_run && w.ended().is_some() {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }
}
