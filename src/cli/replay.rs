//! `rccar replay DIR`: the pipeline over a folder of recorded frames.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rccar::annotate::annotate;
use rccar::lane::LaneStatus;
use rccar::drive::{Clock, Driver, Flow, FrameContext, LoopEnd, LoopError, NoClock, Observer, Parts, StopReason};
use rccar::pipeline::Pipeline;
use rccar::sink::NullSink;
use rccar::source::{FrameError, FrameSource, ReplayDir};
use rccar::telemetry::JsonlWriter;
use rccar::timing::{NoTimer, StageTimer};
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// Folder of PNG/JPEG frames, replayed in name order.
    pub dir: PathBuf,
    /// A stereo pair: DIR holds the left camera's frames and DIR2 the right camera's, with the
    /// same file names (as `rccar sim --record DIR --record-right DIR2` writes them); needs
    /// `ranging.method = "stereo"`. Frames are paired by time (`stereo.max_skew_ms`).
    #[arg(long, value_name = "DIR2")]
    pub right: Option<PathBuf>,
    /// Output folder for telemetry.jsonl and annotated frames: new or empty, and not inside
    /// DIR. Default: a new folder per run, out/replay/<YYYYmmdd-HHMMSS>/, with
    /// out/replay/latest pointing at the newest.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Don't write annotated frames (overrides `replay.annotate`).
    #[arg(long)]
    pub no_annotate: bool,
    /// Write zeros instead of measured stage times (reproducible output).
    #[arg(long)]
    pub no_timing: bool,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Summary of a replay, also used by tests through the JSONL; it also writes the annotated
/// frames.
struct Summary {
    frames: u64,
    skipped: Vec<String>,
    status: [u64; 4],
    abs_err_sum: f64,
    total_us: Vec<u32>,
    bar: ProgressBar,
    annotate_dir: Option<PathBuf>,
    warp_src: [[f64; 2]; 4],
    /// Stereo pairs, boxes ranged by stereo, without a match, largest |skew| ms, pairs dropped.
    stereo: (u64, u64, u64, f64, u64),
}

impl Observer for Summary {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.bar.inc(1);
        let out = ctx.output;
        self.frames += 1;
        self.status[out.lane.status as usize] += 1;
        self.abs_err_sum += out.lane.error_px.map_or(0.0, f64::abs);
        self.total_us.push(out.stage_us.total_us);
        if let Some(dir) = &self.annotate_dir {
            let img = annotate(
                &ctx.frame.image,
                &self.warp_src,
                ctx.pipeline.lane().warp_map().homography(),
                ctx.pipeline.lane().images(),
                &out.lane,
                &out.command,
            );
            let p = dir.join(rccar::source::output_name(&ctx.frame.name));
            img.save(&p)
                .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", p.display())))?;
        }
        Ok(Flow::Continue)
    }

    fn decorate(&mut self, record: &mut rccar::telemetry::FrameRecord) {
        if let Some(st) = &record.stereo {
            self.stereo.0 += 1;
            self.stereo.1 += st.ranged;
            self.stereo.2 += st.unmatched;
            self.stereo.3 = self.stereo.3.max(st.skew_ms.abs());
            self.stereo.4 = st.pairs_dropped;
        }
    }

    fn on_skip(&mut self, e: &FrameError) {
        self.bar.inc(1);
        self.bar.println(format!("skipped {e}"));
        self.skipped.push(e.to_string());
    }
}

/// Runs the replay.
pub fn run(a: ReplayArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    let mut pipeline = Pipeline::new(&cfg)?;
    if let Some(r) = &a.right {
        if cfg.ranging.method != rccar::config::RangingMethod::Stereo {
            bail!(
                "--right {}: ranging.method is {:?}, so a second camera would not be used; add --set ranging.method=stereo (docs/stereo.md)",
                r.display(),
                cfg.ranging.method.name()
            );
        }
        rccar::drive::stereo::install(&mut pipeline);
        if let Some(line) = rccar::drive::stereo::calibration_line(&pipeline, &cfg) {
            println!("{line}");
        }
    } else {
        super::common::warn_single_camera(&cfg);
    }
    pipeline.set_detector(super::common::load_detector(&cfg)?);
    let (w, h) = pipeline.frame_size();
    // Frames smaller than the ROI's extent are refused instead of being blown up.
    let min_size = {
        let max_x = cfg.warp.src.iter().map(|p| p[0]).fold(0.0f64, f64::max);
        let max_y = cfg.warp.src.iter().map(|p| p[1]).fold(0.0f64, f64::max);
        ((max_x.ceil() as u32).min(w), (max_y.ceil() as u32).min(h))
    };
    // A recording of `rccar drive --record`: replayed with the time steps the car saw.
    let open = |dir: &PathBuf| -> Result<ReplayDir> {
        let (source, recorded) = ReplayDir::open_recording(dir, cfg.camera.fps, w, h, min_size)?;
        if let Some(t) = recorded {
            println!(
                "replay: a recording; frame times from its telemetry ({} frames)",
                t.times.len()
            );
            for l in &t.cut_lines {
                let tel = dir.join(rccar::record::TELEMETRY_FILE);
                println!(
                    "  skipped {}:{l}: a cut line (not JSON); its frame has no time and is skipped",
                    tel.display()
                );
            }
        }
        Ok(source)
    };
    let left = open(&a.dir)?;
    let ignored: Vec<String> = left.ignored().to_vec();
    let mut source: Box<dyn FrameSource> = match &a.right {
        None => Box::new(left),
        Some(rdir) => {
            let right = open(rdir)?;
            super::common::check_pair("--right", &a.dir, left.files(), rdir, right.files())?;
            println!(
                "replay: stereo pair, left {} and right {} ({} frames each), reference {}",
                a.dir.display(),
                rdir.display(),
                left.files().len(),
                cfg.stereo.reference
            );
            Box::new(
                rccar::drive::stereo::StereoFrames::from_config(left, right, &cfg)
                    .with_labels(a.dir.display().to_string(), rdir.display().to_string()),
            )
        }
    };
    // The run folder: new, never the recording itself or inside it.
    let mut reads = vec![("DIR", a.dir.as_path())];
    reads.extend(a.right.as_deref().map(|r| ("--right", r)));
    let mut run = super::outdir::create("replay", a.out.as_deref(), "out/replay", &[], &reads)?;
    let annotate_dir = run.join("annotated");
    let annotate_frames = cfg.replay.annotate && !a.no_annotate;
    if annotate_frames {
        run.note_file("annotated");
        std::fs::create_dir_all(&annotate_dir).with_context(|| format!("{}: cannot create", annotate_dir.display()))?;
    }
    let tel_path = run.join("telemetry.jsonl");
    let mut tel = JsonlWriter::new(
        std::fs::File::create(&tel_path).with_context(|| format!("{}: cannot create", tel_path.display()))?,
        tel_path.display().to_string(),
    );

    let bar = ProgressBar::new(source.len_hint().unwrap_or(0) as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut s = Summary {
        frames: 0,
        skipped: vec![],
        status: [0; 4],
        abs_err_sum: 0.0,
        total_us: vec![],
        bar,
        annotate_dir: annotate_frames.then(|| annotate_dir.clone()),
        warp_src: cfg.warp.src,
        stereo: (0, 0, 0, 0.0, 0),
    };
    let stop = super::signals::install();
    let mut wall = WallTimer::new();
    let mut none = NoTimer;
    let timer: &mut dyn StageTimer = if a.no_timing { &mut none } else { &mut wall };
    let wall_clock = super::timer::WallClock::new();
    let clock: &dyn Clock = if a.no_timing { &NoClock } else { &wall_clock };
    super::outdir::started(&mut run);
    let end = {
        let mut obs: [&mut dyn Observer; 2] = [&mut tel, &mut s];
        // Replay moves nothing: its sink forgets the commands (they are in the telemetry).
        Driver::new(cfg.camera.fps).run(Parts {
            source: &mut *source,
            pipeline: &mut pipeline,
            sink: &mut NullSink,
            stop: &stop,
            clock,
            timer,
            observer: &mut obs,
        })?
    };
    s.bar.finish_and_clear();
    let tel_lines = tel.lines();
    tel.finish().with_context(|| format!("{}: cannot write", tel_path.display()))?;
    let stopped = match end {
        LoopEnd::Stopped(why) => Some(why),
        _ => None,
    };
    super::outdir::finish(&mut run, rccar::run_dir::RunState::from_stop(stopped), Some(tel_lines))?;

    let seen = s.status[LaneStatus::Both as usize]
        + s.status[LaneStatus::LeftOnly as usize]
        + s.status[LaneStatus::RightOnly as usize];
    println!("replayed {} frames from {}", s.frames, a.dir.display());
    println!(
        "  lane: both lines {}, left only {}, right only {}, lost {}",
        s.status[0], s.status[1], s.status[2], s.status[3]
    );
    if seen > 0 {
        println!(
            "  mean |error| {:.2} px over {} frames with a lane",
            s.abs_err_sum / seen as f64,
            seen
        );
    }
    if !a.no_timing && !s.total_us.is_empty() {
        let mut t = s.total_us.clone();
        t.sort_unstable();
        println!(
            "  pipeline time per frame: median {} us, max {} us (incl. first-frame warm-up)",
            t[t.len() / 2],
            t[t.len() - 1]
        );
    }
    if a.right.is_some() {
        let (pairs, ranged, unmatched, skew, dropped) = s.stereo;
        println!(
            "  stereo: {pairs} pairs (largest skew {skew:.1} ms, {dropped} frame(s) dropped without a partner); detector boxes ranged by stereo {ranged}, without a match {unmatched}"
        );
    }
    println!("  skipped {} frame(s)", s.skipped.len());
    for k in &s.skipped {
        println!("    {k}");
    }
    for i in &ignored {
        println!("  ignored (not .png/.jpg/.jpeg): {i}");
    }
    println!("  telemetry: {}", tel_path.display());
    if annotate_frames {
        println!("  annotated frames: {}/", annotate_dir.display());
    }
    if let LoopEnd::Stopped(why) = end {
        println!(
            "replay: interrupted ({}) after {} frames; telemetry holds every frame processed",
            if why == StopReason::Terminate { "SIGTERM" } else { "Ctrl-C" },
            s.frames
        );
        return Ok(ExitCode::from(why.exit_code()));
    }
    Ok(if s.frames == 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
