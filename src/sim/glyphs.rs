//! Stroke letters for the signs the simulator paints (no font files): each letter is a few
//! polylines in a unit box (x right 0..1, y up 0..1), drawn with a round pen of a given width.
//! Only the letters signs need are defined.

/// Polylines of one letter, unit box; `None` for letters that are not defined.
pub fn strokes(c: char) -> Option<&'static [&'static [[f32; 2]]]> {
    const S: &[&[[f32; 2]]] = &[&[
        [1.0, 0.82],
        [0.82, 1.0],
        [0.18, 1.0],
        [0.0, 0.82],
        [0.0, 0.64],
        [0.18, 0.5],
        [0.82, 0.5],
        [1.0, 0.36],
        [1.0, 0.18],
        [0.82, 0.0],
        [0.18, 0.0],
        [0.0, 0.18],
    ]];
    const T: &[&[[f32; 2]]] = &[&[[0.0, 1.0], [1.0, 1.0]], &[[0.5, 1.0], [0.5, 0.0]]];
    const O: &[&[[f32; 2]]] = &[&[
        [0.22, 0.0],
        [0.78, 0.0],
        [1.0, 0.22],
        [1.0, 0.78],
        [0.78, 1.0],
        [0.22, 1.0],
        [0.0, 0.78],
        [0.0, 0.22],
        [0.22, 0.0],
    ]];
    const P: &[&[[f32; 2]]] = &[&[
        [0.0, 0.0],
        [0.0, 1.0],
        [0.8, 1.0],
        [1.0, 0.84],
        [1.0, 0.64],
        [0.8, 0.48],
        [0.0, 0.48],
    ]];
    match c {
        'S' => Some(S),
        'T' => Some(T),
        'O' => Some(O),
        'P' => Some(P),
        _ => None,
    }
}

/// Distance from `(x, y)` to the nearest stroke of `text` laid out in a box of width 1 and
/// height 1 (letters `advance` apart, each `letter_w` wide), in box units.
pub fn text_distance(text: &str, letter_w: f32, advance: f32, x: f32, y: f32) -> f32 {
    let mut best = f32::INFINITY;
    for (i, c) in text.chars().enumerate() {
        let x0 = i as f32 * advance;
        // Letters whose box (plus a margin) is far from the point cannot be nearest.
        if x < x0 - 0.3 || x > x0 + letter_w + 0.3 {
            continue;
        }
        let Some(lines) = strokes(c) else { continue };
        for line in lines {
            for w in line.windows(2) {
                let a = [x0 + w[0][0] * letter_w, w[0][1]];
                let b = [x0 + w[1][0] * letter_w, w[1][1]];
                best = best.min(segment_distance(a, b, [x, y]));
            }
        }
    }
    best
}

fn segment_distance(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> f32 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let (apx, apy) = (p[0] - a[0], p[1] - a[1]);
    let l2 = abx * abx + aby * aby;
    let t = if l2 > 0.0 {
        ((apx * abx + apy * aby) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (dx, dy) = (apx - t * abx, apy - t * aby);
    (dx * dx + dy * dy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_has_a_bar_and_a_stem() {
        // On the T's bar and stem, and in its empty lower-left corner.
        assert!(text_distance("T", 1.0, 1.2, 0.2, 1.0) < 1e-6);
        assert!(text_distance("T", 1.0, 1.2, 0.5, 0.3) < 1e-6);
        assert!((text_distance("T", 1.0, 1.2, 0.1, 0.1) - 0.4).abs() < 1e-6);
        assert!(strokes('Z').is_none());
    }
}
