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
//! The key: `bash docs/labs/key/make.sh DIR` writes DIR/key.json (each figure with its
//! tolerance) and DIR/key.md; `key_matches_committed` runs it into a temporary folder and
//! compares every figure with the committed docs/labs/key/key.json within the committed
//! tolerance. Regenerate the committed key on purpose: `bash docs/labs/key/make.sh`.
//! Units are those of each figure (stated in key.json); times are simulated seconds.

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
                    assert!(hit, "{name}:{qn}: quick substitution `{old}` matches nothing in the next block");
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
            let b = Block { car: info.trim() == "sh car", lines: Vec::new() };
            let keep = matches!(info.trim(), "sh" | "sh car");
            if !keep {
                assert!(pending.is_empty(), "{name}:{n}: a quick substitution must be followed by an `sh` block");
            }
            cur = Some((b, keep));
        }
    }
    assert!(cur.is_none(), "{name}: an unclosed code block");
    assert!(pending.is_empty(), "{name}: a quick substitution with no block after it");
    Page { blocks, needs_serial }
}

/// Runs every `sh` block of `docs/labs/<file>` as one script; panics naming the line.
fn run_lab(file: &str) {
    let path = repo().join("docs/labs").join(file);
    let page = parse(&path);
    assert!(
        !page.needs_serial || cfg!(feature = "serial"),
        "{file}: needs the `serial` feature (cargo test --release --features serial --test car labs::)"
    );
    // the firmware lab and the key both build and run the emulator: one at a time
    let _fw = page.needs_serial.then(|| FIRMWARE.lock().unwrap_or_else(|e| e.into_inner()));
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
    let limit = Duration::from_secs(300);
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
    let tail = |s: &str| s.lines().rev().take(25).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n");
    let Some(status) = status else {
        panic!("{file}: still running after {} s\n--- stdout\n{}\n--- stderr\n{}", limit.as_secs(), tail(&stdout), tail(&stderr));
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
            "docs/labs/{file}:{line}: command failed ({status})\n--- stdout\n{}\n--- stderr\n{}",
            tail(&stdout),
            tail(&stderr)
        );
    }
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
}

#[test]
fn every_lab_page_has_a_test() {
    let files = lab_files();
    assert!(files.len() >= 12, "only {} lab pages", files.len());
    for f in &files {
        assert!(TESTED.contains(&f.as_str()), "docs/labs/{f} has no test in tests/labs.rs (add it to labs!)");
    }
    for f in TESTED {
        assert!(files.iter().any(|x| x == f), "tests/labs.rs names docs/labs/{f}, which does not exist");
    }
    // the index links every page
    let index = std::fs::read_to_string(repo().join("docs/labs/README.md")).unwrap();
    for f in &files {
        assert!(index.contains(&format!("({f})")), "docs/labs/README.md does not link {f}");
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
                let Some(i) = words.iter().position(|w| *w == "rccar" || w.ends_with("/rccar")) else { continue };
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
                    if help.contains("Commands:") && help.lines().any(|l| l.trim_start().starts_with(&format!("{w} "))) {
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
    let out = Command::new(env!("CARGO_BIN_EXE_rccar")).args(sub).arg("--help").output().unwrap();
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// The teacher's key regenerated matches the committed one, figure by figure, within each
/// figure's stated tolerance.
#[test]
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
        .output()
        .unwrap();
    eprintln!("key regenerated in {:.1} s", t.elapsed().as_secs_f64());
    assert!(
        out.status.success(),
        "make.sh failed\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let load = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let committed = load(&repo().join("docs/labs/key/key.json"));
    let fresh = load(&dir.path().join("key.json"));
    let figs = |v: &serde_json::Value| -> Vec<(String, f64, f64, String)> {
        v["figures"]
            .as_array()
            .expect("figures")
            .iter()
            .map(|f| {
                (
                    format!("{}/{}", f["lab"].as_str().unwrap(), f["name"].as_str().unwrap()),
                    f["value"].as_f64().unwrap(),
                    f["tol"].as_f64().unwrap(),
                    f["unit"].as_str().unwrap_or("").to_string(),
                )
            })
            .collect()
    };
    let c = figs(&committed);
    let n = figs(&fresh);
    assert!(c.len() >= 12, "the committed key has only {} figures", c.len());
    let mut bad = Vec::new();
    for (name, v, tol, unit) in &c {
        match n.iter().find(|x| &x.0 == name) {
            None => bad.push(format!("{name}: missing from the regenerated key")),
            Some((_, nv, _, _)) => {
                let ok = (nv - v).abs() <= *tol;
                eprintln!("{name}: committed {v} {unit}, now {nv} (tol ±{tol}) {}", if ok { "ok" } else { "DIFFERS" });
                if !ok {
                    bad.push(format!("{name}: committed {v} {unit}, regenerated {nv}, tolerance ±{tol}"));
                }
            }
        }
    }
    for (name, ..) in &n {
        if !c.iter().any(|x| &x.0 == name) {
            bad.push(format!("{name}: new figure not in the committed key (run bash docs/labs/key/make.sh)"));
        }
    }
    assert!(bad.is_empty(), "the key changed:\n{}", bad.join("\n"));
}
