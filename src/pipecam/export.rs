//! The other end of a pipe: `rccar sim --frames-to - --frames-format rgb24` writes every
//! camera frame the simulated car sees to stdout, in a format the pipe source reads, so that
//! `rccar replay 'pipe:rgb24:rccar sim … --frames-to -'` (or a player: `ffplay -f rawvideo
//! -pixel_format rgb24 -video_size 320x240 -`) takes the simulator's frames through a real
//! pipe.

use super::format::{rgb_to_i420, RawFormat};
use crate::drive::{Flow, FrameContext, LoopError, Observer};
use std::io::Write;

/// An observer that writes each processed frame to `out` in `format` (rgb24, yuv420 or
/// mjpeg at quality 90). A reader that goes away (a broken pipe) ends the run.
pub struct FrameWriter {
    out: Box<dyn Write + Send>,
    format: RawFormat,
    buf: Vec<u8>,
    /// Frames written.
    pub frames: u64,
    /// Why writing stopped, if it did.
    pub error: Option<String>,
}

impl FrameWriter {
    /// Writes frames of `format` (`yuvj420` is not written: `yuv420` is) to `out`.
    pub fn new(out: Box<dyn Write + Send>, format: RawFormat) -> Self {
        Self {
            out,
            format,
            buf: Vec::new(),
            frames: 0,
            error: None,
        }
    }

    /// `--frames-to PATH --frames-format NAME`: `None` without a path; `-` is stdout (see
    /// [`FrameWriter::take_stdout`]); an unknown name is rgb24.
    pub fn open(path: Option<&std::path::Path>, format: &str, width: u32) -> std::io::Result<Option<FrameWriter>> {
        let Some(p) = path else {
            return Ok(None);
        };
        let out = if p.as_os_str() == "-" {
            Self::take_stdout()?
        } else {
            Box::new(std::io::BufWriter::new(std::fs::File::create(p).map_err(|e| {
                std::io::Error::new(e.kind(), format!("{}: cannot create: {e}", p.display()))
            })?))
        };
        Ok(Some(FrameWriter::new(
            out,
            RawFormat::parse(format, width).unwrap_or(RawFormat::Rgb24),
        )))
    }

    /// Frames to the process's standard output: the descriptor is kept for the frames and
    /// descriptor 1 becomes a copy of stderr, so everything the program prints from now on
    /// goes to stderr and never into the frame stream.
    #[cfg(unix)]
    pub fn take_stdout() -> std::io::Result<Box<dyn Write + Send>> {
        use std::os::fd::FromRawFd;
        std::io::stdout().flush()?;
        // SAFETY: dup/dup2 on the process's own standard descriptors; the new descriptor is
        // owned by the File from here on.
        unsafe {
            let fd = libc::dup(1);
            if fd < 0 || libc::dup2(2, 1) < 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(Box::new(std::io::BufWriter::with_capacity(
                1 << 16,
                std::fs::File::from_raw_fd(fd),
            )))
        }
    }

    fn encode(&mut self, img: &image::RgbImage) -> Result<(), String> {
        self.buf.clear();
        match self.format {
            RawFormat::Rgb24 => self.buf.extend_from_slice(img.as_raw()),
            RawFormat::Yuv420 { .. } => self.buf = rgb_to_i420(img),
            RawFormat::Mjpeg => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut self.buf, 90)
                .encode_image(img)
                .map_err(|e| e.to_string())?,
        }
        Ok(())
    }
}

impl Observer for FrameWriter {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        if self.error.is_some() {
            return Ok(Flow::Stop);
        }
        let r = self.encode(&ctx.frame.image).and_then(|()| {
            self.out
                .write_all(&self.buf)
                .and_then(|()| self.out.flush())
                .map_err(|e| e.to_string())
        });
        match r {
            Ok(()) => {
                self.frames += 1;
                Ok(Flow::Continue)
            }
            // The reader went away: nobody to drive for.
            Err(e) => {
                self.error = Some(format!("frames: {e} after {} frames", self.frames));
                Ok(Flow::Stop)
            }
        }
    }
}
