//! Recordings as datasets (issue 29): read a recording or a Donkey Car tub as a list of
//! labelled samples, count its labels, and write new recordings and tubs from them.
//!
//! A [`Sample`] is one camera frame and the command that went with it: `steer` and `throttle`
//! (−1..1, as [`crate::control::Command`]), the driving mode, the time since the start of the
//! recording (seconds) and the path of the frame's image. The image is read only when asked
//! ([`Sample::load_image`]), so opening a dataset of 25 000 frames reads only its labels.
//!
//! What the label is: the command the car was actually given. In an rccar telemetry line that
//! is `sent` when the gate changed the command (disarmed, e-stop, brake, fault), else `steer`
//! and `throttle`; in manual mode those are the human's (docs/gamepad.md), in autopilot the
//! pipeline's. The mode is `drive_mode` (absent: `autopilot`, nobody could take over).
//!
//! Three kinds of input ([`Dataset::open`], [`Dataset::open_frames`]):
//!
//! - a recording (`rccar drive --record DIR`, or any output of `rccar data`): DIR/telemetry.jsonl
//!   and seg_NNNNNN/frame_NNNNNNNNN.jpg (`crate::record`);
//! - a folder of frames with its telemetry elsewhere (`rccar sim --record DIR -o RUN`: the
//!   frames in DIR, the telemetry in RUN/telemetry.jsonl, paired by the line's `file`);
//! - a Donkey Car tub v2 ([`tub`]): manifest.json, catalog_N.catalog, images/.
//!
//! Rules for bad input, the same everywhere: what makes the whole input untrustworthy (a
//! missing or unreadable telemetry or manifest, frame numbers or times that go backwards, a
//! manifest that disagrees with its catalogs) is a [`DatasetError`] naming the file and line
//! or key; one bad record (a line that is not JSON, a missing image, a label out of range) is
//! skipped and listed in [`Dataset::skipped`] with its file and line.
//!
//! Outputs ([`write`]) always go into a new or empty folder, never inside an input; inputs are
//! only read.

pub mod stats;
pub mod tub;
pub mod write;

use crate::control::pilot::DriveMode;
use crate::record::{frame_index, SEGMENT_PREFIX, TELEMETRY_FILE};
use image::RgbImage;
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

pub use stats::LabelStats;

/// One labelled frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Frame number: the telemetry's `frame`, or a tub record's `_index`.
    pub frame: u64,
    /// Time since the start of the recording, seconds (a tub's `_timestamp_ms` minus the first).
    pub time_s: f64,
    /// Steering sent, −1 (full left) ..= 1 (full right). Donkey's `user/angle`.
    pub steer: f64,
    /// Throttle sent, −1 (full reverse) ..= 1 (full forward), 0 stop. Donkey's `user/throttle`.
    pub throttle: f64,
    /// Who drove: manual (a human), assisted (the pipeline steers, a human's throttle) or
    /// autopilot. Donkey's `user/mode` `user`, `local_angle`, `local`.
    pub mode: DriveMode,
    /// The frame's image file (JPEG or PNG).
    pub image: PathBuf,
    /// A tub record's `_session_id`; in a merged recording, where the frame came from.
    pub session: Option<String>,
    /// The telemetry line as read (rccar recordings only), so that `cut` copies it unchanged
    /// and `merge` keeps every field.
    pub telemetry: Option<String>,
}

impl Sample {
    /// Reads and decodes the frame's image (RGB, its own size).
    pub fn load_image(&self) -> Result<RgbImage, DatasetError> {
        crate::source::read_image(&self.image)
            .map(|i| i.to_rgb8())
            .map_err(|reason| DatasetError::Bad {
                path: self.image.clone(),
                reason,
            })
    }
}

/// What kind of folder a dataset was read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A recording: telemetry.jsonl and segment folders of JPEG frames.
    Recording,
    /// A folder of frames whose telemetry is another file (`rccar sim --record`).
    Frames,
    /// A Donkey Car tub v2.
    Tub,
}

impl Kind {
    /// How `rccar data ls` names it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Recording => "rccar recording",
            Kind::Frames => "frames + telemetry",
            Kind::Tub => "Donkey tub v2",
        }
    }
}

/// One record that was skipped, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// The file holding the record (a telemetry or catalog file, or the image).
    pub file: PathBuf,
    /// Line number in `file`, 1-based (0: not a line of a text file).
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

impl std::fmt::Display for Skipped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file.display(), self.line, self.reason)
        } else {
            write!(f, "{}: {}", self.file.display(), self.reason)
        }
    }
}

/// A recording or tub read as samples.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The folder given.
    pub path: PathBuf,
    /// What it is.
    pub kind: Kind,
    /// The good samples, in time order.
    pub samples: Vec<Sample>,
    /// Records skipped (bad line, missing image, label out of range), in file order.
    pub skipped: Vec<Skipped>,
    /// Tub records marked deleted in its manifest (`deleted_indexes`, Donkey's tubclean):
    /// left out on purpose, not counted as skipped.
    pub deleted: usize,
    /// Frame files that no telemetry line names (ignored).
    pub unlabelled_frames: usize,
    /// Tub records whose `_timestamp_ms` was not after the one before (two sessions, a clock
    /// step): their time was set 1 ms after the previous frame's, so times still increase.
    pub times_adjusted: usize,
}

/// What can go wrong. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or folder cannot be read.
    #[error("{path}: cannot read: {err}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// A file (or folder) is not what it must be.
    #[error("{path}: {reason}")]
    Bad {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the key when there is one.
        reason: String,
    },
    /// One line of a file contradicts the rest, so the whole file cannot be trusted.
    #[error("{path}:{line}: {reason}")]
    BadLine {
        /// The file.
        path: PathBuf,
        /// Line number, 1-based.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The output folder is not empty (it would mix two datasets).
    #[error("{path}: not empty (holds {found}); outputs go into a new or empty folder: choose another, or remove it")]
    NotEmpty {
        /// The folder.
        path: PathBuf,
        /// An entry in it.
        found: String,
    },
    /// The output folder is an input or inside one (inputs are never changed).
    #[error("{out}: is inside the input {input}; outputs go elsewhere, inputs are never changed")]
    InsideInput {
        /// The output folder.
        out: PathBuf,
        /// The input folder.
        input: PathBuf,
    },
    /// Writing the output failed.
    #[error("{path}: cannot write: {err}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// A request that cannot be done (a drop range that matches no frame, nothing to write).
    #[error("{0}")]
    Request(String),
}

impl Dataset {
    /// Opens `path`: a Donkey tub when it holds manifest.json, else a recording (it must hold
    /// telemetry.jsonl; a `rccar sim --record` folder has its telemetry in the run folder: use
    /// [`Dataset::open_frames`]).
    pub fn open(path: &Path) -> Result<Dataset, DatasetError> {
        if !path.is_dir() {
            return Err(DatasetError::Bad {
                path: path.into(),
                reason: if path.exists() {
                    "not a folder".into()
                } else {
                    "no such folder".into()
                },
            });
        }
        if path.join(tub::MANIFEST).is_file() {
            return tub::read(path);
        }
        let tel = path.join(TELEMETRY_FILE);
        if !tel.is_file() {
            return Err(DatasetError::Bad {
                path: path.into(),
                reason: format!(
                    "neither a recording (no {TELEMETRY_FILE}) nor a Donkey tub (no {}); frames recorded by `rccar sim --record DIR -o RUN` have their telemetry in RUN: give it with --telemetry RUN/{TELEMETRY_FILE}",
                    tub::MANIFEST
                ),
            });
        }
        read_recording(path, &tel, Kind::Recording)
    }

    /// Opens a folder of frames whose telemetry is `telemetry` (`rccar sim --record DIR -o
    /// RUN`: DIR and RUN/telemetry.jsonl). Lines are paired with frames by their `file`.
    pub fn open_frames(frames: &Path, telemetry: &Path) -> Result<Dataset, DatasetError> {
        if !frames.is_dir() {
            return Err(DatasetError::Bad {
                path: frames.into(),
                reason: "no such folder".into(),
            });
        }
        read_recording(frames, telemetry, Kind::Frames)
    }

    /// Label counts, histograms and balance warnings.
    pub fn stats(&self) -> LabelStats {
        LabelStats::of(&self.samples)
    }

    /// The width and height of the first frame (read from its header), if it can be read.
    pub fn frame_size(&self) -> Option<(u32, u32)> {
        let s = self.samples.first()?;
        image::ImageReader::open(&s.image)
            .ok()?
            .with_guessed_format()
            .ok()?
            .into_dimensions()
            .ok()
    }
}

fn is_frame_file(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    lower.ends_with(".jpg") || lower.ends_with(".jpeg") || lower.ends_with(".png")
}

fn read_dir_sorted(dir: &Path) -> Result<Vec<(String, PathBuf, bool)>, DatasetError> {
    let rd = std::fs::read_dir(dir).map_err(|err| DatasetError::Read { path: dir.into(), err })?;
    let mut out = Vec::new();
    for e in rd {
        let e = e.map_err(|err| DatasetError::Read { path: dir.into(), err })?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        let p = e.path();
        let is_dir = p.is_dir();
        out.push((name, p, is_dir));
    }
    out.sort();
    Ok(out)
}

/// The label of one telemetry line: (steer, throttle, mode), or why it cannot be used.
pub fn telemetry_label(v: &Value) -> Result<(f64, f64, DriveMode), String> {
    let num = |obj: &Value, key: &str, what: &str| -> Result<f64, String> {
        let x = obj
            .get(key)
            .ok_or_else(|| format!("no `{what}`"))?
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("`{what}` is not a finite number"))?;
        if !(-1.0..=1.0).contains(&x) {
            return Err(format!("`{what}` {x} is outside -1..1"));
        }
        Ok(x)
    };
    let (steer, throttle) = match v.get("sent").filter(|s| !s.is_null()) {
        Some(sent) => (
            num(sent, "steer", "sent.steer")?,
            num(sent, "throttle", "sent.throttle")?,
        ),
        None => (num(v, "steer", "steer")?, num(v, "throttle", "throttle")?),
    };
    let mode = match v.get("drive_mode") {
        None | Some(Value::Null) => DriveMode::Autopilot,
        Some(m) => m
            .as_str()
            .and_then(DriveMode::parse)
            .ok_or_else(|| format!("`drive_mode` {m} is not manual, assisted or autopilot"))?,
    };
    Ok((steer, throttle, mode))
}

/// Reads a recording's (or a frame folder's) telemetry and pairs its lines with frames.
fn read_recording(dir: &Path, tel: &Path, kind: Kind) -> Result<Dataset, DatasetError> {
    // 1. The frame files: in segment folders by frame number, and loose ones by name.
    let mut by_index: HashMap<u64, PathBuf> = HashMap::new();
    let mut by_name: HashMap<String, PathBuf> = HashMap::new();
    for (name, p, is_dir) in read_dir_sorted(dir)? {
        if is_dir && name.starts_with(SEGMENT_PREFIX) {
            for (n, fp, d) in read_dir_sorted(&p)? {
                if let (false, Some(i)) = (d, frame_index(&n)) {
                    by_index.insert(i, fp);
                }
            }
        } else if !is_dir && is_frame_file(&name) {
            by_name.insert(name, p);
        }
    }
    let frames_on_disk = by_index.len() + by_name.len();
    // 2. The telemetry, one line at a time.
    let text = std::fs::read(tel).map_err(|err| DatasetError::Read { path: tel.into(), err })?;
    let mut ds = Dataset {
        path: dir.into(),
        kind,
        samples: Vec::new(),
        skipped: Vec::new(),
        deleted: 0,
        unlabelled_frames: 0,
        times_adjusted: 0,
    };
    let mut last: Option<(u64, f64, usize)> = None;
    let mut used = 0usize;
    let mut no_image = 0usize;
    for (k, raw) in text.split(|&b| b == b'\n').enumerate() {
        let line_no = k + 1;
        if raw.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let skip = |ds: &mut Dataset, reason: String| {
            ds.skipped.push(Skipped {
                file: tel.into(),
                line: line_no,
                reason,
            })
        };
        // 2a. Not JSON: a line cut by a crash or a full card; skipped.
        let Ok(v) = serde_json::from_slice::<Value>(raw) else {
            skip(&mut ds, "not JSON (a line cut short?)".into());
            continue;
        };
        let bad = |reason: String| DatasetError::BadLine {
            path: tel.into(),
            line: line_no,
            reason,
        };
        // 2b. Frame number and time: increasing, or the file holds two runs.
        let frame = v
            .get("frame")
            .and_then(Value::as_u64)
            .ok_or_else(|| bad("no frame number (`frame`)".into()))?;
        let time_s = v
            .get("time_s")
            .and_then(Value::as_f64)
            .filter(|t| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| bad("no `time_s` (a finite number of seconds, not negative)".into()))?;
        if let Some((f, t, l)) = last {
            if frame <= f {
                return Err(bad(format!(
                    "frame {frame} after frame {f} (line {l}): frame numbers must increase; two runs in one telemetry?"
                )));
            }
            if time_s <= t {
                return Err(bad(format!(
                    "time_s {time_s} is not after line {l}'s {t}: times must increase"
                )));
            }
        }
        last = Some((frame, time_s, line_no));
        // 2c. The label.
        let (steer, throttle, mode) = match telemetry_label(&v) {
            Ok(l) => l,
            Err(reason) => {
                skip(&mut ds, reason);
                continue;
            }
        };
        // 2d. Its frame: by number in a segment folder, else by the line's `file`.
        let file = v.get("file").and_then(Value::as_str).unwrap_or("");
        let image = by_index.get(&frame).or_else(|| by_name.get(file)).cloned();
        let Some(image) = image else {
            no_image += 1;
            skip(
                &mut ds,
                format!("frame {frame}: no image file (deleted by the disk budget, or never written)"),
            );
            continue;
        };
        used += 1;
        let line = String::from_utf8_lossy(raw).trim_end_matches('\r').to_string();
        ds.samples.push(Sample {
            frame,
            time_s,
            steer,
            throttle,
            mode,
            image,
            session: v
                .get("dataset")
                .and_then(|d| d.get("session"))
                .and_then(Value::as_str)
                .map(String::from),
            telemetry: Some(line),
        });
    }
    ds.unlabelled_frames = frames_on_disk.saturating_sub(used);
    if used == 0 && no_image > 0 {
        return Err(DatasetError::Bad {
            path: dir.into(),
            reason: format!(
                "none of the {no_image} frames of {} is here (seg_NNNNNN/frame_NNNNNNNNN.jpg, or the files its lines name); a run folder of `rccar sim -o RUN` holds the telemetry only: give the frames' folder (`--record DIR`) with --telemetry RUN/{TELEMETRY_FILE}",
                tel.display()
            ),
        });
    }
    Ok(ds)
}

/// A range of frame numbers: `A..B` (B left out, as in Rust and Python), `A..=B`, `A..`,
/// `..B`, or one frame `A`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    /// First frame in the range.
    pub start: u64,
    /// First frame after the range (`None`: to the end).
    pub end: Option<u64>,
}

impl FrameRange {
    /// Whether frame `f` is in the range.
    pub fn contains(&self, f: u64) -> bool {
        f >= self.start && self.end.is_none_or(|e| f < e)
    }
}

impl std::fmt::Display for FrameRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.end {
            Some(e) => write!(f, "{}..{}", self.start, e),
            None => write!(f, "{}..", self.start),
        }
    }
}

impl std::str::FromStr for FrameRange {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let num = |t: &str| {
            t.trim()
                .parse::<u64>()
                .map_err(|_| format!("`{s}`: `{t}` is not a frame number (ranges are A..B, A..=B, A.., ..B or A)"))
        };
        let (start, end) = match s.split_once("..") {
            None => {
                let a = num(s)?;
                (a, Some(a + 1))
            }
            Some((a, b)) => {
                let start = if a.trim().is_empty() { 0 } else { num(a)? };
                let end = match b.strip_prefix('=') {
                    Some(b) => Some(num(b)? + 1),
                    None if b.trim().is_empty() => None,
                    None => Some(num(b)?),
                };
                (start, end)
            }
        };
        if end.is_some_and(|e| e <= start) {
            return Err(format!("`{s}` is empty (the end must be after the start)"));
        }
        Ok(FrameRange { start, end })
    }
}

/// The samples left after dropping `drops`. Every range must match at least one frame (a
/// typo would otherwise keep what was meant to go); the error says which frames there are.
pub fn cut(samples: &[Sample], drops: &[FrameRange]) -> Result<Vec<Sample>, DatasetError> {
    for d in drops {
        if !samples.iter().any(|s| d.contains(s.frame)) {
            let span = match (samples.first(), samples.last()) {
                (Some(a), Some(b)) => format!("frames {}..={}", a.frame, b.frame),
                _ => "no frames".into(),
            };
            return Err(DatasetError::Request(format!(
                "--drop {d} matches no frame (this dataset holds {span})"
            )));
        }
    }
    Ok(samples
        .iter()
        .filter(|s| !drops.iter().any(|d| d.contains(s.frame)))
        .cloned()
        .collect())
}

/// The median time between neighbouring samples, seconds (1/30 s when there are fewer than 2).
pub fn median_step_s(samples: &[Sample]) -> f64 {
    let mut d: Vec<f64> = samples.windows(2).map(|w| w[1].time_s - w[0].time_s).collect();
    if d.is_empty() {
        return 1.0 / 30.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// One sample placed in an output: its new frame number and time, and where it came from.
#[derive(Debug, Clone)]
pub struct Placed<'a> {
    /// The sample.
    pub sample: &'a Sample,
    /// Its frame number in the output.
    pub frame: u64,
    /// Its time in the output, seconds.
    pub time_s: f64,
    /// The input it came from (merge), written into the telemetry's `dataset` field.
    pub origin: Option<String>,
}

/// The samples of several datasets one after the other, numbered 0, 1, 2 … and timed so that
/// each part starts one median frame step after the previous part's last frame.
pub fn merge<'a>(parts: &'a [(String, Vec<Sample>)]) -> Vec<Placed<'a>> {
    let mut out = Vec::new();
    let mut t_next = 0.0;
    for (name, samples) in parts {
        let Some(first) = samples.first() else { continue };
        let shift = t_next - first.time_s;
        for s in samples {
            out.push(Placed {
                sample: s,
                frame: out.len() as u64,
                time_s: s.time_s + shift,
                origin: Some(name.clone()),
            });
        }
        if let Some(last) = samples.last() {
            t_next = last.time_s + shift + median_step_s(samples);
        }
    }
    out
}

/// The samples as they are (same frame numbers and times).
pub fn unchanged(samples: &[Sample]) -> Vec<Placed<'_>> {
    samples
        .iter()
        .map(|s| Placed {
            sample: s,
            frame: s.frame,
            time_s: s.time_s,
            origin: None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(frame: u64, t: f64) -> Sample {
        Sample {
            frame,
            time_s: t,
            steer: 0.0,
            throttle: 0.5,
            mode: DriveMode::Autopilot,
            image: PathBuf::from(format!("f{frame}.jpg")),
            session: None,
            telemetry: None,
        }
    }

    #[test]
    fn ranges_parse_as_rust_ranges() {
        let r = |t: &str| t.parse::<FrameRange>().unwrap();
        assert_eq!(
            r("10..20"),
            FrameRange {
                start: 10,
                end: Some(20)
            }
        );
        assert_eq!(
            r("10..=20"),
            FrameRange {
                start: 10,
                end: Some(21)
            }
        );
        assert_eq!(r("10.."), FrameRange { start: 10, end: None });
        assert_eq!(r("..5"), FrameRange { start: 0, end: Some(5) });
        assert_eq!(r("7"), FrameRange { start: 7, end: Some(8) });
        assert!(!r("10..20").contains(20) && r("10..20").contains(19) && !r("10..20").contains(9));
        for bad in ["20..10", "5..5", "a..b", "", "1..x", "-3"] {
            assert!(bad.parse::<FrameRange>().is_err(), "{bad}");
        }
    }

    #[test]
    fn cut_keeps_the_rest_and_refuses_a_range_that_matches_nothing() {
        let v: Vec<Sample> = (0..30).map(|k| s(k, k as f64 / 30.0)).collect();
        let kept = cut(&v, &["5..10".parse().unwrap(), "20..=22".parse().unwrap()]).unwrap();
        let idx: Vec<u64> = kept.iter().map(|s| s.frame).collect();
        let want: Vec<u64> = (0..5).chain(10..20).chain(23..30).collect();
        assert_eq!(idx, want);
        let e = cut(&v, &["40..50".parse().unwrap()]).unwrap_err().to_string();
        assert!(
            e.contains("--drop 40..50 matches no frame") && e.contains("frames 0..=29"),
            "{e}"
        );
    }

    #[test]
    fn merge_numbers_and_times_the_parts_one_after_the_other() {
        let a: Vec<Sample> = (3..6).map(|k| s(k, k as f64 * 0.1)).collect();
        let b: Vec<Sample> = (0..2).map(|k| s(k, 5.0 + k as f64 * 0.05)).collect();
        let parts = vec![("a".to_string(), a), ("b".to_string(), b)];
        let m = merge(&parts);
        let f: Vec<u64> = m.iter().map(|p| p.frame).collect();
        assert_eq!(f, vec![0, 1, 2, 3, 4]);
        let t: Vec<f64> = m.iter().map(|p| (p.time_s * 1000.0).round()).collect();
        // a: 0, 100, 200 ms; then one median step (100 ms) later b: 300, 350 ms.
        assert_eq!(t, vec![0.0, 100.0, 200.0, 300.0, 350.0]);
        assert_eq!(m[3].origin.as_deref(), Some("b"));
    }

    #[test]
    fn the_label_is_what_was_sent() {
        let v: Value = serde_json::from_str(
            r#"{"steer":0.3,"throttle":0.5,"sent":{"steer":0.0,"throttle":0.0},"drive_mode":"manual"}"#,
        )
        .unwrap();
        assert_eq!(telemetry_label(&v).unwrap(), (0.0, 0.0, DriveMode::Manual));
        let v: Value = serde_json::from_str(r#"{"steer":-0.25,"throttle":0.5}"#).unwrap();
        assert_eq!(telemetry_label(&v).unwrap(), (-0.25, 0.5, DriveMode::Autopilot));
        let v: Value = serde_json::from_str(r#"{"steer":1.5,"throttle":0.5}"#).unwrap();
        assert!(telemetry_label(&v).unwrap_err().contains("outside -1..1"));
        let v: Value = serde_json::from_str(r#"{"steer":0.1,"throttle":0.5,"drive_mode":"robot"}"#).unwrap();
        assert!(telemetry_label(&v).unwrap_err().contains("drive_mode"));
    }
}
