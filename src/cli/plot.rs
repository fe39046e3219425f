//! `rccar plot FILE.jsonl|RUN [FILE2.jsonl|RUN2 ...] --y error,steer [--x t] [--out plot.png]
//! [--label NAME ...]`: any numeric telemetry fields (dotted paths into the nested JSON, e.g.
//! `truth.offset_m`) of one or more runs against time, one panel per field, one colour per
//! run. Labs compare runs this way (e.g. `steering.kd` 0 vs 0.1).
//!
//! Aliases: `t` = `time_s`, `xte` = `truth.xte` = `truth.offset_m` (the true cross-track error,
//! metres). `null` (e.g. `error` while the lane is lost) leaves a gap. Units are those of the
//! telemetry (docs/sim.md, docs/lane.md). Reading the fields is `rccar::fields`.
//!
//! Bounded (the bounds are `rccar::fields`'): at most 16 panels (the image is 1000 × (40 +
//! 260·fields) pixels), 8 runs (one colour each), 10 million points over all of them, lines of
//! at most 1 MiB; the files are read line by line, keeping only the plotted numbers.

use anyhow::{Context, Result};
use clap::Args;
use rccar::fields::{default_label, panels, plot_fields, resolve, shown};
use rccar::sim::plot::{self, Trace};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Flags of `rccar plot`.
#[derive(Args, Debug)]
pub struct PlotArgs {
    /// Telemetry files (JSONL, one record per frame), or run folders holding one
    /// (`telemetry.jsonl` inside, e.g. out/sim/20261129-140311; `out/sim` = its latest run);
    /// at most 8 (one colour each).
    #[arg(required = true, value_name = "FILE.jsonl|RUN")]
    pub files: Vec<PathBuf>,
    /// Fields to plot, comma-separated; dotted paths reach into nested records
    /// (`truth.offset_m`). One panel each, at most 16.
    #[arg(long, short, value_delimiter = ',', required = true)]
    pub y: Vec<String>,
    /// The x axis field.
    #[arg(long, short, default_value = "t")]
    pub x: String,
    /// Output PNG.
    #[arg(long, short, default_value = "plot.png")]
    pub out: PathBuf,
    /// Legend name of each file, in order (default: the file's folder name, or its stem).
    #[arg(long)]
    pub label: Vec<String>,
}

/// The telemetry file a `rccar plot` argument names: the file itself, a run folder's
/// `telemetry.jsonl` (what `rccar sim`, `replay` and `drive` write into their run folders), or
/// for a command's output folder (`out/sim`) that of its `latest` run.
fn telemetry_of(given: &Path) -> Result<PathBuf> {
    if !given.is_dir() {
        return Ok(given.to_path_buf());
    }
    // A folder of runs (`out/sim`) stands for its newest run (named by the folder `latest`
    // points at), as for `rccar report`.
    let run = rccar::run_dir::newest_run(given)?.unwrap_or_else(|| given.to_path_buf());
    let file = run.join("telemetry.jsonl");
    if !file.is_file() {
        anyhow::bail!(
            "{}: a folder without telemetry.jsonl; give a run's folder (e.g. out/sim/latest) or a telemetry file",
            given.display()
        );
    }
    Ok(file)
}

/// Runs `rccar plot`.
pub fn run(a: PlotArgs) -> Result<ExitCode> {
    let fields = plot_fields(&a.y, a.files.len(), a.label.len())?;
    let x = resolve(a.x.trim()).to_string();
    let mut traces = Vec::new();
    let mut points = 0usize;
    for (k, given) in a.files.iter().enumerate() {
        let file = &telemetry_of(given)?;
        let read = panels(file, &a.x, &fields, &mut points)?;
        let (records, panels) = (read.records, read.panels);
        let label = a.label.get(k).cloned().unwrap_or_else(|| default_label(file));
        println!("plot: {} ({records} records) as `{label}`", file.display());
        traces.push(Trace { label, panels });
    }
    let font = plot::system_font()
        .with_context(|| format!("no font at {}; apt install fonts-dejavu-core", plot::SYSTEM_FONT))?;
    plot::register_font(font);
    // Panel titles and axis names: the field as typed, and what an alias stands for.
    let names: Vec<String> = fields.iter().map(|f| shown(f)).collect();
    let x_name = if x == "time_s" { "time_s (s)".to_string() } else { shown(a.x.trim()) };
    let img = plot::fields_plot(&x_name, &names, &traces)?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    img.save(&a.out).with_context(|| format!("{}: cannot write", a.out.display()))?;
    println!("  wrote {} ({}×{} px, {} panel(s))", a.out.display(), img.width(), img.height(), fields.len());
    Ok(ExitCode::SUCCESS)
}
