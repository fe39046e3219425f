//! Positives from a few template images, distorted and pasted over backgrounds — what
//! `opencv_createsamples -img template.png -bg bg.txt` did (cvhaartraining's
//! `icvPlaceDistortedSample`): per sample a random perspective (corners moved by up to
//! `max_skew` of the size), in-plane rotation (±`max_angle`), scale, brightness and contrast,
//! then the template is composited over a random crop of a background (its alpha channel, if
//! any, is the mask) and the crop goes through a camera: exposure gamma (`g ↦ 255·(g/255)^γ`,
//! γ log-uniform in [1/`max_gamma`, `max_gamma`]), Gaussian blur (σ ≤ `max_blur` px), noise
//! (σ ≤ `max_noise` grey levels) and, on half of the samples, JPEG at quality
//! `min_jpeg_quality`–95 (what a Pi camera frame and a phone photo go through); the crop is
//! saved with an info.dat box. OpenCV's createsamples has no gamma or JPEG; they are here
//! because the objects a car must find far away are a few pixels of a compressed frame.
//!
//! The homography maps each output pixel back into the template (inverse warping, bilinear);
//! it is solved from the four corner pairs by Gaussian elimination (8 × 8). Seeded. Units:
//! pixels, radians.

use image::{GrayImage, RgbaImage};
use rccar::sim::rng::{mix, SplitMix64};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Distortion ranges.
#[derive(Debug, Clone)]
pub struct DistortOptions {
    /// Samples to write.
    pub count: usize,
    /// Seed.
    pub seed: u64,
    /// Window size; the pasted object is at least this big.
    pub window: (u32, u32),
    /// Largest in-plane rotation, radians.
    pub max_angle: f64,
    /// Largest corner displacement, fraction of the object size (perspective).
    pub max_skew: f64,
    /// Object size as a multiple of the window: [min, max].
    pub scale: (f64, f64),
    /// Brightness offset range, grey levels (±).
    pub max_brightness: f64,
    /// Contrast factor range [min, max].
    pub contrast: (f64, f64),
    /// Largest blur sigma, pixels.
    pub max_blur: f64,
    /// Largest noise standard deviation, grey levels.
    pub max_noise: f64,
    /// Largest exposure gamma (≥ 1); γ is drawn log-uniformly in [1/max, max]. 1 = off.
    pub max_gamma: f64,
    /// Lowest JPEG quality (1–100) for the half of the samples that are JPEG-compressed; 100 = off.
    pub min_jpeg_quality: u8,
}

impl Default for DistortOptions {
    fn default() -> Self {
        DistortOptions {
            count: 1000,
            seed: 1,
            window: (24, 24),
            max_angle: 0.25,
            max_skew: 0.12,
            scale: (1.0, 3.0),
            max_brightness: 40.0,
            contrast: (0.6, 1.3),
            max_blur: 1.5,
            max_noise: 8.0,
            max_gamma: 1.35,
            min_jpeg_quality: 50,
        }
    }
}

/// Solves the 3 × 3 homography H (h33 = 1) with H·src[i] ∝ dst[i]; `None` if degenerate.
pub fn homography(src: [[f64; 2]; 4], dst: [[f64; 2]; 4]) -> Option<[f64; 9]> {
    // 1. Two equations per correspondence.
    let mut a = [[0f64; 9]; 8];
    for i in 0..4 {
        let ([x, y], [u, v]) = (src[i], dst[i]);
        a[2 * i] = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, u];
        a[2 * i + 1] = [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, v];
    }
    // 2. Gaussian elimination with partial pivoting.
    for c in 0..8 {
        let p = (c..8).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-12 {
            return None;
        }
        a.swap(c, p);
        for r in 0..8 {
            if r != c {
                let f = a[r][c] / a[c][c];
                // Row r minus f times row c, written as in the textbook (two rows of `a`).
                #[allow(clippy::needless_range_loop)]
                for k in c..9 {
                    a[r][k] -= f * a[c][k];
                }
            }
        }
    }
    let mut h = [0f64; 9];
    for i in 0..8 {
        h[i] = a[i][8] / a[i][i];
    }
    h[8] = 1.0;
    Some(h)
}

fn apply(h: &[f64; 9], x: f64, y: f64) -> Option<(f64, f64)> {
    let w = h[6] * x + h[7] * y + h[8];
    (w.abs() > 1e-12).then(|| ((h[0] * x + h[1] * y + h[2]) / w, (h[3] * x + h[4] * y + h[5]) / w))
}

/// A standard normal draw.
pub fn gauss(rng: &mut SplitMix64) -> f64 {
    // Box–Muller.
    let u1 = rng.next_f64().max(1e-12);
    let u2 = rng.next_f64();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Separable Gaussian blur of a grey `w` × `h` float image, in place (edges clamped).
pub fn blur(img: &mut [f32], w: usize, h: usize, sigma: f64) {
    let r = (3.0 * sigma).ceil().max(1.0) as isize;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let s: f32 = k.iter().sum();
    let mut tmp = vec![0f32; img.len()];
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let xx = (x as isize + j as isize - r).clamp(0, w as isize - 1) as usize;
                acc += kv * img[y * w + xx];
            }
            tmp[y * w + x] = acc / s;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let yy = (y as isize + j as isize - r).clamp(0, h as isize - 1) as usize;
                acc += kv * tmp[yy * w + x];
            }
            img[y * w + x] = acc / s;
        }
    }
}

/// Composites template `t` onto the grey `cw` × `ch` canvas with its corners (top-left,
/// top-right, bottom-right, bottom-left) at `dst` (pixels; inverse warping, bilinear, the
/// alpha channel as mask), grey = `(g − 128)·contrast + 128 + bright`. `false` when the corners
/// are degenerate.
pub fn paste(
    canvas: &mut [f32],
    cw: u32,
    ch: u32,
    t: &RgbaImage,
    dst: [[f64; 2]; 4],
    contrast: f64,
    bright: f64,
) -> bool {
    let (tw, th) = (t.width() as f64, t.height() as f64);
    let src = [[0.0, 0.0], [tw, 0.0], [tw, th], [0.0, th]];
    let Some(hinv) = homography(dst, src) else { return false };
    // Only the bounding box of the corners can change.
    let x0b = dst.iter().map(|p| p[0]).fold(f64::MAX, f64::min).floor().max(0.0) as u32;
    let y0b = dst.iter().map(|p| p[1]).fold(f64::MAX, f64::min).floor().max(0.0) as u32;
    let x1b = (dst.iter().map(|p| p[0]).fold(f64::MIN, f64::max).ceil().max(0.0) as u32).min(cw);
    let y1b = (dst.iter().map(|p| p[1]).fold(f64::MIN, f64::max).ceil().max(0.0) as u32).min(ch);
    for y in y0b..y1b {
        for x in x0b..x1b {
            let Some((sx, sy)) = apply(&hinv, x as f64 + 0.5, y as f64 + 0.5) else {
                continue;
            };
            let (fx, fy) = (sx - 0.5, sy - 0.5);
            if fx < -0.5 || fy < -0.5 || fx > tw - 0.5 || fy > th - 0.5 {
                continue;
            }
            let (x0, y0) = (fx.floor().max(0.0) as u32, fy.floor().max(0.0) as u32);
            let (x1, y1) = ((x0 + 1).min(t.width() - 1), (y0 + 1).min(t.height() - 1));
            let (ax, ay) = ((fx - x0 as f64).clamp(0.0, 1.0), (fy - y0 as f64).clamp(0.0, 1.0));
            let mut g = 0.0;
            let mut al = 0.0;
            for (px, py, wgt) in [
                (x0, y0, (1.0 - ax) * (1.0 - ay)),
                (x1, y0, ax * (1.0 - ay)),
                (x0, y1, (1.0 - ax) * ay),
                (x1, y1, ax * ay),
            ] {
                let p = t.get_pixel(px, py).0;
                let grey = (9798 * p[0] as u32 + 19235 * p[1] as u32 + 3735 * p[2] as u32 + 16384) >> 15;
                let a = p[3] as f64 / 255.0;
                g += wgt * grey as f64 * a;
                al += wgt * a;
            }
            if al <= 0.0 {
                continue;
            }
            let v = (g / al - 128.0) * contrast + 128.0 + bright;
            let i = (y * cw + x) as usize;
            canvas[i] = (canvas[i] as f64 * (1.0 - al) + v * al) as f32;
        }
    }
    true
}

/// `img` compressed as JPEG at quality `q` and decoded again (in memory).
pub fn jpeg_roundtrip(img: &GrayImage, q: u8) -> Result<GrayImage, String> {
    let mut buf = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, q)
        .encode_image(img)
        .map_err(|e| format!("jpeg: {e}"))?;
    Ok(image::load_from_memory_with_format(&buf, image::ImageFormat::Jpeg)
        .map_err(|e| format!("jpeg: {e}"))?
        .to_luma8())
}

/// Writes `o.count` distorted samples of `templates` over `backgrounds` into `dir` with an
/// `info.dat`; returns its path. Backgrounds must be at least as big as the largest object.
pub fn generate(
    templates: &[RgbaImage],
    backgrounds: &[GrayImage],
    o: &DistortOptions,
    dir: &Path,
) -> Result<PathBuf, String> {
    if templates.is_empty() || backgrounds.is_empty() {
        return Err("need at least one template and one background image".into());
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let list = dir.join("info.dat");
    let mut out =
        std::io::BufWriter::new(std::fs::File::create(&list).map_err(|e| format!("{}: {e}", list.display()))?);
    // The window the samples were made for: `rccar-train train` takes -W/-H from this line.
    writeln!(out, "# rccar-train distort window {}x{}", o.window.0, o.window.1)
        .map_err(|e| format!("{}: {e}", list.display()))?;
    let mut rng = SplitMix64::new(mix(o.seed ^ 0xD157_0127));
    let u = |rng: &mut SplitMix64, lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
    let mut n = 0;
    let mut tries = 0;
    while n < o.count {
        tries += 1;
        if tries > o.count * 20 + 100 {
            return Err(format!(
                "only {n} of {} samples fit: backgrounds too small for the object sizes asked for",
                o.count
            ));
        }
        let t = &templates[(rng.next_u64() % templates.len() as u64) as usize];
        let bg = &backgrounds[(rng.next_u64() % backgrounds.len() as u64) as usize];
        // 1. Object box (window aspect) and a crop 1.5× around it.
        let k = u(&mut rng, o.scale.0, o.scale.1);
        let (ow, oh) = ((o.window.0 as f64 * k).round(), (o.window.1 as f64 * k).round());
        let (cw, ch) = ((ow * 1.5).round() as u32, (oh * 1.5).round() as u32);
        if cw > bg.width() || ch > bg.height() {
            continue;
        }
        let cx0 = (rng.next_u64() % (bg.width() - cw + 1) as u64) as u32;
        let cy0 = (rng.next_u64() % (bg.height() - ch + 1) as u64) as u32;
        let mut crop: Vec<f32> = (0..ch)
            .flat_map(|y| (0..cw).map(move |x| (x, y)))
            .map(|(x, y)| bg.get_pixel(cx0 + x, cy0 + y)[0] as f32)
            .collect();
        let (bx, by) = (((cw as f64 - ow) / 2.0).round(), ((ch as f64 - oh) / 2.0).round());
        // 2. Destination corners: box corners rotated about the centre, each moved (skew).
        let (ccx, ccy) = (bx + ow / 2.0, by + oh / 2.0);
        let a = u(&mut rng, -o.max_angle, o.max_angle);
        let (sa, ca) = a.sin_cos();
        let mut dst = [[0f64; 2]; 4];
        for (i, (dx, dy)) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)].iter().enumerate() {
            let (px, py) = (
                dx * ow + u(&mut rng, -o.max_skew, o.max_skew) * ow,
                dy * oh + u(&mut rng, -o.max_skew, o.max_skew) * oh,
            );
            dst[i] = [ccx + ca * px - sa * py, ccy + sa * px + ca * py];
        }
        // 3. Composite (bilinear template sample, alpha mask), with brightness/contrast.
        let contrast = u(&mut rng, o.contrast.0, o.contrast.1);
        let bright = u(&mut rng, -o.max_brightness, o.max_brightness);
        if !paste(&mut crop, cw, ch, t, dst, contrast, bright) {
            continue;
        }
        // 4. Camera: gamma, blur, noise, JPEG.
        let lg = o.max_gamma.max(1.0).ln();
        let gamma = u(&mut rng, -lg, lg).exp();
        if (gamma - 1.0).abs() > 1e-3 {
            for v in crop.iter_mut() {
                *v = (255.0 * (*v as f64 / 255.0).clamp(0.0, 1.0).powf(gamma)) as f32;
            }
        }
        let sigma = u(&mut rng, 0.0, o.max_blur);
        if sigma > 0.2 {
            blur(&mut crop, cw as usize, ch as usize, sigma);
        }
        let noise = u(&mut rng, 0.0, o.max_noise);
        let mut img = GrayImage::from_fn(cw, ch, |x, y| {
            let v = crop[(y * cw + x) as usize] as f64 + noise * gauss(&mut rng);
            image::Luma([v.round().clamp(0.0, 255.0) as u8])
        });
        let jpeg = rng.next_f64() < 0.5;
        let q_lo = o.min_jpeg_quality.clamp(1, 100) as u64;
        let q = (q_lo + rng.next_u64() % (96u64.saturating_sub(q_lo)).max(1)).min(100) as u8;
        if jpeg && q_lo < 100 {
            img = jpeg_roundtrip(&img, q)?;
        }
        let name = format!("{n:06}.png");
        img.save(dir.join(&name))
            .map_err(|e| format!("{}: {e}", dir.join(&name).display()))?;
        writeln!(out, "{name} 1 {} {} {} {}", bx, by, ow, oh).map_err(|e| format!("{}: {e}", list.display()))?;
        n += 1;
    }
    out.flush().map_err(|e| format!("{}: {e}", list.display()))?;
    Ok(list)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_maps_the_corners() {
        let src = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let dst = [[1.0, 2.0], [12.0, 1.0], [11.0, 13.0], [0.0, 11.0]];
        let h = homography(src, dst).expect("solvable");
        for i in 0..4 {
            let (u, v) = apply(&h, src[i][0], src[i][1]).expect("finite");
            assert!((u - dst[i][0]).abs() < 1e-9 && (v - dst[i][1]).abs() < 1e-9);
        }
        assert!(homography(src, [[0.0, 0.0]; 4]).is_none());
    }

    #[test]
    fn samples_are_seeded_and_boxes_inside_the_crop() {
        let t = RgbaImage::from_fn(20, 20, |x, y| image::Rgba([(x * 12) as u8, (y * 12) as u8, 200, 255]));
        let bg = GrayImage::from_fn(120, 90, |x, y| image::Luma([((x * 3 + y * 5) % 256) as u8]));
        let dir = tempfile::tempdir().expect("tmp");
        let o = DistortOptions {
            count: 12,
            window: (16, 16),
            ..DistortOptions::default()
        };
        let a = generate(std::slice::from_ref(&t), std::slice::from_ref(&bg), &o, &dir.path().join("a")).expect("gen");
        let b = generate(&[t], &[bg], &o, &dir.path().join("b")).expect("gen");
        let (ta, tb) = (
            std::fs::read_to_string(&a).expect("a"),
            std::fs::read_to_string(&b).expect("b"),
        );
        assert_eq!(ta, tb);
        let pa = std::fs::read(dir.path().join("a/000005.png")).expect("png");
        let pb = std::fs::read(dir.path().join("b/000005.png")).expect("png");
        assert_eq!(pa, pb, "same seed, same pixels");
        let (lines, sk) = crate::samples::read_info(&a).expect("info");
        assert!(sk.is_empty());
        assert_eq!(lines.len(), 12);
        let (pos, sk) = crate::samples::load_positives(&[a], 16, 16).expect("load");
        assert!(sk.is_empty(), "{sk:?}");
        assert_eq!(pos.len(), 12);
    }
}
