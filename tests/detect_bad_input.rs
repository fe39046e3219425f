//! Bad input for the cascade loader and the detector (issue 4): every case is a clean error
//! or an empty result, never a panic. Includes a proptest target on the XML loader.

use image::GrayImage;
use proptest::prelude::*;
use rccar::detect::{Cascade, CascadeError, DetectError, DetectParams, Detector};

/// A small valid cascade in the current format: 2 stages, a stump and a 2-node tree.
const GOOD: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<cascade type_id="opencv-cascade-classifier"><stageType>BOOST</stageType>
  <featureType>HAAR</featureType>
  <height>8</height>
  <width>8</width>
  <featureParams><maxCatCount>0</maxCatCount></featureParams>
  <stageNum>2</stageNum>
  <stages>
    <_>
      <maxWeakCount>1</maxWeakCount>
      <stageThreshold>-0.5</stageThreshold>
      <weakClassifiers>
        <_><internalNodes>0 -1 0 0.01</internalNodes><leafValues>-1. 1.</leafValues></_>
      </weakClassifiers></_>
    <_>
      <maxWeakCount>1</maxWeakCount>
      <stageThreshold>-0.5</stageThreshold>
      <weakClassifiers>
        <_><internalNodes>1 -1 1 0.0 0 -2 0 0.02</internalNodes><leafValues>-1. 1. 0.5</leafValues></_>
      </weakClassifiers></_>
  </stages>
  <features>
    <_><rects><_>0 0 8 4 -1.</_><_>0 4 8 4 2.</_></rects><tilted>0</tilted></_>
    <_><rects><_>4 0 4 4 -1.</_><_>4 2 2 2 2.</_></rects><tilted>1</tilted></_>
  </features>
</cascade>
</opencv_storage>
"#;

/// The same shape in the old `opencv-haar-classifier` format.
const GOOD_OLD: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<old type_id="opencv-haar-classifier">
  <size>8 8</size>
  <stages>
    <_>
      <trees><_><_>
        <feature><rects><_>0 0 8 4 -1.</_><_>0 4 8 4 2.</_></rects><tilted>0</tilted></feature>
        <threshold>0.01</threshold><left_val>-1.</left_val><right_val>1.</right_val></_></_></trees>
      <stage_threshold>-0.5</stage_threshold><parent>-1</parent><next>-1</next></_>
  </stages>
</old>
</opencv_storage>
"#;

/// A small LBP cascade: one stage, one category stump on a 3×3 grid of 2×2 cells.
const GOOD_LBP: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<cascade type_id="opencv-cascade-classifier">
  <stageType>BOOST</stageType>
  <featureType>LBP</featureType>
  <height>8</height>
  <width>8</width>
  <featureParams><maxCatCount>256</maxCatCount></featureParams>
  <stages>
    <_>
      <stageThreshold>-0.5</stageThreshold>
      <weakClassifiers>
        <_><internalNodes>0 -1 0 -1 0 0 0 0 0 0 -65536</internalNodes><leafValues>-1. 1.</leafValues></_>
      </weakClassifiers></_>
  </stages>
  <features><_><rect>1 1 2 2</rect></_></features>
</cascade>
</opencv_storage>
"#;

fn load(text: &str) -> Result<Cascade, CascadeError> {
    Cascade::from_xml_str(text, "test.xml")
}

fn err(text: &str) -> String {
    load(text).expect_err("must be rejected").to_string()
}

#[test]
fn good_cascades_load() {
    let c = load(GOOD).unwrap();
    assert_eq!(
        (c.stages.len(), c.trees.len(), c.nodes.len(), c.leaves.len()),
        (2, 2, 3, 5)
    );
    assert!(c.has_tilted);
    assert_eq!(c.max_nodes_per_tree, 2);
    let l = load(GOOD_LBP).unwrap();
    assert_eq!((l.subset_size, l.subsets.len(), l.lbp_features.len()), (8, 8, 1));
    let o = load(GOOD_OLD).unwrap();
    assert!(o.old_format);
    assert_eq!(o.stages[0].threshold, c.stages[0].threshold);
    assert_eq!(o.leaves, vec![-1.0, 1.0]);
}

#[test]
fn every_truncation_is_an_error_not_a_panic() {
    for cut in 0..GOOD.trim_end().len() {
        if !GOOD.is_char_boundary(cut) {
            continue;
        }
        assert!(load(&GOOD[..cut]).is_err(), "truncated at byte {cut} loaded");
    }
    for cut in 0..GOOD_OLD.trim_end().len() {
        assert!(
            load(&GOOD_OLD[..cut]).is_err(),
            "old format truncated at byte {cut} loaded"
        );
    }
}

#[test]
fn truncated_stock_cascade_is_an_error() {
    let path = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("skipped: {path} not installed (Debian package opencv-data)");
        return;
    };
    for frac in [0.1, 0.5, 0.9, 0.999] {
        let cut = (text.len() as f64 * frac) as usize;
        let e = Cascade::from_xml_str(&text[..cut], path).unwrap_err().to_string();
        assert!(e.contains(path) && e.contains("XML"), "{e}");
    }
}

#[test]
fn wrong_rect_counts_are_named() {
    let e = err(&GOOD.replace("0 4 8 4 2.", "0 4 8 4"));
    assert!(e.contains("5 numbers") && e.contains("test.xml:"), "{e}");
    let e = err(&GOOD.replace(
        "<_>0 4 8 4 2.</_></rects>",
        "<_>0 4 8 4 2.</_><_>0 4 8 4 2.</_><_>0 4 8 4 2.</_></rects>",
    ));
    assert!(e.contains("more than 3 rectangles"), "{e}");
    let e = err(&GOOD.replace("<rects><_>0 0 8 4 -1.</_><_>0 4 8 4 2.</_></rects>", "<rects></rects>"));
    assert!(e.contains("at least one rectangle"), "{e}");
    let e = err(&GOOD.replace("0 -1 0 0.01", "0 -1 0"));
    assert!(e.contains("<internalNodes>") && e.contains("multiple of 4"), "{e}");
    let e = err(&GOOD.replace("-1. 1. 0.5", "-1. 1."));
    assert!(e.contains("tree 1 has 2 nodes but 2 leaves"), "{e}");
}

#[test]
fn negative_and_huge_sizes_are_rejected() {
    for (from, to, want) in [
        ("<width>8</width>", "<width>-8</width>", "<width>"),
        ("<width>8</width>", "<width>99999999</width>", "<width>"),
        ("<height>8</height>", "<height>2</height>", "smaller than 3x3"),
        ("<width>8</width>", "<width>8.5</width>", "integer"),
        ("0 0 8 4 -1.", "0 0 -8 4 -1.", "leaves the 8x8 window"),
        ("0 0 8 4 -1.", "0 0 80000 4 -1.", "rectangle coordinate"),
        ("0 0 8 4 -1.", "0 0 9 4 -1.", "leaves the 8x8 window"),
        ("4 0 4 4 -1.", "2 0 4 4 -1.", "leaves the 8x8 window"),
        ("0 -1 0 0.01", "0 -1 5 0.01", "feature 5 of 2"),
        ("0 -1 0 0.01", "0 -1 -3 0.01", "negative feature"),
        ("1 -1 1 0.0", "7 -1 1 0.0", "missing child 7"),
        ("0 -1 0 0.01", "0 -1 0 nan", "not a finite number"),
        (
            "<stageThreshold>-0.5</stageThreshold>",
            "<stageThreshold>1e999</stageThreshold>",
            "finite",
        ),
    ] {
        let e = err(&GOOD.replacen(from, to, 1));
        assert!(e.contains(want), "{from} -> {to}: {e}");
    }
    for (from, to, want) in [
        ("<rect>1 1 2 2</rect>", "<rect>1 1 3 2</rect>", "leaves the 8x8 window"),
        ("<rect>1 1 2 2</rect>", "<rect>1 1 0 2</rect>", "leaves the 8x8 window"),
        ("<rect>1 1 2 2</rect>", "<rect>1 1 2</rect>", "4 integers"),
        ("0 0 0 0 -65536", "0 0 0 -65536", "multiple of 11"),
        (
            "<maxCatCount>256</maxCatCount>",
            "<maxCatCount>0</maxCatCount>",
            "maxCatCount > 0",
        ),
    ] {
        let e = err(&GOOD_LBP.replacen(from, to, 1));
        assert!(e.contains(want), "LBP {from} -> {to}: {e}");
    }
    let e = err(&GOOD_OLD.replace("<size>8 8</size>", "<size>8 -8</size>"));
    assert!(e.contains("<size>"), "{e}");
    let e = err(&GOOD_OLD.replace("<parent>-1</parent>", "<parent>3</parent>"));
    assert!(e.contains("tree-structured"), "{e}");
    assert!(err("<opencv_storage></opencv_storage>").contains("no cascade"));
    assert!(err("").contains("XML"));
    assert!(err(&GOOD.replace("HAAR", "HOG")).contains("HOG"));
}

#[test]
fn missing_file_names_the_path() {
    let e = Cascade::from_file("/nonexistent/cascade.xml").unwrap_err().to_string();
    assert!(
        e.contains("/nonexistent/cascade.xml") && e.contains("cannot read"),
        "{e}"
    );
}

#[test]
fn images_smaller_than_the_window_or_empty_give_nothing() {
    let mut d = Detector::new(load(GOOD).unwrap());
    let p = DetectParams::default();
    for (w, h) in [(0, 0), (0, 10), (10, 0), (7, 7), (7, 100), (100, 7)] {
        assert_eq!(d.detect(&GrayImage::new(w, h), &p), Ok(vec![]), "{w}x{h}");
    }
    // min_size above the image, max_size below the window: no scales, nothing.
    let img = GrayImage::from_fn(40, 30, |x, y| image::Luma([((x * 7 + y * 13) % 256) as u8]));
    for p in [
        DetectParams {
            min_size: (1000, 1000),
            ..p
        },
        DetectParams { max_size: (4, 4), ..p },
    ] {
        assert_eq!(d.detect(&img, &p), Ok(vec![]));
    }
}

#[test]
fn bad_parameters_are_errors() {
    let mut d = Detector::new(load(GOOD).unwrap());
    let img = GrayImage::new(20, 20);
    for sf in [1.0, 0.5, -2.0, f64::NAN, f64::INFINITY] {
        let p = DetectParams {
            scale_factor: sf,
            ..Default::default()
        };
        assert!(
            matches!(d.detect(&img, &p), Err(DetectError::BadScaleFactor(_))),
            "{sf}"
        );
    }
    assert!(matches!(
        d.detect_gray(&[0u8; 10], 20, 20, &DetectParams::default()),
        Err(DetectError::BufferTooSmall { len: 10, .. })
    ));
    let big = GrayImage::new(5000, 5000);
    assert_eq!(
        d.detect(&big, &DetectParams::default()),
        Err(DetectError::ImageTooLarge(5000, 5000))
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// Random bytes never panic the loader.
    #[test]
    fn loader_survives_random_text(s in "\\PC{0,300}") {
        let _ = load(&s);
    }

    /// A valid cascade with one byte replaced, one span deleted or a number swapped for an
    /// arbitrary token loads or fails cleanly, and a loaded one can run.
    #[test]
    fn loader_survives_mutations(base in prop::sample::select(vec![GOOD, GOOD_OLD, GOOD_LBP]),
                                 pos in 0usize..880, len in 0usize..40, byte in 0x20u8..0x7f,
                                 token in prop::sample::select(vec!["-1", "0", "99999", "-99999", "1e40", "nan", "", "1 2", "x", "2147483648", "-2147483649", "4.5"]),
                                 which in 0usize..3) {
        let mut s = base.as_bytes().to_vec();
        let pos = pos % s.len();
        match which {
            0 => s[pos] = byte,
            1 => { let end = (pos + len).min(s.len()); s.drain(pos..end); }
            _ => {
                // Replace the number token that contains `pos` (if any).
                let is_num = |c: u8| c.is_ascii_digit() || c == b'.' || c == b'-' || c == b'e';
                if is_num(s[pos]) {
                    let mut a = pos; while a > 0 && is_num(s[a - 1]) { a -= 1; }
                    let mut b = pos; while b < s.len() && is_num(s[b]) { b += 1; }
                    s.splice(a..b, token.bytes());
                }
            }
        }
        if let Ok(text) = String::from_utf8(s) {
            if let Ok(c) = load(&text) {
                let img = GrayImage::from_fn(24, 20, |x, y| image::Luma([((x * 37 + y * 101) % 256) as u8]));
                let mut d = Detector::new(c);
                let _ = d.detect(&img, &DetectParams { min_neighbors: 0, ..Default::default() });
            }
        }
    }
}
