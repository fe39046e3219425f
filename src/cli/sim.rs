//! `rccar sim`: drive the simulated car round a track with the real pipeline in the loop,
//! report the score, write telemetry and plots; `--record` keeps the camera frames for
//! `rccar replay`; `--sweep key=lo:hi:n` runs a gain sweep in parallel.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::config::Config;
use rccar::drive::{Driver, Flow, FrameContext, LoopEnd, LoopError, Observer, Parts, StopReason};
use rccar::pipeline::Pipeline;
use rccar::sim::plot;
use rccar::sim::run::{Simulation, Summary};
use rccar::sim::scene::Scene;
use rccar::sim::track::Track;
use rccar::sim::world::{lock, SharedWorld, SimCamera, SimScore, SimVehicle, World};
use rccar::telemetry::JsonlWriter;
use rccar::timing::{NoTimer, StageTimer};
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
    /// Stop after this much simulated time, seconds (default: `sim.max_seconds`).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Seed of the camera noise (default: `sim.seed`).
    #[arg(long)]
    pub seed: Option<i64>,
    /// Write every camera frame as PNG into this folder (for `rccar replay DIR`).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Output folder for telemetry.jsonl, summary.json and the plots.
    #[arg(long, short, default_value = "out/sim")]
    pub out: PathBuf,
    /// Gain sweep: `KEY=LO:HI:N`, e.g. `steering.kp=0.2:2.0:10` (any numeric config key).
    #[arg(long, value_name = "KEY=LO:HI:N")]
    pub sweep: Option<String>,
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
    if let Some(sweep) = &a.sweep {
        return run_sweep(&a, &cfg, &track, sweep, font);
    }

    let stop = super::signals::install();
    let world = World::new(&cfg, Arc::new(Scene::new(&track)))?.shared();
    // With a dashboard the operator ends the run (a parked, disarmed car is not "stalled").
    let mut camera = SimCamera::new(world.clone()).ending_with_world(!a.dash.dashboard);
    // --dashboard: paced at real time, the page arms the car (docs/dashboard.md).
    let fps = cfg.camera.fps;
    let mut dash = super::dashboard::Dash::start(&a.dash, &cfg, a.config.local_target()?, Some(world.clone()), &stop, Some(fps), None)?;
    let mut vehicle = dash.sink(SimVehicle::new(world.clone()));
    let mut score = SimScore::new(world.clone()).ending_the_run(!a.dash.dashboard);
    let mut pipeline = Pipeline::new(&cfg)?;
    if a.truth_boxes {
        println!("sim: behaviours see the objects' true boxes (--truth-boxes), not the detector's");
        camera.set_truth_boxes(true);
    } else {
        pipeline.set_detector(super::common::load_detector(&cfg)?);
    }
    // Without recording nobody looks at the frames: render only the rows the pipeline reads
    // on each frame (the lane's; the detectors' too on detection frames): the same decisions.
    if a.record.is_some() || dash.enabled() {
        camera.set_rows(None);
    } else {
        camera.set_row_plan(Some(pipeline.row_plan()));
    }
    if let Some(dir) = &a.record {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    let tel_path = a.out.join("telemetry.jsonl");
    let mut tel = JsonlWriter::new(
        std::fs::File::create(&tel_path).with_context(|| format!("{}: cannot create", tel_path.display()))?,
        tel_path.display().to_string(),
    );
    println!(
        "sim: track {} ({:.2} m, tightest lane radius {:.2} m), {} lap(s), at most {} s",
        track.name,
        track.length,
        track.tightest_lane_radius(),
        cfg.sim.laps,
        cfg.sim.max_seconds
    );
    let mut wall = WallTimer::new();
    let mut none = NoTimer;
    let timer: &mut dyn StageTimer = if a.no_timing { &mut none } else { &mut wall };
    let mut report = Report {
        world: world.clone(),
        record: a.record.clone(),
        series: plot::Series::default(),
    };
    let started = std::time::Instant::now();
    let clock = super::timer::WallClock::new();
    let end = {
        let mut tel = dash.tag(&mut tel);
        let mut obs: [&mut dyn Observer; 4] = [&mut score, &mut tel, &mut report, &mut dash];
        Driver::new(cfg.camera.fps).run(Parts {
            source: &mut camera,
            pipeline: &mut pipeline,
            sink: &mut *vehicle,
            stop: &stop,
            clock: &clock,
            timer,
            observer: &mut obs,
        })?
    };
    let interrupted = match end {
        LoopEnd::Stopped(why) => {
            lock(&world).interrupt();
            Some(why)
        }
        _ => None,
    };
    tel.finish().with_context(|| format!("{}: cannot write", tel_path.display()))?;
    let summary = lock(&world).summary();
    let scene = lock(&world).scene().clone();
    let wall_s = started.elapsed().as_secs_f64();
    print_summary(&summary);
    println!(
        "  {:.1} s simulated in {:.1} s wall: {:.1}x real time",
        summary.seconds,
        wall_s,
        summary.seconds / wall_s.max(1e-9)
    );
    let sum_path = a.out.join("summary.json");
    std::fs::write(&sum_path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("{}: cannot write", sum_path.display()))?;
    println!("  telemetry: {}", tel_path.display());
    println!("  summary:   {}", sum_path.display());
    if let Some(font) = font {
        plot::register_font(font);
        let p1 = a.out.join("xte_steer.png");
        save(&plot::time_plot(&report.series, summary.lane_width_m)?, &p1)?;
        let p2 = a.out.join("path.png");
        save(&plot::path_plot(&report.series, &scene)?, &p2)?;
        println!("  plots:     {} {}", p1.display(), p2.display());
    } else {
        println!("  plots:     skipped (no font at {FONT}; apt install fonts-dejavu-core)");
    }
    if let Some(dir) = &a.record {
        println!(
            "  frames:    {}/ ({} PNG; replay with `rccar replay {}`)",
            dir.display(),
            summary.frames,
            dir.display()
        );
    }
    if let Some(why) = interrupted {
        println!(
            "sim: interrupted ({}) after {} frames; the summary and plots cover what ran",
            if why == StopReason::Terminate { "SIGTERM" } else { "Ctrl-C" },
            summary.frames
        );
        return Ok(ExitCode::from(why.exit_code()));
    }
    let ok = summary.laps >= cfg.sim.laps && summary.lane_departures == 0;
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// What `rccar sim` shows and keeps while the loop runs: transitions on the terminal, the
/// plots' series, the recorded frames.
struct Report {
    world: SharedWorld,
    record: Option<PathBuf>,
    series: plot::Series,
}

impl Observer for Report {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        if let Some(dir) = &self.record {
            let p = dir.join(&ctx.frame.name);
            ctx.frame
                .image
                .save(&p)
                .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", p.display())))?;
        }
        if let Some(tr) = &ctx.record.transition {
            println!(
                "  t={:7.2} s  {} -> {}: {}",
                ctx.record.time_s,
                tr.from.name(),
                tr.to.name(),
                tr.reason
            );
        }
        if let Some(truth) = lock(&self.world).last_truth() {
            self.series.push_parts(ctx.frame.time_s, truth, ctx.output.command.steer);
        }
        Ok(Flow::Continue)
    }
}

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// The plot font, from the system (never committed).
fn load_font() -> Option<&'static [u8]> {
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

/// `key=lo:hi:n` -> (key, values).
fn parse_sweep(s: &str) -> Result<(String, Vec<f64>)> {
    let (key, range) = s
        .split_once('=')
        .with_context(|| format!("--sweep `{s}`: expected KEY=LO:HI:N, e.g. steering.kp=0.2:2.0:10"))?;
    let parts: Vec<&str> = range.split(':').collect();
    if parts.len() != 3 {
        bail!("--sweep `{s}`: expected KEY=LO:HI:N, e.g. steering.kp=0.2:2.0:10");
    }
    let lo: f64 = parts[0]
        .trim()
        .parse()
        .with_context(|| format!("--sweep: LO `{}` is not a number", parts[0]))?;
    let hi: f64 = parts[1]
        .trim()
        .parse()
        .with_context(|| format!("--sweep: HI `{}` is not a number", parts[1]))?;
    let n: usize = parts[2]
        .trim()
        .parse()
        .with_context(|| format!("--sweep: N `{}` is not a count", parts[2]))?;
    if n == 0 || n > 1000 || !lo.is_finite() || !hi.is_finite() {
        bail!("--sweep `{s}`: N must be 1..=1000 and LO, HI finite");
    }
    let vals = (0..n)
        .map(|i| {
            if n == 1 {
                lo
            } else {
                lo + (hi - lo) * i as f64 / (n - 1) as f64
            }
        })
        .collect();
    Ok((key.trim().to_string(), vals))
}

fn run_sweep(a: &SimArgs, cfg: &Config, track: &Track, sweep: &str, font: Option<&'static [u8]>) -> Result<ExitCode> {
    let (key, values) = parse_sweep(sweep)?;
    // Check every value before spending minutes.
    let cfgs: Vec<Config> = values
        .iter()
        .map(|v| {
            cfg.with_override(&format!("{key}={v}"))
                .with_context(|| format!("--sweep {key}={v}"))
        })
        .collect::<Result<_>>()?;
    let scene = Arc::new(Scene::new(track));
    let jobs = a
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    println!(
        "sweep {key} over {} values on {} thread(s), track {}",
        values.len(),
        jobs,
        track.name
    );
    let stop = super::signals::install();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<std::sync::Mutex<Option<Result<Summary, String>>>> =
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
                        // Ctrl-C ends every run of the sweep at its next frame
                        sim.run(&mut NoTimer, |_, _| if stop.is_set() { Err(()) } else { Ok(()) })
                            .unwrap_or_else(|_| sim.summary())
                    });
                if let Ok(mut slot) = results[i].lock() {
                    *slot = Some(r);
                }
            });
        }
    });
    println!(
        "{:>12} {:>5} {:>10} {:>10} {:>6} {:>10} {:>8}  end",
        key, "laps", "rms_m", "max_m", "dep", "rev/s", "lost"
    );
    let mut rows = Vec::new();
    let csv_path = a.out.join("sweep.csv");
    let mut csv = String::from("value,laps,xte_rms_m,xte_max_m,departures,reversals_per_s,lost_frames,end\n");
    for (v, slot) in values.iter().zip(results) {
        match slot.into_inner().ok().flatten() {
            Some(Ok(s)) => {
                println!(
                    "{:>12.4} {:>5} {:>10.4} {:>10.4} {:>6} {:>10.2} {:>8}  {:?}",
                    v,
                    s.laps,
                    s.xte_rms_m,
                    s.xte_max_m,
                    s.lane_departures,
                    s.steer_reversals_per_s,
                    s.lane_lost_frames,
                    s.end
                );
                csv += &format!(
                    "{v},{},{},{},{},{},{},{:?}\n",
                    s.laps,
                    s.xte_rms_m,
                    s.xte_max_m,
                    s.lane_departures,
                    s.steer_reversals_per_s,
                    s.lane_lost_frames,
                    s.end
                );
                rows.push((*v, s));
            }
            Some(Err(e)) => println!("{v:>12.4} error: {e}"),
            None => println!("{v:>12.4} error: the run panicked"),
        }
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("{}: cannot write", csv_path.display()))?;
    if let Some(why) = stop.reason() {
        println!("sweep: interrupted; the rows above cover each run up to that moment");
        return Ok(ExitCode::from(why.exit_code()));
    }
    println!("  table: {}", csv_path.display());
    if let Some(font) = font {
        plot::register_font(font);
        let p = a.out.join("sweep.png");
        save(&plot::sweep_plot(&key, &rows)?, &p)?;
        println!("  plot:  {}", p.display());
    }
    Ok(ExitCode::SUCCESS)
}
