//! Boxes from a CSV file to OpenCV's `info.dat`, and pictures to check them, so a student can
//! label photos with any image viewer that shows pixel coordinates (or a spreadsheet) instead of
//! writing code.
//!
//! CSV: one box per line, `file,x,y,w,h` (pixels, x/y the top-left corner), paths relative to
//! the CSV's folder; a line with only `file` marks a frame without the object (it goes to the
//! background list). A first line that is not numbers (`file,x,y,w,h`) is a header; `#` lines
//! and blank lines are skipped. Every line is checked — the file exists and decodes, five
//! fields, integers, the box non-empty and inside the image — and each problem is reported as
//! `boxes.csv:LINE: …`; nothing is written unless every line is good.
//!
//! Previews: each labelled image with its boxes drawn (PNG), and one contact sheet of every
//! box cut out (`crops.png`), to spot a wrong box at a glance. Units: pixels.

use image::{GenericImageView, RgbImage};
use rccar::detect::Rect;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The labelled images of a CSV: per image (in first-seen order) its boxes.
#[derive(Debug, Clone, Default)]
pub struct Labels {
    /// (image path as resolved, boxes); boxes empty = a frame without the object.
    pub images: Vec<(PathBuf, Vec<Rect>)>,
}

impl Labels {
    /// Boxes in all.
    pub fn boxes(&self) -> usize {
        self.images.iter().map(|(_, b)| b.len()).sum()
    }
}

/// Reads and checks a boxes CSV; `Err` lists every bad line (`file:line: reason`).
pub fn read_csv(csv: &Path) -> Result<Labels, Vec<String>> {
    let text = crate::samples::read_list_text(csv).map_err(|e| vec![e.to_string()])?;
    let dir = csv.parent().unwrap_or(Path::new("."));
    let name = csv.display().to_string();
    let mut errors = Vec::new();
    let mut order: Vec<PathBuf> = Vec::new();
    let mut map: BTreeMap<PathBuf, Vec<Rect>> = BTreeMap::new();
    let mut sizes: BTreeMap<PathBuf, Option<(u32, u32)>> = BTreeMap::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = t.split(',').map(|s| s.trim()).collect();
        if line == 1 && f.len() == 5 && f[1..].iter().all(|s| s.parse::<i64>().is_err()) {
            continue; // header
        }
        let err = |m: String| format!("{name}:{line}: {m}");
        if f.len() != 1 && f.len() != 5 {
            errors.push(err(format!(
                "expected `file,x,y,w,h` (or `file` alone for a frame without the object), found {} fields",
                f.len()
            )));
            continue;
        }
        if f[0].is_empty() {
            errors.push(err("empty file name".into()));
            continue;
        }
        let path = dir.join(f[0]);
        let size = *sizes.entry(path.clone()).or_insert_with(|| {
            image::ImageReader::open(&path)
                .ok()
                .and_then(|r| r.with_guessed_format().ok())
                .and_then(|r| r.into_dimensions().ok())
        });
        let Some((iw, ih)) = size else {
            errors.push(err(format!("{}: missing or not a readable image", path.display())));
            continue;
        };
        if !map.contains_key(&path) {
            order.push(path.clone());
            map.insert(path.clone(), Vec::new());
        }
        if f.len() == 1 {
            continue;
        }
        let nums: Result<Vec<i64>, _> = f[1..].iter().map(|s| s.parse::<i64>()).collect();
        let Ok(n) = nums else {
            errors.push(err(format!("x,y,w,h must be whole pixels, found `{}`", f[1..].join(","))));
            continue;
        };
        let (x, y, w, h) = (n[0], n[1], n[2], n[3]);
        if w <= 0 || h <= 0 {
            errors.push(err(format!("box {w}x{h} is empty")));
            continue;
        }
        if x < 0 || y < 0 || x + w > iw as i64 || y + h > ih as i64 {
            errors.push(err(format!(
                "box x={x} y={y} w={w} h={h} is outside the {iw}x{ih} image {}",
                path.display()
            )));
            continue;
        }
        if let Some(v) = map.get_mut(&path) {
            v.push(Rect::new(x as i32, y as i32, w as i32, h as i32));
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    if order.is_empty() {
        return Err(vec![format!("{name}: no lines")]);
    }
    Ok(Labels {
        images: order
            .into_iter()
            .map(|p| {
                let b = map.remove(&p).unwrap_or_default();
                (p, b)
            })
            .collect(),
    })
}

/// `path` relative to `base` (info.dat paths are relative to the info.dat's folder), with `..`
/// where it lies outside it (`data/pos.dat` naming `frames/a.jpg` writes `../frames/a.jpg`), so
/// the lists keep working when the project folder is moved; absolute only when the two share no
/// root. Lexical: `.` and `..` are resolved on the names, symbolic links are not followed.
pub fn rel(path: &Path, base: &Path) -> String {
    use std::path::Component;
    let norm = |p: &Path| {
        // `Path::new("pos.dat").parent()` is the empty path: the working folder.
        let p = if p.as_os_str().is_empty() { Path::new(".") } else { p };
        let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        let mut out: Vec<Component> = Vec::new();
        for c in abs.components() {
            match c {
                Component::CurDir => {}
                Component::ParentDir => {
                    if matches!(out.last(), Some(Component::Normal(_))) {
                        out.pop();
                    }
                }
                c => out.push(c),
            }
        }
        out.into_iter().collect::<PathBuf>()
    };
    let (p, b) = (norm(path), norm(base));
    let (pc, bc): (Vec<_>, Vec<_>) = (p.components().collect(), b.components().collect());
    let common = pc.iter().zip(&bc).take_while(|(x, y)| x == y).count();
    // Different roots (another drive): only the absolute path names the file.
    if common == 0 {
        return p.display().to_string();
    }
    let mut r = PathBuf::new();
    for _ in common..bc.len() {
        r.push("..");
    }
    for c in &pc[common..] {
        r.push(c);
    }
    r.display().to_string()
}

/// Writes `info` (images with boxes) and, when some lines have no box, `bg` (frames without
/// the object). Returns (images with boxes, boxes, frames without).
pub fn write_lists(l: &Labels, info: &Path, bg: Option<&Path>) -> std::io::Result<(usize, usize, usize)> {
    let base = info.parent().unwrap_or(Path::new("."));
    let mut text = String::new();
    let (mut imgs, mut boxes) = (0, 0);
    for (p, b) in l.images.iter().filter(|(_, b)| !b.is_empty()) {
        text.push_str(&format!("{} {}", rel(p, base), b.len()));
        for r in b {
            text.push_str(&format!(" {} {} {} {}", r.x, r.y, r.width, r.height));
        }
        text.push('\n');
        imgs += 1;
        boxes += b.len();
    }
    if let Some(d) = info.parent() {
        std::fs::create_dir_all(d)?;
    }
    std::fs::write(info, text)?;
    let empty: Vec<&PathBuf> = l.images.iter().filter(|(_, b)| b.is_empty()).map(|(p, _)| p).collect();
    if let Some(bg) = bg {
        let base = bg.parent().unwrap_or(Path::new("."));
        let t: String = empty.iter().map(|p| format!("{}\n", rel(p, base))).collect();
        std::fs::write(bg, t)?;
    }
    Ok((imgs, boxes, empty.len()))
}

/// Writes every box cut out of its image as `DIR/<image stem>_<k>.png` (k = the box's number
/// on that image, from 1): a folder of crops, as `distort --template DIR` takes them. Returns
/// the crops written.
pub fn write_crops(l: &Labels, dir: &Path) -> Result<usize, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut n = 0;
    for (p, boxes) in l.images.iter().filter(|(_, b)| !b.is_empty()) {
        let img = image::open(p).map_err(|e| format!("{}: {e}", p.display()))?;
        let stem = p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        for (k, r) in boxes.iter().enumerate() {
            let c = img.crop_imm(r.x as u32, r.y as u32, r.width as u32, r.height as u32);
            let out = dir.join(format!("{stem}_{}.png", k + 1));
            c.save(&out).map_err(|e| format!("{}: {e}", out.display()))?;
            n += 1;
        }
    }
    Ok(n)
}

fn draw_rect(img: &mut RgbImage, r: Rect, c: [u8; 3], t: i32) {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let mut put = |x: i32, y: i32| {
        if x >= 0 && y >= 0 && x < w && y < h {
            img.put_pixel(x as u32, y as u32, image::Rgb(c));
        }
    };
    for k in 0..t {
        for x in r.x - k..r.x + r.width + k {
            put(x, r.y - 1 - k);
            put(x, r.y + r.height + k);
        }
        for y in r.y - 1 - k..r.y + r.height + 1 + k {
            put(r.x - 1 - k, y);
            put(r.x + r.width + k, y);
        }
    }
}

/// Writes `DIR/<name>_boxes.png` for every labelled image (boxes in green, outside the box so
/// its pixels stay visible) and `DIR/crops.png`, every box cut out and scaled to `cell` px,
/// in CSV order. Returns the files written.
pub fn previews(l: &Labels, dir: &Path, cell: u32) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut written = Vec::new();
    let mut crops = Vec::new();
    for (p, boxes) in l.images.iter().filter(|(_, b)| !b.is_empty()) {
        let img = image::open(p).map_err(|e| format!("{}: {e}", p.display()))?;
        let mut rgb = img.to_rgb8();
        for &r in boxes {
            let c = img.view(r.x as u32, r.y as u32, r.width as u32, r.height as u32).to_image();
            let k = cell as f64 / r.width.max(r.height) as f64;
            let (cw, ch) = (
                ((r.width as f64 * k).round() as u32).max(1),
                ((r.height as f64 * k).round() as u32).max(1),
            );
            crops.push(image::imageops::resize(
                &image::DynamicImage::ImageRgba8(c).to_rgb8(),
                cw,
                ch,
                image::imageops::FilterType::Triangle,
            ));
            draw_rect(&mut rgb, r, [0, 230, 0], 2);
        }
        let stem = p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        let mut out = dir.join(format!("{stem}_boxes.png"));
        let mut k = 1;
        while written.contains(&out) {
            out = dir.join(format!("{stem}_{k}_boxes.png"));
            k += 1;
        }
        rgb.save(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        written.push(out);
    }
    if !crops.is_empty() {
        let cols = (crops.len() as f64).sqrt().ceil().max(1.0) as u32;
        let rows = (crops.len() as u32).div_ceil(cols);
        let pad = 4;
        let mut sheet = RgbImage::from_pixel(cols * (cell + pad) + pad, rows * (cell + pad) + pad, image::Rgb([40, 40, 40]));
        for (i, c) in crops.iter().enumerate() {
            let (cx, cy) = (i as u32 % cols, i as u32 / cols);
            image::imageops::overlay(
                &mut sheet,
                c,
                (pad + cx * (cell + pad)) as i64,
                (pad + cy * (cell + pad)) as i64,
            );
        }
        let out = dir.join("crops.png");
        sheet.save(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        written.push(out);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_is_checked_line_by_line_and_written_as_info_dat() {
        let dir = tempfile::tempdir().expect("tmp");
        let d = dir.path();
        image::RgbImage::from_pixel(100, 80, image::Rgb([9, 9, 9]))
            .save(d.join("a.jpg"))
            .expect("jpg");
        image::RgbImage::from_pixel(50, 40, image::Rgb([9, 9, 9]))
            .save(d.join("b.png"))
            .expect("png");
        let csv = d.join("boxes.csv");
        std::fs::write(&csv, "file,x,y,w,h\na.jpg,10,10,30,30\na.jpg,50,20,20,20\nb.png\n").expect("csv");
        let l = read_csv(&csv).expect("good");
        assert_eq!(l.images.len(), 2);
        assert_eq!(l.boxes(), 2);
        let (imgs, boxes, empty) = write_lists(&l, &d.join("info.dat"), Some(&d.join("bg.txt"))).expect("write");
        assert_eq!((imgs, boxes, empty), (1, 2, 1));
        assert_eq!(
            std::fs::read_to_string(d.join("info.dat")).expect("info"),
            "a.jpg 2 10 10 30 30 50 20 20 20\n"
        );
        assert_eq!(std::fs::read_to_string(d.join("bg.txt")).expect("bg"), "b.png\n");
        let (lines, sk) = crate::samples::read_info(&d.join("info.dat")).expect("parse");
        assert!(sk.is_empty() && lines[0].boxes.len() == 2);
        let files = previews(&l, &d.join("preview"), 48).expect("previews");
        assert_eq!(files.len(), 2);
        assert_eq!(write_crops(&l, &d.join("crops")).expect("crops"), 2);
        assert_eq!(image::image_dimensions(d.join("crops/a_2.png")).expect("crop"), (20, 20));
        let sheet = image::open(d.join("preview/crops.png")).expect("sheet");
        assert_eq!(sheet.width(), 2 * 52 + 4);
        // Every bad line is named; nothing accepted.
        std::fs::write(
            &csv,
            "a.jpg,10,10,30,30\nmissing.jpg,1,1,5,5\na.jpg,90,10,30,30\na.jpg,1,2,x,4\na.jpg,1,2\nb.png,0,0,0,5\n",
        )
        .expect("csv");
        let e = read_csv(&csv).unwrap_err();
        assert_eq!(e.len(), 5, "{e:#?}");
        assert!(e[0].contains("boxes.csv:2:") && e[0].contains("missing.jpg"), "{}", e[0]);
        assert!(e[1].contains(":3:") && e[1].contains("outside the 100x80"), "{}", e[1]);
        assert!(e[2].contains(":4:") && e[2].contains("whole pixels"), "{}", e[2]);
        assert!(e[3].contains(":5:") && e[3].contains("3 fields"), "{}", e[3]);
        assert!(e[4].contains(":6:") && e[4].contains("empty"), "{}", e[4]);
    }

    /// Issue 28: `boxes --out data/pos.dat` naming `frames/a.jpg` wrote an absolute path.
    #[test]
    fn list_paths_are_relative_to_the_list_even_outside_its_folder() {
        let d = tempfile::tempdir().expect("tmp");
        let b = d.path().join("data");
        assert_eq!(rel(&d.path().join("frames/a.jpg"), &b), "../frames/a.jpg");
        assert_eq!(rel(&b.join("x/a.jpg"), &b), "x/a.jpg");
        assert_eq!(rel(&d.path().join("data/../frames/./a.jpg"), &d.path().join("data/sub/")), "../../frames/a.jpg");
        // Relative inputs are taken against the working folder.
        assert_eq!(rel(Path::new("frames/a.jpg"), Path::new("data")), "../frames/a.jpg");
        assert_eq!(rel(Path::new("a.jpg"), Path::new("")), "a.jpg");
        // And the list reads back to the same file.
        std::fs::create_dir_all(d.path().join("frames")).expect("dir");
        image::GrayImage::from_pixel(40, 30, image::Luma([7])).save(d.path().join("frames/a.png")).expect("png");
        let csv = d.path().join("boxes.csv");
        std::fs::write(&csv, "frames/a.png,1,1,20,20\n").expect("csv");
        let l = read_csv(&csv).expect("good");
        write_lists(&l, &b.join("pos.dat"), None).expect("write");
        let text = std::fs::read_to_string(b.join("pos.dat")).expect("info");
        assert_eq!(text, "../frames/a.png 1 1 1 20 20\n");
        let (lines, _) = crate::samples::read_info(&b.join("pos.dat")).expect("parse");
        assert!(lines[0].path.exists(), "{}", lines[0].path.display());
    }
}
