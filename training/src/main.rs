//! `rccar-train`: cascade training tools (see `training/README.md`).

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use rccar_train::evaluate;
use rccar_train::features::HaarMode;
use rccar_train::model::{BoostType, ModelParams};
use rccar_train::samples;
use rccar_train::simgen;
use rccar_train::train::{self, Progress, StageLog, TrainOptions};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "rccar-train",
    about = "Train and evaluate Haar cascades for rccar (OpenCV XML)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a cascade (opencv_traincascade's job).
    Train(TrainArgs),
    /// Render positives, negatives or held-out frames with the simulator.
    Gen(GenArgs),
    /// Recall, precision, FP per frame and the recall–FP curve on labelled frames.
    Evaluate(EvalArgs),
    /// Positives from template images, distorted over backgrounds (opencv_createsamples -img).
    Distort(DistortArgs),
}

#[derive(clap::Args)]
struct DistortArgs {
    /// Template images (PNG with alpha: transparent pixels show the background).
    #[arg(long = "template", required = true)]
    templates: Vec<PathBuf>,
    /// Backgrounds (bg.txt).
    #[arg(long = "bg", required = true)]
    bg: Vec<PathBuf>,
    /// Samples.
    #[arg(long, default_value_t = 1000)]
    count: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Window WxH.
    #[arg(long, default_value = "24x24")]
    window: String,
    /// Output folder (PNG crops + info.dat).
    #[arg(long)]
    out: PathBuf,
    /// Largest rotation, degrees.
    #[arg(long, default_value_t = 15.0)]
    max_angle_deg: f64,
    /// Largest corner displacement (perspective), fraction of the object size.
    #[arg(long, default_value_t = 0.12)]
    max_skew: f64,
    /// Object size range, multiples of the window.
    #[arg(long, default_value_t = 1.0)]
    min_scale: f64,
    /// Object size range, multiples of the window.
    #[arg(long, default_value_t = 3.0)]
    max_scale: f64,
}

fn run_distort(a: DistortArgs) -> anyhow::Result<ExitCode> {
    let mut templates = Vec::new();
    for t in &a.templates {
        templates.push(
            image::open(t)
                .with_context(|| format!("{}: cannot read template", t.display()))?
                .to_rgba8(),
        );
    }
    let (bgs, skipped) = samples::load_backgrounds(&a.bg)?;
    for s in &skipped {
        eprintln!("{s}");
    }
    let o = rccar_train::distort::DistortOptions {
        count: a.count,
        seed: a.seed,
        window: parse_wh(&a.window)?,
        max_angle: a.max_angle_deg.to_radians(),
        max_skew: a.max_skew,
        scale: (a.min_scale, a.max_scale),
        ..Default::default()
    };
    let imgs: Vec<image::GrayImage> = bgs.into_iter().map(|b| b.img).collect();
    let list = rccar_train::distort::generate(&templates, &imgs, &o, &a.out).map_err(anyhow::Error::msg)?;
    eprintln!("{}: {} samples", list.display(), a.count);
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct EvalArgs {
    /// Cascade XML.
    #[arg(long)]
    cascade: PathBuf,
    /// Labelled frames (info.dat).
    #[arg(long)]
    info: PathBuf,
    /// Output folder for report.json and curve.png (default: next to the cascade).
    #[arg(long)]
    out: Option<PathBuf>,
    /// minNeighbors whose numbers are printed as the operating point.
    #[arg(long, default_value_t = 3)]
    min_neighbors: u32,
    /// Scale factor.
    #[arg(long, default_value_t = 1.1)]
    scale_factor: f64,
    /// IoU for a match.
    #[arg(long, default_value_t = 0.5)]
    iou: f64,
    /// Title of the curve.
    #[arg(long)]
    title: Option<String>,
}

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

fn run_evaluate(a: EvalArgs) -> anyhow::Result<ExitCode> {
    let cascade = rccar::detect::Cascade::from_file(&a.cascade)?;
    let (lines, skipped) = samples::read_info(&a.info)?;
    for s in &skipped {
        eprintln!("{s}");
    }
    let mut frames = Vec::new();
    for l in lines {
        match samples::load_gray(&l.path) {
            Ok(img) => frames.push((l.path.display().to_string(), img, l.boxes)),
            Err(e) => eprintln!("{}:{}: skipped: {e}", a.info.display(), l.line),
        }
    }
    if frames.is_empty() {
        bail!("{}: no readable frames", a.info.display());
    }
    let mns: Vec<u32> = (0..=10).collect();
    let rep = evaluate::evaluate(
        cascade,
        &a.cascade.display().to_string(),
        &frames,
        a.scale_factor,
        a.iou,
        &mns,
        a.min_neighbors,
    )?;
    let out = a
        .out
        .unwrap_or_else(|| a.cascade.parent().map(|p| p.to_path_buf()).unwrap_or_default());
    std::fs::create_dir_all(&out).with_context(|| out.display().to_string())?;
    let json = out.join("report.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rep)?).with_context(|| json.display().to_string())?;
    if let Ok(bytes) = std::fs::read(FONT) {
        rccar::sim::plot::register_font(Box::leak(bytes.into_boxed_slice()));
        let title = a
            .title
            .clone()
            .unwrap_or_else(|| format!("{} on {}", a.cascade.display(), a.info.display()));
        let img = evaluate::curve_png(&rep, &title).map_err(anyhow::Error::msg)?;
        let png = out.join("curve.png");
        img.save(&png).with_context(|| png.display().to_string())?;
    } else {
        eprintln!("{FONT} not found (Debian fonts-dejavu-core): no curve.png");
    }
    println!("{} frames, {} boxes, IoU >= {}", rep.frames, rep.boxes, rep.iou);
    println!("minNeighbors  recall  precision  FP/frame   TP   FP  miss");
    for p in &rep.points {
        println!(
            "{:>12}  {:.4}  {:>9.4}  {:>8.4}  {:>3}  {:>3}  {:>4}{}",
            p.min_neighbors,
            p.recall,
            p.precision,
            p.fp_per_frame,
            p.true_positives,
            p.false_positives,
            p.misses,
            if p.min_neighbors == a.min_neighbors { "  <-" } else { "" }
        );
    }
    println!(
        "time per {}x{} frame: median {:.2} ms, mean {:.2} ms, max {:.2} ms",
        rep.frame_size.0, rep.frame_size.1, rep.ms_median, rep.ms_mean, rep.ms_max
    );
    println!("wrote {} and curve.png", json.display());
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct GenArgs {
    /// stop_sign | traffic_light | obstacle.
    #[arg(long)]
    kind: String,
    /// What to make.
    #[arg(long, value_enum)]
    split: simgen::Split,
    /// Samples (positives) or frames.
    #[arg(long, default_value_t = 1000)]
    count: usize,
    /// Seed (use different seeds for training and held-out data).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Track file the objects are placed on.
    #[arg(long, default_value = "config/tracks/default.toml")]
    track: PathBuf,
    /// Window WxH (default per kind: stop 16x16, light 8x20, obstacle 20x16).
    #[arg(long)]
    window: Option<String>,
    /// Object placements to spread the frames over.
    #[arg(long, default_value_t = 20)]
    scenes: usize,
    /// Nearest object distance, metres.
    #[arg(long, default_value_t = 0.2)]
    min_distance: f64,
    /// Farthest object distance, metres.
    #[arg(long, default_value_t = 1.5)]
    max_distance: f64,
}

fn parse_wh(s: &str) -> anyhow::Result<(u32, u32)> {
    let (a, b) = s.split_once('x').with_context(|| format!("`{s}`: expected WxH"))?;
    Ok((a.trim().parse()?, b.trim().parse()?))
}

fn run_gen(a: GenArgs) -> anyhow::Result<ExitCode> {
    let kind = simgen::parse_kind(&a.kind)
        .with_context(|| format!("--kind `{}`: expected stop_sign, traffic_light or obstacle", a.kind))?;
    let window = match &a.window {
        Some(s) => parse_wh(s)?,
        None => simgen::default_window(kind),
    };
    let g = simgen::SimGen::new(&a.track, rccar::config::Config::default())?;
    let opts = simgen::GenOptions {
        kind,
        split: a.split,
        count: a.count,
        seed: a.seed,
        distance_m: (a.min_distance, a.max_distance),
        window,
        scenes: a.scenes,
    };
    let t = std::time::Instant::now();
    let bar = indicatif::ProgressBar::new(a.count as u64);
    let list = g.generate(&opts, &a.out, &mut |n| bar.set_position(n as u64))?;
    bar.finish_and_clear();
    eprintln!(
        "{}: {} items in {:.1} s",
        list.display(),
        a.count,
        t.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct TrainArgs {
    /// Output folder (cascade.xml, stages.json).
    #[arg(long)]
    out: PathBuf,
    /// Positives: info.dat files (`path count x y w h ...`).
    #[arg(long = "pos", required = true)]
    pos: Vec<PathBuf>,
    /// Backgrounds: bg.txt / info.dat files (boxes on a line are kept out of the negatives).
    #[arg(long = "bg", required = true)]
    bg: Vec<PathBuf>,
    /// Window width, pixels.
    #[arg(short = 'W', long, default_value_t = 24)]
    width: i32,
    /// Window height, pixels.
    #[arg(short = 'H', long, default_value_t = 24)]
    height: i32,
    /// Stages.
    #[arg(long, default_value_t = 20)]
    num_stages: u32,
    /// Positives per stage.
    #[arg(long, default_value_t = 1000)]
    num_pos: usize,
    /// Negatives per stage.
    #[arg(long, default_value_t = 1000)]
    num_neg: usize,
    /// Per-stage hit rate.
    #[arg(long, default_value_t = 0.995)]
    min_hit_rate: f64,
    /// Per-stage false-alarm rate.
    #[arg(long, default_value_t = 0.5)]
    max_false_alarm: f64,
    /// Haar feature set.
    #[arg(long, value_enum, default_value_t = HaarMode::Basic)]
    mode: HaarMode,
    /// Boosting.
    #[arg(long, value_enum, default_value_t = BoostType::Gentle)]
    boost: BoostType,
    /// Weak tree depth (1 = stumps, 2).
    #[arg(long, default_value_t = 1)]
    max_depth: u32,
    /// Most weak classifiers per stage.
    #[arg(long, default_value_t = 100)]
    max_weak_count: u32,
    /// Memory for precomputed feature values, MiB.
    #[arg(long, default_value_t = 512)]
    mem_mb: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scale step used when mining negatives (the detector's scaleFactor).
    #[arg(long, default_value_t = 1.1)]
    scale_factor: f64,
    /// Continue from the last finished stage in --out.
    #[arg(long)]
    resume: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

/// Progress on stderr: a bar per stage (on a terminal) and one line per finished stage.
struct Bars {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress for Bars {
    fn stage_start(&mut self, stage: usize, max_weak: usize) {
        let b = indicatif::ProgressBar::new(max_weak as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template("stage {prefix:>2} [{bar:30}] {pos:>3} weak  {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_prefix(stage.to_string());
        self.bar = Some(b);
    }
    fn weak(&mut self, count: usize, hit: f64, fa: f64) {
        if let Some(b) = &self.bar {
            b.set_position(count as u64);
            b.set_message(format!("hit {hit:.4}  false alarm {fa:.4}"));
        }
    }
    fn stage_end(&mut self, l: &StageLog) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        eprintln!(
            "stage {:>2}: {:>3} weak, hit {:.4}, false alarm {:.4}, pos {}, neg {} (acceptance {:.2e}), {} features, {:.1}+{:.1}+{:.1} = {:.1} s",
            l.stage,
            l.weak_count,
            l.hit_rate,
            l.false_alarm,
            l.num_pos,
            l.num_neg,
            l.acceptance_ratio,
            l.features_used,
            l.seconds_mining,
            l.seconds_precompute,
            l.seconds_boost,
            l.seconds
        );
    }
    fn note(&mut self, msg: &str) {
        eprintln!("{msg}");
    }
}

fn run_train(a: TrainArgs) -> anyhow::Result<ExitCode> {
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().ok();
    }
    let (w, h) = (a.width as usize, a.height as usize);
    if a.width < 3 || a.height < 3 {
        bail!("window {}x{}: each side must be at least 3 px", a.width, a.height);
    }
    let (pos, skipped) = samples::load_positives(&a.pos, w, h)?;
    for s in skipped.iter().take(20) {
        eprintln!("{s}");
    }
    if skipped.len() > 20 {
        eprintln!("... {} more skipped lines/boxes", skipped.len() - 20);
    }
    eprintln!("{} positives ({} lines/boxes skipped)", pos.len(), skipped.len());
    if pos.is_empty() {
        bail!("no usable positive in {:?}", a.pos);
    }
    let (bgs, bskipped) = samples::load_backgrounds(&a.bg)?;
    for s in &bskipped {
        eprintln!("{s}");
    }
    eprintln!("{} background images", bgs.len());
    let opts = TrainOptions {
        params: ModelParams {
            width: a.width,
            height: a.height,
            mode: a.mode,
            boost: a.boost,
            min_hit_rate: a.min_hit_rate,
            max_false_alarm: a.max_false_alarm,
            max_depth: a.max_depth,
            max_weak_count: a.max_weak_count,
            num_stages: a.num_stages,
        },
        num_pos: a.num_pos,
        num_neg: a.num_neg,
        mem_mb: a.mem_mb,
        seed: a.seed,
        scale_factor: a.scale_factor,
    };
    let t = std::time::Instant::now();
    let out = train::train(&opts, &pos, &bgs, &a.out, a.resume, &mut Bars { bar: None })
        .with_context(|| format!("training into {}", a.out.display()))?;
    eprintln!(
        "{}: {} stages in {:.1} s ({})",
        out.xml.display(),
        out.stages,
        t.elapsed().as_secs_f64(),
        out.reason
    );
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Train(a) => run_train(a),
        Cmd::Gen(a) => run_gen(a),
        Cmd::Evaluate(a) => run_evaluate(a),
        Cmd::Distort(a) => run_distort(a),
    };
    match r {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
