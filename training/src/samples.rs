//! Training samples from files: positives from OpenCV `info.dat` annotation files (what
//! `opencv_createsamples -info` read: `path count x y w h [x y w h …]` per line, paths relative
//! to the file), negatives from background lists (OpenCV's `bg.txt`: one image path per line;
//! here a line may also carry boxes in the info.dat way, which are then kept out of the
//! negatives — e.g. rendered frames that show the object).
//!
//! Bad lines never stop a run: a missing or unreadable image, a malformed line, a box outside
//! its image or smaller than the window is skipped with a [`Skipped`] note naming the file,
//! line and reason. Boxes are cut out and resized to the window with OpenCV's bit-exact
//! bilinear resize (`INTER_LINEAR_EXACT`, `rccar::detect::resize`), the same the detector's
//! pyramid uses. Units: pixels.

use image::GrayImage;
use rccar::detect::resize::Resizer;
use rccar::detect::Rect;
use std::path::{Path, PathBuf};

/// Largest list file (info.dat, bg.txt, a boxes CSV) read, bytes.
pub const MAX_LIST_BYTES: u64 = 64 << 20;
/// Largest image read, pixels (width × height), as rccar's own limit.
pub const MAX_IMAGE_PIXELS: u64 = rccar::imageio::limits::MAX_IMAGE_PIXELS;
/// Most grey pixels held at once by one command (backgrounds, evaluation frames): 2 GB.
pub const MAX_TOTAL_PIXELS: u64 = 2_000_000_000;
/// Most positive windows loaded for training.
pub const MAX_POSITIVES: usize = 1_000_000;

/// Why a whole file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SampleError {
    /// The list file itself could not be read.
    #[error("{path}: cannot read: {err}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause (in the message, not a `source`: printed once).
        err: std::io::Error,
    },
    /// A bound was exceeded (the message names it).
    #[error("{0}")]
    TooMuch(String),
}

/// Reads a text file of at most [`MAX_LIST_BYTES`]; the error names the file and the bound.
pub fn read_list_text(path: &Path) -> Result<String, SampleError> {
    use std::io::Read;
    let io = |err| SampleError::Io {
        path: path.into(),
        err,
    };
    let mut text = String::new();
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_LIST_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > MAX_LIST_BYTES {
        return Err(SampleError::TooMuch(format!(
            "{}: larger than {MAX_LIST_BYTES} bytes (a list of images and boxes is far smaller)",
            path.display()
        )));
    }
    Ok(text)
}

/// An image's size from its header, refused above [`MAX_IMAGE_PIXELS`] before decoding.
pub fn checked_dimensions(path: &Path) -> Result<(u32, u32), String> {
    let (w, h) = image::image_dimensions(path).map_err(|e| format!("{}: cannot read image: {e}", path.display()))?;
    if w as u64 * h as u64 > MAX_IMAGE_PIXELS {
        return Err(format!(
            "{}: {w}x{h} pixels is above the image limit ({} megapixels)",
            path.display(),
            MAX_IMAGE_PIXELS / 1_000_000
        ));
    }
    Ok((w, h))
}

/// A line or box that was skipped, and why.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Skipped {
    /// The list file.
    pub file: String,
    /// 1-based line number.
    pub line: usize,
    /// What was wrong.
    pub reason: String,
}

impl std::fmt::Display for Skipped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: skipped: {}", self.file, self.line, self.reason)
    }
}

/// One line of an info.dat / bg.txt file.
#[derive(Debug, Clone, PartialEq)]
pub struct InfoLine {
    /// Image path (resolved against the list file's folder).
    pub path: PathBuf,
    /// Boxes (x, y, w, h), pixels.
    pub boxes: Vec<Rect>,
    /// 1-based line number.
    pub line: usize,
}

/// Every .png/.jpg/.jpeg in `dir` and its subfolders (a car's recording keeps its frames in
/// `seg_NNNNNN/` folders), sorted by path; at most 8 levels deep.
pub fn images_under(dir: &Path) -> Vec<PathBuf> {
    fn walk(d: &Path, depth: u32, out: &mut Vec<PathBuf>) {
        let Ok(rd) = std::fs::read_dir(d) else { return };
        let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok()).map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                if depth < 8 {
                    walk(&p, depth + 1, out);
                }
            } else if p
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
            {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, 0, &mut out);
    out
}

/// Parses an info.dat (or bg.txt) file. Malformed lines are returned in the skip list. A
/// folder is read as a bg.txt listing every .png/.jpg in it and its subfolders (sorted, no
/// boxes): a
/// recording of the track (`rccar sim --record DIR`, `rccar drive --record DIR`) or a folder of
/// room photos can be given as backgrounds or held-out frames without writing a list.
pub fn read_info(path: &Path) -> Result<(Vec<InfoLine>, Vec<Skipped>), SampleError> {
    if path.is_dir() {
        let files = images_under(path);
        let lines = files
            .into_iter()
            .enumerate()
            .map(|(i, p)| InfoLine {
                path: p,
                boxes: Vec::new(),
                line: i + 1,
            })
            .collect();
        return Ok((lines, Vec::new()));
    }
    let text = read_list_text(path)?;
    Ok(parse_info(&text, path))
}

/// Parses info.dat text; `origin` names the file and gives the folder paths are relative to.
pub fn parse_info(text: &str, origin: &Path) -> (Vec<InfoLine>, Vec<Skipped>) {
    let dir = origin.parent().unwrap_or(Path::new("."));
    let file = origin.display().to_string();
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let mut it = t.split_whitespace();
        let Some(p) = it.next() else { continue };
        let rest: Vec<&str> = it.collect();
        let skip = |reason: String| Skipped {
            file: file.clone(),
            line,
            reason,
        };
        let mut boxes = Vec::new();
        if !rest.is_empty() {
            let nums: Result<Vec<i64>, _> = rest.iter().map(|s| s.parse::<i64>()).collect();
            let Ok(nums) = nums else {
                skipped.push(skip(format!(
                    "`{}` has a count or box number that is not an integer",
                    t
                )));
                continue;
            };
            let count = nums[0];
            if count < 0 || nums.len() as i64 != 1 + 4 * count {
                skipped.push(skip(format!(
                    "count {count} needs {} numbers after it, found {}",
                    4 * count.max(0),
                    nums.len() - 1
                )));
                continue;
            }
            for b in nums[1..].chunks(4) {
                if b.iter().any(|v| v.abs() > 1 << 20) {
                    skipped.push(skip(format!("box {b:?} is out of range")));
                    continue;
                }
                boxes.push(Rect::new(b[0] as i32, b[1] as i32, b[2] as i32, b[3] as i32));
            }
        }
        out.push(InfoLine {
            path: dir.join(p),
            boxes,
            line,
        });
    }
    (out, skipped)
}

/// Loads an image as grey (OpenCV's integer BT.601 for colour files).
pub fn load_gray(path: &Path) -> Result<GrayImage, String> {
    checked_dimensions(path)?;
    let img = image::open(path).map_err(|e| format!("{}: cannot read image: {e}", path.display()))?;
    let rgb = img.to_rgb8();
    let mut g = GrayImage::new(rgb.width(), rgb.height());
    rccar::detect::gray_from_rgb(&rgb, &mut g);
    Ok(g)
}

/// Cuts `r` out of `img` and resizes it to `w` × `h` (bilinear, exact).
pub fn crop_resize(img: &GrayImage, r: Rect, w: usize, h: usize, rs: &mut Resizer) -> Vec<u8> {
    let (iw, _) = img.dimensions();
    let mut crop = Vec::with_capacity((r.width * r.height) as usize);
    for y in r.y..r.y + r.height {
        let row = (y as u32 * iw) as usize;
        crop.extend_from_slice(&img.as_raw()[row + r.x as usize..row + (r.x + r.width) as usize]);
    }
    let mut out = vec![0u8; w * h];
    rs.resize(&crop, r.width as usize, r.height as usize, &mut out, w, h);
    out
}

/// Positive windows (`w` × `h` each, row-major) from info.dat files, with the skip notes.
pub fn load_positives(files: &[PathBuf], w: usize, h: usize) -> Result<(Vec<Vec<u8>>, Vec<Skipped>), SampleError> {
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    let mut rs = Resizer::new();
    for f in files {
        let (lines, mut sk) = read_info(f)?;
        skipped.append(&mut sk);
        let file = f.display().to_string();
        for l in lines {
            let img = match load_gray(&l.path) {
                Ok(i) => i,
                Err(e) => {
                    skipped.push(Skipped {
                        file: file.clone(),
                        line: l.line,
                        reason: e,
                    });
                    continue;
                }
            };
            let (iw, ih) = (img.width() as i32, img.height() as i32);
            if l.boxes.is_empty() {
                skipped.push(Skipped {
                    file: file.clone(),
                    line: l.line,
                    reason: format!("{}: no boxes on the line (count 0)", l.path.display()),
                });
            }
            for b in l.boxes {
                let reason = if b.width <= 0 || b.height <= 0 {
                    Some(format!("box {b:?} is empty"))
                } else if b.x < 0
                    || b.y < 0
                    || b.x as i64 + b.width as i64 > iw as i64
                    || b.y as i64 + b.height as i64 > ih as i64
                {
                    Some(format!(
                        "box ({}, {}, {}, {}) is outside the {iw}x{ih} image {}",
                        b.x,
                        b.y,
                        b.width,
                        b.height,
                        l.path.display()
                    ))
                } else if (b.width as usize) < w || (b.height as usize) < h {
                    Some(format!(
                        "box {}x{} is smaller than the {w}x{h} window (would be upscaled): {}",
                        b.width,
                        b.height,
                        l.path.display()
                    ))
                } else {
                    None
                };
                match reason {
                    Some(reason) => skipped.push(Skipped {
                        file: file.clone(),
                        line: l.line,
                        reason,
                    }),
                    None => {
                        if out.len() >= MAX_POSITIVES {
                            return Err(SampleError::TooMuch(format!(
                                "{file}:{}: more than {MAX_POSITIVES} positive boxes; use fewer",
                                l.line
                            )));
                        }
                        out.push(crop_resize(&img, b, w, h, &mut rs))
                    }
                }
            }
        }
    }
    Ok((out, skipped))
}

/// A background image to mine negatives from, with boxes to keep out.
#[derive(Debug, Clone)]
pub struct Background {
    /// Where it came from (for messages).
    pub name: String,
    /// Grey pixels.
    pub img: GrayImage,
    /// Object boxes: windows overlapping one of them (IoU ≥ 0.3, `scan::AVOID_IOU`) are not negatives.
    pub avoid: Vec<Rect>,
}

/// Background images from bg.txt / info.dat files, with the skip notes.
pub fn load_backgrounds(files: &[PathBuf]) -> Result<(Vec<Background>, Vec<Skipped>), SampleError> {
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    let mut pixels = 0u64;
    for f in files {
        let (lines, mut sk) = read_info(f)?;
        skipped.append(&mut sk);
        for l in lines {
            if let Ok((w, h)) = image::image_dimensions(&l.path) {
                pixels += w as u64 * h as u64;
                if pixels > MAX_TOTAL_PIXELS {
                    return Err(SampleError::TooMuch(format!(
                        "{}:{}: the backgrounds so far hold more than {MAX_TOTAL_PIXELS} pixels; use fewer or smaller ones",
                        f.display(),
                        l.line
                    )));
                }
            }
            match load_gray(&l.path) {
                Ok(img) => out.push(Background {
                    name: l.path.display().to_string(),
                    img,
                    avoid: l.boxes,
                }),
                Err(reason) => skipped.push(Skipped {
                    file: f.display().to_string(),
                    line: l.line,
                    reason,
                }),
            }
        }
    }
    Ok((out, skipped))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_is_a_list_of_frames_without_the_object() {
        // A car's recording: frames in seg_ folders, telemetry beside them.
        let d = tempfile::tempdir().expect("tmp");
        for f in ["seg_000001/frame_2.jpg", "seg_000000/frame_1.jpg", "a.png"] {
            let p = d.path().join(f);
            std::fs::create_dir_all(p.parent().expect("parent")).expect("dir");
            GrayImage::from_pixel(40, 30, image::Luma([9])).save(&p).expect("img");
        }
        std::fs::write(d.path().join("telemetry.jsonl"), "{}\n").expect("jsonl");
        let (lines, skipped) = read_info(d.path()).expect("folder");
        assert!(skipped.is_empty());
        let names: Vec<String> = lines
            .iter()
            .map(|l| l.path.strip_prefix(d.path()).expect("inside").display().to_string())
            .collect();
        assert_eq!(names, ["a.png", "seg_000000/frame_1.jpg", "seg_000001/frame_2.jpg"]);
        assert!(lines.iter().all(|l| l.boxes.is_empty()));
        let (bgs, _) = load_backgrounds(&[d.path().to_path_buf()]).expect("backgrounds");
        assert_eq!(bgs.len(), 3);
    }

    #[test]
    fn info_lines_parse_and_bad_ones_are_named() {
        let text = "a.png 1 0 0 10 10\n\n# c\nb.png 2 1 2 3 4 5 6 7 8\nc.png 2 1 2 3 4\nd.png x 1\ne.png\n";
        let (lines, skipped) = parse_info(text, Path::new("dir/info.dat"));
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0].path, Path::new("dir/a.png"));
        assert_eq!(lines[1].boxes[1], Rect::new(5, 6, 7, 8));
        assert!(lines[2].boxes.is_empty());
        assert_eq!(skipped.len(), 2);
        assert_eq!(skipped[0].line, 5);
        assert!(skipped[0].to_string().contains("dir/info.dat:5"), "{}", skipped[0]);
        assert_eq!(skipped[1].line, 6);
    }

    /// A PNG that holds only its header (IHDR, an empty IDAT, IEND): enough for
    /// `image::image_dimensions`, far too little to decode.
    fn png_header(path: &Path, w: u32, h: u32) {
        fn crc(bytes: &[u8]) -> u32 {
            let mut c = !0u32;
            for &b in bytes {
                c ^= b as u32;
                for _ in 0..8 {
                    c = if c & 1 == 1 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
                }
            }
            !c
        }
        let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut ihdr = w.to_be_bytes().to_vec();
        ihdr.extend(h.to_be_bytes());
        ihdr.extend([8, 0, 0, 0, 0]); // 8-bit grey, no interlace
        for (kind, data) in [(&b"IHDR"[..], &ihdr[..]), (b"IDAT", &[]), (b"IEND", &[])] {
            out.extend((data.len() as u32).to_be_bytes());
            let mut body = kind.to_vec();
            body.extend(data);
            out.extend(&body);
            out.extend(crc(&body).to_be_bytes());
        }
        std::fs::write(path, out).unwrap();
    }

    /// The image bound: 40 million pixels pass the header check, one more is refused before
    /// decoding, with the file and the limit named.
    #[test]
    fn images_above_the_pixel_bound_are_refused_from_the_header() {
        let dir = tempfile::tempdir().unwrap();
        let at = dir.path().join("at.png");
        png_header(&at, 8000, 5000);
        assert_eq!(8000 * 5000, MAX_IMAGE_PIXELS);
        assert_eq!(checked_dimensions(&at), Ok((8000, 5000)));
        let over = dir.path().join("over.png");
        png_header(&over, 40_000_001, 1);
        let e = checked_dimensions(&over).unwrap_err();
        assert!(
            e.contains("over.png") && e.contains("40000001x1") && e.contains("40 megapixels"),
            "{e}"
        );
        // load_gray refuses it the same way (before allocating 40 MB).
        assert_eq!(load_gray(&over).unwrap_err(), e);
    }

    /// The list bound: a list of exactly MAX_LIST_BYTES is read, one byte more is refused,
    /// naming the file and the bound.
    #[test]
    fn list_files_above_the_byte_bound_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let at = dir.path().join("at.txt");
        let mut text = "# padding\n".repeat((MAX_LIST_BYTES / 10) as usize);
        text.push_str(&"#".repeat((MAX_LIST_BYTES - text.len() as u64) as usize));
        assert_eq!(text.len() as u64, MAX_LIST_BYTES);
        std::fs::write(&at, &text).unwrap();
        assert_eq!(read_list_text(&at).unwrap().len() as u64, MAX_LIST_BYTES);
        let over = dir.path().join("over.txt");
        text.push('#');
        std::fs::write(&over, &text).unwrap();
        let e = read_info(&over).unwrap_err().to_string();
        assert!(
            e.contains("over.txt") && e.contains(&format!("larger than {MAX_LIST_BYTES} bytes")),
            "{e}"
        );
    }
}
