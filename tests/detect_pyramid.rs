//! One pyramid for several cascades (issue 13): `DetectStage` builds each scale once and runs
//! every cascade on it. These tests check that this changes no box:
//!
//! 1. every cascade's boxes (and raw hits, in order) from the shared pyramid are the ones it
//!    finds alone (which `tests/parity/detect_parity.py` checks against OpenCV), for cascades of
//!    different window sizes (the shipped 16×16, 8×20, 20×16 and stock 24×24, 20×20, 14×28
//!    tilted, LBP) with different size limits, sequential and parallel;
//! 2. with a region, the raw hits are exactly the full-frame hits whose boxes lie inside it
//!    (OpenCV's skip chain is reproduced at the region's left edge), and the boxes are those
//!    hits grouped;
//! 3. rows outside `rows_needed` do not matter: overwriting them changes nothing;
//! 4. in parallel, with the large levels cut into bands of window rows, every cascade's raw
//!    hits are its sequential ones in the same order.
//!
//! Images: OpenCV's sample photos (Debian `opencv-doc`), simulator frames of the scenario
//! track, a seeded noise-and-shapes scene.

use image::GrayImage;
use rccar::detect::group::group_rectangles;
use rccar::detect::{Cascade, CascadeSpec, DetectParams, DetectStage, Detector, Rect};
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const DOC: &str = "/usr/share/doc/opencv-doc/examples/data/";

fn cascades() -> Vec<(String, Cascade, DetectParams)> {
    let p = |mn: u32, min: u32, max: u32| DetectParams {
        min_neighbors: mn,
        min_size: (min, min),
        max_size: (max, max),
        ..Default::default()
    };
    let mut out = vec![];
    for (name, path, params) in [
        ("stop_sign", format!("{ROOT}/config/cascades/stop_sign.xml"), p(3, 0, 0)),
        (
            "traffic_light",
            format!("{ROOT}/config/cascades/traffic_light.xml"),
            p(2, 22, 0),
        ),
        ("obstacle", format!("{ROOT}/config/cascades/obstacle.xml"), p(3, 0, 90)),
        (
            "face",
            "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml".into(),
            p(3, 30, 0),
        ),
        (
            "eye",
            "/usr/share/opencv4/haarcascades/haarcascade_eye.xml".into(),
            p(1, 0, 0),
        ),
        (
            "body",
            "/usr/share/opencv4/haarcascades/haarcascade_fullbody.xml".into(),
            p(1, 0, 0),
        ),
        (
            "lbp_face",
            "/usr/share/opencv4/lbpcascades/lbpcascade_frontalface.xml".into(),
            p(2, 0, 0),
        ),
    ] {
        if Path::new(&path).is_file() {
            out.push((name.to_string(), Cascade::from_file(&path).unwrap(), params));
        } else {
            eprintln!("skipped: {path} not installed");
        }
    }
    out
}

fn images() -> Vec<(String, GrayImage)> {
    let mut out = vec![];
    for name in ["messi5.jpg", "baboon.jpg", "home.jpg", "lena.jpg", "stop_sign.jpg"] {
        let p = PathBuf::from(DOC).join(name);
        if let Ok(img) = image::open(&p) {
            let g = img.to_luma8();
            let g = image::imageops::resize(&g, 320, 240, image::imageops::FilterType::Triangle);
            out.push((name.to_string(), g));
        }
    }
    // Simulator frames on the approaches to the scenario track's objects.
    let cfg = rccar::config::Config::default();
    let track = rccar::sim::track::Track::load(&Path::new(ROOT).join("config/tracks/scenarios.toml")).unwrap();
    for s in [3.0, 35.6, 37.2] {
        let mut sim = rccar::sim::run::Simulation::new(&cfg, &track).unwrap();
        sim.place_at(s);
        sim.step();
        let rgb = sim.image().clone();
        let mut g = GrayImage::new(0, 0);
        rccar::detect::gray_from_rgb(&rgb, &mut g);
        out.push((format!("sim@{s}"), g));
    }
    let mut seed = 99u32;
    out.push((
        "noise+shapes".into(),
        GrayImage::from_fn(211, 157, |x, y| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = if (x / 23 + y / 17) % 3 == 0 { 200 } else { 60 };
            image::Luma([(v + (seed >> 26)) as u8])
        }),
    ));
    out
}

fn stage(cs: &[(String, Cascade, DetectParams)]) -> DetectStage {
    DetectStage::from_cascades(
        cs.iter()
            .map(|(n, c, p)| {
                (
                    CascadeSpec {
                        label: n.clone(),
                        path: PathBuf::new(),
                        traffic_light: false,
                        params: *p,
                    },
                    c.clone(),
                )
            })
            .collect(),
    )
}

fn inside(b: &Rect, r: &Rect) -> bool {
    b.x >= r.x && b.y >= r.y && b.x + b.width <= r.x + r.width && b.y + b.height <= r.y + r.height
}

#[test]
fn shared_pyramid_gives_each_cascades_own_boxes() {
    let cs = cascades();
    let imgs = images();
    assert!(cs.len() >= 3 && imgs.len() >= 4);
    let (mut boxes, mut runs) = (0, 0);
    for parallel in [false, true] {
        let mut st = stage(&cs);
        st.set_parallel(parallel);
        for (name, g) in &imgs {
            let found = st.run(g, None).unwrap();
            for (label, c, p) in &cs {
                let alone = Detector::new(c.clone()).detect(g, p).unwrap();
                let shared: Vec<_> = found.iter().filter(|o| &o.label == label).collect();
                assert_eq!(shared.len(), alone.len(), "{label} on {name} (parallel {parallel})");
                for (s, a) in shared.iter().zip(&alone) {
                    assert_eq!((s.rect, s.neighbors), (a.rect, a.neighbors), "{label} on {name}");
                }
                boxes += alone.len();
                runs += 1;
            }
        }
    }
    println!(
        "shared pyramid: {runs} cascade runs ({} cascades x {} images x seq/par), {boxes} boxes, 0 differing",
        cs.len(),
        imgs.len()
    );
}

/// In parallel the large levels are cut into bands of window rows, shared by the threads as
/// each becomes free: every cascade's raw hits (minNeighbors 0: each window that passed) are
/// still exactly its sequential ones, in the same order, on every image and in a region.
#[test]
fn parallel_bands_give_the_sequential_raw_hits_in_order() {
    let cs: Vec<_> = cascades()
        .into_iter()
        .map(|(n, c, p)| (n, c, DetectParams { min_neighbors: 0, ..p }))
        .collect();
    let imgs = images();
    let (mut hits, mut runs) = (0, 0);
    for (name, g) in &imgs {
        let (w, h) = (g.width() as i32, g.height() as i32);
        for region in [None, Some(Rect::new(9, h / 5 + 1, w - 20, h * 3 / 5))] {
            let mut st = stage(&cs);
            st.set_parallel(true);
            for (n, _, _) in &cs {
                st.set_region(n, region);
            }
            let found = st.run(g, None).unwrap();
            for (label, c, p) in &cs {
                let mut d = Detector::new(c.clone());
                d.detect(g, p).unwrap();
                let frame = Rect::new(0, 0, w, h);
                let want: Vec<Rect> = d
                    .raw_hits()
                    .iter()
                    .filter(|b| region.is_none_or(|r| inside(b, &r)))
                    .map(|b| b.intersect(&frame))
                    .filter(|b| b.area() > 0)
                    .collect();
                let got: Vec<Rect> = found.iter().filter(|o| &o.label == label).map(|o| o.rect).collect();
                assert_eq!(got, want, "{label} on {name} in {region:?}");
                hits += want.len();
                runs += 1;
            }
        }
    }
    assert!(hits > 300, "too few raw hits to tell: {hits}");
    println!("parallel bands: {runs} cascade runs, {hits} raw hits, all identical and in order");
}

#[test]
fn a_region_keeps_exactly_the_hits_inside_it() {
    let cs = cascades();
    let imgs = images();
    let (mut kept, mut total, mut runs) = (0, 0, 0);
    for (name, g) in &imgs {
        let (w, h) = (g.width() as i32, g.height() as i32);
        // Regions with odd edges, so the region's left edge cuts the skip chain anywhere.
        for r in [
            Rect::new(w / 2 - 1, 0, w - w / 2 + 1, h * 2 / 3),
            Rect::new(7, h / 3 + 3, w / 2 + 5, h - h / 3 - 3),
            Rect::new(13, 11, w - 30, h - 25),
            Rect::new(-20, -20, w + 40, h + 40),
        ] {
            let raw: Vec<_> = cs
                .iter()
                .map(|(n, c, p)| (n.clone(), c.clone(), DetectParams { min_neighbors: 0, ..*p }))
                .collect();
            let mut st = stage(&raw);
            let mut grouped = stage(&cs);
            for (n, _, _) in &cs {
                st.set_region(n, Some(r));
                grouped.set_region(n, Some(r));
            }
            let found = st.run(g, None).unwrap();
            let found_g = grouped.run(g, None).unwrap();
            for (label, c, p) in &cs {
                let mut d = Detector::new(c.clone());
                d.detect(g, &DetectParams { min_neighbors: 0, ..*p }).unwrap();
                let want: Vec<Rect> = d.raw_hits().iter().copied().filter(|b| inside(b, &r)).collect();
                let got: Vec<Rect> = found.iter().filter(|o| &o.label == label).map(|o| o.rect).collect();
                // Raw hits come out clipped to the frame (as OpenCV's clipObjects does).
                let frame = Rect::new(0, 0, w, h);
                let want_clipped: Vec<Rect> = want
                    .iter()
                    .map(|b| b.intersect(&frame))
                    .filter(|b| b.area() > 0)
                    .collect();
                assert_eq!(got, want_clipped, "{label} on {name} in {r:?}");
                let groups: Vec<_> = group_rectangles(&want, p.min_neighbors as i32, 0.2)
                    .into_iter()
                    .map(|(b, n)| (b.intersect(&Rect::new(0, 0, w, h)), n))
                    .filter(|(b, _)| b.area() > 0)
                    .collect();
                let got_g: Vec<_> = found_g
                    .iter()
                    .filter(|o| &o.label == label)
                    .map(|o| (o.rect, o.neighbors))
                    .collect();
                assert_eq!(got_g, groups, "{label} on {name} in {r:?} grouped");
                kept += want.len();
                total += d.raw_hits().len();
                runs += 1;
            }
        }
    }
    println!("regions: {runs} runs, {kept} of {total} raw hits inside their regions, all identical, 0 differing");
}

#[test]
fn rows_outside_rows_needed_do_not_matter() {
    let cs = cascades();
    let imgs = images();
    let mut st = stage(&cs);
    let (mut checked, mut skipped_rows) = (0, 0);
    for (name, g) in &imgs {
        let (w, h) = (g.width() as i32, g.height() as i32);
        for (n, _, _) in &cs {
            st.set_region(n, Some(Rect::new(w / 2, 5, w / 2, h / 2)));
        }
        st.set_region("obstacle", Some(Rect::new(0, h / 2 + 10, w, h / 2 - 10)));
        let spans = st.rows_needed(g.width(), g.height());
        assert!(!spans.is_empty());
        let want = st.run(g, None).unwrap();
        let mut other = g.clone();
        for y in 0..g.height() as usize {
            if !spans.iter().any(|s| s.contains(&y)) {
                skipped_rows += 1;
                for x in 0..g.width() {
                    other.put_pixel(x, y as u32, image::Luma([(x * 37 % 251) as u8]));
                }
            }
        }
        assert_eq!(st.run(&other, None).unwrap(), want, "{name}: rows {spans:?}");
        checked += 1;
    }
    assert!(skipped_rows > 0);
    println!("rows_needed: {checked} images, {skipped_rows} rows outside the spans overwritten, boxes unchanged");
}
