//! Writing datasets: a new recording (the layout of `crate::record`, so `rccar replay` plays
//! it with its times) from placed samples, and the output-folder rules both writers share.
//!
//! An output folder must be new or empty and must not lie inside an input (inputs are only
//! read). If writing fails half-way, what was written is removed again, so a failed command
//! leaves no half dataset that looks whole.
//!
//! Frames: a JPEG frame kept at its size is copied byte for byte (no second JPEG loss); a PNG
//! frame, or one resized (`size`), is encoded as JPEG at `quality`. A frame that cannot be read
//! or decoded is skipped and listed with its file.

use super::{DatasetError, Placed, Skipped};
use crate::record::{frame_name, segment_name, TELEMETRY_FILE};
use image::codecs::jpeg::JpegEncoder;
use serde_json::{json, Value};
use std::io::Write;
use std::path::{Path, PathBuf};

/// How frames are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameOptions {
    /// Resize every frame to width × height (None: keep each frame's size and JPEG bytes).
    pub size: Option<(u32, u32)>,
    /// JPEG quality for frames that must be encoded, 1..=100.
    pub quality: u8,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            size: None,
            quality: 90,
        }
    }
}

/// What a writer did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteReport {
    /// Frames written (with their labels).
    pub frames: usize,
    /// Frames copied byte for byte.
    pub copied: usize,
    /// Frames decoded and encoded again (PNG, or resized).
    pub encoded: usize,
    /// Frames skipped: their image could not be read.
    pub skipped: Vec<Skipped>,
}

/// A folder being filled; emptied again on drop unless [`Output::keep`] was called.
#[derive(Debug)]
pub struct Output {
    dir: PathBuf,
    made: bool,
    keep: bool,
}

impl Output {
    /// Checks and makes `out`: new or empty, not inside any of `inputs`.
    pub fn create(out: &Path, inputs: &[&Path]) -> Result<Output, DatasetError> {
        let abs = absolute(out);
        for input in inputs {
            let inp = absolute(input);
            if abs.starts_with(&inp) {
                return Err(DatasetError::InsideInput {
                    out: out.into(),
                    input: input.to_path_buf(),
                });
            }
        }
        let made = !out.exists();
        if !made {
            let rd = std::fs::read_dir(out).map_err(|err| DatasetError::Read { path: out.into(), err })?;
            let mut names: Vec<String> = rd
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            if let Some(found) = names.into_iter().next() {
                return Err(DatasetError::NotEmpty {
                    path: out.into(),
                    found,
                });
            }
        }
        std::fs::create_dir_all(out).map_err(|err| DatasetError::Write { path: out.into(), err })?;
        Ok(Output {
            dir: out.into(),
            made,
            keep: false,
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Everything was written: keep it.
    pub fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        if self.keep {
            return;
        }
        if self.made {
            let _ = std::fs::remove_dir_all(&self.dir);
        } else if let Ok(rd) = std::fs::read_dir(&self.dir) {
            // It was empty when we started: everything in it is ours.
            for e in rd.flatten() {
                let p = e.path();
                let _ = if p.is_dir() {
                    std::fs::remove_dir_all(&p)
                } else {
                    std::fs::remove_file(&p)
                };
            }
        }
    }
}

/// `p` made absolute and, as far as it exists, with symbolic links resolved.
fn absolute(p: &Path) -> PathBuf {
    let abs = if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(p)
    };
    // Resolve the longest existing ancestor, then put the rest back.
    let mut rest = Vec::new();
    let mut cur = abs.as_path();
    loop {
        if let Ok(c) = cur.canonicalize() {
            let mut out = c;
            for r in rest.iter().rev() {
                out.push(r);
            }
            return out;
        }
        match (cur.parent(), cur.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                cur = parent;
            }
            _ => return abs,
        }
    }
}

/// Writes the frame `src` to `dst` as JPEG: copied when it is a JPEG of the wanted size,
/// else decoded (resized) and encoded. `Ok(true)`: copied. `Err(Ok(reason))`: the source
/// frame is unusable (skip it); `Err(Err(e))`: the write failed (stop).
pub(crate) fn put_frame(src: &Path, dst: &Path, opts: FrameOptions) -> Result<bool, Result<String, DatasetError>> {
    let bytes = std::fs::read(src).map_err(|e| Ok(format!("cannot read: {e}")))?;
    if bytes.is_empty() {
        return Err(Ok("empty file (0 bytes)".into()));
    }
    if let Some(why) = crate::source::image_damage(&bytes) {
        return Err(Ok(why));
    }
    let write =
        |data: &[u8]| std::fs::write(dst, data).map_err(|err| Err(DatasetError::Write { path: dst.into(), err }));
    let dims = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| Ok(format!("cannot read: {e}")))?
        .into_dimensions()
        .map_err(|e| Ok(format!("not a readable image: {e}")))?;
    if crate::imageio::is_jpeg(&bytes) && opts.size.is_none_or(|s| s == dims) {
        write(&bytes)?;
        return Ok(true);
    }
    let mut img = crate::source::decode_image(&bytes).map_err(Ok)?.to_rgb8();
    if let Some((w, h)) = opts.size.filter(|&s| s != dims) {
        img = image::imageops::resize(&img, w, h, image::imageops::FilterType::Triangle);
    }
    let mut jpeg = Vec::with_capacity(64 * 1024);
    JpegEncoder::new_with_quality(&mut jpeg, opts.quality.clamp(1, 100))
        .encode_image(&img)
        .map_err(|e| Ok(format!("cannot encode JPEG: {e}")))?;
    write(&jpeg)?;
    Ok(false)
}

/// The telemetry line of a placed sample: the line as read when nothing about it changed
/// (`cut`), else the line with its new `frame`, `time_s` and `file` and a `dataset` object
/// saying where it came from; for a sample without a telemetry line (a tub's), a line with
/// the label, the mode and who drove.
fn telemetry_line(p: &Placed<'_>) -> String {
    let s = p.sample;
    let unchanged = p.frame == s.frame && p.time_s == s.time_s && p.origin.is_none();
    if let (true, Some(raw)) = (unchanged, &s.telemetry) {
        return raw.clone();
    }
    let mut origin = serde_json::Map::new();
    if let Some(o) = &p.origin {
        origin.insert("from".into(), json!(o));
    }
    origin.insert("frame".into(), json!(s.frame));
    origin.insert("time_s".into(), json!(s.time_s));
    if let Some(sess) = &s.session {
        origin.insert("session".into(), json!(sess));
    }
    let mut v = match s.telemetry.as_deref().map(serde_json::from_str::<Value>) {
        Some(Ok(Value::Object(m))) => m,
        _ => {
            let mut m = serde_json::Map::new();
            m.insert("steer".into(), json!(s.steer));
            m.insert("throttle".into(), json!(s.throttle));
            m.insert("drive_mode".into(), json!(s.mode.name()));
            let pilot = match s.mode {
                crate::control::pilot::DriveMode::Manual => "human",
                crate::control::pilot::DriveMode::Assisted => "shared",
                crate::control::pilot::DriveMode::Autopilot => "autopilot",
            };
            m.insert("pilot".into(), json!(pilot));
            m
        }
    };
    v.insert("frame".into(), json!(p.frame));
    v.insert("file".into(), json!(frame_name(p.frame)));
    v.insert("time_s".into(), json!(p.time_s));
    v.insert("dataset".into(), Value::Object(origin));
    Value::Object(v).to_string()
}

/// Frames per segment folder in a written recording (as the recorder's default).
pub const SEGMENT_FRAMES: u64 = 300;

/// Writes `placed` as a new recording in `out`: seg_NNNNNN/frame_NNNNNNNNN.jpg (frame k in
/// segment k / 300) and telemetry.jsonl, one line per frame written. `inputs`: the folders
/// read, which `out` must not be inside. Frame numbers and times must increase.
pub fn write_recording(
    out: &Path,
    placed: &[Placed<'_>],
    inputs: &[&Path],
    opts: FrameOptions,
) -> Result<WriteReport, DatasetError> {
    if placed.is_empty() {
        return Err(DatasetError::Request("nothing to write: no frames left".into()));
    }
    for w in placed.windows(2) {
        assert!(
            w[1].frame > w[0].frame && w[1].time_s > w[0].time_s,
            "placed samples must increase in frame and time"
        );
    }
    let output = Output::create(out, inputs)?;
    let mut report = WriteReport::default();
    let mut tel = String::new();
    let mut made_seg = None;
    for p in placed {
        let seg = p.frame / SEGMENT_FRAMES;
        let seg_dir = out.join(segment_name(seg));
        if made_seg != Some(seg) {
            std::fs::create_dir_all(&seg_dir).map_err(|err| DatasetError::Write {
                path: seg_dir.clone(),
                err,
            })?;
            made_seg = Some(seg);
        }
        match put_frame(&p.sample.image, &seg_dir.join(frame_name(p.frame)), opts) {
            Ok(copied) => {
                report.frames += 1;
                if copied {
                    report.copied += 1;
                } else {
                    report.encoded += 1;
                }
            }
            Err(Ok(reason)) => {
                report.skipped.push(Skipped {
                    file: p.sample.image.clone(),
                    line: 0,
                    reason,
                });
                continue;
            }
            Err(Err(e)) => return Err(e),
        }
        tel.push_str(&telemetry_line(p));
        tel.push('\n');
    }
    if report.frames == 0 {
        return Err(DatasetError::Request("nothing written: no frame could be read".into()));
    }
    // Segment folders left empty by skipped frames are taken away again.
    for k in 0..=placed.last().map_or(0, |p| p.frame / SEGMENT_FRAMES) {
        let _ = std::fs::remove_dir(out.join(segment_name(k)));
    }
    let path = out.join(TELEMETRY_FILE);
    write_synced(&path, tel.as_bytes())?;
    output.keep();
    Ok(report)
}

/// Writes `data` to `path` and syncs it to the disk.
pub(crate) fn write_synced(path: &Path, data: &[u8]) -> Result<(), DatasetError> {
    let err = |err| DatasetError::Write { path: path.into(), err };
    let mut f = std::fs::File::create(path).map_err(err)?;
    f.write_all(data).map_err(err)?;
    f.sync_all().map_err(err)
}
