//! `rccar replay DIR`: the pipeline over a folder of recorded frames.

use super::common::ConfigArgs;
use super::timer::WallTimer;
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rccar::annotate::annotate;
use rccar::lane::LaneStatus;
use rccar::pipeline::Pipeline;
use rccar::source::{FrameSource, ReplayDir};
use rccar::telemetry::FrameRecord;
use rccar::timing::{NoTimer, StageTimer};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// Folder of PNG/JPEG frames, replayed in name order.
    pub dir: PathBuf,
    /// Output folder for telemetry.jsonl and annotated frames.
    #[arg(long, short, default_value = "out/replay")]
    pub out: PathBuf,
    /// Don't write annotated frames (overrides `replay.annotate`).
    #[arg(long)]
    pub no_annotate: bool,
    /// Write zeros instead of measured stage times (reproducible output).
    #[arg(long)]
    pub no_timing: bool,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Summary of a replay, also used by tests through the JSONL.
struct Summary {
    frames: u64,
    skipped: Vec<String>,
    status: [u64; 4],
    abs_err_sum: f64,
    total_us: Vec<u32>,
}

/// Runs the replay.
pub fn run(a: ReplayArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    let mut pipeline = Pipeline::new(&cfg)?;
    pipeline.set_detector(super::common::load_detector(&cfg)?);
    let (w, h) = pipeline.frame_size();
    // Frames smaller than the ROI's extent are refused instead of being blown up.
    let min_size = {
        let max_x = cfg.warp.src.iter().map(|p| p[0]).fold(0.0f64, f64::max);
        let max_y = cfg.warp.src.iter().map(|p| p[1]).fold(0.0f64, f64::max);
        ((max_x.ceil() as u32).min(w), (max_y.ceil() as u32).min(h))
    };
    let mut source = ReplayDir::open(&a.dir, cfg.camera.fps, w, h, min_size)?;
    let annotate_dir = a.out.join("annotated");
    let annotate_frames = cfg.replay.annotate && !a.no_annotate;
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    if annotate_frames {
        std::fs::create_dir_all(&annotate_dir).with_context(|| format!("{}: cannot create", annotate_dir.display()))?;
    }
    let tel_path = a.out.join("telemetry.jsonl");
    let mut tel = std::io::BufWriter::new(
        std::fs::File::create(&tel_path).with_context(|| format!("{}: cannot create", tel_path.display()))?,
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
    };
    let mut last_time: Option<f64> = None;
    let mut wall = WallTimer::new();
    let mut none = NoTimer;
    while let Some(item) = source.next_frame() {
        bar.inc(1);
        let frame = match item {
            Ok(f) => f,
            Err(e) => {
                bar.println(format!("skipped {e}"));
                s.skipped.push(e.to_string());
                continue;
            }
        };
        // dt counts skipped frames: time passed even if we could not see.
        let dt = last_time.map_or(1.0 / cfg.camera.fps, |t| frame.time_s - t);
        last_time = Some(frame.time_s);
        let timer: &mut dyn StageTimer = if a.no_timing { &mut none } else { &mut wall };
        let out = pipeline.step(&frame.image, dt, timer);
        let rec = FrameRecord::new(
            frame.index,
            &frame.name,
            frame.time_s,
            &out.lane,
            &out.command,
            out.stage_us,
        )
        .with_pipeline(&out, &pipeline);
        writeln!(tel, "{}", rec.to_json_line())?;
        s.frames += 1;
        s.status[out.lane.status as usize] += 1;
        s.abs_err_sum += out.lane.error_px.map_or(0.0, f64::abs);
        s.total_us.push(out.stage_us.total_us);
        if annotate_frames {
            let img = annotate(
                &frame.image,
                &cfg.warp.src,
                pipeline.lane().warp_map().homography(),
                pipeline.lane().images(),
                &out.lane,
                &out.command,
            );
            let p = annotate_dir.join(rccar::source::output_name(&frame.name));
            img.save(&p).with_context(|| format!("{}: cannot write", p.display()))?;
        }
    }
    bar.finish_and_clear();
    tel.flush()?;

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
    println!("  skipped {} frame(s)", s.skipped.len());
    for k in &s.skipped {
        println!("    {k}");
    }
    for i in source.ignored() {
        println!("  ignored (not .png/.jpg/.jpeg): {i}");
    }
    println!("  telemetry: {}", tel_path.display());
    if annotate_frames {
        println!("  annotated frames: {}/", annotate_dir.display());
    }
    Ok(if s.frames == 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
