//! Image files decoded as OpenCV's `cv2.imread` decodes them (issue 13), so that `rccar detect`,
//! `stages` and replay see the pixels OpenCV sees and a cascade near its thresholds gives
//! OpenCV's boxes.
//!
//! OpenCV decodes JPEG with libjpeg-turbo's defaults: the accurate integer IDCT
//! (`JDCT_ISLOW`), "fancy" (triangular) chroma upsampling and its fixed-point YCbCr → RGB
//! tables. The `image` crate's pure-Rust decoder (zune-jpeg) uses another IDCT and upsampling,
//! so a few pixels per block differ by ±1–2 levels.
//!
//! * With the cargo feature `jpeg-turbo`, JPEG files are decoded by libjpeg-turbo's code (the
//!   `mozjpeg` crate builds the mozjpeg fork of libjpeg-turbo from source with the C compiler;
//!   nasm is optional, its SIMD paths are bit-exact with the C ones): the same pixels as
//!   `cv2.imread` (`tests/parity/jpeg_parity.py`).
//! * Without it (the default build needs nothing but Rust), JPEG goes through the `image`
//!   crate like every other format: close to OpenCV's pixels, not identical.
//!
//! PNG and other formats are lossless: every decoder gives the same pixels. EXIF orientation is
//! not applied (`cv2.imread` applies it; camera frames and the project's files carry none).
//! Units: 8-bit pixels.

use image::DynamicImage;
use std::path::Path;

/// Bounds on the images a file or a flag can make rccar decode, checked from the header before
/// anything is allocated (frame folders, `detect`, `stages`, calibration photos, `stereo`, the
/// trainer's samples).
pub mod limits {
    /// Largest image a frame source, `stages` or `detect` decodes, pixels (width × height).
    pub const MAX_IMAGE_PIXELS: u64 = 40_000_000;
    /// Largest image side, pixels.
    pub const MAX_IMAGE_SIDE: u32 = 16_384;
}

/// Why an image file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ImageIoError {
    /// The file could not be read.
    #[error("{path}: {err}")]
    Read {
        /// The file.
        path: String,
        /// The I/O error.
        err: std::io::Error,
    },
    /// The bytes are not a decodable image.
    #[error("{path}: not a readable image: {msg}")]
    Decode {
        /// The file.
        path: String,
        /// What the decoder said.
        msg: String,
    },
}

/// Whether JPEG files are decoded like OpenCV (the `jpeg-turbo` feature).
pub const JPEG_LIKE_OPENCV: bool = cfg!(feature = "jpeg-turbo");

/// Whether `bytes` start like a JPEG file (SOI marker followed by another marker).
pub fn is_jpeg(bytes: &[u8]) -> bool {
    bytes.len() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF
}

/// Reads and decodes an image file (see [`decode`]).
pub fn open(path: &Path) -> Result<DynamicImage, ImageIoError> {
    let bytes = std::fs::read(path).map_err(|err| ImageIoError::Read {
        path: path.display().to_string(),
        err,
    })?;
    decode(&bytes, &path.display().to_string())
}

/// Decodes an image held in memory; `name` names it in errors. JPEG with the `jpeg-turbo`
/// feature as libjpeg-turbo (grey JPEGs stay grey, colour ones become RGB), everything else by
/// the `image` crate (format guessed from the bytes).
pub fn decode(bytes: &[u8], name: &str) -> Result<DynamicImage, ImageIoError> {
    #[cfg(feature = "jpeg-turbo")]
    if is_jpeg(bytes) {
        return turbo::decode(bytes).map_err(|msg| ImageIoError::Decode {
            path: name.to_string(),
            msg,
        });
    }
    image::load_from_memory(bytes).map_err(|e| ImageIoError::Decode {
        path: name.to_string(),
        msg: e.to_string(),
    })
}

#[cfg(feature = "jpeg-turbo")]
mod turbo {
    use image::{DynamicImage, GrayImage, RgbImage};

    /// libjpeg-turbo with OpenCV's settings: ISLOW IDCT, fancy upsampling (both libjpeg's
    /// defaults, set explicitly), RGB or grey output. libjpeg reports fatal errors by unwinding
    /// (mozjpeg's `unwinding` feature), caught here.
    pub fn decode(bytes: &[u8]) -> Result<DynamicImage, String> {
        std::panic::catch_unwind(|| -> Result<DynamicImage, String> {
            let mut d = mozjpeg::Decompress::new_mem(bytes).map_err(|e| e.to_string())?;
            d.dct_method(mozjpeg::DctMethod::IntegerSlow);
            d.do_fancy_upsampling(true);
            let grey = d.color_space() == mozjpeg::ColorSpace::JCS_GRAYSCALE;
            let (w, h) = (d.width() as u32, d.height() as u32);
            let img = if grey {
                let mut s = d.grayscale().map_err(|e| e.to_string())?;
                let px = s.read_scanlines::<u8>().map_err(|e| e.to_string())?;
                s.finish().map_err(|e| e.to_string())?;
                DynamicImage::ImageLuma8(GrayImage::from_raw(w, h, px).ok_or("short image data")?)
            } else {
                let mut s = d.rgb().map_err(|e| e.to_string())?;
                let px = s.read_scanlines::<u8>().map_err(|e| e.to_string())?;
                s.finish().map_err(|e| e.to_string())?;
                DynamicImage::ImageRgb8(RgbImage::from_raw(w, h, px).ok_or("short image data")?)
            };
            Ok(img)
        })
        .unwrap_or_else(|p| {
            Err(p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "libjpeg error".into()))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_jpeg_reads_back_and_garbage_is_an_error() {
        let img = image::RgbImage::from_fn(40, 24, |x, y| image::Rgb([(x * 6) as u8, (y * 10) as u8, 128]));
        let mut buf = std::io::Cursor::new(Vec::new());
        image::DynamicImage::ImageRgb8(img.clone())
            .write_to(&mut buf, image::ImageFormat::Jpeg)
            .unwrap();
        let bytes = buf.into_inner();
        assert!(is_jpeg(&bytes));
        let back = decode(&bytes, "mem.jpg").unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (40, 24));
        let diff = back
            .pixels()
            .zip(img.pixels())
            .map(|(a, b)| (a[0] as i32 - b[0] as i32).abs())
            .max()
            .unwrap();
        assert!(diff < 20, "lossy but close: {diff}");
        // A truncated JPEG may decode (libjpeg fills the rest grey, as cv2.imread does) or fail,
        // but does not panic; garbage is an error naming the file.
        let _ = decode(&bytes[..bytes.len() / 3], "cut.jpg");
        for bad in [&b"\xFF\xD8\xFFnot a jpeg"[..], &b"hello"[..]] {
            let e = decode(bad, "bad.jpg").map(|_| ()).unwrap_err().to_string();
            assert!(e.starts_with("bad.jpg"), "{e}");
        }
    }
}
