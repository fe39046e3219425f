//! Where frames come from: the camera, a folder of recorded images, or the simulator.
//!
//! A [`FrameSource`] yields frames one by one. A frame that cannot be used (unreadable file,
//! damaged, too small, too large) is reported as an `Err` for that frame only, so the caller
//! can name it, count it and go on: one bad frame never ends a run.
//!
//! Reading an image file ([`read_image`]) goes in three steps:
//! 1. structure check of the bytes ([`image_damage`]): a JPEG must reach its end-of-image
//!    marker (a JPEG cut short otherwise decodes with its missing part filled grey, with no
//!    error), a PNG must have every chunk complete with a matching CRC and an IEND;
//! 2. the size from the header, against [`crate::imageio::limits`], before any pixel is
//!    allocated;
//! 3. the decode itself ([`decode_image`], one function so another decoder can replace it).
//!
//! File names are kept lossless ([`escape_name`]) and output names unique ([`output_name`]).

use crate::classes::ObjectClass;
use crate::control::behaviour::LightColor;
use image::RgbImage;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};

/// One frame and where it came from.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Position in the sequence (counting frames that failed or were dropped).
    pub index: u64,
    /// Time since the start of the sequence, seconds: the time the pipeline sees (dt).
    pub time_s: f64,
    /// File name or label, escaped by [`escape_name`] (lossless for any file name); the
    /// same string names the frame in telemetry and, through [`output_name`], on disk.
    pub name: String,
    /// The image, resized to the configured camera size.
    pub image: RgbImage,
    /// When the frame was captured on the caller's clock ([`crate::timing::Clock`]), seconds;
    /// `None`: the loop takes the time it received the frame.
    pub captured_s: Option<f64>,
    /// Ground truth the source knows (the simulator), as JSON: telemetry carries it without
    /// knowing the simulator's types.
    pub truth: Option<serde_json::Value>,
    /// Boxes to use instead of the detector's (the simulator's ground-truth switch).
    pub given: Option<Vec<GivenBox>>,
    /// The second camera's view of the same moment (a stereo pair, `ranging.method =
    /// "stereo"`; src/drive/stereo.rs); `None` for a single camera.
    pub other: Option<OtherView>,
}

/// A box handed to the pipeline instead of the detector's (the simulator's ground truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GivenBox {
    /// What it is.
    pub class: ObjectClass,
    /// [left, top, right, bottom], pixel-centre coordinates.
    pub bbox: [f64; 4],
    /// A traffic light's colour.
    pub light: Option<LightColor>,
    /// A turn sign's arrow.
    pub arrow: Option<crate::classes::TurnArrow>,
}

/// The other camera's image of a stereo frame (the reference camera's is [`Frame::image`]).
#[derive(Debug, Clone)]
pub struct OtherView {
    /// The other camera's image, the size of the reference image.
    pub image: RgbImage,
    /// Its file name or label.
    pub name: String,
    /// Other camera's time minus the reference camera's, seconds.
    pub skew_s: f64,
    /// Frames dropped so far because they had no partner within `stereo.max_skew_ms`.
    pub pairs_dropped: u64,
}

impl Frame {
    /// A frame with no capture time, truth or given boxes.
    pub fn new(index: u64, time_s: f64, name: String, image: RgbImage) -> Self {
        Self {
            index,
            time_s,
            name,
            image,
            captured_s: None,
            truth: None,
            given: None,
            other: None,
        }
    }
}

/// A frame that could not be used.
#[derive(Debug, thiserror::Error)]
#[error("{name}: {reason}")]
pub struct FrameError {
    /// Position in the sequence.
    pub index: u64,
    /// File name or label.
    pub name: String,
    /// What was wrong.
    pub reason: String,
    /// `true`: no frame arrived in time (a camera that stalled or was unplugged); the loop
    /// sends neutral and waits. `false`: this one frame is unusable; the loop skips it.
    pub stalled: bool,
}

impl FrameError {
    /// One unusable frame.
    pub fn bad(index: u64, name: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            index,
            name: name.into(),
            reason: reason.into(),
            stalled: false,
        }
    }

    /// No frame within the stall time.
    pub fn stalled(index: u64, name: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            index,
            name: name.into(),
            reason: reason.into(),
            stalled: true,
        }
    }
}

/// A source that cannot start at all.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The folder cannot be listed.
    #[error("{path}: cannot read folder: {error}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// Underlying error (in the message, not repeated as a source).
        error: std::io::Error,
    },
    /// The folder has no PNG or JPEG files.
    #[error("{0}: no .png/.jpg/.jpeg frames in this folder")]
    Empty(PathBuf),
    /// The folder is a recording whose telemetry cannot be used (see
    /// [`crate::record::recorded_times`]).
    #[error(transparent)]
    Recording(#[from] crate::record::RecordError),
}

/// Something that produces frames.
pub trait FrameSource {
    /// The next frame, an error for one unusable frame, or `None` at the end.
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>>;
    /// How many frames to expect, if known (for progress bars).
    fn len_hint(&self) -> Option<usize> {
        None
    }
    /// Why the source ended when it cannot be used at all (a camera that delivers the wrong
    /// size, a device gone for good), as one line naming it; `None` for a normal end (the end
    /// of a folder) or while it runs.
    fn fatal(&self) -> Option<String> {
        None
    }
}

/// A source played at its frames' own times on a clock (a folder of frames as the car's
/// camera on the bench: `rccar drive --camera DIR`). The first frame sets the origin; each
/// later frame is held back until its time has come, and stamped with the capture time.
pub struct Paced<S> {
    inner: S,
    clock: std::sync::Arc<dyn crate::timing::Clock + Send + Sync>,
    t0: Option<f64>,
}

impl<S: FrameSource> Paced<S> {
    /// Plays `inner` on `clock`.
    pub fn new(inner: S, clock: std::sync::Arc<dyn crate::timing::Clock + Send + Sync>) -> Self {
        Self { inner, clock, t0: None }
    }
}

impl<S: FrameSource> FrameSource for Paced<S> {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let item = self.inner.next_frame()?;
        if let Ok(f) = &item {
            let t0 = *self.t0.get_or_insert_with(|| self.clock.now_s() - f.time_s);
            let wait = t0 + f.time_s - self.clock.now_s();
            if wait > 0.0 {
                self.clock.sleep_s(wait);
            }
        }
        Some(item.map(|mut f| {
            f.captured_s = Some(self.clock.now_s());
            f
        }))
    }
    fn len_hint(&self) -> Option<usize> {
        self.inner.len_hint()
    }
    fn fatal(&self) -> Option<String> {
        self.inner.fatal()
    }
}

/// Frames from a folder of PNG/JPEG files, sorted by name, resized to the camera size.
#[derive(Debug)]
pub struct ReplayDir {
    files: Vec<PathBuf>,
    ignored: Vec<String>,
    next: usize,
    fps: f64,
    width: u32,
    height: u32,
    min_size: (u32, u32),
    /// A recording's frame times (frame index → seconds), see [`ReplayDir::with_recorded_times`].
    times: Option<std::collections::BTreeMap<u64, f64>>,
    /// The frame number last handed out with a recorded time.
    last_recorded: Option<u64>,
}

fn is_frame_file(p: &Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Some("png" | "jpg" | "jpeg")
    )
}

impl ReplayDir {
    /// Lists `dir`: its PNG/JPEG files in name order, then the frames of its segment folders
    /// `seg_*` (a recording, see `record`), folder by folder. Frames are `1/fps` seconds apart and resized to `width × height`; a frame
    /// smaller than `min_size` (the ROI's extent) is refused rather than blown up.
    pub fn open(dir: &Path, fps: f64, width: u32, height: u32, min_size: (u32, u32)) -> Result<Self, SourceError> {
        let entries = std::fs::read_dir(dir).map_err(|error| SourceError::Io {
            path: dir.into(),
            error,
        })?;
        let mut files = Vec::new();
        let mut ignored = Vec::new();
        let mut segments = Vec::new();
        for e in entries {
            let e = e.map_err(|error| SourceError::Io {
                path: dir.into(),
                error,
            })?;
            let p = e.path();
            let name = escape_name(&e.file_name());
            if name.starts_with('.') {
                continue;
            }
            if p.is_dir() {
                // A recording (src/record.rs) keeps its frames in segment folders seg_NNNNNN.
                if name.starts_with(crate::record::SEGMENT_PREFIX) {
                    segments.push(p);
                }
                continue;
            }
            if is_frame_file(&p) {
                files.push(p);
            } else {
                ignored.push(name);
            }
        }
        files.sort();
        // Then each segment's frames, segments in name (= time) order.
        segments.sort();
        for seg in &segments {
            let entries = std::fs::read_dir(seg).map_err(|error| SourceError::Io {
                path: seg.clone(),
                error,
            })?;
            let mut in_seg: Vec<PathBuf> = entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| is_frame_file(p) && !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')))
                .collect();
            in_seg.sort();
            files.extend(in_seg);
        }
        if files.is_empty() {
            return Err(SourceError::Empty(dir.into()));
        }
        ignored.sort();
        Ok(Self {
            files,
            ignored,
            next: 0,
            fps,
            width,
            height,
            min_size,
            times: None,
            last_recorded: None,
        })
    }

    /// [`ReplayDir::open`], and when `dir` is a recording (it holds the recorder's
    /// telemetry.jsonl with times), the recording's own frame numbers and times
    /// ([`ReplayDir::with_recorded_times`]). The times read back are returned too (cut lines
    /// to report). A telemetry that contradicts itself is refused
    /// ([`SourceError::Recording`], naming its file and line).
    pub fn open_recording(
        dir: &Path,
        fps: f64,
        width: u32,
        height: u32,
        min_size: (u32, u32),
    ) -> Result<(Self, Option<crate::record::RecordedTimes>), SourceError> {
        let source = Self::open(dir, fps, width, height, min_size)?;
        if !dir.join(crate::record::TELEMETRY_FILE).is_file() {
            return Ok((source, None));
        }
        let t = crate::record::recorded_times(dir)?;
        if t.times.is_empty() {
            return Ok((source, None));
        }
        Ok((source.with_recorded_times(t.times.clone()), Some(t)))
    }

    /// Uses a recording's own frame numbers and times (`crate::record::recorded_times`) for the
    /// frames named `frame_NNNNNNNNN.jpg`, so a replay sees the time steps the car saw (the car
    /// drops late frames; they are not always 1/fps apart). A frame without a time (its line
    /// was cut, or it is not named as the recorder names frames) or whose number is not above
    /// the last one's (a copy from another run) is an unusable frame, named and skipped:
    /// never a frame number twice or a time step of zero.
    pub fn with_recorded_times(mut self, times: std::collections::BTreeMap<u64, f64>) -> Self {
        self.ignored.retain(|n| n != crate::record::TELEMETRY_FILE);
        self.times = Some(times);
        self
    }

    /// The frame files, in the order they are replayed.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Files in the folder that are not frames (named in the summary, never silently dropped).
    pub fn ignored(&self) -> &[String] {
        &self.ignored
    }

    fn load(&self, path: &Path) -> Result<RgbImage, String> {
        load_frame(path, self.width, self.height, self.min_size)
    }
}

impl FrameSource for ReplayDir {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let path = self.files.get(self.next)?.clone();
        let index = self.next as u64;
        self.next += 1;
        let name = path.file_name().map(escape_name).unwrap_or_default();
        let (index, time_s) = match &self.times {
            None => (index, index as f64 / self.fps),
            Some(t) => {
                let Some(i) = crate::record::frame_index(&name) else {
                    return Some(Err(FrameError::bad(
                        index,
                        name,
                        "not a frame of this recording (the recorder names them frame_NNNNNNNNN.jpg); skipped",
                    )));
                };
                if let Some(last) = self.last_recorded.filter(|&l| i <= l) {
                    return Some(Err(FrameError::bad(
                        i,
                        name,
                        format!("frame {i} comes after frame {last}: a frame of another run; skipped"),
                    )));
                }
                let Some(&ts) = t.get(&i) else {
                    return Some(Err(FrameError::bad(
                        i,
                        name,
                        "no time in the recording's telemetry (its line is cut or missing); skipped",
                    )));
                };
                self.last_recorded = Some(i);
                (i, ts)
            }
        };
        Some(match self.load(&path) {
            Ok(image) => Ok(Frame::new(index, time_s, name, image)),
            Err(reason) => Err(FrameError::bad(index, name, reason)),
        })
    }

    fn len_hint(&self) -> Option<usize> {
        Some(self.files.len())
    }
}

/// `name`, or `name~2`, `name~3`... if an earlier image of this run already used it (the same
/// file name in two folders).
pub fn unique_name(name: String, used: &mut std::collections::HashSet<String>) -> String {
    if used.insert(name.clone()) {
        return name;
    }
    (2..)
        .map(|k| format!("{name}~{k}"))
        .find(|n| used.insert(n.clone()))
        .unwrap_or(name)
}

/// A file name as text, lossless: valid UTF-8 is kept, a backslash becomes `\\`, and every
/// byte that is not UTF-8 becomes `\xNN` (so two different names never give the same text).
pub fn escape_name(name: &OsStr) -> String {
    #[cfg(unix)]
    let bytes: std::borrow::Cow<[u8]> = {
        use std::os::unix::ffi::OsStrExt;
        std::borrow::Cow::Borrowed(name.as_bytes())
    };
    #[cfg(not(unix))]
    let bytes: std::borrow::Cow<[u8]> = std::borrow::Cow::Owned(name.to_string_lossy().into_owned().into_bytes());
    let mut out = String::with_capacity(bytes.len());
    for chunk in bytes.utf8_chunks() {
        out.push_str(&chunk.valid().replace('\\', "\\\\"));
        for b in chunk.invalid() {
            out.push_str(&format!("\\x{b:02X}"));
        }
    }
    out
}

/// The output file name for a frame named `name` (an [`escape_name`] text): the whole name,
/// extension included, plus `.png` (`a.jpg` → `a.jpg.png`, `a.png` → `a.png.png`), so frames
/// `a.jpg` and `a.png` of one folder never overwrite each other's output.
pub fn output_name(name: &str) -> String {
    format!("{name}.png")
}

/// The smallest frame worth resizing for an ROI `src` on a `width × height` camera: the ROI's
/// extent (a smaller frame would be blown up, not measured).
pub fn min_frame_size(src: &[[f64; 2]; 4], width: u32, height: u32) -> (u32, u32) {
    let max_x = src.iter().map(|p| p[0]).fold(0.0f64, f64::max);
    let max_y = src.iter().map(|p| p[1]).fold(0.0f64, f64::max);
    ((max_x.ceil() as u32).min(width), (max_y.ceil() as u32).min(height))
}

/// Reads an image file for the pipeline: [`read_image`], refused when smaller than `min_size`,
/// resized to `width × height`.
pub fn load_frame(path: &Path, width: u32, height: u32, min_size: (u32, u32)) -> Result<RgbImage, String> {
    let img = read_image(path)?.to_rgb8();
    let (w, h) = img.dimensions();
    if w < min_size.0 || h < min_size.1 {
        return Err(format!(
            "{w}×{h} is smaller than the ROI (needs at least {}×{})",
            min_size.0, min_size.1
        ));
    }
    Ok(if (w, h) == (width, height) {
        img
    } else {
        image::imageops::resize(&img, width, height, image::imageops::FilterType::Triangle)
    })
}

/// Reads, checks and decodes one image file (PNG or JPEG). The error says what is wrong
/// (without the file name, which the caller adds).
pub fn read_image(path: &Path) -> Result<image::DynamicImage, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    if bytes.is_empty() {
        return Err("empty file (0 bytes)".into());
    }
    if let Some(why) = image_damage(&bytes) {
        return Err(why);
    }
    decode_image(&bytes)
}

/// Decodes image bytes after checking the size in the header against
/// [`crate::imageio::limits`]; the one place that calls the decoder.
pub fn decode_image(bytes: &[u8]) -> Result<image::DynamicImage, String> {
    use crate::imageio::limits::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format!("cannot read: {e}"))
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| format!("not a readable image: {e}"))?;
    if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE || w as u64 * h as u64 > MAX_IMAGE_PIXELS {
        return Err(format!(
            "{w}×{h} pixels is outside the image limit (1..={MAX_IMAGE_SIDE} per side, at most {} megapixels)",
            MAX_IMAGE_PIXELS / 1_000_000
        ));
    }
    // JPEG as cv2.imread decodes it (libjpeg-turbo's IDCT and upsampling) with the
    // `jpeg-turbo` feature; see src/imageio.rs.
    if crate::imageio::is_jpeg(bytes) {
        return crate::imageio::decode(bytes, "").map_err(|e| match e {
            crate::imageio::ImageIoError::Decode { msg, .. } => format!("not a readable image: {msg}"),
            e => e.to_string(),
        });
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_IMAGE_PIXELS * 8);
    let mut r = reader()?;
    r.limits(limits);
    r.decode().map_err(|e| format!("not a readable image: {e}"))
}

/// Damage a decoder would not report: a JPEG whose data ends before its end-of-image marker
/// (cut short while copying: the missing part would decode as flat grey), a PNG chunk that
/// is cut short or fails its CRC, a PNG without IEND. `None` when the structure is whole
/// (or the format is neither, left to the decoder).
pub fn image_damage(bytes: &[u8]) -> Option<String> {
    if bytes.starts_with(&[0xFF, 0xD8]) {
        jpeg_damage(bytes)
    } else if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        png_damage(bytes)
    } else {
        None
    }
}

/// Walks the JPEG marker segments and entropy-coded scans up to EOI.
fn jpeg_damage(b: &[u8]) -> Option<String> {
    let n = b.len();
    let truncated = |at: usize, what: &str| {
        Some(format!(
            "damaged JPEG: the file ends at byte {n} {what} (at byte {at}), before the end-of-image marker; it was cut short (the missing part would decode as grey)"
        ))
    };
    let mut pos = 2;
    let mut scans = 0;
    loop {
        // 1. A marker: 0xFF, optional fill bytes, the code.
        if pos >= n {
            return truncated(pos, "between segments");
        }
        if b[pos] != 0xFF {
            return Some(format!(
                "damaged JPEG: byte {pos} should start a marker (0xFF), found 0x{:02X}",
                b[pos]
            ));
        }
        while pos < n && b[pos] == 0xFF {
            pos += 1;
        }
        if pos >= n {
            return truncated(pos, "inside a marker");
        }
        let code = b[pos];
        pos += 1;
        match code {
            0xD9 => {
                return (scans == 0).then(|| "damaged JPEG: it ends (EOI) before any image data".to_string());
            }
            0xD0..=0xD7 | 0x01 => continue,
            _ => {}
        }
        // 2. A segment with a length.
        if pos + 2 > n {
            return truncated(pos, &format!("inside the length of segment 0xFF{code:02X}"));
        }
        let len = u16::from_be_bytes([b[pos], b[pos + 1]]) as usize;
        if len < 2 {
            return Some(format!(
                "damaged JPEG: segment 0xFF{code:02X} at byte {pos} has length {len}"
            ));
        }
        if pos + len > n {
            return truncated(pos, &format!("inside segment 0xFF{code:02X} of {len} bytes"));
        }
        pos += len;
        if code == 0xDA {
            // 3. Entropy-coded data: runs until a marker other than a stuffed 0xFF00 or RSTn.
            scans += 1;
            let start = pos;
            loop {
                match b[pos..].iter().position(|&x| x == 0xFF) {
                    None => return truncated(start, "inside the image data of a scan"),
                    Some(k) => {
                        pos += k;
                        let mut q = pos + 1;
                        while q < n && b[q] == 0xFF {
                            q += 1;
                        }
                        if q >= n {
                            return truncated(start, "inside the image data of a scan");
                        }
                        match b[q] {
                            0x00 | 0xD0..=0xD7 => pos = q + 1,
                            _ => break,
                        }
                    }
                }
            }
        }
    }
}

/// Walks the PNG chunks: complete, CRC-checked, up to IEND.
fn png_damage(b: &[u8]) -> Option<String> {
    let n = b.len();
    let mut pos = 8;
    let mut first = true;
    loop {
        if pos + 8 > n {
            return Some(format!(
                "damaged PNG: the file ends at byte {n}, before the IEND chunk; it was cut short"
            ));
        }
        let len = u32::from_be_bytes([b[pos], b[pos + 1], b[pos + 2], b[pos + 3]]) as usize;
        let kind = &b[pos + 4..pos + 8];
        let name = String::from_utf8_lossy(kind).into_owned();
        if first && kind != b"IHDR" {
            return Some("damaged PNG: the first chunk is not IHDR".into());
        }
        first = false;
        if len > n || pos + 12 + len > n {
            return Some(format!(
                "damaged PNG: chunk {name} at byte {pos} needs {len} bytes but the file ends at byte {n}; it was cut short"
            ));
        }
        let crc = u32::from_be_bytes([b[pos + 8 + len], b[pos + 9 + len], b[pos + 10 + len], b[pos + 11 + len]]);
        if crc32(&b[pos + 4..pos + 8 + len]) != crc {
            return Some(format!(
                "damaged PNG: chunk {name} at byte {pos} fails its CRC (the bytes were changed)"
            ));
        }
        if kind == b"IEND" {
            return None;
        }
        pos += 12 + len;
    }
}

/// CRC-32 (IEEE, as PNG uses it).
fn crc32(data: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
            *e = c;
        }
        t
    });
    !data
        .iter()
        .fold(!0u32, |c, &x| t[((c ^ x as u32) & 0xFF) as usize] ^ (c >> 8))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_bytes() -> Vec<u8> {
        let img = RgbImage::from_fn(40, 30, |x, y| image::Rgb([(x * 6) as u8, (y * 8) as u8, 90]));
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    }

    fn jpeg_bytes() -> Vec<u8> {
        let img = RgbImage::from_fn(64, 48, |x, y| {
            image::Rgb([(x * 4) as u8, (y * 5) as u8, ((x ^ y) * 3) as u8])
        });
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Jpeg).unwrap();
        out.into_inner()
    }

    #[test]
    fn whole_files_pass_and_cut_files_are_named() {
        for (kind, b) in [("PNG", png_bytes()), ("JPEG", jpeg_bytes())] {
            assert_eq!(image_damage(&b), None, "{kind}");
            assert!(decode_image(&b).is_ok(), "{kind}");
            for cut in [b.len() / 2, b.len() - 1, 20] {
                let why = image_damage(&b[..cut]).unwrap_or_else(|| panic!("{kind} cut at {cut} passed"));
                assert!(why.contains(kind) && why.contains("cut short"), "{why}");
            }
        }
    }

    #[test]
    fn the_image_crate_does_not_see_a_jpeg_cut_in_half() {
        // Why the structure check exists: the decoder fills the missing half and says nothing.
        let b = jpeg_bytes();
        let half = &b[..b.len() / 2];
        if let Ok(img) = decode_image(half) {
            assert_eq!(img.width(), 64);
        }
        assert!(image_damage(half).is_some());
    }

    #[test]
    fn png_byte_flip_fails_the_crc() {
        let mut b = png_bytes();
        let k = b.len() - 20;
        b[k] ^= 0x10;
        let why = image_damage(&b).unwrap();
        assert!(why.contains("CRC"), "{why}");
    }

    #[test]
    fn names_are_escaped_losslessly_and_outputs_are_unique() {
        use std::os::unix::ffi::OsStrExt;
        assert_eq!(escape_name(OsStr::new("a.png")), "a.png");
        assert_eq!(escape_name(OsStr::from_bytes(b"fr\xFFame.png")), "fr\\xFFame.png");
        // A name that already reads like an escape stays distinct.
        assert_eq!(escape_name(OsStr::new("fr\\xFFame.png")), "fr\\\\xFFame.png");
        assert_ne!(output_name("a.jpg"), output_name("a.png"));
        assert_eq!(output_name("a.jpg"), "a.jpg.png");
    }

    #[test]
    fn min_frame_size_is_the_roi_extent() {
        let src = crate::config::WarpConfig::default().src;
        assert_eq!(min_frame_size(&src, 320, 240), (309, 151));
    }
}
