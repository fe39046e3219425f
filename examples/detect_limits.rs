//! Where and how big the detectors' boxes are in the simulator (issue 13): the figures behind
//! the `[detect]` regions and size limits. Drives the car along config/tracks/scenarios.toml
//! (every 5 cm) and, for each object in view at 0.2–2 m, matches the shipped cascade's boxes
//! (no region, no size limit) to the true box (IoU ≥ 0.3), and prints per class: the boxes'
//! extent in the frame (fractions of width/height), their widths against f·W/d (box width over
//! the predicted width of the object), and the true boxes' extent.
//!
//! `cargo run --release --example detect_limits`

use rccar::classes::ObjectClass;
use rccar::config::Config;
use rccar::detect::Rect;
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use std::path::Path;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cfg = Config::default();
    cfg.sim.noise_sigma = 2.0;
    let track = Track::load(&root.join("config/tracks/scenarios.toml")).unwrap();
    let (det, _) = rccar::pipeline::load_detector(&cfg, root).unwrap();
    let mut det = det.expect("cascades");
    for l in ["stop_sign", "traffic_light", "obstacle"] {
        det.set_limits(l, None, (0, 0), (0, 0));
    }
    let f_px = rccar::camera::PinholeCamera::from(&cfg.camera).f_px;
    let (w, h) = (cfg.camera.width as f64, cfg.camera.height as f64);
    let mut sim = Simulation::new(&cfg, &track).unwrap();
    let len = track.length;
    // per class: (min x0, min y0, max x1, max y1) of matched boxes, ratios, count; truth extent
    type ClassStats = (Vec<[f64; 4]>, Vec<(f64, f64)>, Vec<[f64; 4]>);
    let mut stats: std::collections::BTreeMap<String, ClassStats> = Default::default();
    let mut s = 0.0;
    while s < len {
        sim.place_at(s);
        let step = sim.step();
        s += 0.05;
        let objs: Vec<_> = step
            .truth
            .objects
            .iter()
            .filter(|o| o.distance_m >= 0.2 && o.distance_m <= 2.0 && !o.clipped)
            .cloned()
            .collect();
        if objs.is_empty() {
            continue;
        }
        let found = det.run_rgb(sim.image()).unwrap();
        for o in &objs {
            let label = format!("{:?}", o.kind);
            let t = o.bbox;
            let tr = Rect::new(
                t[0].round() as i32,
                t[1].round() as i32,
                (t[2] - t[0]).round() as i32,
                (t[3] - t[1]).round() as i32,
            );
            let e = stats.entry(label.clone()).or_default();
            e.2.push([t[0] / w, t[1] / h, t[2] / w, t[3] / h]);
            for b in found
                .iter()
                .filter(|b| ObjectClass::from_label(&b.label) == Some(o.kind))
            {
                if b.rect.iou(&tr) >= 0.3 {
                    let r = b.rect;
                    e.0.push([
                        r.x as f64 / w,
                        r.y as f64 / h,
                        (r.x + r.width) as f64 / w,
                        (r.y + r.height) as f64 / h,
                    ]);
                    // box width × distance / f: the object width the box stands for, metres
                    e.1.push((o.distance_m, r.width as f64 * o.distance_m / f_px));
                }
            }
        }
    }
    for (k, (boxes, ratios, truth)) in &stats {
        let ext = |v: &[[f64; 4]]| {
            v.iter().fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |a, b| {
                [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
            })
        };
        let wm: Vec<f64> = ratios.iter().map(|r| r.1).collect();
        let (mn, mx) = wm.iter().fold((f64::MAX, f64::MIN), |a, &b| (a.0.min(b), a.1.max(b)));
        let dmin = ratios.iter().map(|r| r.0).fold(f64::MAX, f64::min);
        let dmax = ratios.iter().map(|r| r.0).fold(f64::MIN, f64::max);
        println!(
            "{k:>13}: {} matched boxes at {dmin:.2}..{dmax:.2} m; box extent {:.3?}; truth extent {:.3?} ({} views); box width·d/f = {mn:.3}..{mx:.3} m",
            boxes.len(),
            ext(boxes),
            ext(truth),
            truth.len()
        );
    }
}
