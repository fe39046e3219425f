//! `rccar plot FILE.jsonl [FILE2.jsonl ...] --y error,steer [--x t] [--out plot.png]
//! [--label NAME ...]`: any numeric telemetry fields (dotted paths into the nested JSON, e.g.
//! `truth.offset_m`) of one or more runs against time, one panel per field, one colour per
//! run. Labs compare runs this way (e.g. `steering.kd` 0 vs 0.1).
//!
//! Aliases: `t` = `time_s`, `xte` = `truth.xte` = `truth.offset_m` (the true cross-track error,
//! metres). `null` (e.g. `error` while the lane is lost) leaves a gap. Units are those of the
//! telemetry (docs/sim.md, docs/lane.md).
//!
//! Bounded: at most [`MAX_FIELDS`] panels (the image is 1000 × (40 + 260·fields) pixels),
//! [`MAX_FILES`] runs (one colour each), [`MAX_POINTS`] points over all of them, lines of at
//! most [`MAX_LINE_BYTES`]; the files are read line by line, keeping only the plotted numbers.

use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::sim::plot::{self, Trace};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Flags of `rccar plot`.
#[derive(Args, Debug)]
pub struct PlotArgs {
    /// Telemetry files (JSONL, one record per frame), e.g. out/sim/telemetry.jsonl; at most 8
    /// (one colour each).
    #[arg(required = true, value_name = "FILE.jsonl")]
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

/// Field aliases for students: the short names used in the labs.
pub fn resolve(field: &str) -> &str {
    match field {
        "t" | "time" => "time_s",
        "xte" | "truth.xte" => "truth.offset_m",
        f => f,
    }
}

/// The value at a dotted path, if the record has it.
fn lookup<'a>(v: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(v, |v, k| v.get(k))
}

/// Every numeric leaf's dotted path in `v` (arrays not entered).
fn numeric_paths(v: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let p = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                numeric_paths(x, &p, out);
            }
        }
        Value::Number(_) => {
            out.insert(prefix.to_string());
        }
        _ => {}
    }
}

/// Most panels (`--y` fields): the image is 1000 × (40 + 260·16) = 1000 × 4200 pixels.
pub const MAX_FIELDS: usize = 16;
/// Most telemetry files: one colour each (`plot::RUN_COLOURS`).
pub const MAX_FILES: usize = plot::RUN_COLOURS.len();
/// Most points over all files and fields (16 bytes each: 160 MB), e.g. 8 runs × 3 fields of
/// a 2-hour drive at 30 fps (216,000 records each) is 5.2 million.
pub const MAX_POINTS: usize = 10_000_000;
/// Longest telemetry line, bytes (a record is about 1 kB).
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Most distinct numeric fields listed when a field is not found.
const MAX_LISTED: usize = 400;

/// Reads a telemetry file line by line and calls `each(line number, record)` for every record;
/// only what `each` keeps stays in memory. Errors name the file and line.
fn read_jsonl(path: &Path, mut each: impl FnMut(usize, &Value) -> Result<()>) -> Result<usize> {
    use std::io::{BufRead, Read};
    let f = std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut r = std::io::BufReader::new(f);
    let mut buf = Vec::new();
    let (mut line, mut records) = (0usize, 0usize);
    loop {
        buf.clear();
        let n = r
            .by_ref()
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut buf)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            break;
        }
        line += 1;
        if buf.len() > MAX_LINE_BYTES {
            bail!(
                "{}:{line}: line longer than {MAX_LINE_BYTES} bytes (a telemetry record is about 1 kB): not a telemetry file",
                path.display()
            );
        }
        if buf.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let v: Value = serde_json::from_slice(&buf)
            .with_context(|| format!("{}:{line}: not a JSON record", path.display()))?;
        if !v.is_object() {
            bail!("{}:{line}: not a JSON object (a telemetry record is one)", path.display());
        }
        records += 1;
        each(line, &v)?;
    }
    if records == 0 {
        bail!("{}: no records", path.display());
    }
    Ok(records)
}

/// The number at `path` in `rec`: `None` when absent, NaN for `null`; an error for a string.
fn number(rec: &Value, path: &str, file: &Path, line: usize, shown: &str) -> Result<Option<f64>> {
    match lookup(rec, path) {
        None => Ok(None),
        Some(Value::Null) => Ok(Some(f64::NAN)),
        Some(Value::Number(n)) => Ok(n.as_f64()),
        Some(Value::Bool(b)) => Ok(Some(if *b { 1.0 } else { 0.0 })),
        Some(other) => bail!(
            "{}:{line}: `{shown}` is not a number ({}); plot numeric fields only",
            file.display(),
            other
        ),
    }
}

fn default_label(p: &Path) -> String {
    let stem = p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    let parent = p
        .parent()
        .and_then(|d| d.file_name())
        .map(|s| s.to_string_lossy().to_string());
    match parent {
        Some(d) if stem == "telemetry" => d,
        _ => stem,
    }
}

/// Runs `rccar plot`.
pub fn run(a: PlotArgs) -> Result<ExitCode> {
    if a.label.len() > a.files.len() {
        bail!("--label given {} times for {} file(s)", a.label.len(), a.files.len());
    }
    let fields: Vec<String> = a.y.iter().map(|f| f.trim().to_string()).filter(|f| !f.is_empty()).collect();
    if fields.is_empty() {
        bail!("--y: name at least one field, e.g. --y error,steer");
    }
    if fields.len() > MAX_FIELDS {
        bail!(
            "--y: {} fields; at most {MAX_FIELDS} (one panel each, 260 px tall): plot them in several images",
            fields.len()
        );
    }
    if a.files.len() > MAX_FILES {
        bail!(
            "{} telemetry files; at most {MAX_FILES} in one plot (one colour each): plot them in groups",
            a.files.len()
        );
    }
    let x = resolve(a.x.trim()).to_string();
    let mut traces = Vec::new();
    let mut points = 0usize;
    for (k, file) in a.files.iter().enumerate() {
        let mut avail = BTreeSet::new();
        let wanted: Vec<&str> = std::iter::once(x.as_str()).chain(fields.iter().map(|f| resolve(f))).collect();
        let mut seen = vec![false; wanted.len()];
        let mut panels = vec![Vec::new(); fields.len()];
        let records = read_jsonl(file, |line, r| {
            if avail.len() < MAX_LISTED {
                numeric_paths(r, "", &mut avail);
            }
            for (s, w) in seen.iter_mut().zip(&wanted) {
                *s |= lookup(r, w).is_some();
            }
            let Some(xv) = number(r, &x, file, line, &a.x)? else { return Ok(()) };
            points += fields.len();
            if points > MAX_POINTS {
                bail!(
                    "{}:{line}: more than {MAX_POINTS} points to plot over all files and fields: plot fewer fields or a shorter run",
                    file.display()
                );
            }
            for (p, f) in panels.iter_mut().zip(&fields) {
                let y = number(r, resolve(f), file, line, f)?.unwrap_or(f64::NAN);
                p.push((xv, y));
            }
            Ok(())
        })?;
        for (f, s) in std::iter::once(&a.x).chain(&fields).zip(&seen) {
            if !s {
                let list: Vec<&str> = avail.iter().map(String::as_str).collect();
                bail!(
                    "{}: no field `{}` in the telemetry; numeric fields: {} (aliases: t, xte)",
                    file.display(),
                    f.trim(),
                    list.join(", ")
                );
            }
        }
        let label = a.label.get(k).cloned().unwrap_or_else(|| default_label(file));
        println!("plot: {} ({records} records) as `{label}`", file.display());
        traces.push(Trace { label, panels });
    }
    let font = super::sim::load_font()
        .with_context(|| format!("no font at {}; apt install fonts-dejavu-core", super::sim::FONT))?;
    plot::register_font(font);
    // Panel titles and axis names: the field as typed, and what an alias stands for.
    let shown = |f: &str| {
        let r = resolve(f);
        if r == f { f.to_string() } else { format!("{f} = {r}") }
    };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dotted_paths_and_aliases() {
        let v: Value = serde_json::json!({"t": 1, "truth": {"offset_m": 0.02, "pose": [1, 2]}, "s": "x", "e": null});
        assert_eq!(lookup(&v, resolve("truth.xte")), Some(&serde_json::json!(0.02)));
        assert_eq!(resolve("t"), "time_s");
        let mut p = BTreeSet::new();
        numeric_paths(&v, "", &mut p);
        assert_eq!(p.into_iter().collect::<Vec<_>>(), vec!["t", "truth.offset_m"]);
        assert!(number(&v, "e", Path::new("f"), 3, "e").unwrap().unwrap().is_nan());
        let e = number(&v, "s", Path::new("f.jsonl"), 3, "s").unwrap_err().to_string();
        assert!(e.starts_with("f.jsonl:3: `s` is not a number"), "{e}");
    }
}
