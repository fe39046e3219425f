//! Issue 15: a fuzz-style test per input surface. Seeded random edits of real inputs (the
//! shipped config and tracks, the shipped cascade, sample frames as PNG and JPEG, OpenCV's
//! baboon.jpg when opencv-doc is installed, calibration CSVs, command-line flags); each case
//! must end in a value or a clean error, never a panic or an abort. Every test prints how
//! many cases ended which way. Deterministic (fixed seeds); `RCCAR_FUZZ_SCALE=N` scales the
//! counts (default 1, e.g. 10 for a longer run).

use rccar::config::Config;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// SplitMix64: small, seeded, good enough to pick edits.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn pick<'a>(&mut self, v: &[&'a str]) -> &'a str {
        v[self.below(v.len())]
    }
}

fn scale() -> usize {
    std::env::var("RCCAR_FUZZ_SCALE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
        .max(1)
}

/// Values a student (or a cat on the keyboard) might type where a number belongs.
const NASTY: &[&str] = &[
    "0",
    "-1",
    "1",
    "0.5",
    "-0.0",
    "1e309",
    "-1e309",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "1e-320",
    "4294967296",
    "-9223372036854775809",
    "18446744073709551616",
    "99999999999",
    "1e3",
    "\"x\"",
    "true",
    "[]",
    "[1, 2]",
    "{}",
    "\"\"",
    "0x10",
    "1_000",
    "'a'",
    "2.5e-3",
    "1000000",
];

/// A random number, sometimes sane, sometimes wild.
fn number(r: &mut Rng) -> String {
    match r.below(4) {
        0 => r.pick(NASTY).to_string(),
        1 => format!("{}", (r.unit() - 0.5) * 10f64.powi(r.below(12) as i32 - 3)),
        2 => format!("{}", r.below(5000)),
        _ => format!("{:.3}", r.unit() * 2.0),
    }
}

/// One random edit of a TOML text: a value replaced, a line dropped or doubled, a byte
/// inserted, two lines swapped, the text cut short.
fn edit_toml(text: &str, r: &mut Rng) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let n = lines.len();
    match r.below(7) {
        0..=2 => {
            // Replace the value of a `key = value` line (the most useful edit).
            let keyed: Vec<usize> = (0..n)
                .filter(|&i| lines[i].contains(" = ") && !lines[i].starts_with('#'))
                .collect();
            if let Some(&i) = keyed.get(r.below(keyed.len())) {
                let key = lines[i].split(" = ").next().unwrap_or("").to_string();
                lines[i] = format!("{key} = {}", number(r));
            }
        }
        3 => {
            let i = r.below(n);
            lines.remove(i.min(n - 1));
        }
        4 => {
            let i = r.below(n);
            let l = lines[i].clone();
            lines.insert(i, l);
        }
        5 => {
            let (a, b) = (r.below(n), r.below(n));
            lines.swap(a, b);
        }
        _ => {
            let mut s = lines.join("\n");
            let cut = r.below(s.len() + 1);
            let cut = (0..=cut).rev().find(|&c| s.is_char_boundary(c)).unwrap_or(0);
            s.truncate(cut);
            if r.below(2) == 0 {
                let b = [b'[', b']', b'"', b'=', b'\n', b'#', b'.', b'{'][r.below(8)];
                s.push(b as char);
            }
            return s;
        }
    }
    lines.join("\n")
}

/// Runs `f` and turns a panic into a failure that shows the input.
fn no_panic<T>(what: &str, input: &str, f: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(v) => v,
        Err(_) => panic!("{what} panicked on this input:\n-----\n{input}\n-----"),
    }
}

/// Config TOML: random edits of config/car.toml; a config that loads must also build the
/// pipeline and run one frame.
#[test]
fn fuzz_config_toml() {
    let base = std::fs::read_to_string(Path::new(ROOT).join("config/car.toml")).unwrap();
    let mut r = Rng(15);
    let (mut ok, mut err, mut stepped) = (0, 0, 0);
    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
    for _ in 0..1500 * scale() {
        let mut text = base.clone();
        for _ in 0..1 + r.below(3) {
            text = edit_toml(&text, &mut r);
        }
        match no_panic("Config::from_toml_str", &text, || {
            Config::from_toml_str(&text, "fuzz.toml")
        }) {
            Ok(cfg) => {
                ok += 1;
                let p = no_panic("Pipeline::new", &text, || rccar::pipeline::Pipeline::new(&cfg));
                if let Ok(mut p) = p {
                    let (w, h) = p.frame_size();
                    if stepped < 150 && (w as u64 * h as u64) <= 1 << 20 {
                        let img = image::RgbImage::from_pixel(w, h, image::Rgb([90, 90, 90]));
                        no_panic("Pipeline::step", &text, || {
                            p.step(&img, 1.0 / cfg.camera.fps, &mut rccar::timing::NoTimer)
                        });
                        stepped += 1;
                    }
                }
            }
            Err(e) => {
                err += 1;
                let msg = e.to_string();
                assert!(msg.starts_with("fuzz.toml"), "error does not name the file: {msg}");
                let kind = msg.split(':').nth(1).unwrap_or("").trim().chars().take(24).collect();
                *kinds.entry(kind).or_default() += 1;
            }
        }
    }
    println!(
        "config TOML: {} cases, {ok} loaded ({stepped} ran a frame), {err} clean errors",
        ok + err
    );
    assert!(ok > 100 && err > 100, "the edits should both keep and break configs");
}

/// Track TOML: random edits of both shipped tracks; a track that loads must build its scene
/// (a sample of them: a scene is a few milliseconds to a second).
#[test]
fn fuzz_track_toml() {
    let mut r = Rng(16);
    let (mut ok, mut err, mut scenes) = (0, 0, 0);
    for name in ["default.toml", "scenarios.toml"] {
        let base = std::fs::read_to_string(Path::new(ROOT).join("config/tracks").join(name)).unwrap();
        for _ in 0..600 * scale() {
            let mut text = base.clone();
            for _ in 0..1 + r.below(2) {
                text = edit_toml(&text, &mut r);
            }
            match no_panic("Track::from_toml_str", &text, || {
                rccar::sim::track::Track::from_toml_str(&text, name)
            }) {
                Ok(t) => {
                    ok += 1;
                    if scenes < 12 {
                        no_panic("Scene::new", &text, || rccar::sim::scene::Scene::new(&t));
                        scenes += 1;
                    }
                }
                Err(e) => {
                    err += 1;
                    assert!(e.to_string().starts_with(name), "{e}");
                }
            }
        }
    }
    println!(
        "track TOML: {} cases, {ok} loaded ({scenes} scenes built), {err} clean errors",
        ok + err
    );
    assert!(ok > 50 && err > 200);
}

/// Cascade XML: truncations, byte flips, dropped lines and replaced numbers in the shipped
/// stop-sign cascade; a cascade that loads must run on an image.
#[test]
fn fuzz_cascade_xml() {
    use rccar::detect::{Cascade, DetectParams, Detector};
    let base = std::fs::read_to_string(Path::new(ROOT).join("config/cascades/stop_sign.xml")).unwrap();
    let img = image::GrayImage::from_fn(96, 72, |x, y| image::Luma([((x * 7 + y * 13) % 256) as u8]));
    let mut r = Rng(17);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..300 * scale() {
        let mut text = base.clone();
        match r.below(4) {
            0 => {
                let cut = r.below(text.len());
                let cut = (0..=cut).rev().find(|&c| text.is_char_boundary(c)).unwrap_or(0);
                text.truncate(cut);
            }
            1 => {
                let mut b = text.into_bytes();
                for _ in 0..1 + r.below(4) {
                    let i = r.below(b.len());
                    b[i] = b"<>/\"0123456789.-e abc\n"[r.below(21)];
                }
                text = String::from_utf8_lossy(&b).into_owned();
            }
            2 => {
                let mut lines: Vec<&str> = text.lines().collect();
                lines.remove(r.below(lines.len()));
                text = lines.join("\n");
            }
            _ => {
                // Replace one number token with a nasty one.
                let spots: Vec<usize> = text
                    .char_indices()
                    .filter(|&(i, c)| c.is_ascii_digit() && i > 0 && !text.as_bytes()[i - 1].is_ascii_alphanumeric())
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&i) = spots.get(r.below(spots.len())) {
                    let end = text[i..]
                        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
                        .map_or(text.len(), |e| i + e);
                    let v = r.pick(&[
                        "-1",
                        "999999999",
                        "1e309",
                        "nan",
                        "0",
                        "-0",
                        "65536",
                        "4294967297",
                        "3.5",
                    ]);
                    text.replace_range(i..end, v);
                }
            }
        }
        let c = no_panic("Cascade::from_xml_str", &text, || {
            Cascade::from_xml_str(&text, "stop_sign.xml")
        });
        match c {
            Ok(c) => {
                ok += 1;
                let mut d = Detector::new(c);
                let _ = no_panic("Detector::detect", &text, || d.detect(&img, &DetectParams::default()));
            }
            Err(e) => {
                err += 1;
                assert!(e.to_string().contains("stop_sign.xml"), "{e}");
            }
        }
    }
    println!(
        "cascade XML: {} cases, {ok} loaded and ran, {err} clean errors",
        ok + err
    );
    assert!(err > 100);
}

fn encode(img: &image::DynamicImage, f: image::ImageFormat) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, f).unwrap();
    out.into_inner()
}

/// Image files: random truncations and byte flips of PNG and JPEG (our frames, and OpenCV's
/// baboon.jpg when installed): every case is a decoded image or a named error; a truncation is
/// always caught (never a frame with a grey hole).
#[test]
fn fuzz_image_files() {
    let frame = image::open(Path::new(ROOT).join("tests/data/lane_sample/frame_010.png")).unwrap();
    let gray = image::DynamicImage::ImageLuma8(frame.to_luma8());
    let mut seeds = vec![
        ("frame.png", encode(&frame, image::ImageFormat::Png)),
        ("gray.png", encode(&gray, image::ImageFormat::Png)),
        ("frame.jpg", encode(&frame.to_rgb8().into(), image::ImageFormat::Jpeg)),
    ];
    if let Ok(b) = std::fs::read("/usr/share/doc/opencv-doc/examples/data/baboon.jpg") {
        seeds.push(("baboon.jpg", b));
    }
    let mut r = Rng(18);
    let (mut decoded, mut damaged, mut undecodable, mut cuts) = (0, 0, 0, 0);
    for (name, seed) in &seeds {
        assert_eq!(rccar::source::image_damage(seed), None, "{name} is whole");
        for _ in 0..150 * scale() {
            let mut b = seed.clone();
            let op = r.below(3);
            if op != 1 {
                // Truncation anywhere (the structure check must catch every one).
                b.truncate(r.below(b.len()));
            }
            if op != 0 {
                for _ in 0..1 + r.below(8) {
                    let i = r.below(b.len());
                    b[i] ^= 1 << r.below(8);
                }
            }
            let desc = format!("{name}, op {op}, {} of {} bytes", b.len(), seed.len());
            let dmg = no_panic("image_damage", &desc, || rccar::source::image_damage(&b));
            if op == 0 {
                cuts += 1;
                assert!(dmg.is_some() || b.is_empty(), "a truncation was not caught: {desc}");
            }
            match dmg {
                Some(why) => {
                    damaged += 1;
                    assert!(why.contains("damaged"), "{why}");
                }
                None => match no_panic("decode_image", &desc, || rccar::source::decode_image(&b)) {
                    Ok(_) => decoded += 1,
                    Err(_) => undecodable += 1,
                },
            }
        }
    }
    println!(
        "image files: {} cases ({cuts} truncations, all caught): {damaged} damaged (named), {undecodable} decoder errors, {decoded} decoded (flips inside JPEG data)",
        decoded + damaged + undecodable
    );
}

/// Calibration CSVs: random rows (nasty numbers, wrong column counts, duplicates, headers);
/// the parser and the fit never panic, and the CLI refuses or fits without touching files.
#[test]
fn fuzz_calibration_csv() {
    use rccar::ranging::{fit, parse_pairs_csv, FitOptions, TiltRanging};
    let cam = rccar::camera::PinholeCamera::from(&rccar::config::CameraConfig::default());
    let start = TiltRanging::from_camera(&cam);
    let mut r = Rng(19);
    let csv = |r: &mut Rng| {
        let mut s = String::new();
        if r.below(2) == 0 {
            s += "row_px,distance_m,height_m\n";
        }
        for _ in 0..r.below(12) {
            let d = 0.25 + r.unit() * 1.5;
            let v = start.row(d, 0.0);
            let cols = match r.below(6) {
                0 => format!("{},{}", number(r), number(r)),
                1 => format!("{:.1},{d:.3},{}", v, number(r)),
                2 => format!("{:.1}", v),
                3 => "# a comment".into(),
                _ => format!("{:.1},{d:.3}", v + (r.unit() - 0.5) * 4.0),
            };
            s += &cols;
            s.push('\n');
        }
        s
    };
    let (mut fitted, mut refused) = (0, 0);
    for _ in 0..1500 * scale() {
        let text = csv(&mut r);
        let pairs = no_panic("parse_pairs_csv", &text, || parse_pairs_csv(&text, "p.csv"));
        if let Ok(p) = pairs {
            for fit_ay in [false, true] {
                let o = FitOptions {
                    fit_ay,
                    ..Default::default()
                };
                match no_panic("fit", &text, || fit(&p, start, o)) {
                    Ok(_) => fitted += 1,
                    Err(_) => refused += 1,
                }
            }
        } else {
            refused += 1;
        }
    }
    // Through the command, with its checks (30 files).
    let t = tempfile::tempdir().unwrap();
    let (mut cli_ok, mut cli_refused) = (0, 0);
    for i in 0..30 {
        let text = csv(&mut r);
        let f = t.path().join(format!("p{i}.csv"));
        std::fs::write(&f, &text).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_rccar"))
            .current_dir(ROOT)
            .args(["calibrate", "ranging", "--dry-run", "--no-local"])
            .arg(&f)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{text}\n{err}");
        match o.status.code() {
            Some(0) => cli_ok += 1,
            Some(2) => {
                cli_refused += 1;
                assert!(err.starts_with("error: "), "{err}");
            }
            c => panic!("exit {c:?} on\n{text}\n{err}"),
        }
        assert_eq!(std::fs::read_to_string(&f).unwrap(), text);
    }
    println!(
        "calibration CSV: {} library cases ({fitted} fits, {refused} clean errors); CLI: {cli_ok} fitted (dry run), {cli_refused} refused",
        fitted + refused
    );
}

/// Command-line flags: random values inside and outside their ranges for config, roi,
/// detect, sim and calibrate; every run exits 0, 1 or 2 with no panic and no signal.
#[test]
fn fuzz_cli_flags() {
    let t = tempfile::tempdir().unwrap();
    let img = t.path().join("tiny.png");
    image::open(Path::new(ROOT).join("tests/data/lane_sample/frame_000.png"))
        .unwrap()
        .resize(96, 72, image::imageops::FilterType::Triangle)
        .save(&img)
        .unwrap();
    let cascade = Path::new(ROOT).join("config/cascades/stop_sign.xml");
    let keys: Vec<String> = numeric_keys(&toml::Table::try_from(Config::default()).unwrap(), "");
    let mut r = Rng(20);
    let mut codes = [0usize; 3];
    let n = 160 * scale();
    for i in 0..n {
        let (args, why): (Vec<String>, &str) = match i % 8 {
            0..=2 => {
                let k = &keys[r.below(keys.len())];
                (
                    vec![
                        "config".into(),
                        "check".into(),
                        "--no-local".into(),
                        "--set".into(),
                        format!("{k}={}", number(&mut r)),
                    ],
                    "config --set",
                )
            }
            3 => (
                vec![
                    "config".into(),
                    "roi".into(),
                    "--no-local".into(),
                    "--near".into(),
                    number(&mut r),
                    "--far".into(),
                    number(&mut r),
                    "--half-width".into(),
                    number(&mut r),
                ],
                "config roi",
            ),
            4 | 5 => (
                vec![
                    "detect".into(),
                    "--no-annotate".into(),
                    "--cascade".into(),
                    cascade.display().to_string(),
                    "--scale-factor".into(),
                    number(&mut r),
                    "--min-neighbors".into(),
                    number(&mut r),
                    "--min-size".into(),
                    format!("{}x{}", number(&mut r), number(&mut r)),
                    img.display().to_string(),
                ],
                "detect",
            ),
            6 => {
                // Valid run lengths are kept short; invalid ones must be refused at once.
                let secs = if r.below(2) == 0 {
                    format!("{:.2}", 0.05 + r.unit() * 0.1)
                } else {
                    r.pick(&["nan", "inf", "-1", "0", "1e309", "x", "36001"]).into()
                };
                (
                    vec![
                        "sim".into(),
                        "--no-local".into(),
                        "--no-timing".into(),
                        "--seconds".into(),
                        secs,
                        "--laps".into(),
                        number(&mut r),
                        "--seed".into(),
                        number(&mut r),
                        "-o".into(),
                        t.path().join("sim").display().to_string(),
                    ],
                    "sim",
                )
            }
            _ => {
                let n = if r.below(2) == 0 {
                    format!("{}", 3 + r.below(10))
                } else {
                    number(&mut r)
                };
                (
                    vec![
                        "calibrate".into(),
                        "ranging".into(),
                        "--dry-run".into(),
                        "--no-local".into(),
                        "--from-sim".into(),
                        n,
                        "--sim-tilt-error-deg".into(),
                        number(&mut r),
                        "--sim-tape-sigma-m".into(),
                        number(&mut r),
                        "--max-rms-px".into(),
                        number(&mut r),
                        "--v0-sigma-px".into(),
                        number(&mut r),
                    ],
                    "calibrate",
                )
            }
        };
        let o = Command::new(env!("CARGO_BIN_EXE_rccar"))
            .current_dir(ROOT)
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{why} {args:?}\n{err}");
        match o.status.code() {
            Some(c @ 0..=2) => codes[c as usize] += 1,
            c => panic!("{why} {args:?}: exit {c:?} (a signal or an abort)\n{err}"),
        }
        if o.status.code() == Some(2) {
            assert!(
                err.contains("error"),
                "{why} {args:?}: exit 2 without an error line\n{err}"
            );
        }
    }
    println!(
        "CLI flags: {n} runs: {} exit 0, {} exit 1, {} exit 2 (all clean)",
        codes[0], codes[1], codes[2]
    );
    // Both kinds must occur: runs the values let through and runs refused cleanly. How many of
    // each depends on which of the config's numeric keys the seeded picks land on, and that list
    // grows with every new config section (after [colour_template] and sim.steer_noise the
    // seeded run gave 10 accepted of 160), so the floor is loose on purpose.
    assert!(codes[0] >= 5 && codes[1] + codes[2] >= 30, "{codes:?}");
}

/// Dotted keys of every number in the default config (e.g. `steering.kp`, `warp.out_width`).
fn numeric_keys(t: &toml::Table, prefix: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (k, v) in t {
        let full = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(s) => out.extend(numeric_keys(s, &full)),
            toml::Value::Integer(_) | toml::Value::Float(_) | toml::Value::Array(_) => out.push(full),
            _ => {}
        }
    }
    out
}
