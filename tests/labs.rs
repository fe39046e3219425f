//! The labs do not rot: every command in `docs/labs/*.md` runs here, and the teacher's key
//! (`docs/labs/key/key.json`) is regenerated and compared with the committed one.
//!
//! How a lab page is read (the rules are also in docs/labs/README.md):
//! - a fenced block opened with <code>```sh</code> is run: all such blocks of one page, in
//!   order, as one bash script (`set -euo pipefail`), in a fresh empty folder outside the
//!   repository, with `RCCAR` (the repository), `RCCAR_CONFIG` (its config/car.toml) and the
//!   build's `rccar` / `rccar-train` on `PATH`, exactly as a student sets them up. A non-zero
//!   exit fails the test, naming the page and the Markdown line of the failing command.
//! - a block opened with <code>```sh car</code> is for the real car and is not run; every
//!   `rccar SUB … --flag` in it is checked against `rccar SUB --help` instead.
//! - `<!-- quick: OLD => NEW -->` before a block replaces OLD by NEW in that block for this
//!   test (a shorter run); a substitution that matches nothing fails the test.
//! - a page with `<!-- needs: serial -->` is run only when the build has the `serial`
//!   feature (tests/all.sh stage `labs-link`); in the plain `cargo test` it is ignored.
//!
//! The key: `bash docs/labs/key/make.sh DIR` reruns every experiment whose result a page
//! quotes and writes DIR/key.json (each figure with its command and tolerance) and DIR/key.md.
//! The pages mark what they quote (`<!-- key: NAME -->` after a number, `<!-- key-table:
//! PREFIX -->` before a table; docs/labs/README.md, "For the teacher"), and:
//! - `pages_quote_the_committed_key` compares every quoted figure with the committed
//!   docs/labs/key/key.json within the figure's tolerance plus the page's rounding, and fails
//!   on a table of numbers or a "Measured" decimal that names no figure (quick);
//! - `key_matches_committed` regenerates the key into a temporary folder and compares it with
//!   the committed one and with the pages (needs the serial build: lab 11's figures come from
//!   the firmware in the emulator; tests/all.sh stage `labs-link`).
//!
//! Regenerate the committed key on purpose: `bash docs/labs/key/make.sh`. Units are those of
//! each figure (stated in key.json); simulator times are simulated seconds; figures marked
//! `timing` are wall-clock times of the machine that made the key (only their presence is
//! checked on a rerun).

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Folder of the `rccar` binary under test (and of `rccar-train`, built beside it).
fn bin_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_rccar")).parent().unwrap().to_path_buf()
}

/// `rccar-train` lives in the workspace member `training/`; `cargo test --workspace` builds
/// it, a single `cargo test --test car labs::` may not. Build it once if it is missing.
fn ensure_trainer() {
    static ONCE: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    ONCE.get_or_init(|| {
        if bin_dir().join("rccar-train").exists() {
            return;
        }
        let st = Command::new(env!("CARGO"))
            .args(["build", "--release", "-p", "rccar-train", "--bin", "rccar-train"])
            .current_dir(repo())
            .status()
            .expect("cargo build -p rccar-train");
        assert!(st.success(), "cargo build --release -p rccar-train failed");
    });
}

/// Held while `make -C firmware` and the emulator run (lab 11 and the key's lab 11 figures).
static FIRMWARE: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// One fenced block of a lab page.
#[derive(Debug)]
struct Block {
    /// `sh` (run) or `sh car` (checked only).
    car: bool,
    /// (Markdown line number, 1-based; text) of each line inside the fences.
    lines: Vec<(usize, String)>,
}

/// A parsed lab page.
struct Page {
    blocks: Vec<Block>,
    needs_serial: bool,
}

/// Reads a page's `sh` blocks, applying its `<!-- quick: OLD => NEW -->` substitutions.
fn parse(path: &Path) -> Page {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    let mut blocks = Vec::new();
    let mut pending: Vec<(usize, String, String)> = Vec::new();
    // the open block, and whether it is kept (an `sh` block) or skipped (any other language)
    let mut cur: Option<(Block, bool)> = None;
    let mut needs_serial = false;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let t = line.trim();
        if let Some((b, _)) = cur.as_mut() {
            if t.starts_with("```") {
                let (mut b, keep) = cur.take().unwrap();
                if !keep {
                    continue;
                }
                for (qn, old, new) in pending.drain(..) {
                    let mut hit = false;
                    for (_, l) in b.lines.iter_mut() {
                        if l.contains(&old) {
                            *l = l.replace(&old, &new);
                            hit = true;
                        }
                    }
                    assert!(
                        hit,
                        "{name}:{qn}: quick substitution `{old}` matches nothing in the next block"
                    );
                }
                blocks.push(b);
            } else {
                b.lines.push((n, line.to_string()));
            }
            continue;
        }
        if t == "<!-- needs: serial -->" {
            needs_serial = true;
        }
        if let Some(rest) = t.strip_prefix("<!-- quick:") {
            let body = rest
                .strip_suffix("-->")
                .unwrap_or_else(|| panic!("{name}:{n}: quick comment must end on its line"));
            let (old, new) = body
                .split_once("=>")
                .unwrap_or_else(|| panic!("{name}:{n}: quick comment needs `OLD => NEW`"));
            pending.push((n, old.trim().to_string(), new.trim().to_string()));
        }
        if let Some(info) = t.strip_prefix("```") {
            let b = Block {
                car: info.trim() == "sh car",
                lines: Vec::new(),
            };
            let keep = matches!(info.trim(), "sh" | "sh car");
            if !keep {
                assert!(
                    pending.is_empty(),
                    "{name}:{n}: a quick substitution must be followed by an `sh` block"
                );
            }
            cur = Some((b, keep));
        }
    }
    assert!(cur.is_none(), "{name}: an unclosed code block");
    assert!(
        pending.is_empty(),
        "{name}: a quick substitution with no block after it"
    );
    Page { blocks, needs_serial }
}

/// Runs every `sh` block of `docs/labs/<file>` as one script; panics naming the line.
fn run_lab(file: &str) {
    run_page(&format!("docs/labs/{file}"), Duration::from_secs(300));
}

/// What a page's run left: its output and the folder it ran in (kept until dropped).
struct PageRun {
    stdout: String,
    stderr: String,
    work: tempfile::TempDir,
}

/// Runs every `sh` block of the page `rel` (relative to the repository) as one script, as
/// [`run_lab`] does, within `limit`; panics naming the Markdown line of a failing command.
fn run_page(rel: &str, limit: Duration) -> PageRun {
    let file = rel;
    let path = repo().join(rel);
    let page = parse(&path);
    assert!(
        !page.needs_serial || cfg!(feature = "serial"),
        "{file}: needs the `serial` feature (cargo test --release --features serial --test car labs::)"
    );
    // the firmware lab and the key both build and run the emulator: one at a time
    let _fw = page
        .needs_serial
        .then(|| FIRMWARE.lock().unwrap_or_else(|e| e.into_inner()));
    ensure_trainer();
    let mut script = String::from(
        "set -euo pipefail\n\
         trap 'rc=$?; echo \"LABFAIL $LINENO $rc\" >&2' ERR\n\
         trap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n",
    );
    let header = script.lines().count();
    // script line (1-based) → Markdown line
    let mut map: Vec<usize> = vec![0; header];
    for b in page.blocks.iter().filter(|b| !b.car) {
        for (n, l) in &b.lines {
            script.push_str(l);
            script.push('\n');
            map.push(*n);
        }
    }
    assert!(map.len() > header, "{file}: no ```sh block to run");
    let work = tempfile::Builder::new().prefix("rccar-lab-").tempdir().unwrap();
    let path_var = format!("{}:{}", bin_dir().display(), std::env::var("PATH").unwrap_or_default());
    let start = Instant::now();
    let mut child = {
        use std::os::unix::process::CommandExt;
        Command::new("bash")
            .arg("-c")
            .arg(&script)
            .current_dir(work.path())
            .env("PATH", path_var)
            .env("RCCAR", repo())
            .env("RCCAR_CONFIG", repo().join("config/car.toml"))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .expect("bash")
    };
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let t_out = std::thread::spawn(move || {
        let mut s = String::new();
        out.read_to_string(&mut s).ok();
        s
    });
    let t_err = std::thread::spawn(move || {
        let mut s = String::new();
        err.read_to_string(&mut s).ok();
        s
    });
    // A lab that hangs must fail, not stall the suite.
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if start.elapsed() > limit {
            unsafe { libc::kill(-(child.id() as i32), libc::SIGKILL) };
            child.wait().ok();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    // end stray background jobs of the lab (its EXIT trap normally does)
    unsafe { libc::kill(-(child.id() as i32), libc::SIGKILL) };
    let stdout = t_out.join().unwrap();
    let stderr = t_err.join().unwrap();
    let secs = start.elapsed().as_secs_f64();
    eprintln!("{file}: ran in {secs:.1} s");
    let tail = |s: &str| {
        s.lines()
            .rev()
            .take(25)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("\n")
    };
    let Some(status) = status else {
        panic!(
            "{file}: still running after {} s\n--- stdout\n{}\n--- stderr\n{}",
            limit.as_secs(),
            tail(&stdout),
            tail(&stderr)
        );
    };
    if !status.success() {
        let line = stderr
            .lines()
            .filter_map(|l| l.strip_prefix("LABFAIL "))
            .filter_map(|l| l.split_whitespace().next()?.parse::<usize>().ok())
            .next()
            .and_then(|sl| map.get(sl - 1).copied())
            .map(|n| n.to_string())
            .unwrap_or_else(|| "?".into());
        panic!(
            "{file}:{line}: command failed ({status})\n--- stdout\n{}\n--- stderr\n{}",
            tail(&stdout),
            tail(&stderr)
        );
    }
    PageRun { stdout, stderr, work }
}

/// The lab pages: `NN-name.md` in docs/labs.
fn lab_files() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(repo().join("docs/labs"))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".md") && n.as_bytes()[0].is_ascii_digit())
        .collect();
    v.sort();
    v
}

macro_rules! labs {
    ($($(#[$m:meta])* $test:ident => $file:literal),* $(,)?) => {
        $( $(#[$m])* #[test] fn $test() { run_lab($file) } )*
        const TESTED: &[&str] = &[$($file),*];
    };
}

labs! {
    lab01 => "01-p-steering.md",
    lab02 => "02-pd-damping.md",
    lab03 => "03-pid-integral.md",
    lab04 => "04-speed.md",
    lab05 => "05-step-response.md",
    lab06 => "06-camera-model.md",
    lab07 => "07-vision-tuning.md",
    lab08 => "08-detection.md",
    lab09 => "09-monocular-ranging.md",
    lab10 => "10-stereo-ranging.md",
    // shown as ignored (not as passed) in a build without the serial link
    #[cfg_attr(not(feature = "serial"), ignore = "needs --features serial: tests/all.sh stage labs-link")]
    lab11 => "11-serial-link.md",
    lab12 => "12-behaviours.md",
    lab13 => "13-pure-pursuit.md",
    lab14 => "14-routes.md",
    lab15 => "15-data-balance.md",
    lab16 => "16-learned-pilot.md",
}

/// Issue 28, must-show 2: docs/training.md's real-photo recipe runs as written (its `sh`
/// blocks with the page's quick counts), from frames with boxes and from a folder of crops, on
/// material made here: the simulator's track without objects as the car's two recordings,
/// photo-like frames (the simulator's stop sign on OpenCV's sample photos, Debian opencv-doc)
/// for the sign, none of it committed. Then the held-out figures both `evaluate` runs printed
/// (shown on stderr) are checked at minNeighbors 3 against what this data gave, with room for
/// a sign or two: see `RECIPE_*` and docs/training.md, "The recipe as a test".
///
/// Without opencv-doc the test says so and passes, unless `RCCAR_OPENCV_DOC` is set (as
/// tests/all.sh does after installing it).
#[test]
fn training_recipe() {
    let (doc, required) = match std::env::var_os("RCCAR_OPENCV_DOC") {
        Some(d) => (PathBuf::from(d), true),
        None => (PathBuf::from("/usr/share/doc/opencv-doc/examples/data"), false),
    };
    if !doc.join("baboon.jpg").is_file() {
        assert!(!required, "{}: OpenCV's sample photos missing (apt-get install opencv-doc)", doc.display());
        eprintln!("skipped: OpenCV's sample photos not installed (apt-get install opencv-doc)");
        return;
    }
    let run = run_page("docs/training.md", Duration::from_secs(900));
    let d = run.work.path();
    // The page's output without `rccar detect`'s JSON lines: the summaries and both tables.
    let shown: Vec<&str> = run.stdout.lines().filter(|l| !l.starts_with('{')).collect();
    eprintln!("--- the recipe's output\n{}", shown.join("\n"));
    // Step 2: lists relative to themselves (issue 28: they were absolute), and a next step.
    let pos = std::fs::read_to_string(d.join("data/pos.dat")).expect("data/pos.dat");
    assert!(pos.lines().all(|l| l.starts_with("../photos/frames/")), "{pos}");
    assert!(run.stdout.contains("next: rccar-train distort --templates-from-info data/pos.dat"));
    // Step 3: the crops' window is the one given; the boxes' one says what it is.
    assert!(run.stdout.contains("window 14x14"), "{}", run.stdout);
    // Step 4: the summary names the per-frame figures, and the positives the stages used.
    let summary = |key: &str| run.stdout.lines().filter(|l| l.starts_with(key)).collect::<Vec<_>>();
    let held = summary("held-out ");
    assert_eq!(held.len(), 2, "{held:?}");
    assert!(held.iter().all(|l| l.contains("per frame without the object (280)")), "{held:?}");
    let pos = summary("positives ");
    assert!(pos.len() == 2 && pos.iter().all(|l| l.contains("per stage used")), "{pos:?}");
    // The held-out negatives come from other folders than training's: no same-source note.
    assert!(!run.stderr.contains("come from the folders training's backgrounds"), "{}", run.stderr);
    // Step 5: both models, figures named, the track recording's line.
    for (model, min_recall, max_fp_neg, max_fp_track) in [
        ("data/model", RECIPE_BOXES.0, RECIPE_BOXES.1, RECIPE_BOXES.2),
        ("data/model-crops", RECIPE_CROPS.0, RECIPE_CROPS.1, RECIPE_CROPS.2),
    ] {
        let rep: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(model).join("report.json")).expect("report.json"))
                .expect("json");
        let p3 = &rep["points"][3];
        let recall = p3["recall"].as_f64().expect("recall");
        let fp_neg = p3["fp_per_negative_frame"].as_f64().expect("FP per negative frame");
        let track = rep["frames_detail"]
            .as_array()
            .expect("frames_detail")
            .iter()
            .filter(|f| f[0].as_str().is_some_and(|n| n.contains("track-b")))
            .map(|f| f[2].as_u64().expect("fp"))
            .collect::<Vec<_>>();
        let fp_track = track.iter().sum::<u64>() as f64 / track.len().max(1) as f64;
        eprintln!(
            "{model}: recall {recall:.3} ({} of {} boxes), {fp_neg:.4} FP per frame without the sign ({} frames), \
             {fp_track:.4} per track-b frame ({} frames)",
            p3["true_positives"],
            rep["boxes"],
            rep["negative_frames"],
            track.len()
        );
        assert_eq!(rep["sign_frames"].as_u64(), Some(24));
        assert_eq!(rep["negative_frames"].as_u64(), Some(40 + 240));
        assert_eq!(track.len(), 240, "the 8 s recording of track-b");
        assert!(recall >= min_recall, "{model}: recall {recall} < {min_recall}");
        assert!(fp_neg <= max_fp_neg, "{model}: {fp_neg} FP per negative frame > {max_fp_neg}");
        assert!(fp_track <= max_fp_track, "{model}: {fp_track} FP per track frame > {max_fp_track}");
        // The car's minNeighbors, chosen on these held-out frames: the smallest of 1-10 whose
        // false positives per frame without the sign are within the default target 0.01.
        let within = rep["points"].as_array().expect("points").iter().find(|p| {
            p["min_neighbors"].as_u64().is_some_and(|m| m >= 1)
                && p["fp_per_negative_frame"].as_f64().is_some_and(|f| f <= 0.01)
        });
        assert_eq!(rep["target_fp_per_frame"].as_f64(), Some(0.01));
        assert_eq!(
            rep["chosen_min_neighbors"].as_u64(),
            within.and_then(|p| p["min_neighbors"].as_u64()),
            "{model}"
        );
    }
    let choices: Vec<&str> = run.stdout.lines().filter(|l| l.starts_with("choose: ")).collect();
    eprintln!("{}", choices.join("\n"));
    assert_eq!(choices.len(), 2, "{}", run.stdout);
    assert!(run.stdout.contains("track-b: 240 frames without the object"), "{}", run.stdout);
    // Held-out negatives from training's own files, then from its folders: said (one stage).
    let train = |bg: &str, holdout: &str, out: &str| {
        let o = Command::new(bin_dir().join("rccar-train"))
            .args(["train", "--pos", "data/distorted/info.dat", "--bg", bg, "--holdout", holdout])
            .args(["--num-stages", "1", "--num-neg", "50", "--out", out])
            .current_dir(d)
            .output()
            .expect("rccar-train");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).to_string()
    };
    let so = train("track-a", "track-a", "same-files");
    assert!(so.contains("240 of the 240 held-out frames without the object are also training backgrounds"), "{so}");
    let bg = std::fs::read_to_string(d.join("data/bg.txt")).expect("bg.txt");
    let lines: Vec<&str> = bg.lines().collect();
    std::fs::write(d.join("data/half.txt"), lines[..40].join("\n")).expect("half");
    std::fs::write(d.join("data/rest.txt"), lines[40..].join("\n")).expect("rest");
    let so = train("data/half.txt", "data/rest.txt", "same-folder");
    assert!(so.contains("40 of the 40 held-out frames without the object come from the folders"), "{so}");
    // The command the page used to give (a --bg list no step made) fails naming the file once.
    let out = Command::new(bin_dir().join("rccar-train"))
        .args(["distort", "--templates-from-info", "data/pos.dat", "--bg", "data/bg_distort.txt", "--out", "x"])
        .current_dir(d)
        .output()
        .expect("rccar-train");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(err.matches("bg_distort.txt").count(), 1, "{err}");
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
}

/// What the recipe test accepts at minNeighbors 3, (recall ≥, FP per frame without the sign ≤,
/// FP per track-b frame ≤), for the model from boxes and the one from crops. Measured (the
/// run is seeded, its photos are opencv-doc's alone; docs/training.md, "The recipe as a
/// test"): boxes 0.875 (21/24), 1.13, 0.042; crops 0.875 (21/24), 0.79, 0.088 — 12 stages on
/// 30 signs and 80 photos make a weak cascade, and the test says so rather than hide it.
/// Accepted: two signs of the 24 fewer, and about 1.5× the false positives (the track's, 10
/// and 21 of 240 frames, more: a few frames' difference).
const RECIPE_BOXES: (f64, f64, f64) = (0.79, 1.7, 0.15);
const RECIPE_CROPS: (f64, f64, f64) = (0.79, 1.2, 0.2);

#[test]
fn every_lab_page_has_a_test() {
    let files = lab_files();
    assert!(files.len() >= 12, "only {} lab pages", files.len());
    for f in &files {
        assert!(
            TESTED.contains(&f.as_str()),
            "docs/labs/{f} has no test in tests/labs.rs (add it to labs!)"
        );
    }
    for f in TESTED {
        assert!(
            files.iter().any(|x| x == f),
            "tests/labs.rs names docs/labs/{f}, which does not exist"
        );
    }
    // the index links every page
    let index = std::fs::read_to_string(repo().join("docs/labs/README.md")).unwrap();
    for f in &files {
        assert!(
            index.contains(&format!("({f})")),
            "docs/labs/README.md does not link {f}"
        );
    }
}

/// Commands for the real car cannot run here; their flags must still exist.
#[test]
fn car_commands_use_flags_that_exist() {
    let mut checked = 0;
    for f in lab_files() {
        let page = parse(&repo().join("docs/labs").join(&f));
        for b in page.blocks.iter().filter(|b| b.car) {
            // join continuation lines
            let mut cmds: Vec<(usize, String)> = Vec::new();
            let mut acc: Option<(usize, String)> = None;
            for (n, l) in &b.lines {
                let (start, mut s) = acc.take().unwrap_or((*n, String::new()));
                let t = l.trim_end();
                if let Some(x) = t.strip_suffix('\\') {
                    s.push_str(x);
                    s.push(' ');
                    acc = Some((start, s));
                } else {
                    s.push_str(t);
                    cmds.push((start, s));
                }
            }
            for (n, c) in cmds {
                let words: Vec<&str> = c.split_whitespace().collect();
                let Some(i) = words.iter().position(|w| *w == "rccar" || w.ends_with("/rccar")) else {
                    continue;
                };
                // the subcommand path: words after `rccar` up to the first flag or argument
                // that `--help` does not list as a command
                let mut sub: Vec<&str> = Vec::new();
                for w in &words[i + 1..] {
                    if w.starts_with('-') {
                        break;
                    }
                    let mut probe = sub.clone();
                    probe.push(w);
                    let help = help_of(&sub);
                    if help.contains("Commands:") && help.lines().any(|l| l.trim_start().starts_with(&format!("{w} ")))
                    {
                        sub = probe;
                    } else {
                        break;
                    }
                }
                let help = help_of(&sub);
                for w in &words[i + 1..] {
                    if w.starts_with("--") {
                        let flag = w.split('=').next().unwrap();
                        assert!(
                            help.contains(&format!("{flag} ")) || help.contains(&format!("{flag}\n")),
                            "docs/labs/{f}:{n}: `rccar {}` has no flag {flag}",
                            sub.join(" ")
                        );
                        checked += 1;
                    }
                    if matches!(*w, "|" | "&&" | ";" | "&") {
                        break;
                    }
                }
            }
        }
    }
    assert!(checked >= 10, "only {checked} car flags checked");
}

fn help_of(sub: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_rccar"))
        .args(sub)
        .arg("--help")
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).to_string()
}

// ---- the key and the figures the pages quote ----------------------------------------------

/// A figure's value: a number, or a word (how a run ended: `laps_done`).
#[derive(Debug, Clone, PartialEq)]
enum Val {
    Num(f64),
    Word(String),
}

impl std::fmt::Display for Val {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Val::Num(v) => write!(f, "{v}"),
            Val::Word(w) => write!(f, "{w}"),
        }
    }
}

/// One figure of docs/labs/key/key.json.
#[derive(Debug, Clone)]
struct Figure {
    /// `LAB/NAME`, e.g. `01/kp/2/rms_m`.
    id: String,
    value: Val,
    tol: f64,
    unit: String,
    /// A wall-clock time of the machine that made the key: a rerun only checks it is there.
    timing: bool,
}

fn load_key(path: &Path) -> Vec<Figure> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    v["figures"]
        .as_array()
        .unwrap_or_else(|| panic!("{}: no `figures`", path.display()))
        .iter()
        .map(|f| Figure {
            id: format!("{}/{}", f["lab"].as_str().unwrap(), f["name"].as_str().unwrap()),
            value: match &f["value"] {
                serde_json::Value::String(w) => Val::Word(w.clone()),
                n => Val::Num(
                    n.as_f64()
                        .unwrap_or_else(|| panic!("{}: bad value {n}", path.display())),
                ),
            },
            tol: f["tol"].as_f64().unwrap(),
            unit: f["unit"].as_str().unwrap_or("").to_string(),
            timing: f["timing"].as_bool().unwrap_or(false),
        })
        .collect()
}

/// A number as a page writes it: value and the number of digits after the point.
#[derive(Debug, Clone, Copy)]
struct Written {
    v: f64,
    decimals: u32,
    /// Byte range in the text it was read from.
    at: (usize, usize),
}

/// The numbers in `text`: `12`, `0.0413`, `-29.78`, `−0.08` (Unicode minus), `+7.8`; a digit
/// glued to a letter (`v0`, `a_y2`) is not a number, nor is the `2` of `1e-2`.
fn numbers(text: &str) -> Vec<Written> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if !b[i].is_ascii_digit() {
            i += 1;
            continue;
        }
        let before = text[..i].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '.') {
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            continue;
        }
        // a sign right before, itself not glued to a word
        let mut start = i;
        let mut neg = false;
        if let Some(c @ ('-' | '−' | '+')) = before {
            let s = i - c.len_utf8();
            if !text[..s]
                .chars()
                .next_back()
                .is_some_and(|p| p.is_alphanumeric() || p == ')' || p == ']')
            {
                start = s;
                neg = c != '+';
            }
        }
        let mut j = i;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        let mut decimals = 0;
        if j + 1 < b.len() && b[j] == b'.' && b[j + 1].is_ascii_digit() {
            let k = j + 1;
            j = k;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            decimals = (j - k) as u32;
        }
        let v: f64 = text[i..j].parse().unwrap();
        out.push(Written {
            v: if neg { -v } else { v },
            decimals,
            at: (start, j),
        });
        i = j;
    }
    out
}

/// A table label as a figure name: a number as Rust prints it (`2.0` → `2`), anything else
/// lower-cased with each run of other characters as one `_` (`RMS m` → `rms_m`,
/// `cruise → stop_sign` → `cruise_stop_sign`).
fn slug(label: &str) -> String {
    let t = label.replace("**", "");
    let t = t.trim();
    if let Ok(v) = t.parse::<f64>() {
        return format!("{v}");
    }
    let mut s = String::new();
    for c in t.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('_') {
            s.push('_');
        }
    }
    s.trim_matches('_').to_string()
}

/// One figure a page quotes.
#[derive(Debug)]
struct Quote {
    /// Markdown line (1-based).
    line: usize,
    /// The key figure it names (`LAB/NAME`).
    id: String,
    /// What the page says.
    page: Val,
    /// Digits after the point on the page (its rounding).
    decimals: u32,
}

/// Reads the figures a lab page quotes (docs/labs/README.md, "For the teacher"):
/// - `<!-- key: NAME -->` names the figure NAME of this page's lab (`NAME (lab NN)`: of lab
///   NN) for the last number before it on its line;
/// - `<!-- key-table: PREFIX -->` (or `PREFIX labels=2`) before a table: every body cell with
///   one number, or one word, is the figure PREFIX/ROW/COLUMN (labels through [`slug`]; ROW is
///   the first cell, or the first two joined by `/`); free text without digits is not a figure.
///
/// And lints: a table with numbers and no key-table comment, or a number with a decimal point
/// in a paragraph that says "Measured" that names no figure, is an error (a setting there is
/// written as `code` or as an assignment, `Kp = 0.5`). Returns the quotes and the errors (`FILE:LINE: what`).
fn quotes(file: &str, text: &str) -> (Vec<Quote>, Vec<String>) {
    let lab = &file[..2];
    let mut out = Vec::new();
    let mut errs = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut in_code = false;
    let mut table_prefix: Option<(String, usize, usize)> = None; // (prefix, labels, marker line)
    let mut i = 0;
    // paragraph lines (index, text) for the "Measured" lint
    let mut para: Vec<(usize, &str)> = Vec::new();
    let flush = |para: &mut Vec<(usize, &str)>, errs: &mut Vec<String>| {
        if para.iter().any(|(_, l)| l.contains("Measured")) {
            for (n, l) in para.iter() {
                for w in unmarked(l) {
                    // a setting written as an assignment (`Kp = 0.5`) is not a result
                    if w.decimals > 0 && !l[..w.at.0].trim_end().ends_with('=') {
                        errs.push(format!(
                            "{file}:{}: `{}` in a \"Measured\" paragraph names no key figure (add <!-- key: NAME -->, or write a setting as `code`)",
                            n + 1,
                            &l[w.at.0..w.at.1]
                        ));
                    }
                }
            }
        }
        para.clear();
    };
    while i < lines.len() {
        let l = lines[i];
        let t = l.trim();
        if t.starts_with("```") {
            flush(&mut para, &mut errs);
            in_code = !in_code;
            i += 1;
            continue;
        }
        if in_code {
            i += 1;
            continue;
        }
        if let Some(rest) = t.strip_prefix("<!-- key-table:") {
            flush(&mut para, &mut errs);
            let body = rest.trim_end_matches("-->").trim();
            let mut parts = body.split_whitespace();
            let prefix = parts.next().unwrap_or("").to_string();
            let mut labels = 1;
            for p in parts {
                match p.strip_prefix("labels=").and_then(|n| n.parse().ok()) {
                    Some(n) => labels = n,
                    None => errs.push(format!("{file}:{}: key-table: unknown `{p}`", i + 1)),
                }
            }
            table_prefix = Some((prefix, labels, i + 1));
            i += 1;
            continue;
        }
        if t.starts_with('|') {
            flush(&mut para, &mut errs);
            let start = i;
            let mut rows: Vec<(usize, Vec<String>)> = Vec::new();
            while i < lines.len() && lines[i].trim().starts_with('|') {
                let cells: Vec<String> = lines[i]
                    .trim()
                    .trim_matches('|')
                    .split('|')
                    .map(|c| c.trim().to_string())
                    .collect();
                if !cells.iter().all(|c| c.chars().all(|ch| matches!(ch, '-' | ':' | ' '))) {
                    rows.push((i + 1, cells));
                }
                i += 1;
            }
            let Some((prefix, labels, _)) = table_prefix.take() else {
                let has_numbers = rows
                    .iter()
                    .skip(1)
                    .any(|(_, r)| r.iter().skip(1).any(|c| !numbers(c).is_empty()));
                if has_numbers {
                    errs.push(format!(
                        "{file}:{}: a table of numbers without <!-- key-table: PREFIX --> before it",
                        start + 1
                    ));
                }
                continue;
            };
            let Some(((_, head), body)) = rows.split_first() else {
                continue;
            };
            for (n, row) in body {
                let label: Vec<String> = row.iter().take(labels).map(|c| slug(c)).collect();
                for (j, cell) in row.iter().enumerate().skip(labels) {
                    let col = slug(head.get(j).map_or("", |h| h.as_str()));
                    let clean = cell.replace("**", "").replace('`', "");
                    let nums = numbers(&clean);
                    let page = match nums.as_slice() {
                        [] => {
                            let w = clean.trim();
                            if w.is_empty() || w.contains(char::is_whitespace) || matches!(w, "—" | "–" | "-") {
                                continue;
                            }
                            (Val::Word(w.to_string()), 0)
                        }
                        [w] => (Val::Num(w.v), w.decimals),
                        _ => {
                            errs.push(format!(
                                "{file}:{n}: cell `{cell}` holds more than one number (one figure per cell)"
                            ));
                            continue;
                        }
                    };
                    let id = format!("{lab}/{prefix}/{}/{col}", label.join("/"));
                    let alt = (labels == 1).then(|| format!("{lab}/{prefix}/{col}/{}", label[0]));
                    out.push(Quote {
                        line: *n,
                        id: alt.map_or(id.clone(), |a| format!("{id}|{a}")),
                        page: page.0,
                        decimals: page.1,
                    });
                }
            }
            continue;
        }
        if let Some((_, _, m)) = &table_prefix {
            // (blank lines may stand between the comment and its table)
            if !t.is_empty() {
                errs.push(format!("{file}:{m}: key-table comment not followed by a table"));
                table_prefix = None;
            }
        }
        // inline markers
        let mut from = 0;
        while let Some(k) = l[from..].find("<!-- key:") {
            let at = from + k;
            let end = l[at..].find("-->").map(|e| at + e + 3).unwrap_or(l.len());
            let body = l[at + "<!-- key:".len()..end.saturating_sub(3)].trim();
            let (name, flab) = match body.strip_suffix(')').and_then(|b| b.rsplit_once("(lab ")) {
                Some((n, other)) => (n.trim(), other.trim()),
                None => (body, lab),
            };
            let seg = l[from..at].replace("**", "  ");
            match numbers(&seg).last() {
                Some(w) => out.push(Quote {
                    line: i + 1,
                    id: format!("{flab}/{name}"),
                    page: Val::Num(w.v),
                    decimals: w.decimals,
                }),
                None => {
                    // a word figure: the last word before the marker
                    let w = seg
                        .trim_end_matches(|c: char| !c.is_alphanumeric() && c != '_')
                        .rsplit(|c: char| !c.is_alphanumeric() && c != '_')
                        .next()
                        .unwrap_or("");
                    if w.is_empty() {
                        errs.push(format!(
                            "{file}:{}: <!-- key: {body} --> follows no number or word",
                            i + 1
                        ));
                    } else {
                        out.push(Quote {
                            line: i + 1,
                            id: format!("{flab}/{name}"),
                            page: Val::Word(w.to_string()),
                            decimals: 0,
                        });
                    }
                }
            }
            from = end;
        }
        if t.is_empty() || t.starts_with('#') {
            flush(&mut para, &mut errs);
        } else {
            para.push((i, l));
        }
        i += 1;
    }
    flush(&mut para, &mut errs);
    if table_prefix.is_some() {
        errs.push(format!("{file}: a key-table comment at the end"));
    }
    (out, errs)
}

/// The numbers of a line that no `<!-- key -->` names, outside `code`.
fn unmarked(line: &str) -> Vec<Written> {
    // blank out code spans and markers, keeping byte positions
    let mut masked = String::with_capacity(line.len());
    let mut in_tick = false;
    let mut rest = line;
    while let Some(c) = rest.chars().next() {
        if rest.starts_with("<!--") {
            let e = rest.find("-->").map_or(rest.len(), |e| e + 3);
            masked.push_str(&"\u{1}".repeat(e));
            rest = &rest[e..];
            continue;
        }
        if c == '`' {
            in_tick = !in_tick;
        }
        if in_tick || c == '`' {
            masked.push_str(&" ".repeat(c.len_utf8()));
        } else {
            masked.push(c);
        }
        rest = &rest[c.len_utf8()..];
    }
    let nums = numbers(&masked);
    // a number is named when the next thing after it (skipping text without digits) is a marker
    nums.iter()
        .enumerate()
        .filter(|(k, w)| {
            let next_num = nums.get(k + 1).map_or(masked.len(), |n| n.at.0);
            !masked[w.at.1..next_num].contains('\u{1}')
        })
        .map(|(_, w)| *w)
        .collect()
}

/// Compares what the pages quote with `key`; returns one line per disagreement. `timing`
/// figures are compared too (the pages must quote the key's), unless `skip_timing`.
fn check_quotes(file: &str, qs: &[Quote], key: &[Figure], skip_timing: bool) -> Vec<String> {
    let mut bad = Vec::new();
    for q in qs {
        let ids: Vec<&str> = q.id.split('|').collect();
        let Some(f) = ids.iter().find_map(|id| key.iter().find(|f| f.id == *id)) else {
            bad.push(format!("docs/labs/{file}:{}: no figure {} in the key", q.line, ids[0]));
            continue;
        };
        if f.timing && skip_timing {
            continue;
        }
        let ok = match (&q.page, &f.value) {
            (Val::Num(p), Val::Num(k)) => (p - k).abs() <= f.tol + 0.5 * 10f64.powi(-(q.decimals as i32)) + 1e-9,
            (Val::Word(p), Val::Word(k)) => slug(p).replace('_', "") == slug(k).replace('_', ""),
            _ => false,
        };
        if !ok {
            bad.push(format!(
                "docs/labs/{file}:{}: quotes {} for {}, the key has {} {} (tolerance ±{}{})",
                q.line,
                q.page,
                f.id,
                f.value,
                f.unit,
                f.tol,
                if q.decimals > 0 {
                    format!(" + the page's rounding to {} decimals", q.decimals)
                } else {
                    String::new()
                }
            ));
        }
    }
    bad
}

/// Every lab page's quoted figures against `key`: (number of quotes per page, disagreements).
fn check_pages(key: &[Figure], skip_timing: bool) -> (Vec<(String, usize)>, Vec<String>) {
    let mut counts = Vec::new();
    let mut bad = Vec::new();
    for f in lab_files() {
        let text = std::fs::read_to_string(repo().join("docs/labs").join(&f)).unwrap();
        let (qs, errs) = quotes(&f, &text);
        bad.extend(errs.into_iter().map(|e| format!("docs/labs/{e}")));
        bad.extend(check_quotes(&f, &qs, key, skip_timing));
        counts.push((f, qs.len()));
    }
    (counts, bad)
}

/// The lab pages quote only figures of the committed key, each within its tolerance (plus the
/// page's own rounding): a number edited on a page, or a figure regenerated without updating
/// the page, fails here. Quick: reads the committed key, reruns nothing.
#[test]
fn pages_quote_the_committed_key() {
    let key = load_key(&repo().join("docs/labs/key/key.json"));
    let (counts, bad) = check_pages(&key, false);
    for (f, n) in &counts {
        eprintln!("{f}: {n} figures quoted");
    }
    assert!(
        bad.is_empty(),
        "the lab pages disagree with docs/labs/key/key.json:\n{}",
        bad.join("\n")
    );
    for (f, n) in &counts {
        assert!(*n > 0, "docs/labs/{f} quotes no figure of the key");
    }
    // figures of the key no page quotes: the sweeps' other columns (kept for the teacher)
    let quoted: std::collections::HashSet<String> = lab_files()
        .iter()
        .flat_map(|f| {
            let text = std::fs::read_to_string(repo().join("docs/labs").join(f)).unwrap();
            quotes(f, &text)
                .0
                .into_iter()
                .flat_map(|q| q.id.split('|').map(String::from).collect::<Vec<_>>())
        })
        .collect();
    let unused = key.iter().filter(|f| !quoted.contains(&f.id)).count();
    eprintln!(
        "{} key figures, {unused} quoted by no page (the sweeps' other columns, for the teacher)",
        key.len()
    );
}

/// The check above, on a page edited in memory: one quoted number changed beyond its
/// tolerance is reported with its line; the page as committed is not.
#[test]
fn an_edited_figure_on_a_page_is_caught() {
    let key = load_key(&repo().join("docs/labs/key/key.json"));
    let file = "01-p-steering.md";
    let text = std::fs::read_to_string(repo().join("docs/labs").join(file)).unwrap();
    let (qs, errs) = quotes(file, &text);
    assert!(
        errs.is_empty() && check_quotes(file, &qs, &key, false).is_empty(),
        "{errs:?}"
    );
    // the first quoted number in a table, 0.1 larger
    let q = qs
        .iter()
        .find(|q| matches!(q.page, Val::Num(_)) && q.decimals > 0)
        .expect("a number");
    let line = text.lines().nth(q.line - 1).unwrap();
    let w = numbers(line).into_iter().find(|w| w.decimals > 0).unwrap();
    let edited_line = format!(
        "{}{:.*}{}",
        &line[..w.at.0],
        q.decimals as usize,
        w.v + 0.1,
        &line[w.at.1..]
    );
    let edited = text.replacen(line, &edited_line, 1);
    let (qs2, _) = quotes(file, &edited);
    let bad = check_quotes(file, &qs2, &key, false);
    eprintln!("edited line {}: `{edited_line}`\n{}", q.line, bad.join("\n"));
    assert_eq!(bad.len(), 1, "{bad:?}");
    assert!(
        bad[0].starts_with(&format!("docs/labs/{file}:{}:", q.line)),
        "{}",
        bad[0]
    );
    // an unmarked measured decimal is refused
    let (_, errs) = quotes(file, "Measured: RMS 0.0413 m.\n");
    assert_eq!(errs.len(), 1, "{errs:?}");
    // and a table of numbers without its key-table comment
    let (_, errs) = quotes(file, "| Kp | 0.5 |\n|---|---|\n| RMS m | 0.0413 |\n");
    assert_eq!(errs.len(), 1, "{errs:?}");
}

#[test]
fn numbers_and_labels_are_read_as_written() {
    let v: Vec<(f64, u32)> = numbers("x = −29.78 and 348.78, v0 119.16 px, +7.8 %, 10→90, a_y2, 1.5.")
        .iter()
        .map(|w| (w.v, w.decimals))
        .collect();
    assert_eq!(
        v,
        vec![
            (-29.78, 2),
            (348.78, 2),
            (119.16, 2),
            (7.8, 1),
            (10.0, 0),
            (90.0, 0),
            (1.5, 1)
        ]
    );
    assert_eq!(slug("RMS m"), "rms_m");
    assert_eq!(slug("**2.0**"), "2");
    assert_eq!(slug("cruise → stop_sign"), "cruise_stop_sign");
    assert_eq!(slug("settling (±2.5 mm)"), "settling_2_5_mm");
    assert_eq!(
        unmarked("a 1.5<!-- key: x --> b 2.5 `3.5`")
            .iter()
            .map(|w| w.v)
            .collect::<Vec<_>>(),
        vec![2.5]
    );
}

/// The teacher's key regenerated matches the committed one, figure by figure, within each
/// figure's stated tolerance, and the lab pages quote the regenerated figures within it too.
/// Timing figures (wall-clock times) are only checked to be there. Lab 11 of the key talks to
/// the firmware through `rccar link` and `rccar drive`, so this needs the serial build
/// (tests/all.sh stage `labs-link`).
#[test]
#[cfg_attr(
    not(feature = "serial"),
    ignore = "needs --features serial: tests/all.sh stage labs-link"
)]
fn key_matches_committed() {
    ensure_trainer();
    let _fw = FIRMWARE.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::Builder::new().prefix("rccar-key-").tempdir().unwrap();
    let path_var = format!("{}:{}", bin_dir().display(), std::env::var("PATH").unwrap_or_default());
    let t = Instant::now();
    let out = Command::new("bash")
        .arg(repo().join("docs/labs/key/make.sh"))
        .arg(dir.path())
        .current_dir(dir.path())
        .env("PATH", path_var)
        .env_remove("LABS")
        .output()
        .unwrap();
    eprintln!("key regenerated in {:.1} s", t.elapsed().as_secs_f64());
    // what each lab's figures cost (make.sh: "lab NN took N s, N s of CPU")
    for l in String::from_utf8_lossy(&out.stderr).lines().filter(|l| l.contains(" took ")) {
        eprintln!("{l}");
    }
    assert!(
        out.status.success(),
        "make.sh failed\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let committed = load_key(&repo().join("docs/labs/key/key.json"));
    let fresh = load_key(&dir.path().join("key.json"));
    let mut bad = Vec::new();
    for lab in 1..=12 {
        let l = format!("{lab:02}/");
        if !committed.iter().any(|f| f.id.starts_with(&l)) {
            bad.push(format!("lab {lab:02}: no figure in the committed key"));
        }
    }
    for c in &committed {
        match fresh.iter().find(|x| x.id == c.id) {
            None => bad.push(format!("{}: missing from the regenerated key", c.id)),
            Some(n) => {
                let ok = match (&c.value, &n.value) {
                    _ if c.timing => matches!(n.value, Val::Num(v) if v.is_finite() && v >= 0.0),
                    (Val::Num(a), Val::Num(b)) => (a - b).abs() <= c.tol,
                    (Val::Word(a), Val::Word(b)) => a == b,
                    _ => false,
                };
                if !ok {
                    bad.push(format!(
                        "{}: committed {} {}, regenerated {}, tolerance ±{}",
                        c.id, c.value, c.unit, n.value, c.tol
                    ));
                }
            }
        }
    }
    for n in &fresh {
        if !committed.iter().any(|x| x.id == n.id) {
            bad.push(format!(
                "{}: new figure not in the committed key (run bash docs/labs/key/make.sh)",
                n.id
            ));
        }
    }
    // the pages against the regenerated key (timing figures: against the committed one, in
    // pages_quote_the_committed_key)
    let (_, page_bad) = check_pages(&fresh, true);
    bad.extend(page_bad);
    eprintln!(
        "{} figures of the committed key compared; {} problems (figures or pages)",
        committed.len(),
        bad.len()
    );
    assert!(bad.is_empty(), "the key changed:\n{}", bad.join("\n"));
}
