//! A small end-to-end training run (simulator data, a few stages) so the trainer cannot
//! silently break, plus resume and bad-input behaviour (issue 6, "must show").

use rccar::classes::ObjectClass;
use rccar::detect::{Cascade, DetectParams, Detector, Rect};
use rccar_train::evaluate::{group, match_boxes};
use rccar_train::features::HaarMode;
use rccar_train::model::{BoostType, ModelParams};
use rccar_train::samples::{self, Background};
use rccar_train::simgen::{GenOptions, SimGen, Split};
use rccar_train::train::{self, NoProgress, TrainOptions};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn gen(dir: &Path, split: Split, count: usize, seed: u64) -> PathBuf {
    gen_lit(dir, split, count, seed, 0)
}

/// As [`gen`], each frame at a light level 0..=`light` (docs/light.md).
fn gen_lit(dir: &Path, split: Split, count: usize, seed: u64, light: u32) -> PathBuf {
    let g = SimGen::new(
        &root().join("config/tracks/default.toml"),
        rccar::config::Config::default(),
    )
    .expect("track");
    g.generate(
        &GenOptions {
            kind: ObjectClass::StopSign,
            split,
            count,
            seed,
            distance_m: (0.2, 1.0),
            window: (16, 16),
            scenes: 4,
            light_variation: 0.0,
            light_level: light,
        },
        &dir.join(format!("{split:?}-{light}")),
        &mut |_| {},
    )
    .expect("generate")
}

fn opts(stages: u32) -> TrainOptions {
    TrainOptions {
        params: ModelParams {
            width: 16,
            height: 16,
            mode: HaarMode::Basic,
            boost: BoostType::Gentle,
            min_hit_rate: 0.995,
            max_false_alarm: 0.5,
            max_depth: 1,
            max_weak_count: 20,
            num_stages: stages,
        },
        num_pos: 150,
        num_neg: 300,
        // 64 until issue 28 made --mem-mb count the program (32 MiB, was 24) and the Haar pool:
        // 80 leaves the feature values about what 64 did (at 64 fewer features fit, and this
        // small cascade found 15 of the 20 held-out signs).
        mem_mb: 80,
        seed: 3,
        scale_factor: 1.2,
        mirror_negatives: false,
        upside_down_negatives: false,
    }
}

struct Data {
    _dir: tempfile::TempDir,
    pos: Vec<Vec<u8>>,
    bgs: Vec<Background>,
    eval: PathBuf,
    root: PathBuf,
}

fn data() -> Data {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = gen(dir.path(), Split::Positives, 200, 1);
    let n = gen(dir.path(), Split::Negatives, 30, 2);
    let e = gen(dir.path(), Split::Eval, 20, 1001);
    let (pos, sk) = samples::load_positives(&[p], 16, 16).expect("positives");
    assert!(sk.is_empty(), "{sk:?}");
    let (bgs, sk) = samples::load_backgrounds(&[n]).expect("backgrounds");
    assert!(sk.is_empty(), "{sk:?}");
    let root = dir.path().to_path_buf();
    Data {
        _dir: dir,
        pos,
        bgs,
        eval: e,
        root,
    }
}

#[test]
fn small_training_run_finds_stop_signs_and_resumes_identically() {
    let d = data();
    // 1. Three stages straight through.
    let full = d.root.join("full");
    let out = train::train(&opts(3), &d.pos, &d.bgs, &full, false, &mut NoProgress).expect("train");
    assert_eq!(out.stages, 3, "{}", out.reason);
    let xml = std::fs::read_to_string(&out.xml).expect("xml");
    let cascade = Cascade::from_xml_str(&xml, "full").expect("rccar loads it");
    assert_eq!(cascade.stages.len(), 3);
    // 2. Two stages, then "interrupted" and resumed to three: the same cascade, byte for byte.
    let part = d.root.join("part");
    train::train(&opts(2), &d.pos, &d.bgs, &part, false, &mut NoProgress).expect("train 2");
    let again = train::train(&opts(3), &d.pos, &d.bgs, &part, true, &mut NoProgress).expect("resume");
    assert_eq!(again.stages, 3);
    assert_eq!(
        std::fs::read_to_string(&again.xml).expect("xml"),
        xml,
        "resumed run differs"
    );
    // 3. It finds most held-out stop signs (a 3-stage cascade: recall high, FP not yet low).
    let (lines, _) = samples::read_info(&d.eval).expect("eval");
    let mut det = Detector::new(cascade);
    let (mut tp, mut total) = (0, 0);
    for l in &lines {
        let img = samples::load_gray(&l.path).expect("frame");
        det.detect(
            &img,
            &DetectParams {
                min_neighbors: 0,
                ..DetectParams::default()
            },
        )
        .expect("detect");
        let boxes: Vec<Rect> = group(det.raw_hits(), 1, img.width(), img.height());
        tp += match_boxes(&boxes, &l.boxes, 0.5).0;
        total += l.boxes.len();
    }
    assert!(tp as f64 >= 0.8 * total as f64, "recall {tp}/{total}");
}

#[test]
fn bad_input_is_named_skipped_or_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let img = image::GrayImage::from_fn(40, 30, |x, y| image::Luma([((x * 7 + y * 13) % 256) as u8]));
    img.save(d.join("ok.png")).expect("png");
    std::fs::write(d.join("broken.png"), b"not a png").expect("write");
    let info = d.join("info.dat");
    std::fs::write(
        &info,
        "ok.png 1 0 0 20 20\nmissing.png 1 0 0 20 20\nbroken.png 1 0 0 20 20\nok.png 1 30 20 20 20\nok.png 1 0 0 8 8\nok.png 2 0 0 20\n",
    )
    .expect("write");
    // 1. Missing/unreadable images, boxes outside, a box smaller than the window, a short line:
    // each named and skipped, the good box kept.
    let (pos, skipped) = samples::load_positives(std::slice::from_ref(&info), 16, 16).expect("loads");
    assert_eq!(pos.len(), 1);
    let text: Vec<String> = skipped.iter().map(|s| s.to_string()).collect();
    assert_eq!(skipped.len(), 5, "{text:#?}");
    assert!(
        text.iter().any(|t| t.contains(":2:") && t.contains("missing.png")),
        "{text:#?}"
    );
    assert!(
        text.iter().any(|t| t.contains(":3:") && t.contains("broken.png")),
        "{text:#?}"
    );
    assert!(
        text.iter().any(|t| t.contains(":4:") && t.contains("outside")),
        "{text:#?}"
    );
    assert!(
        text.iter()
            .any(|t| t.contains(":5:") && t.contains("smaller than the 16x16 window")),
        "{text:#?}"
    );
    assert!(text.iter().any(|t| t.contains(":6:")), "{text:#?}");
    // 2. A list file that does not exist is an error naming it.
    let e = samples::load_positives(&[d.join("nope.dat")], 16, 16).unwrap_err();
    assert!(e.to_string().contains("nope.dat"), "{e}");
    // 3. Zero negatives: no backgrounds, or only flat ones, is a clear error.
    let pos20: Vec<Vec<u8>> = (0..20)
        .map(|i| (0..256).map(|p| ((p * (i + 3)) % 251) as u8).collect())
        .collect();
    let e = train::train(&opts(2), &pos20, &[], &d.join("m1"), false, &mut NoProgress).unwrap_err();
    assert!(e.to_string().contains("no background images"), "{e}");
    let flat = Background {
        name: "flat".into(),
        img: image::GrayImage::from_pixel(64, 48, image::Luma([128])),
        avoid: vec![],
    };
    let e = train::train(&opts(2), &pos20, &[flat], &d.join("m2"), false, &mut NoProgress).unwrap_err();
    assert!(e.to_string().contains("no negative windows"), "{e}");
    // 4. A window larger than the backgrounds gives no negatives either (an error, no panic).
    let small = Background {
        name: "small".into(),
        img: image::GrayImage::from_fn(12, 12, |x, y| image::Luma([((x * 31 + y * 17) % 256) as u8])),
        avoid: vec![],
    };
    let e = train::train(&opts(2), &pos20, &[small], &d.join("m3"), false, &mut NoProgress).unwrap_err();
    assert!(e.to_string().contains("no negative windows"), "{e}");
    // 5. Positives of the wrong size and a bad window are refused.
    let e = train::train(&opts(2), &[vec![0u8; 10]], &[], &d.join("m4"), false, &mut NoProgress).unwrap_err();
    assert!(!e.to_string().is_empty());
    // 6. Resuming from a stages.json of another window size is refused, naming the file.
    let m5 = d.join("m5");
    std::fs::create_dir_all(&m5).expect("dir");
    let mut o = opts(2);
    o.params.width = 20;
    let other = train::StageFile {
        options: o,
        stages: vec![],
        log: vec![],
        finished: None,
        positives_total: 0,
        backgrounds_total: 0,
    };
    std::fs::write(m5.join("stages.json"), serde_json::to_string(&other).expect("json")).expect("write");
    let bg = Background {
        name: "tex".into(),
        img: image::GrayImage::from_fn(64, 48, |x, y| image::Luma([((x * 31 + y * 17) % 256) as u8])),
        avoid: vec![],
    };
    let e = train::train(&opts(2), &pos20, std::slice::from_ref(&bg), &m5, true, &mut NoProgress).unwrap_err();
    assert!(
        e.to_string().contains("stages.json") && e.to_string().contains("20x16"),
        "{e}"
    );
    // 7. Backgrounds that cannot supply the negatives: training stops with what to add.
    // Noise against noise: each stage can only halve the false alarms, and one 40×30 image
    // holds about 650 windows of 16×16 (scale step 1.2).
    let mut rng = rccar::sim::rng::SplitMix64::new(11);
    let few = Background {
        name: "few".into(),
        img: image::GrayImage::from_fn(40, 30, |_, _| image::Luma([(rng.next_u64() % 256) as u8])),
        avoid: vec![],
    };
    let pos_real: Vec<Vec<u8>> = (0..200)
        .map(|_| (0..256).map(|_| (rng.next_u64() % 256) as u8).collect())
        .collect();
    let mut o = opts(6);
    o.num_neg = 2000;
    let out = train::train(&o, &pos_real, &[few], &d.join("m6"), false, &mut NoProgress).expect("trains");
    assert!(out.negatives_ran_out, "{}", out.reason);
    assert!(
        out.reason.contains("negatives ran out") && out.reason.contains("add background images"),
        "{}",
        out.reason
    );
    // 8. A corrupt stages.json is refused, not a panic.
    std::fs::write(m5.join("stages.json"), "{ truncated").expect("write");
    let e = train::train(&opts(2), &pos20, &[bg], &m5, true, &mut NoProgress).unwrap_err();
    assert!(e.to_string().contains("not a stages.json"), "{e}");
}

/// `gen --light-level 3`: the frames take light levels 0..=3 at random — dusk dims most of
/// them (at levels 2 and 3 the floor and walls get 70 % and 45 % of the light), so the frames
/// are darker on the whole than the same seed's frames in steady light, and the level-0 run is
/// the same as before the option existed (no random number drawn for it).
#[test]
fn gen_light_level_darkens_the_frames_and_level_0_draws_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mean = |list: &Path| {
        let text = std::fs::read_to_string(list).unwrap();
        let (mut sum, mut n) = (0.0, 0.0);
        for line in text.lines() {
            let path = list.parent().unwrap().join(line.split_whitespace().next().unwrap());
            let img = image::open(&path).unwrap().to_luma8();
            sum += img.as_raw().iter().map(|&p| p as f64).sum::<f64>();
            n += img.as_raw().len() as f64;
        }
        sum / n
    };
    let steady = gen(dir.path(), Split::Negatives, 12, 7);
    let lit = gen_lit(dir.path(), Split::Negatives, 12, 7, 3);
    let (a, b) = (mean(&steady), mean(&lit));
    eprintln!("mean grey of 12 frames: steady light {a:.1}, light levels 0..=3 {b:.1}");
    assert!(
        b < 0.8 * a,
        "light levels 0..=3: mean grey {b:.1} against {a:.1} in steady light"
    );
    // Level 0: the pixels `gen` wrote before the option existed (main at 83e7d19; the renderer
    // is deterministic): FNV-1a over the last frame's grey pixels. A random number drawn for
    // the light when it is off would move every later frame's pose.
    let list = std::fs::read_to_string(&steady).unwrap();
    let last = list.lines().last().unwrap().split_whitespace().next().unwrap();
    let img = image::open(steady.parent().unwrap().join(last)).unwrap().to_luma8();
    let fnv = img.as_raw().iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &p| {
        (h ^ p as u64).wrapping_mul(0x100_0000_01b3)
    });
    assert_eq!(fnv, FNV_LAST_STEADY, "{fnv:#x}");
}

/// [`gen_light_level_darkens_the_frames_and_level_0_draws_nothing`]'s level-0 frame hash.
const FNV_LAST_STEADY: u64 = 0xb85f_438b_767c_c9e4;
