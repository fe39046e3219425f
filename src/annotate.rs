//! Annotated frames: what the pipeline saw and decided, drawn over the camera frame.
//!
//! Drawn: the ROI trapezoid (yellow), the bird's-eye binary image as an inset with its column
//! histogram, both lines (red when seen, orange when estimated) mapped back into the camera
//! view, the lane centre L_c (green) and the car's centre L_F (blue) as in Fig. 7 of Rivera &
//! Andaluz (2021), and the error and commands as text. Text uses a built-in 5×7 pixel font, so
//! no font file is needed on the car.

use crate::control::Command;
use crate::lane::warp::Homography;
use crate::lane::{LaneImages, LaneMeasurement, LaneStatus};
use image::{Rgb, RgbImage};

const YELLOW: Rgb<u8> = Rgb([255, 220, 0]);
const RED: Rgb<u8> = Rgb([255, 40, 40]);
const ORANGE: Rgb<u8> = Rgb([255, 150, 0]);
const GREEN: Rgb<u8> = Rgb([40, 230, 60]);
const BLUE: Rgb<u8> = Rgb([60, 120, 255]);
const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const BLACK: Rgb<u8> = Rgb([0, 0, 0]);

/// Draws everything onto a copy of `frame`.
pub fn annotate(
    frame: &RgbImage,
    roi: &[[f64; 2]; 4],
    homography: &Homography,
    images: &LaneImages,
    lane: &LaneMeasurement,
    cmd: &Command,
) -> RgbImage {
    annotate_with(frame, roi, homography, images, lane, cmd, true)
}

/// [`annotate`], with the bird's-eye inset in the top-right corner or without it (the
/// dashboard draws the bird's-eye view beside the frame: an inset there would only cover
/// the scene, where a stop sign stands).
pub fn annotate_with(
    frame: &RgbImage,
    roi: &[[f64; 2]; 4],
    homography: &Homography,
    images: &LaneImages,
    lane: &LaneMeasurement,
    cmd: &Command,
    inset: bool,
) -> RgbImage {
    let mut out = frame.clone();
    // ROI trapezoid.
    for k in 0..4 {
        let (a, b) = (roi[k], roi[(k + 1) % 4]);
        line(&mut out, a[0], a[1], b[0], b[1], YELLOW);
    }
    // Lines and centres, from the bird's-eye band back into the camera view.
    let bh = images.binary.height();
    let inv = homography.inverse();
    let top = (bh - images.band_rows) as f64;
    let bottom = bh as f64 - 1.0;
    let vertical = |out: &mut RgbImage, col: f64, y0: f64, colour: Rgb<u8>| {
        if let Some(inv) = &inv {
            if let (Some(a), Some(b)) = (inv.apply(col, y0), inv.apply(col, bottom)) {
                line(out, a.0, a.1, b.0, b.1, colour);
            }
        }
    };
    if let Some(l) = lane.p_left {
        vertical(&mut out, l, top, if lane.left_estimated { ORANGE } else { RED });
    }
    if let Some(r) = lane.p_right {
        vertical(&mut out, r, top, if lane.right_estimated { ORANGE } else { RED });
    }
    if let Some(c) = lane.lane_center {
        vertical(&mut out, c, top, GREEN);
    }
    vertical(&mut out, lane.frame_center, 0.0, BLUE);

    if inset {
        draw_inset(&mut out, images, lane);
    }

    // Text.
    let status = match lane.status {
        LaneStatus::Both => "BOTH",
        LaneStatus::LeftOnly => "LEFT ONLY",
        LaneStatus::RightOnly => "RIGHT ONLY",
        LaneStatus::Lost => "LOST",
    };
    let err = lane.error_px.map_or("ERR --".to_string(), |e| format!("ERR {e:+.1}PX"));
    text(&mut out, 3, 3, &err, WHITE);
    text(&mut out, 3, 13, &format!("STEER {:+.2}", cmd.steer), WHITE);
    text(&mut out, 3, 23, &format!("THR {:.2}", cmd.throttle), WHITE);
    text(
        &mut out,
        3,
        33,
        status,
        if lane.status == LaneStatus::Both { GREEN } else { ORANGE },
    );
    out
}

/// The junction rule's state under the lane's text (src/lane/junction.rs): `FORK LEFT ROUTE 3`
/// (the way and why; the route step from 1), `FORK RIGHT SIGN`, `MERGE KEEP RIGHT`.
pub fn junction(img: &mut RgbImage, j: &crate::lane::junction::JunctionReport) {
    use crate::lane::junction::{JunctionKind, Side};
    let side = |s: Side| if s == Side::Left { "LEFT" } else { "RIGHT" };
    let s = match j.kind {
        JunctionKind::Fork => {
            let way = j.way.map_or("", |w| match w {
                crate::route::Step::Left => "LEFT",
                crate::route::Step::Straight => "STRAIGHT",
                crate::route::Step::Right => "RIGHT",
            });
            let why = match (j.why, j.step) {
                (Some(crate::route::Why::Route), Some(k)) => format!("ROUTE {}", k + 1),
                (Some(crate::route::Why::Sign), _) => "SIGN".into(),
                _ => "DEFAULT".into(),
            };
            format!("FORK {way} {why}")
        }
        JunctionKind::Merge => format!("MERGE KEEP {}", side(j.keep)),
    };
    text(img, 3, 43, &s, YELLOW);
}

/// A line across the lane (`StopLineSeen`) drawn over an annotated frame: its near edge's
/// bird's-eye row mapped back into the camera view (magenta; in dashes for a yield line), with
/// its distance. `homography` maps camera to bird's-eye pixels, `bird_w` is the bird's-eye
/// width.
pub fn draw_stop_line(
    img: &mut RgbImage,
    homography: &Homography,
    bird_w: u32,
    seen: &crate::lane::stop_line::StopLineSeen,
) {
    const MAGENTA: Rgb<u8> = Rgb([255, 60, 220]);
    let Some(inv) = homography.inverse() else { return };
    let n = if seen.dashed { 9 } else { 1 };
    let step = (bird_w as f64 - 1.0) / n as f64;
    for k in (0..n).step_by(2) {
        let (u0, u1) = (k as f64 * step, (k + 1) as f64 * step);
        if let (Some(a), Some(b)) = (inv.apply(u0, seen.row), inv.apply(u1, seen.row)) {
            line(img, a.0, a.1, b.0, b.1, MAGENTA);
            if k == 0 {
                let label = if seen.dashed { "YIELD LINE" } else { "STOP LINE" };
                let t = format!("{label} {:.2}M", seen.distance_m);
                text(img, a.0.max(0.0) as i64 + 2, a.1 as i64 - 9, &t, MAGENTA);
            }
        }
    }
}

/// The bird's-eye binary image at 1/3 size with its histogram, top right.
fn draw_inset(out: &mut RgbImage, images: &LaneImages, lane: &LaneMeasurement) {
    let (bw, bh) = images.binary.dimensions();
    let scale = 3u32;
    let (iw, ih) = (bw / scale, bh / scale);
    let (ox, oy) = (out.width().saturating_sub(iw + 2), 2u32);
    for y in 0..ih {
        for x in 0..iw {
            let v = images.binary.get_pixel(x * scale, y * scale).0[0];
            let g = if v > 0 { 230 } else { 30 };
            put(out, (ox + x) as i64, (oy + y) as i64, Rgb([g, g, g]));
        }
    }
    let max = images.hist.iter().copied().max().unwrap_or(0).max(1) as f64;
    for x in 0..iw {
        let c = images.hist[(x * scale) as usize] as f64 / max;
        let hgt = (c * ih as f64 * 0.5) as u32;
        for y in 0..hgt {
            put(out, (ox + x) as i64, (oy + ih - 1 - y) as i64, YELLOW);
        }
    }
    let mark = |out: &mut RgbImage, col: Option<f64>, colour| {
        if let Some(c) = col {
            let x = ox as f64 + c / scale as f64;
            line(out, x, oy as f64, x, (oy + ih - 1) as f64, colour);
        }
    };
    mark(out, lane.p_left, RED);
    mark(out, lane.p_right, RED);
    mark(out, lane.lane_center, GREEN);
    mark(out, Some(lane.frame_center), BLUE);
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A straight line from (x0, y0) to (x1, y1), clipped to the image.
pub fn line(img: &mut RgbImage, x0: f64, y0: f64, x1: f64, y1: f64, c: Rgb<u8>) {
    if ![x0, y0, x1, y1].iter().all(|v| v.is_finite() && v.abs() < 1e6) {
        return;
    }
    let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        put(
            img,
            (x0 + t * (x1 - x0)).round() as i64,
            (y0 + t * (y1 - y0)).round() as i64,
            c,
        );
    }
}

/// Writes `s` (upper case, digits, `+-.:=/%()_`) at (x, y) with a 1-pixel black shadow.
pub fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, c: Rgb<u8>) {
    for (i, ch) in s.chars().enumerate() {
        let g = glyph(ch.to_ascii_uppercase());
        for (row, bits) in g.iter().enumerate() {
            for col in 0..5 {
                if bits & (0x10 >> col) != 0 {
                    let (px, py) = (x + i as i64 * 6 + col, y + row as i64);
                    put(img, px + 1, py + 1, BLACK);
                    put(img, px, py, c);
                }
            }
        }
    }
}

/// 5×7 glyphs, one byte per row, bit 4 = leftmost column.
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        _ => [0; 7],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_draws_only_inside_the_image() {
        let mut img = RgbImage::new(20, 10);
        text(&mut img, 15, 5, "88", WHITE); // runs off the right and bottom edges
        assert!(img.pixels().any(|p| *p == WHITE));
    }

    #[test]
    fn line_handles_non_finite_endpoints() {
        let mut img = RgbImage::new(10, 10);
        line(&mut img, f64::NAN, 0.0, 5.0, 5.0, WHITE);
        line(&mut img, 0.0, 0.0, 9.0, 9.0, WHITE);
        assert_eq!(*img.get_pixel(4, 4), WHITE);
    }
}
