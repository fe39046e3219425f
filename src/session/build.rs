//! Building a [`Session`]: checks first, then the pipeline, the world, the source, the sink
//! behind the gate, the GPIO, the recording, and the telemetry file last (a run that cannot
//! start leaves no file behind).

use super::observers::{CameraHealth, CarState, Pacer, StatusLine};
use super::spec::*;
use super::{Own, Session, SessionError};
use crate::config::{Config, RangingMethod, StereoReference};
use crate::control::Command;
use crate::drive::{Actor, Arming, Driver, Gate, GateOptions};
use crate::health::{Health, Part, PartState};
use crate::pipeline::Pipeline;
use crate::record::observer::RecordObserver;
use crate::record::Recorder;
use crate::sim::camera::{ActuatorState, SimCamera};
use crate::sim::scene::Scene;
use crate::sim::track::Track;
use crate::sim::world::{lock, SharedWorld, SimScore, SimVehicle, World};
use crate::sink::{Actuators, NullSink};
use crate::source::{FrameSource, Paced, ReplayDir};
use crate::telemetry::JsonlWriter;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

fn invalid(s: impl Into<String>) -> SessionError {
    SessionError::Invalid(s.into())
}

/// The session's pieces while it is being built.
struct Parts {
    notes: Vec<(Level, String)>,
    world: Option<SharedWorld>,
    actuators: ActuatorState,
    stereo_pair: bool,
}

pub(super) fn build(cfg: &Config, spec: SessionSpec, env: SessionEnv) -> Result<Session, SessionError> {
    check(cfg, &spec)?;
    let health = Health::new();
    health.set(Part::Camera, PartState::Waiting, "no frame yet");
    let arming = Arming::new(health.clone());
    // Driving by hand: how long an input holds, the human's throttle ceiling.
    arming
        .controls()
        .configure(cfg.manual.input_timeout_ms as f64 / 1e3, cfg.manual.max_throttle);
    let mut parts = Parts {
        notes: Vec::new(),
        world: None,
        actuators: Arc::new(Mutex::new(Command::NEUTRAL)),
        stereo_pair: is_pair(cfg, &spec),
    };
    // 1. The pipeline (and its detector).
    let mut pipeline = Pipeline::new(cfg)?;
    setup_pipeline(cfg, &spec, &mut pipeline, &mut parts)?;
    // 2. The frame source (the simulated world first).
    let source = open_source(cfg, &spec, &env, &pipeline, &mut parts)?;
    // A camera's end is a fault; a folder's, or a replayed pipe's, is not.
    let device = match &spec.source {
        SourceSpec::Cameras { left: CameraSpec::V4l(_), .. } => true,
        SourceSpec::Cameras { left, timing, .. } => left.is_device() && *timing == Timing::WallClock,
        SourceSpec::Sim { .. } => false,
    };
    // 3. The sink behind the one gate.
    let (actuators, link, pwm) = open_sink(cfg, &spec, &env, &mut parts)?;
    if matches!(spec.sink, SinkSpec::Link { .. }) {
        health.set(Part::Link, PartState::Ok, "");
    }
    #[cfg(not(feature = "serial"))]
    let _ = &link;
    // Armed from the start is the state the run begins in, not an event of it.
    if spec.arm == ArmAt::Start {
        arming.arm(Actor::Program).map_err(|e| invalid(e.to_string()))?;
    }
    let gate = Gate::new(
        actuators,
        GateOptions {
            arming: arming.clone(),
            stop: env.stop.clone(),
            clock: env.clock.clone(),
            give_up_s: spec.link_give_up_s,
        },
    );
    // 4. GPIO, recording, and last the telemetry file.
    let gpio = open_gpio(cfg, &arming)?;
    let recorder = open_recorder(cfg, &spec)?.map(|r| r.switched_by(arming.clone()));
    let telemetry = open_telemetry(&spec)?;
    // 5. Arming on the flag (an operator arms otherwise).
    if spec.arm == ArmAt::Flag {
        arming.arm(Actor::Flag).map_err(|e| invalid(e.to_string()))?;
    }
    let wall = is_wall_clock(&spec);
    let own = Own {
        camera: CameraHealth(arming.clone()),
        gpio,
        score: parts
            .world
            .clone()
            .map(|w| SimScore::new(w).ending_the_run(!spec.operator_ends_run).held_by(arming.clone())),
        car: wall.then(|| CarState(arming.clone())),
        telemetry,
        recorder,
        status: spec.status_every_s.map(|every| StatusLine {
            every_s: every.max(0.2),
            last_print: 0.0,
            clock: env.clock.clone(),
            window: Default::default(),
            deadline: spec.seconds,
            started: env.clock.now_s(),
            stop: env.stop.clone(),
            arming: arming.clone(),
            say: env.say.clone(),
            car: wall,
        }),
        pulse: pwm.as_ref().map(|p| p.observer()),
        pacer: matches!(source_timing(&spec), Timing::RealTime).then(|| Pacer {
            clock: env.clock.clone(),
            period_s: 1.0 / cfg.camera.fps.max(1.0),
            next: None,
        }),
    };
    Ok(Session {
        cfg: cfg.clone(),
        source,
        pipeline,
        gate,
        arming,
        world: parts.world,
        device,
        own,
        pwm,
        #[cfg(feature = "serial")]
        link,
        driver: Driver::new(cfg.camera.fps),
        env,
        notes: parts.notes,
        neutral_sent: true,
    })
}

/// The recorder(s) of `spec.record` (their folders created).
fn open_recorder(cfg: &Config, spec: &SessionSpec) -> Result<Option<RecordObserver>, SessionError> {
    Ok(match &spec.record {
        Some((dir, right)) => Some(RecordObserver::new(
            Recorder::create(dir, cfg.record.options())?,
            match right {
                Some(d2) => Some(Recorder::create(d2, cfg.record.options())?),
                None => None,
            },
        )),
        None => None,
    })
}

/// The telemetry file of `spec.telemetry`, created (the last output a build makes).
fn open_telemetry(spec: &SessionSpec) -> Result<Option<(JsonlWriter<std::fs::File>, PathBuf)>, SessionError> {
    Ok(match &spec.telemetry {
        Some(path) => {
            let f = std::fs::File::create(path).map_err(|error| SessionError::Io {
                path: path.clone(),
                error: std::io::Error::new(error.kind(), format!("cannot create: {error}")),
            })?;
            Some((JsonlWriter::new(f, path.display().to_string()), path.clone()))
        }
        None => None,
    })
}

fn source_timing(spec: &SessionSpec) -> Timing {
    match &spec.source {
        SourceSpec::Cameras { timing, .. } | SourceSpec::Sim { timing, .. } => *timing,
    }
}

fn is_wall_clock(spec: &SessionSpec) -> bool {
    source_timing(spec) == Timing::WallClock
}

fn is_pair(cfg: &Config, spec: &SessionSpec) -> bool {
    cfg.ranging.method == RangingMethod::Stereo
        && match &spec.source {
            SourceSpec::Cameras { right, .. } => right.is_some(),
            SourceSpec::Sim { .. } => !spec.truth_boxes,
        }
}

/// What cannot work together, refused before anything is opened.
fn check(cfg: &Config, spec: &SessionSpec) -> Result<(), SessionError> {
    if let Some(s) = spec.seconds {
        if !(s.is_finite() && s > 0.0) {
            return Err(invalid(format!("--seconds {s}: must be a positive number of seconds")));
        }
    }
    let timing = source_timing(spec);
    match (&spec.source, &spec.sink) {
        (SourceSpec::Cameras { right: Some(r), .. }, _) if cfg.ranging.method != RangingMethod::Stereo => {
            return Err(invalid(format!(
                "a second camera ({}): ranging.method is {:?}, so it would not be used; add --set ranging.method=stereo (docs/stereo.md)",
                r.label(),
                cfg.ranging.method.name()
            )))
        }
        (SourceSpec::Cameras { timing: Timing::RealTime, .. }, _) => {
            return Err(invalid("cameras run lock-step (a replay) or on the wall clock (the car)"))
        }
        (SourceSpec::Cameras { timing: Timing::LockStep, .. }, SinkSpec::Link { .. }) => {
            return Err(invalid("a replay moves nothing: no serial link"))
        }
        (SourceSpec::Cameras { .. }, SinkSpec::Link { pwm_log: Some(_), .. }) => {
            return Err(invalid("--pwm-log: only with the simulator as the camera (--camera sim)"))
        }
        (SourceSpec::Sim { .. }, SinkSpec::Link { .. }) if timing != Timing::WallClock => {
            return Err(invalid("the lock-step simulator drives its own car: no serial link"))
        }
        (SourceSpec::Sim { .. }, SinkSpec::Link { pwm_log: None, .. }) => {
            return Err(invalid(
                "--camera sim with --port: name the emulator's report with --pwm-log FILE so the firmware's pulses move the simulated car",
            ))
        }
        (SourceSpec::Sim { stall: Some(_), .. }, _) if timing != Timing::WallClock => {
            return Err(invalid("a camera stall is a wall-clock test (rccar drive --camera sim)"))
        }
        _ => {}
    }
    if let (Some((_, Some(d2))), false) = (&spec.record, is_pair(cfg, spec)) {
        return Err(invalid(format!(
            "--record-right {}: there is one camera; it needs ranging.method = \"stereo\" and a pair (--camera-right, or --camera sim)",
            d2.display()
        )));
    }
    Ok(())
}

/// The detector and stereo ranging of the pipeline.
fn setup_pipeline(cfg: &Config, spec: &SessionSpec, pipeline: &mut Pipeline, parts: &mut Parts) -> Result<(), SessionError> {
    if parts.stereo_pair {
        crate::drive::stereo::install(pipeline);
        if let Some(line) = crate::drive::stereo::calibration_line(pipeline, cfg) {
            parts.notes.push((Level::Info, line));
        }
    } else if cfg.ranging.method == RangingMethod::Stereo {
        parts.notes.push((
            Level::Warn,
            "ranging: method = \"stereo\" but this run has one camera; ranges are monocular \
             (a pair: `rccar drive --camera-right`, `rccar replay DIR --right DIR2`, `rccar sim` \
             without --truth-boxes; docs/stereo.md)"
                .into(),
        ));
    }
    if spec.detector == DetectorSpec::FromConfig && !spec.truth_boxes {
        let (stage, missing) = crate::pipeline::load_detector(cfg, Path::new("."))?;
        // A configured model that is not there is an error, not a silently weaker car.
        if let Some(m) = missing.first() {
            return Err(invalid(m.to_string()));
        }
        pipeline.set_detector(stage);
    }
    Ok(())
}

/// The frame source of the spec.
fn open_source(
    cfg: &Config,
    spec: &SessionSpec,
    env: &SessionEnv,
    pipeline: &Pipeline,
    parts: &mut Parts,
) -> Result<Box<dyn FrameSource>, SessionError> {
    match &spec.source {
        SourceSpec::Sim {
            scene,
            timing,
            stall,
            start_offset_m,
        } => {
            let scene = match scene {
                SceneSpec::Track(p) => Arc::new(Scene::new(&Track::load(p)?)),
                SceneSpec::Shared(s) => s.clone(),
            };
            let world = World::new(cfg, scene)?.shared();
            if let Some(m) = start_offset_m {
                lock(&world).kick(*m, 0.0);
            }
            parts.world = Some(world.clone());
            Ok(Box::new(sim_camera(cfg, spec, env, pipeline, parts, world, *timing, *stall)))
        }
        SourceSpec::Cameras { left, right, timing } => {
            let l = open_camera(cfg, env, pipeline, left, *timing, &mut parts.notes)?;
            let Some(r) = right else {
                return Ok(l);
            };
            if let (CameraSpec::Folder(ld), CameraSpec::Folder(rd)) = (left, r) {
                check_pair_folders(cfg, pipeline, ld, rd)?;
            }
            let rs = open_camera(cfg, env, pipeline, r, *timing, &mut parts.notes)?;
            parts.notes.push((
                Level::Info,
                format!(
                    "stereo pair, left {} and right {}, reference {}, frames paired within {} ms",
                    left.label(),
                    r.label(),
                    cfg.stereo.reference,
                    cfg.stereo.max_skew_ms
                ),
            ));
            Ok(Box::new(
                crate::drive::stereo::StereoFrames::from_config(l, rs, cfg).with_labels(left.label(), r.label()),
            ))
        }
    }
}

/// The simulator's camera: lock-step or on the wall clock, with the rows it must render.
#[allow(clippy::too_many_arguments)]
fn sim_camera(
    cfg: &Config,
    spec: &SessionSpec,
    env: &SessionEnv,
    pipeline: &Pipeline,
    parts: &mut Parts,
    world: SharedWorld,
    timing: Timing,
    stall: Option<(f64, f64)>,
) -> SimCamera {
    let operator = spec.operator_ends_run;
    let mut cam = SimCamera::new(world.clone()).ending_with_world(!operator);
    cam.set_truth_boxes(spec.truth_boxes);
    if parts.stereo_pair {
        let scene = lock(&world).scene().clone();
        cam.set_other(Some(crate::sim::stereo::other_camera(
            cfg,
            scene,
            crate::sim::render::RenderOptions::from_config(&cfg.sim),
        )));
        parts.notes.push((
            Level::Info,
            format!(
                "stereo pair, reference camera {} with the other {} m to its {} (ranging.method = \"stereo\")",
                cfg.stereo.reference,
                cfg.stereo.base_m,
                if cfg.stereo.reference == StereoReference::Right { "left" } else { "right" }
            ),
        ));
    }
    // Without anyone looking, render only the rows the pipeline reads (the same decisions).
    // A stereo pair is rendered whole (matching reads beyond the detector's rows).
    let whole = spec.frames_viewed || parts.stereo_pair;
    if timing == Timing::WallClock {
        let rows = (!whole && !pipeline.has_detector()).then(|| crate::sim::world::roi_rows(cfg));
        cam.set_rows(rows);
        cam.on_wall_clock(env.clock.clone(), parts.actuators.clone(), stall)
    } else {
        if whole {
            cam.set_rows(None);
        } else {
            cam.set_row_plan(Some(pipeline.row_plan()));
        }
        cam
    }
}

/// One camera: a V4L2 device, a camera program, or a folder (lock-step, or paced on the wall
/// clock).
fn open_camera(
    cfg: &Config,
    env: &SessionEnv,
    pipeline: &Pipeline,
    cam: &CameraSpec,
    timing: Timing,
    notes: &mut Vec<(Level, String)>,
) -> Result<Box<dyn FrameSource>, SessionError> {
    match cam {
        CameraSpec::V4l(index) => open_v4l(cfg, env, *index),
        CameraSpec::Pipe { .. } | CameraSpec::Picam { .. } => open_pipe(cfg, env, cam, timing, notes),
        CameraSpec::Folder(dir) => {
            let src = open_folder(cfg, pipeline, dir, notes)?;
            Ok(if timing == Timing::WallClock {
                Box::new(Paced::new(src, env.clock.clone()))
            } else {
                Box::new(src)
            })
        }
    }
}

/// A camera program's stdout (src/pipecam/): on the wall clock, newest frame only with stall
/// detection; lock-step (a replay), every frame.
#[cfg(unix)]
fn open_pipe(
    cfg: &Config,
    env: &SessionEnv,
    cam: &CameraSpec,
    timing: Timing,
    notes: &mut Vec<(Level, String)>,
) -> Result<Box<dyn FrameSource>, SessionError> {
    use crate::pipecam::{format::RawFormat, rpicam, PipeCommand};
    let c = &cfg.camera;
    let cmd = match cam {
        CameraSpec::Pipe { format, command } => {
            let f = RawFormat::parse(format, c.width).ok_or_else(|| invalid(format!("--camera {}: unknown format", cam.label())))?;
            PipeCommand::parse(f, command).map_err(|e| invalid(format!("--camera {}: {e}", cam.label())))?
        }
        CameraSpec::Picam { index, mjpeg } => {
            let program = rpicam::find_program().ok_or_else(|| {
                SessionError::Camera(format!(
                    "--camera {}: neither rpicam-vid nor libcamera-vid is on PATH (Raspberry Pi OS: sudo apt install rpicam-apps-lite, or rpicam-apps; docs/pi.md section 11)",
                    cam.label()
                ))
            })?;
            let codec = if *mjpeg { rpicam::Codec::Mjpeg } else { rpicam::Codec::Yuv420 };
            rpicam::command(&program.to_string_lossy(), &rpicam::Picam { index: *index, codec }, c)
        }
        _ => return Err(invalid("not a camera program")),
    };
    let line = cmd.line();
    let what = format!("{} {}×{}", cmd.format.name(), c.width, c.height);
    if timing == Timing::WallClock {
        let src = crate::pipecam::open_wallclock(cmd, (c.width, c.height), c.fps, env.clock.clone(), &env.stop)
            .map_err(SessionError::Camera)?;
        notes.push((
            Level::Info,
            format!(
                "camera {}: `{line}` ({what}) as process {} in its own process group; stall after {} ms",
                cam.label(),
                src.pid().unwrap_or(0),
                crate::pipecam::stall_time(c.fps).as_millis()
            ),
        ));
        Ok(Box::new(src))
    } else {
        let src = crate::pipecam::open_lockstep(cmd, (c.width, c.height), c.fps, env.stop.clone()).map_err(SessionError::Camera)?;
        notes.push((Level::Info, format!("camera {}: `{line}` ({what}), every frame in order at {} fps", cam.label(), c.fps)));
        Ok(Box::new(src))
    }
}

#[cfg(not(unix))]
fn open_pipe(_: &Config, _: &SessionEnv, cam: &CameraSpec, _: Timing, _: &mut Vec<(Level, String)>) -> Result<Box<dyn FrameSource>, SessionError> {
    Err(SessionError::Camera(format!("--camera {}: camera programs need Linux", cam.label())))
}

#[cfg(feature = "camera")]
fn open_v4l(cfg: &Config, env: &SessionEnv, index: u32) -> Result<Box<dyn FrameSource>, SessionError> {
    let src = crate::camera_source::open(
        index,
        cfg.camera.fps,
        cfg.camera.width,
        cfg.camera.height,
        env.clock.clone(),
        std::time::Duration::from_millis(500),
    )
    .map_err(|e| SessionError::Camera(e.to_string()))?;
    Ok(Box::new(src))
}

#[cfg(not(feature = "camera"))]
fn open_v4l(_cfg: &Config, _env: &SessionEnv, index: u32) -> Result<Box<dyn FrameSource>, SessionError> {
    Err(SessionError::Camera(format!(
        "--camera v4l:{index}: this rccar was built without the camera: cargo build --release --features camera (needs Debian libclang-dev)"
    )))
}

/// A folder of frames; a recording (it has its telemetry) replays with its own frame times.
fn open_folder(cfg: &Config, pipeline: &Pipeline, dir: &Path, notes: &mut Vec<(Level, String)>) -> Result<ReplayDir, SessionError> {
    let (w, h) = pipeline.frame_size();
    // Frames smaller than the ROI's extent are refused instead of being blown up.
    let max_x = cfg.warp.src.iter().map(|p| p[0]).fold(0.0f64, f64::max);
    let max_y = cfg.warp.src.iter().map(|p| p[1]).fold(0.0f64, f64::max);
    let min_size = ((max_x.ceil() as u32).min(w), (max_y.ceil() as u32).min(h));
    // A recording of `rccar drive --record`: replayed with the time steps the car saw.
    let (src, recorded) = ReplayDir::open_recording(dir, cfg.camera.fps, w, h, min_size)?;
    if let Some(t) = recorded {
        notes.push((
            Level::Info,
            format!("{}: a recording; frame times from its telemetry ({} frames)", dir.display(), t.times.len()),
        ));
        let tel = dir.join(crate::record::TELEMETRY_FILE);
        for l in &t.cut_lines {
            notes.push((
                Level::Info,
                format!("skipped {}:{l}: a cut line (not JSON); its frame has no time and is skipped", tel.display()),
            ));
        }
    }
    for i in src.ignored() {
        notes.push((Level::Info, format!("{}: ignored (not .png/.jpg/.jpeg): {i}", dir.display())));
    }
    Ok(src)
}

/// The two folders of a pair must hold the same frames (names, in order) of one size.
fn check_pair_folders(cfg: &Config, pipeline: &Pipeline, ldir: &Path, rdir: &Path) -> Result<(), SessionError> {
    let (w, h) = pipeline.frame_size();
    let list = |d: &Path| ReplayDir::open(d, cfg.camera.fps, w, h, (1, 1)).map(|s| s.files().to_vec());
    check_pair(ldir, &list(ldir)?, rdir, &list(rdir)?).map_err(SessionError::Pair)
}

/// The two folders of a stereo pair must hold the same frames (file names, in order) of the
/// same size: otherwise frames would pair with the wrong partner. The error names the file.
pub fn check_pair(ldir: &Path, left: &[PathBuf], rdir: &Path, right: &[PathBuf]) -> Result<(), String> {
    let rel = |dir: &Path, p: &PathBuf| p.strip_prefix(dir).unwrap_or(p).to_path_buf();
    for (l, r) in left.iter().zip(right) {
        if rel(ldir, l) != rel(rdir, r) {
            return Err(format!(
                "{} has no partner: the right folder's frame at that place is {} (the folders must hold the same frame names; {} and {} frames)",
                l.display(),
                r.display(),
                left.len(),
                right.len()
            ));
        }
    }
    if left.len() != right.len() {
        let (longer, n) = if left.len() > right.len() { (left, right.len()) } else { (right, left.len()) };
        return Err(format!(
            "{} has no partner in the other folder ({} has {} frames, {} has {}); the folders must hold the same frames",
            longer[n].display(),
            ldir.display(),
            left.len(),
            rdir.display(),
            right.len()
        ));
    }
    let dims = |p: &PathBuf| {
        image::ImageReader::open(p)
            .ok()
            .and_then(|r| r.with_guessed_format().ok())
            .and_then(|r| r.into_dimensions().ok())
    };
    for (l, r) in left.iter().zip(right) {
        if let (Some(a), Some(b)) = (dims(l), dims(r)) {
            if a != b {
                return Err(format!(
                    "{} is {}x{} but {} is {}x{}: the two cameras' frames must have one size",
                    l.display(),
                    a.0,
                    a.1,
                    r.display(),
                    b.0,
                    b.1
                ));
            }
        }
    }
    Ok(())
}

#[cfg(feature = "serial")]
type LinkOut = Option<super::LinkHandles>;
#[cfg(not(feature = "serial"))]
type LinkOut = ();

/// The actuators, the link's handles and the firmware's pulse watcher.
type Sinks = (Box<dyn Actuators>, LinkOut, Option<crate::sim::pwm::PwmWatcher>);

/// The actuators: the simulated car, the link (with the firmware's pulses moving the
/// simulated car), or nothing.
fn open_sink(
    _cfg: &Config,
    spec: &SessionSpec,
    env: &SessionEnv,
    parts: &mut Parts,
) -> Result<Sinks, SessionError> {
    let wall = is_wall_clock(spec);
    match (&spec.sink, &parts.world) {
        (SinkSpec::DryRun, Some(w)) if !wall => Ok((Box::new(SimVehicle::new(w.clone())), Default::default(), None)),
        (SinkSpec::DryRun, Some(_)) => Ok((
            Box::new(crate::sim::pwm::SimActuators(parts.actuators.clone())),
            Default::default(),
            None,
        )),
        (SinkSpec::DryRun, None) => Ok((Box::new(NullSink), Default::default(), None)),
        (SinkSpec::Link { port, pwm_log, bit_errors }, _) => {
            let pwm = match pwm_log {
                Some(log) => Some(
                    crate::sim::pwm::PwmWatcher::start(log, parts.actuators.clone(), env.clock.clone()).map_err(
                        |e| SessionError::Io {
                            path: log.clone(),
                            error: std::io::Error::new(e.kind(), format!("cannot read the emulator's report: {e}")),
                        },
                    )?,
                ),
                None => None,
            };
            let (sink, link) = open_link(port, *bit_errors, &env.say, &mut parts.notes)?;
            Ok((sink, link, pwm))
        }
    }
}

#[cfg(feature = "serial")]
fn open_link(
    port: &str,
    bit_errors: f64,
    _say: &Say,
    notes: &mut Vec<(Level, String)>,
) -> Result<(Box<dyn Actuators>, LinkOut), SessionError> {
    let (sink, hello) = crate::link::sink::LinkSink::open(port, bit_errors, std::time::Duration::from_secs(3))?;
    notes.push((
        Level::Info,
        format!(
            "link {port}: protocol {}, firmware {}.{}.{}",
            hello.protocol_version, hello.fw_major, hello.fw_minor, hello.fw_patch
        ),
    ));
    let handles = super::LinkHandles {
        link: sink.link(),
        flipped: sink.bits_flipped(),
        noisy: bit_errors > 0.0,
    };
    Ok((Box::new(sink), Some(handles)))
}

#[cfg(not(feature = "serial"))]
fn open_link(
    _port: &str,
    _bit_errors: f64,
    _say: &Say,
    _notes: &mut Vec<(Level, String)>,
) -> Result<(Box<dyn Actuators>, LinkOut), SessionError> {
    Err(invalid(
        "this rccar was built without the serial link: cargo build --release --features serial (or use --dry-run)",
    ))
}

#[cfg(feature = "gpio")]
fn open_gpio(cfg: &Config, arming: &Arc<Arming>) -> Result<Option<Box<dyn crate::drive::Observer>>, SessionError> {
    if !cfg.gpio.enabled {
        return Ok(None);
    }
    let opts = cfg.gpio.options();
    let dev = crate::gpio::pi::GpioDevices::open(&opts)?;
    Ok(Some(Box::new(crate::gpio::observer::GpioObserver::new(dev, arming.clone(), opts.ultrasonic))))
}

#[cfg(not(feature = "gpio"))]
fn open_gpio(cfg: &Config, _arming: &Arc<Arming>) -> Result<Option<Box<dyn crate::drive::Observer>>, SessionError> {
    if cfg.gpio.enabled {
        return Err(invalid(
            "gpio.enabled = true but this rccar was built without the GPIO: cargo build --release --features gpio (on the Pi)",
        ));
    }
    Ok(None)
}
