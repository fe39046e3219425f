//! `rccar-train`: cascade training tools (see `training/README.md`).

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use rccar_train::features::HaarMode;
use rccar_train::model::{BoostType, ModelParams};
use rccar_train::samples;
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
    };
    match r {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
