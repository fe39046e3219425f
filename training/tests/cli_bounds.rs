//! Every size and count a user gives `rccar-train` has a stated bound, enforced with an error
//! that names the flag and the bound (issue 24). Each case runs the binary with a deadline: a
//! command that spins (before: `gen --window 0x0`, `16x0` or `100000x100000` placed scenes
//! forever at 100 % CPU) fails the test instead of hanging it.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs `rccar-train ARGS` in `dir`; (exit code, stderr). Killed after `secs`.
fn run(dir: &Path, args: &[&str], secs: u64) -> (Option<i32>, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rccar-train"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rccar-train runs");
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            assert!(!err.contains("panicked"), "rccar-train {args:?} panicked:\n{err}");
            return (status.code(), err);
        }
        if Instant::now() > deadline {
            child.kill().ok();
            child.wait().ok();
            panic!("rccar-train {args:?} still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn track() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/tracks/default.toml")
        .display()
        .to_string()
}

/// `gen`: the window, count, scenes and distances, each refused by name and bound; a window
/// that fits the bounds but no view at those distances gives up after 20 placements.
#[test]
fn gen_refuses_every_size_out_of_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let t = track();
    let base = [
        "gen",
        "--kind",
        "stop_sign",
        "--split",
        "positives",
        "--out",
        "o",
        "--track",
        &t,
    ];
    let cases: [(&[&str], &str); 13] = [
        (&["--light-level", "4"], "--light-level 4: must be 0..=3"),
        (&["--window", "257x16"], "--window 257x16: each side must be 3..=256 px"),
        (&["--count", "1000001"], "--count 1000001: must be 1..=1000000"),
        (&["--window", "0x0"], "--window 0x0: each side must be 3..=256 px"),
        (&["--window", "16x0"], "--window 16x0: each side must be 3..=256 px"),
        (
            &["--window", "100000x100000"],
            "--window 100000x100000: each side must be 3..=256 px",
        ),
        (
            &["--window", "250x250"],
            "--window 250x250: larger than the 320x240 camera image",
        ),
        (&["--count", "0"], "--count 0: must be 1..=1000000"),
        (&["--count", "99999999"], "--count 99999999: must be 1..=1000000"),
        (&["--scenes", "0"], "--scenes 0: must be 1..=10000"),
        (&["--min-distance", "0"], "each must be 0.05..=20 m, min < max"),
        (
            &["--min-distance", "2", "--max-distance", "1"],
            "each must be 0.05..=20 m, min < max",
        ),
        (&["--max-distance", "1e9"], "each must be 0.05..=20 m, min < max"),
    ];
    for (extra, want) in cases {
        let args: Vec<&str> = base.iter().copied().chain(extra.iter().copied()).collect();
        let (code, err) = run(d, &args, 60);
        assert_eq!(code, Some(2), "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: no {want:?} in {err}");
    }
    // In bounds, but no stop sign 0.2..1.5 m away is 200 px wide.
    let args: Vec<&str> = base
        .iter()
        .copied()
        .chain(["--window", "200x200", "--count", "5"])
        .collect();
    let (code, err) = run(d, &args, 120);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("no view of the StopSign") && err.contains("smaller --window"),
        "{err}"
    );
}

/// Every other size and count flag of `rccar-train`: the bound itself passes the check (the
/// run then stops on the missing input instead, without naming the flag), the bound + 1 (or
/// − 1) is refused with exit 2 and a message naming the flag and the bound.
#[test]
fn every_flag_bound_is_accepted_and_one_past_it_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let train: &[&str] = &["train", "--out", "m", "--pos", "none.dat", "--bg", "none.txt"];
    let eval: &[&str] = &["evaluate", "--cascade", "none.xml", "--info", "none.dat"];
    let distort: &[&str] = &["distort", "--template", "none.png", "--bg", "none.txt", "--out", "o"];
    let photoset: &[&str] = &["photoset", "--photos", "none", "--out", "p"];
    // (command, flag, value at the bound, value past it, the message past it)
    #[rustfmt::skip]
    let cases: &[(&[&str], &str, &str, &str, &str)] = &[
        (train, "--num-stages", "100", "101", "--num-stages 101: must be 1..=100"),
        (train, "--num-stages", "1", "0", "--num-stages 0: must be 1..=100"),
        (train, "--num-pos", "1000000", "1000001", "--num-pos 1000001: must be 1..=1000000"),
        (train, "--num-neg", "1000000", "1000001", "--num-neg 1000001: must be 1..=1000000"),
        (train, "--num-neg", "1", "0", "--num-neg 0: must be 1..=1000000"),
        (train, "--max-weak-count", "10000", "10001", "--max-weak-count 10001: must be 1..=10000"),
        (train, "--mem-mb", "65536", "65537", "--mem-mb 65537: must be 1..=65536 MiB"),
        (train, "--threads", "256", "257", "--threads 257: must be 1..=256"),
        (train, "--target-fp-per-frame", "1000", "1001", "--target-fp-per-frame 1001: must be 0..=1000"),
        (train, "--scale-factor", "2", "2.01", "--scale-factor 2.01: must be 1.01..=2"),
        (train, "--scale-factor", "1.01", "1", "--scale-factor 1: must be 1.01..=2"),
        (train, "--holdout-min-neighbors", "100", "101", "--holdout-min-neighbors 101: must be 0..=100"),
        (train, "--holdout-min-size", "16384", "16385", "--holdout-min-size 16385x16385: each side must be 0..=16384 px"),
        (train, "-W", "256", "257", "-W 257: must be 3..=256 px"),
        (train, "-W", "3", "2", "-W 2: must be 3..=256 px"),
        (train, "-H", "256", "257", "-H 257: must be 3..=256 px"),
        (eval, "--min-neighbors", "100", "101", "--min-neighbors 101: must be 0..=100"),
        (eval, "--scale-factor", "2", "2.01", "--scale-factor 2.01: must be 1.01..=2"),
        (eval, "--min-size", "16384x1", "16385x1", "--min-size 16385x1: each side must be 0..=16384 px"),
        (eval, "--iou", "1", "1.01", "--iou 1.01: must be 0.01..=1"),
        (distort, "--count", "1000000", "1000001", "--count 1000001: must be 1..=1000000"),
        (distort, "--max-angle-deg", "180", "181", "--max-angle-deg 181: must be 0..=180 degrees"),
        (distort, "--max-skew", "0.5", "0.51", "--max-skew 0.51: must be 0..=0.5"),
        (distort, "--max-scale", "20", "21", "--max-scale 21: must be 1..=20"),
        (distort, "--window", "256x3", "257x3", "--window 257x3: each side must be 3..=256 px"),
        (photoset, "--with-sign", "100000", "100001", "--with-sign 100001: must be 0..=100000"),
        (photoset, "--without", "100000", "100001", "--without 100001: must be 0..=100000"),
        (photoset, "--sign-px", "4x1024", "4x1025", "--sign-px 4x1025: each must be 4..=1024 px"),
        (photoset, "--sign-px", "4x4", "3x4", "--sign-px 3x4: each must be 4..=1024 px"),
    ];
    for &(cmd, flag, ok, bad, want) in cases {
        let with = |v: &str| -> Vec<String> {
            cmd.iter()
                .map(|s| s.to_string())
                .chain([flag.to_string(), v.to_string()])
                .collect()
        };
        let args = with(bad);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err) = run(d, &args, 30);
        assert_eq!(code, Some(2), "{flag} {bad}: {err}");
        assert!(err.contains(want), "{flag} {bad}: no {want:?} in {err}");
        let args = with(ok);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err) = run(d, &args, 30);
        assert_eq!(code, Some(2), "{flag} {ok}: {err}");
        let name = flag.trim_start_matches('-');
        assert!(
            !err.contains("must be") && err.contains("none"),
            "{flag} {ok} (the bound) was refused or did not reach the missing input: {err} ({name})"
        );
    }
}

/// `photoset --printed` styles stop signs only: with `--traffic-light` as well it is refused by
/// name (it made traffic lights and silently dropped `--printed`).
#[test]
fn photoset_refuses_printed_traffic_lights() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "photoset",
        "--photos",
        "none",
        "--out",
        "p",
        "--printed",
        "--traffic-light",
    ];
    let (code, err) = run(dir.path(), &args, 30);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--printed") && err.contains("--traffic-light") && err.contains("cannot be used with"),
        "{err}"
    );
    assert!(!dir.path().join("p").exists(), "a refused photoset wrote its folder");
}

/// The training inputs' bounds through the command: a list above 64 MiB and an image above
/// 40 megapixels are refused naming the file (the bounds themselves: samples.rs unit tests).
#[test]
fn train_refuses_a_huge_list_and_a_huge_image_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("big.dat"), vec![b'#'; (64 << 20) + 1]).unwrap();
    let (code, err) = run(d, &["train", "--out", "m", "--pos", "big.dat", "--bg", "big.dat"], 60);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("big.dat: larger than 67108864 bytes"), "{err}");
    // A PNG whose header says 40000001 x 1: refused before decoding, the line skipped by name.
    png_header(&d.join("huge.png"), 40_000_001, 1);
    std::fs::write(d.join("pos.dat"), "huge.png 1 0 0 20 20\n").unwrap();
    let (code, err) = run(
        d,
        &["train", "--out", "m", "--pos", "pos.dat", "--bg", "pos.dat", "-W", "20"],
        60,
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("pos.dat:1") && err.contains("40000001x1 pixels is above the image limit"),
        "{err}"
    );
}

/// A file that cannot be read is named with the OS's reason once (it was printed twice: in the
/// message and again as the error's source).
#[test]
fn a_missing_list_file_is_named_with_the_reason_once() {
    let dir = tempfile::tempdir().unwrap();
    let (code, err) = run(dir.path(), &["train", "--out", "m", "--pos", "missing.dat", "--bg", "missing.dat"], 60);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("missing.dat: cannot read: "), "{err}");
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
}

/// A PNG that holds only its header (IHDR, an empty IDAT, IEND): enough for the header check,
/// far too little to decode.
fn png_header(path: &Path, w: u32, h: u32) {
    fn crc(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 == 1 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    for (kind, data) in [(&b"IHDR"[..], &ihdr[..]), (b"IDAT", &[]), (b"IEND", &[])] {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc(&body).to_be_bytes());
    }
    std::fs::write(path, out).unwrap();
}
