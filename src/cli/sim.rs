//! `rccar sim`: drive the simulated car round a track with the real pipeline in the loop,
//! report the score, write telemetry and plots; `--record` keeps the camera frames for
//! `rccar replay`; `--sweep key=lo:hi:n` runs a gain sweep in parallel (given twice: a grid
//! with a heat map); `--start-offset M` / `--kick T:DY` measure the step response.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{bail, Context, Result};
use rccar::sim::step::{step_metrics, StepOptions};
use clap::Args;
use rccar::config::{RangingMethod, StereoReference};
use rccar::drive::{Clock, Level, LoopEnd, NoClock, Observer, StopReason};
use rccar::session::{ArmAt, SceneSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::sim::plot;
use rccar::sim::report::RunReport;
use rccar::run_dir::{RunDir, RunState};
use rccar::sim::run::Summary;
use rccar::sim::scene::Scene;
use rccar::sim::track::Track;
use rccar::sim::world::lock;
use rccar::timing::NoTimer;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

/// Flags of `rccar sim`.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Track file (default: `sim.track` of the config, config/tracks/default.toml).
    #[arg(long)]
    pub track: Option<PathBuf>,
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
    #[command(flatten)]
    pub config: ConfigArgs,
    #[command(flatten)]
    pub dash: super::dashboard::DashArgs,
}

/// Runs `rccar sim`.
pub fn run(a: SimArgs) -> Result<ExitCode> {
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
    let track_path = a.track.clone().unwrap_or_else(|| PathBuf::from(&cfg.sim.track));
    let track = Track::load(&track_path)?;
    let font = load_font();
    let step = parse_step(a.start_offset, a.kick.as_deref(), track.spec.road.lane_width_m)?;
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
    // The run folder (and the --record folders): new, or refused before anything is written.
    let sweeping = !a.sweep.is_empty();
    let record: [(&str, Option<&Path>); 2] = if sweeping {
        [("--record", None), ("--record-right", None)]
    } else {
        [("--record", a.record.as_deref()), ("--record-right", a.record_right.as_deref())]
    };
    let mut run = super::outdir::create("sim", a.out.as_deref(), "out/sim", &record, &[])?;
    if sweeping {
        return super::sweep::run_sweep(&a.sweep, a.jobs, &cfg, &track, font, run);
    }
    let stop = super::signals::install();
    let clock: Arc<dyn Clock + Send + Sync> = if a.no_timing { Arc::new(NoClock) } else { Arc::new(super::timer::WallClock::new()) };
    let say: rccar::drive::Say = Arc::new(|level, line: &str| match level {
        Level::Info => super::signals::say(line),
        Level::Warn => super::signals::say_err(line),
    });
    let mut spec = SessionSpec::new(
        SourceSpec::Sim {
            scene: SceneSpec::Shared(Arc::new(Scene::new(&track))),
            // --dashboard: paced at real time, the page arms the car (docs/dashboard.md).
            timing: if a.dash.dashboard { Timing::RealTime } else { Timing::LockStep },
            stall: None,
            start_offset_m: a.start_offset,
        },
        SinkSpec::DryRun,
    );
    spec.arm = if a.dash.dashboard { ArmAt::Operator } else { ArmAt::Start };
    spec.truth_boxes = a.truth_boxes;
    spec.frames_viewed = a.record.is_some() || a.dash.dashboard;
    spec.operator_ends_run = a.dash.dashboard;
    spec.telemetry = Some(run.join("telemetry.jsonl"));
    let timer: Box<dyn rccar::timing::StageTimer + Send> = if a.no_timing { Box::new(NoTimer) } else { Box::new(WallTimer::new()) };
    let env = SessionEnv { clock: clock.clone(), stop: stop.clone(), timer, say: say.clone() };
    let mut session = Session::build(&cfg, spec, env)?;
    if a.truth_boxes {
        println!("sim: behaviours see the objects' true boxes (--truth-boxes), not the detector's");
    }
    for (level, line) in session.notes() {
        match level {
            Level::Info => println!("sim: {line}"),
            Level::Warn => eprintln!("{line}"),
        }
    }
    let world = session.world().expect("a simulation has a world").clone();
    let mut dash = super::dashboard::Dash::start(&a.dash, &cfg, a.config.local_target()?, &session, &stop, clock)?;
    println!(
        "sim: track {} ({:.2} m, tightest lane radius {:.2} m), {} lap(s), at most {} s",
        track.name,
        track.length,
        track.tightest_lane_radius(),
        cfg.sim.laps,
        cfg.sim.max_seconds
    );
    let mut report = RunReport::new(world.clone(), say);
    report.record = a.record.clone();
    report.record_right = a.record_right.clone();
    report.reference_left = cfg.stereo.reference != StereoReference::Right;
    report.kick = step.filter(|s| s.kick).map(|s| (s.t, s.dy));
    let started = std::time::Instant::now();
    super::outdir::started(&mut run);
    let end = {
        let mut obs: [&mut dyn Observer; 2] = [&mut report, &mut dash];
        session.run(&mut obs)
    };
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
    let tel_path = outcome.telemetry.as_ref().map(|t| t.0.clone()).unwrap_or_default();
    let scene = lock(&world).scene().clone();
    let wall_s = started.elapsed().as_secs_f64();
    print_summary(&summary);
    if stereo {
        let t = &report.stereo;
        println!(
            "  stereo: {} pairs, detector boxes ranged by stereo {}, without a match {}",
            t.pairs, t.ranged, t.unmatched
        );
    }
    println!(
        "  {:.1} s simulated in {:.1} s wall: {:.1}x real time",
        summary.seconds,
        wall_s,
        summary.seconds / wall_s.max(1e-9)
    );
    let mut sum_json = serde_json::to_value(&summary)?;
    let mut step_fig = None;
    if let Some(st) = step {
        // After a kick the first frame that sees it is the one after the kick's frame.
        let t0 = if st.kick { report.kicked_at.map(|t| t + 1e-6) } else { Some(0.0) };
        match t0.map(|t0| step_metrics(&report.series.t, &report.series.xte, t0, &StepOptions::default())) {
            Some(Ok(m)) => {
                print_step(&m);
                sum_json["step"] = serde_json::to_value(&m)?;
                step_fig = Some(m);
            }
            Some(Err(e)) => println!("  step response: {e}"),
            None => println!("  step response: the run ended before the kick at t = {} s", st.t),
        }
    }
    // Summary and configuration (for `rccar report`), each whole or not at all.
    let sum_path = run.write_json("summary.json", &sum_json)?;
    run.write_json("config.json", &cfg)?;
    println!("  telemetry: {}", tel_path.display());
    println!("  summary:   {}", sum_path.display());
    write_plots(&mut run, font, &report, &summary, &scene, step_fig.as_ref())?;
    print_frames(&a, summary.frames);
    let tel_lines = outcome.telemetry.as_ref().map(|t| t.1);
    super::outdir::finish(&mut run, RunState::from_stop(interrupted), tel_lines)?;
    if let Some(why) = interrupted {
        println!(
            "sim: interrupted ({}) after {} frames; the summary and plots cover what ran",
            signal_name(why),
            summary.frames
        );
        return Ok(ExitCode::from(why.exit_code()));
    }
    let ok = summary.laps >= cfg.sim.laps && summary.lane_departures == 0;
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// How a stop reason is said.
fn signal_name(why: StopReason) -> &'static str {
    match why {
        StopReason::Terminate => "SIGTERM",
        StopReason::Hangup => "SIGHUP",
        StopReason::Quit => "SIGQUIT",
        StopReason::Interrupt => "Ctrl-C",
        StopReason::Fault => "a fault",
        StopReason::Requested => "requested",
    }
}

/// The time and path plots (and the step plot), when the font is there.
fn write_plots(
    run: &mut RunDir,
    font: Option<&'static [u8]>,
    report: &RunReport,
    summary: &Summary,
    scene: &Scene,
    step: Option<&rccar::sim::step::StepMetrics>,
) -> Result<()> {
    let Some(font) = font else {
        println!("  plots:     skipped (no font at {FONT}; apt install fonts-dejavu-core)");
        return Ok(());
    };
    plot::register_font(font);
    let p1 = save(run, "xte_steer.png", &plot::time_plot(&report.series, summary.lane_width_m)?)?;
    let p2 = save(run, "path.png", &plot::path_plot(&report.series, scene)?)?;
    println!("  plots:     {} {}", p1.display(), p2.display());
    if let Some(m) = step {
        let p3 = save(run, "step.png", &plot::step_plot(&report.series.t, &report.series.xte, m)?)?;
        println!("  step:      {}", p3.display());
    }
    Ok(())
}

/// Where the recorded frames went.
fn print_frames(a: &SimArgs, frames: u64) {
    match (&a.record, &a.record_right) {
        (Some(dir), Some(right)) => println!(
            "  frames:    {}/ and {}/ ({} PNG each; replay with `rccar replay {} --right {} --set ranging.method=stereo`)",
            dir.display(),
            right.display(),
            frames,
            dir.display(),
            right.display()
        ),
        (Some(dir), None) => println!(
            "  frames:    {}/ ({} PNG; replay with `rccar replay {}`)",
            dir.display(),
            frames,
            dir.display()
        ),
        _ => {}
    }
}

pub(crate) const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// The plot font, from the system (never committed).
pub(crate) fn load_font() -> Option<&'static [u8]> {
    std::fs::read(FONT).ok().map(|b| &*Box::leak(b.into_boxed_slice()))
}

/// Writes a plot into the run folder as `name` (PNG, atomically); returns its path.
pub(crate) fn save(run: &mut RunDir, name: &str, img: &image::RgbImage) -> Result<PathBuf> {
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot encode PNG", run.join(name).display()))?;
    Ok(run.write(name, &png.into_inner())?)
}

fn print_summary(s: &Summary) {
    println!("sim: {} frames, {:.1} s, ended: {:?}", s.frames, s.seconds, s.end);
    let times: Vec<String> = s.lap_times_s.iter().map(|t| format!("{t:.2}")).collect();
    println!("  laps completed:   {} (lap times s: [{}])", s.laps, times.join(", "));
    println!(
        "  cross-track error: RMS {:.4} m ({:.1}% of the {:.2} m lane), max {:.4} m",
        s.xte_rms_m,
        100.0 * s.xte_rms_m / s.lane_width_m,
        s.lane_width_m,
        s.xte_max_m
    );
    println!(
        "  lane departures:  {} ({:.2} s with a wheel outside)",
        s.lane_departures, s.time_outside_s
    );
    println!(
        "  steering reversals {:.2}/s, lane lost in {} frames",
        s.steer_reversals_per_s, s.lane_lost_frames
    );
}

/// A step-response request: a start offset (`kick` false, at t = 0) or a kick at `t`.
#[derive(Debug, Clone, Copy)]
struct StepReq {
    kick: bool,
    t: f64,
    dy: f64,
}

/// Checks `--start-offset` and `--kick T:DY` (at most a lane width either way).
fn parse_step(offset: Option<f64>, kick: Option<&str>, lane_width: f64) -> Result<Option<StepReq>> {
    let check = |what: &str, dy: f64| -> Result<()> {
        if !dy.is_finite() || dy.abs() > lane_width {
            bail!("{what}: {dy} m is off the lane; give at most ±{lane_width} m (the lane width)");
        }
        Ok(())
    };
    match (offset, kick) {
        (Some(_), Some(_)) => bail!("--start-offset and --kick: give one of them"),
        (Some(m), None) => {
            check("--start-offset", m)?;
            Ok(Some(StepReq { kick: false, t: 0.0, dy: m }))
        }
        (None, Some(k)) => {
            let form = || format!("--kick `{k}`: expected T:DY (seconds 0..=36000 : metres), e.g. 5:0.05");
            let (t, dy) = k.split_once(':').with_context(form)?;
            let t: f64 = t.trim().parse().ok().filter(|t: &f64| (0.0..=36_000.0).contains(t)).with_context(form)?;
            let dy: f64 = dy.trim().parse().ok().filter(|d: &f64| d.is_finite()).with_context(form)?;
            check("--kick", dy)?;
            Ok(Some(StepReq { kick: true, t, dy }))
        }
        (None, None) => Ok(None),
    }
}

fn print_step(m: &rccar::sim::step::StepMetrics) {
    let s = |v: Option<f64>| v.map_or("not reached".to_string(), |v| format!("{v:.2} s"));
    println!(
        "  step response from {:+.4} m at t = {:.2} s (window {:.1} s):",
        m.initial_offset_m, m.t0_s, m.window_s
    );
    println!("    rise time 10→90 %:  {}", s(m.rise_time_s));
    println!("    overshoot:          {:.1} % of the offset", m.overshoot_pct);
    println!(
        "    settling time:      {} (band ±{:.1} mm = 5 % of the offset, at least 2 mm)",
        s(m.settling_time_s),
        m.band_m * 1000.0
    );
}
