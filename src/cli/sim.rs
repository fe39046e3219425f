//! `rccar sim`: drive the simulated car round a track with the real pipeline in the loop,
//! report the score, write telemetry and plots; `--record` keeps the camera frames for
//! `rccar replay`; `--sweep key=lo:hi:n` runs a gain sweep in parallel (given twice: a grid
//! with a heat map); `--start-offset M` / `--kick T:DY` measure the step response.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{bail, Context, Result};
use rccar::sim::step::{step_metrics, StepOptions};
use rccar::sim::sweep::{self, Chatter, SweepRun};
use clap::Args;
use rccar::config::{Config, RangingMethod, StereoReference};
use rccar::drive::{Clock, Level, LoopEnd, NoClock, Observer, StopReason};
use rccar::session::{ArmAt, SceneSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::sim::plot;
use rccar::sim::report::RunReport;
use rccar::sim::run::{Simulation, Summary};
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
    /// Output folder for telemetry.jsonl, summary.json and the plots.
    #[arg(long, short, default_value = "out/sim")]
    pub out: PathBuf,
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
    /// Parallel runs in a sweep (default: the number of cores).
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
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    let font = load_font();
    let step = parse_step(a.start_offset, a.kick.as_deref(), track.spec.road.lane_width_m)?;
    if !a.sweep.is_empty() {
        if step.is_some() {
            bail!("--start-offset/--kick: not with --sweep (one run at a time)");
        }
        return run_sweep(&a, &cfg, &track, font);
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
    for dir in a.record.iter().chain(&a.record_right) {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
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
    spec.telemetry = Some(a.out.join("telemetry.jsonl"));
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
    let sum_path = a.out.join("summary.json");
    std::fs::write(&sum_path, serde_json::to_string_pretty(&sum_json)?)
        .with_context(|| format!("{}: cannot write", sum_path.display()))?;
    // The run's configuration, for `rccar report` (differences from the defaults).
    let cfg_path = a.out.join("config.json");
    std::fs::write(&cfg_path, serde_json::to_string_pretty(&cfg)?)
        .with_context(|| format!("{}: cannot write", cfg_path.display()))?;
    println!("  telemetry: {}", tel_path.display());
    println!("  summary:   {}", sum_path.display());
    write_plots(&a, font, &report, &summary, &scene, step_fig.as_ref())?;
    print_frames(&a, summary.frames);
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
    a: &SimArgs,
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
    let p1 = a.out.join("xte_steer.png");
    save(&plot::time_plot(&report.series, summary.lane_width_m)?, &p1)?;
    let p2 = a.out.join("path.png");
    save(&plot::path_plot(&report.series, scene)?, &p2)?;
    println!("  plots:     {} {}", p1.display(), p2.display());
    if let Some(m) = step {
        let p3 = a.out.join("step.png");
        save(&plot::step_plot(&report.series.t, &report.series.xte, m)?, &p3)?;
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

fn save(img: &image::RgbImage, p: &Path) -> Result<()> {
    img.save(p).with_context(|| format!("{}: cannot write", p.display()))
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
            let form = || format!("--kick `{k}`: expected T:DY (seconds:metres), e.g. 5:0.05");
            let (t, dy) = k.split_once(':').with_context(form)?;
            let t: f64 = t.trim().parse().ok().filter(|t: &f64| t.is_finite() && *t >= 0.0).with_context(form)?;
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

fn run_sweep(a: &SimArgs, cfg: &Config, track: &Track, font: Option<&'static [u8]>) -> Result<ExitCode> {
    let axes = sweep::parse_axes(&a.sweep)?;
    let keys: Vec<&str> = axes.iter().map(|x| x.key.as_str()).collect();
    let points = sweep::grid(&axes);
    // Check every value before spending minutes.
    let cfgs: Vec<Config> = points
        .iter()
        .map(|p| {
            let mut c = cfg.clone();
            for (k, v) in keys.iter().zip(p) {
                c = c.with_override(&format!("{k}={v}")).with_context(|| format!("--sweep {k}={v}"))?;
            }
            Ok(c)
        })
        .collect::<Result<_>>()?;
    let scene = Arc::new(Scene::new(track));
    let jobs = a
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    println!(
        "sweep {} over {} run(s) on {} thread(s), track {}",
        keys.join(" × "),
        cfgs.len(),
        jobs,
        track.name
    );
    let stop = super::signals::install();
    let next = std::sync::atomic::AtomicUsize::new(0);
    // One slot per run: its summary and steering chatter, or why it could not start.
    type RunResult = Result<(Summary, f64), String>;
    let results: Vec<std::sync::Mutex<Option<RunResult>>> =
        (0..cfgs.len()).map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..jobs.min(cfgs.len()) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if i >= cfgs.len() {
                    break;
                }
                let r = Simulation::with_scene(&cfgs[i], scene.clone())
                    .map_err(|e| e.to_string())
                    .map(|mut sim| {
                        sim.set_full_frames(false);
                        let mut chatter = Chatter::default();
                        // Ctrl-C ends every run of the sweep at its next frame
                        let sum = sim
                            .run(|_, st| {
                                chatter.push(st.out.command.steer);
                                if stop.is_set() {
                                    Err(())
                                } else {
                                    Ok(())
                                }
                            })
                            .unwrap_or_else(|_| sim.summary());
                        (sum, chatter.rms())
                    });
                if let Ok(mut slot) = results[i].lock() {
                    *slot = Some(r);
                }
            });
        }
    });
    let head: Vec<String> = keys.iter().map(|k| format!("{k:>12}")).collect();
    println!(
        "{} {:>5} {:>10} {:>10} {:>6} {:>10} {:>9} {:>8}  end",
        head.join(" "),
        "laps",
        "rms_m",
        "max_m",
        "dep",
        "rev/s",
        "dsteer",
        "lost"
    );
    let mut runs = Vec::new();
    for (p, slot) in points.iter().zip(results) {
        let vals: Vec<String> = p.iter().map(|v| format!("{v:>12.4}")).collect();
        let vals = vals.join(" ");
        match slot.into_inner().ok().flatten() {
            Some(Ok((s, chatter))) => {
                println!(
                    "{vals} {:>5} {:>10.4} {:>10.4} {:>6} {:>10.2} {:>9.4} {:>8}  {:?}",
                    s.laps, s.xte_rms_m, s.xte_max_m, s.lane_departures, s.steer_reversals_per_s, chatter, s.lane_lost_frames, s.end
                );
                runs.push(SweepRun {
                    values: p.clone(),
                    summary: s,
                    steer_diff_rms: chatter,
                });
            }
            Some(Err(e)) => println!("{vals} error: {e}"),
            None => println!("{vals} error: the run panicked"),
        }
    }
    let csv_path = a.out.join("sweep.csv");
    std::fs::write(&csv_path, sweep::csv(&keys, &runs)).with_context(|| format!("{}: cannot write", csv_path.display()))?;
    if let Some(why) = stop.reason() {
        println!("sweep: interrupted; the rows above cover each run up to that moment");
        return Ok(ExitCode::from(why.exit_code()));
    }
    println!("  table: {}", csv_path.display());
    if let Some(font) = font {
        plot::register_font(font);
        if axes.len() == 1 {
            let rows: Vec<(f64, Summary)> = runs.iter().map(|r| (r.values[0], r.summary.clone())).collect();
            let p = a.out.join("sweep.png");
            save(&plot::sweep_plot(keys[0], &rows)?, &p)?;
            println!("  plot:  {}", p.display());
        } else {
            let p = a.out.join("sweep_grid.png");
            save(&plot::grid_plot(keys[0], keys[1], &axes[0].values, &axes[1].values, &runs)?, &p)?;
            println!("  heat map: {}", p.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}
