//! `rccar drive`: the car's main loop on the wall clock — a frame source, the pipeline, the
//! serial link — built by the library's session builder ([`rccar::session::Session`]).
//!
//! Frame sources: the V4L2 camera (`--camera v4l:0`, feature `camera`), a folder of frames
//! played at the configured fps (`--camera DIR`, bench tests at the desk), or the simulator as
//! a camera (`--camera sim`: the simulated car's view; the simulated car is moved by what the
//! firmware outputs when `--pwm-log` names the firmware emulator's report, or by the gate's
//! commands with `--dry-run`). Sink: the serial link (`--port`, feature `serial`) or nothing
//! (`--dry-run`).
//!
//! Safety (docs/drive.md): the car starts disarmed; `--arm`, the start button (SIGUSR1 at the
//! desk) or the dashboard arm it through the one arming state, and only the gate lets commands
//! through. A reconnect disarms; a lost link or a silent brake sensor is a fault; every way
//! out — the end, INT, TERM, HUP, QUIT, a panic, a fault — sends neutral before files are
//! closed, and a second signal sends neutral from another thread and exits at once.
//!
//! A gamepad on the car (`--pad`, `gamepad.enabled`, feature `gamepad`; docs/gamepad.md)
//! drives, arms and stops through the same arming state and gate.

use super::common::ConfigArgs;
use super::signals::{say, say_err};
use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::drive::{Actor, LoopEnd, Observer};
use rccar::run_dir::{RunDir, RunState};
use rccar::session::{ArmAt, CameraSpec, Level, SceneSpec, Session, SessionSpec, SinkSpec, SourceSpec, Timing};
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar drive`.
#[derive(Args, Debug)]
pub struct DriveArgs {
    /// Frame source: `picam:INDEX[:mjpeg]` (the camera module through rpicam-vid), `v4l:INDEX`
    /// (a USB webcam, /dev/videoINDEX; feature `camera`), `'pipe:FORMAT:COMMAND'` (frames a
    /// command writes: FORMAT rgb24|yuv420|yuvj420|mjpeg at [camera] width×height), `sim` (the
    /// simulator's camera), or a folder of PNG/JPEG frames played at the configured fps.
    #[arg(long, default_value = "v4l:0")]
    pub camera: String,
    /// The right camera of a stereo pair (`--camera` is then the left one): `v4l:INDEX` or a
    /// folder of frames; needs `ranging.method = "stereo"`. Frames are paired by time
    /// (`stereo.max_skew_ms`); `--camera sim` renders its pair itself.
    #[arg(long, value_name = "SPEC")]
    pub camera_right: Option<String>,
    /// Serial port of the Arduino (e.g. /dev/ttyACM0) or the firmware emulator's pty.
    #[arg(long)]
    pub port: Option<String>,
    /// Run everything without a port: nothing is sent (with `--camera sim` the simulated car
    /// does what the gate sends: nothing until armed).
    #[arg(long)]
    pub dry_run: bool,
    /// Arm from the first frame (otherwise the start button or the dashboard arms).
    #[arg(long)]
    pub arm: bool,
    /// The way to take at each fork met, comma-separated: `left,straight,right` (default:
    /// `[route] steps`); with `route.junctions = "auto"` it turns the junction rule on
    /// (docs/junctions.md).
    #[arg(long)]
    pub route: Option<String>,
    /// Stop after this many seconds of wall-clock time (default: until stopped); 0 < S <= 86400.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// With `--camera sim`: laps to drive before stopping (default: `sim.laps`; 0 = no limit).
    #[arg(long)]
    pub laps: Option<u32>,
    /// With `--camera sim`: the firmware emulator's report (its stdout, `PULSE servo|esc WIDTH
    /// T` lines); the simulated car then moves by those pulse widths, not by the commands.
    #[arg(long, value_name = "FILE")]
    pub pwm_log: Option<PathBuf>,
    /// Keep the camera frames (JPEG, `record.jpeg_quality`) and telemetry in this folder, within
    /// a disk budget; `rccar replay DIR` replays it with the same time steps.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// With a camera pair (`ranging.method = "stereo"`): keep the other camera's frames in
    /// this second folder, under the same names and with the same telemetry, so that
    /// `rccar replay DIR --right DIR2` replays the pair.
    #[arg(long, value_name = "DIR2", requires = "record")]
    pub record_right: Option<PathBuf>,
    /// Disk budget of the recording, megabytes (default `record.max_mb`; 1..=1000000); the
    /// oldest frames go first, the telemetry is always kept.
    #[arg(long, value_name = "MB")]
    pub record_max_mb: Option<f64>,
    /// Output folder for telemetry.jsonl and summary.json: new or empty (default: a new
    /// folder under out/drive/, with out/drive/latest pointing at it).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Seconds between status lines (0.2..=3600).
    #[arg(long, default_value_t = 2.0)]
    pub status_every: f64,
    /// A link that stays down this long, seconds, ends the run as a fault (exit 3); shorter
    /// drop-outs disarm the car until it is armed again.
    #[arg(long, value_name = "S", default_value_t = 3.0)]
    pub link_timeout: f64,
    /// Test hook: with `--camera sim`, the camera delivers nothing from T for D seconds
    /// (`T:D`), as a stalled or unplugged camera would.
    #[arg(long, value_name = "T:D", hide = true)]
    pub sim_stall: Option<String>,
    /// Test hook: flip each bit written to the link with this probability once armed (a noisy
    /// cable), reproducibly seeded.
    #[arg(long, value_name = "BER", hide = true)]
    pub link_bit_errors: Option<f64>,
    #[command(flatten)]
    pub config: ConfigArgs,
    #[command(flatten)]
    pub dash: super::dashboard::DashArgs,
    #[command(flatten)]
    pub pad: super::pad::PadArgs,
}

/// The session `rccar drive` asks for.
fn spec(a: &DriveArgs, track: PathBuf, stereo: bool, run: &RunDir) -> Result<SessionSpec> {
    if a.port.is_none() && !a.dry_run {
        bail!("no --port: name the Arduino's serial port (e.g. --port /dev/ttyACM0), or --dry-run to run without one");
    }
    if a.port.is_some() && a.dry_run {
        bail!("--port and --dry-run: choose one");
    }
    if !(a.link_timeout.is_finite() && (0.1..=60.0).contains(&a.link_timeout)) {
        bail!("--link-timeout {}: give 0.1 ..= 60 seconds", a.link_timeout);
    }
    let source = if a.camera == "sim" {
        if a.camera_right.is_some() {
            bail!("--camera-right: --camera sim renders its own pair with ranging.method = \"stereo\"; leave --camera-right out");
        }
        SourceSpec::Sim {
            scene: SceneSpec::Track(track),
            timing: Timing::WallClock,
            stall: a.sim_stall.as_deref().map(parse_stall).transpose()?,
            start_offset_m: None,
        }
    } else {
        if a.camera_right.is_some() && !stereo {
            bail!(
                "--camera-right {}: ranging.method is not \"stereo\", so a second camera would not be used; add --set ranging.method=stereo (docs/stereo.md)",
                a.camera_right.as_deref().unwrap_or_default()
            );
        }
        let cam = |s: &str| match CameraSpec::parse(s).map_err(anyhow::Error::msg)? {
            CameraSpec::Folder(p) if !p.is_dir() => {
                bail!("--camera {s}: not `sim`, `picam:INDEX`, `v4l:INDEX`, `pipe:FORMAT:COMMAND` or a folder of frames")
            }
            c => Ok(c),
        };
        SourceSpec::Cameras {
            left: cam(&a.camera)?,
            right: a.camera_right.as_deref().map(cam).transpose()?,
            timing: Timing::WallClock,
        }
    };
    let sink = match &a.port {
        Some(port) => SinkSpec::Link {
            port: port.clone(),
            pwm_log: a.pwm_log.clone(),
            bit_errors: a.link_bit_errors.unwrap_or(0.0),
        },
        None if a.pwm_log.is_some() => bail!("--pwm-log needs the firmware: give --port, not --dry-run"),
        None => SinkSpec::DryRun,
    };
    let mut s = SessionSpec::new(source, sink);
    s.arm = if a.arm { ArmAt::Flag } else { ArmAt::Operator };
    s.frames_viewed = a.record.is_some() || a.dash.dashboard;
    s.telemetry = Some(run.join("telemetry.jsonl"));
    s.record = a.record.clone().map(|d| (d, a.record_right.clone()));
    s.seconds = a.seconds;
    s.status_every_s = Some(a.status_every);
    s.link_give_up_s = a.link_timeout;
    Ok(s)
}

/// Runs `rccar drive`.
pub fn run(a: DriveArgs) -> Result<ExitCode> {
    let mut cfg = a.config.load()?;
    if let Some(s) = a.seconds.filter(|s| !(*s > 0.0 && *s <= 86_400.0)) {
        bail!("--seconds {s}: must be > 0 and <= 86400 seconds (a day)");
    }
    if !(0.2..=3600.0).contains(&a.status_every) {
        bail!("--status-every {}: must be 0.2..=3600 seconds", a.status_every);
    }
    if let Some(l) = a.laps {
        cfg = cfg.with_override(&format!("sim.laps={l}"))?;
    }
    if let Some(r) = a.route.as_deref() {
        cfg.route.steps = rccar::route::parse_list(r).map_err(|e| anyhow::anyhow!("--route {r:?}: {e}"))?;
    }
    if let Some(mb) = a.record_max_mb {
        if !(1.0..=1_000_000.0).contains(&mb) {
            bail!("--record-max-mb {mb:?}: must be 1..=1000000 megabytes (as record.max_mb)");
        }
        cfg = cfg.with_override(&format!("record.max_mb={mb}"))?;
    }
    // The run folder (and the recordings): new, or refused before anything is written; a run
    // that does not start takes back what it made.
    let reads: Vec<(&str, &std::path::Path)> = [("--camera", Some(a.camera.as_str())), ("--camera-right", a.camera_right.as_deref())]
        .into_iter()
        .filter_map(|(f, c)| c.map(std::path::Path::new).filter(|p| p.is_dir()).map(|p| (f, p)))
        .collect();
    let record = [("--record", a.record.as_deref()), ("--record-right", a.record_right.as_deref())];
    let mut run = super::outdir::create("drive", a.out.as_deref(), "out/drive", &record, &reads)?;
    let spec = spec(&a, PathBuf::from(&cfg.sim.track), cfg.ranging.method == rccar::config::RangingMethod::Stereo, &run)?;
    let stop = super::signals::install();
    let env = super::timer::session_env(false, stop.clone());
    let clock = env.clock.clone();
    let mut session = Session::build(&cfg, spec, env).map_err(|e| match e {
        rccar::session::SessionError::Pair(m) => anyhow::anyhow!("--camera-right: {m}"),
        e => e.into(),
    })?;
    super::signals::notes("drive", &session);
    hooks(&session);
    say(&format!(
        "drive: camera {}, {}, {} fps configured; {}",
        a.camera,
        a.port.as_deref().map_or("dry run (no port)".to_string(), |p| format!("link {p}")),
        cfg.camera.fps,
        if a.arm { "arming from the first frame" } else { "disarmed (press the button, arm on the dashboard, or hold Start on the pad)" }
    ));
    let mut pad = a.pad.start(&cfg, &session, clock.clone(), true)?;
    let mut dash = a.dash.start(&cfg, a.config.local_target()?, &session, &stop, clock)?;
    super::outdir::started(&mut run);
    let end = {
        let mut obs: [&mut dyn Observer; 2] = [&mut dash, &mut pad];
        session.run(&mut obs)
    };
    // The pad's thread stops before the files are closed (neutral has gone out).
    drop(pad);
    say(&format!("drive: {}", session.stats().line()));
    // Neutral has gone out (the session's gate); now the files.
    let outcome = session.finish()?;
    report(&mut run, &outcome)?;
    let state = match &end {
        _ if outcome.fault.is_some() => RunState::Failed,
        Ok(LoopEnd::Stopped(why)) => RunState::from_stop(Some(*why)),
        Ok(_) => RunState::Finished,
        Err(_) => RunState::Failed,
    };
    super::outdir::finish(&mut run, state, outcome.telemetry.as_ref().map(|t| t.1))?;
    let end = end?;
    Ok(exit_code(end, &outcome))
}

/// SIGUSR1 (the desk's start/stop button) toggles arming; a second signal sends neutral
/// through the link from the signal thread.
fn hooks(session: &Session) {
    // An exit that skips the destructors still ends the camera program.
    super::signals::on_emergency(rccar::pipecam::child::kill_all);
    let arming = session.arming().clone();
    super::signals::on_button(move || match arming.toggle(Actor::Button) {
        Ok(true) => say("button: armed"),
        Ok(false) => say("button: stop (disarmed; press again to drive)"),
        Err(why) => say_err(&format!("button: not armed: {why}")),
    });
    #[cfg(feature = "serial")]
    if let Some(link) = session.link() {
        super::signals::on_emergency(move || {
            link.drive(0, 0);
            let _ = link.disarm();
        });
    }
}

/// The end of the run on the terminal, and summary.json (every way out writes it).
fn report(run: &mut RunDir, o: &rccar::session::Outcome) -> Result<()> {
    for (level, line) in o.end_lines() {
        match level {
            Level::Info => say(&line),
            Level::Warn => say_err(&line),
        }
    }
    let json = o.summary_json()?;
    run.write_json("summary.json", &json)?;
    Ok(())
}

/// A fault first (one line naming it, exit 3), then a signal's code, then "nothing usable".
fn exit_code(end: LoopEnd, o: &rccar::session::Outcome) -> ExitCode {
    if let Some(f) = &o.fault {
        say_err(&format!("drive: fault: {f}; neutral sent"));
        return ExitCode::from(rccar::drive::StopReason::Fault.exit_code());
    }
    match end {
        // A run that reached its --seconds without one usable frame did not work: exit 1 below.
        LoopEnd::Stopped(rccar::drive::StopReason::Requested) if o.stats.frames == 0 => {}
        LoopEnd::Stopped(why) => {
            say(&format!("drive: stopped ({why:?}); neutral sent"));
            return ExitCode::from(why.exit_code());
        }
        _ => {}
    }
    if o.stats.frames == 0 {
        say_err(&format!(
            "drive: no usable frame ({} skipped); neutral sent",
            o.stats.skipped
        ));
        return ExitCode::from(1);
    }
    say("drive: done; neutral sent");
    ExitCode::SUCCESS
}

fn parse_stall(s: &str) -> Result<(f64, f64)> {
    let form = || format!("--sim-stall {s}: expected T:D (seconds), e.g. 4:1");
    let (t, d) = s.split_once(':').with_context(form)?;
    let t: f64 = t.parse().ok().filter(|t: &f64| t.is_finite() && *t >= 0.0).with_context(form)?;
    let d: f64 = d.parse().ok().filter(|d: &f64| d.is_finite() && *d > 0.0).with_context(form)?;
    Ok((t, d))
}
