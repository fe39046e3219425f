//! `rccar replay DIR`: the pipeline over a folder of recorded frames.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rccar::annotate::annotate;
use rccar::lane::LaneStatus;
use rccar::drive::{Clock, Flow, FrameContext, Level, LoopEnd, LoopError, NoClock, Observer, StopReason};
use rccar::session::{CameraSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::source::FrameError;
use rccar::timing::{NoTimer, StageTimer};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

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
    /// Output folder for telemetry.jsonl and annotated frames: new or empty, never the
    /// recording itself (default: a new folder under out/replay/, with out/replay/latest).
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
    if let (Some(r), false) = (&a.right, cfg.ranging.method == rccar::config::RangingMethod::Stereo) {
        anyhow::bail!(
            "--right {}: ranging.method is {:?}, so a second camera would not be used; add --set ranging.method=stereo (docs/stereo.md)",
            r.display(),
            cfg.ranging.method.name()
        );
    }
    let stop = super::signals::install();
    let clock: Arc<dyn Clock + Send + Sync> = if a.no_timing { Arc::new(NoClock) } else { Arc::new(super::timer::WallClock::new()) };
    let timer: Box<dyn StageTimer + Send> = if a.no_timing { Box::new(NoTimer) } else { Box::new(WallTimer::new()) };
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: CameraSpec::Folder(a.dir.clone()),
            right: a.right.clone().map(CameraSpec::Folder),
            timing: Timing::LockStep,
        },
        SinkSpec::DryRun,
    );
    // The run folder: new, never the recording itself or inside it.
    let mut reads = vec![("DIR", a.dir.as_path())];
    reads.extend(a.right.as_deref().map(|r| ("--right", r)));
    let mut run = super::outdir::create("replay", a.out.as_deref(), "out/replay", &[], &reads)?;
    let tel_path = run.join("telemetry.jsonl");
    spec.telemetry = Some(tel_path.clone());
    let env = SessionEnv {
        clock,
        stop,
        timer,
        say: Arc::new(|level, line: &str| match level {
            Level::Info => super::signals::say(line),
            Level::Warn => super::signals::say_err(line),
        }),
    };
    let mut session = Session::build(&cfg, spec, env).map_err(|e| match e {
        rccar::session::SessionError::Pair(m) => anyhow::anyhow!("--right: {m}"),
        e => e.into(),
    })?;
    for (level, line) in session.notes() {
        match level {
            Level::Info => println!("replay: {line}"),
            Level::Warn => eprintln!("{line}"),
        }
    }
    let annotate_dir = run.join("annotated");
    let annotate_frames = cfg.replay.annotate && !a.no_annotate;
    if annotate_frames {
        run.note_file("annotated");
        std::fs::create_dir_all(&annotate_dir).with_context(|| format!("{}: cannot create", annotate_dir.display()))?;
    }
    let bar = ProgressBar::new(session.source().len_hint().unwrap_or(0) as u64);
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
    // Replay moves nothing: its sink forgets the commands (they are in the telemetry).
    super::outdir::started(&mut run);
    let end = session.run(&mut s);
    s.bar.finish_and_clear();
    let outcome = session.finish()?;
    let end = end?;
    let stopped = match end {
        LoopEnd::Stopped(why) => Some(why),
        _ => None,
    };
    super::outdir::finish(&mut run, rccar::run_dir::RunState::from_stop(stopped), outcome.telemetry.as_ref().map(|t| t.1))?;

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
    println!("  telemetry: {}", tel_path.display());
    if annotate_frames {
        println!("  annotated frames: {}/", annotate_dir.display());
    }
    if let LoopEnd::Stopped(why) = end {
        println!(
            "replay: interrupted ({}) after {} frames; telemetry holds every frame processed",
            match why {
                StopReason::Terminate => "SIGTERM",
                StopReason::Hangup => "SIGHUP",
                StopReason::Quit => "SIGQUIT",
                _ => "Ctrl-C",
            },
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
