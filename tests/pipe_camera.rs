//! Issue 30: frames from a camera program's stdout (`--camera 'pipe:FORMAT:COMMAND'`, the
//! camera module's `picam:N` through rpicam-vid) — shown here with a producer Debian packages
//! (ffmpeg's testsrc at 320×240, 30 fps), since this machine has no camera:
//! 1. frames delivered and the capture → command latency reported (`drive`, `camera check`);
//! 2. a frozen producer (SIGSTOP) is a stall: neutral within 0.5 s; SIGCONT: driving resumes;
//! 3. Ctrl-C, SIGTERM and SIGHUP leave no camera program behind (and SIGKILL of rccar: the
//!    parent-death signal ends it);
//! 4. garbage and short frames are counted unusable frames, in bounded memory;
//! 5. the simulator's own frames through a pipe drive its lap with the same decisions.

use rccar::config::Config;
use rccar::drive::{Flow, FrameContext, Level, LoopError, Observer, StopReason, StopSignal};
use rccar::session::{ArmAt, CameraSpec, DetectorSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::source::FrameError;
use rccar::timing::{Clock, NoTimer};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_rccar");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rccar-pipe-camera-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// ffmpeg is what these tests run as a camera; tests/all.sh installs it. Without it they
/// cannot check anything, so they fail rather than pass unchecked.
fn need_ffmpeg() {
    let ok = Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        ok,
        "these tests need ffmpeg as a camera: apt-get install ffmpeg (tests/all.sh installs it)"
    );
}

/// ffmpeg's test pattern at 320×240, 30 fps in real time, as raw I420 on stdout; `token`
/// marks its command line so that /proc can find it (and anything it leaves behind).
fn testsrc(token: &str) -> String {
    format!(
        "pipe:yuv420:ffmpeg -nostdin -loglevel error -re -f lavfi -i testsrc=size=320x240:rate=30 -pix_fmt yuv420p -metadata comment={token} -f rawvideo -"
    )
}

fn token(name: &str) -> String {
    format!("rccar-test-{}-{name}", std::process::id())
}

/// Processes whose command line holds `token` and that are not rccar itself: (pid, state,
/// command line). A zombie (state Z) holds no camera; it is listed all the same.
fn left_behind(token: &str) -> Vec<(u32, char, String)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        if !cmd.contains(token) || cmd.contains(" drive ") || cmd.contains(" camera check") {
            continue;
        }
        let state = std::fs::read_to_string(e.path().join("stat"))
            .ok()
            .and_then(|s| s.rsplit(')').next().and_then(|r| r.trim_start().chars().next()))
            .unwrap_or('?');
        out.push((pid, state, cmd));
    }
    out
}

fn alive(token: &str) -> Vec<(u32, char, String)> {
    left_behind(token).into_iter().filter(|p| p.1 != 'Z').collect()
}

fn records(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("telemetry.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Must show 1: frames delivered and the capture → command latency reported, through the
/// whole car (`drive --dry-run`, armed) with ffmpeg's testsrc as the camera.
#[test]
fn testsrc_frames_drive_the_loop_and_latency_is_reported() {
    need_ffmpeg();
    let tok = token("frames");
    let out = scratch("frames");
    let o = Command::new(EXE)
        .current_dir(root())
        .args([
            "drive",
            "--camera",
            &testsrc(&tok),
            "--dry-run",
            "--arm",
            "--seconds",
            "4",
        ])
        .args(["--set", "detect.enabled=false", "--status-every", "1", "--out"])
        .arg(&out)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert_eq!(o.status.code(), Some(0), "{stdout}\n{stderr}");
    let recs = records(&out);
    let mut lat: Vec<f64> = recs.iter().filter_map(|r| r["latency_ms"].as_f64()).collect();
    let line = stdout
        .lines()
        .find(|l| l.contains("latency capture->command"))
        .expect("the latency line");
    println!("{line}");
    println!(
        "testsrc 320x240@30 through the pipe: {} frames in 4 s, capture -> command median {:.2} ms, max {:.2} ms",
        recs.len(),
        median(&mut lat),
        lat.last().unwrap()
    );
    assert!(recs.len() >= 90, "{} frames in 4 s at 30 fps", recs.len());
    assert_eq!(lat.len(), recs.len(), "every record has its latency");
    assert!(line.contains(&format!("{} frames", recs.len())), "{line}");
    assert!(median(&mut lat) < 50.0, "median latency {} ms", median(&mut lat));
    assert!(stdout.contains("in its own process group"), "{stdout}");
    assert!(alive(&tok).is_empty(), "{:?}", alive(&tok));
}

/// Must show 1: `rccar camera check` on the pipe: the real size, the fps, the latency, and a
/// frame saved that shows the test pattern.
#[test]
fn camera_check_reports_size_fps_latency_and_saves_a_frame() {
    need_ffmpeg();
    let tok = token("check");
    let dir = scratch("check");
    let png = dir.join("frame.png");
    let o = Command::new(EXE)
        .current_dir(root())
        .args([
            "camera",
            "check",
            "--camera",
            &testsrc(&tok),
            "--seconds",
            "2",
            "--save",
        ])
        .arg(&png)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    println!("{stdout}");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("size: 320×240 (configured 320×240)"), "{stdout}");
    let fps: f64 = stdout
        .lines()
        .find_map(|l| l.split(" = ").nth(1)?.split(" fps").next()?.parse().ok())
        .expect("an fps figure");
    assert!((25.0..=35.0).contains(&fps), "{fps} fps from a 30 fps producer");
    assert!(
        stdout.contains("latency capture -> command (lane pipeline): median"),
        "{stdout}"
    );
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (320, 240));
    // testsrc's colour bars: many distinct colours, not a flat or garbled frame
    let colours: std::collections::HashSet<[u8; 3]> =
        img.pixels().map(|p| [p[0] & 0xF0, p[1] & 0xF0, p[2] & 0xF0]).collect();
    assert!(colours.len() > 20, "{} colours", colours.len());
    assert!(alive(&tok).is_empty(), "{:?}", alive(&tok));
}

struct Wall(Instant);
impl Clock for Wall {
    fn now_s(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
    fn sleep_s(&self, s: f64) {
        std::thread::sleep(Duration::from_secs_f64(s.max(0.0)));
    }
}

/// What the loop did, on the run's clock.
#[derive(Default)]
struct Seen {
    frames: Vec<(f64, String)>,
    stalls: Vec<(f64, f64, f64)>,
}

struct Watch {
    clock: Arc<Wall>,
    sent: Arc<rccar::drive::Sent>,
    seen: Arc<Mutex<Seen>>,
    /// Time the loop spends after each frame's command (a slow loop).
    slow: Duration,
}

impl Observer for Watch {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let car = ctx.record.car.map(|c| c.name().to_string()).unwrap_or_default();
        self.seen.lock().unwrap().frames.push((self.clock.now_s(), car));
        std::thread::sleep(self.slow);
        Ok(Flow::Continue)
    }
    fn on_stall(&mut self, _e: &FrameError) {
        // Called after the neutral went out through the gate: what it sent, and when.
        let (t, thr) = (self.sent.clock_s.get(), self.sent.throttle.get());
        self.seen.lock().unwrap().stalls.push((self.clock.now_s(), t, thr));
    }
}

/// The car in-process (`drive --dry-run --arm`, lane pipeline only) on the camera `pipe`;
/// with its clock, stop signal and the camera program's pid (from the session's note).
fn pipe_session(pipe: &str) -> (Session, Arc<Wall>, StopSignal, i32) {
    let mut cfg = Config::default();
    cfg.detect.enabled = false;
    let clock = Arc::new(Wall(Instant::now()));
    let stop = StopSignal::new();
    let env = SessionEnv {
        clock: clock.clone(),
        stop: stop.clone(),
        timer: Box::new(NoTimer),
        say: Arc::new(|_: Level, _: &str| {}),
    };
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: CameraSpec::parse(pipe).unwrap(),
            right: None,
            timing: Timing::WallClock,
        },
        SinkSpec::DryRun,
    );
    spec.arm = ArmAt::Flag;
    spec.detector = DetectorSpec::Off;
    let session = Session::build(&cfg, spec, env).unwrap();
    let note = session
        .notes()
        .iter()
        .map(|n| n.1.clone())
        .find(|n| n.contains("as process"))
        .unwrap();
    let pid: i32 = note
        .split("as process ")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    (session, clock, stop, pid)
}

/// Must show 1: a frozen producer (SIGSTOP) is detected and neutral sent within 0.5 s; when
/// it continues (SIGCONT) frames come again and the car drives.
#[test]
fn sigstop_sends_neutral_within_half_a_second_and_sigcont_resumes() {
    need_ffmpeg();
    let tok = token("stop");
    let (mut session, clock, stop, pid) = pipe_session(&testsrc(&tok));
    let seen = Arc::new(Mutex::new(Seen::default()));
    let mut watch = Watch {
        clock: clock.clone(),
        sent: session.sent(),
        seen: seen.clone(),
        slow: Duration::ZERO,
    };
    let times = Arc::new(Mutex::new((0.0, 0.0)));
    let (c, s, t) = (clock.clone(), stop.clone(), times.clone());
    let signaller = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(1500));
        let t_stop = c.now_s();
        unsafe { libc::kill(pid, libc::SIGSTOP) };
        std::thread::sleep(Duration::from_millis(1500));
        let t_cont = c.now_s();
        unsafe { libc::kill(pid, libc::SIGCONT) };
        *t.lock().unwrap() = (t_stop, t_cont);
        std::thread::sleep(Duration::from_millis(1500));
        s.request(StopReason::Requested);
    });
    session.run(&mut watch).unwrap();
    signaller.join().unwrap();
    let outcome = session.finish().unwrap();
    let (t_stop, t_cont) = *times.lock().unwrap();
    let seen = seen.lock().unwrap();
    let (stall_seen, neutral_at, throttle) = seen
        .stalls
        .first()
        .copied()
        .expect("a stall while the producer was stopped");
    let gap = neutral_at - t_stop;
    let before = seen.frames.iter().filter(|f| f.0 < t_stop).count();
    let after: Vec<_> = seen.frames.iter().filter(|f| f.0 > t_cont).collect();
    let first_after = after.first().map_or(f64::NAN, |f| f.0 - t_cont);
    println!(
        "SIGSTOP at {t_stop:.3} s: neutral sent {:.0} ms later (stall seen at {stall_seen:.3} s, throttle {throttle}); \
         {} stalls while stopped; SIGCONT at {t_cont:.3} s: first frame {:.0} ms later, {} frames after, car `{}`; {} frames before",
        gap * 1e3,
        seen.stalls.len(),
        first_after * 1e3,
        after.len(),
        after.last().map_or("", |f| f.1.as_str()),
        before,
    );
    assert!(gap > 0.0 && gap <= 0.5, "neutral {gap} s after SIGSTOP");
    assert_eq!(throttle, 0.0, "the stall's command is neutral");
    assert!(
        seen.stalls.iter().all(|s| s.0 < t_cont + 0.5),
        "no stall once it continued"
    );
    assert!(before >= 30, "{before} frames before the freeze");
    assert!(after.len() >= 30, "{} frames after SIGCONT", after.len());
    assert!(first_after < 0.5, "frames again {first_after} s after SIGCONT");
    assert_eq!(after.last().unwrap().1, "driving", "armed and driving again");
    assert!(
        outcome.stats.stalls >= 2 && outcome.fault.is_none(),
        "{:?}",
        outcome.stats.line()
    );
    assert!(alive(&tok).is_empty(), "{:?}", alive(&tok));
}

/// The newest frame only: a producer at 120 fps and a loop that takes 50 ms a frame. The loop
/// gets the newest frame each time (the others are dropped and counted), so the frame it
/// steers by is fresh: capture -> command stays a few ms. A queue would hand it ever older
/// frames (or stall the producer behind a full pipe).
#[test]
fn a_slow_loop_gets_the_newest_frame_and_the_rest_are_dropped() {
    need_ffmpeg();
    let tok = token("newest");
    let pipe = testsrc(&tok).replace("rate=30", "rate=120");
    let (mut session, clock, stop, _pid) = pipe_session(&pipe);
    let mut watch = Watch {
        clock: clock.clone(),
        sent: session.sent(),
        seen: Arc::new(Mutex::new(Seen::default())),
        slow: Duration::from_millis(50),
    };
    let s = stop.clone();
    let t = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_secs(3));
        s.request(StopReason::Requested);
    });
    session.run(&mut watch).unwrap();
    t.join().unwrap();
    let st = session.finish().unwrap().stats;
    let mut lat = st.latency_ms.clone();
    let med = median(&mut lat);
    println!(
        "120 fps producer, 50 ms loop, 3 s: {} frames processed, {} dropped, capture -> command median {med:.2} ms, max {:.2} ms",
        st.frames,
        st.dropped,
        lat.last().unwrap()
    );
    assert!(st.frames >= 30 && st.frames <= 70, "{} frames at ~20 per s", st.frames);
    assert!(
        st.dropped >= 2 * st.frames,
        "{} dropped of a 120 fps stream",
        st.dropped
    );
    assert!(med < 20.0, "the frame steered by is fresh: median {med} ms");
    assert!(alive(&tok).is_empty(), "{:?}", alive(&tok));
}

/// Starts `rccar drive` on `camera`; returns it once it has written `n` frames.
fn drive_until(camera: &str, out: &Path, n: usize) -> Child {
    let mut child = Command::new(EXE)
        .current_dir(root())
        .args([
            "drive",
            "--camera",
            camera,
            "--dry-run",
            "--arm",
            "--set",
            "detect.enabled=false",
            "--out",
        ])
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while records(out).len() < n {
        assert!(child.try_wait().unwrap().is_none(), "rccar drive ended early");
        assert!(t0.elapsed() < Duration::from_secs(60), "no {n} frames in 60 s");
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

fn wait_code(child: &mut Child, within: Duration) -> Option<i32> {
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return st.code();
        }
        if t0.elapsed() > within {
            let _ = child.kill();
            panic!("rccar did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Must show 1: Ctrl-C, SIGTERM and SIGHUP each stop the car with neutral and its exit code,
/// and leave no camera program behind (/proc has no process with its command line).
#[test]
fn int_term_and_hup_leave_no_camera_program() {
    need_ffmpeg();
    for (sig, name, code) in [
        (libc::SIGINT, "INT", 130),
        (libc::SIGTERM, "TERM", 143),
        (libc::SIGHUP, "HUP", 129),
    ] {
        let tok = token(&format!("sig{name}"));
        let out = scratch(&format!("sig{name}"));
        let mut child = drive_until(&testsrc(&tok), &out, 30);
        let producer = alive(&tok);
        assert_eq!(producer.len(), 1, "one camera program: {producer:?}");
        let t0 = Instant::now();
        unsafe { libc::kill(child.id() as i32, sig) };
        let got = wait_code(&mut child, Duration::from_secs(10));
        let exit_ms = t0.elapsed().as_millis();
        let left = left_behind(&tok);
        println!(
            "SIG{name}: exit {got:?} after {exit_ms} ms, {} frames; camera program {} -> left behind: {left:?} (/proc/{} exists: {})",
            records(&out).len(),
            producer[0].0,
            producer[0].0,
            Path::new(&format!("/proc/{}", producer[0].0)).exists()
        );
        assert_eq!(got, Some(code), "SIG{name}");
        assert!(left.is_empty(), "SIG{name} left {left:?}");
        assert!(
            !Path::new(&format!("/proc/{}", producer[0].0)).exists(),
            "reaped, not a zombie"
        );
    }
}

/// SIGKILL of rccar runs none of its code: the kernel's parent-death signal ends the camera
/// program, so nothing holds the camera after a crash. The program here would live on
/// otherwise: it ignores SIGHUP and SIGPIPE and writes nothing more after its one frame (as a
/// camera program stuck in its driver), so neither the broken pipe nor the orphaned process
/// group's SIGHUP would end it.
#[test]
fn sigkill_of_rccar_ends_a_camera_program_that_would_live_on() {
    let secs = format!("3000.{}", std::process::id());
    let cam = format!("pipe:rgb24:sh -c \"trap '' HUP PIPE; head -c 230400 /dev/zero; exec sleep {secs}\"");
    let out = scratch("kill9");
    let mut child = drive_until(&cam, &out, 1);
    let producer = alive(&secs);
    assert_eq!(producer.len(), 1, "{producer:?}");
    child.kill().unwrap();
    child.wait().unwrap();
    let t0 = Instant::now();
    while !alive(&secs).is_empty() && t0.elapsed() < Duration::from_secs(3) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let left = alive(&secs);
    println!(
        "SIGKILL of rccar: its camera program {} {} after {} ms",
        producer[0].0,
        if left.is_empty() { "gone" } else { "STILL THERE" },
        t0.elapsed().as_millis(),
    );
    for p in &left {
        unsafe { libc::kill(p.0 as i32, libc::SIGKILL) };
    }
    assert!(left.is_empty(), "{left:?}");
}

/// A short frame and a producer that ends are named (a counted unusable frame, then a camera
/// fault: exit 3), and a producer writing garbage gives counted unusable frames in bounded
/// memory, never a panic.
#[test]
fn short_frames_and_garbage_are_counted_unusable_frames() {
    // 1000 bytes of a 230400-byte rgb24 frame, then the end of the stream.
    let out = scratch("short");
    let o = Command::new(EXE)
        .current_dir(root())
        .args([
            "drive",
            "--camera",
            "pipe:rgb24:head -c 1000 /dev/zero",
            "--dry-run",
            "--set",
            "detect.enabled=false",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    println!("{stderr}");
    assert_eq!(o.status.code(), Some(3), "a camera fault: {stderr}");
    assert!(stderr.contains("short frame: 1000 of 230400 bytes"), "{stderr}");
    assert!(stderr.contains("`head` ended (exit status: 0)"), "{stderr}");
    // Endless random bytes as "MJPEG" for 3 s: unusable frames, each named.
    let (code, stderr, peak_kb) = drive_watching_memory("garbage", "pipe:mjpeg:cat /dev/urandom");
    let skipped = stderr.lines().filter(|l| l.contains("not a JPEG frame")).count();
    let last = stderr.lines().last().unwrap_or("").to_string();
    println!(
        "random bytes as MJPEG for 3 s: exit {code:?}, {skipped} unusable frames named, peak RSS {:.1} MB; {last}",
        peak_kb as f64 / 1024.0
    );
    assert_eq!(code, Some(1), "no usable frame: {last}");
    assert!(skipped >= 10, "{skipped} unusable frames");
    assert!(stderr.contains("no usable frame"), "{last}");
    assert!(!stderr.contains("panicked"));
    assert!(peak_kb < 200 * 1024, "peak RSS {peak_kb} kB");
    // A JPEG that starts (SOI, SOS) and never ends: 300 MB of image data without a marker.
    // The reader gives up at its bound (2 × W×H×3 + 1 MiB), never holding the 300 MB.
    let endless = "pipe:mjpeg:sh -c \"printf '\\377\\330\\377\\332\\000\\002'; head -c 300000000 /dev/zero; sleep 5\"";
    let (code, stderr, peak_kb) = drive_watching_memory("endless", endless);
    // (The first, "a JPEG longer than ...", may be replaced by the garbage after it before the
    // loop takes it: newest frame only.)
    let unusable = stderr
        .lines()
        .filter(|l| l.contains("a JPEG longer than") || l.contains("not a JPEG frame"))
        .count();
    println!(
        "a JPEG of 300 MB: exit {code:?}, {unusable} unusable frames named, peak RSS {:.1} MB",
        peak_kb as f64 / 1024.0
    );
    assert_eq!(code, Some(1));
    assert!(
        unusable >= 1,
        "{}",
        stderr.lines().take(5).collect::<Vec<_>>().join("\n")
    );
    assert!(peak_kb < 200 * 1024, "peak RSS {peak_kb} kB");
}

/// Runs `drive --camera CAMERA --dry-run --seconds 3`; its exit code, stderr, and its peak
/// resident memory, kB (sampled every 20 ms).
fn drive_watching_memory(name: &str, camera: &str) -> (Option<i32>, String, u64) {
    let out = scratch(name);
    let mut child = Command::new(EXE)
        .current_dir(root())
        .args(["drive", "--camera", camera, "--dry-run", "--seconds", "3", "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || std::io::read_to_string(err).unwrap_or_default());
    let mut peak_kb = 0u64;
    while child.try_wait().unwrap().is_none() {
        if let Ok(s) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
            let kb = s
                .lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.split_whitespace().next()?.parse().ok());
            peak_kb = peak_kb.max(kb.unwrap_or(0));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let code = child.wait().unwrap().code();
    (code, reader.join().unwrap(), peak_kb)
}

/// The decision fields of a telemetry record.
const DECISIONS: [&str; 8] = [
    "time_s",
    "p_left",
    "p_right",
    "lane_center",
    "error",
    "status",
    "steer",
    "throttle",
];

fn read(p: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// Must show 2: the simulator's own frames, written raw to its stdout (`rccar sim --frames-to
/// -`), read back through the pipe source lock-step (`rccar replay 'pipe:rgb24:…'`): one lap,
/// every frame, the same decisions as the simulator's own run, field for field (rgb24 is
/// lossless; the replay tolerance of a JPEG recording is not needed). And the same with the
/// frames as MJPEG at quality 90 (as a recording keeps them) over the first 20 s, within the
/// record → replay tolerance's mean (|steer| mean ≤ 0.01).
#[test]
fn sim_frames_through_a_pipe_drive_the_lap_with_the_same_decisions() {
    let dir = scratch("simpipe");
    let sim_args = "--no-timing --set detect.enabled=false --frames-to -";
    for (format, extra, exact) in [
        ("rgb24", "--laps 1", true),
        ("mjpeg", "--seconds 20 --frames-format mjpeg", false),
    ] {
        let (sim_out, rep_out) = (dir.join(format!("sim-{format}")), dir.join(format!("replay-{format}")));
        let pipe = format!("pipe:{format}:{EXE} sim {sim_args} {extra} -o {}", sim_out.display());
        let o = Command::new(EXE)
            .current_dir(root())
            .args([
                "replay",
                &pipe,
                "--no-annotate",
                "--no-timing",
                "--set",
                "detect.enabled=false",
                "-o",
            ])
            .arg(&rep_out)
            .output()
            .unwrap();
        let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "{stdout}\n{stderr}");
        assert!(!stderr.contains("replay: pipe"), "the simulator failed: {stderr}");
        let a = read(&sim_out.join("telemetry.jsonl"));
        let b = read(&rep_out.join("telemetry.jsonl"));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(sim_out.join("summary.json")).unwrap()).unwrap();
        assert_eq!(a.len(), b.len(), "{format}: every frame went through the pipe");
        let (mut worst, mut sum, mut differing) = (0.0f64, 0.0, 0);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x["frame"], y["frame"]);
            let d = (x["steer"].as_f64().unwrap() - y["steer"].as_f64().unwrap()).abs();
            (worst, sum) = (worst.max(d), sum + d);
            differing += DECISIONS.iter().any(|k| x[k] != y[k]) as usize;
            if exact {
                for k in DECISIONS {
                    assert_eq!(x[k], y[k], "{format} frame {}: {k}", x["frame"]);
                }
            }
        }
        let mean = sum / a.len() as f64;
        println!(
            "{format}: {} frames through the pipe ({} laps, ended {}), decisions differing in {differing} frames, |steer difference| mean {mean:.5}, max {worst:.5}",
            a.len(),
            summary["laps"],
            summary["end"]
        );
        if exact {
            assert_eq!(summary["laps"], 1, "the simulator drove its lap");
            assert_eq!(differing, 0);
        } else {
            // The mean bound of the record -> replay tolerance. Its max (0.05) is not asserted:
            // measured here, the left line's peak switches from 28 to 7 px one frame earlier in
            // the lossless run than through JPEG at frame 504 (|steer| 0.083 for that frame;
            // every other frame is within 0.036), a discrete choice, not the pipe.
            assert!(
                mean <= 0.01,
                "{format}: steer differs by {mean} on average (max {worst})"
            );
        }
    }
}
