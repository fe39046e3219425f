//! `rccar report DIR`: one page a student hands in for a run (the report itself is
//! `rccar::report`; here: which folder, the one-run check's verdict, printing). DIR is an output folder of
//! `rccar sim` or `rccar replay` (summary.json, telemetry.jsonl, config.json, the PNG plots);
//! writes `DIR/report.md` (images linked beside it) and `DIR/report.html` (self-contained:
//! the images base64-embedded, so it survives e-mail).
//!
//! Contents: the run (run.json), the configuration keys that differ from the defaults
//! (`config.json`, written by `rccar sim`), the summary figures with units (and the step
//! response when there is one), figures from the telemetry (frames, lane lost, RMS of the lane
//! error, RMS of the frame-to-frame steering change), and every plot of the run in DIR.
//!
//! One run only ([`rccar::run_dir::check_run`]): files of different runs side by side (run ids
//! that disagree, a telemetry with more or fewer frames than the run wrote) are refused, each
//! mismatch named (`--force` writes the report anyway, the warning on top); a plot the run
//! did not write is left out and named. DIR may also be a folder of runs (`out/sim`): its
//! `latest` is reported.

use anyhow::{bail, Result};
use clap::Args;
use rccar::report::Report;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Flags of `rccar report`.
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// A run's output folder (e.g. out/sim/latest), holding summary.json and/or
    /// telemetry.jsonl; or a folder of runs (out/sim), whose newest run (latest) is reported.
    pub dir: PathBuf,
    /// Title of the report (default: "rccar run: DIR").
    #[arg(long)]
    pub title: Option<String>,
    /// Write the report even when its files are not one run's (the mismatches on top).
    #[arg(long)]
    pub force: bool,
}

/// Runs `rccar report`.
pub fn run(a: ReportArgs) -> Result<ExitCode> {
    let dir = run_folder(&a.dir)?;
    let dir = &dir;
    // One run's files, or nothing (unless --force).
    let check = rccar::run_dir::check_run(dir)?;
    for n in &check.notes {
        eprintln!("report: note: {n}");
    }
    for f in &check.foreign {
        eprintln!(
            "report: left out {}: not written by this run (not in {})",
            dir.join(f).display(),
            rccar::run_dir::RUN_FILE
        );
    }
    if !check.problems.is_empty() {
        if !a.force {
            bail!(
                "{}: these files are not one run's: {}; report one run's folder (each run writes a new one), or give --force to write the report anyway with this warning on top",
                dir.display(),
                check.problems.join("; ")
            );
        }
        eprintln!(
            "report: WARNING: {}: these files are not one run's: {}",
            dir.display(),
            check.problems.join("; ")
        );
    }
    let title = a.title.clone().unwrap_or_else(|| format!("rccar run: {}", dir.display()));
    let report = Report::load(dir, &check, title)?;
    let bad = &report.skipped_lines;
    if !bad.is_empty() {
        let tel = dir.join("telemetry.jsonl");
        let shown: Vec<String> = bad.iter().take(5).map(|l| format!("{}:{l}", tel.display())).collect();
        eprintln!("report: skipped {} line(s) that are not JSON: {}", bad.len(), shown.join(", "));
    }
    let (md_path, html_path, html_len) = report.write(dir)?;
    println!(
        "report: {} and {} ({} plot(s) embedded, {} KB)",
        md_path.display(),
        html_path.display(),
        report.plots.len(),
        html_len / 1024
    );
    Ok(ExitCode::SUCCESS)
}

/// The run folder `given` names: itself, or the newest run of a folder of runs.
fn run_folder(given: &Path) -> Result<PathBuf> {
    let dir = match rccar::run_dir::newest_run(given)? {
        Some(target) => {
            println!("report: {} is a folder of runs; reporting the newest, {}", given.display(), target.display());
            target
        }
        None => given.to_path_buf(),
    };
    rccar::run_dir::has_run_files(&dir)?;
    Ok(dir)
}
