//! Traffic-light state inside a detected box, the seed paper's method (Rivera & Andaluz 2021,
//! Sec. 3.2 iv: "the brightest point of the light after a Gaussian blur gives its colour by
//! its position"), with a hue check added.
//!
//! 1. Crop the box (clipped to the image) and convert it to grey (OpenCV's integer BT.601).
//! 2. Gaussian blur (separable, σ = box width / 8, at least 1 px) so that one hot pixel or
//!    a specular glint does not win over a lit lamp.
//! 3. The brightest blurred pixel is the lit lamp. Its row gives the state: upper third →
//!    red, middle third → amber, lower third → green (a vertical light, red on top).
//! 4. The hue of the original pixels around that spot (mean RGB in a 3×3 patch) must agree:
//!    red ≤ 20° or ≥ 330°, amber 20°–70°, green 80°–200°. Agreement keeps the confidence;
//!    a saturated hue that names another lamp lowers it to a third; a grey (unsaturated)
//!    spot to two thirds.
//! 5. Confidence = hue factor × contrast, where contrast = (peak − mean of the blurred box)
//!    / 128, clipped to [0, 1]: a dark box or a box with no lit lamp reads as unsure.
//!
//! Units: pixels; hue in degrees [0, 360); confidence in [0, 1].

use super::group::Rect;
use image::RgbImage;

/// Which lamp is lit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightState {
    /// Top lamp.
    Red,
    /// Middle lamp.
    Amber,
    /// Bottom lamp.
    Green,
    /// The box is empty, outside the image or too small to read.
    Unknown,
}

/// The state of a traffic light and how sure we are.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LightReading {
    /// Lamp judged lit (by its position).
    pub state: LightState,
    /// 0 (guess) … 1 (bright, saturated lamp whose hue agrees with its position).
    pub confidence: f32,
    /// Brightest spot in image pixels.
    pub spot: (u32, u32),
    /// Hue at the spot in degrees, `None` when the spot is grey (saturation < 0.25).
    pub hue: Option<f32>,
}

impl LightReading {
    const UNKNOWN: LightReading = LightReading {
        state: LightState::Unknown,
        confidence: 0.0,
        spot: (0, 0),
        hue: None,
    };
}

/// Reads the state of the traffic light inside `rect` of an RGB frame.
pub fn light_state(img: &RgbImage, rect: Rect) -> LightReading {
    // 1. Crop and grey.
    let frame = Rect::new(0, 0, img.width() as i32, img.height() as i32);
    let r = rect.intersect(&frame);
    if r.width < 3 || r.height < 3 {
        return LightReading::UNKNOWN;
    }
    let (w, h) = (r.width as usize, r.height as usize);
    let mut grey = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let p = img.get_pixel((r.x as usize + x) as u32, (r.y as usize + y) as u32).0;
            let v = (9798 * p[0] as u32 + 19235 * p[1] as u32 + 3735 * p[2] as u32 + 16384) >> 15;
            grey[y * w + x] = v as f32;
        }
    }
    // 2. Blur.
    let sigma = (w as f32 / 8.0).max(1.0);
    let blurred = gaussian(&grey, w, h, sigma);
    // 3. Brightest spot (first maximum in raster order) and its third.
    let (mut best, mut bi) = (f32::MIN, 0);
    for (i, &v) in blurred.iter().enumerate() {
        if v > best {
            best = v;
            bi = i;
        }
    }
    let (sx, sy) = (bi % w, bi / w);
    let state = match sy * 3 / h {
        0 => LightState::Red,
        1 => LightState::Amber,
        _ => LightState::Green,
    };
    // 4. Hue around the spot.
    let mut acc = [0f32; 3];
    let mut n = 0.0;
    for y in sy.saturating_sub(1)..(sy + 2).min(h) {
        for x in sx.saturating_sub(1)..(sx + 2).min(w) {
            let p = img.get_pixel((r.x as usize + x) as u32, (r.y as usize + y) as u32).0;
            for k in 0..3 {
                acc[k] += p[k] as f32;
            }
            n += 1.0;
        }
    }
    let hue = hue_of(acc[0] / n, acc[1] / n, acc[2] / n);
    let hue_factor = match hue {
        None => 2.0 / 3.0,
        Some(hd) if hue_state(hd) == Some(state) => 1.0,
        Some(_) => 1.0 / 3.0,
    };
    // 5. Contrast.
    let mean = blurred.iter().sum::<f32>() / blurred.len() as f32;
    let contrast = ((best - mean) / 128.0).clamp(0.0, 1.0);
    LightReading {
        state,
        confidence: hue_factor * contrast,
        spot: ((r.x as usize + sx) as u32, (r.y as usize + sy) as u32),
        hue,
    }
}

/// The lamp a hue belongs to, if any.
fn hue_state(h: f32) -> Option<LightState> {
    if !(20.0..330.0).contains(&h) {
        Some(LightState::Red)
    } else if h < 70.0 {
        Some(LightState::Amber)
    } else if (80.0..=200.0).contains(&h) {
        Some(LightState::Green)
    } else {
        None
    }
}

/// HSV hue in degrees, `None` if the colour is nearly grey.
fn hue_of(r: f32, g: f32, b: f32) -> Option<f32> {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    if max <= 0.0 || (max - min) / max < 0.25 {
        return None;
    }
    let d = max - min;
    let h = if max == r {
        60.0 * ((g - b) / d)
    } else if max == g {
        60.0 * ((b - r) / d) + 120.0
    } else {
        60.0 * ((r - g) / d) + 240.0
    };
    Some(if h < 0.0 { h + 360.0 } else { h })
}

/// Separable Gaussian blur with replicated borders.
fn gaussian(src: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f32 = kernel.iter().sum();
    let clamp = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let mut tmp = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (k, &c) in kernel.iter().enumerate() {
                s += c * src[y * w + clamp(x as isize + k as isize - radius, w)];
            }
            tmp[y * w + x] = s / norm;
        }
    }
    let mut out = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (k, &c) in kernel.iter().enumerate() {
                s += c * tmp[clamp(y as isize + k as isize - radius, h) * w + x];
            }
            out[y * w + x] = s / norm;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    /// A 30×90 dark housing with one lit lamp (a disc of radius 10) in third `lamp`.
    fn light(lamp: usize, colour: [u8; 3]) -> RgbImage {
        let mut img = RgbImage::from_pixel(50, 110, Rgb([20, 20, 20]));
        let cy = 10 + 15 + lamp as i32 * 30;
        for y in 0..110 {
            for x in 0..50 {
                if (x - 25) * (x - 25) + (y - cy) * (y - cy) <= 100 {
                    img.put_pixel(x as u32, y as u32, Rgb(colour));
                }
            }
        }
        img
    }

    #[test]
    fn each_lamp_is_read_with_high_confidence() {
        let rect = Rect::new(10, 10, 30, 90);
        for (lamp, colour, state) in [
            (0, [255, 30, 20], LightState::Red),
            (1, [255, 190, 0], LightState::Amber),
            (2, [40, 255, 120], LightState::Green),
        ] {
            let r = light_state(&light(lamp, colour), rect);
            assert_eq!(r.state, state);
            assert!(r.confidence > 0.5, "{state:?}: {}", r.confidence);
            assert!((r.spot.1 as i32 - (25 + lamp as i32 * 30)).abs() <= 2, "{:?}", r.spot);
        }
    }

    #[test]
    fn a_specular_glint_does_not_outshine_the_lit_lamp() {
        // Green lamp lit at the bottom, a 2×2 white glint on the (dark) red lamp at the top.
        let mut img = light(2, [40, 255, 120]);
        for (x, y) in [(30, 22), (31, 22), (30, 23), (31, 23)] {
            img.put_pixel(x, y, Rgb([255, 255, 255]));
        }
        let r = light_state(&img, Rect::new(10, 10, 30, 90));
        assert_eq!(r.state, LightState::Green);
        assert!(r.confidence > 0.5, "{}", r.confidence);
    }

    #[test]
    fn wrong_hue_or_dark_box_lowers_confidence() {
        let rect = Rect::new(10, 10, 30, 90);
        let good = light_state(&light(2, [40, 255, 120]), rect);
        let green_on_top = light_state(&light(0, [40, 255, 120]), rect);
        assert_eq!(green_on_top.state, LightState::Red);
        assert!(green_on_top.confidence < good.confidence / 2.0);
        let dark = light_state(&RgbImage::from_pixel(50, 110, Rgb([20, 20, 20])), rect);
        assert_eq!(dark.confidence, 0.0);
        let outside = light_state(&RgbImage::new(10, 10), Rect::new(20, 20, 5, 5));
        assert_eq!(outside.state, LightState::Unknown);
    }
}
