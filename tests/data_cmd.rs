//! `rccar data` (issue 29): a simulated drive is cut, merged, exported to a Donkey tub v2,
//! read back by a small reader of this file's own (serde_json and image only, nothing of
//! `rccar::dataset`), imported again and replayed; a tub made here is imported; bad input is
//! refused or skipped with the file and line named, and inputs are never changed.

use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn rccar(args: &[&str], paths: &[&Path]) -> Output {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut c = Command::new(env!("CARGO_BIN_EXE_rccar"));
    c.current_dir(root).args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().expect("rccar runs")
}

/// A command's exit code, stdout and stderr, for assertion messages.
pub(crate) fn text(o: &Output) -> String {
    format!(
        "exit {:?}\n--- stdout\n{}--- stderr\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn lines(p: &Path) -> Vec<String> {
    std::fs::read_to_string(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        .lines()
        .map(String::from)
        .collect()
}

fn json_lines(p: &Path) -> Vec<Value> {
    lines(p).iter().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// Every file under `dir` with its bytes (to prove an input was not changed).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.as_raw().len() as f64
}

/// A tub v2 read as Donkey's datastore_v2 does, in a few lines: the manifest's five JSON lines,
/// the catalogs in its order, each `.catalog_manifest` checked against its catalog, records
/// at deleted positions left out. Returns (position, record) pairs.
pub(crate) fn read_tub_independently(tub: &Path) -> Vec<(u64, Value)> {
    let m = lines(&tub.join("manifest.json"));
    assert_eq!(m.len(), 5, "manifest.json has 5 lines: {m:?}");
    let inputs: Value = serde_json::from_str(&m[0]).unwrap();
    let types: Value = serde_json::from_str(&m[1]).unwrap();
    assert_eq!(
        inputs,
        serde_json::json!(["cam/image_array", "user/angle", "user/throttle", "user/mode"])
    );
    assert_eq!(types, serde_json::json!(["image_array", "float", "float", "str"]));
    let _user_meta: Value = serde_json::from_str(&m[2]).unwrap();
    let meta: Value = serde_json::from_str(&m[3]).unwrap();
    assert!(
        meta["created_at"].as_f64().is_some() && meta["sessions"]["last_id"].as_u64().is_some(),
        "{meta}"
    );
    let cat: Value = serde_json::from_str(&m[4]).unwrap();
    let deleted: Vec<u64> = cat["deleted_indexes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let mut out = Vec::new();
    let mut pos = 0u64;
    for p in cat["paths"].as_array().unwrap() {
        let name = p.as_str().unwrap();
        let body = std::fs::read_to_string(tub.join(name)).unwrap();
        let stem = name.strip_suffix(".catalog").unwrap();
        let cm: Value =
            serde_json::from_str(&std::fs::read_to_string(tub.join(format!("{stem}.catalog_manifest"))).unwrap())
                .unwrap();
        assert_eq!(cm["start_index"].as_u64(), Some(pos), "{name}");
        assert_eq!(cm["path"].as_str(), Some(format!("{stem}.catalog_manifest").as_str()));
        // Donkey seeks by these lengths: each is the line's length with its newline.
        let lens: Vec<u64> = body.split_inclusive('\n').map(|l| l.len() as u64).collect();
        let want: Vec<u64> = cm["line_lengths"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(lens, want, "{name}: line_lengths");
        for l in body.lines() {
            if !deleted.contains(&pos) {
                out.push((pos, serde_json::from_str(l).unwrap()));
            }
            pos += 1;
        }
    }
    assert_eq!(cat["current_index"].as_u64(), Some(pos));
    out
}

#[test]
fn sim_drive_cut_merge_export_read_back_import_and_replay() {
    let tmp = tempfile::tempdir().unwrap();
    let t = |n: &str| tmp.path().join(n);
    // 1. 20 s of the simulator, detection off so that the car reaches the first curve.
    let o = rccar(
        &[
            "sim",
            "--seconds",
            "20",
            "--no-timing",
            "--set",
            "detect.enabled=false",
            "--record",
        ],
        &[&t("frames"), Path::new("-o"), &t("run")],
    );
    assert!(o.status.code().is_some(), "{}", text(&o));
    let run_tel = t("run").join("telemetry.jsonl");
    let sim_lines = lines(&run_tel);
    assert_eq!(sim_lines.len(), 600);
    let before = snapshot(&t("frames"));

    // 2. Cut frames 100..200 and 550.. out: 450 left, numbered and timed as they were.
    let o = rccar(
        &["data", "cut", "--drop", "100..200", "--drop", "550..", "--telemetry"],
        &[&run_tel, &t("frames"), Path::new("-o"), &t("cut")],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("cut: 450 of 600 frames kept (150 dropped by 2 range(s))"),
        "{}",
        text(&o)
    );
    let cut_lines = lines(&t("cut").join("telemetry.jsonl"));
    let kept: Vec<usize> = (0..100).chain(200..550).collect();
    assert_eq!(cut_lines.len(), 450);
    for (l, &k) in cut_lines.iter().zip(&kept) {
        assert_eq!(l, &sim_lines[k], "a cut line is the recorded line, unchanged");
    }
    let seg = |s: &str| {
        let mut v: Vec<String> = std::fs::read_dir(t("cut").join(s))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    };
    let (s0, s1) = (seg("seg_000000"), seg("seg_000001"));
    assert_eq!((s0.len(), s1.len()), (200, 250));
    assert_eq!(
        (s0[99].as_str(), s0[100].as_str()),
        ("frame_000000099.jpg", "frame_000000200.jpg")
    );
    assert_eq!(s1.last().unwrap(), "frame_000000549.jpg");
    // `ls` says the same.
    let o = rccar(&["data", "ls", "--json"], &[&t("cut")]);
    assert!(o.status.success(), "{}", text(&o));
    let ls: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(ls["stats"]["frames"], 450);
    assert_eq!(ls["stats"]["frame_span"], serde_json::json!([0, 549]));
    assert_eq!(ls["frame_size"], serde_json::json!([320, 240]));

    // 3. Frames 500..599 on their own, then merged after the first cut: 550 frames, 0..549.
    let o = rccar(
        &["data", "cut", "--drop", "..500", "--telemetry"],
        &[&run_tel, &t("frames"), Path::new("-o"), &t("tail")],
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = rccar(
        &["data", "merge"],
        &[&t("cut"), &t("tail"), Path::new("-o"), &t("merged")],
    );
    assert!(o.status.success(), "{}", text(&o));
    let merged = json_lines(&t("merged").join("telemetry.jsonl"));
    assert_eq!(merged.len(), 550);
    let sim: Vec<Value> = sim_lines.iter().map(|l| serde_json::from_str(l).unwrap()).collect();
    let origin: Vec<usize> = kept.iter().copied().chain(500..600).collect();
    for (k, (m, &o)) in merged.iter().zip(&origin).enumerate() {
        assert_eq!(m["frame"], k as u64);
        assert_eq!(m["dataset"]["frame"], o as u64);
        assert_eq!(
            (&m["steer"], &m["throttle"]),
            (&sim[o]["steer"], &sim[o]["throttle"]),
            "frame {k}"
        );
    }
    // The second part starts one frame (1/30 s) after the first part's last frame.
    let (t449, t450) = (
        merged[449]["time_s"].as_f64().unwrap(),
        merged[450]["time_s"].as_f64().unwrap(),
    );
    assert!((t450 - t449 - 1.0 / 30.0).abs() < 1e-9, "{t449} {t450}");

    // 4. Export to a tub and read it back with the reader above.
    let o = rccar(&["data", "export", "--tub"], &[&t("tub"), &t("merged")]);
    assert!(o.status.success(), "{}", text(&o));
    let recs = read_tub_independently(&t("tub"));
    assert_eq!(recs.len(), 550);
    let mut worst: f64 = 0.0;
    for (k, (pos, r)) in recs.iter().enumerate() {
        let o = origin[k];
        assert_eq!(*pos, k as u64);
        assert_eq!(r["_index"], k as u64);
        // Labels exactly (the sim's lines have no `sent`: the command is the label).
        assert_eq!(r["user/angle"], sim[o]["steer"], "record {k}");
        assert_eq!(r["user/throttle"], sim[o]["throttle"], "record {k}");
        assert_eq!(r["user/mode"], "local");
        let name = r["cam/image_array"].as_str().unwrap();
        assert_eq!(name, format!("{k}_cam_image_array_.jpg"));
        // Time: ms after the first record, as the merged recording's.
        let ms = r["_timestamp_ms"].as_i64().unwrap() - recs[0].1["_timestamp_ms"].as_i64().unwrap();
        assert!(
            (ms as f64 - merged[k]["time_s"].as_f64().unwrap() * 1000.0).abs() <= 0.5,
            "record {k}: {ms} ms"
        );
        // Images: the sim's PNG frame within JPEG's loss (quality 90).
        if k % 25 == 0 {
            let got = image::open(t("tub").join("images").join(name)).unwrap().to_rgb8();
            let want = image::open(t("frames").join(format!("frame_{o:06}.png")))
                .unwrap()
                .to_rgb8();
            worst = worst.max(mean_abs_diff(&got, &want));
        }
    }
    eprintln!("tub images vs the simulator's PNG frames: worst mean |diff| {worst:.2} grey levels");
    assert!(worst < 3.0, "{worst}");

    // 5. Import the tub again: the same labels, frames byte for byte; replay plays it.
    let o = rccar(&["data", "import"], &[&t("tub"), Path::new("-o"), &t("imported")]);
    assert!(o.status.success(), "{}", text(&o));
    let imp = json_lines(&t("imported").join("telemetry.jsonl"));
    assert_eq!(imp.len(), 550);
    for (k, l) in imp.iter().enumerate() {
        assert_eq!(l["frame"], k as u64);
        assert_eq!(
            (&l["steer"], &l["throttle"]),
            (&merged[k]["steer"], &merged[k]["throttle"])
        );
        assert_eq!(l["drive_mode"], "autopilot");
    }
    let a = std::fs::read(t("imported").join("seg_000001/frame_000000321.jpg")).unwrap();
    let b = std::fs::read(t("tub").join("images/321_cam_image_array_.jpg")).unwrap();
    assert!(a == b, "an imported JPEG is the tub's, byte for byte");
    let o = rccar(
        &[
            "replay",
            "--no-annotate",
            "--no-timing",
            "--set",
            "detect.enabled=false",
        ],
        &[&t("imported"), Path::new("-o"), &t("replayed")],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("replayed 550 frames"),
        "{}",
        text(&o)
    );
    assert_eq!(lines(&t("replayed").join("telemetry.jsonl")).len(), 550);

    // A simulator's run folder holds the telemetry, not the frames: said so.
    let o = rccar(&["data", "ls"], &[&t("run")]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("none of the 600 frames of"),
        "{}",
        text(&o)
    );

    // Inputs untouched all along.
    assert!(snapshot(&t("frames")) == before, "the recorded frames were changed");
}

/// One of the tub's images: stripes that move with `k`, 160 × 120 like Donkey's camera.
fn stripes(k: u32) -> image::RgbImage {
    image::RgbImage::from_fn(160, 120, |x, y| {
        let v = if (x + 4 * k) % 20 < 10 { 220 } else { 30 };
        image::Rgb([v, (y * 2) as u8, 100])
    })
}

/// Writes a tub v2 as Donkey does: 25 records in catalogs of 10, positions 3 and 12 deleted,
/// record 7 driven by the pilot's steering and 8 by the pilot alone.
fn make_tub(dir: &Path) -> Vec<(f64, f64, &'static str, i64)> {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut labels = Vec::new();
    let mut cats: Vec<String> = Vec::new();
    for k in 0..25u32 {
        let angle = ((k as f64) * 0.37).sin() * 0.8;
        let throttle = 0.25 + 0.01 * k as f64;
        let mode = match k {
            7 => "local_angle",
            8 => "local",
            _ => "user",
        };
        let ts = 1_637_997_839_367 + 50 * k as i64;
        let name = format!("{k}_cam_image_array_.jpg");
        stripes(k).save(dir.join("images").join(&name)).unwrap();
        let rec = serde_json::json!({
            "_index": k, "_session_id": "21-11-27_0", "_timestamp_ms": ts,
            "cam/image_array": name, "user/angle": angle, "user/mode": mode, "user/throttle": throttle,
        });
        if k % 10 == 0 {
            cats.push(String::new());
        }
        let c = cats.last_mut().unwrap();
        c.push_str(&rec.to_string());
        c.push('\n');
        labels.push((angle, throttle, mode, ts));
    }
    let mut paths = Vec::new();
    for (i, c) in cats.iter().enumerate() {
        std::fs::write(dir.join(format!("catalog_{i}.catalog")), c).unwrap();
        let lens: Vec<usize> = c.split_inclusive('\n').map(str::len).collect();
        let cm = serde_json::json!({"created_at": 1.5, "line_lengths": lens, "path": format!("catalog_{i}.catalog_manifest"), "start_index": i * 10});
        std::fs::write(dir.join(format!("catalog_{i}.catalog_manifest")), format!("{cm}\n")).unwrap();
        paths.push(format!("catalog_{i}.catalog"));
    }
    let manifest = format!(
        "[\"cam/image_array\", \"user/angle\", \"user/throttle\", \"user/mode\"]\n[\"image_array\", \"float\", \"float\", \"str\"]\n{{}}\n{{\"created_at\": 1.5, \"sessions\": {{\"all_full_ids\": [\"21-11-27_0\"], \"last_id\": 0, \"last_full_id\": \"21-11-27_0\"}}}}\n{}\n",
        serde_json::json!({"paths": paths, "current_index": 25, "max_len": 10, "deleted_indexes": [3, 12]})
    );
    std::fs::write(dir.join("manifest.json"), manifest).unwrap();
    labels
}

#[test]
fn a_tub_made_here_is_listed_and_imported() {
    let tmp = tempfile::tempdir().unwrap();
    let tub = tmp.path().join("tub");
    let labels = make_tub(&tub);
    let before = snapshot(&tub);
    // ls: 23 frames (2 deleted), modes and the steering bins counted here by hand.
    let o = rccar(&["data", "ls", "--json"], &[&tub]);
    assert!(o.status.success(), "{}", text(&o));
    let ls: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(ls["kind"], "Donkey tub v2");
    assert_eq!(ls["deleted"], 2);
    assert_eq!(ls["frame_size"], serde_json::json!([160, 120]));
    assert_eq!(ls["stats"]["frames"], 23);
    assert_eq!(
        ls["stats"]["modes"],
        serde_json::json!([["manual", 21], ["assisted", 1], ["autopilot", 1]])
    );
    let edges = [-1.0, -0.8, -0.6, -0.4, -0.2, -0.05, 0.05, 0.2, 0.4, 0.6, 0.8, 1.0];
    let mut hist = [0u64; 11];
    let mut left_straight_right = [0u64; 3];
    for (k, (a, ..)) in labels.iter().enumerate() {
        if k == 3 || k == 12 {
            continue;
        }
        hist[edges[1..11].iter().take_while(|&&e| *a >= e).count()] += 1;
        left_straight_right[if *a < -0.05 {
            0
        } else if *a < 0.05 {
            1
        } else {
            2
        }] += 1;
    }
    assert_eq!(ls["stats"]["steer_hist"], serde_json::json!(hist));
    assert_eq!(
        ls["stats"]["steer_left_straight_right"],
        serde_json::json!(left_straight_right)
    );
    eprintln!("steer histogram of the made tub: {hist:?}, left/straight/right {left_straight_right:?}");
    assert!((ls["stats"]["duration_s"].as_f64().unwrap() - 1.2).abs() < 1e-9);

    // import: frame numbers are Donkey's positions, times from _timestamp_ms, JPEGs copied.
    let out = tmp.path().join("rec");
    let o = rccar(&["data", "import"], &[&tub, Path::new("-o"), &out]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("import: 23 frames"),
        "{}",
        text(&o)
    );
    let tel = json_lines(&out.join("telemetry.jsonl"));
    let want: Vec<usize> = (0..25).filter(|k| *k != 3 && *k != 12).collect();
    assert_eq!(tel.len(), want.len());
    for (l, &k) in tel.iter().zip(&want) {
        let (angle, throttle, mode, ts) = labels[k];
        assert_eq!(l["frame"], k as u64);
        assert_eq!(l["steer"].as_f64(), Some(angle), "frame {k}");
        assert_eq!(l["throttle"].as_f64(), Some(throttle), "frame {k}");
        let m = match mode {
            "user" => "manual",
            "local_angle" => "assisted",
            _ => "autopilot",
        };
        assert_eq!(l["drive_mode"], m, "frame {k}");
        assert!((l["time_s"].as_f64().unwrap() - (ts - labels[0].3) as f64 / 1000.0).abs() < 1e-12);
        let a = std::fs::read(out.join(format!("seg_000000/frame_{k:09}.jpg"))).unwrap();
        assert!(a == std::fs::read(tub.join(format!("images/{k}_cam_image_array_.jpg"))).unwrap());
    }
    // The small frames replay once made the camera's size (the ROI needs 309 × 151).
    let big = tmp.path().join("big");
    let o = rccar(&["data", "import", "--size", "320x240"], &[&tub, Path::new("-o"), &big]);
    assert!(o.status.success(), "{}", text(&o));
    let o = rccar(
        &[
            "replay",
            "--no-annotate",
            "--no-timing",
            "--set",
            "detect.enabled=false",
        ],
        &[&big, Path::new("-o"), &tmp.path().join("replayed")],
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("replayed 23 frames"),
        "{}",
        text(&o)
    );
    assert!(snapshot(&tub) == before, "the tub was changed");
}

#[test]
fn bad_tubs_are_refused_or_their_bad_records_skipped_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    let fresh = |name: &str| {
        let d = tmp.path().join(name);
        make_tub(&d);
        d
    };
    let import = |tub: &Path, out: &str| rccar(&["data", "import"], &[tub, Path::new("-o"), &tmp.path().join(out)]);

    // One record not JSON, one image missing: skipped and named, the rest imported, exit 1.
    let tub = fresh("torn");
    let cat = tub.join("catalog_0.catalog");
    let mut l = lines(&cat);
    l[4] = l[4][..40].to_string();
    std::fs::write(&cat, l.join("\n") + "\n").unwrap();
    // (the catalog's manifest still counts 10 lines: it does)
    std::fs::remove_file(tub.join("images/21_cam_image_array_.jpg")).unwrap();
    let o = import(&tub, "torn-out");
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(err.contains("2 record(s) skipped"), "{err}");
    assert!(err.contains(&format!("{}:5: not JSON", cat.display())), "{err}");
    assert!(
        err.contains("catalog_2.catalog:2: `cam/image_array`: image")
            && err.contains("21_cam_image_array_.jpg is missing"),
        "{err}"
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("import: 21 frames"),
        "{}",
        text(&o)
    );

    // A manifest that counts more records than the catalogs hold: refused, nothing written.
    let tub = fresh("short");
    let m = std::fs::read_to_string(tub.join("manifest.json")).unwrap();
    std::fs::write(
        tub.join("manifest.json"),
        m.replace("\"current_index\":25", "\"current_index\":30"),
    )
    .unwrap();
    let o = import(&tub, "short-out");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("manifest.json:5: manifest mismatch: `current_index` says 30 records, the catalogs hold 25"),
        "{err}"
    );
    assert!(!tmp.path().join("short-out").exists(), "nothing written");

    // A catalog whose own manifest counts other lines: refused, naming it.
    let tub = fresh("lens");
    let cm = tub.join("catalog_1.catalog_manifest");
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&cm).unwrap()).unwrap();
    let mut v2 = v.clone();
    v2["line_lengths"].as_array_mut().unwrap().pop();
    std::fs::write(&cm, v2.to_string()).unwrap();
    let o = import(&tub, "lens-out");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("catalog_1.catalog_manifest:1: manifest mismatch: `line_lengths` lists 9 records, catalog_1.catalog holds 10"), "{}", text(&o));

    // No steering among the inputs: refused, naming the key.
    let tub = fresh("noangle");
    let m = std::fs::read_to_string(tub.join("manifest.json")).unwrap();
    std::fs::write(
        tub.join("manifest.json"),
        m.replacen("\"user/angle\"", "\"user/angel\"", 1),
    )
    .unwrap();
    let o = import(&tub, "noangle-out");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("manifest.json:1: no `user/angle` among the inputs"),
        "{}",
        text(&o)
    );

    // A line of the manifest that is not JSON.
    let tub = fresh("badman");
    let m = std::fs::read_to_string(tub.join("manifest.json")).unwrap();
    std::fs::write(
        tub.join("manifest.json"),
        m.replacen("[\"image_array\"", "[image_array", 1),
    )
    .unwrap();
    let o = import(&tub, "badman-out");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("manifest.json:2: the types: not JSON"),
        "{}",
        text(&o)
    );

    // Outputs: never a folder that holds something, never inside the input.
    let tub = fresh("good");
    let before = snapshot(&tub);
    let full = tmp.path().join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("notes.txt"), "car 3").unwrap();
    let o = rccar(&["data", "import"], &[&tub, Path::new("-o"), &full]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("not empty (holds notes.txt)"),
        "{}",
        text(&o)
    );
    let o = rccar(&["data", "import"], &[&tub, Path::new("-o"), &tub.join("inside")]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("is inside the input"),
        "{}",
        text(&o)
    );
    assert!(snapshot(&tub) == before, "the input tub was changed");
    assert_eq!(std::fs::read_to_string(full.join("notes.txt")).unwrap(), "car 3");
}

#[test]
fn bad_recordings_and_requests_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let tub = tmp.path().join("tub");
    make_tub(&tub);
    let rec = tmp.path().join("rec");
    let o = rccar(&["data", "import"], &[&tub, Path::new("-o"), &rec]);
    assert!(o.status.success(), "{}", text(&o));
    // A drop range that matches no frame is a typo, not a no-op.
    let o = rccar(
        &["data", "cut", "--drop", "100..200"],
        &[&rec, Path::new("-o"), &tmp.path().join("c1")],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .contains("--drop 100..200 matches no frame (this dataset holds frames 0..=24)"),
        "{}",
        text(&o)
    );
    assert!(!tmp.path().join("c1").exists());
    // Frame numbers that go back: two runs in one telemetry; refused naming the line.
    let tel = rec.join("telemetry.jsonl");
    let mut l = lines(&tel);
    l.swap(5, 6);
    std::fs::write(&tel, l.join("\n") + "\n").unwrap();
    let o = rccar(&["data", "ls"], &[&rec]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("telemetry.jsonl:7: frame 6 after frame 7 (line 6)"),
        "{}",
        text(&o)
    );
    // A cut line (a crash) is skipped and named; the rest is used.
    l.swap(5, 6);
    l[10] = "{\"frame\":11,\"fi".into();
    std::fs::write(&tel, l.join("\n") + "\n").unwrap();
    let o = rccar(&["data", "ls", "--json"], &[&rec]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("telemetry.jsonl:11: not JSON"),
        "{}",
        text(&o)
    );
    let ls: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (
            ls["stats"]["frames"].as_u64(),
            ls["skipped"].as_u64(),
            ls["unlabelled_frames"].as_u64()
        ),
        (Some(22), Some(1), Some(1))
    );
    // A folder of frames without telemetry says where a simulator run keeps it.
    let o = rccar(&["data", "ls"], &[&rec.join("seg_000000")]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--telemetry RUN/telemetry.jsonl"),
        "{}",
        text(&o)
    );
}
