//! Abdollahi's stop-sign detector (MSc thesis 2011, Sec. 3.1.1): colour first, shape second.
//!
//! 1. **HSV threshold** (Sec. 3.1.1.1): every pixel is converted to hue, saturation and value
//!    as OpenCV's `cvtColor(RGB2HSV)` does for 8-bit images (H in 0..180 = degrees / 2,
//!    S and V in 0..255), and kept when its hue is red (H ≤ `hue_low_max` or
//!    H ≥ `hue_high_min`), S ≥ `sat_min` and V ≥ `val_min`. Hue does not change with the
//!    light's brightness, which is why the thesis thresholds in HSV rather than RGB.
//! 2. **Candidates**: 8-connected components of the red mask; components closer than
//!    `merge_px` are merged (the white letters can cut a small sign's red in two); a
//!    candidate must be at least `min_size_px` across and roughly square (an octagon's box).
//! 3. **Template matching** (Sec. 3.1.1.2): the thesis matches each candidate with stop-sign
//!    templates of six sizes (42…102 px on its frames). Here a template is the red mask of a
//!    picture of a stop sign (red octagon around white letters) at six sizes; the candidate's
//!    red mask, resampled to the size of the nearest template, is compared with it by the
//!    mean-subtracted normalised correlation (OpenCV's `TM_CCOEFF_NORMED`) at shifts of
//!    ±`shift_px`; the best score must reach `min_score`. The letters make the difference
//!    between a sign and any other red blob (a red lamp, a red car): a filled disc scores
//!    about 0.5 against a sign's mask. (The thesis adds SIFT features in this step; rccar does
//!    not.)
//!
//! The box reported is the candidate's red component grown by `face_per_red` about its
//! centre: the sign's face with its white rim, as a cascade boxes it. Units: pixels; hue in OpenCV's 0..180.
//!
//! The template picture is the caller's ([`HsvSignDetector::new`]); the pipeline uses
//! [`octagon_model`] ([`HsvSignDetector::with_octagon_model`]): a sign drawn from the
//! proportions of the standard STOP sign (MUTCD R1-1), not from any photo or from the
//! simulator's own sign picture, so that a score on photos or renders is not a template
//! matched against itself.

use crate::detect::Rect;
use image::{GrayImage, Rgb, RgbImage};

/// Side of the [`octagon_model`] picture the templates are resampled from, pixels (more than
/// the largest template size).
pub const OCTAGON_MODEL_PX: u32 = 240;

/// Hue, saturation, value of one 8-bit RGB pixel, exactly as OpenCV's
/// `cvtColor(COLOR_RGB2HSV)` (its 12-bit fixed-point tables): V = max, S = 255·(V − min)/V,
/// H = degrees / 2 in 0..180.
pub fn rgb_to_hsv(r: u8, g: u8, b: u8) -> (u8, u8, u8) {
    const SHIFT: i32 = 12;
    let (r, g, b) = (r as i32, g as i32, b as i32);
    let v = r.max(g).max(b);
    let diff = v - r.min(g).min(b);
    let sdiv = if v == 0 {
        0
    } else {
        (((255 << SHIFT) as f64) / v as f64).round() as i32
    };
    let hdiv = if diff == 0 {
        0
    } else {
        (((180 << SHIFT) as f64) / (6.0 * diff as f64)).round() as i32
    };
    let s = (diff * sdiv + (1 << (SHIFT - 1))) >> SHIFT;
    let h = if v == r {
        g - b
    } else if v == g {
        b - r + 2 * diff
    } else {
        r - g + 4 * diff
    };
    let mut h = (h * hdiv + (1 << (SHIFT - 1))) >> SHIFT;
    if h < 0 {
        h += 180;
    }
    (h as u8, s as u8, v as u8)
}

/// Options of the HSV + template detector.
#[derive(Debug, Clone, PartialEq)]
pub struct HsvSignOptions {
    /// Red hues at the low end: H ≤ this (OpenCV's 0..180 scale).
    pub hue_low_max: u8,
    /// Red hues at the high end: H ≥ this.
    pub hue_high_min: u8,
    /// Smallest saturation of a red pixel, 0..255.
    pub sat_min: u8,
    /// Smallest value (brightness) of a red pixel, 0..255.
    pub val_min: u8,
    /// Smallest candidate width and height, pixels.
    pub min_size_px: u32,
    /// Largest ratio of a candidate's longer side to its shorter one.
    pub max_aspect: f64,
    /// Components whose boxes are within this many pixels of each other are merged.
    pub merge_px: i32,
    /// Template sides, pixels (the thesis's six sizes, scaled to the frame).
    pub template_sizes: Vec<u32>,
    /// Template shifts tried around the candidate, ± pixels (at template scale).
    pub shift_px: i32,
    /// Lowest correlation with the template that makes a candidate a stop sign (−1..1).
    pub min_score: f64,
    /// Size of the sign's face (white rim included) over that of its red part; the red
    /// box is grown by it about its centre so the box reported is the face, as a cascade
    /// boxes it (the simulator's rim is 10 % of the radius: 1/0.9; a real sign's ~1.05).
    pub face_per_red: f64,
    /// The white rim: the mean brightness (V) of the one-pixel ring just outside the red box
    /// must be at least this fraction of the red pixels' mean V (0 = no check). A red lamp
    /// on a dark housing, or a red blob on a dark background, fails it; a stop sign's white
    /// rim passes.
    pub rim_value_ratio: f64,
}

impl Default for HsvSignOptions {
    fn default() -> Self {
        Self {
            hue_low_max: 10,
            hue_high_min: 165,
            sat_min: 110,
            val_min: 50,
            min_size_px: 10,
            max_aspect: 1.5,
            merge_px: 1,
            template_sizes: vec![12, 16, 22, 30, 42, 58],
            shift_px: 1,
            min_score: 0.6,
            face_per_red: 1.0 / 0.9,
            rim_value_ratio: 0.8,
        }
    }
}

/// One accepted candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignDetection {
    /// Box in frame pixels (the red component).
    pub rect: Rect,
    /// Correlation with the best template.
    pub score: f64,
}

/// What became of a candidate ([`HsvSignDetector::candidates`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Narrower or lower than `min_size_px`.
    TooSmall,
    /// Longer side over shorter above `max_aspect`.
    NotSquare,
    /// The ring around it is darker than `rim_value_ratio` × its red (no white rim).
    DarkRim,
    /// Its correlation with the template is below `min_score`.
    LowScore,
    /// A stop sign.
    Sign,
}

/// One red component and what became of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// The red component's box, frame pixels.
    pub red: Rect,
    /// The face's box it would report (`red` grown by `face_per_red`).
    pub face: Rect,
    /// Kept or why not.
    pub verdict: Verdict,
    /// Its template correlation (NaN when rejected before the template step).
    pub score: f64,
}

/// A template: a sign's red mask at one size, mean-subtracted, with its norm.
#[derive(Debug, Clone)]
struct Template {
    size: u32,
    /// Zero-mean values, row-major size × size.
    t: Vec<f32>,
    norm: f32,
}

/// The detector: its templates and scratch buffers.
#[derive(Debug, Clone)]
pub struct HsvSignDetector {
    opts: HsvSignOptions,
    templates: Vec<Template>,
    mask: Vec<u8>,
    labels: Vec<u32>,
    stack: Vec<u32>,
    patch: Vec<f32>,
}

/// Why templates could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TemplateError {
    /// The picture holds no red pixel at the thresholds.
    #[error("the template picture has no red pixels at the HSV thresholds")]
    NoRed,
    /// No template size given, or one is below 4 px.
    #[error("template sizes must be ≥ 4 px and at least one is needed, got {0:?}")]
    BadSizes(Vec<u32>),
}

/// The red mask of `img` as 0/1 bytes, row-major.
fn red_mask(img: &RgbImage, o: &HsvSignOptions, out: &mut Vec<u8>) {
    out.clear();
    out.extend(img.pixels().map(|p| is_red(p.0, o) as u8));
}

#[inline]
fn is_red(p: [u8; 3], o: &HsvSignOptions) -> bool {
    // Cheap rejections before the hue: red is the largest channel of a red pixel.
    let (r, g, b) = (p[0], p[1], p[2]);
    if r < o.val_min || r < g || r < b {
        // V = max; with R not the max, H is 60..300 degrees: never red at these thresholds
        // unless the thresholds reach that far, so fall back to the full test.
        if o.hue_low_max < 30 && o.hue_high_min > 150 {
            return false;
        }
    }
    let (h, s, v) = rgb_to_hsv(r, g, b);
    s >= o.sat_min && v >= o.val_min && (h <= o.hue_low_max || h >= o.hue_high_min)
}

/// Area-average resampling of a w×h float map to n×n (each output pixel the mean of the
/// input it covers).
fn resample(src: &[f32], w: usize, h: usize, n: usize, out: &mut Vec<f32>) {
    out.clear();
    out.resize(n * n, 0.0);
    let (sx, sy) = (w as f64 / n as f64, h as f64 / n as f64);
    for oy in 0..n {
        let (y0, y1) = (oy as f64 * sy, (oy + 1) as f64 * sy);
        for ox in 0..n {
            let (x0, x1) = (ox as f64 * sx, (ox + 1) as f64 * sx);
            let mut acc = 0.0;
            let mut y = y0.floor() as usize;
            while (y as f64) < y1 && y < h {
                let wy = ((y + 1) as f64).min(y1) - (y as f64).max(y0);
                let mut x = x0.floor() as usize;
                while (x as f64) < x1 && x < w {
                    let wx = ((x + 1) as f64).min(x1) - (x as f64).max(x0);
                    acc += wx * wy * src[y * w + x] as f64;
                    x += 1;
                }
                y += 1;
            }
            out[oy * n + ox] = (acc / (sx * sy)) as f32;
        }
    }
}

impl HsvSignDetector {
    /// A detector whose templates are the red mask of `picture`, a frontal photo (or
    /// rendering) of a stop sign cropped to the red face, resampled to every template size.
    pub fn new(opts: HsvSignOptions, picture: &RgbImage) -> Result<Self, TemplateError> {
        if opts.template_sizes.is_empty() || opts.template_sizes.iter().any(|&s| s < 4) {
            return Err(TemplateError::BadSizes(opts.template_sizes.clone()));
        }
        let mut m = vec![];
        red_mask(picture, &opts, &mut m);
        // Crop to the red pixels' box.
        let (w, h) = (picture.width() as usize, picture.height() as usize);
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if m[y * w + x] != 0 {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x);
                    y1 = y1.max(y);
                }
            }
        }
        if x0 == usize::MAX {
            return Err(TemplateError::NoRed);
        }
        let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
        let crop: Vec<f32> = (y0..=y1)
            .flat_map(|y| (x0..=x1).map(move |x| (y, x)))
            .map(|(y, x)| m[y * w + x] as f32)
            .collect();
        let mut templates = vec![];
        let mut buf = vec![];
        for &n in &opts.template_sizes {
            resample(&crop, cw, ch, n as usize, &mut buf);
            let (t, norm) = zero_mean(&buf);
            templates.push(Template { size: n, t, norm });
        }
        Ok(Self {
            opts,
            templates,
            mask: vec![],
            labels: vec![],
            stack: vec![],
            patch: vec![],
        })
    }

    /// A detector whose templates are made from [`octagon_model`] (geometry, no picture).
    pub fn with_octagon_model(opts: HsvSignOptions) -> Result<Self, TemplateError> {
        Self::new(opts, &octagon_model(OCTAGON_MODEL_PX))
    }

    /// The options.
    pub fn options(&self) -> &HsvSignOptions {
        &self.opts
    }

    /// Stop signs in `img`.
    pub fn detect(&mut self, img: &RgbImage) -> Vec<SignDetection> {
        self.candidates(img)
            .into_iter()
            .filter(|c| c.verdict == Verdict::Sign)
            .map(|c| SignDetection {
                rect: c.face,
                score: c.score,
            })
            .collect()
    }

    /// Every candidate of `img` (red component after merging) with the step that kept or
    /// rejected it: what [`HsvSignDetector::detect`] decides, for finding out why a sign was
    /// missed or a red object taken for one.
    pub fn candidates(&mut self, img: &RgbImage) -> Vec<Candidate> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        // 1. HSV threshold.
        let mut mask = std::mem::take(&mut self.mask);
        red_mask(img, &self.opts, &mut mask);
        // 2. Connected components (8-connected), then merge near boxes.
        let mut boxes = self.components(&mask, w, h);
        merge_boxes(&mut boxes, self.opts.merge_px);
        // 3. Shape: template matching of each plausible candidate.
        let mut out = vec![];
        for b in boxes {
            let (bw, bh) = (b[2] - b[0] + 1, b[3] - b[1] + 1);
            let (lo, hi) = (bw.min(bh) as f64, bw.max(bh) as f64);
            // Grow the red box to the face about its centre (edges at ±0.5 px).
            let k = self.opts.face_per_red;
            let (cx, cy) = ((b[0] + b[2]) as f64 / 2.0, (b[1] + b[3]) as f64 / 2.0);
            let (fw, fh) = ((bw as f64 * k).round() as i32, (bh as f64 * k).round() as i32);
            let face = Rect {
                x: (cx - (fw as f64 - 1.0) / 2.0).round() as i32,
                y: (cy - (fh as f64 - 1.0) / 2.0).round() as i32,
                width: fw,
                height: fh,
            };
            let red = Rect::new(b[0], b[1], bw, bh);
            let (verdict, score) = if (lo as u32) < self.opts.min_size_px {
                (Verdict::TooSmall, f64::NAN)
            } else if hi / lo > self.opts.max_aspect {
                (Verdict::NotSquare, f64::NAN)
            } else if self.opts.rim_value_ratio > 0.0 && !rim_is_bright(img, &mask, b, self.opts.rim_value_ratio) {
                (Verdict::DarkRim, f64::NAN)
            } else {
                let score = self.score(&mask, w, b);
                if score >= self.opts.min_score {
                    (Verdict::Sign, score)
                } else {
                    (Verdict::LowScore, score)
                }
            };
            out.push(Candidate {
                red,
                face,
                verdict,
                score,
            });
        }
        self.mask = mask;
        out
    }

    /// Boxes [x0, y0, x1, y1] (inclusive) of the mask's 8-connected components.
    fn components(&mut self, mask: &[u8], w: usize, h: usize) -> Vec<[i32; 4]> {
        self.labels.clear();
        self.labels.resize(w * h, 0);
        let mut boxes = vec![];
        for start in 0..w * h {
            if mask[start] == 0 || self.labels[start] != 0 {
                continue;
            }
            let id = boxes.len() as u32 + 1;
            let (sx, sy) = ((start % w) as i32, (start / w) as i32);
            let mut bb = [sx, sy, sx, sy];
            self.labels[start] = id;
            self.stack.clear();
            self.stack.push(start as u32);
            while let Some(p) = self.stack.pop() {
                let (x, y) = ((p as usize % w) as i32, (p as usize / w) as i32);
                bb = [bb[0].min(x), bb[1].min(y), bb[2].max(x), bb[3].max(y)];
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                            continue;
                        }
                        let q = ny as usize * w + nx as usize;
                        if mask[q] != 0 && self.labels[q] == 0 {
                            self.labels[q] = id;
                            self.stack.push(q as u32);
                        }
                    }
                }
            }
            boxes.push(bb);
        }
        boxes
    }

    /// Best correlation of the candidate box `b` (inclusive corners) with the template of the
    /// nearest size, over shifts of ±shift_px at template scale.
    fn score(&mut self, mask: &[u8], w: usize, b: [i32; 4]) -> f64 {
        let (bw, bh) = ((b[2] - b[0] + 1) as usize, (b[3] - b[1] + 1) as usize);
        let side = ((bw * bh) as f64).sqrt();
        let t = self
            .templates
            .iter()
            .min_by(|a, c| ((a.size as f64 / side).ln().abs()).total_cmp(&(c.size as f64 / side).ln().abs()))
            .expect("at least one template");
        let n = t.size as usize;
        let s = self.opts.shift_px.max(0) as usize;
        // The candidate plus a margin of s template pixels each side, resampled so that the
        // candidate box maps onto n × n.
        let (px, py) = (bw as f64 / n as f64, bh as f64 / n as f64);
        let m = n + 2 * s;
        let src: Vec<f32> = (0..m * m).map(|_| 0.0).collect();
        let mut src = src;
        // Sample the mask (nearest-area) at template resolution with the margin.
        for oy in 0..m {
            for ox in 0..m {
                let fx0 = b[0] as f64 + (ox as f64 - s as f64) * px;
                let fy0 = b[1] as f64 + (oy as f64 - s as f64) * py;
                let mut acc = 0.0;
                let mut cnt = 0.0;
                // 2×2 sub-samples per output pixel (enough for a mask).
                for (ax, ay) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                    let x = (fx0 + ax * px).floor() as i64;
                    let y = (fy0 + ay * py).floor() as i64;
                    if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < mask.len() / w {
                        acc += mask[y as usize * w + x as usize] as f32;
                    }
                    cnt += 1.0;
                }
                src[oy * m + ox] = acc / cnt;
            }
        }
        let mut best = f64::NEG_INFINITY;
        for dy in 0..=2 * s {
            for dx in 0..=2 * s {
                self.patch.clear();
                for y in 0..n {
                    self.patch
                        .extend_from_slice(&src[(dy + y) * m + dx..(dy + y) * m + dx + n]);
                }
                let (p, pn) = zero_mean(&self.patch);
                if pn <= 1e-6 || t.norm <= 1e-6 {
                    continue;
                }
                let dot: f32 = p.iter().zip(&t.t).map(|(a, b)| a * b).sum();
                best = best.max((dot / (pn * t.norm)) as f64);
            }
        }
        best
    }
}

/// Whether the mean V of the one-pixel ring around box `b` (inclusive corners; pixels
/// outside the image are left out) reaches `ratio` × the mean V of the red pixels inside.
fn rim_is_bright(img: &RgbImage, mask: &[u8], b: [i32; 4], ratio: f64) -> bool {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let val = |x: i32, y: i32| {
        let p = img.get_pixel(x as u32, y as u32).0;
        p[0].max(p[1]).max(p[2]) as f64
    };
    let (mut red, mut nred) = (0.0, 0.0);
    for y in b[1]..=b[3] {
        for x in b[0]..=b[2] {
            if mask[(y * w + x) as usize] != 0 {
                red += val(x, y);
                nred += 1.0;
            }
        }
    }
    let (mut ring, mut nring) = (0.0, 0.0);
    for y in b[1] - 1..=b[3] + 1 {
        for x in b[0] - 1..=b[2] + 1 {
            let on_ring = y == b[1] - 1 || y == b[3] + 1 || x == b[0] - 1 || x == b[2] + 1;
            if on_ring && x >= 0 && y >= 0 && x < w && y < h {
                ring += val(x, y);
                nring += 1.0;
            }
        }
    }
    nred > 0.0 && nring > 0.0 && ring / nring >= ratio * red / nred
}

/// `v − mean(v)` and its Euclidean norm.
fn zero_mean(v: &[f32]) -> (Vec<f32>, f32) {
    let mean = v.iter().sum::<f32>() / v.len().max(1) as f32;
    let z: Vec<f32> = v.iter().map(|x| x - mean).collect();
    let n = z.iter().map(|x| x * x).sum::<f32>().sqrt();
    (z, n)
}

/// Merges boxes (inclusive corners) that come within `gap` pixels of each other, until none do.
fn merge_boxes(boxes: &mut Vec<[i32; 4]>, gap: i32) {
    loop {
        let mut merged = false;
        'outer: for i in 0..boxes.len() {
            for j in i + 1..boxes.len() {
                let (a, b) = (boxes[i], boxes[j]);
                if a[0] <= b[2] + gap && b[0] <= a[2] + gap && a[1] <= b[3] + gap && b[1] <= a[3] + gap {
                    boxes[i] = [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])];
                    boxes.swap_remove(j);
                    merged = true;
                    break 'outer;
                }
            }
        }
        if !merged {
            return;
        }
    }
}

/// A picture of a stop sign made from geometry alone, `n` × `n` pixels: a regular octagon
/// (flats horizontal and vertical) with a white rim 2.5 % of its width (MUTCD R1-1: a ¾-inch
/// border on a 30-inch sign), red inside, and the word STOP in white block letters: cap height
/// ⅓ of the width (10 inches on 30), the word 0.7 of the width, strokes ⅙ of the cap height
/// (about Series C's). Outside the octagon: mid grey. The letters are drawn from rectangles
/// (no font), which is all a template of the red mask needs: the white band across the middle
/// is what tells a sign from a red disc.
pub fn octagon_model(n: u32) -> RgbImage {
    const RED: Rgb<u8> = Rgb([200, 20, 30]);
    const WHITE: Rgb<u8> = Rgb([240, 240, 240]);
    let mut img = RgbImage::from_pixel(n, n, Rgb([128, 128, 128]));
    let s = n as f64;
    let c = s / 2.0;
    // 1. The octagon and its rim: a pixel centre is inside when its distance from the centre
    //    along the flats and along the diagonals is within the apothem.
    let apothem = s / 2.0;
    let rim = 0.025 * s;
    for y in 0..n {
        for x in 0..n {
            let (dx, dy) = ((x as f64 + 0.5 - c).abs(), (y as f64 + 0.5 - c).abs());
            let d = dx.max(dy).max((dx + dy) / std::f64::consts::SQRT_2);
            if d < apothem - rim {
                img.put_pixel(x, y, RED);
            } else if d < apothem {
                img.put_pixel(x, y, WHITE);
            }
        }
    }
    // 2. The letters: four cells across 0.7 of the width, each 0.16 wide with 0.02 gaps.
    let cap = s / 3.0;
    let stroke = cap / 6.0;
    let (lw, gap) = (0.16 * s, 0.02 * s);
    let x0 = c - (4.0 * lw + 3.0 * gap) / 2.0;
    let top = c - cap / 2.0;
    let mid = c - stroke / 2.0;
    let bottom = c + cap / 2.0 - stroke;
    let mut fill = |x: f64, y: f64, w: f64, h: f64| {
        let (xa, ya) = (x.round().max(0.0) as u32, y.round().max(0.0) as u32);
        let (xb, yb) = (((x + w).round() as u32).min(n), ((y + h).round() as u32).min(n));
        for yy in ya..yb {
            for xx in xa..xb {
                img.put_pixel(xx, yy, WHITE);
            }
        }
    };
    for (i, letter) in ['S', 'T', 'O', 'P'].into_iter().enumerate() {
        let l = x0 + i as f64 * (lw + gap);
        let r = l + lw - stroke;
        match letter {
            'S' => {
                fill(l, top, lw, stroke);
                fill(l, mid, lw, stroke);
                fill(l, bottom, lw, stroke);
                fill(l, top, stroke, mid - top);
                fill(r, mid, stroke, bottom - mid);
            }
            'T' => {
                fill(l, top, lw, stroke);
                fill(l + (lw - stroke) / 2.0, top, stroke, cap);
            }
            'O' => {
                fill(l, top, lw, stroke);
                fill(l, bottom, lw, stroke);
                fill(l, top, stroke, cap);
                fill(r, top, stroke, cap);
            }
            _ => {
                fill(l, top, stroke, cap);
                fill(l, top, lw, stroke);
                fill(l, mid, lw, stroke);
                fill(r, top, stroke, mid - top);
            }
        }
    }
    img
}

/// The red mask of `img` as a grey image (255 = red), for plots and debugging.
pub fn red_mask_image(img: &RgbImage, opts: &HsvSignOptions) -> GrayImage {
    let mut m = vec![];
    red_mask(img, opts, &mut m);
    GrayImage::from_raw(img.width(), img.height(), m.into_iter().map(|v| v * 255).collect())
        .expect("mask has the image's size")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hsv_matches_opencv_on_hand_values() {
        // Values from cv2.cvtColor(np.uint8([[[r, g, b]]]), cv2.COLOR_RGB2HSV).
        assert_eq!(rgb_to_hsv(255, 0, 0), (0, 255, 255));
        assert_eq!(rgb_to_hsv(0, 255, 0), (60, 255, 255));
        assert_eq!(rgb_to_hsv(0, 0, 255), (120, 255, 255));
        assert_eq!(rgb_to_hsv(196, 22, 28), (179, 226, 196));
        assert_eq!(rgb_to_hsv(200, 20, 30), (178, 229, 200));
        assert_eq!(rgb_to_hsv(90, 200, 30), (49, 217, 200));
        assert_eq!(rgb_to_hsv(17, 3, 250), (122, 252, 250));
        assert_eq!(rgb_to_hsv(128, 128, 128), (0, 0, 128));
        assert_eq!(rgb_to_hsv(0, 0, 0), (0, 0, 0));
        // 80 random colours (numpy seed 1) through cv2 4.x.
        let cv: [(u8, u8, u8, u8, u8, u8); 80] = [
            (255, 228, 34, 26, 221, 255),
            (21, 52, 236, 116, 232, 236),
            (62, 160, 81, 66, 156, 160),
            (81, 56, 173, 126, 172, 173),
            (92, 158, 16, 44, 229, 158),
            (125, 1, 235, 136, 254, 235),
            (156, 98, 255, 131, 157, 255),
            (61, 235, 180, 80, 189, 235),
            (139, 101, 126, 160, 70, 139),
            (130, 51, 207, 135, 192, 207),
            (108, 13, 28, 175, 224, 108),
            (200, 22, 250, 143, 233, 250),
            (54, 134, 139, 92, 156, 139),
            (122, 153, 72, 41, 135, 153),
            (21, 135, 16, 59, 225, 135),
            (12, 245, 119, 74, 242, 245),
            (80, 212, 23, 51, 227, 212),
            (183, 16, 182, 150, 233, 183),
            (108, 238, 118, 62, 139, 238),
            (32, 185, 21, 58, 226, 185),
            (161, 158, 234, 121, 83, 234),
            (200, 252, 220, 72, 53, 252),
            (117, 151, 32, 39, 201, 151),
            (199, 248, 173, 50, 77, 248),
            (236, 6, 0, 1, 255, 236),
            (156, 181, 41, 35, 197, 181),
            (196, 10, 61, 172, 242, 196),
            (48, 238, 51, 60, 204, 238),
            (125, 102, 211, 126, 132, 211),
            (245, 172, 229, 157, 76, 245),
            (146, 234, 4, 41, 251, 234),
            (68, 143, 211, 104, 173, 211),
            (254, 49, 29, 3, 226, 254),
            (57, 26, 239, 124, 227, 239),
            (192, 188, 74, 29, 157, 192),
            (47, 6, 73, 138, 234, 73),
            (2, 218, 115, 76, 253, 218),
            (21, 221, 121, 75, 231, 221),
            (247, 205, 9, 25, 246, 247),
            (96, 167, 11, 44, 238, 167),
            (34, 184, 244, 99, 219, 244),
            (153, 37, 172, 146, 200, 172),
            (104, 112, 74, 36, 87, 112),
            (149, 28, 10, 4, 238, 149),
            (38, 7, 236, 124, 247, 236),
            (163, 64, 13, 10, 235, 163),
            (217, 133, 86, 11, 154, 217),
            (169, 30, 140, 156, 210, 169),
            (148, 115, 157, 144, 68, 157),
            (87, 201, 189, 87, 145, 201),
            (160, 71, 36, 8, 198, 160),
            (117, 232, 34, 47, 218, 232),
            (206, 120, 102, 5, 129, 206),
            (63, 57, 46, 19, 69, 63),
            (216, 158, 195, 161, 68, 216),
            (93, 205, 44, 51, 200, 205),
            (118, 106, 14, 27, 225, 118),
            (220, 11, 20, 179, 242, 220),
            (146, 163, 178, 104, 46, 178),
            (82, 209, 38, 52, 209, 209),
            (253, 41, 149, 165, 214, 253),
            (201, 148, 145, 2, 71, 201),
            (194, 131, 254, 135, 123, 254),
            (208, 106, 155, 166, 125, 208),
            (167, 158, 86, 27, 124, 167),
            (17, 4, 129, 123, 247, 129),
            (139, 2, 194, 141, 252, 194),
            (129, 134, 72, 32, 118, 134),
            (240, 111, 156, 170, 137, 240),
            (140, 254, 254, 90, 114, 254),
            (208, 22, 144, 160, 228, 208),
            (203, 113, 224, 144, 126, 224),
            (72, 145, 13, 47, 232, 145),
            (232, 248, 107, 33, 145, 248),
            (180, 56, 133, 161, 176, 180),
            (94, 245, 99, 61, 157, 245),
            (242, 17, 135, 164, 237, 242),
            (198, 121, 41, 15, 202, 198),
            (180, 167, 122, 23, 82, 180),
            (129, 187, 124, 58, 86, 187),
        ];
        for (r, g, b, h, s, v) in cv {
            assert_eq!(rgb_to_hsv(r, g, b), (h, s, v), "rgb {r} {g} {b}");
        }
    }

    /// A red octagon in a white rim with white bars across the middle (a crude sign), `n` px
    /// across.
    fn sign(n: u32, letters: bool) -> RgbImage {
        let mut img = RgbImage::from_pixel(n, n, Rgb([120, 120, 120]));
        let c = (n as f64 - 1.0) / 2.0;
        let r = n as f64 / 2.0;
        for y in 0..n {
            for x in 0..n {
                let (dx, dy) = ((x as f64 - c).abs(), (y as f64 - c).abs());
                let oct = dx.max(dy).max((dx + dy) / std::f64::consts::SQRT_2);
                if oct < r && oct >= 0.88 * r {
                    img.put_pixel(x, y, Rgb([240, 240, 240]));
                } else if oct < r {
                    let bar = letters && dy < 0.17 * r && (x as f64 - c).rem_euclid(r / 2.0) < r / 3.5;
                    img.put_pixel(x, y, if bar { Rgb([240, 240, 240]) } else { Rgb([200, 20, 30]) });
                }
            }
        }
        img
    }

    #[test]
    fn finds_a_sign_and_rejects_a_plain_disc() {
        let tpl = sign(80, true);
        let o = HsvSignOptions {
            face_per_red: 1.0,
            rim_value_ratio: 0.0,
            min_score: 0.8,
            ..HsvSignOptions::default()
        };
        let mut det = HsvSignDetector::new(o, &tpl).unwrap();
        let mut img = RgbImage::from_pixel(160, 120, Rgb([100, 100, 100]));
        image::imageops::overlay(&mut img, &sign(30, true), 20, 30);
        // A red disc of the same size.
        for y in 0..30i32 {
            for x in 0..30i32 {
                if (x - 15).pow(2) + (y - 15).pow(2) < 15 * 15 {
                    img.put_pixel(100 + x as u32, 40 + y as u32, Rgb([200, 20, 30]));
                }
            }
        }
        let found = det.detect(&img);
        assert_eq!(found.len(), 1, "{found:?}");
        let r = found[0].rect;
        // The red part of the 30 px sign: 0.88 of it, centred.
        assert!(
            (r.x - 22).abs() <= 1 && (r.y - 32).abs() <= 1 && (r.width - 26).abs() <= 2,
            "{r:?}"
        );
        // The rim check alone rejects the disc (dark grey around it), keeps the sign.
        let o = HsvSignOptions {
            min_score: 0.0,
            ..HsvSignOptions::default()
        };
        let mut det = HsvSignDetector::new(o, &tpl).unwrap();
        let found = det.detect(&img);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(found[0].rect.x < 60);
    }

    #[test]
    fn template_errors() {
        let grey = RgbImage::from_pixel(10, 10, Rgb([90, 90, 90]));
        assert_eq!(
            HsvSignDetector::new(HsvSignOptions::default(), &grey).unwrap_err(),
            TemplateError::NoRed
        );
        let o = HsvSignOptions {
            template_sizes: vec![],
            ..HsvSignOptions::default()
        };
        assert!(matches!(
            HsvSignDetector::new(o, &sign(20, true)),
            Err(TemplateError::BadSizes(_))
        ));
    }

    /// The geometric model's templates find a sign drawn from the model at another size, and
    /// `candidates` says what became of every red blob: a disc on a dark ground fails the rim
    /// check, a bar is not square, a speck too small. Without the rim check the template alone
    /// scores the disc close to a sign (a red mask's correlation is mostly its outline): the
    /// real-photo options (`[colour_template]`, no rim check) take a sign-sized red disc for a
    /// sign (docs/detect.md).
    #[test]
    fn the_octagon_model_finds_its_sign_and_candidates_explain_the_rest() {
        let model = octagon_model(OCTAGON_MODEL_PX);
        // Red inside, white rim and letters, grey outside; the word crosses the middle.
        assert_eq!(model.get_pixel(OCTAGON_MODEL_PX / 2, 30).0, [200, 20, 30]);
        assert_eq!(model.get_pixel(0, 0).0, [128, 128, 128]);
        let row = OCTAGON_MODEL_PX / 2 - 30;
        let white = (0..OCTAGON_MODEL_PX)
            .filter(|&x| model.get_pixel(x, row).0 == [240, 240, 240])
            .count();
        assert!(white > 40, "letters across the middle: {white}");
        let mut det = HsvSignDetector::with_octagon_model(HsvSignOptions::default()).unwrap();
        let mut img = RgbImage::from_pixel(160, 120, Rgb([60, 60, 60]));
        image::imageops::overlay(&mut img, &octagon_model(30), 20, 30);
        let red = Rgb([200, 20, 30]);
        for y in 0..30i32 {
            for x in 0..30i32 {
                if (x - 15).pow(2) + (y - 15).pow(2) < 15 * 15 {
                    img.put_pixel(100 + x as u32, 40 + y as u32, red);
                }
            }
        }
        for (x, y, w, h) in [(60, 95, 40, 12), (140, 10, 4, 4)] {
            for yy in y..y + h {
                for xx in x..x + w {
                    img.put_pixel(xx, yy, red);
                }
            }
        }
        let c = det.candidates(&img);
        let at = |x: i32| {
            c.iter()
                .find(|c| (c.red.x - x).abs() <= 3)
                .unwrap_or_else(|| panic!("{c:?}"))
        };
        assert_eq!(c.len(), 4, "{c:?}");
        assert_eq!(at(20).verdict, Verdict::Sign, "{c:?}");
        assert!(at(20).score > 0.85, "{c:?}");
        assert_eq!(at(100).verdict, Verdict::DarkRim);
        assert_eq!(at(60).verdict, Verdict::NotSquare);
        assert_eq!(at(140).verdict, Verdict::TooSmall);
        assert!(at(100).score.is_nan());
        let found = det.detect(&img);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].rect, at(20).face);
        // No rim check: the disc reaches the template, and scores below the sign but well above
        // the real-photo threshold of 0.4.
        let mut det = HsvSignDetector::with_octagon_model(HsvSignOptions {
            rim_value_ratio: 0.0,
            ..HsvSignOptions::default()
        })
        .unwrap();
        let c = det.candidates(&img);
        let disc = c.iter().find(|c| c.red.x >= 100 && c.red.x < 110).unwrap();
        let sign = c.iter().find(|c| c.red.x < 30).unwrap();
        assert!(disc.score > 0.4 && disc.score < sign.score, "{c:?}");
    }
}
