//! Evaluation of a cascade on labelled frames (an info.dat: simulator ground truth or hand
//! labels): recall, precision and false positives per frame for each `minNeighbors`, the
//! recall–FP curve over them, and the detection time per frame.
//!
//! A detection matches a labelled box when their IoU is at least `iou` (0.5, PASCAL VOC);
//! matching is greedy, best IoU first, one-to-one. Unmatched detections are false positives,
//! unmatched boxes misses. Detection is rccar's own (`rccar::detect::Detector`), with the raw
//! hits computed once per frame and grouped for every `minNeighbors` the way
//! `detectMultiScale` groups them (`groupRectangles(hits, minNeighbors, 0.2)`, then clipped).

use image::{GrayImage, RgbImage};
use plotters::prelude::*;
use rccar::detect::{group_rectangles, Cascade, DetectParams, Detector, Rect};
use std::time::Instant;

/// Numbers at one `minNeighbors`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Point {
    /// The grouping threshold.
    pub min_neighbors: u32,
    /// Labelled boxes found.
    pub true_positives: usize,
    /// Detections matching no box.
    pub false_positives: usize,
    /// Boxes not found.
    pub misses: usize,
    /// TP / boxes.
    pub recall: f64,
    /// TP / detections (1 when there are none).
    pub precision: f64,
    /// FP / frames, over all frames (those with the object too).
    pub fp_per_frame: f64,
    /// False positives on the frames without the object (a bg.txt's frames, a folder).
    #[serde(default)]
    pub fp_negative_frames: usize,
    /// Those / the frames without the object (`None` when there are none): the figure to
    /// compare with what the car sees on a track without the object.
    #[serde(default)]
    pub fp_per_negative_frame: Option<f64>,
    /// False positives on the frames with the object / those frames (`None` when there are
    /// none): boxes beside or around the object.
    #[serde(default)]
    pub fp_per_sign_frame: Option<f64>,
}

/// A whole evaluation.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// Cascade file.
    pub cascade: String,
    /// Frames evaluated.
    pub frames: usize,
    /// Labelled boxes.
    pub boxes: usize,
    /// Frames without the object (no box): every detection there is a false positive.
    #[serde(default)]
    pub negative_frames: usize,
    /// Frames with at least one box.
    #[serde(default)]
    pub sign_frames: usize,
    /// IoU needed for a match.
    pub iou: f64,
    /// Scale factor used.
    pub scale_factor: f64,
    /// Smallest window searched, pixels ((0, 0): the cascade's size).
    pub min_size: (u32, u32),
    /// One point per minNeighbors.
    pub points: Vec<Point>,
    /// Median / mean / max time of a full `detect` call per frame, ms.
    pub ms_median: f64,
    /// Mean.
    pub ms_mean: f64,
    /// Max.
    pub ms_max: f64,
    /// Frame size the times are for.
    pub frame_size: (u32, u32),
    /// Per-frame details at the reporting minNeighbors: (file, found, false positives).
    pub frames_detail: Vec<(String, usize, usize)>,
    /// The false-positive target [`Report::choose`] chose for (`None`: no choice made).
    pub target_fp_per_frame: Option<f64>,
    /// The chosen operating point ([`Report::choose`]): the smallest minNeighbors ≥ 1 whose
    /// false positives per frame without the object are at most the target (`None`: no frame
    /// without the object, or none of 1–10 meets it).
    pub chosen_min_neighbors: Option<u32>,
}

impl Report {
    /// Chooses the operating point for the car: the smallest `minNeighbors` of 1 and up whose
    /// false positives **per frame without the object** (the held-out track recording: what the
    /// car sees) are at most `target`. Both recall and false positives fall as minNeighbors
    /// grows (a group needs more hits), so the smallest that meets the target keeps the most
    /// recall. 0 (raw hits, no grouping) is never chosen. Frames with the object only give the
    /// recall there; without frames lacking the object nothing is chosen.
    pub fn choose(&mut self, target: f64) -> Option<&Point> {
        self.target_fp_per_frame = Some(target);
        let p = self
            .points
            .iter()
            .filter(|p| p.min_neighbors >= 1)
            .find(|p| p.fp_per_negative_frame.is_some_and(|f| f <= target));
        self.chosen_min_neighbors = p.map(|p| p.min_neighbors);
        p
    }
}

/// Greedy one-to-one matching; returns (TP, FP, misses).
pub fn match_boxes(dets: &[Rect], truth: &[Rect], iou: f64) -> (usize, usize, usize) {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, d) in dets.iter().enumerate() {
        for (j, t) in truth.iter().enumerate() {
            let v = d.iou(t);
            if v >= iou {
                pairs.push((v, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut du, mut tu) = (vec![false; dets.len()], vec![false; truth.len()]);
    let mut tp = 0;
    for (_, i, j) in pairs {
        if !du[i] && !tu[j] {
            du[i] = true;
            tu[j] = true;
            tp += 1;
        }
    }
    (tp, dets.len() - tp, truth.len() - tp)
}

/// Groups raw hits as `detectMultiScale` does for `min_neighbors` and clips them to the frame.
pub fn group(raw: &[Rect], min_neighbors: u32, w: u32, h: u32) -> Vec<Rect> {
    let g: Vec<Rect> = if min_neighbors > 0 {
        group_rectangles(raw, min_neighbors as i32, rccar::detect::detector::GROUP_EPS)
            .into_iter()
            .map(|(r, _)| r)
            .collect()
    } else {
        raw.to_vec()
    };
    let frame = Rect::new(0, 0, w as i32, h as i32);
    g.into_iter()
        .map(|r| r.intersect(&frame))
        .filter(|r| r.area() > 0)
        .collect()
}

/// Evaluates `cascade` on `(name, frame, boxes)` items at every minNeighbors in `mns`, with
/// the detector's `scale_factor` and `min_size` (pixels, (0, 0) = the cascade's window: as
/// `rccar detect` with `[detect] min_size_px`); `report_mn` picks the per-frame detail.
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    cascade: Cascade,
    name: &str,
    frames: &[(String, GrayImage, Vec<Rect>)],
    scale_factor: f64,
    min_size: (u32, u32),
    iou: f64,
    mns: &[u32],
    report_mn: u32,
) -> Result<Report, rccar::detect::DetectError> {
    let mut det = Detector::new(cascade);
    let params = DetectParams {
        scale_factor,
        min_size,
        min_neighbors: 0,
        ..DetectParams::default()
    };
    // (TP, FP, misses, FP on frames without the object) per minNeighbors.
    let mut acc = vec![(0usize, 0usize, 0usize, 0usize); mns.len()];
    let negative_frames = frames.iter().filter(|f| f.2.is_empty()).count();
    let sign_frames = frames.len() - negative_frames;
    let mut times = Vec::new();
    let mut detail = Vec::new();
    let mut boxes = 0;
    let mut size = (0, 0);
    for (fname, img, truth) in frames {
        boxes += truth.len();
        size = img.dimensions();
        // The time of a full detect call (scan + grouping at the reporting minNeighbors).
        let t = Instant::now();
        det.detect(
            img,
            &DetectParams {
                min_neighbors: report_mn,
                ..params
            },
        )?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        let raw = det.raw_hits().to_vec();
        for (k, &mn) in mns.iter().enumerate() {
            let d = group(&raw, mn, img.width(), img.height());
            let (tp, fp, miss) = match_boxes(&d, truth, iou);
            acc[k].0 += tp;
            acc[k].1 += fp;
            acc[k].2 += miss;
            if truth.is_empty() {
                acc[k].3 += fp;
            }
            if mn == report_mn {
                detail.push((fname.clone(), tp, fp));
            }
        }
    }
    let n = frames.len().max(1) as f64;
    let points = mns
        .iter()
        .zip(&acc)
        .map(|(&mn, &(tp, fp, miss, fp_neg))| Point {
            min_neighbors: mn,
            true_positives: tp,
            false_positives: fp,
            misses: miss,
            recall: tp as f64 / boxes.max(1) as f64,
            precision: if tp + fp > 0 { tp as f64 / (tp + fp) as f64 } else { 1.0 },
            fp_per_frame: fp as f64 / n,
            fp_negative_frames: fp_neg,
            fp_per_negative_frame: (negative_frames > 0).then(|| fp_neg as f64 / negative_frames as f64),
            fp_per_sign_frame: (sign_frames > 0).then(|| (fp - fp_neg) as f64 / sign_frames as f64),
        })
        .collect();
    let mut sorted = times.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    Ok(Report {
        cascade: name.to_string(),
        frames: frames.len(),
        boxes,
        negative_frames,
        sign_frames,
        iou,
        scale_factor,
        min_size,
        points,
        ms_median: sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
        ms_mean: times.iter().sum::<f64>() / times.len().max(1) as f64,
        ms_max: sorted.last().copied().unwrap_or(0.0),
        frame_size: size,
        frames_detail: detail,
        target_fp_per_frame: None,
        chosen_min_neighbors: None,
    })
}

/// Recall against false positives per frame, one point per minNeighbors ≥ 1 (labelled).
pub fn curve_png(r: &Report, title: &str) -> Result<RgbImage, String> {
    let (w, h) = (800u32, 500u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        // minNeighbors 0 (raw hits, tens of FP per frame) would squash the axis: left out.
        let pts_all: Vec<&Point> = r.points.iter().filter(|p| p.min_neighbors > 0).collect();
        let xmax = pts_all.iter().map(|p| p.fp_per_frame).fold(0.1, f64::max) * 1.1;
        let ymin = pts_all.iter().map(|p| p.recall).fold(1.0, f64::min).min(0.9) - 0.02;
        let mut c = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..xmax, ymin..1.005)
            .map_err(|x| e(&x))?;
        c.configure_mesh()
            .x_desc("false positives per frame")
            .y_desc("recall")
            .draw()
            .map_err(|x| e(&x))?;
        let pts: Vec<(f64, f64)> = pts_all.iter().map(|p| (p.fp_per_frame, p.recall)).collect();
        c.draw_series(LineSeries::new(pts.clone(), &BLUE)).map_err(|x| e(&x))?;
        c.draw_series(pts.iter().map(|&p| Circle::new(p, 4, BLUE.filled())))
            .map_err(|x| e(&x))?;
        c.draw_series(pts_all.iter().map(|p| {
            Text::new(
                format!("mn={}", p.min_neighbors),
                (p.fp_per_frame, p.recall),
                ("sans-serif", 12).into_font(),
            )
        }))
        .map_err(|x| e(&x))?;
        // The target: recall ≥ 0.95 at ≤ 0.05 FP per frame.
        c.draw_series(LineSeries::new(
            [(0.0, 0.95), (0.05, 0.95), (0.05, 1.005)],
            RED.stroke_width(1),
        ))
        .map_err(|x| e(&x))?;
        root.present().map_err(|x| e(&x))?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| "plot buffer".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_is_one_to_one_best_first() {
        let t = [Rect::new(0, 0, 10, 10)];
        let d = [
            Rect::new(1, 0, 10, 10),
            Rect::new(0, 0, 10, 10),
            Rect::new(50, 50, 10, 10),
        ];
        assert_eq!(match_boxes(&d, &t, 0.5), (1, 2, 0));
        assert_eq!(match_boxes(&[], &t, 0.5), (0, 0, 1));
    }

    /// Issue 28: false positives on frames without the object and on frames with it are
    /// reported apart (the all-frames figure mixed them without saying so).
    #[test]
    fn false_positives_are_split_by_frame_kind() {
        let mut c = Cascade::from_file(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../config/cascades/stop_sign.xml"
        )))
        .expect("cascade");
        // A window every sample passes: stage thresholds far below any sum.
        for st in c.stages.iter_mut() {
            st.threshold = -1e9;
        }
        let (cw, ch) = (c.width, c.height);
        let img = GrayImage::from_fn(48, 32, |x, y| image::Luma([((x * 37 + y * 91) % 251) as u8]));
        let frames = vec![
            ("neg1".to_string(), img.clone(), vec![]),
            ("neg2".to_string(), img.clone(), vec![]),
            ("sign".to_string(), img.clone(), vec![Rect::new(0, 0, cw, ch)]),
        ];
        let r = evaluate(c, "test", &frames, 1.1, (0, 0), 0.5, &[0], 0).expect("eval");
        assert_eq!((r.negative_frames, r.sign_frames), (2, 1));
        let p = &r.points[0];
        // Every window of every frame is a raw hit; the sign frame's one box matches at most one.
        assert!(p.fp_negative_frames > 0);
        let neg = p.fp_per_negative_frame.expect("negatives");
        let sign = p.fp_per_sign_frame.expect("signs");
        assert!((neg * 2.0 - p.fp_negative_frames as f64).abs() < 1e-9);
        assert!((neg * 2.0 + sign - p.false_positives as f64).abs() < 1e-9, "{p:?}");
        assert!((p.fp_per_frame * 3.0 - p.false_positives as f64).abs() < 1e-9);
    }

    fn point(mn: u32, recall: f64, fp_neg: Option<f64>) -> Point {
        Point {
            min_neighbors: mn,
            true_positives: 0,
            false_positives: 0,
            misses: 0,
            recall,
            precision: 1.0,
            fp_per_frame: 0.0,
            fp_negative_frames: 0,
            fp_per_negative_frame: fp_neg,
            fp_per_sign_frame: None,
        }
    }

    fn report(points: Vec<Point>) -> Report {
        Report {
            cascade: String::new(),
            frames: 0,
            boxes: 0,
            negative_frames: 0,
            sign_frames: 0,
            iou: 0.5,
            scale_factor: 1.1,
            min_size: (0, 0),
            points,
            ms_median: 0.0,
            ms_mean: 0.0,
            ms_max: 0.0,
            frame_size: (0, 0),
            frames_detail: vec![],
            target_fp_per_frame: None,
            chosen_min_neighbors: None,
        }
    }

    /// The chosen minNeighbors is the smallest of 1 and up whose false positives per frame
    /// without the object meet the target (0, raw hits, never; the target itself counts as
    /// met); none when no value meets it or there are no such frames.
    #[test]
    fn the_smallest_min_neighbors_within_the_target_is_chosen() {
        let curve = [(0, 0.95, 0.0), (1, 0.9, 0.30), (2, 0.85, 0.05), (3, 0.8, 0.01), (4, 0.7, 0.0)];
        let mut r = report(curve.iter().map(|&(m, rc, f)| point(m, rc, Some(f))).collect());
        assert_eq!(r.choose(0.01).map(|p| p.min_neighbors), Some(3));
        assert_eq!((r.chosen_min_neighbors, r.target_fp_per_frame), (Some(3), Some(0.01)));
        assert_eq!(r.choose(0.05).map(|p| p.recall), Some(0.85));
        assert_eq!(r.choose(1.0).map(|p| p.min_neighbors), Some(1), "0 is not an operating point");
        let mut r = report(vec![point(1, 0.9, Some(0.5)), point(2, 0.8, Some(0.2))]);
        assert!(r.choose(0.1).is_none());
        assert_eq!(r.chosen_min_neighbors, None);
        let mut r = report(vec![point(1, 0.9, None), point(2, 0.8, None)]);
        assert!(r.choose(0.1).is_none(), "no frame without the object: nothing to choose on");
    }
}
