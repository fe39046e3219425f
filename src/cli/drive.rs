//! `rccar drive`: the car's main loop on the wall clock — a frame source, the pipeline, the
//! serial link — through the one loop every run uses ([`rccar::drive::Driver`]).
//!
//! Frame sources: the V4L2 camera (`--camera v4l:0`, feature `camera`), a folder of frames
//! played at the configured fps (`--camera DIR`, bench tests at the desk), or the simulator as
//! a camera (`--camera sim`: the simulated car's view; the simulated car is moved by what the
//! firmware outputs when `--pwm-log` names the firmware emulator's report, or by the commands
//! themselves with `--dry-run`). Sink: the serial link (`--port`, feature `serial`) or nothing
//! (`--dry-run`).
//!
//! Safety: the car is disarmed until the link handshake succeeded, a first frame arrived and
//! `--arm` was given (or the button pressed); a reconnect disarms again; every way out — the
//! end, Ctrl-C, SIGTERM, a panic, a lost camera — sends neutral before files are closed, and a
//! second Ctrl-C/SIGTERM sends neutral from another thread and exits at once.

use super::common::ConfigArgs;
use super::timer::{WallClock, WallTimer};
use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::config::Config;
use rccar::control::Command;
use rccar::drive::{Clock, Driver, Flow, FrameContext, LoopEnd, LoopError, LoopStats, Observer, Parts, StopReason, StopSignal};
use rccar::pipeline::Pipeline;
use rccar::run_dir::RunState;
use rccar::sim::scene::Scene;
use rccar::sim::track::Track;
use rccar::sim::world::{lock, SharedWorld, SimScore, World};
use rccar::sink::{CommandSink, NullSink, SinkError};
use rccar::source::{Frame, FrameError, FrameSource, ReplayDir};
use rccar::telemetry::JsonlWriter;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Flags of `rccar drive`.
#[derive(Args, Debug)]
pub struct DriveArgs {
    /// Frame source: `v4l:INDEX` (the car's camera, /dev/videoINDEX; feature `camera`), `sim`
    /// (the simulator's camera), or a folder of PNG/JPEG frames played at the configured fps.
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
    /// follows the commands directly).
    #[arg(long)]
    pub dry_run: bool,
    /// Arm as soon as the link is up and the first frame arrived (otherwise the start button
    /// arms).
    #[arg(long)]
    pub arm: bool,
    /// Stop after this many seconds of wall-clock time (default: until stopped).
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
    /// Disk budget of the recording, megabytes (default `record.max_mb`); the oldest frames go
    /// first, the telemetry is always kept.
    #[arg(long, value_name = "MB")]
    pub record_max_mb: Option<f64>,
    /// Output folder for telemetry.jsonl and summary.json: new or empty. Default: a new folder
    /// per run, out/drive/<YYYYmmdd-HHMMSS>/, with out/drive/latest pointing at the newest.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Seconds between status lines.
    #[arg(long, default_value_t = 2.0)]
    pub status_every: f64,
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
}

/// Runs `rccar drive`.
pub fn run(a: DriveArgs) -> Result<ExitCode> {
    let mut cfg = a.config.load()?;
    if let Some(l) = a.laps {
        cfg = cfg.with_override(&format!("sim.laps={l}"))?;
    }
    if let Some(s) = a.seconds {
        if !(s.is_finite() && s > 0.0) {
            bail!("--seconds {s}: must be a positive number of seconds");
        }
    }
    if a.port.is_none() && !a.dry_run {
        bail!("no --port: name the Arduino's serial port (e.g. --port /dev/ttyACM0), or --dry-run to run without one");
    }
    if a.port.is_some() && a.dry_run {
        bail!("--port and --dry-run: choose one");
    }
    if let Some(mb) = a.record_max_mb {
        cfg = cfg.with_override(&format!("record.max_mb={mb}"))?;
    }
    // Everything that can fail is checked before the car can move: the run folder and the
    // recording folders (new or empty; a run that fails to start takes them back)…
    let reads: Vec<(&str, &std::path::Path)> = [
        ("--camera", Some(a.camera.as_str())),
        ("--camera-right", a.camera_right.as_deref()),
    ]
    .into_iter()
    .filter_map(|(f, c)| c.map(std::path::Path::new).filter(|p| p.is_dir()).map(|p| (f, p)))
    .collect();
    let mut run = super::outdir::create(
        "drive",
        a.out.as_deref(),
        "out/drive",
        &[
            ("--record", a.record.as_deref()),
            ("--record-right", a.record_right.as_deref()),
        ],
        &reads,
    )?;
    let mut recorder = match &a.record {
        Some(dir) => Some(RecordObs {
            rec: rccar::record::Recorder::create(dir, cfg.record.options())
                .with_context(|| format!("--record {}", dir.display()))?,
            right: match &a.record_right {
                Some(d2) => Some(
                    rccar::record::Recorder::create(d2, cfg.record.options())
                        .with_context(|| format!("--record-right {}", d2.display()))?,
                ),
                None => None,
            },
            warned: false,
        }),
        None => None,
    };
    // …and the GPIO (button, LED, ultrasonic brake).
    let req = Arc::new(Requests::default());
    let mut gpio = open_gpio(&cfg, req.clone())?;
    let stop = super::signals::install();
    super::signals::install_button();
    let clock = Arc::new(WallClock::new());
    let tel_path = run.join("telemetry.jsonl");
    let tel_file = std::fs::File::create(&tel_path).with_context(|| format!("{}: cannot create", tel_path.display()))?;
    let mut tel = JsonlWriter::new(tel_file, tel_path.display().to_string());

    let mut pipeline = Pipeline::new(&cfg)?;
    let stereo = cfg.ranging.method == rccar::config::RangingMethod::Stereo;
    if let Some(r) = &a.camera_right {
        if !stereo {
            bail!(
                "--camera-right {r}: ranging.method is {:?}, so a second camera would not be used; add --set ranging.method=stereo (docs/stereo.md)",
                cfg.ranging.method.name()
            );
        }
        if a.camera == "sim" {
            bail!("--camera-right {r}: --camera sim renders its own pair with ranging.method = \"stereo\"; leave --camera-right out");
        }
    }
    let pair = stereo && (a.camera_right.is_some() || a.camera == "sim");
    if let (Some(d2), false) = (&a.record_right, pair) {
        bail!(
            "--record-right {}: there is one camera; it needs ranging.method = \"stereo\" and a pair (--camera-right, or --camera sim)",
            d2.display()
        );
    }
    if pair {
        rccar::drive::stereo::install(&mut pipeline);
        if let Some(line) = rccar::drive::stereo::calibration_line(&pipeline, &cfg) {
            println!("{line}");
        }
    } else {
        super::common::warn_single_camera(&cfg);
    }
    pipeline.set_detector(super::common::load_detector(&cfg)?);

    // ---- the frame source -----------------------------------------------------------------
    let actuators = Arc::new(Mutex::new(Command::NEUTRAL));
    let mut world: Option<SharedWorld> = None;
    let mut pwm: Option<PwmWatcher> = None;
    let mut source: Box<dyn FrameSource> = match a.camera.as_str() {
        "sim" => {
            let track_path = PathBuf::from(&cfg.sim.track);
            let track = Track::load(&track_path)?;
            let w = World::new(&cfg, Arc::new(Scene::new(&track)))?.shared();
            world = Some(w.clone());
            if let Some(log) = &a.pwm_log {
                if a.dry_run {
                    bail!("--pwm-log needs the firmware: give --port, not --dry-run");
                }
                pwm = Some(PwmWatcher::start(log, actuators.clone(), clock.clone(), req.clone())?);
            } else if !a.dry_run {
                bail!("--camera sim with --port: name the emulator's report with --pwm-log FILE so the firmware's pulses move the simulated car");
            }
            let stall = match &a.sim_stall {
                Some(s) => Some(parse_stall(s)?),
                None => None,
            };
            let mut cam = PacedSimCamera::new(w.clone(), actuators.clone(), clock.clone(), &cfg, stall);
            if pair {
                let scene = lock(&w).scene().clone();
                cam.other = Some((
                    rccar::sim::stereo::other_camera(&cfg, scene, rccar::sim::render::RenderOptions::from_config(&cfg.sim)),
                    image::RgbImage::new(cfg.camera.width, cfg.camera.height),
                ));
                cam.truth_rows = None;
            }
            Box::new(cam)
        }
        spec => open_source(spec, &cfg, &pipeline, &clock)?,
    };
    if let Some(r) = &a.camera_right {
        let (ldir, rdir) = (PathBuf::from(&a.camera), PathBuf::from(r));
        if ldir.is_dir() && rdir.is_dir() {
            // Two folders are paired by their frame times; check first that frame i of one is
            // frame i of the other, as `rccar replay --right` does.
            let (w, h) = pipeline.frame_size();
            let list = |d: &PathBuf| ReplayDir::open(d, cfg.camera.fps, w, h, (1, 1)).map(|s| s.files().to_vec());
            super::common::check_pair("--camera-right", &ldir, &list(&ldir)?, &rdir, &list(&rdir)?)?;
        }
        let right = open_source(r, &cfg, &pipeline, &clock)?;
        source = Box::new(rccar::drive::stereo::StereoFrames::from_config(source, right, &cfg));
        println!(
            "drive: stereo pair, left {} and right {r}, reference {}, frames paired within {} ms",
            a.camera, cfg.stereo.reference, cfg.stereo.max_skew_ms
        );
    }

    // ---- the sink -------------------------------------------------------------------------
    let mut sink: Box<dyn ArmableSink> = match &a.port {
        Some(port) => open_link(port, a.link_bit_errors.unwrap_or(0.0))?,
        None if world.is_some() => Box::new(DirectSink(actuators.clone())),
        None => Box::new(Disarmed(NullSink)),
    };
    println!(
        "drive: camera {}, {}, {} fps configured; {}",
        a.camera,
        a.port.as_deref().map_or("dry run (no port)".to_string(), |p| format!("link {p}")),
        cfg.camera.fps,
        if a.arm { "arming after the first frame" } else { "disarmed (press the button or pass --arm)" }
    );

    // ---- observers --------------------------------------------------------------------------
    let mut status = Status {
        every_s: a.status_every.max(0.2),
        last_print: 0.0,
        clock: clock.clone(),
        window: LoopStats::default(),
        last: None,
        deadline: a.seconds,
        stop: stop.clone(),
        arm_wanted: a.arm,
        armed: false,
        events: Vec::new(),
        req: req.clone(),
    };
    let mut score = world.clone().map(SimScore::new);
    let mut none_rec = rccar::drive::NoObserver;
    let mut none_gpio = rccar::drive::NoObserver;
    let rec_obs: &mut dyn Observer = match recorder.as_mut() {
        Some(r) => r,
        None => &mut none_rec,
    };
    let gpio_obs: &mut dyn Observer = match gpio.as_mut() {
        Some(g) => g.as_mut(),
        None => &mut none_gpio,
    };
    let mut arming = Arming {
        sink: &mut *sink,
        presses: req.presses(),
        req: req.clone(),
    };
    // --dashboard: the page's Arm also arms the link (as the button does); its disarm,
    // e-stop and lost heartbeat send neutral through the gate (docs/dashboard.md).
    let mut dash = super::dashboard::Dash::start(&a.dash, &cfg, a.config.local_target()?, None, &stop, None, Some({
        let req = req.clone();
        Arc::new(move || req.request_arm())
    }))?;
    let mut arming = dash.sink(&mut arming);
    let end = {
        let mut none = rccar::drive::NoObserver;
        let score_obs: &mut dyn Observer = match score.as_mut() {
            Some(s) => s,
            None => &mut none,
        };
        let mut tel = dash.tag(&mut tel);
        let mut obs: [&mut dyn Observer; 6] = [gpio_obs, score_obs, &mut tel, &mut status, &mut dash, rec_obs];
        let mut timer = WallTimer::new();
        let mut driver = Driver::new(cfg.camera.fps);
        super::outdir::started(&mut run);
        let r = driver.run(Parts {
            source: &mut *source,
            pipeline: &mut pipeline,
            sink: &mut *arming,
            stop: &stop,
            clock: clock.as_ref(),
            timer: &mut timer,
            observer: &mut obs,
        });
        print_loop_stats(driver.stats());
        r
    };
    // Neutral has gone out (the loop's guard); now the files.
    drop(source);
    if let Some(r) = recorder {
        let dir = r.rec.dir().to_path_buf();
        match r.rec.finish() {
            Ok(st) => println!("  recording: {}/ ({st:?}); replay with `rccar replay {}`", dir.display(), dir.display()),
            Err(e) => eprintln!("  recording: {}: {e}", dir.display()),
        }
        if let Some(rr) = r.right {
            let d2 = rr.dir().to_path_buf();
            match rr.finish() {
                Ok(st) => println!(
                    "  recording, other camera: {}/ ({st:?}); replay the pair with `rccar replay {} --right {} --set ranging.method=stereo`",
                    d2.display(),
                    dir.display(),
                    d2.display()
                ),
                Err(e) => eprintln!("  recording: {}: {e}", d2.display()),
            }
        }
    }
    let tel_lines = tel.lines();
    tel.finish().with_context(|| format!("{}: cannot write", tel_path.display()))?;
    println!("  telemetry: {} ({} frames)", tel_path.display(), tel_lines);
    if let Some(p) = &pwm {
        if let Some((med, max)) = p.latency_ms() {
            println!("  capture -> pulse latency: median {med:.1} ms, max {max:.1} ms");
        }
    }
    if let Some(w) = &world {
        let sum = lock(w).summary();
        println!(
            "  sim: {} laps, RMS cross-track {:.4} m, max {:.4} m, departures {}, ended {:?}",
            sum.laps, sum.xte_rms_m, sum.xte_max_m, sum.lane_departures, sum.end
        );
        run.write_json("summary.json", &sum)?;
    }
    let state = match &end {
        Ok(LoopEnd::Stopped(why)) => RunState::from_stop(Some(*why)),
        Ok(_) => RunState::Finished,
        Err(_) => RunState::Failed,
    };
    super::outdir::finish(&mut run, state, Some(tel_lines))?;
    let end = end?;
    Ok(match end {
        LoopEnd::Stopped(why) => {
            println!("drive: stopped ({why:?}); neutral sent");
            ExitCode::from(why.exit_code())
        }
        _ => ExitCode::SUCCESS,
    })
}

fn parse_stall(s: &str) -> Result<(f64, f64)> {
    let (t, d) = s.split_once(':').context("--sim-stall T:D")?;
    let t: f64 = t.parse().context("--sim-stall T")?;
    let d: f64 = d.parse().context("--sim-stall D")?;
    Ok((t, d))
}

fn print_loop_stats(s: &LoopStats) {
    let lat = LoopStats::median_max(&s.latency_ms);
    let per = LoopStats::median_max(&s.period_ms);
    println!(
        "drive: {} frames, {} dropped, {} skipped, {} stalls; latency capture->command {}; period {}",
        s.frames,
        s.dropped,
        s.skipped,
        s.stalls,
        lat.map_or("-".into(), |(m, x)| format!("median {m:.1} ms, max {x:.1} ms")),
        per.map_or("-".into(), |(m, x)| format!("median {m:.1} ms, max {x:.1} ms")),
    );
}

// ---- sinks that know about arming -------------------------------------------------------------

/// A sink that may be armed (the link) or needs no arming.
trait ArmableSink: CommandSink {
    /// Arms: from now on commands move the car. Errors name the port.
    fn arm(&mut self) -> Result<(), SinkError>;
    /// Whether commands currently move the car (false after a reconnect until re-armed).
    fn armed(&self) -> bool;
}

/// The dry run without the simulator: nothing moves.
struct Disarmed<S: CommandSink>(S);
impl<S: CommandSink> CommandSink for Disarmed<S> {
    fn send(&mut self, c: Command, t: f64) -> Result<(), SinkError> {
        self.0.send(c, t)
    }
}
impl<S: CommandSink> ArmableSink for Disarmed<S> {
    fn arm(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    fn armed(&self) -> bool {
        true
    }
}

/// The dry run in the simulator: the simulated car's actuators follow the commands directly.
struct DirectSink(Arc<Mutex<Command>>);
impl CommandSink for DirectSink {
    fn send(&mut self, c: Command, _t: f64) -> Result<(), SinkError> {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = c;
        Ok(())
    }
}
impl ArmableSink for DirectSink {
    fn arm(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    fn armed(&self) -> bool {
        true
    }
}

/// Holds the car at neutral until armed; arms after the first frame when asked; the button
/// (SIGUSR1 at the desk, the GPIO button on the car) arms, and disarms when pressed again.
struct Arming<'a> {
    sink: &'a mut dyn ArmableSink,
    presses: u32,
    req: Arc<Requests>,
}
impl CommandSink for Arming<'_> {
    fn send(&mut self, c: Command, t: f64) -> Result<(), SinkError> {
        let p = self.req.presses();
        if p != self.presses {
            self.presses = p;
            if self.sink.armed() {
                println!("button: stop (disarmed; press again to drive)");
                self.sink.stop()?;
            } else {
                self.req.request_arm();
            }
        }
        if self.req.arm.swap(false, std::sync::atomic::Ordering::SeqCst) && !self.sink.armed() {
            self.sink.arm()?;
        }
        if self.sink.armed() {
            // The ultrasonic emergency brake overrides vision: no forward throttle.
            let c = if self.req.braking() {
                Command {
                    steer: c.steer,
                    throttle: c.throttle.min(0.0),
                }
            } else {
                c
            };
            self.sink.send(c, t)
        } else {
            self.sink.send(Command::NEUTRAL, t)
        }
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        self.sink.stop()
    }
}

/// What the parts of one `rccar drive` run tell the arming sink between frames, shared by
/// `Arc` (the dashboard's server thread raises `arm` too).
#[derive(Default)]
struct Requests {
    /// Raised by `--arm` after the first frame, by the start button, or by a dashboard.
    arm: std::sync::atomic::AtomicBool,
    /// Set while the ultrasonic sensor says something is nearer than `gpio.brake_m`.
    brake: std::sync::atomic::AtomicBool,
    /// Presses of the GPIO start/stop button (the same as SIGUSR1 at the desk).
    gpio_presses: std::sync::atomic::AtomicU32,
    /// Frames whose commanded servo width is waiting to show up as a pulse: (capture time, µs).
    pending: Mutex<Vec<(f64, f64)>>,
}

impl Requests {
    /// Button presses so far, from SIGUSR1 and the GPIO button.
    fn presses(&self) -> u32 {
        super::signals::button_presses() + self.gpio_presses.load(std::sync::atomic::Ordering::SeqCst)
    }
    fn request_arm(&self) {
        self.arm.store(true, std::sync::atomic::Ordering::SeqCst);
    }
    fn braking(&self) -> bool {
        self.brake.load(std::sync::atomic::Ordering::SeqCst)
    }
}

#[cfg(not(feature = "serial"))]
fn open_link(_port: &str, _ber: f64) -> Result<Box<dyn ArmableSink>> {
    bail!("this rccar was built without the serial link: cargo build --release --features serial (or use --dry-run)")
}

#[cfg(feature = "serial")]
fn open_link(port: &str, ber: f64) -> Result<Box<dyn ArmableSink>> {
    use rccar::link::transport::{Link, LinkOptions};
    use std::sync::atomic::{AtomicBool, Ordering};
    if !std::path::Path::new(port).exists() {
        bail!("{port}: no such serial port (is the Arduino plugged in? `ls /dev/ttyACM* /dev/ttyUSB*`)");
    }
    if !(0.0..0.5).contains(&ber) {
        bail!("--link-bit-errors {ber}: must be in 0 ..< 0.5");
    }
    let inject = Arc::new(AtomicBool::new(false));
    let inj = inject.clone();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let wire_fault: Option<rccar::link::transport::WireFault> = (ber > 0.0).then(|| {
        Box::new(move |bytes: &mut Vec<u8>| {
            if !inj.load(Ordering::SeqCst) {
                return;
            }
            for b in bytes.iter_mut() {
                for bit in 0..8 {
                    // xorshift64*: reproducible noise
                    state ^= state >> 12;
                    state ^= state << 25;
                    state ^= state >> 27;
                    let u = (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
                    if u < ber {
                        *b ^= 1 << bit;
                    }
                }
            }
        }) as rccar::link::transport::WireFault
    });
    let link = Arc::new(Link::open(
        port,
        LinkOptions {
            rearm_after_reconnect: false,
            wire_fault,
            ..LinkOptions::default()
        },
    ));
    let hello = link
        .wait_connected(Duration::from_secs(3))
        .with_context(|| format!("{port}: no rccar firmware answering (busy port, wrong device, or not flashed: make -C firmware flash)"))?;
    println!(
        "link {port}: protocol {}, firmware {}.{}.{}",
        hello.protocol_version, hello.fw_major, hello.fw_minor, hello.fw_patch
    );
    // A second Ctrl-C while the main thread is stuck: neutral and disarm from the signal thread.
    let l = link.clone();
    super::signals::on_emergency(move || {
        l.drive(0, 0);
        let _ = l.disarm();
    });
    Ok(Box::new(LinkSink {
        handshakes: link.stats().handshakes,
        link,
        armed: false,
        inject,
    }))
}

/// The serial link as the car's sink: disarmed until armed, and again after any reconnect.
#[cfg(feature = "serial")]
struct LinkSink {
    link: Arc<rccar::link::transport::Link>,
    armed: bool,
    handshakes: u64,
    /// The test hook's noise starts once armed.
    inject: Arc<std::sync::atomic::AtomicBool>,
}

#[cfg(feature = "serial")]
impl LinkSink {
    fn check_reconnect(&mut self) {
        let h = self.link.stats().handshakes;
        if h != self.handshakes {
            self.handshakes = h;
            if self.armed {
                eprintln!("link: reconnected; disarmed until armed again (button or --arm restart)");
            }
            self.armed = false;
        }
    }
}

#[cfg(feature = "serial")]
impl CommandSink for LinkSink {
    fn send(&mut self, c: Command, _t: f64) -> Result<(), SinkError> {
        use rccar::link::protocol::to_permille;
        self.check_reconnect();
        if self.armed {
            // Our own pause (a stalled camera) let the firmware's 250 ms failsafe trip: the car
            // stood at neutral; this session armed it and still wants to drive, so arm again.
            // (A reconnect, by contrast, disarms: see check_reconnect.)
            if let Some((t, _)) = self.link.telemetry() {
                if t.state == rccar::link::protocol::State::Failsafe && c != Command::NEUTRAL {
                    eprintln!("link: firmware failsafe had tripped (no command for its timeout); arming again");
                    self.link.arm().map_err(|e| SinkError(e.to_string()))?;
                }
            }
            self.link.drive(to_permille(c.steer), to_permille(c.throttle));
        }
        Ok(())
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        self.inject.store(false, std::sync::atomic::Ordering::SeqCst);
        self.link.drive(0, 0);
        self.armed = false;
        self.link.disarm().map_err(|e| SinkError(e.to_string()))
    }
}

#[cfg(feature = "serial")]
impl ArmableSink for LinkSink {
    fn arm(&mut self) -> Result<(), SinkError> {
        self.check_reconnect();
        self.link.arm().map_err(|e| SinkError(e.to_string()))?;
        self.handshakes = self.link.stats().handshakes;
        self.armed = true;
        self.inject.store(true, std::sync::atomic::Ordering::SeqCst);
        println!("link: armed");
        Ok(())
    }
    fn armed(&self) -> bool {
        self.armed && self.link.is_connected()
    }
}

// ---- frame sources on the wall clock -----------------------------------------------------------

#[cfg(feature = "camera")]
fn open_camera(spec: &str, cfg: &Config, clock: Arc<WallClock>) -> Result<Box<dyn FrameSource>> {
    let index: u32 = spec[4..]
        .parse()
        .with_context(|| format!("--camera {spec}: expected v4l:INDEX, e.g. v4l:0"))?;
    let src = rccar::camera_source::open(
        index,
        cfg.camera.fps,
        cfg.camera.width,
        cfg.camera.height,
        clock,
        Duration::from_millis(500),
    )?;
    Ok(Box::new(src))
}

#[cfg(not(feature = "camera"))]
fn open_camera(spec: &str, _cfg: &Config, _clock: Arc<WallClock>) -> Result<Box<dyn FrameSource>> {
    bail!("--camera {spec}: this rccar was built without the camera: cargo build --release --features camera (needs Debian libclang-dev)")
}

/// A camera (`v4l:INDEX`) or a folder of frames played at the configured fps.
fn open_source(spec: &str, cfg: &Config, pipeline: &Pipeline, clock: &Arc<WallClock>) -> Result<Box<dyn FrameSource>> {
    if spec.starts_with("v4l:") {
        return open_camera(spec, cfg, clock.clone());
    }
    let p = PathBuf::from(spec);
    if !p.is_dir() {
        bail!("--camera {spec}: not `sim`, `v4l:INDEX` or a folder of frames");
    }
    let (w, h) = pipeline.frame_size();
    Ok(Box::new(Paced {
        inner: ReplayDir::open(&p, cfg.camera.fps, w, h, (1, 1))?,
        clock: clock.clone(),
        t0: None,
    }))
}

/// A folder of frames played at their own times on the wall clock.
struct Paced<S: FrameSource> {
    inner: S,
    clock: Arc<WallClock>,
    t0: Option<f64>,
}

impl<S: FrameSource> FrameSource for Paced<S> {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let item = self.inner.next_frame()?;
        if let Ok(f) = &item {
            let t0 = *self.t0.get_or_insert_with(|| self.clock.now_s() - f.time_s);
            let wait = t0 + f.time_s - self.clock.now_s();
            if wait > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(wait));
            }
        }
        Some(item.map(|mut f| {
            f.captured_s = Some(self.clock.now_s());
            f
        }))
    }
}

/// The simulator as the car's camera, on the wall clock: at each tick (1/fps) the world is
/// advanced to now under what the actuators do (the firmware's pulse widths, or the commands
/// in a dry run), then rendered. A late tick is never queued: the next frame is the one due
/// now, and the ticks missed are counted as dropped.
struct PacedSimCamera {
    world: SharedWorld,
    actuators: Arc<Mutex<Command>>,
    clock: Arc<WallClock>,
    image: image::RgbImage,
    fps: f64,
    t0: f64,
    last_advance: f64,
    carry: f64,
    tick: u64,
    stall: Option<(f64, f64)>,
    stalled_reported: u64,
    truth_rows: Option<std::ops::Range<usize>>,
    /// A stereo pair's other camera and its image (`ranging.method = "stereo"`).
    other: Option<(rccar::sim::stereo::OtherCamera, image::RgbImage)>,
}

impl PacedSimCamera {
    fn new(
        world: SharedWorld,
        actuators: Arc<Mutex<Command>>,
        clock: Arc<WallClock>,
        cfg: &Config,
        stall: Option<(f64, f64)>,
    ) -> Self {
        let now = clock.now_s();
        let rows = (!cfg.detect.enabled).then(|| rccar::sim::run::roi_rows(cfg));
        Self {
            world,
            actuators,
            clock,
            image: image::RgbImage::new(cfg.camera.width, cfg.camera.height),
            fps: cfg.camera.fps,
            t0: now,
            last_advance: now,
            carry: 0.0,
            tick: 0,
            stall,
            stalled_reported: 0,
            truth_rows: rows,
            other: None,
        }
    }

    fn advance_to_now(&mut self) -> f64 {
        let now = self.clock.now_s();
        let cmd = *self.actuators.lock().unwrap_or_else(|e| e.into_inner());
        lock(&self.world).advance(now - self.last_advance, cmd, &mut self.carry);
        self.last_advance = now;
        now
    }
}

impl FrameSource for PacedSimCamera {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        if lock(&self.world).ended().is_some() {
            return None;
        }
        // 1. Wait for the next tick (physics keeps running while we wait).
        let due = self.t0 + (self.tick + 1) as f64 / self.fps;
        loop {
            let now = self.advance_to_now();
            if now >= due {
                break;
            }
            std::thread::sleep(Duration::from_secs_f64((due - now).min(0.002)));
        }
        // 2. A scripted camera stall: nothing for D seconds; tell the loop every 0.5 s.
        let t = self.clock.now_s() - self.t0;
        if let Some((at, dur)) = self.stall {
            if t >= at && t < at + dur {
                let until = (t + 0.5).min(at + dur);
                while self.clock.now_s() - self.t0 < until {
                    self.advance_to_now();
                    std::thread::sleep(Duration::from_millis(2));
                }
                if self.clock.now_s() - self.t0 < at + dur {
                    self.stalled_reported += 1;
                    return Some(Err(FrameError::stalled(
                        self.tick,
                        "sim camera",
                        "no frame for 500 ms (stalled or unplugged)",
                    )));
                }
            }
        }
        // 3. Render the view at the car's pose now: the newest tick (ticks we were too late
        //    for are dropped, never queued).
        let now = self.advance_to_now();
        self.tick = ((now - self.t0) * self.fps).floor() as u64;
        let t = now - self.t0;
        let mut w = lock(&self.world);
        let truth = w.render(self.tick, t, &mut self.image, self.truth_rows.clone());
        let other = self.other.as_mut().map(|(r, img)| {
            let pose = w.vehicle().pose;
            let all = 0..img.height() as usize;
            rccar::sim::stereo::render_spans(r, &pose, t, self.tick, img, &[all], w.config().sim.blur_px);
            img.clone()
        });
        drop(w);
        let mut f = Frame::new(self.tick, t, format!("frame_{:06}.png", self.tick), self.image.clone());
        f.other = other.map(|image| rccar::source::OtherView {
            image,
            name: f.name.clone(),
            skew_s: 0.0,
            pairs_dropped: 0,
        });
        f.captured_s = Some(now);
        f.truth = serde_json::to_value(&truth).ok();
        Some(Ok(f))
    }
}

// ---- the firmware's pulses -------------------------------------------------------------------

/// Follows the firmware emulator's report (`PULSE servo|esc WIDTH_US T_US` lines) and turns
/// the newest pulse widths into the simulated car's actuator command: servo 1000..2000 µs →
/// steer −1..1, ESC 1000..2000 µs → throttle −1..1 (the firmware's default end points). Also
/// measures capture → pulse latency against the frames' commands.
struct PwmWatcher {
    latencies: Arc<Mutex<Vec<f64>>>,
    quit: Arc<std::sync::atomic::AtomicBool>,
}

impl PwmWatcher {
    fn start(path: &PathBuf, actuators: Arc<Mutex<Command>>, clock: Arc<WallClock>, req: Arc<Requests>) -> Result<Self> {
        use std::io::{BufRead, Seek};
        let mut f = std::fs::File::open(path).with_context(|| format!("{}: cannot read the emulator's report", path.display()))?;
        // Start from the current end: old pulses are not this run's.
        f.seek(std::io::SeekFrom::End(0)).with_context(|| format!("{}: cannot seek", path.display()))?;
        let latencies = Arc::new(Mutex::new(Vec::new()));
        let quit = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (lat, q) = (latencies.clone(), quit.clone());
        std::thread::Builder::new().name("rccar-pwm".into()).spawn(move || {
            let mut r = std::io::BufReader::new(f);
            let mut line = String::new();
            while !q.load(std::sync::atomic::Ordering::SeqCst) {
                line.clear();
                match r.read_line(&mut line) {
                    Ok(0) => {
                        std::thread::sleep(Duration::from_millis(1));
                        continue;
                    }
                    Ok(_) if !line.ends_with('\n') => {
                        // a line being written: wait for its end
                        let mut rest = String::new();
                        while !rest.ends_with('\n') && !q.load(std::sync::atomic::Ordering::SeqCst) {
                            std::thread::sleep(Duration::from_millis(1));
                            let _ = r.read_line(&mut rest);
                        }
                        line.push_str(&rest);
                    }
                    Ok(_) => {}
                    Err(_) => break,
                }
                let t: Vec<&str> = line.split_whitespace().collect();
                if let ["PULSE", pin, w, _t] = t.as_slice() {
                    let Ok(w) = w.parse::<f64>() else { continue };
                    let v = ((w - 1500.0) / 500.0).clamp(-1.0, 1.0);
                    let now = clock.now_s();
                    let mut a = actuators.lock().unwrap_or_else(|e| e.into_inner());
                    if *pin == "servo" {
                        a.steer = v;
                        let mut p = req.pending.lock().unwrap_or_else(|e| e.into_inner());
                        if let Some(i) = p.iter().rposition(|&(_, us)| (us - w).abs() <= 1.0) {
                            lat.lock().unwrap_or_else(|e| e.into_inner()).push((now - p[i].0) * 1e3);
                            p.drain(..=i);
                        }
                    } else if *pin == "esc" {
                        a.throttle = v;
                    }
                }
            }
        })?;
        Ok(Self { latencies, quit })
    }

    fn latency_ms(&self) -> Option<(f64, f64)> {
        LoopStats::median_max(&self.latencies.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Drop for PwmWatcher {
    fn drop(&mut self) {
        self.quit.store(true, std::sync::atomic::Ordering::SeqCst);
    }
}

// ---- status line and arming ------------------------------------------------------------------

/// Prints one status line every few seconds, arms after the first frame when `--arm` was
/// given, and ends the run at `--seconds`.
struct Status {
    every_s: f64,
    last_print: f64,
    clock: Arc<WallClock>,
    window: LoopStats,
    last: Option<(String, Option<f64>, f64, f64)>,
    deadline: Option<f64>,
    stop: StopSignal,
    arm_wanted: bool,
    armed: bool,
    events: Vec<String>,
    req: Arc<Requests>,
}

impl Observer for Status {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let r = ctx.record;
        if self.arm_wanted && !self.armed {
            self.req.request_arm();
            self.armed = true;
        }
        // Commanded servo width, for the capture -> pulse latency (firmware default end points).
        if let Some(c) = ctx.frame.captured_s {
            let us = f64::from(rccar::link::protocol::permille_to_us(
                rccar::link::protocol::to_permille(r.steer),
                1000,
                1500,
                2000,
            ));
            let mut p = self.req.pending.lock().unwrap_or_else(|e| e.into_inner());
            p.push((c, us));
            let n = p.len();
            if n > 300 {
                p.drain(..n - 300);
            }
        }
        self.window.frames += 1;
        if let Some(l) = r.latency_ms {
            self.window.latency_ms.push(l);
        }
        if let Some(p) = r.period_ms {
            self.window.period_ms.push(p);
        }
        self.window.dropped = r.dropped.unwrap_or(0);
        self.last = Some((
            r.behaviour.map_or("-".into(), |m| m.name().to_string()),
            r.error,
            r.steer,
            r.throttle,
        ));
        let now = self.clock.now_s();
        if now - self.last_print >= self.every_s {
            let fps = self.window.frames as f64 / (now - self.last_print).max(1e-6);
            let lat = LoopStats::median_max(&self.window.latency_ms);
            let (b, e, s, t) = self.last.clone().unwrap_or_default();
            println!(
                "t={:6.1} s  {:5.1} fps  dropped {}  latency {}  {}  error {}  steer {:+.2}  throttle {:+.2}",
                now,
                fps,
                self.window.dropped,
                lat.map_or("-".into(), |(m, x)| format!("{m:.1}/{x:.1} ms")),
                b,
                e.map_or("-".into(), |e| format!("{e:+.3}")),
                s,
                t
            );
            self.window = LoopStats::default();
            self.last_print = now;
        }
        if let Some(d) = self.deadline {
            if now >= d {
                self.stop.request(StopReason::Requested);
            }
        }
        Ok(Flow::Continue)
    }

    fn on_stall(&mut self, e: &FrameError) {
        let msg = format!("camera stalled: {e}; neutral sent, waiting for frames");
        println!("t={:6.1} s  {msg}", self.clock.now_s());
        self.events.push(msg);
    }

    fn on_skip(&mut self, e: &FrameError) {
        println!("t={:6.1} s  skipped {e}", self.clock.now_s());
    }
}

// ---- recording and GPIO ------------------------------------------------------------------------

/// Keeps each frame (JPEG) and its telemetry line in the recording; a failed write is counted
/// and reported once, never the end of the run.
struct RecordObs {
    rec: rccar::record::Recorder,
    /// The other camera of a pair (`--record-right`): its frames under the reference frame's
    /// index (the same names) and the same telemetry lines.
    right: Option<rccar::record::Recorder>,
    warned: bool,
}

impl Observer for RecordObs {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let line = ctx.record.to_json_line();
        let a = self.rec.write_frame(ctx.frame.index, &ctx.frame.image);
        let b = self.rec.write_telemetry_line(&line);
        let c = match (&mut self.right, &ctx.frame.other) {
            (Some(r), Some(o)) => r.write_frame(ctx.frame.index, &o.image).and(r.write_telemetry_line(&line)),
            _ => Ok(()),
        };
        if let Err(e) = a.and(b).and(c) {
            if !self.warned {
                eprintln!("recording: {e} (counted; the run goes on)");
                self.warned = true;
            }
        }
        Ok(Flow::Continue)
    }
}

#[cfg(feature = "gpio")]
fn open_gpio(cfg: &Config, req: Arc<Requests>) -> Result<Option<Box<dyn Observer>>> {
    if !cfg.gpio.enabled {
        return Ok(None);
    }
    let dev = rccar::gpio::pi::GpioDevices::open(&cfg.gpio.options())?;
    Ok(Some(Box::new(GpioObs { dev, distance: None, braking: false, req })))
}

#[cfg(not(feature = "gpio"))]
fn open_gpio(cfg: &Config, _req: Arc<Requests>) -> Result<Option<Box<dyn Observer>>> {
    if cfg.gpio.enabled {
        bail!("gpio.enabled = true but this rccar was built without the GPIO: cargo build --release --features gpio (on the Pi)");
    }
    Ok(None)
}

/// The Pi's button, LED and ultrasonic brake, polled between frames.
#[cfg(feature = "gpio")]
struct GpioObs {
    dev: rccar::gpio::pi::GpioDevices,
    distance: Option<f64>,
    braking: bool,
    req: Arc<Requests>,
}

#[cfg(feature = "gpio")]
impl Observer for GpioObs {
    fn before_frame(&mut self, _p: &mut Pipeline) -> Flow {
        use rccar::gpio::LedState;
        use std::sync::atomic::Ordering;
        let driving = !self.req.braking();
        let ev = self.dev.poll(LedState::from_status(false, true, true, driving));
        if ev.presses > 0 {
            self.req.gpio_presses.fetch_add(ev.presses, Ordering::SeqCst);
        }
        self.req.brake.store(ev.brake, Ordering::SeqCst);
        self.distance = ev.distance_m;
        Flow::Continue
    }
    fn decorate(&mut self, r: &mut rccar::telemetry::FrameRecord) {
        r.ultrasonic_m = self.distance;
        let b = self.req.braking();
        if b != self.braking {
            r.events.push(if b { "ultrasonic brake on".into() } else { "ultrasonic brake off".into() });
            self.braking = b;
        }
    }
}
