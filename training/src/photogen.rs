//! Photo-like labelled frames for checking that a cascade trained the real-photo way
//! generalises, without anyone's photo set: the simulator's stop sign (its face painted by
//! `rccar::sim::scene` — red octagon, white rim, STOP — rendered head-on with 4 × 4
//! supersampling into an RGBA template) pasted into crops of photographs that are on the
//! system anyway (by default OpenCV's sample pictures from Debian's opencv-doc; any folder
//! with `--photos`, e.g. scikit-image's data photos), then passed through a camera model.
//!
//! Per frame (320 × 240, seeded):
//! 1. background: a photo, a random crop of 40–100% of the largest 4:3 region, resized to the
//!    frame (exact bilinear), mirrored half of the time;
//! 2. with a sign (frames "with"): face size 16–64 px by default (log-uniform: 1.65–0.41 m
//!    with the car's 265 px focal length and a 10 cm sign), seen up to 40° off-axis (width × cos), rotated
//!    ±8°, corners jittered ±6% (perspective), its own lighting (contrast 0.7–1.2, ±30 grey),
//!    a grey post below; the label is the axis-aligned box around the face's corners, as a
//!    person would draw it;
//! 3. camera: exposure gain 0.6–1.4 and gamma 0.8–1.25, Gaussian blur σ 0.3–1.3 px on half of
//!    the frames, noise σ 1–6 grey levels, saved as JPEG at quality 60–95.
//!
//! With `printed` (`photoset --printed`) the sign looks like a printed or toy sign rather than
//! the simulator's ([`printed_style`]: a light frame, washed and jittered colours, posts of any
//! grey and width); with `traffic_light` (`photoset --traffic-light`) the object is a traffic
//! light ([`traffic_light_style`]). Neither changes the default frames.
//!
//! Written: `frames/NNNNNN.jpg`, `info.dat` (frames with a sign), `bg.txt` (frames without),
//! and `boxes.csv` (both, in the CSV form `rccar-train boxes` reads). Units: pixels.

use crate::distort::{blur, gauss, paste};
use image::{GrayImage, RgbaImage};
use rccar::detect::resize::Resizer;
use rccar::sim::rng::{mix, SplitMix64};
use rccar::sim::scene::{PanelKind, Prim, Scene};
use rccar::sim::track::Track;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Frame size, pixels (the car's camera).
pub const FRAME: (u32, u32) = (320, 240);

/// The simulator's stop-sign face, `px` × `px` RGBA (alpha = coverage of the octagon).
pub fn stop_sign_template(track: &Path, px: u32) -> Result<RgbaImage, String> {
    let track = Track::load(track).map_err(|e| format!("{}: {e}", track.display()))?;
    let scene = Scene::new(&track);
    let r = &track.floor_rect;
    let centre = [(r[0] + r[2]) / 2.0, (r[1] + r[3]) / 2.0, 0.17];
    let width = 0.10;
    let prims = [Prim::Panel {
        center: centre,
        dir: [1.0, 0.0],
        kind: PanelKind::StopFace { width },
    }];
    let ss = 4;
    Ok(RgbaImage::from_fn(px, px, |i, j| {
        let (mut acc, mut n) = ([0f32; 3], 0u32);
        for sj in 0..ss {
            for si in 0..ss {
                let u = ((i * ss + si) as f64 + 0.5) / (px * ss) as f64 * width - width / 2.0;
                let w = width / 2.0 - ((j * ss + sj) as f64 + 0.5) / (px * ss) as f64 * width;
                // Looking along −x at the panel: +y is the viewer's right.
                let o = [centre[0] + 1.0, centre[1] + u, centre[2] + w];
                if let Some(h) = scene.intersect(&prims, o, [-1.0, 0.0, 0.0], 10.0) {
                    for (a, c) in acc.iter_mut().zip(h.rgb) {
                        *a += c;
                    }
                    n += 1;
                }
            }
        }
        if n == 0 {
            return image::Rgba([0, 0, 0, 0]);
        }
        let c = |k: usize| (acc[k] / n as f32).round().clamp(0.0, 255.0) as u8;
        image::Rgba([c(0), c(1), c(2), (255 * n / (ss * ss)) as u8])
    }))
}

/// JPEG and PNG files in `dirs` (not recursive; a file may be named directly), sorted, without
/// duplicates.
pub fn list_photos(dirs: &[PathBuf]) -> Vec<PathBuf> {
    let is_img = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
    };
    let mut out = Vec::new();
    for d in dirs {
        if d.is_file() && is_img(d) {
            out.push(d.clone());
        } else if let Ok(rd) = std::fs::read_dir(d) {
            out.extend(
                rd.filter_map(|e| e.ok())
                    .map(|e| e.path())
                    .filter(|p| p.is_file() && is_img(p)),
            );
        }
    }
    out.sort();
    out.dedup();
    out
}

/// Where Debian's opencv-doc puts OpenCV's sample pictures: the default photos of `photoset`.
pub const OPENCV_SAMPLES: &str = "/usr/share/doc/opencv-doc/examples/data";

/// The default photo directories: OpenCV's sample pictures ([`OPENCV_SAMPLES`], Debian's
/// opencv-doc), if installed. Only these: a fixed Debian package gives every machine the same
/// photos, so the same seed gives the same frames (a Python package's data folder, found or not
/// and of whatever version, made a seeded run differ between machines). Other photos, such as
/// scikit-image's data folder, are named with `--photos`.
pub fn system_photo_dirs() -> Vec<PathBuf> {
    [PathBuf::from(OPENCV_SAMPLES)].into_iter().filter(|d| d.is_dir()).collect()
}

/// Photos split in two disjoint halves by position in the sorted list (`part` 0 or 1).
pub fn half(photos: &[PathBuf], part: usize) -> Vec<PathBuf> {
    photos.iter().skip(part % 2).step_by(2).cloned().collect()
}

/// The photos of a named part: `all`; `0` or `1` (the halves of [`half`]); `0-train` and
/// `0-val`, half 0 split again — every fifth photo of it (`0-val`) is kept for validation and
/// the other four fifths (`0-train`) are for training, so a validation set made from `0-val`
/// shows the trainer photos it never saw, and the test half `1` stays untouched. `None` for
/// another name.
pub fn part(photos: &[PathBuf], name: &str) -> Option<Vec<PathBuf>> {
    let h0 = || half(photos, 0).into_iter().enumerate();
    Some(match name {
        "all" => photos.to_vec(),
        "0" => half(photos, 0),
        "1" => half(photos, 1),
        "0-train" => h0().filter(|(i, _)| i % 5 != 4).map(|(_, p)| p).collect(),
        "0-val" => h0().filter(|(i, _)| i % 5 == 4).map(|(_, p)| p).collect(),
        _ => return None,
    })
}

/// What to make.
#[derive(Debug, Clone)]
pub struct PhotoSetOptions {
    /// Frames showing one sign.
    pub with_sign: usize,
    /// Frames without.
    pub without: usize,
    /// Seed.
    pub seed: u64,
    /// Sign face size range, pixels.
    pub sign_px: (f64, f64),
    /// Signs made to look like printed or toy signs rather than the simulator's own
    /// ([`printed_style`]: a light frame around the face, colours jittered and washed towards
    /// white, a post of any grey and width). Off: the frames of earlier rounds, byte for byte.
    pub printed: bool,
    /// Traffic lights instead of stop signs ([`traffic_light_style`]).
    pub traffic_light: bool,
}

impl Default for PhotoSetOptions {
    fn default() -> Self {
        PhotoSetOptions {
            with_sign: 48,
            without: 350,
            seed: 1,
            sign_px: (16.0, 64.0),
            printed: false,
            traffic_light: false,
        }
    }
}

/// The lists written.
#[derive(Debug, Clone)]
pub struct PhotoSet {
    /// Frames with a sign and its box.
    pub info: PathBuf,
    /// Frames without.
    pub bg: PathBuf,
    /// Both, as a boxes CSV.
    pub csv: PathBuf,
}

/// Step 2 of [`generate`]: the sign `template` on a post (`post`) pasted into the `FRAME`-sized
/// `canvas` (size from `o.sign_px`, up to 40° off its axis, ±8° roll, ±6% corner jitter,
/// contrast and brightness); its box [x, y, w, h] clipped to the frame.
fn paste_sign(
    canvas: &mut [f32],
    template: &RgbaImage,
    post: &RgbaImage,
    post_width: f64,
    o: &PhotoSetOptions,
    rng: &mut SplitMix64,
) -> [i64; 4] {
    let (fw, fh) = FRAME;
    let u = |r: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * r.next_f64();
    let s = (o.sign_px.0.ln() + (o.sign_px.1.ln() - o.sign_px.0.ln()) * rng.next_f64()).exp();
    // Seen up to 40° off its axis: narrower by cos (`s` is the height; the width as the
    // template's).
    let aspect = template.width() as f64 / template.height() as f64;
    let sx = s * aspect * u(rng, 0.0, 40f64.to_radians()).cos();
    let margin = 4.0;
    let ccx = u(rng, margin + sx / 2.0 + 3.0, fw as f64 - margin - sx / 2.0 - 3.0);
    let ccy = u(rng, margin + s / 2.0 + 3.0, fh as f64 - margin - s / 2.0 - 3.0);
    let a = u(rng, -8f64, 8.0).to_radians();
    let (sa, ca) = a.sin_cos();
    let mut dst = [[0f64; 2]; 4];
    for (i, (dx, dy)) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)].iter().enumerate() {
        let (px, py) = (dx * sx + u(rng, -0.06, 0.06) * s, dy * s + u(rng, -0.06, 0.06) * s);
        dst[i] = [ccx + ca * px - sa * py, ccy + sa * px + ca * py];
    }
    let contrast = u(rng, 0.7, 1.2);
    let bright = u(rng, -30.0, 30.0);
    // The post: from under the face down 1-3 face sizes.
    let (pw2, pl) = (s * post_width, s * u(rng, 1.0, 3.0));
    let (bx, by) = (ccx - sa * s * 0.45, ccy + ca * s * 0.45);
    let post_dst = [
        [bx - pw2 / 2.0, by],
        [bx + pw2 / 2.0, by],
        [bx + pw2 / 2.0 - sa * pl, by + ca * pl],
        [bx - pw2 / 2.0 - sa * pl, by + ca * pl],
    ];
    paste(canvas, fw, fh, post, post_dst, contrast, bright);
    paste(canvas, fw, fh, template, dst, contrast, bright);
    let x0 = dst.iter().map(|p| p[0]).fold(f64::MAX, f64::min).round();
    let y0 = dst.iter().map(|p| p[1]).fold(f64::MAX, f64::min).round();
    let x1 = dst.iter().map(|p| p[0]).fold(f64::MIN, f64::max).round();
    let y1 = dst.iter().map(|p| p[1]).fold(f64::MIN, f64::max).round();
    let (x0, y0) = (x0.max(0.0), y0.max(0.0));
    let (x1, y1) = (x1.min(fw as f64), y1.min(fh as f64));
    [x0 as i64, y0 as i64, (x1 - x0) as i64, (y1 - y0) as i64]
}

/// One printed-looking sign (`PhotoSetOptions::printed`): the template with a light frame
/// (grey 150–255) 0–12 % of the width wide around a shrunk face, its colours
/// jittered (each channel × 0.8–1.2) and washed towards white by 0–50 % (a printed or toy sign's
/// pale red is far lighter in grey than the simulator's), and a post of grey 80–240 whose width
/// (0.05–0.2 of the face) is returned with it.
fn printed_style(template: &RgbaImage, rng: &mut SplitMix64) -> (RgbaImage, RgbaImage, f64) {
    let u = |r: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * r.next_f64();
    let gain = [u(rng, 0.8, 1.2), u(rng, 0.8, 1.2), u(rng, 0.8, 1.2)];
    let wash = u(rng, 0.0, 0.5);
    // A toy or printed sign's light frame around the red: the face shrunk by 0-24 % inside the
    // template's octagon, the ring left filled with a light grey.
    let k = 1.0 - u(rng, 0.0, 0.24);
    let rim = u(rng, 150.0, 255.0) as u8;
    let (w, h) = template.dimensions();
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let mut t = RgbaImage::from_fn(w, h, |x, y| {
        let a = template.get_pixel(x, y).0[3];
        let (sx, sy) = (cx + (x as f64 + 0.5 - cx) / k, cy + (y as f64 + 0.5 - cy) / k);
        let inner = if sx >= 0.0 && sy >= 0.0 && sx < w as f64 && sy < h as f64 {
            template.get_pixel(sx as u32, sy as u32).0
        } else {
            [0; 4]
        };
        let ia = inner[3] as f64 / 255.0;
        let c = |i: usize| (inner[i] as f64 * ia + rim as f64 * (1.0 - ia)).round() as u8;
        image::Rgba([c(0), c(1), c(2), a])
    });
    for p in t.pixels_mut() {
        for (ch, g) in p.0.iter_mut().zip(gain) {
            let v = *ch as f64 * g;
            *ch = (v + (255.0 - v) * wash).round().clamp(0.0, 255.0) as u8;
        }
    }
    let g = u(rng, 80.0, 240.0) as u8;
    let post = RgbaImage::from_pixel(4, 4, image::Rgba([g, g, g, 255]));
    (t, post, u(rng, 0.05, 0.2))
}

/// One traffic light (`PhotoSetOptions::traffic_light`): half of them drawn as the simulator
/// draws its housing (`rccar::sim::scene`: a box, three round lamps 0.3 of its height apart,
/// radius 0.12 of it, one lit or none), half as a toy's block with a single lit lamp anywhere
/// between 0.2 and 0.8 of its height; in both the housing 0.38–0.65 of its height wide and of any
/// grey (10–250: black plastic to a light wooden block), a dark cap on the top 8–15 % of half of
/// them, lamps a little larger or smaller, unlit lamps dim, the lit one bright with a whitish
/// centre; and a post of grey 40–230, 0.1–0.3 of the housing's width wide.
pub fn traffic_light_style(rng: &mut SplitMix64) -> (RgbaImage, RgbaImage, f64) {
    let u = |r: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * r.next_f64();
    let h = 100u32;
    let w = (h as f64 * u(rng, 0.38, 0.65)).round() as u32;
    let house = u(rng, 10.0, 250.0);
    let cap = if rng.next_f64() < 0.5 { u(rng, 0.08, 0.15) * h as f64 } else { 0.0 };
    let cap_grey = u(rng, 10.0, 60.0);
    let r = h as f64 * u(rng, 0.10, 0.15);
    let rgb = [[255.0, 40.0, 30.0], [255.0, 170.0, 20.0], [40.0, 255.0, 110.0]];
    // (centre's offset from the middle, colour, lit) per lamp.
    let lamps: Vec<(f64, [f64; 3], bool)> = if rng.next_f64() < 0.5 {
        let lit = (rng.next_u64() % 4) as usize; // 3: none lit
        (0..3).map(|k| ((k as f64 - 1.0) * 0.3 * h as f64, rgb[k], k == lit)).collect()
    } else {
        let k = (rng.next_u64() % 3) as usize;
        vec![((u(rng, 0.2, 0.8) - 0.5) * h as f64, rgb[k], true)]
    };
    let ss = 4;
    let t = RgbaImage::from_fn(w, h, |i, j| {
        let mut acc = [0f64; 3];
        for sj in 0..ss {
            for si in 0..ss {
                let x = i as f64 + (si as f64 + 0.5) / ss as f64 - w as f64 / 2.0;
                let y = j as f64 + (sj as f64 + 0.5) / ss as f64 - h as f64 / 2.0;
                let mut c = if y + h as f64 / 2.0 < cap { [cap_grey; 3] } else { [house; 3] };
                for &(cy, col, lit) in &lamps {
                    let dy = y - cy;
                    let r2 = (x * x + dy * dy) / (r * r);
                    if r2 <= 1.0 {
                        c = if lit {
                            let q = (1.0 - r2) * (1.0 - r2) * 0.7;
                            [0, 1, 2].map(|m| col[m] + (255.0 - col[m]) * q)
                        } else {
                            [0, 1, 2].map(|m| col[m] * 0.16 + 8.0)
                        };
                    }
                }
                for m in 0..3 {
                    acc[m] += c[m];
                }
            }
        }
        let c = |m: usize| (acc[m] / (ss * ss) as f64).round().clamp(0.0, 255.0) as u8;
        image::Rgba([c(0), c(1), c(2), 255])
    });
    let g = u(rng, 40.0, 230.0) as u8;
    let post = RgbaImage::from_pixel(4, 4, image::Rgba([g, g, g, 255]));
    (t, post, u(rng, 0.1, 0.3) * w as f64 / h as f64)
}

/// Makes a photo-like set from `photos` (at least one readable, at least 64 × 48) into `dir`.
pub fn generate(photos: &[PathBuf], template: &RgbaImage, o: &PhotoSetOptions, dir: &Path) -> Result<PhotoSet, String> {
    let io = |p: &Path, e: &dyn std::fmt::Display| format!("{}: {e}", p.display());
    let mut bgs: Vec<GrayImage> = Vec::new();
    for p in photos {
        if let Ok(g) = crate::samples::load_gray(p) {
            if g.width() >= 64 && g.height() >= 48 {
                bgs.push(g);
            }
        }
    }
    if bgs.is_empty() {
        return Err(format!(
            "no readable photo of at least 64x48 among {} files",
            photos.len()
        ));
    }
    let fdir = dir.join("frames");
    std::fs::create_dir_all(&fdir).map_err(|e| io(&fdir, &e))?;
    let (fw, fh) = FRAME;
    let mut rs = Resizer::new();
    let mut info = String::new();
    let mut bg = String::new();
    let mut csv = String::from("file,x,y,w,h\n");
    let post = RgbaImage::from_pixel(4, 4, image::Rgba([150, 150, 155, 255]));
    for n in 0..o.with_sign + o.without {
        let mut rng = SplitMix64::new(mix(o.seed.wrapping_mul(0x5851_F42D) ^ n as u64));
        let u = |r: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * r.next_f64();
        // 1. Background crop.
        let src = &bgs[(rng.next_u64() % bgs.len() as u64) as usize];
        let (pw, ph) = (src.width() as f64, src.height() as f64);
        let full = (pw / fw as f64).min(ph / fh as f64);
        let k = full * u(&mut rng, 0.4, 1.0);
        let (cw, ch) = (((fw as f64 * k) as u32).max(8), ((fh as f64 * k) as u32).max(6));
        let (cx, cy) = (
            (u(&mut rng, 0.0, 1.0) * (src.width() - cw) as f64) as u32,
            (u(&mut rng, 0.0, 1.0) * (src.height() - ch) as f64) as u32,
        );
        let crop = image::imageops::crop_imm(src, cx, cy, cw, ch).to_image();
        let mut frame = vec![0u8; (fw * fh) as usize];
        rs.resize(
            crop.as_raw(),
            cw as usize,
            ch as usize,
            &mut frame,
            fw as usize,
            fh as usize,
        );
        if rng.next_f64() < 0.5 {
            for row in frame.chunks_mut(fw as usize) {
                row.reverse();
            }
        }
        let mut canvas: Vec<f32> = frame.iter().map(|&v| v as f32).collect();
        // 2. The sign.
        let mut label = None;
        if n < o.with_sign {
            label = Some(if o.traffic_light {
                let (t, p, pw) = traffic_light_style(&mut rng);
                paste_sign(&mut canvas, &t, &p, pw, o, &mut rng)
            } else if o.printed {
                let (t, p, pw) = printed_style(template, &mut rng);
                paste_sign(&mut canvas, &t, &p, pw, o, &mut rng)
            } else {
                paste_sign(&mut canvas, template, &post, 0.06, o, &mut rng)
            });
        }
        // 3. Camera: exposure, gamma, blur, noise, JPEG.
        let gain = u(&mut rng, 0.6, 1.4);
        let gamma = u(&mut rng, 0.8, 1.25);
        for v in canvas.iter_mut() {
            *v = (255.0 * ((*v as f64 * gain / 255.0).clamp(0.0, 1.0)).powf(gamma)) as f32;
        }
        if rng.next_f64() < 0.5 {
            blur(&mut canvas, fw as usize, fh as usize, u(&mut rng, 0.3, 1.3));
        }
        let noise = u(&mut rng, 1.0, 6.0);
        let img = GrayImage::from_fn(fw, fh, |x, y| {
            let v = canvas[(y * fw + x) as usize] as f64 + noise * gauss(&mut rng);
            image::Luma([v.round().clamp(0.0, 255.0) as u8])
        });
        let q = 60 + (rng.next_u64() % 36) as u8;
        let name = format!("frames/{n:06}.jpg");
        let path = dir.join(&name);
        let f = std::fs::File::create(&path).map_err(|e| io(&path, &e))?;
        let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(std::io::BufWriter::new(f), q);
        enc.encode_image(&img).map_err(|e| io(&path, &e))?;
        match label {
            Some([x, y, w, h]) => {
                info.push_str(&format!("{name} 1 {x} {y} {w} {h}\n"));
                csv.push_str(&format!("{name},{x},{y},{w},{h}\n"));
            }
            None => {
                bg.push_str(&format!("{name}\n"));
                csv.push_str(&format!("{name}\n"));
            }
        }
    }
    let set = PhotoSet {
        info: dir.join("info.dat"),
        bg: dir.join("bg.txt"),
        csv: dir.join("boxes.csv"),
    };
    for (p, t) in [(&set.info, &info), (&set.bg, &bg), (&set.csv, &csv)] {
        let mut f = std::fs::File::create(p).map_err(|e| io(p, &e))?;
        f.write_all(t.as_bytes()).map_err(|e| io(p, &e))?;
    }
    Ok(set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photo_parts_are_disjoint_and_cover_the_halves() {
        let photos: Vec<PathBuf> = (0..23).map(|i| PathBuf::from(format!("p{i:02}.jpg"))).collect();
        let get = |n: &str| part(&photos, n).expect("known part");
        let (tr, va, te) = (get("0-train"), get("0-val"), get("1"));
        assert_eq!((tr.len(), va.len(), te.len()), (10, 2, 11));
        for p in &va {
            assert!(!tr.contains(p) && !te.contains(p), "{p:?}");
        }
        let mut h0 = [tr, va].concat();
        h0.sort();
        assert_eq!(h0, get("0"));
        assert_eq!(get("all").len(), 23);
        assert!(part(&photos, "2").is_none());
    }

    #[test]
    fn template_is_the_red_octagon_with_transparent_corners() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/tracks/default.toml");
        let t = stop_sign_template(&root, 64).expect("template");
        assert_eq!(t.get_pixel(0, 0).0[3], 0, "corner outside the octagon");
        let c = t.get_pixel(32, 12).0; // upper middle: red face
        assert_eq!(c[3], 255);
        assert!(c[0] > 2 * c[1] && c[0] > 120, "{c:?}");
        let rim = t.get_pixel(32, 1).0; // white rim
        assert!(rim[1] > 150, "{rim:?}");
    }

    #[test]
    fn printed_signs_keep_the_octagon_and_vary_the_red_and_the_frame() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/tracks/default.toml");
        let t = stop_sign_template(&root, 64).expect("template");
        let grey = |p: [u8; 4]| 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
        let (mut reds, mut edges) = (Vec::new(), Vec::new());
        for seed in 0..40 {
            let mut rng = SplitMix64::new(seed);
            let (p, post, pw) = printed_style(&t, &mut rng);
            assert!(p.pixels().zip(t.pixels()).all(|(a, b)| a.0[3] == b.0[3]), "the octagon's outline");
            assert!((0.05..=0.2).contains(&pw) && post.get_pixel(0, 0).0[3] == 255);
            reds.push(grey(p.get_pixel(32, 20).0)); // the red between rim and letters
            edges.push(grey(p.get_pixel(32, 1).0)); // the rim, or the frame around a shrunk face
        }
        let span = |v: &[f64]| v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
        assert!(span(&reds) > 60.0, "the red's grey varies: {reds:?}");
        assert!(edges.iter().all(|&e| e > 100.0), "a light frame: {edges:?}");
    }

    #[test]
    fn traffic_lights_are_opaque_upright_housings_with_a_lit_lamp_most_of_the_time() {
        let mut lit = 0;
        for seed in 0..40 {
            let mut rng = SplitMix64::new(seed);
            let (t, _, pw) = traffic_light_style(&mut rng);
            assert_eq!(t.height(), 100);
            assert!((38..=65).contains(&t.width()), "{}", t.width());
            assert!(t.pixels().all(|p| p.0[3] == 255));
            assert!(pw > 0.0 && pw < 0.3);
            // A lit lamp: a strongly coloured pixel on the housing's middle column.
            let x = t.width() / 2;
            if (0..100).any(|y| {
                let p = t.get_pixel(x, y).0;
                p.iter().max().unwrap() - p.iter().min().unwrap() > 100
            }) {
                lit += 1;
            }
        }
        assert!(lit >= 25, "{lit} of 40 lit (1 in 8 should have none)");
    }
}
