//! Numeric telemetry fields by dotted path (`truth.offset_m`), for `rccar plot`: reading a
//! run's telemetry.jsonl (a loader), the students' aliases (`t` = `time_s`, `xte` =
//! `truth.xte` = `truth.offset_m`), and each run's panels of (x, y) points. `null` (e.g.
//! `error` while the lane is lost) is NaN: a gap in the plot.
//!
//! Bounded ([`plot_fields`] checks a request): at most [`MAX_FIELDS`] panels (the image is
//! 1000 × (40 + 260·fields) pixels), [`MAX_FILES`] runs (one colour each), [`MAX_POINTS`] points over all of them, lines of at
//! most [`MAX_LINE_BYTES`]; the files are read line by line, keeping only the plotted numbers.

use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Most panels (`--y` fields): the image is 1000 × (40 + 260·16) = 1000 × 4200 pixels.
pub const MAX_FIELDS: usize = 16;
/// Most telemetry files: one colour each ([`crate::sim::plot::RUN_COLOURS`]).
pub const MAX_FILES: usize = crate::sim::plot::RUN_COLOURS.len();
/// Most points over all files and fields (16 bytes each: 160 MB), e.g. 8 runs × 3 fields of
/// a 2-hour drive at 30 fps (216,000 records each) is 5.2 million.
pub const MAX_POINTS: usize = 10_000_000;
/// Longest telemetry line, bytes (a record is about 1 kB).
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Most distinct numeric fields listed when a field is not found.
const MAX_LISTED: usize = 400;

/// A telemetry file or field that cannot be plotted; each names the file (and line).
#[derive(Debug, thiserror::Error)]
pub enum FieldsError {
    /// The file cannot be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A line is not JSON.
    #[error("{}:{line}: not a JSON record", path.display())]
    NotJson {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// Where in the line and why.
        #[source]
        source: serde_json::Error,
    },
    /// A line is JSON but not an object.
    #[error("{}:{line}: not a JSON object (a telemetry record is one)", path.display())]
    NotObject {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
    },
    /// A line longer than [`MAX_LINE_BYTES`].
    #[error("{}:{line}: line longer than {MAX_LINE_BYTES} bytes (a telemetry record is about 1 kB): not a telemetry file", path.display())]
    LineTooLong {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
    },
    /// More than [`MAX_POINTS`] points over all files and fields.
    #[error("{}:{line}: more than {MAX_POINTS} points to plot over all files and fields: plot fewer fields or a shorter run", path.display())]
    TooManyPoints {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
    },
    /// No record at all.
    #[error("{}: no records", .0.display())]
    Empty(PathBuf),
    /// The field holds something else than a number, `null` or a bool.
    #[error("{}:{line}: `{field}` is not a number ({value}); plot numeric fields only", path.display())]
    NotNumber {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The field as typed.
        field: String,
        /// What it holds.
        value: String,
    },
    /// No record has the field.
    #[error("{}: no field `{field}` in the telemetry; numeric fields: {available} (aliases: t, xte)", path.display())]
    NoField {
        /// The file.
        path: PathBuf,
        /// The field as typed.
        field: String,
        /// The numeric fields the file has, comma-separated.
        available: String,
    },
}

/// A plot request out of its bounds (the message names the flag and the bound).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// More `--label`s than files.
    #[error("--label given {labels} times for {files} file(s)")]
    Labels {
        /// `--label`s given.
        labels: usize,
        /// Files given.
        files: usize,
    },
    /// No field named.
    #[error("--y: name at least one field, e.g. --y error,steer")]
    NoField,
    /// More than [`MAX_FIELDS`] fields.
    #[error("--y: {0} fields; at most {MAX_FIELDS} (one panel each, 260 px tall): plot them in several images")]
    TooManyFields(usize),
    /// More than [`MAX_FILES`] files.
    #[error("{0} telemetry files; at most {MAX_FILES} in one plot (one colour each): plot them in groups")]
    TooManyFiles(usize),
}

/// The fields to plot from `--y` (trimmed, empty ones dropped), with `files` telemetry files
/// and `labels` legend names checked against the bounds.
pub fn plot_fields(y: &[String], files: usize, labels: usize) -> Result<Vec<String>, RequestError> {
    if labels > files {
        return Err(RequestError::Labels { labels, files });
    }
    let fields: Vec<String> = y.iter().map(|f| f.trim().to_string()).filter(|f| !f.is_empty()).collect();
    if fields.is_empty() {
        return Err(RequestError::NoField);
    }
    if fields.len() > MAX_FIELDS {
        return Err(RequestError::TooManyFields(fields.len()));
    }
    if files > MAX_FILES {
        return Err(RequestError::TooManyFiles(files));
    }
    Ok(fields)
}

/// Field aliases for students: the short names used in the labs.
pub fn resolve(field: &str) -> &str {
    match field {
        "t" | "time" => "time_s",
        "xte" | "truth.xte" => "truth.offset_m",
        f => f,
    }
}

/// A field as typed, and what an alias stands for (panel titles and axis names).
pub fn shown(f: &str) -> String {
    let r = resolve(f);
    if r == f {
        f.to_string()
    } else {
        format!("{f} = {r}")
    }
}

/// The value at a dotted path, if the record has it.
pub fn lookup<'a>(v: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(v, |v, k| v.get(k))
}

/// Calls `each(dotted path, value)` for every leaf of `v` that is not an object (arrays are
/// leaves: not entered). The one walk behind [`numeric_paths`] and the report's flattening.
pub fn for_each_leaf(v: &Value, prefix: &str, each: &mut impl FnMut(&str, &Value)) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let p = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                for_each_leaf(x, &p, each);
            }
        }
        leaf => each(prefix, leaf),
    }
}

/// Every numeric leaf's dotted path in `v` (arrays not entered).
pub fn numeric_paths(v: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    for_each_leaf(v, prefix, &mut |p, leaf| {
        if leaf.is_number() {
            out.insert(p.to_string());
        }
    });
}

/// Reads a telemetry file line by line and calls `each(line number, record)` for every record;
/// only what `each` keeps stays in memory. Returns the number of records. Errors name the file
/// and line.
pub fn read_jsonl(
    path: &Path,
    mut each: impl FnMut(usize, &Value) -> Result<(), FieldsError>,
) -> Result<usize, FieldsError> {
    use std::io::{BufRead, Read};
    let read_err = |source| FieldsError::Read {
        path: path.to_path_buf(),
        source,
    };
    let f = std::fs::File::open(path).map_err(read_err)?;
    let mut r = std::io::BufReader::new(f);
    let mut buf = Vec::new();
    let (mut line, mut records) = (0usize, 0usize);
    loop {
        buf.clear();
        let n = r
            .by_ref()
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut buf)
            .map_err(read_err)?;
        if n == 0 {
            break;
        }
        line += 1;
        if buf.len() > MAX_LINE_BYTES {
            return Err(FieldsError::LineTooLong {
                path: path.to_path_buf(),
                line,
            });
        }
        if buf.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let v: Value = serde_json::from_slice(&buf).map_err(|source| FieldsError::NotJson {
            path: path.to_path_buf(),
            line,
            source,
        })?;
        if !v.is_object() {
            return Err(FieldsError::NotObject {
                path: path.to_path_buf(),
                line,
            });
        }
        records += 1;
        each(line, &v)?;
    }
    if records == 0 {
        return Err(FieldsError::Empty(path.to_path_buf()));
    }
    Ok(records)
}

/// The number at `path` in `rec`: `None` when absent, NaN for `null`; an error for a string.
pub fn number(rec: &Value, path: &str, file: &Path, line: usize, shown: &str) -> Result<Option<f64>, FieldsError> {
    match lookup(rec, path) {
        None => Ok(None),
        Some(Value::Null) => Ok(Some(f64::NAN)),
        Some(Value::Number(n)) => Ok(n.as_f64()),
        Some(Value::Bool(b)) => Ok(Some(if *b { 1.0 } else { 0.0 })),
        Some(other) => Err(FieldsError::NotNumber {
            path: file.to_path_buf(),
            line,
            field: shown.to_string(),
            value: other.to_string(),
        }),
    }
}

/// A run's legend name: its folder's name for a `telemetry.jsonl`, else the file's stem.
pub fn default_label(p: &Path) -> String {
    let stem = p
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let parent = p
        .parent()
        .and_then(|d| d.file_name())
        .map(|s| s.to_string_lossy().to_string());
    match parent {
        Some(d) if stem == "telemetry" => d,
        _ => stem,
    }
}

/// One run's panels, as [`panels`] read them.
#[derive(Debug, Clone, PartialEq)]
pub struct Panels {
    /// One panel per field: the (x, y) points of the records that have x.
    pub panels: Vec<Vec<(f64, f64)>>,
    /// The file's records.
    pub records: usize,
}

/// One panel per field of `fields` (trimmed, as typed): the (x, y) points of the records of
/// `file` that have `x` (as typed; aliases allowed), read line by line. Every field must occur
/// in some record. `points` counts the points over all files (at most [`MAX_POINTS`]).
pub fn panels(file: &Path, x: &str, fields: &[String], points: &mut usize) -> Result<Panels, FieldsError> {
    let xr = resolve(x.trim());
    let mut avail = BTreeSet::new();
    let wanted: Vec<&str> = std::iter::once(xr).chain(fields.iter().map(|f| resolve(f))).collect();
    let mut seen = vec![false; wanted.len()];
    let mut panels = vec![Vec::new(); fields.len()];
    let records = read_jsonl(file, |line, r| {
        if avail.len() < MAX_LISTED {
            numeric_paths(r, "", &mut avail);
        }
        for (s, w) in seen.iter_mut().zip(&wanted) {
            *s |= lookup(r, w).is_some();
        }
        let Some(xv) = number(r, xr, file, line, x)? else {
            return Ok(());
        };
        *points += fields.len();
        if *points > MAX_POINTS {
            return Err(FieldsError::TooManyPoints {
                path: file.to_path_buf(),
                line,
            });
        }
        for (p, f) in panels.iter_mut().zip(fields) {
            let y = number(r, resolve(f), file, line, f)?.unwrap_or(f64::NAN);
            p.push((xv, y));
        }
        Ok(())
    })?;
    for (f, s) in std::iter::once(&x.to_string()).chain(fields).zip(&seen) {
        if !s {
            let list: Vec<&str> = avail.iter().map(String::as_str).collect();
            return Err(FieldsError::NoField {
                path: file.to_path_buf(),
                field: f.trim().to_string(),
                available: list.join(", "),
            });
        }
    }
    Ok(Panels { panels, records })
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
