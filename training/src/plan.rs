//! Training settings chosen from the data, with the reason for each, so a student with 42
//! photos and a student with 3000 renders both get a sensible run without tuning flags.
//!
//! * Window: the `# rccar-train distort window WxH` line `distort` writes, else from the
//!   positives' boxes: aspect = the median box width / height; the shorter side = the 5th
//!   percentile of the boxes' shorter sides (the smallest objects you labelled are the farthest
//!   ones that matter) divided by 1.1² = 1.21 — two steps of the detector's scale factor, so
//!   that even those smallest objects are hit at about three pyramid scales and get the
//!   `minNeighbors` + 1 = 4 raw hits the detector's grouping needs (an object only as big as
//!   the window is hit at one scale and a few offsets, and is lost at minNeighbors 3: on the
//!   photo-like check a 17 × 18 window from the 5th percentile lost most signs under 22 px,
//!   a 14 × 15 one found them) — clamped to 12–20 px (below 12 the features see little; the
//!   Haar pool grows with the fourth power of the side, so 24 px trains about twice as slowly
//!   as 20 px, for no gain at the car's 320 × 240 where a 10 cm sign is 18 px wide at 1.5 m).
//! * Positives per stage: each stage loses up to `1 − min_hit_rate` of the positives it
//!   keeps, so `num_stages` stages need `num_pos · (1 + (num_stages − 1)(1 − min_hit_rate))`
//!   (the rule in OpenCV's traincascade documentation); `num_pos` defaults to the largest that
//!   fits what exists, and a larger request is reduced, with a note.
//!
//! Units: pixels.

use crate::samples::InfoLine;

/// Smallest and largest side of an automatically chosen window, pixels.
pub const AUTO_SIDE: (u32, u32) = (12, 20);

/// The window's shorter side is the 5th-percentile box side divided by this: two steps of the
/// detector's scale factor 1.1 (see the module notes).
pub const SMALLEST_MARGIN: f64 = 1.21;

/// `train`'s default per-stage hit rate. OpenCV's default is 0.995; over the 18-20 stages a
/// few hundred backgrounds need, 0.995 keeps 0.995^20 = 90% of the training positives and
/// fewer of unseen ones (on the photo-like check: recall 0.81 at minNeighbors 3 with no false
/// positive left), 0.998 keeps 96% and lets more raw hits through on each object.
pub const DEFAULT_MIN_HIT_RATE: f64 = 0.998;

/// `distort`'s default sample count. 3000 rather than 1500: on the photo-like check's
/// validation photos (never trained on) twice the positives, with `DEFAULT_NUM_NEG`, found
/// 197 of 200 signs at minNeighbors 3 where 1500 with 1000 negatives found 193, at the same
/// 0.0125 false positives per frame; training takes about 1.4× the CPU time.
pub const DEFAULT_DISTORT_COUNT: usize = 3000;

/// `train`'s default negatives per stage (OpenCV's documentation example uses 1000 with 2000
/// positives). More negatives per stage show each stage more kinds of texture, so fewer stages
/// reach the same false-alarm rate and fewer positives are lost on the way.
pub const DEFAULT_NUM_NEG: usize = 2000;

/// Fewer positives than this: the advice is to make more with `distort`.
pub const FEW_POSITIVES: usize = 500;

/// The window `distort` wrote into an info.dat (`# rccar-train distort window WxH`), if any.
pub fn window_hint(text: &str) -> Option<(u32, u32)> {
    text.lines().find_map(|l| {
        let rest = l.trim().strip_prefix("# rccar-train distort window ")?;
        let (a, b) = rest.trim().split_once('x')?;
        Some((a.parse().ok()?, b.parse().ok()?))
    })
}

/// A window chosen from boxes, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowChoice {
    /// Width, height, pixels.
    pub size: (u32, u32),
    /// One line explaining it.
    pub why: String,
}

/// Chooses the window from the boxes of `lines` (see the module notes); `None` without boxes.
pub fn choose_window(lines: &[InfoLine]) -> Option<WindowChoice> {
    let boxes: Vec<(f64, f64)> = lines
        .iter()
        .flat_map(|l| l.boxes.iter())
        .filter(|b| b.width > 0 && b.height > 0)
        .map(|b| (b.width as f64, b.height as f64))
        .collect();
    if boxes.is_empty() {
        return None;
    }
    let mut aspects: Vec<f64> = boxes.iter().map(|(w, h)| w / h).collect();
    aspects.sort_by(|a, b| a.total_cmp(b));
    let aspect = aspects[aspects.len() / 2];
    let mut short: Vec<f64> = boxes.iter().map(|(w, h)| w.min(*h)).collect();
    short.sort_by(|a, b| a.total_cmp(b));
    let p5 = short[(short.len() as f64 * 0.05) as usize];
    let wanted = (p5 / SMALLEST_MARGIN).floor() as u32;
    let side = wanted.clamp(AUTO_SIDE.0, AUTO_SIDE.1);
    let size = if aspect >= 1.0 {
        (((side as f64 * aspect).round() as u32).min(64), side)
    } else {
        (side, ((side as f64 / aspect).round() as u32).min(64))
    };
    // Say what the window really is against those boxes: the 1.21 rule, or the clamp.
    let ratio = p5 / side as f64;
    let rule = if side == wanted {
        format!("the window is {ratio:.2}x smaller so they are found at several scales")
    } else if side < wanted {
        format!(
            "{:.0} px / {SMALLEST_MARGIN} = {wanted} px is above the {} px limit, so the window is {ratio:.2}x smaller \
             than them (a larger window trains much more slowly and finds no more at 320x240)",
            p5, AUTO_SIDE.1
        )
    } else {
        format!(
            "{:.0} px / {SMALLEST_MARGIN} = {wanted} px is below the {} px limit, so those boxes are only {ratio:.2} \
             times the window: they are found at fewer scales, and boxes under {} px not at all",
            p5, AUTO_SIDE.0, side
        )
    };
    Some(WindowChoice {
        size,
        why: format!(
            "window {}x{} from {} boxes: median aspect {:.2}, 5% of boxes are under {:.0} px on their shorter side; {rule} \
             (sides kept within {}-{} px)",
            size.0,
            size.1,
            boxes.len(),
            aspect,
            p5,
            AUTO_SIDE.0,
            AUTO_SIDE.1
        ),
    })
}

/// The window for templates given as crops (`distort --template`), whose sizes say nothing of
/// how large the object is in the car's frames: the crops' median aspect ratio at the largest
/// automatic side ([`AUTO_SIDE`]`.1`, 20 px), and why; `None` without templates. With frames
/// and boxes the window comes from the boxes ([`choose_window`]); with crops, `--window` from
/// the smallest object in your frames ÷ 1.21 is better.
pub fn window_for_crops(sizes: &[(u32, u32)]) -> Option<WindowChoice> {
    let mut aspects: Vec<f64> = sizes
        .iter()
        .filter(|(w, h)| *w > 0 && *h > 0)
        .map(|&(w, h)| w as f64 / h as f64)
        .collect();
    if aspects.is_empty() {
        return None;
    }
    aspects.sort_by(|a, b| a.total_cmp(b));
    let aspect = aspects[aspects.len() / 2];
    let side = AUTO_SIDE.1;
    let size = if aspect >= 1.0 {
        (((side as f64 * aspect).round() as u32).min(64), side)
    } else {
        (side, ((side as f64 / aspect).round() as u32).min(64))
    };
    Some(WindowChoice {
        size,
        why: format!(
            "window {}x{} for {} crops: their median aspect {aspect:.2} at {side} px on the shorter side (crops do not \
             say how large the object is in the car's frames: objects smaller than about {} px will not be found; \
             give --window WxH = the smallest object in your frames / {SMALLEST_MARGIN})",
            size.0,
            size.1,
            sizes.len(),
            (side as f64 * SMALLEST_MARGIN).round()
        ),
    })
}

/// The most positives per stage `available` positives can feed through `num_stages` stages.
pub fn max_num_pos(available: usize, num_stages: u32, min_hit_rate: f64) -> usize {
    let k = 1.0 + (num_stages.max(1) - 1) as f64 * (1.0 - min_hit_rate).max(0.0);
    ((available as f64 / k).floor() as usize).max(1).min(available)
}

/// Positives per stage: `asked` (or the most that fit) reduced to what exists, and a note when
/// it was reduced or the positives are few.
pub fn choose_num_pos(
    asked: Option<usize>,
    available: usize,
    num_stages: u32,
    min_hit_rate: f64,
) -> (usize, Option<String>) {
    let fit = max_num_pos(available, num_stages, min_hit_rate);
    let n = asked.map_or(fit, |a| a.min(fit));
    let mut notes = Vec::new();
    if let Some(a) = asked {
        if a > fit {
            notes.push(format!(
                "--num-pos {a} asked, but there are {available} usable positives and {num_stages} stages at hit rate \
                 {min_hit_rate} need {:.2} × num_pos: using {n} per stage",
                1.0 + (num_stages.max(1) - 1) as f64 * (1.0 - min_hit_rate)
            ));
        }
    }
    if available < FEW_POSITIVES {
        notes.push(format!(
            "only {available} positives: a cascade trained on so few finds mostly those very views. Make \
             1000-2000 with `rccar-train distort --template <your crops> --count 1500` (docs/training.md, step 3) \
             and train on its info.dat"
        ));
    }
    (n, (!notes.is_empty()).then(|| notes.join("; ")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rccar::detect::Rect;
    use std::path::PathBuf;

    fn lines(boxes: &[(i32, i32)]) -> Vec<InfoLine> {
        boxes
            .iter()
            .enumerate()
            .map(|(i, &(w, h))| InfoLine {
                path: PathBuf::from("x.png"),
                boxes: vec![Rect::new(0, 0, w, h)],
                line: i + 1,
            })
            .collect()
    }

    #[test]
    fn window_follows_the_boxes_aspect_and_small_end() {
        // Square boxes from 20 to 119 px: the 5th percentile is 25 → 25 / 1.21 = 20.7 → 20.
        let sq: Vec<(i32, i32)> = (20..120).map(|s| (s, s)).collect();
        assert_eq!(choose_window(&lines(&sq)).expect("boxes").size, (20, 20));
        // From 30 px: the 5th percentile is 35 → clamped to 20.
        let big: Vec<(i32, i32)> = (30..130).map(|s| (s, s)).collect();
        assert_eq!(choose_window(&lines(&big)).expect("boxes").size, (20, 20));
        // Tall boxes (aspect 0.4), 15-59 px wide: the 5th percentile (index 2) is 17 → 17 / 1.21
        // = 14.05 → 14 × 35.
        let tall: Vec<(i32, i32)> = (15..60).map(|s| (s, (s as f64 / 0.4).round() as i32)).collect();
        let c = choose_window(&lines(&tall)).expect("boxes");
        assert_eq!(c.size.0, 14, "{}", c.why);
        assert!((35..=36).contains(&c.size.1), "{}", c.why);
        // Tiny boxes: never below 12.
        assert_eq!(choose_window(&lines(&[(8, 8); 10])).expect("boxes").size, (12, 12));
        // Issue 28: the message says what the window is against the boxes, clamp included
        // (66 px boxes with a 20 px window are 3.30x larger, not 1.21x).
        let c = choose_window(&lines(&[(66, 66); 20])).expect("boxes");
        assert_eq!(c.size, (20, 20));
        assert!(c.why.contains("3.30x smaller") && c.why.contains("above the 20 px limit"), "{}", c.why);
        assert!(!c.why.contains("1.21x"), "{}", c.why);
        let c = choose_window(&lines(&[(8, 8); 10])).expect("boxes");
        assert!(c.why.contains("below the 12 px limit") && c.why.contains("0.67 times"), "{}", c.why);
        let c = choose_window(&lines(&sq)).expect("boxes");
        assert!(c.why.contains("1.25x smaller so they are found"), "{}", c.why);
        // Crops: their aspect at 20 px, and the advice to give --window.
        let c = window_for_crops(&[(40, 100), (30, 80), (50, 120)]).expect("crops");
        assert_eq!(c.size, (20, 50), "{}", c.why);
        assert!(c.why.contains("--window") && c.why.contains("3 crops"), "{}", c.why);
        assert_eq!(window_for_crops(&[(64, 64)]).expect("crops").size, (20, 20));
        assert!(window_for_crops(&[]).is_none());
        assert!(choose_window(&[]).is_none());
        assert_eq!(window_hint("# rccar-train distort window 20x16\na.png 1 0 0 20 16\n"), Some((20, 16)));
        assert_eq!(window_hint("a.png 1 0 0 20 16\n"), None);
    }

    #[test]
    fn positives_are_never_silently_fewer_than_asked() {
        // 42 positives, 1000 asked: reduced, said, and the advice to distort.
        let (n, note) = choose_num_pos(Some(1000), 42, 20, 0.995);
        assert_eq!(n, 38); // 42 / 1.095
        let note = note.expect("a note");
        assert!(note.contains("--num-pos 1000") && note.contains("using 38") && note.contains("distort"), "{note}");
        // Plenty: the default is what fits, no note.
        let (n, note) = choose_num_pos(None, 3000, 20, 0.995);
        assert_eq!(n, 2739);
        assert!(note.is_none());
    }
}
