//! `rccar sim`: drive the simulated car round a track with the real pipeline in the loop,
//! report the score, write telemetry and plots; `--record` keeps the camera frames for
//! `rccar replay`; `--sweep key=lo:hi:n` runs a gain sweep in parallel (given twice: a grid
//! with a heat map); `--start-offset M` / `--kick T:DY` measure the step response.

use super::signals::say;
use super::common::ConfigArgs;
use anyhow::{bail, Result};
use rccar::sim::step::{StepMetrics, StepRequest};
use clap::Args;
use rccar::config::{Config, RangingMethod, StereoReference};
use rccar::drive::{LoopEnd, Observer};
use rccar::session::{ArmAt, SceneSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::sim::plot::{self, system_font, SYSTEM_FONT};
use rccar::sim::report::RunReport;
use rccar::run_dir::{RunDir, RunState};
use rccar::sim::run::Summary;
use rccar::sim::scene::Scene;
use rccar::sim::track::Track;
use rccar::sim::world::lock;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

/// Flags of `rccar sim`.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Track file (default: `sim.track` of the config, config/tracks/default.toml).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// The way to take at each fork reached, comma-separated: `left,straight,right` (default:
    /// `[route] steps`, else the track file's `route`). Turns the junction rule on.
    #[arg(long)]
    pub route: Option<String>,
    /// Laps to drive (default: `sim.laps`).
    #[arg(long)]
    pub laps: Option<u32>,
    /// Stop after this much simulated time, seconds (default: `sim.max_seconds`). Without
    /// `--laps` this is a timed run (no lap count to reach; exit 0 unless the car left the lane).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Seed of the camera noise (default: `sim.seed`).
    #[arg(long)]
    pub seed: Option<i64>,
    /// Write every camera frame as PNG into this folder (for `rccar replay DIR`).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Write every camera frame to this file, `-` for stdout (all text then goes to stderr):
    /// raw frames for `rccar replay 'pipe:FORMAT:rccar sim … --frames-to -'` or a player.
    #[arg(long, value_name = "FILE")]
    pub frames_to: Option<PathBuf>,
    /// The format of `--frames-to`: rgb24, yuv420 (I420, BT.601 16..235) or mjpeg.
    #[arg(long, default_value = "rgb24", value_parser = ["rgb24", "yuv420", "mjpeg"])]
    pub frames_format: String,
    /// With `ranging.method = "stereo"`: write the right camera's frames as PNG into this
    /// folder (`--record` then holds the left camera's), for `rccar replay DIR --right DIR2`.
    #[arg(long, value_name = "DIR2")]
    pub record_right: Option<PathBuf>,
    /// Output folder for telemetry.jsonl, summary.json and the plots: new or empty (default: a
    /// new folder under out/sim/, with out/sim/latest pointing at it).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Gain sweep: `KEY=LO:HI:N`, e.g. `steering.kp=0.2:2.0:10` (any numeric config key).
    /// Give it twice for a grid over two keys (sweep.csv and the heat map sweep_grid.png).
    #[arg(long, value_name = "KEY=LO:HI:N")]
    pub sweep: Vec<String>,
    /// Step response: start the car this many metres left (+) or right (−) of the lane
    /// centre, then measure rise time, overshoot and settling (step.png, summary "step").
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub start_offset: Option<f64>,
    /// Step response: at simulated time T seconds move the car DY metres sideways (+ = left),
    /// e.g. `--kick 5:0.05`; then measure as with --start-offset.
    #[arg(long, value_name = "T:DY")]
    pub kick: Option<String>,
    /// Parallel runs in a sweep (default: the number of cores; 1..=256).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Write zeros instead of measured stage times (reproducible telemetry).
    #[arg(long)]
    pub no_timing: bool,
    /// Give the behaviours the objects' true image boxes instead of running the cascades.
    #[arg(long)]
    pub truth_boxes: bool,
    /// Take every sign, light and obstacle off the track (as switched off in the track file):
    /// with `--record`, the recording of the track without the sign that a detector's training
    /// starts from (docs/training.md, step 1).
    #[arg(long)]
    pub no_objects: bool,
    #[command(flatten)]
    pub config: ConfigArgs,
    #[command(flatten)]
    pub dash: super::dashboard::DashArgs,
    #[command(flatten)]
    pub pad: super::pad::PadArgs,
}

/// The configuration with `--laps`, `--seconds` and `--seed` applied.
fn config(a: &SimArgs) -> Result<Config> {
    let mut cfg = a.config.load()?;
    if let Some(j) = a.jobs.filter(|j| !(1..=256).contains(j)) {
        bail!("--jobs {j}: must be 1..=256 parallel runs");
    }
    let mut sets = Vec::new();
    if let Some(l) = a.laps {
        sets.push(format!("sim.laps={l}"));
    }
    if let Some(s) = a.seconds {
        sets.push(format!("sim.max_seconds={s}"));
        if a.laps.is_none() {
            // `--seconds` alone is a timed run: drive that long, no lap count to reach
            sets.push("sim.laps=0".into());
        }
    }
    if let Some(s) = a.seed {
        sets.push(format!("sim.seed={s}"));
    }
    for s in &sets {
        cfg = cfg.with_override(s)?;
    }
    Ok(cfg)
}

/// Flags that do not go together; returns whether the run is a stereo one.
fn check_flags(a: &SimArgs, cfg: &Config, step: Option<StepRequest>) -> Result<bool> {
    if !a.sweep.is_empty() && step.is_some() {
        bail!("--start-offset/--kick: not with --sweep (one run at a time)");
    }
    let stereo = cfg.ranging.method == RangingMethod::Stereo && !a.truth_boxes;
    if a.record_right.is_some() && !stereo {
        bail!(
            "--record-right: there is one camera; it needs ranging.method = \"stereo\" (--set ranging.method=stereo) and no --truth-boxes"
        );
    }
    if stereo && a.record.is_some() && a.record_right.is_none() {
        bail!("--record with ranging.method = \"stereo\": give --record-right DIR2 for the right camera's frames");
    }
    Ok(stereo)
}

/// CPU time of this process so far (all its threads), seconds; `None` where the clock is not
/// available.
fn process_cpu_s() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
        let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
        (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(unix))]
    None
}

/// What the speed figure cost: the run's CPU time and how many of the machine's cores it had
/// on average (CPU / wall), e.g. ` (62.1 s CPU: 1.4 of 2 cores)`. On a machine shared with other
/// work the real-time factor drops while the CPU time stays: this says which happened.
fn cpu_share(cpu_started: Option<f64>, wall_s: f64) -> String {
    let (Some(a), Some(b)) = (cpu_started, process_cpu_s()) else {
        return String::new();
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!(" ({:.1} s CPU: {:.1} of {cores} cores)", b - a, (b - a) / wall_s.max(1e-9))
}

/// The simulated car, built by the library's session builder.
fn session(a: &SimArgs, cfg: &Config, track: &Track, run: &RunDir, env: SessionEnv) -> Result<Session> {
    let live = a.dash.dashboard || a.pad.pad.is_some();
    let mut spec = SessionSpec::new(
        SourceSpec::Sim {
            scene: SceneSpec::Shared(Arc::new(Scene::new(track))),
            // --dashboard or --pad: paced at real time, a person arms the car
            // (docs/dashboard.md, docs/gamepad.md).
            timing: if live { Timing::RealTime } else { Timing::LockStep },
            stall: None,
            start_offset_m: a.start_offset,
        },
        SinkSpec::DryRun,
    );
    spec.arm = if live { ArmAt::Operator } else { ArmAt::Start };
    spec.truth_boxes = a.truth_boxes;
    spec.frames_viewed = a.record.is_some() || a.frames_to.is_some() || a.dash.dashboard;
    spec.operator_ends_run = live;
    spec.telemetry = Some(run.join("telemetry.jsonl"));
    let session = Session::build(cfg, spec, env)?;
    if a.truth_boxes {
        say("sim: behaviours see the objects' true boxes (--truth-boxes), not the detector's");
    }
    super::signals::notes("sim", &session);
    Ok(session)
}

/// The track file: `--track` (a path, or a name such as `town` for `<name>.toml` beside the
/// configured `sim.track`), else `sim.track`.
fn track_path(arg: Option<&Path>, cfg: &Config) -> PathBuf {
    let default = PathBuf::from(&cfg.sim.track);
    match arg {
        None => default,
        Some(p) if p.exists() || p.components().count() > 1 || p.extension().is_some() => p.to_path_buf(),
        Some(name) => default
            .parent()
            .unwrap_or(Path::new("."))
            .join(format!("{}.toml", name.display())),
    }
}

/// Runs `rccar sim`.
pub fn run(a: SimArgs) -> Result<ExitCode> {
    let mut cfg = config(&a)?;
    let track_path = track_path(a.track.as_deref(), &cfg);
    let mut track = Track::load(&track_path)?;
    if a.no_objects {
        for o in &mut track.objects {
            o.1 = false;
        }
    }
    let route = match a.route.as_deref() {
        Some(r) => Some(rccar::route::parse_list(r).map_err(|e| anyhow::anyhow!("--route {r:?}: {e}"))?),
        None => None,
    };
    let steps = rccar::sim::plan::configure_route(&mut cfg, &track, route);
    let plan = if track.junctions.is_empty() {
        None
    } else {
        let plan = track
            .plan(&steps, cfg.sim.laps.max(1))
            .map_err(|e| anyhow::anyhow!("{}: {e}", track_path.display()))?;
        say(&format!(
            "sim: route [{}]: {} forks, {} merges, {} crossings on the track; the plan:",
            rccar::route::to_list(&steps),
            track.junctions.iter().filter(|j| j.kind == rccar::sim::network::JunctionKind::Fork).count(),
            track.junctions.iter().filter(|j| j.kind == rccar::sim::network::JunctionKind::Merge).count(),
            track.junctions.iter().filter(|j| j.kind == rccar::sim::network::JunctionKind::Crossing).count(),
        ));
        for l in rccar::sim::plan::passage_lines(&track, &plan) {
            say(&format!("    {l}"));
        }
        Some(plan)
    };
    let cfg = cfg;
    let font = system_font();
    let step = StepRequest::parse(a.start_offset, a.kick.as_deref(), track.spec.road.lane_width_m)?;
    let stereo = check_flags(&a, &cfg, step)?;
    // The run folder (and the --record folders): new, or refused before anything is written.
    let sweeping = !a.sweep.is_empty();
    super::pad::check_sim(&a.pad, sweeping)?;
    let record: [(&str, Option<&Path>); 2] = if sweeping {
        [("--record", None), ("--record-right", None)]
    } else {
        [("--record", a.record.as_deref()), ("--record-right", a.record_right.as_deref())]
    };
    let mut run = super::outdir::create("sim", a.out.as_deref(), "out/sim", &record, &[])?;
    if sweeping {
        return super::sweep::run_sweep(&a.sweep, a.jobs, &cfg, &track, font, run);
    }
    let mut frames = rccar::pipecam::export::FrameWriter::open(a.frames_to.as_deref(), &a.frames_format, cfg.camera.width)?;
    let stop = super::signals::install();
    let env = super::timer::session_env(a.no_timing, stop.clone());
    let (clock, lines) = (env.clock.clone(), env.say.clone());
    let mut session = session(&a, &cfg, &track, &run, env)?;
    let world = session.world().expect("a simulation has a world").clone();
    let mut pad = a.pad.start(&cfg, &session, clock.clone(), false)?;
    let mut dash = a.dash.start(&cfg, a.config.local_target()?, &session, &stop, clock)?;
    say(&format!(
        "sim: track {} ({:.2} m, tightest lane radius {:.2} m), {} lap(s), at most {} s",
        track.name,
        track.length,
        track.tightest_lane_radius(),
        cfg.sim.laps,
        cfg.sim.max_seconds
    ));
    let mut report = RunReport::new(world.clone(), lines);
    report.record = a.record.clone();
    report.record_right = a.record_right.clone();
    report.reference_left = cfg.stereo.reference != StereoReference::Right;
    report.kick = step.filter(|s| s.kick).map(|s| (s.t, s.dy));
    let started = std::time::Instant::now();
    let cpu_started = process_cpu_s();
    super::outdir::started(&mut run);
    let end = {
        let mut obs: [&mut dyn Observer; 4] = [&mut report, &mut dash, &mut frames, &mut pad];
        session.run(&mut obs)
    };
    drop(pad);
    if let Some(e) = frames.as_ref().and_then(|f| f.error.as_ref()) {
        eprintln!("sim: {e}; the run ended there");
    }
    let interrupted = match end {
        Ok(LoopEnd::Stopped(why)) => {
            lock(&world).interrupt();
            Some(why)
        }
        _ => None,
    };
    let outcome = session.finish()?;
    end?;
    let summary = outcome.summary.clone().expect("a simulation has a score");
    let scene = lock(&world).scene().clone();
    let wall_s = started.elapsed().as_secs_f64();
    for line in summary.lines() {
        say(&line);
    }
    if stereo {
        say(&report.stereo.line());
    }
    say(&format!(
        "  {:.1} s simulated in {:.1} s wall: {:.1}x real time{}",
        summary.seconds,
        wall_s,
        summary.seconds / wall_s.max(1e-9),
        cpu_share(cpu_started, wall_s)
    ));
    let step_fig = write_summary(&mut run, &cfg, &report, &summary, step, &outcome)?;
    write_plots(&mut run, font, &report, &summary, &scene, step_fig.as_ref())?;
    if let Some(line) = report.frames_line(summary.frames) {
        say(&line);
    }
    let tel_lines = outcome.telemetry.as_ref().map(|t| t.1);
    super::outdir::finish(&mut run, RunState::from_stop(interrupted), tel_lines)?;
    if let Some(why) = interrupted {
        say(&format!(
            "sim: interrupted ({}) after {} frames; the summary and plots cover what ran",
            why.said(),
            summary.frames
        ));
        return Ok(ExitCode::from(why.exit_code()));
    }
    let mut ok = summary.laps >= cfg.sim.laps && summary.lane_departures == 0;
    if let Some(plan) = &plan {
        use rccar::sim::plan::fork_ways_of;
        let (want, got) = (fork_ways_of(plan), fork_ways_of(&summary.junctions));
        if want == got {
            say(&format!("  route: every fork as planned ({} forks)", got.len()));
        } else {
            say(&format!(
                "  route: driven {} forks, planned {}; first difference at fork passage {} (the telemetry's `junction` field says why each fork went its way)",
                got.len(),
                want.len(),
                want.iter().zip(&got).position(|(a, b)| a != b).unwrap_or(want.len().min(got.len())) + 1
            ));
            ok = false;
        }
    }
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// The step response (when asked for), then summary.json and config.json (for `rccar
/// report`), each whole or not at all.
fn write_summary(run: &mut RunDir, cfg: &Config, report: &RunReport, summary: &Summary, step: Option<StepRequest>, outcome: &rccar::session::Outcome) -> Result<Option<StepMetrics>> {
    let mut sum_json = serde_json::to_value(summary)?;
    let (lines, step_fig) = step.map(|st| report.step_summary(&st)).unwrap_or_default();
    for line in lines {
        say(&line);
    }
    if let Some(m) = &step_fig {
        sum_json["step"] = serde_json::to_value(m)?;
    }
    let sum_path = run.write_json("summary.json", &sum_json)?;
    run.write_json("config.json", cfg)?;
    let tel_path = outcome.telemetry.as_ref().map(|t| t.0.clone()).unwrap_or_default();
    say(&format!("  telemetry: {}", tel_path.display()));
    say(&format!("  summary:   {}", sum_path.display()));
    Ok(step_fig)
}

/// The time and path plots (and the step plot), when the font is there.
fn write_plots(
    run: &mut RunDir,
    font: Option<&'static [u8]>,
    report: &RunReport,
    summary: &Summary,
    scene: &Scene,
    step: Option<&StepMetrics>,
) -> Result<()> {
    let Some(font) = font else {
        say(&format!("  plots:     skipped (no font at {SYSTEM_FONT}; apt install fonts-dejavu-core)"));
        return Ok(());
    };
    plot::register_font(font);
    let p = report.write_plots(run, summary.lane_width_m, scene, step)?;
    say(&format!("  plots:     {} {}", p.time.display(), p.path.display()));
    if let Some(step) = p.step {
        say(&format!("  step:      {}", step.display()));
    }
    Ok(())
}
