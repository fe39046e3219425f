//! Recording on the car: camera frames as JPEG and the telemetry lines, in one run folder,
//! within a disk budget, replayable by `rccar replay DIR`.
//!
//! Layout of a recording (`DIR` is the folder given to `--record`):
//!
//! ```text
//! DIR/
//!   telemetry.jsonl            one line per frame, as the drive loop writes it; flushed
//!                              to the OS per line, fsynced by finish(); never deleted
//!   seg_000000/                frames 0 .. segment_frames-1 of the run
//!     frame_000000000.jpg      frame index zero-padded to 9 digits, so the name order
//!     frame_000000001.jpg      is the time order (`ReplayDir` sorts by name)
//!     ...
//!   seg_000001/                the next segment_frames frames, and so on
//! ```
//!
//! Disk budget (`max_bytes`, config `record.max_mb`): the recorder counts what it wrote,
//! each file rounded up to 4 KiB blocks as a filesystem stores it. Before a frame is written,
//! while the frames plus the telemetry would exceed the budget, the oldest closed segment is
//! deleted (oldest frames go first; the telemetry and the segment being filled are never
//! deleted). If that is not enough, the frame is not written and is counted in
//! [`RecordStats::frames_over_budget`]; so a budget should hold several segments.
//!
//! Failures: [`Recorder::create`] makes the folder, refuses one that is not empty (it would
//! mix two runs: a new or empty folder only), and proves it can write there (a 256 KiB probe file, fsynced, then deleted), so
//! a read-only or full folder is one clear error naming the path before the car moves. A
//! card that fills up before the budget is reached (ENOSPC) makes the recorder delete the
//! oldest closed segment and try again, as if over budget. A write that still fails (card
//! full with nothing left to delete, card pulled) is counted in [`RecordStats`] and returned,
//! and the next frame tries again: a recording problem never ends the run. A recorder dropped
//! before anything was recorded (the run failed to start) removes what `create` made, so the
//! same folder can be used again at once.
//!
//! Frames are encoded with the `image` crate's baseline JPEG encoder at
//! `jpeg_quality` (1..=100); JPEG changes pixel values slightly, so a replay of a recording
//! sees frames that differ from the live ones by a few grey levels.

pub mod observer;

use image::codecs::jpeg::JpegEncoder;
use image::RgbImage;
use std::collections::VecDeque;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Name of the telemetry file inside a recording.
pub const TELEMETRY_FILE: &str = "telemetry.jsonl";
/// Prefix of the segment folders inside a recording.
pub const SEGMENT_PREFIX: &str = "seg_";
/// Size of the probe file written by [`Recorder::create`], bytes.
pub const PROBE_BYTES: usize = 256 * 1024;
/// Files are counted in whole blocks of this size, bytes.
const BLOCK: u64 = 4096;
const PROBE_FILE: &str = ".rccar_write_test";

/// The folder name of segment `k`.
pub fn segment_name(k: u64) -> String {
    format!("{SEGMENT_PREFIX}{k:06}")
}

/// The file name of frame `index`.
pub fn frame_name(index: u64) -> String {
    format!("frame_{index:09}.jpg")
}

/// The frame index in a recorded file name: `frame_000000123.jpg` → 123.
pub fn frame_index(file_name: &str) -> Option<u64> {
    let stem = file_name.strip_prefix("frame_")?.strip_suffix(".jpg")?;
    if stem.is_empty() || !stem.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    stem.parse().ok()
}

/// The longest telemetry line read back, bytes (a longer one is treated as cut).
pub const MAX_TELEMETRY_LINE: usize = 1 << 20;

/// The time of each recorded frame, read back from a recording's telemetry.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordedTimes {
    /// Frame number → `time_s`. Empty when the telemetry has no `time_s` at all (frames are
    /// then replayed 1/fps apart).
    pub times: std::collections::BTreeMap<u64, f64>,
    /// Line numbers (1-based) that are not JSON: cut by a crash or a full card (the recorder
    /// may leave a line torn). Skipped; their frames have no time and are not replayed.
    pub cut_lines: Vec<usize>,
}

/// Reads one line of `r` into `buf` (its newline kept), keeping at most
/// `MAX_TELEMETRY_LINE` bytes; `None` at the end, else whether the line was longer.
fn read_line(r: &mut impl std::io::BufRead, buf: &mut Vec<u8>) -> std::io::Result<Option<bool>> {
    buf.clear();
    let mut too_long = false;
    let mut any = false;
    loop {
        let chunk = r.fill_buf()?;
        if chunk.is_empty() {
            break;
        }
        any = true;
        let (take, done) = match chunk.iter().position(|&b| b == b'\n') {
            Some(k) => (k + 1, true),
            None => (chunk.len(), false),
        };
        if buf.len() + take <= MAX_TELEMETRY_LINE {
            buf.extend_from_slice(&chunk[..take]);
        } else {
            too_long = true;
        }
        r.consume(take);
        if done {
            break;
        }
    }
    Ok(any.then_some(too_long))
}

/// Reads `DIR/telemetry.jsonl` of a recording for the frames' times, so a replay can use the
/// recorded time steps (the car skips late frames, so they are not always 1/fps apart).
/// The drive loop must pass [`Recorder::write_frame`] the same index as the line's `frame`.
///
/// A line that is not JSON (cut) is skipped and listed in [`RecordedTimes::cut_lines`]: a
/// crash or a full card leaves such lines, and the rest of the recording is good. A line that
/// reads but contradicts the others refuses the whole recording with
/// [`RecordError::BadTelemetry`] naming the file and line, because then it is not known which
/// lines to trust (two runs in one folder, an edited file): a frame number that is missing,
/// repeated or not above the previous one; a `time_s` that is missing (when other lines have
/// one), not a finite number (a NaN is written as `null`), negative, or not after the
/// previous line's.
pub fn recorded_times(dir: &Path) -> Result<RecordedTimes, RecordError> {
    let path = dir.join(TELEMETRY_FILE);
    let file = File::open(&path).map_err(|err| RecordError::Read {
        path: path.clone(),
        err,
    })?;
    let mut r = std::io::BufReader::new(file);
    let bad = |line: usize, reason: String| RecordError::BadTelemetry {
        path: path.clone(),
        line,
        reason,
    };
    let mut out = RecordedTimes::default();
    // (frame, line) and (time, line) of the last good line; whether lines have times.
    let mut last_frame: Option<(u64, usize)> = None;
    let mut last_time: Option<(f64, usize)> = None;
    let mut with_time: Option<(bool, usize)> = None;
    let mut buf = Vec::with_capacity(4096);
    let mut line_no = 0;
    // 1. One line at a time, at most MAX_TELEMETRY_LINE bytes kept (a longer one counts as cut).
    while let Some(too_long) = read_line(&mut r, &mut buf).map_err(|err| RecordError::Read {
        path: path.clone(),
        err,
    })? {
        line_no += 1;
        if buf.iter().all(u8::is_ascii_whitespace) && !too_long {
            continue;
        }
        // 2. Not JSON: a cut line, skipped.
        let v: serde_json::Value = match (too_long, serde_json::from_slice(&buf)) {
            (false, Ok(v)) => v,
            _ => {
                out.cut_lines.push(line_no);
                continue;
            }
        };
        // 3. The frame number: present, above the last one.
        let frame = v
            .get("frame")
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| bad(line_no, "no frame number (`frame`)".into()))?;
        if let Some((f, l)) = last_frame {
            if frame == f {
                return Err(bad(line_no, format!("frame {frame} again (line {l} had it)")));
            }
            if frame < f {
                return Err(bad(
                    line_no,
                    format!("frame {frame} after frame {f} (line {l}): frame numbers must increase"),
                ));
            }
        }
        last_frame = Some((frame, line_no));
        // 4. Its time: on every line or none, finite, not negative, after the last one.
        let t = v.get("time_s");
        match (with_time, t.is_some()) {
            (Some((true, l)), false) => {
                return Err(bad(line_no, format!("no time_s (line {l} has one)")));
            }
            (Some((false, l)), true) => {
                return Err(bad(line_no, format!("a time_s, but line {l} has none")));
            }
            _ => with_time = Some((t.is_some(), line_no)),
        }
        let Some(t) = t else { continue };
        let t = t
            .as_f64()
            .filter(|t| t.is_finite())
            .ok_or_else(|| bad(line_no, format!("time_s {t} is not a finite number of seconds")))?;
        if t < 0.0 {
            return Err(bad(line_no, format!("time_s {t} is negative")));
        }
        if let Some((p, l)) = last_time {
            if t <= p {
                return Err(bad(
                    line_no,
                    format!("time_s {t} is not after line {l}'s {p}: times must increase"),
                ));
            }
        }
        last_time = Some((t, line_no));
        out.times.insert(frame, t);
    }
    Ok(out)
}

/// How to record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordOptions {
    /// JPEG quality, 1..=100 (values outside are clamped).
    pub jpeg_quality: u8,
    /// Disk budget of the whole recording (frames + telemetry), bytes.
    pub max_bytes: u64,
    /// Frames per segment folder (at least 1).
    pub segment_frames: u32,
}

impl Default for RecordOptions {
    fn default() -> Self {
        Self {
            jpeg_quality: 90,
            max_bytes: 2_000_000_000,
            segment_frames: 300,
        }
    }
}

/// What can go wrong while recording. Every variant names the path.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The folder cannot be made.
    #[error("{path}: cannot create the recording folder: {err}")]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// The folder exists but a test write failed (read-only, full, no permission).
    #[error("{path}: cannot record here: {err}")]
    NotWritable {
        /// The file that could not be written.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// The folder is not empty (a recording on top of another would mix two runs).
    #[error(
        "{path}: not empty (holds {found}); a recording goes into a new or empty folder: choose another, or remove it"
    )]
    NotEmpty {
        /// The folder.
        path: PathBuf,
        /// An entry in it.
        found: String,
    },
    /// A write during the run failed (counted; the run goes on).
    #[error("{path}: write failed: {err}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// A recording's telemetry contradicts itself (see [`recorded_times`]).
    #[error("{path}:{line}: {reason}; this recording's telemetry is damaged or holds two runs (record again, or replay a copy without the bad lines)")]
    BadTelemetry {
        /// The telemetry file.
        path: PathBuf,
        /// Line number, 1-based.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A recording's telemetry cannot be read back.
    #[error("{path}: cannot read: {err}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        err: std::io::Error,
    },
    /// A frame could not be encoded (counted; the run goes on).
    #[error("{path}: cannot encode JPEG: {message}")]
    Encode {
        /// The file it was meant for.
        path: PathBuf,
        /// Encoder message.
        message: String,
    },
}

/// Counters of one recording.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordStats {
    /// Frames written.
    pub frames_written: u64,
    /// Frames whose write failed.
    pub frames_failed: u64,
    /// Frames not written because the budget was used up even after deleting old segments.
    pub frames_over_budget: u64,
    /// Frames deleted with old segments.
    pub frames_deleted: u64,
    /// Segments deleted to stay within the budget.
    pub segments_deleted: u64,
    /// Telemetry lines written.
    pub telemetry_lines: u64,
    /// Telemetry lines whose write failed.
    pub telemetry_failed: u64,
    /// Bytes now on disk (frames kept + telemetry), counted in 4 KiB blocks.
    pub bytes_on_disk: u64,
    /// The last failure, for the status line.
    pub last_error: Option<String>,
}

#[derive(Debug)]
struct Segment {
    index: u64,
    path: PathBuf,
    bytes: u64,
    frames_kept: u64,
    frames_tried: u32,
    created: bool,
}

/// Writes one recording. See the module documentation for the layout and the budget.
#[derive(Debug)]
pub struct Recorder {
    dir: PathBuf,
    opts: RecordOptions,
    telemetry: File,
    telemetry_path: PathBuf,
    telemetry_bytes: u64,
    line: Vec<u8>,
    jpeg: Vec<u8>,
    closed: VecDeque<Segment>,
    current: Option<Segment>,
    next_segment: u64,
    stats: RecordStats,
    /// `create` made the folder (it did not exist).
    made_dir: bool,
    /// `finish` was called.
    finished: bool,
}

/// ENOSPC: the filesystem is full.
fn is_disk_full(e: &std::io::Error) -> bool {
    e.raw_os_error() == Some(28)
}

fn blocks(bytes: u64) -> u64 {
    bytes.div_ceil(BLOCK) * BLOCK
}

impl Recorder {
    /// Makes `dir` (and its parents), checks that it is empty and that a file can be written
    /// and synced there, and opens the telemetry file. Call it before the car moves: its error
    /// is the one line to show.
    pub fn create(dir: &Path, opts: RecordOptions) -> Result<Self, RecordError> {
        // 1. The folder.
        let made_dir = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|err| RecordError::CreateDir {
            path: dir.into(),
            err,
        })?;
        // 2. Empty: not a second recording on top of a first, nor beside other files.
        let entries = std::fs::read_dir(dir).map_err(|err| RecordError::CreateDir {
            path: dir.into(),
            err,
        })?;
        let mut names: Vec<String> = entries
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect();
        names.sort();
        if let Some(found) = names.into_iter().find(|n| n != PROBE_FILE) {
            return Err(RecordError::NotEmpty {
                path: dir.into(),
                found,
            });
        }
        // 3. A real write, synced so that a full card fails now and not at the first frame.
        let probe = dir.join(PROBE_FILE);
        let probe_result = (|| {
            let mut f = File::create(&probe)?;
            f.write_all(&vec![0u8; PROBE_BYTES])?;
            f.sync_all()
        })();
        let _ = std::fs::remove_file(&probe);
        // A folder made here is taken back when the checks fail.
        let unmake = || {
            if made_dir {
                let _ = std::fs::remove_dir(dir);
            }
        };
        probe_result.map_err(|err| {
            unmake();
            RecordError::NotWritable {
                path: probe.clone(),
                err,
            }
        })?;
        // 4. The telemetry file.
        let telemetry_path = dir.join(TELEMETRY_FILE);
        let telemetry = File::create(&telemetry_path).map_err(|err| {
            unmake();
            RecordError::NotWritable {
                path: telemetry_path.clone(),
                err,
            }
        })?;
        Ok(Self {
            dir: dir.into(),
            opts: RecordOptions {
                jpeg_quality: opts.jpeg_quality.clamp(1, 100),
                segment_frames: opts.segment_frames.max(1),
                ..opts
            },
            telemetry,
            telemetry_path,
            telemetry_bytes: 0,
            line: Vec::with_capacity(4096),
            jpeg: Vec::with_capacity(64 * 1024),
            closed: VecDeque::new(),
            current: None,
            next_segment: 0,
            stats: RecordStats::default(),
            made_dir,
            finished: false,
        })
    }

    /// The recording folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The counters so far.
    pub fn stats(&self) -> &RecordStats {
        &self.stats
    }

    /// Bytes left of the disk budget (`record.max_mb`), counted as [`RecordStats::bytes_on_disk`].
    pub fn bytes_left(&self) -> u64 {
        self.opts.max_bytes.saturating_sub(self.used())
    }

    /// Writes frame `index` (the loop's frame number; it names the file) as JPEG into the
    /// current segment. An error is also counted in the stats; the caller reports it and
    /// goes on (never end the run for it). A frame skipped for the budget is `Ok` and counted
    /// in [`RecordStats::frames_over_budget`].
    pub fn write_frame(&mut self, index: u64, img: &RgbImage) -> Result<(), RecordError> {
        // 1. The segment this frame belongs to (a new one after segment_frames frames).
        if self
            .current
            .as_ref()
            .is_none_or(|s| s.frames_tried >= self.opts.segment_frames)
        {
            if let Some(full) = self.current.take() {
                self.closed.push_back(full);
            }
            let k = self.next_segment;
            self.next_segment += 1;
            self.current = Some(Segment {
                index: k,
                path: self.dir.join(segment_name(k)),
                bytes: 0,
                frames_kept: 0,
                frames_tried: 0,
                created: false,
            });
        }
        let seg = self.current.as_mut().expect("a current segment was just ensured");
        seg.frames_tried += 1;
        let path = seg.path.join(frame_name(index));

        // 2. Encode into memory, so the size is known before anything is written.
        self.jpeg.clear();
        let encoded = JpegEncoder::new_with_quality(&mut self.jpeg, self.opts.jpeg_quality).encode_image(img);
        if let Err(e) = encoded {
            return Err(self.frame_failed(RecordError::Encode {
                path,
                message: e.to_string(),
            }));
        }
        let size = blocks(self.jpeg.len() as u64);

        // 3. Make room: oldest closed segments first; the current one and telemetry stay.
        while self.used() + size > self.opts.max_bytes {
            let Some(old) = self.closed.pop_front() else { break };
            self.delete_segment(old);
        }
        if self.used() + size > self.opts.max_bytes {
            self.stats.frames_over_budget += 1;
            return Ok(());
        }

        // 4. Write (making the segment folder first; retried if it failed before).
        let seg = self.current.as_mut().expect("current segment");
        if !seg.created {
            if let Err(err) = std::fs::create_dir_all(&seg.path) {
                let path = seg.path.clone();
                return Err(self.frame_failed(RecordError::Write { path, err }));
            }
            seg.created = true;
        }
        let mut written = std::fs::write(&path, &self.jpeg);
        // The card is fuller than the budget assumed: make room as if over budget, retry.
        while written.as_ref().is_err_and(is_disk_full) && !self.closed.is_empty() {
            let _ = std::fs::remove_file(&path);
            if let Some(old) = self.closed.pop_front() {
                self.delete_segment(old);
            }
            written = std::fs::write(&path, &self.jpeg);
        }
        let seg = self.current.as_mut().expect("current segment");
        match written {
            Ok(()) => {
                seg.bytes += size;
                seg.frames_kept += 1;
                self.stats.frames_written += 1;
                self.stats.bytes_on_disk = self.used();
                Ok(())
            }
            Err(err) => {
                // A partial file would replay as a damaged frame: remove it. A folder that
                // vanished is made again for the next frame.
                let _ = std::fs::remove_file(&path);
                if !seg.path.is_dir() {
                    seg.created = false;
                }
                Err(self.frame_failed(RecordError::Write { path, err }))
            }
        }
    }

    /// Appends one telemetry line (a newline is added) and hands it to the OS at once, so a
    /// crash loses at most the line being written. A failure is counted and returned (a line
    /// that failed part-way may be left torn in the file); the caller reports it and goes on.
    pub fn write_telemetry_line(&mut self, line: &str) -> Result<(), RecordError> {
        self.line.clear();
        self.line.extend_from_slice(line.trim_end_matches('\n').as_bytes());
        self.line.push(b'\n');
        // Written piece by piece so that after a full card has been given room (old frames
        // deleted) the line goes on where it stopped: no torn or doubled lines.
        let mut off = 0;
        let written = loop {
            match self.telemetry.write(&self.line[off..]) {
                Ok(0) => break Err(std::io::Error::from(std::io::ErrorKind::WriteZero)),
                Ok(n) => {
                    off += n;
                    if off == self.line.len() {
                        break Ok(());
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if is_disk_full(&e) && !self.closed.is_empty() => {
                    if let Some(old) = self.closed.pop_front() {
                        self.delete_segment(old);
                    }
                }
                Err(e) => break Err(e),
            }
        };
        self.telemetry_bytes += off as u64;
        match written {
            Ok(()) => {
                self.stats.telemetry_lines += 1;
                self.stats.bytes_on_disk = self.used();
                Ok(())
            }
            Err(err) => {
                self.stats.telemetry_failed += 1;
                let e = RecordError::Write {
                    path: self.telemetry_path.clone(),
                    err,
                };
                self.stats.last_error = Some(e.to_string());
                Err(e)
            }
        }
    }

    /// Syncs the telemetry to the card and returns the counters. Dropping a recorder without
    /// `finish` loses nothing that was written (every line went to the OS), only the fsync.
    pub fn finish(mut self) -> Result<RecordStats, RecordError> {
        self.finished = true;
        self.telemetry
            .flush()
            .and_then(|_| self.telemetry.sync_all())
            .map_err(|err| RecordError::Write {
                path: self.telemetry_path.clone(),
                err,
            })?;
        Ok(std::mem::take(&mut self.stats))
    }

    /// Bytes counted against the budget: telemetry + every kept frame.
    fn used(&self) -> u64 {
        blocks(self.telemetry_bytes)
            + self.closed.iter().map(|s| s.bytes).sum::<u64>()
            + self.current.as_ref().map_or(0, |s| s.bytes)
    }

    fn delete_segment(&mut self, seg: Segment) {
        if seg.created {
            if let Err(e) = std::fs::remove_dir_all(&seg.path) {
                // Its bytes are still on the card; nothing better to do than say so.
                self.stats.last_error = Some(format!("{}: cannot delete old segment: {e}", seg.path.display()));
            }
        }
        debug_assert!(seg.index < self.next_segment);
        self.stats.segments_deleted += 1;
        self.stats.frames_deleted += seg.frames_kept;
        self.stats.bytes_on_disk = self.used();
    }

    fn frame_failed(&mut self, e: RecordError) -> RecordError {
        self.stats.frames_failed += 1;
        self.stats.last_error = Some(e.to_string());
        e
    }
}

impl Drop for Recorder {
    /// Dropped without `finish` before anything was tried (the run failed to start): takes
    /// back the empty telemetry file and the folder `create` made, so a retry can use it.
    fn drop(&mut self) {
        let s = &self.stats;
        let nothing =
            s.frames_written + s.frames_failed + s.frames_over_budget + s.telemetry_lines + s.telemetry_failed == 0;
        if self.finished || !nothing || self.current.is_some() {
            return;
        }
        let _ = std::fs::remove_file(&self.telemetry_path);
        if self.made_dir {
            let _ = std::fs::remove_dir(&self.dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::{FrameSource, ReplayDir};
    use std::process::Command;

    fn opts(max_bytes: u64, segment_frames: u32) -> RecordOptions {
        RecordOptions {
            jpeg_quality: 90,
            max_bytes,
            segment_frames,
        }
    }

    /// A frame with structure (stripes that move with `k`) and noise, so JPEG sizes are
    /// realistic (roughly 15-30 kB at 320×240, quality 90).
    fn frame(k: u64) -> RgbImage {
        let mut seed = k.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        RgbImage::from_fn(320, 240, |x, y| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let n = (seed >> 59) as u8; // 0..31 of noise
            let stripe = if ((x + k as u32 * 3) / 20).is_multiple_of(2) { 200 } else { 60 };
            let v = stripe - 16 + n;
            image::Rgb([v, (y % 256) as u8, v / 2])
        })
    }

    /// Bytes of all files under `dir`, rounded to blocks like the recorder counts them.
    fn disk_usage(dir: &Path) -> u64 {
        let mut total = 0;
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                total += disk_usage(&p);
            } else {
                total += blocks(std::fs::metadata(&p).unwrap().len());
            }
        }
        total
    }

    fn segments(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with(SEGMENT_PREFIX))
            .collect();
        v.sort();
        v
    }

    #[test]
    fn names_sort_in_time_order() {
        assert_eq!(frame_name(7), "frame_000000007.jpg");
        assert_eq!(segment_name(12), "seg_000012");
        let mut names: Vec<String> = [1000u64, 9, 10, 99, 100_000_000]
            .iter()
            .map(|&i| frame_name(i))
            .collect();
        names.sort();
        assert_eq!(names[0], frame_name(9));
        assert_eq!(names[4], frame_name(100_000_000));
    }

    #[test]
    fn frame_times_read_back() {
        assert_eq!(frame_index(&frame_name(123)), Some(123));
        assert_eq!(frame_index("frame_000.png"), None);
        assert_eq!(frame_index("frame_.jpg"), None);
        assert_eq!(frame_index("frame_-1.jpg"), None);
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let mut r = Recorder::create(&dir, RecordOptions::default()).unwrap();
        // Frames 0, 1, 3 (frame 2 came late and was skipped), then a torn line.
        for (k, t) in [(0u64, 0.0), (1, 0.0334), (3, 0.1002)] {
            r.write_frame(k, &frame(k)).unwrap();
            r.write_telemetry_line(&format!("{{\"frame\":{k},\"time_s\":{t},\"steer\":0.1}}"))
                .unwrap();
        }
        r.write_telemetry_line("{\"frame\":4,\"ti").unwrap();
        r.finish().unwrap();
        let t = recorded_times(&dir).unwrap();
        assert_eq!(t.times.len(), 3);
        assert_eq!(t.times[&3], 0.1002);
        assert_eq!(t.cut_lines, [4]);
        let e = recorded_times(tmp.path()).unwrap_err().to_string();
        assert!(e.contains("telemetry.jsonl") && e.contains("cannot read"), "{e}");
    }

    /// The times of a telemetry file with these lines.
    fn times_of(lines: &[&str]) -> Result<RecordedTimes, RecordError> {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join(TELEMETRY_FILE), lines.join("\n") + "\n").unwrap();
        recorded_times(tmp.path())
    }

    #[test]
    fn recorded_times_refuse_lines_that_contradict_the_others() {
        let ok = times_of(&[
            r#"{"frame":0,"time_s":0.0}"#,
            r#"{"frame":2,"ti"#,
            r#"{"frame":3,"time_s":0.1}"#,
            "",
        ])
        .unwrap();
        assert_eq!(ok.times.len(), 2);
        assert_eq!(ok.cut_lines, [2]);
        // No times at all: none (frames 1/fps apart); frame numbers are still checked.
        assert!(times_of(&[r#"{"frame":0}"#, r#"{"frame":1}"#])
            .unwrap()
            .times
            .is_empty());
        for (lines, want) in [
            (
                &[r#"{"frame":0,"time_s":0}"#, r#"{"frame":0,"time_s":1}"#][..],
                ":2: frame 0 again (line 1 had it)",
            ),
            (
                &[r#"{"frame":5,"time_s":0}"#, r#"{"frame":4,"time_s":1}"#],
                ":2: frame 4 after frame 5 (line 1)",
            ),
            (&[r#"{"time_s":0}"#], ":1: no frame number"),
            (&[r#"{"frame":1,"time_s":-100}"#], ":1: time_s -100 is negative"),
            (
                &[r#"{"frame":1,"time_s":null}"#],
                ":1: time_s null is not a finite number",
            ),
            (
                &[r#"{"frame":1,"time_s":"1"}"#],
                ":1: time_s \"1\" is not a finite number",
            ),
            (
                &[r#"{"frame":1,"time_s":0.5}"#, r#"{"frame":2,"time_s":0.5}"#],
                ":2: time_s 0.5 is not after line 1's 0.5",
            ),
            (
                &[r#"{"frame":1,"time_s":0.5}"#, r#"{"frame":2}"#],
                ":2: no time_s (line 1 has one)",
            ),
            (
                &[r#"{"frame":1}"#, r#"{"frame":2,"time_s":0.5}"#],
                ":2: a time_s, but line 1 has none",
            ),
        ] {
            let e = times_of(lines).unwrap_err().to_string();
            assert!(
                e.contains(&format!("telemetry.jsonl{want}")) && e.contains("damaged or holds two runs"),
                "{lines:?}: {e}"
            );
        }
        // A line longer than the bound is a cut line, never held whole.
        let long = format!(r#"{{"frame":1,"time_s":0.5,"x":"{}"}}"#, "y".repeat(MAX_TELEMETRY_LINE));
        let t = times_of(&[r#"{"frame":0,"time_s":0}"#, &long, r#"{"frame":2,"time_s":1}"#]).unwrap();
        assert_eq!((t.times.len(), t.cut_lines.as_slice()), (2, &[2][..]));
    }

    #[test]
    fn a_recorder_dropped_before_recording_takes_back_its_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        drop(Recorder::create(&dir, RecordOptions::default()).unwrap());
        assert!(!dir.exists(), "a failed start leaves nothing");
        // An empty folder that was there stays, empty.
        std::fs::create_dir(&dir).unwrap();
        drop(Recorder::create(&dir, RecordOptions::default()).unwrap());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        // Once something was recorded, or after finish, everything stays.
        let mut r = Recorder::create(&dir, RecordOptions::default()).unwrap();
        r.write_telemetry_line("{}").unwrap();
        drop(r);
        assert!(dir.join(TELEMETRY_FILE).is_file());
        let other = tmp.path().join("other");
        Recorder::create(&other, RecordOptions::default())
            .unwrap()
            .finish()
            .unwrap();
        assert!(other.join(TELEMETRY_FILE).is_file());
    }

    #[test]
    fn budget_deletes_oldest_segments_and_keeps_telemetry() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        // About 4 segments of 5 frames fit in 500 kB; 60 frames need about 12.
        let mut r = Recorder::create(&dir, opts(500_000, 5)).unwrap();
        for k in 0..60u64 {
            r.write_frame(k, &frame(k)).unwrap();
            r.write_telemetry_line(&format!("{{\"frame\":{k},\"steer\":0.{k:03}}}"))
                .unwrap();
            let used = disk_usage(&dir);
            assert!(used <= 500_000, "frame {k}: {used} bytes on disk > budget");
            assert_eq!(
                used,
                r.stats().bytes_on_disk,
                "frame {k}: the recorder's count is the disk's"
            );
        }
        let s = r.finish().unwrap();
        eprintln!(
            "budget 500 kB, 60 frames in segments of 5: {s:?}, left {:?}",
            segments(&dir)
        );
        // Every frame was written, old ones were deleted, none skipped.
        assert_eq!(s.frames_written, 60);
        assert_eq!(s.frames_over_budget, 0);
        assert_eq!(s.frames_failed, 0);
        assert!(s.segments_deleted >= 6, "{s:?}");
        assert_eq!(s.frames_deleted, s.segments_deleted * 5);
        // The segments left are the newest ones, contiguous, ending with the last.
        let segs = segments(&dir);
        let first = s.segments_deleted;
        let want: Vec<String> = (first..12).map(segment_name).collect();
        assert_eq!(segs, want, "{s:?}");
        // The telemetry is complete: 60 lines, in order.
        let tel = std::fs::read_to_string(dir.join(TELEMETRY_FILE)).unwrap();
        let lines: Vec<&str> = tel.lines().collect();
        assert_eq!(lines.len(), 60);
        assert_eq!(lines[0], "{\"frame\":0,\"steer\":0.000}");
        assert_eq!(lines[59], "{\"frame\":59,\"steer\":0.059}");
    }

    #[test]
    fn tiny_budget_skips_frames_but_never_telemetry() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        // 40 kB: about one frame next to the telemetry.
        let mut r = Recorder::create(&dir, opts(40_000, 3)).unwrap();
        let long_line = "x".repeat(2000);
        let mut tel_since_frame = 0;
        for k in 0..30u64 {
            let before = r.stats().frames_written;
            r.write_frame(k, &frame(k)).unwrap();
            if r.stats().frames_written > before {
                tel_since_frame = 0;
            }
            r.write_telemetry_line(&long_line).unwrap();
            tel_since_frame += 2001;
            // Within the budget when a frame is written; telemetry written since may pass it.
            let used = disk_usage(&dir);
            assert!(used <= 40_000 + blocks(tel_since_frame), "frame {k}: {used} bytes");
        }
        let s = r.finish().unwrap();
        assert!(s.frames_over_budget > 0, "{s:?}");
        assert_eq!(s.telemetry_lines, 30);
        let tel = std::fs::read_to_string(dir.join(TELEMETRY_FILE)).unwrap();
        assert_eq!(
            tel.lines().count(),
            30,
            "telemetry is never deleted, even past the budget"
        );
        assert_eq!(tel.len(), 30 * 2001);
    }

    #[test]
    fn round_trip_through_replay_dir() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let mut r = Recorder::create(&dir, opts(1_000_000_000, 4)).unwrap();
        let frames: Vec<RgbImage> = (0..11).map(frame).collect();
        for (k, f) in frames.iter().enumerate() {
            r.write_frame(k as u64, f).unwrap();
            r.write_telemetry_line(&format!("{{\"frame\":{k}}}")).unwrap();
        }
        r.finish().unwrap();
        assert_eq!(segments(&dir), vec!["seg_000000", "seg_000001", "seg_000002"]);
        let mut src = ReplayDir::open(&dir, 30.0, 320, 240, (320, 240)).unwrap();
        assert_eq!(src.len_hint(), Some(11));
        assert_eq!(src.ignored(), &[TELEMETRY_FILE.to_string()]);
        let mut k = 0;
        while let Some(f) = src.next_frame() {
            let f = f.unwrap();
            assert_eq!(f.index, k as u64);
            assert!(f.name.ends_with(&frame_name(k as u64)), "{}", f.name);
            assert!((f.time_s - k as f64 / 30.0).abs() < 1e-12);
            // JPEG at quality 90: the replayed frame is the recorded one within a few levels.
            let diff: f64 = f
                .image
                .as_raw()
                .iter()
                .zip(frames[k].as_raw())
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
                / f.image.as_raw().len() as f64;
            eprintln!("frame {k}: mean |recorded - replayed| = {diff:.2} grey levels");
            assert!(diff < 6.0, "frame {k}: mean |diff| {diff:.2} grey levels");
            // The frame is its own, not a neighbour: the stripes moved by 3 px per frame.
            if k > 0 {
                let other: f64 = f
                    .image
                    .as_raw()
                    .iter()
                    .zip(frames[k - 1].as_raw())
                    .map(|(a, b)| (*a as f64 - *b as f64).abs())
                    .sum::<f64>()
                    / f.image.as_raw().len() as f64;
                assert!(other > diff + 5.0, "frame {k}: {other:.2} vs {diff:.2}");
            }
            k += 1;
        }
        assert_eq!(k, 11);
    }

    #[test]
    fn a_folder_that_holds_a_recording_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let mut r = Recorder::create(&dir, RecordOptions::default()).unwrap();
        r.write_frame(0, &frame(0)).unwrap();
        r.finish().unwrap();
        let e = Recorder::create(&dir, RecordOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&dir.display().to_string()) && e.contains("not empty (holds seg_000000)"),
            "{e}"
        );
        // Other files too (a recording goes into a new or empty folder); an empty one is fine.
        let other = tmp.path().join("notes");
        std::fs::create_dir(&other).unwrap();
        std::fs::write(other.join("README.txt"), "car 3").unwrap();
        let e = Recorder::create(&other, RecordOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("not empty (holds README.txt)"), "{e}");
        std::fs::remove_file(other.join("README.txt")).unwrap();
        Recorder::create(&other, RecordOptions::default()).unwrap();
    }

    #[test]
    fn uncreatable_folder_names_the_path() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("a_file");
        std::fs::write(&file, "x").unwrap();
        let dir = file.join("run");
        let e = Recorder::create(&dir, RecordOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(&dir.display().to_string()) && e.contains("cannot create"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
    }

    #[test]
    fn full_device_is_refused_before_the_run() {
        // The probe file is a link to /dev/full: its write fails with ENOSPC, as on a full card.
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        std::fs::create_dir(&dir).unwrap();
        std::os::unix::fs::symlink("/dev/full", dir.join(PROBE_FILE)).unwrap();
        let e = Recorder::create(&dir, RecordOptions::default()).unwrap_err();
        assert!(
            matches!(&e, RecordError::NotWritable { err, .. } if err.raw_os_error() == Some(28)),
            "{e:?}"
        );
        let msg = e.to_string();
        assert!(
            msg.contains(&dir.display().to_string()) && msg.contains("cannot record here"),
            "{msg}"
        );
        assert!(
            !dir.join(TELEMETRY_FILE).exists(),
            "nothing created when the check fails"
        );
    }

    #[test]
    fn write_failures_mid_run_are_counted_and_the_run_goes_on() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let mut r = Recorder::create(&dir, opts(1_000_000_000, 4)).unwrap();
        r.write_frame(0, &frame(0)).unwrap();
        // Frame 2's file turns out to be on a full device (ENOSPC) ...
        std::os::unix::fs::symlink("/dev/full", dir.join("seg_000000").join(frame_name(2))).unwrap();
        r.write_frame(1, &frame(1)).unwrap();
        let e = r.write_frame(2, &frame(2)).unwrap_err().to_string();
        assert!(e.contains("frame_000000002.jpg") && e.contains("write failed"), "{e}");
        // ... and the next segment's folder vanishes under us (card pulled and put back).
        r.write_frame(3, &frame(3)).unwrap();
        r.write_frame(4, &frame(4)).unwrap(); // opens seg_000001
        std::fs::remove_dir_all(dir.join("seg_000001")).unwrap();
        assert!(r.write_frame(5, &frame(5)).is_err());
        r.write_frame(6, &frame(6)).unwrap(); // folder made again
        r.write_telemetry_line("{}").unwrap();
        let s = r.finish().unwrap();
        assert_eq!((s.frames_written, s.frames_failed), (5, 2), "{s:?}");
        assert!(s.last_error.unwrap().contains("frame_000000005.jpg"));
        assert!(dir.join("seg_000001").join(frame_name(6)).is_file());
    }

    /// A tmpfs mounted for one test (root only); unmounted on drop.
    struct Mount(PathBuf);
    impl Mount {
        fn tmpfs(at: &Path, opts: &str) -> Option<Mount> {
            let ok = Command::new("mount")
                .args(["-t", "tmpfs", "-o", opts, "tmpfs"])
                .arg(at)
                .status()
                .is_ok_and(|s| s.success());
            if !ok {
                eprintln!("cannot mount a tmpfs here (not root?): this part is not checked");
            }
            ok.then(|| Mount(at.into()))
        }
    }
    impl Drop for Mount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }

    #[test]
    fn read_only_and_full_filesystems() {
        let tmp = tempfile::tempdir().unwrap();
        // Read-only: a read-only tmpfs (as root), or a folder without write permission.
        let ro = tmp.path().join("ro");
        std::fs::create_dir(&ro).unwrap();
        let _m1 = Mount::tmpfs(&ro, "ro,size=1m");
        if _m1.is_none() {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        }
        let e = Recorder::create(&ro, RecordOptions::default()).unwrap_err().to_string();
        assert!(e.contains(&ro.display().to_string()), "{e}");
        assert!(
            e.contains("Read-only file system") || e.contains("ermission denied"),
            "{e}"
        );
        eprintln!("read-only: {e}");
        // Full: a 128 KiB tmpfs cannot take the 256 KiB probe.
        let full = tmp.path().join("full");
        std::fs::create_dir(&full).unwrap();
        if let Some(_m2) = Mount::tmpfs(&full, "size=128k") {
            let e = Recorder::create(&full.join("run"), RecordOptions::default())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("run/.rccar_write_test") && e.contains("No space left"),
                "{e}"
            );
            eprintln!("full: {e}");
        }
        // Filling up during the run: 1 MiB takes the probe and about 30 frames. With a
        // budget far above that, the full card makes the recorder drop old segments itself;
        // with segments as big as the card, writes fail, are counted, and the run goes on.
        let small = tmp.path().join("small");
        std::fs::create_dir(&small).unwrap();
        if let Some(_m3) = Mount::tmpfs(&small, "size=1m") {
            for (seg_frames, sub) in [(5u32, "a"), (1000, "b")] {
                let dir = small.join(sub);
                let mut r = Recorder::create(&dir, opts(1_000_000_000, seg_frames)).unwrap();
                let mut failed = 0;
                for k in 0..100u64 {
                    failed += usize::from(r.write_frame(k, &frame(k)).is_err());
                    let _ = r.write_telemetry_line("{\"frame\":1}");
                }
                let s = r.finish().unwrap();
                eprintln!("1 MiB tmpfs, 100 frames, segments of {seg_frames}: {s:?}");
                assert_eq!(s.frames_failed as usize, failed);
                assert_eq!(s.frames_written + s.frames_failed, 100, "{s:?}");
                assert_eq!(s.telemetry_lines, 100, "{s:?}");
                if seg_frames == 5 {
                    assert!(s.frames_failed <= 1 && s.segments_deleted >= 10, "{s:?}");
                    // The last frame is on the card.
                    assert!(dir.join(segment_name(19)).join(frame_name(99)).is_file());
                } else {
                    assert!(s.frames_written > 5 && s.frames_written < 50, "{s:?}");
                    assert!(s.last_error.as_deref().unwrap_or("").contains("No space left"), "{s:?}");
                }
                drop(std::fs::remove_dir_all(&dir));
            }
        }
    }
}
