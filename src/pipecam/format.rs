//! The frame formats a camera program writes to its stdout, and how one frame is cut from the
//! byte stream and turned into RGB.
//!
//! | name      | layout                                                        | from                              |
//! |-----------|---------------------------------------------------------------|-----------------------------------|
//! | `rgb24`   | W×H×3 bytes, R G B per pixel, rows top to bottom              | ffmpeg `-pix_fmt rgb24`, GStreamer `RGB` |
//! | `yuv420`  | I420 planar: Y (W×H), U, V (⌈W/2⌉×⌈H/2⌉ each), BT.601 16..235 | ffmpeg `-pix_fmt yuv420p`, GStreamer `I420` |
//! | `yuvj420` | the same planes, BT.601 full range 0..255 (JPEG's)            | `rpicam-vid --codec yuv420`, ffmpeg `yuvj420p` |
//! | `mjpeg`   | one whole JPEG after another (SOI … EOI)                      | `rpicam-vid --codec mjpeg`, ffmpeg `-f mjpeg` |
//!
//! Bounds: a raw frame is exactly [`RawFormat::frame_bytes`] long (at most 4096×4096×3 = 48
//! MiB, the largest `[camera]` size); a JPEG is cut out of a buffer that never grows beyond
//! [`RawFormat::max_jpeg_bytes`] (2 × W×H×3 + 1 MiB): a longer "frame" is garbage, counted as
//! an unusable frame and skipped to the next JPEG start. Nothing a producer writes makes the
//! reader panic or allocate without bound.

use image::RgbImage;
use std::io::Read;

/// How the frames on a pipe are laid out (see the module notes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawFormat {
    /// 3 bytes per pixel, R, G, B.
    Rgb24,
    /// Planar YUV 4:2:0 (I420), BT.601.
    Yuv420 {
        /// 0..255 (JPEG's range, what rpicam-vid writes) rather than 16..235.
        full_range: bool,
        /// Bytes per luma row (≥ width): the camera's ISP may pad rows; each chroma row is
        /// ⌈stride/2⌉ bytes. [`RawFormat::yuv420`] has stride = width.
        stride: u32,
    },
    /// Motion JPEG: whole JPEG images one after another.
    Mjpeg,
}

impl RawFormat {
    /// The format names `--camera pipe:FORMAT:...` takes.
    pub const NAMES: &'static str = "rgb24, yuv420, yuvj420 or mjpeg";

    /// Reads a format name (see [`RawFormat::NAMES`]) for frames `width` pixels wide.
    pub fn parse(name: &str, width: u32) -> Option<RawFormat> {
        Some(match name {
            "rgb24" => RawFormat::Rgb24,
            "yuv420" => RawFormat::yuv420(false, width),
            "yuvj420" => RawFormat::yuv420(true, width),
            "mjpeg" => RawFormat::Mjpeg,
            _ => return None,
        })
    }

    /// I420 with unpadded rows.
    pub fn yuv420(full_range: bool, width: u32) -> RawFormat {
        RawFormat::Yuv420 {
            full_range,
            stride: width,
        }
    }

    /// Its name (as [`RawFormat::parse`] reads it).
    pub fn name(&self) -> &'static str {
        match self {
            RawFormat::Rgb24 => "rgb24",
            RawFormat::Yuv420 { full_range: false, .. } => "yuv420",
            RawFormat::Yuv420 { full_range: true, .. } => "yuvj420",
            RawFormat::Mjpeg => "mjpeg",
        }
    }

    /// Bytes of one `width × height` frame of a raw format; `None` for MJPEG (every frame
    /// has its own length) or a stride narrower than the width.
    pub fn frame_bytes(&self, width: u32, height: u32) -> Option<usize> {
        let (w, h) = (width as usize, height as usize);
        match *self {
            RawFormat::Rgb24 => Some(w * h * 3),
            RawFormat::Yuv420 { stride, .. } if stride >= width => {
                let s = stride as usize;
                Some(s * h + 2 * s.div_ceil(2) * h.div_ceil(2))
            }
            _ => None,
        }
    }

    /// The longest JPEG taken for one `width × height` frame, bytes.
    pub fn max_jpeg_bytes(width: u32, height: u32) -> usize {
        2 * width as usize * height as usize * 3 + (1 << 20)
    }

    /// One raw frame's bytes as RGB (`bytes` is [`RawFormat::frame_bytes`] long).
    pub fn to_rgb(&self, bytes: &[u8], width: u32, height: u32) -> Option<RgbImage> {
        if Some(bytes.len()) != self.frame_bytes(width, height) {
            return None;
        }
        match *self {
            RawFormat::Rgb24 => RgbImage::from_raw(width, height, bytes.to_vec()),
            RawFormat::Yuv420 { full_range, stride } => Some(i420_to_rgb(bytes, width, height, stride, full_range)),
            RawFormat::Mjpeg => None,
        }
    }
}

/// BT.601 Y'CbCr → R'G'B', 16.16 fixed point, rounded and clamped; chroma shared by each 2×2
/// block (nearest, as the JPEG and I420 layouts place it).
fn i420_to_rgb(b: &[u8], width: u32, height: u32, stride: u32, full_range: bool) -> RgbImage {
    let (w, h, s) = (width as usize, height as usize, stride as usize);
    let cs = s.div_ceil(2);
    let (u0, v0) = (s * h, s * h + cs * h.div_ceil(2));
    // (luma scale, luma offset, R from V, G from U, G from V, B from U) × 65536
    let (ky, oy, rv, gu, gv, bu): (i32, i32, i32, i32, i32, i32) = if full_range {
        (65536, 0, 91881, 22554, 46802, 116130)
    } else {
        (76309, 16, 104597, 25675, 53279, 132201)
    };
    let mut out = vec![0u8; w * h * 3];
    for y in 0..h {
        let (yrow, crow) = (y * s, (y / 2) * cs);
        for x in 0..w {
            let l = ky * (b[yrow + x] as i32 - oy) + 32768;
            let cu = b[u0 + crow + x / 2] as i32 - 128;
            let cv = b[v0 + crow + x / 2] as i32 - 128;
            let px = &mut out[(y * w + x) * 3..][..3];
            px[0] = ((l + rv * cv) >> 16).clamp(0, 255) as u8;
            px[1] = ((l - gu * cu - gv * cv) >> 16).clamp(0, 255) as u8;
            px[2] = ((l + bu * cu) >> 16).clamp(0, 255) as u8;
        }
    }
    RgbImage::from_raw(width, height, out).unwrap_or_default()
}

/// An RGB image as I420 (BT.601, 16..235; each chroma sample the mean of its 2×2 block): what
/// `rccar sim --frames-to - --frames-format yuv420` writes.
pub fn rgb_to_i420(img: &RgbImage) -> Vec<u8> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![0u8; w * h + 2 * cw * ch];
    let p = img.as_raw();
    let rgb = |x: usize, y: usize| {
        let i = (y * w + x) * 3;
        (p[i] as i32, p[i + 1] as i32, p[i + 2] as i32)
    };
    for y in 0..h {
        for x in 0..w {
            let (r, g, b) = rgb(x, y);
            out[y * w + x] = ((16829 * r + 33039 * g + 6416 * b + 32768 + (16 << 16)) >> 16) as u8;
        }
    }
    let (us, vs) = out.split_at_mut(w * h).1.split_at_mut(cw * ch);
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut r, mut g, mut b, mut n) = (0, 0, 0, 0);
            for (x, y) in [
                (2 * cx, 2 * cy),
                (2 * cx + 1, 2 * cy),
                (2 * cx, 2 * cy + 1),
                (2 * cx + 1, 2 * cy + 1),
            ] {
                if x < w && y < h {
                    let (pr, pg, pb) = rgb(x, y);
                    (r, g, b, n) = (r + pr, g + pg, b + pb, n + 1);
                }
            }
            let (r, g, b) = (r / n, g / n, b / n);
            us[cy * cw + cx] = ((-9714 * r - 19070 * g + 28784 * b + 32768 + (128 << 16)) >> 16).clamp(0, 255) as u8;
            vs[cy * cw + cx] = ((28784 * r - 24103 * g - 4681 * b + 32768 + (128 << 16)) >> 16).clamp(0, 255) as u8;
        }
    }
    out
}

/// Where the first complete JPEG in a buffer ends.
#[derive(Debug, PartialEq, Eq)]
pub enum JpegExtent {
    /// The buffer starts with a whole JPEG of this many bytes (up to and with its EOI).
    Whole(usize),
    /// More bytes are needed.
    Incomplete,
    /// Not a JPEG from the start: why, and where the next JPEG start (SOI) is, if any.
    Broken(String, Option<usize>),
}

/// The next SOI marker (FF D8 FF) at or after `from`.
pub fn next_soi(b: &[u8], from: usize) -> Option<usize> {
    b.get(from..)?
        .windows(3)
        .position(|w| w == [0xFF, 0xD8, 0xFF])
        .map(|p| p + from)
}

/// Walks the JPEG that starts `b` — marker segments by their lengths, entropy-coded data up
/// to the next marker that is not a stuffed byte or a restart — to its EOI (after at least one
/// scan). A new SOI inside it means it was cut short.
pub fn jpeg_extent(b: &[u8]) -> JpegExtent {
    let broken = |why: String, at: usize| JpegExtent::Broken(why, next_soi(b, at));
    if b.len() < 3 {
        return if b.iter().zip([0xFF, 0xD8, 0xFF]).all(|(a, e)| *a == e) {
            JpegExtent::Incomplete
        } else {
            broken("no JPEG start (FF D8)".into(), 1)
        };
    }
    if b[..3] != [0xFF, 0xD8, 0xFF] {
        return broken("no JPEG start (FF D8)".into(), 1);
    }
    let n = b.len();
    let (mut pos, mut scans) = (2, 0);
    loop {
        if pos >= n {
            return JpegExtent::Incomplete;
        }
        if b[pos] != 0xFF {
            return broken(format!("byte {pos} should start a marker, found 0x{:02X}", b[pos]), pos);
        }
        while pos < n && b[pos] == 0xFF {
            pos += 1;
        }
        if pos >= n {
            return JpegExtent::Incomplete;
        }
        let code = b[pos];
        pos += 1;
        match code {
            0xD9 if scans > 0 => return JpegExtent::Whole(pos),
            0xD9 => return broken("it ends (EOI) before any image data".into(), pos),
            0xD8 => return broken("a new JPEG starts inside this one (it was cut short)".into(), pos - 2),
            0xD0..=0xD7 | 0x01 => continue,
            _ => {}
        }
        if pos + 2 > n {
            return JpegExtent::Incomplete;
        }
        let len = u16::from_be_bytes([b[pos], b[pos + 1]]) as usize;
        if len < 2 {
            return broken(format!("segment 0xFF{code:02X} at byte {pos} has length {len}"), pos);
        }
        if pos + len > n {
            return JpegExtent::Incomplete;
        }
        pos += len;
        if code == 0xDA {
            scans += 1;
            loop {
                match b[pos..].iter().position(|&x| x == 0xFF) {
                    None => return JpegExtent::Incomplete,
                    Some(k) => {
                        pos += k;
                        let mut q = pos + 1;
                        while q < n && b[q] == 0xFF {
                            q += 1;
                        }
                        if q >= n {
                            return JpegExtent::Incomplete;
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

/// One item read from a frame stream.
#[derive(Debug)]
pub enum Item {
    /// A frame (its size as the producer made it: MJPEG frames may differ from the
    /// configured size; the caller decides).
    Frame(RgbImage),
    /// An unusable frame, and why (a short frame at the end, garbage, a JPEG that does not
    /// decode or is too long).
    Bad(String),
    /// The stream ended (the producer closed its stdout).
    End,
}

/// Cuts frames of one format out of a byte stream (a camera program's stdout).
pub struct FrameReader<R> {
    r: R,
    format: RawFormat,
    width: u32,
    height: u32,
    buf: Vec<u8>,
    /// MJPEG: the bytes of `buf` already read; raw: unused.
    have: usize,
    ended: bool,
}

impl<R: Read> FrameReader<R> {
    /// Frames of `format` at `width × height` from `r`.
    pub fn new(r: R, format: RawFormat, width: u32, height: u32) -> Self {
        Self {
            r,
            format,
            width,
            height,
            buf: Vec::new(),
            have: 0,
            ended: false,
        }
    }

    /// Reads into `self.buf[from..to]` until full or the end of the stream; how far it got.
    fn fill(&mut self, from: usize, to: usize) -> std::io::Result<usize> {
        let mut at = from;
        while at < to {
            match self.r.read(&mut self.buf[at..to]) {
                Ok(0) => break,
                Ok(k) => at += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(at)
    }

    /// The next frame, unusable frame or the end. An I/O error of the pipe itself is
    /// returned as such.
    pub fn next_item(&mut self) -> std::io::Result<Item> {
        if self.ended {
            return Ok(Item::End);
        }
        match self.format.frame_bytes(self.width, self.height) {
            Some(n) => self.next_raw(n),
            None => self.next_jpeg(),
        }
    }

    fn next_raw(&mut self, n: usize) -> std::io::Result<Item> {
        self.buf.resize(n, 0);
        let got = self.fill(0, n)?;
        if got == n {
            return Ok(match self.format.to_rgb(&self.buf, self.width, self.height) {
                Some(img) => Item::Frame(img),
                None => Item::Bad("cannot convert the frame".into()),
            });
        }
        self.ended = true;
        Ok(if got == 0 {
            Item::End
        } else {
            Item::Bad(format!(
                "short frame: {got} of {n} bytes before the stream ended ({} {}×{})",
                self.format.name(),
                self.width,
                self.height
            ))
        })
    }

    fn next_jpeg(&mut self) -> std::io::Result<Item> {
        let max = RawFormat::max_jpeg_bytes(self.width, self.height);
        // Bytes dropped since the last item, and why (reported as one unusable frame).
        let (mut skipped, mut why) = (0usize, String::new());
        let garbage = |n: usize, why: &str| Item::Bad(format!("{n} bytes that are not a JPEG frame ({why}); skipped"));
        loop {
            match jpeg_extent(&self.buf[..self.have]) {
                JpegExtent::Whole(_) if skipped > 0 => return Ok(garbage(skipped, &why)),
                JpegExtent::Whole(len) => {
                    let item = match crate::source::decode_image(&self.buf[..len]) {
                        Ok(img) => Item::Frame(img.to_rgb8()),
                        Err(why) => Item::Bad(format!("JPEG of {len} bytes: {why}")),
                    };
                    self.consume(len);
                    return Ok(item);
                }
                JpegExtent::Broken(w, Some(next)) => {
                    self.consume(next);
                    return Ok(garbage(skipped + next, &w));
                }
                JpegExtent::Broken(w, None) => {
                    // No JPEG start in sight: drop all but the last two bytes (a start may be
                    // split across reads) and read on.
                    let k = self.have.saturating_sub(2).max(1).min(self.have);
                    self.consume(k);
                    (skipped, why) = (skipped + k, w);
                    if skipped >= max {
                        return Ok(garbage(skipped, &why));
                    }
                }
                JpegExtent::Incomplete if self.have >= max => {
                    let skip = next_soi(&self.buf[..self.have], 1).unwrap_or(self.have);
                    self.consume(skip);
                    return Ok(Item::Bad(format!(
                        "a JPEG longer than {max} bytes (2 × W×H×3 + 1 MiB for {}×{}): not a frame; skipped",
                        self.width, self.height
                    )));
                }
                JpegExtent::Incomplete => {}
            }
            // More bytes: one read, whatever the pipe holds now (at least one byte).
            let want = (self.have + 64 * 1024).min(max);
            if self.buf.len() < want {
                self.buf.resize(want, 0);
            }
            let k = loop {
                match self.r.read(&mut self.buf[self.have..want]) {
                    Ok(k) => break k,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(e),
                }
            };
            if k == 0 {
                self.ended = true;
                let left = self.have + skipped;
                self.have = 0;
                return Ok(match (left, skipped) {
                    (0, _) => Item::End,
                    (_, 0) => Item::Bad(format!("{left} bytes of a JPEG cut short by the end of the stream")),
                    _ => garbage(left, &why),
                });
            }
            self.have += k;
        }
    }

    fn consume(&mut self, n: usize) {
        let n = n.min(self.have);
        self.buf.copy_within(n..self.have, 0);
        self.have -= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(w: u32, h: u32, q: u8) -> Vec<u8> {
        let img = RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([(x * 7) as u8, (y * 5) as u8, ((x + y) * 3) as u8])
        });
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, q)
            .encode_image(&img)
            .unwrap();
        out
    }

    /// A reader that hands out at most `k` bytes per read (a pipe delivering in pieces).
    struct Trickle<'a>(&'a [u8], usize);
    impl Read for Trickle<'_> {
        fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
            let n = self.0.len().min(out.len()).min(self.1);
            out[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    fn items(bytes: &[u8], format: RawFormat, w: u32, h: u32, piece: usize) -> Vec<Item> {
        let mut r = FrameReader::new(Trickle(bytes, piece), format, w, h);
        let mut out = Vec::new();
        loop {
            match r.next_item().unwrap() {
                Item::End => return out,
                i => out.push(i),
            }
            assert!(out.len() < 1000, "runaway");
        }
    }

    #[test]
    fn frame_sizes_are_the_stated_layouts() {
        assert_eq!(RawFormat::Rgb24.frame_bytes(320, 240), Some(230_400));
        assert_eq!(RawFormat::yuv420(false, 320).frame_bytes(320, 240), Some(115_200));
        // odd sizes: chroma planes round up (as ffmpeg's yuv420p)
        assert_eq!(RawFormat::yuv420(false, 5).frame_bytes(5, 3), Some(15 + 2 * 3 * 2));
        // padded rows (rpicam-vid at 4056 wide: stride 4096, rpicam-apps issue 151)
        let f = RawFormat::Yuv420 {
            full_range: true,
            stride: 4096,
        };
        assert_eq!(f.frame_bytes(4056, 3040), Some(18_677_760));
        assert_eq!(
            RawFormat::Yuv420 {
                full_range: true,
                stride: 100
            }
            .frame_bytes(128, 8),
            None
        );
        assert_eq!(RawFormat::Mjpeg.frame_bytes(320, 240), None);
        for n in ["rgb24", "yuv420", "yuvj420", "mjpeg"] {
            assert_eq!(RawFormat::parse(n, 320).unwrap().name(), n);
        }
        assert!(RawFormat::parse("h264", 320).is_none());
    }

    #[test]
    fn yuv_conversion_matches_bt601_in_both_ranges() {
        // grey levels, and the primaries as ffmpeg's yuv420p writes them (16..235)
        let one = |y: u8, u: u8, v: u8, full| {
            let f = RawFormat::yuv420(full, 2);
            f.to_rgb(&[y, y, y, y, u, v], 2, 2).unwrap().get_pixel(1, 1).0
        };
        assert_eq!(one(16, 128, 128, false), [0, 0, 0]);
        assert_eq!(one(235, 128, 128, false), [255, 255, 255]);
        assert_eq!(one(0, 128, 128, true), [0, 0, 0]);
        assert_eq!(one(128, 128, 128, true), [128, 128, 128]);
        let red = one(81, 90, 240, false);
        assert!(red[0] >= 253 && red[1] <= 2 && red[2] <= 2, "{red:?}");
        let red = one(76, 85, 255, true);
        assert!(red[0] >= 253 && red[1] <= 2 && red[2] <= 2, "{red:?}");
    }

    #[test]
    fn rgb_through_i420_and_back_is_close() {
        let img = RgbImage::from_fn(33, 17, |x, y| {
            image::Rgb([(x * 7) as u8, (y * 13) as u8, 200 - (x * 3) as u8])
        });
        let yuv = rgb_to_i420(&img);
        let back = RawFormat::yuv420(false, 33).to_rgb(&yuv, 33, 17).unwrap();
        // luma survives to a grey level or two; chroma is shared by 2×2 blocks
        let grey = |p: &image::Rgb<u8>| (299 * p[0] as i32 + 587 * p[1] as i32 + 114 * p[2] as i32) / 1000;
        let worst = img
            .pixels()
            .zip(back.pixels())
            .map(|(a, b)| (grey(a) - grey(b)).abs())
            .max()
            .unwrap();
        assert!(worst <= 3, "grey differs by {worst}");
    }

    #[test]
    fn padded_rows_are_skipped() {
        // 2×2 frame in rows of 4 bytes: the padding (0xEE) must not show
        let f = RawFormat::Yuv420 {
            full_range: true,
            stride: 4,
        };
        let bytes = [10, 20, 0xEE, 0xEE, 30, 40, 0xEE, 0xEE, 128, 0xEE, 128, 0xEE];
        let img = f.to_rgb(&bytes, 2, 2).unwrap();
        let g: Vec<u8> = img.pixels().map(|p| p[0]).collect();
        assert_eq!(g, [10, 20, 30, 40]);
    }

    #[test]
    fn raw_frames_are_cut_exactly_and_a_short_one_is_named() {
        let (w, h) = (8, 4);
        let n = RawFormat::Rgb24.frame_bytes(w, h).unwrap();
        let mut bytes: Vec<u8> = (0..3 * n).map(|i| (i % 251) as u8).collect();
        bytes.truncate(2 * n + 10);
        let got = items(&bytes, RawFormat::Rgb24, w, h, 7);
        assert_eq!(got.len(), 3);
        assert!(matches!(&got[1], Item::Frame(i) if i.as_raw()[..] == bytes[n..2 * n]));
        match &got[2] {
            Item::Bad(why) => assert!(why.contains("short frame: 10 of 96 bytes"), "{why}"),
            i => panic!("{i:?}"),
        }
    }

    #[test]
    fn a_jpeg_stream_is_cut_at_each_eoi_and_garbage_is_counted() {
        let a = jpeg(64, 48, 90);
        // cut inside the image data (after the start of scan), as a producer that dies does
        let sos = a.windows(2).position(|w| w == [0xFF, 0xDA]).unwrap();
        let cut = (sos + a.len()) / 2;
        let mut s = Vec::new();
        s.extend_from_slice(b"garbage before the first frame");
        s.extend_from_slice(&a);
        s.extend_from_slice(&a);
        s.extend_from_slice(&a[..cut]); // cut short, then a whole one
        s.extend_from_slice(&a);
        s.extend_from_slice(&a[..40]); // cut by the end of the stream
        for piece in [1, 5, 4096] {
            let got = items(&s, RawFormat::Mjpeg, 64, 48, piece);
            let kinds: Vec<&str> = got
                .iter()
                .map(|i| if matches!(i, Item::Frame(_)) { "F" } else { "B" })
                .collect();
            assert_eq!(kinds, ["B", "F", "F", "B", "F", "B"], "piece {piece}: {got:?}");
        }
    }

    #[test]
    fn an_exif_thumbnail_does_not_end_the_frame() {
        // A JPEG inside an APP1 segment (a thumbnail) has its own EOI: the walker skips the
        // segment by its length.
        let thumb = jpeg(8, 8, 50);
        let main = jpeg(16, 8, 90);
        let mut app1 = vec![0xFF, 0xE1];
        app1.extend_from_slice(&((thumb.len() + 2) as u16).to_be_bytes());
        app1.extend_from_slice(&thumb);
        let mut j = main[..2].to_vec();
        j.extend_from_slice(&app1);
        j.extend_from_slice(&main[2..]);
        assert_eq!(jpeg_extent(&j), JpegExtent::Whole(j.len()));
    }

    #[test]
    fn endless_garbage_stays_bounded() {
        // A producer writing a JPEG start and then never an end: the buffer stops at the
        // bound, the bytes are reported and dropped.
        let (w, h) = (16, 16);
        let max = RawFormat::max_jpeg_bytes(w, h);
        let mut s = jpeg(w, h, 90);
        s.truncate(s.len() - 2);
        s.resize(3 * max, 0x55);
        let mut r = FrameReader::new(Trickle(&s, 100_000), RawFormat::Mjpeg, w, h);
        let mut bad = 0;
        loop {
            match r.next_item().unwrap() {
                Item::End => break,
                Item::Bad(_) => bad += 1,
                Item::Frame(_) => panic!("no frame in there"),
            }
            assert!(r.buf.len() <= max, "buffer {} > {max}", r.buf.len());
        }
        assert!(bad >= 1);
    }
}
