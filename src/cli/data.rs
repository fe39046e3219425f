//! `rccar data ls|cut|merge|export|import`: recordings as datasets (docs/data.md). The work is
//! `rccar::dataset`; here: flags, the clock for a tub's timestamps, and the report.
//!
//! Exit codes: 0 done; 1 done, but records were skipped (each named on stderr, the output holds
//! the rest); 2 nothing done (bad input named with its file and line or key, an output folder
//! that is not new and empty, a drop range that matches nothing).

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use rccar::dataset::{self, tub, write::FrameOptions, Dataset, FrameRange, Skipped};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `rccar data …`
#[derive(Subcommand, Debug)]
pub enum DataCmd {
    /// Frames, duration, driving modes and steering/throttle histograms of recordings or Donkey
    /// tubs, with a warning when the labels are unbalanced.
    Ls(LsArgs),
    /// Copy a recording without some frame ranges (like Donkey's tubclean) into a new folder.
    Cut(CutArgs),
    /// Join recordings (or tubs) one after the other into a new recording.
    Merge(MergeArgs),
    /// Write a recording as a Donkey Car tub v2 (manifest.json, catalogs, images/).
    Export(ExportArgs),
    /// Read a Donkey Car tub v2 into a new rccar recording (`rccar replay` plays it).
    Import(ImportArgs),
}

/// Flags of `rccar data ls`.
#[derive(Args, Debug)]
pub struct LsArgs {
    /// Recordings (folders with telemetry.jsonl) or Donkey tubs (folders with manifest.json).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// The telemetry of a folder of frames from `rccar sim --record DIR -o RUN`
    /// (RUN/telemetry.jsonl); only with one DIR.
    #[arg(long, value_name = "FILE")]
    pub telemetry: Option<PathBuf>,
    /// Print one JSON object per folder instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Flags of `rccar data cut`.
#[derive(Args, Debug)]
pub struct CutArgs {
    /// The recording (or tub) to cut; it is only read.
    pub dir: PathBuf,
    /// Frames to leave out, by frame number: `A..B` (B kept), `A..=B`, `A..`, `..B` or `A`
    /// (repeatable). Without any, the recording is copied whole.
    #[arg(long = "drop", value_name = "RANGE")]
    pub drops: Vec<FrameRange>,
    /// The new recording: a new or empty folder.
    #[arg(long, short)]
    pub out: PathBuf,
    /// The telemetry of a `rccar sim --record` folder of frames (RUN/telemetry.jsonl).
    #[arg(long, value_name = "FILE")]
    pub telemetry: Option<PathBuf>,
    #[command(flatten)]
    pub frames: FrameArgs,
}

/// Flags of `rccar data merge`.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// Recordings or tubs, joined in this order.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// The new recording: a new or empty folder.
    #[arg(long, short)]
    pub out: PathBuf,
    #[command(flatten)]
    pub frames: FrameArgs,
}

/// Flags of `rccar data export`.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The recording to export.
    pub dir: PathBuf,
    /// The tub to write: a new or empty folder.
    #[arg(long, value_name = "OUT")]
    pub tub: PathBuf,
    /// The telemetry of a `rccar sim --record` folder of frames (RUN/telemetry.jsonl).
    #[arg(long, value_name = "FILE")]
    pub telemetry: Option<PathBuf>,
    #[command(flatten)]
    pub frames: FrameArgs,
}

/// Flags of `rccar data import`.
#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The Donkey tub v2 (the folder holding manifest.json).
    pub tub: PathBuf,
    /// The new recording: a new or empty folder.
    #[arg(long, short)]
    pub out: PathBuf,
    #[command(flatten)]
    pub frames: FrameArgs,
}

/// How frames are written.
#[derive(Args, Debug)]
pub struct FrameArgs {
    /// Resize every frame to WxH, e.g. `160x120` (Donkey's camera) or `320x240` (rccar's, so
    /// that `rccar replay` can use a Donkey tub's small frames). Default: keep each frame's size
    /// (JPEG frames are then copied byte for byte).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// JPEG quality for frames that are encoded (PNG frames, resized frames), 1..=100.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub quality: u8,
}

impl FrameArgs {
    fn options(&self) -> FrameOptions {
        FrameOptions {
            size: self.size,
            quality: self.quality,
        }
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: give WxH, e.g. 160x120"))?;
    let p = |t: &str| {
        t.parse::<u32>()
            .ok()
            .filter(|v| (16..=4096).contains(v))
            .ok_or_else(|| format!("`{s}`: sides are 16..4096 pixels"))
    };
    Ok((p(w)?, p(h)?))
}

/// Runs a `data` subcommand.
pub fn run(c: DataCmd) -> Result<ExitCode> {
    match c {
        DataCmd::Ls(a) => ls(a),
        DataCmd::Cut(a) => cut(a),
        DataCmd::Merge(a) => merge(a),
        DataCmd::Export(a) => export(a),
        DataCmd::Import(a) => import(a),
    }
}

fn open(dir: &Path, telemetry: Option<&Path>) -> Result<Dataset> {
    Ok(match telemetry {
        Some(t) => Dataset::open_frames(dir, t)?,
        None => Dataset::open(dir)?,
    })
}

/// Says the skipped records on stderr (the first ten and how many more).
fn say_skipped(what: &str, skipped: &[Skipped]) {
    if skipped.is_empty() {
        return;
    }
    let e = super::signals::say_err;
    e(&format!("{what}: {} record(s) skipped:", skipped.len()));
    for s in skipped.iter().take(10) {
        e(&format!("  {s}"));
    }
    if skipped.len() > 10 {
        e(&format!("  … and {} more", skipped.len() - 10));
    }
}

fn exit(skipped: usize) -> ExitCode {
    if skipped > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

fn ls(a: LsArgs) -> Result<ExitCode> {
    if a.telemetry.is_some() && a.dirs.len() != 1 {
        bail!("--telemetry names the telemetry of one folder of frames: give one DIR with it");
    }
    let mut skipped = 0;
    let mut all = Vec::new();
    for d in &a.dirs {
        let ds = open(d, a.telemetry.as_deref())?;
        let st = ds.stats();
        skipped += ds.skipped.len();
        if a.json {
            let v = serde_json::json!({
                "path": d,
                "kind": ds.kind.name(),
                "frame_size": ds.frame_size(),
                "skipped": ds.skipped.len(),
                "deleted": ds.deleted,
                "unlabelled_frames": ds.unlabelled_frames,
                "times_adjusted": ds.times_adjusted,
                "stats": st,
            });
            println!("{v}");
        } else {
            let size = ds.frame_size().map_or("?".into(), |(w, h)| format!("{w}×{h}"));
            let span = st
                .frame_span
                .map_or(String::new(), |(f, l)| format!(" (frames {f}..={l})"));
            println!(
                "{}: {}, {} frames{span}, {:.2} s, {size}",
                d.display(),
                ds.kind.name(),
                st.frames,
                st.duration_s
            );
            let mut notes = Vec::new();
            if ds.deleted > 0 {
                notes.push(format!("{} deleted in the tub (left out)", ds.deleted));
            }
            if !ds.skipped.is_empty() {
                notes.push(format!("{} records skipped (below)", ds.skipped.len()));
            }
            if ds.unlabelled_frames > 0 {
                notes.push(format!(
                    "{} frame files without telemetry (ignored)",
                    ds.unlabelled_frames
                ));
            }
            if ds.times_adjusted > 0 {
                notes.push(format!(
                    "{} timestamps not increasing (set 1 ms after the frame before)",
                    ds.times_adjusted
                ));
            }
            if !notes.is_empty() {
                println!("  {}", notes.join("; "));
            }
            for l in st.lines() {
                println!("  {l}");
            }
        }
        say_skipped(&d.display().to_string(), &ds.skipped);
        all.extend(ds.samples);
    }
    if a.dirs.len() > 1 && !a.json {
        let st = dataset::LabelStats::of(&all);
        println!(
            "all {} folders: {} frames, {:.2} s",
            a.dirs.len(),
            st.frames,
            st.duration_s
        );
        for l in st.lines() {
            println!("  {l}");
        }
    }
    Ok(exit(skipped))
}

fn cut(a: CutArgs) -> Result<ExitCode> {
    let ds = open(&a.dir, a.telemetry.as_deref())?;
    say_skipped(&a.dir.display().to_string(), &ds.skipped);
    let kept = dataset::cut(&ds.samples, &a.drops)?;
    let placed = dataset::unchanged(&kept);
    let mut inputs = vec![a.dir.as_path()];
    inputs.extend(a.telemetry.as_deref());
    let r = dataset::write::write_recording(&a.out, &placed, &inputs, a.frames.options())?;
    say_skipped(&a.out.display().to_string(), &r.skipped);
    println!(
        "cut: {} of {} frames kept ({} dropped by {} range(s)) into {}",
        r.frames,
        ds.samples.len(),
        ds.samples.len() - kept.len(),
        a.drops.len(),
        a.out.display()
    );
    Ok(exit(ds.skipped.len() + r.skipped.len()))
}

fn merge(a: MergeArgs) -> Result<ExitCode> {
    let mut parts = Vec::new();
    let mut skipped = 0;
    for d in &a.dirs {
        let ds = open(d, None)?;
        say_skipped(&d.display().to_string(), &ds.skipped);
        skipped += ds.skipped.len();
        parts.push((d.display().to_string(), ds.samples));
    }
    let placed = dataset::merge(&parts);
    let inputs: Vec<&Path> = a.dirs.iter().map(PathBuf::as_path).collect();
    let r = dataset::write::write_recording(&a.out, &placed, &inputs, a.frames.options())?;
    say_skipped(&a.out.display().to_string(), &r.skipped);
    let counts: Vec<String> = parts.iter().map(|(_, s)| s.len().to_string()).collect();
    println!(
        "merge: {} frames ({}) into {}",
        r.frames,
        counts.join(" + "),
        a.out.display()
    );
    Ok(exit(skipped + r.skipped.len()))
}

fn export(a: ExportArgs) -> Result<ExitCode> {
    let ds = open(&a.dir, a.telemetry.as_deref())?;
    say_skipped(&a.dir.display().to_string(), &ds.skipped);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let opts = tub::TubOptions {
        frames: a.frames.options(),
        created_at: now.as_secs_f64(),
        start_ms: now.as_millis() as i64,
        session_id: format!("{}_0", yy_mm_dd(now.as_secs() as i64)),
    };
    let mut inputs = vec![a.dir.as_path()];
    inputs.extend(a.telemetry.as_deref());
    let r = tub::write(&a.tub, &ds.samples, &inputs, &opts)?;
    say_skipped(&a.tub.display().to_string(), &r.skipped);
    println!(
        "export: {} records into the tub {} ({} images copied, {} encoded)",
        r.frames,
        a.tub.display(),
        r.copied,
        r.encoded
    );
    Ok(exit(ds.skipped.len() + r.skipped.len()))
}

fn import(a: ImportArgs) -> Result<ExitCode> {
    if !a.tub.join(tub::MANIFEST).is_file() {
        bail!("{}: not a Donkey tub v2 (no {})", a.tub.display(), tub::MANIFEST);
    }
    let ds = tub::read(&a.tub)?;
    say_skipped(&a.tub.display().to_string(), &ds.skipped);
    let placed = dataset::unchanged(&ds.samples);
    let r = dataset::write::write_recording(&a.out, &placed, &[a.tub.as_path()], a.frames.options())?;
    say_skipped(&a.out.display().to_string(), &r.skipped);
    let mut extra = String::new();
    if ds.deleted > 0 {
        extra += &format!(", {} deleted in the tub left out", ds.deleted);
    }
    if ds.times_adjusted > 0 {
        extra += &format!(
            ", {} timestamps not increasing were set 1 ms after the frame before",
            ds.times_adjusted
        );
    }
    println!(
        "import: {} frames from {} into {}{extra}",
        r.frames,
        a.tub.display(),
        a.out.display()
    );
    Ok(exit(ds.skipped.len() + r.skipped.len()))
}

/// `YY-MM-DD` of a Unix time in UTC (Donkey's session ids start with it).
fn yy_mm_dd(unix_s: i64) -> String {
    // Days to a civil date (H. Hinnant's algorithm).
    let z = unix_s.div_euclid(86_400) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{:02}-{m:02}-{d:02}", y % 100)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_and_sizes() {
        assert_eq!(yy_mm_dd(1_637_997_387), "21-11-27");
        assert_eq!(yy_mm_dd(0), "70-01-01");
        assert_eq!(yy_mm_dd(951_782_400), "00-02-29");
        assert_eq!(parse_size("160x120"), Ok((160, 120)));
        assert!(parse_size("160").is_err() && parse_size("8x8").is_err());
    }
}
