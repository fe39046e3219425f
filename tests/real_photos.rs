//! Issue 28, must-show 0 and 3 on real photos: DeepPiCar's published photos of miniature road
//! signs on a floor track (github.com/dctian/DeepPiCar, GPL-3.0, never committed here),
//! fetched and listed by `training/realsets/deeppicar.sh OUT`. Set `RCCAR_REALSIGNS=OUT` to
//! run; without it (CI, a fresh clone) the test prints why and passes: **it is not run in CI**.
//!
//! At the car's 320×240 on DeepPiCar's `train` folder (43 photos, 42 with stop signs, 61
//! signs; the colour detector's `[colour_template]` options were chosen on the `test` and
//! `ver1` folders, training/realsets/tune_colour.py) and 219 frames of the track without
//! signs, through the pipeline's own loader (`pipeline::load_detector`, whole frames): the
//! stop sign by the shipped cascade and by `classes.stop_sign.detect = "colour_template"`.
//! A detection matches a labelled box at IoU ≥ 0.5 (one to one, best first). Prints the
//! table docs/detect.md quotes and holds both to what was measured; training/realsets/score.sh
//! prints the same and more (OpenCV's boxes, the photos' own size, the traffic light).
//!
//!     RCCAR_REALSIGNS=~/data/realsigns/deeppicar cargo test --release --test it real_photos -- --nocapture

use rccar::config::{Config, DetectMethod};
use rccar::detect::Rect;
use rccar::ranging::ObjectClass;
use std::path::{Path, PathBuf};

/// (path relative to the list, boxes) of an info.dat / bg.txt.
fn read_list(path: &Path) -> Vec<(String, Vec<Rect>)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let t: Vec<&str> = l.split_whitespace().collect();
            let n: usize = t.get(1).map_or(0, |v| v.parse().unwrap());
            let v: Vec<i32> = t.iter().skip(2).take(4 * n).map(|v| v.parse().unwrap()).collect();
            (
                t[0].to_string(),
                v.chunks(4).map(|c| Rect::new(c[0], c[1], c[2], c[3])).collect(),
            )
        })
        .collect()
}

/// Greedy one-to-one matching at IoU ≥ 0.5: (found, false boxes).
fn matched(dets: &[Rect], truth: &[Rect]) -> (usize, usize) {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, d) in dets.iter().enumerate() {
        for (j, t) in truth.iter().enumerate() {
            let v = d.iou(t);
            if v >= 0.5 {
                pairs.push((v, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut du, mut tu) = (vec![false; dets.len()], vec![false; truth.len()]);
    let mut tp = 0;
    for (_, i, j) in pairs {
        if !du[i] && !tu[j] {
            (du[i], tu[j]) = (true, true);
            tp += 1;
        }
    }
    (tp, dets.len() - tp)
}

/// (signs found, signs, false boxes on the photos, false boxes on the track frames).
fn score(cfg: &Config, photos: &[(String, Vec<Rect>)], track: &[(String, Vec<Rect>)], dir: &Path) -> [usize; 4] {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (stage, missing) = rccar::pipeline::load_detector(cfg, &root.join("config")).unwrap();
    assert!(missing.is_empty(), "{missing:?}");
    let mut stage = stage.unwrap();
    let mut out = [0; 4];
    for (k, list) in [photos, track].into_iter().enumerate() {
        for (p, truth) in list {
            let img = image::open(dir.join(p)).unwrap().to_rgb8();
            let found: Vec<Rect> = stage
                .run_rgb(&img)
                .unwrap()
                .into_iter()
                .filter(|o| o.label == "stop_sign")
                .map(|o| o.rect)
                .collect();
            let (tp, fp) = matched(&found, truth);
            if k == 0 {
                out[0] += tp;
                out[1] += truth.len();
                out[2] += fp;
            } else {
                out[3] += fp;
            }
        }
    }
    out
}

#[test]
fn stop_sign_cascade_and_colour_template_on_real_photos() {
    let Some(out) = std::env::var_os("RCCAR_REALSIGNS").map(PathBuf::from) else {
        eprintln!(
            "skipped: RCCAR_REALSIGNS is not set (the real photos are fetched, not committed: \
             bash training/realsets/deeppicar.sh OUT, then RCCAR_REALSIGNS=OUT); not run in CI"
        );
        return;
    };
    let dir = out.join("sets/320");
    let photos: Vec<_> = read_list(&dir.join("stop_sign.info.dat"))
        .into_iter()
        .filter(|(p, _)| p.starts_with("train/"))
        .collect();
    let track = read_list(&dir.join("track.bg.txt"));
    assert_eq!(
        (photos.len(), track.len()),
        (43, 219),
        "{}: not deeppicar.sh's lists",
        dir.display()
    );
    // Only the stop sign: the other classes' cascades are switched off.
    let mut cfg = Config::default();
    for c in ObjectClass::ALL.into_iter().filter(|c| *c != ObjectClass::StopSign) {
        cfg.classes[c].model.clear();
    }
    let cascade = score(&cfg, &photos, &track, &dir);
    cfg.classes[ObjectClass::StopSign].detect = DetectMethod::ColourTemplate;
    let colour = score(&cfg, &photos, &track, &dir);
    println!("| stop sign, 320x240 | recall | false boxes / photo | false boxes / track frame |");
    println!("|---|---|---|---|");
    for (name, s) in [("shipped cascade", cascade), ("colour + template", colour)] {
        println!(
            "| {name} | {}/{} = {:.3} | {}/{} = {:.3} | {}/{} = {:.3} |",
            s[0],
            s[1],
            s[0] as f64 / s[1] as f64,
            s[2],
            photos.len(),
            s[2] as f64 / photos.len() as f64,
            s[3],
            track.len(),
            s[3] as f64 / track.len() as f64
        );
    }
    // What was measured (docs/detect.md); a change to either detector shows here.
    assert_eq!(cascade, [11, 61, 24, 80], "the shipped cascade's numbers changed");
    assert!(
        colour[0] >= 42 && colour[2] <= 3 && colour[3] == 0,
        "colour + template: {colour:?}"
    );
}
