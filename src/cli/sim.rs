//! `rccar sim`: drive the simulated car round a track with the real pipeline in the loop,
//! report the score, write telemetry and plots; `--record` keeps the camera frames for
//! `rccar replay`; `--sweep key=lo:hi:n` runs a gain sweep in parallel (given twice: a grid
//! with a heat map); `--start-offset M` / `--kick T:DY` measure the step response.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{bail, Context, Result};
use rccar::sim::step::{step_metrics, StepOptions};
use clap::Args;
use rccar::drive::{Driver, Flow, FrameContext, LoopEnd, LoopError, Observer, Parts, StopReason};
use rccar::pipeline::Pipeline;
use rccar::run_dir::{RunDir, RunState};
use rccar::sim::plot;
use rccar::sim::run::Summary;
use rccar::sim::scene::Scene;
use rccar::sim::track::Track;
use rccar::sim::world::{lock, SharedWorld, SimCamera, SimScore, SimVehicle, World};
use rccar::telemetry::JsonlWriter;
use rccar::timing::{NoTimer, StageTimer};
use std::path::PathBuf;
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
    /// Output folder for telemetry.jsonl, summary.json and the plots: new or empty (a folder
    /// holding a run is refused). Default: a new folder per run, out/sim/<YYYYmmdd-HHMMSS>/,
    /// with out/sim/latest pointing at the newest.
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
    let font = load_font();
    let step = parse_step(a.start_offset, a.kick.as_deref(), track.spec.road.lane_width_m)?;
    if !a.sweep.is_empty() && step.is_some() {
        bail!("--start-offset/--kick: not with --sweep (one run at a time)");
    }
    // The run folder (and the --record folders): new, or refused before anything is written.
    let sweeping = !a.sweep.is_empty();
    let record: [(&str, Option<&std::path::Path>); 2] = if sweeping {
        [("--record", None), ("--record-right", None)]
    } else {
        [
            ("--record", a.record.as_deref()),
            ("--record-right", a.record_right.as_deref()),
        ]
    };
    let mut run = super::outdir::create("sim", a.out.as_deref(), "out/sim", &record, &[])?;
    if sweeping {
        return super::sweep::run_sweep(&a.sweep, a.jobs, &cfg, &track, font, run);
    }

    let stop = super::signals::install();
    let world = World::new(&cfg, Arc::new(Scene::new(&track)))?.shared();
    if let Some(m) = a.start_offset {
        lock(&world).kick(m, 0.0);
    }
    // With a dashboard the operator ends the run (a parked, disarmed car is not "stalled").
    let mut camera = SimCamera::new(world.clone()).ending_with_world(!a.dash.dashboard);
    // --dashboard: paced at real time, the page arms the car (docs/dashboard.md).
    let fps = cfg.camera.fps;
    let mut dash = super::dashboard::Dash::start(&a.dash, &cfg, a.config.local_target()?, Some(world.clone()), &stop, Some(fps), None)?;
    let mut vehicle = dash.sink(SimVehicle::new(world.clone()));
    let mut score = SimScore::new(world.clone()).ending_the_run(!a.dash.dashboard);
    let mut pipeline = Pipeline::new(&cfg)?;
    // ranging.method = "stereo": a camera pair (src/sim/stereo.rs `other_camera`).
    let stereo = cfg.ranging.method == rccar::config::RangingMethod::Stereo && !a.truth_boxes;
    if a.record_right.is_some() && !stereo {
        bail!(
            "--record-right: there is one camera; it needs ranging.method = \"stereo\" (--set ranging.method=stereo) and no --truth-boxes"
        );
    }
    if stereo && a.record.is_some() && a.record_right.is_none() {
        bail!("--record with ranging.method = \"stereo\": give --record-right DIR2 for the right camera's frames");
    }
    if a.truth_boxes {
        println!("sim: behaviours see the objects' true boxes (--truth-boxes), not the detector's");
        camera.set_truth_boxes(true);
        super::common::warn_single_camera(&cfg);
    } else {
        pipeline.set_detector(super::common::load_detector(&cfg)?);
    }
    if stereo {
        let scene = lock(&world).scene().clone();
        camera.set_other(Some(rccar::sim::stereo::other_camera(
            &cfg,
            scene,
            rccar::sim::render::RenderOptions::from_config(&cfg.sim),
        )));
        rccar::drive::stereo::install(&mut pipeline);
        if let Some(line) = rccar::drive::stereo::calibration_line(&pipeline, &cfg) {
            println!("{line}");
        }
        println!(
            "sim: stereo pair, reference camera {} with the other {} m to its {} (ranging.method = \"stereo\")",
            cfg.stereo.reference,
            cfg.stereo.base_m,
            cfg.stereo.reference.other()
        );
    }
    // Without recording nobody looks at the frames: render only the rows the pipeline reads
    // on each frame (the lane's; the detectors' too on detection frames): the same decisions.
    // A stereo pair is rendered whole (matching reads beyond the detector's rows).
    if a.record.is_some() || dash.enabled() || stereo {
        camera.set_rows(None);
    } else {
        camera.set_row_plan(Some(pipeline.row_plan()));
    }
    let tel_path = run.join("telemetry.jsonl");
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
        record_right: a.record_right.clone(),
        reference_left: cfg.stereo.reference.is_left(),
        stereo: StereoTally::default(),
        series: plot::Series::default(),
        kick: step.filter(|s| s.kick).map(|s| (s.t, s.dy)),
        kicked_at: None,
    };
    let started = std::time::Instant::now();
    let clock = super::timer::WallClock::new();
    super::outdir::started(&mut run);
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
    let tel_lines = tel.lines();
    tel.finish().with_context(|| format!("{}: cannot write", tel_path.display()))?;
    let summary = lock(&world).summary();
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
    if let Some(font) = font {
        plot::register_font(font);
        let p1 = save(
            &mut run,
            "xte_steer.png",
            &plot::time_plot(&report.series, summary.lane_width_m)?,
        )?;
        let p2 = save(&mut run, "path.png", &plot::path_plot(&report.series, &scene)?)?;
        println!("  plots:     {} {}", p1.display(), p2.display());
        if let Some(m) = &step_fig {
            let p3 = save(
                &mut run,
                "step.png",
                &plot::step_plot(&report.series.t, &report.series.xte, m)?,
            )?;
            println!("  step:      {}", p3.display());
        }
    } else {
        println!("  plots:     skipped (no font at {FONT}; apt install fonts-dejavu-core)");
    }
    match (&a.record, &a.record_right) {
        (Some(dir), Some(right)) => println!(
            "  frames:    {}/ and {}/ ({} PNG each; replay with `rccar replay {} --right {} --set ranging.method=stereo`)",
            dir.display(),
            right.display(),
            summary.frames,
            dir.display(),
            right.display()
        ),
        (Some(dir), None) => println!(
            "  frames:    {}/ ({} PNG; replay with `rccar replay {}`)",
            dir.display(),
            summary.frames,
            dir.display()
        ),
        _ => {}
    }
    super::outdir::finish(&mut run, RunState::from_stop(interrupted), Some(tel_lines))?;
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
    /// The (left) camera's frames.
    record: Option<PathBuf>,
    /// A stereo pair's right camera's frames.
    record_right: Option<PathBuf>,
    /// `stereo.reference = "left"`.
    reference_left: bool,
    stereo: StereoTally,
    series: plot::Series,
    /// `--kick T:DY`: (T seconds, DY metres), done once.
    kick: Option<(f64, f64)>,
    /// Time of the frame after which the kick was applied, seconds.
    kicked_at: Option<f64>,
}

/// Stereo frames and boxes of a run.
#[derive(Debug, Default)]
struct StereoTally {
    pairs: u64,
    ranged: u64,
    unmatched: u64,
}

impl Observer for Report {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        // With a pair, the reference camera's image goes to its side's folder.
        let other = ctx.frame.other.as_ref().map(|o| &o.image);
        let (left, right) = match other {
            Some(o) if !self.reference_left => (o, Some(&ctx.frame.image)),
            o => (&ctx.frame.image, o),
        };
        for (dir, img) in [(&self.record, Some(left)), (&self.record_right, right)] {
            if let (Some(dir), Some(img)) = (dir, img) {
                let p = dir.join(&ctx.frame.name);
                img.save(&p)
                    .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", p.display())))?;
            }
        }
        if let Some(s) = &ctx.record.stereo {
            self.stereo.pairs += 1;
            self.stereo.ranged += s.ranged;
            self.stereo.unmatched += s.unmatched;
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
        let mut w = lock(&self.world);
        if let Some(truth) = w.last_truth() {
            self.series.push_parts(ctx.frame.time_s, truth, ctx.output.command.steer);
        }
        if let Some((t, dy)) = self.kick {
            if self.kicked_at.is_none() && ctx.frame.time_s + 1e-9 >= t {
                w.kick(dy, 0.0);
                self.kicked_at = Some(ctx.frame.time_s);
                println!("  t={:7.2} s  kicked {:+.3} m sideways", ctx.frame.time_s, dy);
            }
        }
        Ok(Flow::Continue)
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
