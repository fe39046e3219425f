//! Donkey Car's tub v2 (donkeycar/parts/tub_v2.py and datastore_v2.py), read and written.
//!
//! ```text
//! TUB/
//!   manifest.json              5 JSON lines: inputs (keys), types, user metadata,
//!                              manifest metadata (created_at, sessions), catalog metadata
//!                              (paths, current_index, max_len, deleted_indexes)
//!   catalog_0.catalog          one JSON record per line, keys sorted: _index, _session_id,
//!   catalog_0.catalog_manifest _timestamp_ms, cam/image_array, user/angle, user/mode,
//!   catalog_1.catalog          user/throttle; max_len (1000) records per catalog
//!   ...                        the .catalog_manifest: created_at, line_lengths, path, start_index
//!   images/0_cam_image_array_.jpg   the image of record 0 (`{index}_{key with / as _}_.jpg`)
//! ```
//!
//! Mapping to rccar (both ways the same): `user/angle` is `steer` and `user/throttle` is
//! `throttle`, unchanged: both are −1..1 with −1 full left (Donkey's `PWMSteering` maps −1 to
//! `STEERING_LEFT_PWM`) and +1 full forward. `user/mode` `user` is manual, `local_angle`
//! assisted (the pilot steers, the human's throttle), `local` autopilot; a tub without
//! `user/mode` is taken as driven by hand. `_timestamp_ms` minus the first record's is the
//! time. `_index` is the frame number, so frame numbers of an imported tub are Donkey's.
//!
//! Donkey deletes records by listing their positions in `deleted_indexes` (tubclean); they
//! are left out and counted in [`super::Dataset::deleted`]. A record's position counts every
//! line of the catalogs in order, as Donkey's `ManifestIterator` does.

use super::{Dataset, DatasetError, Kind, Sample, Skipped};
use crate::control::pilot::DriveMode;
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The manifest's file name.
pub const MANIFEST: &str = "manifest.json";
/// The images' folder.
pub const IMAGES: &str = "images";
/// The camera image's key.
pub const IMAGE_KEY: &str = "cam/image_array";
/// Steering, −1..1.
pub const ANGLE_KEY: &str = "user/angle";
/// Throttle, −1..1.
pub const THROTTLE_KEY: &str = "user/throttle";
/// Driving mode: `user`, `local_angle`, `local`.
pub const MODE_KEY: &str = "user/mode";
/// Records per catalog, as Donkey's default `max_catalog_len`.
pub const MAX_LEN: usize = 1000;

/// Donkey's name of a driving mode.
pub fn mode_name(m: DriveMode) -> &'static str {
    match m {
        DriveMode::Manual => "user",
        DriveMode::Assisted => "local_angle",
        DriveMode::Autopilot => "local",
    }
}

/// The driving mode of Donkey's name.
pub fn parse_mode(s: &str) -> Option<DriveMode> {
    match s {
        "user" => Some(DriveMode::Manual),
        "local_angle" => Some(DriveMode::Assisted),
        "local" | "pilot" => Some(DriveMode::Autopilot),
        _ => None,
    }
}

/// The image file name Donkey gives record `index`'s `cam/image_array`.
pub fn image_name(index: u64) -> String {
    format!("{index}_{}_.jpg", IMAGE_KEY.replace('/', "_"))
}

/// The catalog metadata (manifest.json's fifth line).
struct CatalogMeta {
    paths: Vec<String>,
    current_index: u64,
    deleted: BTreeSet<u64>,
}

fn read_manifest(dir: &Path) -> Result<(Vec<String>, Vec<String>, CatalogMeta), DatasetError> {
    let path = dir.join(MANIFEST);
    let text = std::fs::read_to_string(&path).map_err(|err| DatasetError::Read {
        path: path.clone(),
        err,
    })?;
    let lines: Vec<&str> = text.lines().collect();
    let bad = |line: usize, reason: String| DatasetError::BadLine {
        path: path.clone(),
        line,
        reason,
    };
    let parse = |k: usize, what: &str| -> Result<Value, DatasetError> {
        let l = lines.get(k).ok_or_else(|| {
            bad(
                k + 1,
                format!("missing: a tub's manifest has 5 lines, line {} holds {what}", k + 1),
            )
        })?;
        serde_json::from_str(l).map_err(|e| bad(k + 1, format!("{what}: not JSON ({e})")))
    };
    let strings = |v: Value, k: usize, what: &str| -> Result<Vec<String>, DatasetError> {
        v.as_array()
            .and_then(|a| {
                a.iter()
                    .map(|x| x.as_str().map(String::from))
                    .collect::<Option<Vec<_>>>()
            })
            .ok_or_else(|| bad(k + 1, format!("{what} must be a list of strings")))
    };
    let inputs = strings(parse(0, "the inputs")?, 0, "the inputs")?;
    let types = strings(parse(1, "the types")?, 1, "the types")?;
    if inputs.len() != types.len() {
        return Err(bad(
            2,
            format!(
                "{} types for {} inputs (line 1): they go in pairs",
                types.len(),
                inputs.len()
            ),
        ));
    }
    let meta = parse(4, "the catalog metadata")?;
    let key = |k: &str| {
        meta.get(k)
            .ok_or_else(|| bad(5, format!("no `{k}` in the catalog metadata")))
    };
    let paths = strings(key("paths")?.clone(), 4, "`paths`")?;
    let current_index = key("current_index")?
        .as_u64()
        .ok_or_else(|| bad(5, "`current_index` must be a whole number".into()))?;
    let deleted = match meta.get("deleted_indexes") {
        None | Some(Value::Null) => BTreeSet::new(),
        Some(d) => d
            .as_array()
            .and_then(|a| a.iter().map(Value::as_u64).collect::<Option<BTreeSet<_>>>())
            .ok_or_else(|| bad(5, "`deleted_indexes` must be a list of whole numbers".into()))?,
    };
    Ok((
        inputs,
        types,
        CatalogMeta {
            paths,
            current_index,
            deleted,
        },
    ))
}

/// Reads a tub v2 (see the module notes). Bad manifests, missing catalogs and a catalog that
/// disagrees with its manifest are errors; one bad record is skipped and listed.
pub fn read(dir: &Path) -> Result<Dataset, DatasetError> {
    let manifest = dir.join(MANIFEST);
    let (inputs, types, meta) = read_manifest(dir)?;
    // 1. The keys: an image, the angle and the throttle must be recorded.
    let type_of = |k: &str| inputs.iter().position(|i| i == k).map(|p| types[p].as_str());
    let image_key = if type_of(IMAGE_KEY) == Some("image_array") {
        IMAGE_KEY.to_string()
    } else {
        inputs
            .iter()
            .zip(&types)
            .find(|(_, t)| *t == "image_array")
            .map(|(i, _)| i.clone())
            .ok_or_else(|| DatasetError::BadLine {
                path: manifest.clone(),
                line: 1,
                reason: format!("no camera image among the inputs (`{IMAGE_KEY}` of type image_array)"),
            })?
    };
    for k in [ANGLE_KEY, THROTTLE_KEY] {
        if type_of(k).is_none() {
            return Err(DatasetError::BadLine {
                path: manifest.clone(),
                line: 1,
                reason: format!("no `{k}` among the inputs: this tub has no steering/throttle labels"),
            });
        }
    }
    let mut ds = Dataset {
        path: dir.into(),
        kind: Kind::Tub,
        samples: Vec::new(),
        skipped: Vec::new(),
        deleted: 0,
        unlabelled_frames: 0,
        times_adjusted: 0,
    };
    let images = dir.join(IMAGES);
    let mut position: u64 = 0;
    let mut t0: Option<i64> = None;
    let mut last_t: Option<f64> = None;
    // 2. The catalogs, in the manifest's order; a record's position counts every line.
    for name in &meta.paths {
        if name.contains('/') || name.contains('\\') || name.starts_with('.') {
            return Err(DatasetError::BadLine {
                path: manifest.clone(),
                line: 5,
                reason: format!("catalog `{name}` is not a file name in the tub"),
            });
        }
        let cat = dir.join(name);
        let text = std::fs::read(&cat).map_err(|err| DatasetError::Read { path: cat.clone(), err })?;
        let lines: Vec<&[u8]> = text
            .split(|&b| b == b'\n')
            .filter(|l| !l.iter().all(u8::is_ascii_whitespace))
            .collect();
        check_catalog_manifest(dir, name, lines.len(), position)?;
        for (k, raw) in text.split(|&b| b == b'\n').enumerate() {
            let line_no = k + 1;
            if raw.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            let pos = position;
            position += 1;
            if meta.deleted.contains(&pos) {
                ds.deleted += 1;
                continue;
            }
            match record(&images, &image_key, raw, pos) {
                Ok((ts, mut s)) => {
                    // 3. Time from _timestamp_ms, kept increasing.
                    let t = match ts {
                        Some(ts) => (ts - *t0.get_or_insert(ts)) as f64 / 1000.0,
                        None => last_t.map_or(0.0, |t| t + 0.05),
                    };
                    s.time_s = match last_t {
                        Some(p) if t <= p => {
                            ds.times_adjusted += 1;
                            p + 0.001
                        }
                        _ => t,
                    };
                    last_t = Some(s.time_s);
                    ds.samples.push(s);
                }
                Err(reason) => ds.skipped.push(Skipped {
                    file: cat.clone(),
                    line: line_no,
                    reason,
                }),
            }
        }
    }
    // 4. The manifest's count against the catalogs'.
    if position != meta.current_index {
        return Err(DatasetError::BadLine {
            path: manifest,
            line: 5,
            reason: format!(
                "manifest mismatch: `current_index` says {} records, the catalogs hold {position}",
                meta.current_index
            ),
        });
    }
    Ok(ds)
}

/// A catalog's `.catalog_manifest`, when there is one, must count the catalog's lines and
/// start where the catalogs before it ended.
fn check_catalog_manifest(dir: &Path, catalog: &str, lines: usize, start: u64) -> Result<(), DatasetError> {
    let stem = catalog.strip_suffix(".catalog").unwrap_or(catalog);
    let path = dir.join(format!("{stem}.catalog_manifest"));
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    let bad = |reason: String| DatasetError::BadLine {
        path: path.clone(),
        line: 1,
        reason,
    };
    let v: Value =
        serde_json::from_str(text.lines().next().unwrap_or("")).map_err(|e| bad(format!("not JSON ({e})")))?;
    if let Some(ll) = v.get("line_lengths").and_then(Value::as_array) {
        if ll.len() != lines {
            return Err(bad(format!(
                "manifest mismatch: `line_lengths` lists {} records, {catalog} holds {lines}",
                ll.len()
            )));
        }
    }
    if let Some(s) = v.get("start_index").and_then(Value::as_u64) {
        if s != start {
            return Err(bad(format!(
                "manifest mismatch: `start_index` {s}, but the catalogs before {catalog} hold {start} records"
            )));
        }
    }
    Ok(())
}

/// One catalog line: its timestamp (ms) and sample, or why it is skipped.
fn record(images: &Path, image_key: &str, raw: &[u8], pos: u64) -> Result<(Option<i64>, Sample), String> {
    let v: Value = serde_json::from_slice(raw).map_err(|e| format!("not JSON ({e})"))?;
    if !v.is_object() {
        return Err("not a JSON object".into());
    }
    if let Some(i) = v.get("_index") {
        if i.as_u64() != Some(pos) {
            return Err(format!(
                "`_index` {i} at record {pos} of the tub (records count every catalog line)"
            ));
        }
    }
    let num = |k: &str| -> Result<f64, String> {
        let x = v
            .get(k)
            .ok_or_else(|| format!("no `{k}`"))?
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("`{k}` is not a finite number"))?;
        if !(-1.0..=1.0).contains(&x) {
            return Err(format!("`{k}` {x} is outside -1..1"));
        }
        Ok(x)
    };
    let steer = num(ANGLE_KEY)?;
    let throttle = num(THROTTLE_KEY)?;
    let mode = match v.get(MODE_KEY) {
        None | Some(Value::Null) => DriveMode::Manual,
        Some(m) => m
            .as_str()
            .and_then(parse_mode)
            .ok_or_else(|| format!("`{MODE_KEY}` {m} is not user, local_angle or local"))?,
    };
    let name = v
        .get(image_key)
        .and_then(Value::as_str)
        .ok_or_else(|| format!("no `{image_key}`"))?;
    if name.contains('/') || name.contains('\\') || name.starts_with('.') {
        return Err(format!("`{image_key}` {name:?} is not a file name in images/"));
    }
    let image: PathBuf = images.join(name);
    if !image.is_file() {
        return Err(format!("`{image_key}`: image {} is missing", image.display()));
    }
    let ts = v.get("_timestamp_ms").and_then(Value::as_i64);
    Ok((
        ts,
        Sample {
            frame: pos,
            time_s: 0.0,
            steer,
            throttle,
            mode,
            image,
            session: v.get("_session_id").and_then(Value::as_str).map(String::from),
            telemetry: None,
        },
    ))
}

/// How to write a tub.
#[derive(Debug, Clone, PartialEq)]
pub struct TubOptions {
    /// Frame size and JPEG quality (Donkey's default camera is 160 × 120).
    pub frames: super::write::FrameOptions,
    /// The manifest's `created_at` and the catalogs', Unix seconds (the caller reads the clock).
    pub created_at: f64,
    /// `_timestamp_ms` of time 0 of the recording, Unix milliseconds.
    pub start_ms: i64,
    /// `_session_id` of samples that bring none (Donkey: `YY-MM-DD_N`).
    pub session_id: String,
}

/// Python's `json.dumps` of a list of strings (`", "` between items).
fn py_str_list(items: &[String]) -> String {
    let q: Vec<String> = items.iter().map(|s| Value::from(s.as_str()).to_string()).collect();
    format!("[{}]", q.join(", "))
}

/// Keeps a session id ASCII, as Python's json writes it (line lengths count characters).
fn ascii(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_ascii() && !c.is_ascii_control() { c } else { '_' })
        .collect()
}

/// Writes `samples` as a new tub v2 in `out` (new or empty, not inside any of `inputs`):
/// records numbered 0, 1, 2 … in the samples' order, `_timestamp_ms` = `start_ms` + time.
pub fn write(
    out: &Path,
    samples: &[Sample],
    inputs: &[&Path],
    opts: &TubOptions,
) -> Result<super::write::WriteReport, DatasetError> {
    use super::write::{put_frame, write_synced, Output, WriteReport};
    if samples.is_empty() {
        return Err(DatasetError::Request("nothing to write: no frames".into()));
    }
    let output = Output::create(out, inputs)?;
    let images = out.join(IMAGES);
    std::fs::create_dir_all(&images).map_err(|err| DatasetError::Write {
        path: images.clone(),
        err,
    })?;
    let mut report = WriteReport::default();
    let mut catalogs: Vec<(String, u64, Vec<usize>, String)> = Vec::new();
    let mut sessions: Vec<String> = Vec::new();
    let mut index: u64 = 0;
    for s in samples {
        // 1. The image, named after the record's index.
        match put_frame(&s.image, &images.join(image_name(index)), opts.frames) {
            Ok(copied) => {
                if copied {
                    report.copied += 1;
                } else {
                    report.encoded += 1;
                }
            }
            Err(Ok(reason)) => {
                report.skipped.push(Skipped {
                    file: s.image.clone(),
                    line: 0,
                    reason,
                });
                continue;
            }
            Err(Err(e)) => return Err(e),
        }
        // 2. The record, keys sorted and spaced as Python's json.dumps(sort_keys=True).
        let session = ascii(s.session.as_deref().unwrap_or(&opts.session_id));
        if !sessions.contains(&session) {
            sessions.push(session.clone());
        }
        let line = format!(
            "{{\"_index\": {index}, \"_session_id\": {}, \"_timestamp_ms\": {}, \"{IMAGE_KEY}\": \"{}\", \"{ANGLE_KEY}\": {}, \"{MODE_KEY}\": \"{}\", \"{THROTTLE_KEY}\": {}}}\n",
            Value::from(session),
            opts.start_ms + (s.time_s * 1000.0).round() as i64,
            image_name(index),
            Value::from(s.steer),
            mode_name(s.mode),
            Value::from(s.throttle),
        );
        if (index as usize).is_multiple_of(MAX_LEN) {
            catalogs.push((
                format!("catalog_{}.catalog", catalogs.len()),
                index,
                Vec::new(),
                String::new(),
            ));
        }
        let cat = catalogs.last_mut().expect("a catalog was just opened");
        cat.2.push(line.len());
        cat.3.push_str(&line);
        index += 1;
        report.frames += 1;
    }
    if report.frames == 0 {
        return Err(DatasetError::Request("nothing written: no frame could be read".into()));
    }
    // 3. The catalogs and their manifests.
    for (name, start, lengths, text) in &catalogs {
        write_synced(&out.join(name), text.as_bytes())?;
        let stem = name.trim_end_matches(".catalog");
        let lens: Vec<String> = lengths.iter().map(usize::to_string).collect();
        let cm = format!(
            "{{\"created_at\": {}, \"line_lengths\": [{}], \"path\": \"{stem}.catalog_manifest\", \"start_index\": {start}}}\n",
            Value::from(opts.created_at),
            lens.join(", ")
        );
        write_synced(&out.join(format!("{stem}.catalog_manifest")), cm.as_bytes())?;
    }
    // 4. The manifest, last: a tub without it is not mistaken for a whole one.
    let names: Vec<String> = catalogs.iter().map(|c| c.0.clone()).collect();
    let manifest = format!(
        "{}\n{}\n{{}}\n{{\"created_at\": {}, \"sessions\": {{\"all_full_ids\": {}, \"last_id\": {}, \"last_full_id\": {}}}}}\n{{\"paths\": {}, \"current_index\": {index}, \"max_len\": {MAX_LEN}, \"deleted_indexes\": []}}\n",
        py_str_list(&[IMAGE_KEY.into(), ANGLE_KEY.into(), THROTTLE_KEY.into(), MODE_KEY.into()]),
        py_str_list(&["image_array".into(), "float".into(), "float".into(), "str".into()]),
        Value::from(opts.created_at),
        py_str_list(&sessions),
        sessions.len().saturating_sub(1),
        Value::from(sessions.last().cloned().unwrap_or_default()),
        py_str_list(&names),
    );
    write_synced(&out.join(MANIFEST), manifest.as_bytes())?;
    output.keep();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_modes_as_donkey_writes_them() {
        assert_eq!(image_name(0), "0_cam_image_array_.jpg");
        assert_eq!(image_name(25299), "25299_cam_image_array_.jpg");
        for m in DriveMode::ALL {
            assert_eq!(parse_mode(mode_name(m)), Some(m));
        }
        assert_eq!(py_str_list(&["a".into(), "b/c".into()]), "[\"a\", \"b/c\"]");
    }
}
