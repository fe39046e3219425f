//! Issue 24, "runs lost or mixed": a run never destroys or mixes another. Each case of the
//! issue as the command a student would type, in a temporary folder: an output folder that
//! holds a run is refused with the fix in the message, the default output is a new folder per
//! run (`out/sim/<date-time>/`, `out/sim/latest`), a run that fails to start leaves nothing
//! behind, a recording is never written into or replayed mixed, `report` refuses files of two
//! runs, and Ctrl-C during a sweep writes no rows for the runs that never started.

use rccar::record::{RecordOptions, Recorder};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const EXE: &str = env!("CARGO_BIN_EXE_rccar");

struct Out {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// `rccar ARGS` in `cwd` with the shipped configuration (no local.toml, detection off: the
/// runs stay short).
fn rccar(cwd: &Path, args: &[&str]) -> Out {
    let mut c = Command::new(EXE);
    c.current_dir(cwd).args(args);
    if !matches!(args.first(), Some(&"report")) {
        c.arg("--config").arg(Path::new(ROOT).join("config/car.toml"));
        c.args(["--no-local", "--set", "detect.enabled=false"]);
    }
    let o = c.env_remove("RCCAR_CONFIG").stdin(Stdio::null()).output().unwrap();
    let out = Out {
        code: o.status.code(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    assert!(
        !out.stderr.contains("panicked"),
        "rccar {args:?} panicked:\n{}",
        out.stderr
    );
    out
}

fn error_line(o: &Out) -> String {
    let l: Vec<&str> = o.stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(l.len(), 1, "one error line expected:\n{}{}", o.stdout, o.stderr);
    l[0].to_string()
}

fn lines(p: &Path) -> usize {
    std::fs::read_to_string(p).map_or(0, |s| s.lines().count())
}

/// Every telemetry.jsonl under `dir` (any depth, symlinks not followed): its lines and an FNV-1a
/// hash of its bytes.
fn telemetry_files(dir: &Path) -> Vec<(PathBuf, usize, u64)> {
    let mut v = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else { return v };
    for e in rd.flatten() {
        let p = e.path();
        let ft = e.file_type().unwrap();
        if ft.is_dir() {
            v.extend(telemetry_files(&p));
        } else if ft.is_file() && p.file_name().is_some_and(|n| n == "telemetry.jsonl") {
            let b = std::fs::read(&p).unwrap();
            let hash = b.iter().fold(0xcbf29ce484222325u64, |h, &x| {
                (h ^ x as u64).wrapping_mul(0x100000001b3)
            });
            v.push((p.clone(), b.iter().filter(|&&x| x == b'\n').count(), hash));
        }
    }
    v.sort();
    v
}

/// The run folders under a default parent (`out/sim`): every entry but `latest`.
fn run_folders(parent: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(parent)
        .map(|rd| {
            rd.flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir() && !p.ends_with("latest"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
}

const SHORT_SIM: [&str; 6] = ["sim", "--laps", "0", "--seconds", "0.5", "--no-timing"];

#[test]
fn sim_twice_with_the_default_out_keeps_both_runs() {
    let t = tempfile::tempdir().unwrap();
    let a = rccar(t.path(), &SHORT_SIM);
    assert_eq!(a.code, Some(0), "{}{}", a.stdout, a.stderr);
    let b = rccar(t.path(), &SHORT_SIM);
    assert_eq!(b.code, Some(0), "{}{}", b.stdout, b.stderr);
    let parent = t.path().join("out/sim");
    let runs = run_folders(&parent);
    assert_eq!(runs.len(), 2, "two runs, two folders: {runs:?}");
    for r in &runs {
        assert_eq!(lines(&r.join("telemetry.jsonl")), 15, "{}", r.display());
        let run = json(&r.join("run.json"));
        assert_eq!(run["command"], "sim");
        assert_eq!(json(&r.join("summary.json"))["run_id"], run["run_id"]);
        assert_eq!(json(&r.join("config.json"))["run_id"], run["run_id"]);
        assert_eq!(run["telemetry_frames"], 15);
        assert_eq!(run["state"], "finished");
    }
    assert_ne!(
        json(&runs[0].join("run.json"))["run_id"],
        json(&runs[1].join("run.json"))["run_id"]
    );
    // latest points at the second run, and each run printed its folder.
    let latest = std::fs::canonicalize(parent.join("latest")).unwrap();
    let printed = |o: &Out, r: &Path| {
        o.stdout
            .contains(&format!("{}/", r.file_name().unwrap().to_string_lossy()))
    };
    let second = runs.iter().find(|r| printed(&b, r)).expect("folder printed");
    assert!(
        runs.iter().any(|r| printed(&a, r) && r != second),
        "the first run printed its folder"
    );
    assert_eq!(latest, std::fs::canonicalize(second).unwrap());
    // `report out/sim` reports the newest run.
    let r = rccar(t.path(), &["report", "out/sim"]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    assert!(second.join("report.html").is_file());
}

#[test]
fn an_explicit_out_that_holds_a_run_is_refused_before_anything_is_written() {
    let t = tempfile::tempdir().unwrap();
    let first = rccar(t.path(), &[&SHORT_SIM[..], &["-o", "mine"]].concat());
    assert_eq!(first.code, Some(0), "{}{}", first.stdout, first.stderr);
    let before = telemetry_files(t.path());
    let summary = std::fs::read(t.path().join("mine/summary.json")).unwrap();
    // Again into the same folder, longer: refused, nothing touched.
    let again = rccar(t.path(), &["sim", "--laps", "0", "--seconds", "1", "-o", "mine"]);
    assert_eq!(again.code, Some(2), "{}{}", again.stdout, again.stderr);
    let e = error_line(&again);
    println!("{e}");
    assert!(
        e.contains("mine") && e.contains("holds a run of") && e.contains("(15 frames)"),
        "{e}"
    );
    assert!(e.contains("choose another --out, or remove it"), "{e}");
    assert_eq!(
        telemetry_files(t.path()),
        before,
        "the first run's telemetry is untouched"
    );
    assert_eq!(std::fs::read(t.path().join("mine/summary.json")).unwrap(), summary);
    // A folder with anything else in it is refused too; an empty one is fine.
    std::fs::create_dir(t.path().join("notes")).unwrap();
    std::fs::write(t.path().join("notes/todo.txt"), "tune kd").unwrap();
    let o = rccar(t.path(), &[&SHORT_SIM[..], &["-o", "notes"]].concat());
    assert_eq!(o.code, Some(2));
    assert!(error_line(&o).contains("not empty"), "{}", o.stderr);
    assert_eq!(std::fs::read_dir(t.path().join("notes")).unwrap().count(), 1);
    std::fs::create_dir(t.path().join("empty")).unwrap();
    assert_eq!(
        rccar(t.path(), &[&SHORT_SIM[..], &["-o", "empty"]].concat()).code,
        Some(0)
    );
    // replay into a folder holding a replay: refused (its annotated frames would mix).
    let sample = format!("{ROOT}/tests/data/lane_sample");
    let r1 = rccar(t.path(), &["replay", &sample, "--no-timing", "-o", "rep"]);
    assert_eq!(r1.code, Some(0), "{}", r1.stderr);
    let annotated = std::fs::read_dir(t.path().join("rep/annotated")).unwrap().count();
    let r2 = rccar(t.path(), &["replay", &sample, "--no-timing", "-o", "rep"]);
    assert_eq!(r2.code, Some(2));
    assert!(error_line(&r2).contains("holds a run of"), "{}", r2.stderr);
    assert_eq!(
        std::fs::read_dir(t.path().join("rep/annotated")).unwrap().count(),
        annotated
    );
}

#[test]
fn a_drive_that_fails_to_start_leaves_the_previous_run_whole() {
    let t = tempfile::tempdir().unwrap();
    let ok = rccar(t.path(), &["drive", "--camera", "sim", "--dry-run", "--seconds", "2"]);
    assert_eq!(ok.code, Some(0), "{}{}", ok.stdout, ok.stderr);
    let before = telemetry_files(t.path());
    assert_eq!(before.len(), 1);
    let n = before[0].1;
    assert!(n >= 10, "{n} frames in 2 s");
    let folders = run_folders(&t.path().join("out/drive"));
    // Fails after the output was set up (the frame source is checked late).
    let bad = rccar(t.path(), &["drive", "--camera", "no/such/folder", "--dry-run"]);
    assert_eq!(bad.code, Some(2));
    assert!(error_line(&bad).contains("no/such/folder"));
    assert_eq!(
        telemetry_files(t.path()),
        before,
        "the previous run's telemetry is untouched"
    );
    assert_eq!(
        run_folders(&t.path().join("out/drive")),
        folders,
        "the failed run left no folder"
    );
    // and its report is one run's
    let r = rccar(t.path(), &["report", "out/drive/latest"]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    let md = std::fs::read_to_string(t.path().join("out/drive/latest/report.md")).unwrap();
    assert!(md.contains(&format!("| frames in telemetry | {n} |")), "{md}");
    assert!(md.contains(&format!("| frames | {n} |")), "{md}");
}

#[test]
fn a_failed_drive_record_leaves_nothing_and_the_retry_works() {
    let t = tempfile::tempdir().unwrap();
    let bad = rccar(
        t.path(),
        &[
            "drive",
            "--camera",
            "no/such/folder",
            "--dry-run",
            "--record",
            "rec",
            "-o",
            "o1",
        ],
    );
    assert_eq!(bad.code, Some(2));
    assert!(
        !t.path().join("rec").exists(),
        "the failed run left its recording folder"
    );
    assert!(!t.path().join("o1").exists(), "the failed run left its output folder");
    let retry = rccar(
        t.path(),
        &[
            "drive",
            "--camera",
            "sim",
            "--dry-run",
            "--seconds",
            "2",
            "--record",
            "rec",
            "-o",
            "o2",
        ],
    );
    assert_eq!(retry.code, Some(0), "{}{}", retry.stdout, retry.stderr);
    assert!(lines(&t.path().join("rec/telemetry.jsonl")) >= 10);
}

#[test]
fn sim_record_into_an_old_recording_is_refused() {
    let t = tempfile::tempdir().unwrap();
    let a = rccar(
        t.path(),
        &[
            "sim",
            "--laps",
            "0",
            "--seconds",
            "1",
            "--no-timing",
            "--record",
            "frames",
            "-o",
            "a",
        ],
    );
    assert_eq!(a.code, Some(0), "{}", a.stderr);
    let pngs = |d: &Path| {
        let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| {
                (
                    e.file_name().to_string_lossy().into_owned(),
                    std::fs::read(e.path()).unwrap(),
                )
            })
            .collect();
        v.sort();
        v
    };
    let before = pngs(&t.path().join("frames"));
    assert_eq!(before.len(), 30);
    let b = rccar(
        t.path(),
        &[
            "sim",
            "--laps",
            "0",
            "--seconds",
            "0.3",
            "--no-timing",
            "--seed",
            "9",
            "--record",
            "frames",
            "-o",
            "b",
        ],
    );
    assert_eq!(b.code, Some(2), "{}{}", b.stdout, b.stderr);
    let e = error_line(&b);
    assert!(
        e.contains("--record") && e.contains("frames") && e.contains("30 frames"),
        "{e}"
    );
    assert_eq!(pngs(&t.path().join("frames")), before, "the old recording is untouched");
    assert!(!t.path().join("b").exists(), "nothing of the refused run was created");
}

/// A drive recording of 1 s (about 30 frames) in `dir/rec`.
fn drive_recording(dir: &Path) -> PathBuf {
    let o = rccar(
        dir,
        &[
            "drive",
            "--camera",
            "sim",
            "--dry-run",
            "--seconds",
            "1",
            "--record",
            "rec",
            "-o",
            "drive",
        ],
    );
    assert_eq!(o.code, Some(0), "{}{}", o.stdout, o.stderr);
    dir.join("rec")
}

#[test]
fn replay_into_its_own_recording_is_refused() {
    let t = tempfile::tempdir().unwrap();
    let rec = drive_recording(t.path());
    let tel = std::fs::read(rec.join("telemetry.jsonl")).unwrap();
    for out in ["rec", "rec/replay", "rec/seg_000000"] {
        let o = rccar(t.path(), &["replay", "rec", "--no-annotate", "-o", out]);
        assert_eq!(o.code, Some(2), "-o {out}: {}{}", o.stdout, o.stderr);
        let e = error_line(&o);
        println!("-o {out}: {e}");
        assert!(e.contains("-o") || e.contains("--out"), "{e}");
    }
    assert_eq!(
        std::fs::read(rec.join("telemetry.jsonl")).unwrap(),
        tel,
        "the recording's telemetry is untouched"
    );
    assert!(!rec.join("replay").exists());
}

/// A recording with frames `frames` (a late frame dropped in between) whose telemetry lines
/// are `tel` (frame number → line; `None` writes the line cut in half).
fn recording(dir: &Path, frames: &[u64], line: impl Fn(u64) -> Option<String>) -> PathBuf {
    let rec = dir.join("rec");
    let mut r = Recorder::create(&rec, RecordOptions::default()).unwrap();
    let img = image::open(Path::new(ROOT).join("tests/data/lane_sample/frame_000.png"))
        .unwrap()
        .to_rgb8();
    for &k in frames {
        r.write_frame(k, &img).unwrap();
        let full = format!("{{\"frame\":{k},\"time_s\":{},\"steer\":0.0}}", k as f64 / 30.0);
        match line(k) {
            Some(l) => r.write_telemetry_line(&l).unwrap(),
            None => r.write_telemetry_line(&full[..full.len() / 2]).unwrap(),
        }
    }
    r.finish().unwrap();
    rec
}

fn replay_records(dir: &Path, rec: &Path) -> (Out, Vec<serde_json::Value>) {
    let out = dir.join(format!("replay_{}", std::fs::read_dir(dir).unwrap().count()));
    let o = rccar(
        dir,
        &[
            "replay",
            rec.to_str().unwrap(),
            "--no-annotate",
            "--no-timing",
            "-o",
            out.to_str().unwrap(),
        ],
    );
    let recs = std::fs::read_to_string(out.join("telemetry.jsonl"))
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    (o, recs)
}

#[test]
fn a_recording_with_a_cut_line_replays_in_order_without_the_frame() {
    let t = tempfile::tempdir().unwrap();
    // Frames 0, 2, 3, 4, 5 (1 came late), frame 3's line cut (the card filled up mid-line).
    let full = |k: u64| format!("{{\"frame\":{k},\"time_s\":{},\"steer\":0.0}}", k as f64 / 30.0);
    let rec = recording(t.path(), &[0, 2, 3, 4, 5], |k| (k != 3).then(|| full(k)));
    let (o, recs) = replay_records(t.path(), &rec);
    assert_eq!(o.code, Some(0), "{}{}", o.stdout, o.stderr);
    let frames: Vec<u64> = recs.iter().map(|r| r["frame"].as_u64().unwrap()).collect();
    let times: Vec<f64> = recs.iter().map(|r| r["time_s"].as_f64().unwrap()).collect();
    println!("replayed frames {frames:?} at {times:?}\n{}", o.stdout);
    assert_eq!(
        frames,
        vec![0, 2, 4, 5],
        "the frame without a time is skipped, the others keep their numbers"
    );
    for w in times.windows(2) {
        assert!(w[1] > w[0] + 0.03, "time steps {times:?}");
    }
    assert!(
        (times[1] - 2.0 / 30.0).abs() < 1e-9 && (times[3] - 5.0 / 30.0).abs() < 1e-9,
        "{times:?}"
    );
    assert!(
        o.stdout.contains("telemetry.jsonl:3"),
        "the cut line is named:\n{}",
        o.stdout
    );
    assert!(
        o.stdout.contains("frame_000000003.jpg"),
        "the frame without a time is named:\n{}",
        o.stdout
    );
}

#[test]
fn a_recording_with_bad_times_or_frame_numbers_is_refused_naming_the_line() {
    let t = tempfile::tempdir().unwrap();
    type Line = Box<dyn Fn(u64) -> String>;
    let cases: [(&str, Line, &str); 4] = [
        (
            "negative time",
            Box::new(|k| {
                format!(
                    "{{\"frame\":{k},\"time_s\":{}}}",
                    if k == 0 { -100.0 } else { k as f64 / 30.0 }
                )
            }),
            ":1:",
        ),
        (
            "time going back",
            Box::new(|k| {
                format!(
                    "{{\"frame\":{k},\"time_s\":{}}}",
                    if k == 3 { 0.01 } else { k as f64 / 30.0 }
                )
            }),
            ":4:",
        ),
        (
            "same frame twice",
            Box::new(|k| {
                format!(
                    "{{\"frame\":{},\"time_s\":{}}}",
                    if k == 3 { 2 } else { k },
                    k as f64 / 30.0
                )
            }),
            ":4:",
        ),
        // a NaN time is written as null
        (
            "a time that is not a number",
            Box::new(|k| {
                format!(
                    "{{\"frame\":{k},\"time_s\":{}}}",
                    if k == 1 {
                        "null".to_string()
                    } else {
                        (k as f64 / 30.0).to_string()
                    }
                )
            }),
            ":2:",
        ),
    ];
    for (what, line, at) in cases {
        let d = t.path().join(what.replace(' ', "_"));
        std::fs::create_dir(&d).unwrap();
        let rec = recording(&d, &[0, 1, 2, 3, 4], |k| Some(line(k)));
        let (o, recs) = replay_records(&d, &rec);
        assert_eq!(o.code, Some(2), "{what}: {}{}", o.stdout, o.stderr);
        let e = error_line(&o);
        println!("{what}: {e}");
        assert!(e.contains(&format!("telemetry.jsonl{at}")), "{what}: {e}");
        assert!(recs.is_empty(), "{what}: nothing replayed");
    }
}

fn sim_run(dir: &Path, out: &str, seconds: &str) {
    let o = rccar(
        dir,
        &["sim", "--laps", "0", "--seconds", seconds, "--no-timing", "-o", out],
    );
    assert_eq!(o.code, Some(0), "{}{}", o.stdout, o.stderr);
}

#[test]
fn report_refuses_files_of_two_runs() {
    let t = tempfile::tempdir().unwrap();
    sim_run(t.path(), "a", "0.5");
    sim_run(t.path(), "b", "1");
    // Run b's telemetry (30 frames) beside run a's summary (15 frames).
    std::fs::copy(t.path().join("b/telemetry.jsonl"), t.path().join("a/telemetry.jsonl")).unwrap();
    let o = rccar(t.path(), &["report", "a"]);
    assert_ne!(o.code, Some(0), "{}{}", o.stdout, o.stderr);
    let all = format!("{}{}", o.stdout, o.stderr);
    println!("{all}");
    assert!(
        all.contains("telemetry.jsonl") && all.contains("30") && all.contains("15"),
        "{all}"
    );
    assert!(!t.path().join("a/report.html").exists(), "no report of a mixed folder");
    // Run b's config beside run a's summary: the run ids differ.
    sim_run(t.path(), "c", "0.5");
    std::fs::copy(t.path().join("b/config.json"), t.path().join("c/config.json")).unwrap();
    let o = rccar(t.path(), &["report", "c"]);
    assert_ne!(o.code, Some(0));
    let all = format!("{}{}", o.stdout, o.stderr);
    assert!(all.contains("config.json"), "{all}");
    // A plot of another run is named and left out.
    sim_run(t.path(), "d", "0.5");
    std::fs::write(
        t.path().join("d/old_plot.png"),
        std::fs::read(t.path().join("b/path.png")).unwrap_or_default(),
    )
    .unwrap();
    let o = rccar(t.path(), &["report", "d"]);
    let all = format!("{}{}", o.stdout, o.stderr);
    assert!(all.contains("old_plot.png"), "{all}");
    let html = std::fs::read_to_string(t.path().join("d/report.html")).unwrap_or_default();
    assert!(!html.contains("old_plot.png"), "another run's plot is not embedded");
    // --force writes the report with the warning on top.
    let o = rccar(t.path(), &["report", "a", "--force"]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let md = std::fs::read_to_string(t.path().join("a/report.md")).unwrap();
    assert!(md.contains("do not belong to one run"), "{md}");
}

#[test]
fn report_refuses_the_issue_folder_a_summary_and_an_emptied_telemetry() {
    // What an older rccar left in out/drive: a summary of 28 frames, its telemetry emptied by a
    // drive that failed to start, no run.json.
    let t = tempfile::tempdir().unwrap();
    let d = t.path().join("out/drive");
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(
        d.join("summary.json"),
        r#"{"track":"default","frames":28,"seconds":0.93,"laps":0,"end":"time_up"}"#,
    )
    .unwrap();
    std::fs::write(d.join("telemetry.jsonl"), "").unwrap();
    let o = rccar(t.path(), &["report", "out/drive"]);
    let all = format!("{}{}", o.stdout, o.stderr);
    println!("{all}");
    assert_ne!(o.code, Some(0), "{all}");
    assert!(
        all.contains("28") && all.contains("telemetry.jsonl") && all.contains('0'),
        "{all}"
    );
}

#[test]
fn ctrl_c_during_a_sweep_writes_no_rows_for_runs_that_never_started() {
    let t = tempfile::tempdir().unwrap();
    let mut child = Command::new(EXE)
        .current_dir(t.path())
        .args([
            "sim",
            "--laps",
            "0",
            "--seconds",
            "6",
            "--no-timing",
            "--jobs",
            "1",
            "-o",
            "sw",
        ])
        .args(["--sweep", "steering.kp=0.5:3:12", "--config"])
        .arg(Path::new(ROOT).join("config/car.toml"))
        .args(["--no-local", "--set", "detect.enabled=false"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Progress: one line per finished run, while the sweep runs.
    let (tx, rx) = std::sync::mpsc::channel();
    let stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for l in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(l.clone());
            all += &l;
            all.push('\n');
        }
        all
    });
    let t0 = Instant::now();
    let mut progress = None;
    while t0.elapsed() < Duration::from_secs(120) {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(l) if l.contains("[1/12]") => {
                progress = Some(l);
                break;
            }
            Ok(_) | Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(_) => break, // exited
        }
    }
    let _ = Command::new("kill").args(["-INT", &child.id().to_string()]).status();
    let status = child.wait().unwrap();
    let stdout = reader.join().unwrap();
    println!("{stdout}");
    let progress = progress.expect("a progress line after the first run, before the sweep ended");
    assert!(progress.contains("steering.kp=0.5"), "{progress}");
    assert_eq!(status.code(), Some(130), "{stdout}");
    let csv = std::fs::read_to_string(t.path().join("sw/sweep.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    println!("{csv}");
    assert!(!rows.is_empty() && rows.len() < 12, "{} rows", rows.len());
    for r in &rows {
        let end = r.rsplit(',').next().unwrap();
        let laps_rms: Vec<&str> = r.split(',').skip(1).take(4).collect();
        assert!(
            end == "time_up" || end == "interrupted" || end == "left_the_road" || end == "stalled",
            "{r}"
        );
        if end != "interrupted" {
            assert!(laps_rms[2] != "0", "a row with RMS 0 is a run that never ran: {r}");
        }
    }
    // The terminal says which ran and which did not.
    assert!(stdout.contains("not run"), "{stdout}");
    let finished = stdout.lines().filter(|l| l.contains("/12]")).count();
    let cut = rows.iter().filter(|r| r.ends_with(",interrupted")).count();
    assert_eq!(
        rows.len(),
        finished,
        "one row per run that finished or was cut short (cut short: {cut})"
    );
}
