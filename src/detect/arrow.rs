//! A turn sign's arrow direction inside its detector box, read the way a traffic light's lamp
//! colour is read (src/detect/light.rs): from the colours inside the box, after detection.
//!
//! The sign is a blue disc with a white rim and a white arrow: a thin shaft on the tail side
//! and a tall head on the side it points to. The arrow's pixels are the white ones enclosed by
//! blue: in each column of the box, those between its topmost and its lowest blue pixel (the
//! rim and whatever lies around the disc are outside that span, whatever the box's offset).
//! Each gets a whiteness weight (its smallest channel over its largest: ~1 for the white
//! arrow, ~0.1 for the blue; 0 up to 0.5, 1 from 0.95: blur mixes them). The head spreads
//! far above and below the arrow's centre row, the shaft does not, so
//!
//! `score = Σ white · sign(x − x_w) · |y − y_w|`
//!
//! about the white pixels' own centroid (x_w, y_w) is positive for an arrow pointing right
//! (in the image), negative for left. Boxes with little white, or whose score is small against
//! `Σ white · |y − y_w|` (no clear head), read `None`. Units: pixels.

use super::Rect;
use crate::classes::TurnArrow;
use image::RgbImage;

/// |score| over the total |y − y_w| weight below which the arrow counts as unread.
const MIN_CONTRAST: f64 = 0.15;

/// The direction of the arrow inside box `r` of `img` (see the module notes), `None` when it
/// cannot be told (too little white, no clear head, the box outside the image).
pub fn read_arrow(img: &RgbImage, r: Rect) -> Option<TurnArrow> {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let (x0, y0) = (r.x.clamp(0, w), r.y.clamp(0, h));
    let (x1, y1) = ((r.x + r.width).clamp(0, w), (r.y + r.height).clamp(0, h));
    if x1 - x0 < 4 || y1 - y0 < 4 {
        return None;
    }
    let px = |x: i32, y: i32| {
        let p = img.get_pixel(x as u32, y as u32).0;
        let mx = p[0].max(p[1]).max(p[2]) as f64;
        let mn = p[0].min(p[1]).min(p[2]) as f64;
        let blue = p[2] >= 30 && p[2] as f64 >= 1.3 * p[0] as f64 && p[2] as f64 >= 1.1 * p[1] as f64;
        (
            blue,
            if mx >= 20.0 {
                ((mn / mx - 0.5) / 0.45).clamp(0.0, 1.0)
            } else {
                0.0
            },
        )
    };
    // The white pixels enclosed by blue in their column: (x, y, weight).
    let mut white = Vec::new();
    for x in x0..x1 {
        let (Some(top), Some(bottom)) = ((y0..y1).find(|&y| px(x, y).0), (y0..y1).rfind(|&y| px(x, y).0)) else {
            continue;
        };
        for y in top + 1..bottom {
            let w = px(x, y).1;
            if w > 0.0 {
                white.push((x as f64, y as f64, w));
            }
        }
    }
    // The arrow's own centre (a box off by a few pixels moves the box's centre, not it).
    let white_n: f64 = white.iter().map(|p| p.2).sum();
    if white_n < 3.0 {
        return None;
    }
    let xc = white.iter().map(|p| p.0 * p.2).sum::<f64>() / white_n;
    let yc = white.iter().map(|p| p.1 * p.2).sum::<f64>() / white_n;
    let (mut score, mut total) = (0.0f64, 0.0f64);
    for &(x, y, w) in &white {
        score += w * (x - xc).signum() * (y - yc).abs();
        total += w * (y - yc).abs();
    }
    if total <= 0.0 || score.abs() < MIN_CONTRAST * total {
        return None;
    }
    Some(if score > 0.0 { TurnArrow::Right } else { TurnArrow::Left })
}
