//! `rccar replay DIR`: the pipeline over a folder of recorded frames.

use super::common::ConfigArgs;
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rccar::drive::{Flow, FrameContext, LoopEnd, LoopError, Observer};
use rccar::session::replay::ReplayTally;
use rccar::session::{CameraSpec, Session, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::source::FrameError;
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// Folder of PNG/JPEG frames, replayed in name order; or `'pipe:FORMAT:COMMAND'`: every
    /// frame the command writes, in order, frame i at i/fps (e.g. `rccar sim --frames-to -`).
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

/// The progress bar: one step per frame, the skipped frames said above it.
struct Bar(ProgressBar);

impl Observer for Bar {
    fn on_frame(&mut self, _ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.0.inc(1);
        Ok(Flow::Continue)
    }
    fn on_skip(&mut self, e: &FrameError) {
        self.0.inc(1);
        self.0.println(format!("skipped {e}"));
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
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: match a.dir.to_str().filter(|d| d.starts_with("pipe:")) {
                Some(p) => CameraSpec::parse(p).map_err(anyhow::Error::msg)?,
                None => CameraSpec::Folder(a.dir.clone()),
            },
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
    let env = super::timer::session_env(a.no_timing, stop);
    let mut session = Session::build(&cfg, spec, env).map_err(|e| match e {
        rccar::session::SessionError::Pair(m) => anyhow::anyhow!("--right: {m}"),
        e => e.into(),
    })?;
    super::signals::notes("replay", &session);
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
    let mut bar = Bar(bar);
    let mut s = ReplayTally::new(annotate_frames.then(|| annotate_dir.clone()), cfg.warp.src);
    // Replay moves nothing: its sink forgets the commands (they are in the telemetry).
    super::outdir::started(&mut run);
    let end = {
        let mut obs: [&mut dyn Observer; 2] = [&mut bar, &mut s];
        session.run(&mut obs)
    };
    bar.0.finish_and_clear();
    let outcome = session.finish()?;
    let end = end?;
    if let Some(f) = &outcome.fault {
        eprintln!("replay: {f}");
    }
    let stopped = match end {
        LoopEnd::Stopped(why) => Some(why),
        _ => None,
    };
    super::outdir::finish(&mut run, rccar::run_dir::RunState::from_stop(stopped), outcome.telemetry.as_ref().map(|t| t.1))?;

    println!("replayed {} frames from {}", s.frames, a.dir.display());
    for line in s.lines(!a.no_timing, a.right.is_some()) {
        println!("{line}");
    }
    println!("  telemetry: {}", tel_path.display());
    if annotate_frames {
        println!("  annotated frames: {}/", annotate_dir.display());
    }
    if let LoopEnd::Stopped(why) = end {
        println!(
            "replay: interrupted ({}) after {} frames; telemetry holds every frame processed",
            why.said(),
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
