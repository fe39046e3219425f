//! Where frames come from: the camera, a folder of recorded images, or the simulator.
//!
//! A [`FrameSource`] yields frames one by one. A frame that cannot be used (unreadable file,
//! too small) is reported as an `Err` for that frame only, so the caller can name it, count
//! it and go on: one bad frame never ends a run.

use image::RgbImage;
use std::path::{Path, PathBuf};

/// One frame and where it came from.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Position in the sequence (counting frames that failed).
    pub index: u64,
    /// Time since the start of the sequence, seconds.
    pub time_s: f64,
    /// File name or label.
    pub name: String,
    /// The image, resized to the configured camera size.
    pub image: RgbImage,
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
}

/// A source that cannot start at all.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The folder cannot be listed.
    #[error("{path}: cannot read folder: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The folder has no PNG or JPEG files.
    #[error("{0}: no .png/.jpg/.jpeg frames in this folder")]
    Empty(PathBuf),
}

/// Something that produces frames.
pub trait FrameSource {
    /// The next frame, an error for one unusable frame, or `None` at the end.
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>>;
    /// How many frames to expect, if known (for progress bars).
    fn len_hint(&self) -> Option<usize> {
        None
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
    /// Lists `dir`. Frames are `1/fps` seconds apart and resized to `width × height`; a frame
    /// smaller than `min_size` (the ROI's extent) is refused rather than blown up.
    pub fn open(dir: &Path, fps: f64, width: u32, height: u32, min_size: (u32, u32)) -> Result<Self, SourceError> {
        let entries = std::fs::read_dir(dir).map_err(|source| SourceError::Io {
            path: dir.into(),
            source,
        })?;
        let mut files = Vec::new();
        let mut ignored = Vec::new();
        for e in entries {
            let e = e.map_err(|source| SourceError::Io {
                path: dir.into(),
                source,
            })?;
            let p = e.path();
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with('.') || p.is_dir() {
                continue;
            }
            if is_frame_file(&p) {
                files.push(p);
            } else {
                ignored.push(name);
            }
        }
        if files.is_empty() {
            return Err(SourceError::Empty(dir.into()));
        }
        files.sort();
        ignored.sort();
        Ok(Self {
            files,
            ignored,
            next: 0,
            fps,
            width,
            height,
            min_size,
        })
    }

    /// Files in the folder that are not frames (named in the summary, never silently dropped).
    pub fn ignored(&self) -> &[String] {
        &self.ignored
    }

    fn load(&self, path: &Path) -> Result<RgbImage, String> {
        let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
        if meta.len() == 0 {
            return Err("empty file (0 bytes)".into());
        }
        let img = crate::imageio::open(path)
            .map_err(|e| match e {
                crate::imageio::ImageIoError::Read { source, .. } => source.to_string(),
                crate::imageio::ImageIoError::Decode { msg, .. } => format!("not a readable image: {msg}"),
            })?
            .to_rgb8();
        let (w, h) = img.dimensions();
        if w < self.min_size.0 || h < self.min_size.1 {
            return Err(format!(
                "{w}×{h} is smaller than the ROI (needs at least {}×{})",
                self.min_size.0, self.min_size.1
            ));
        }
        Ok(if (w, h) == (self.width, self.height) {
            img
        } else {
            image::imageops::resize(&img, self.width, self.height, image::imageops::FilterType::Triangle)
        })
    }
}

impl FrameSource for ReplayDir {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let path = self.files.get(self.next)?.clone();
        let index = self.next as u64;
        self.next += 1;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        Some(match self.load(&path) {
            Ok(image) => Ok(Frame {
                index,
                time_s: index as f64 / self.fps,
                name,
                image,
            }),
            Err(reason) => Err(FrameError { index, name, reason }),
        })
    }

    fn len_hint(&self) -> Option<usize> {
        Some(self.files.len())
    }
}
