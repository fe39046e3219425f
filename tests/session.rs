//! The car built in-process by the library's session builder (`rccar::session`, issue 25):
//! the same parts `rccar drive` wires, run from a test, and the faults that end a run (issue
//! 24): a camera of the wrong size is a camera fault the exit code reads, not a quiet end.

use rccar::capture::{CaptureSource, GrabError, Grabber};
use rccar::config::Config;
use rccar::drive::{Level, LoopEnd, NoObserver, StopSignal};
use rccar::health::Part;
use rccar::session::{CameraSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
use rccar::timing::{Clock, NoTimer};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

struct Wall(Instant);
impl Clock for Wall {
    fn now_s(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
    fn sleep_s(&self, s: f64) {
        std::thread::sleep(Duration::from_secs_f64(s.max(0.0)));
    }
}

fn env() -> SessionEnv {
    SessionEnv {
        clock: Arc::new(Wall(Instant::now())),
        stop: StopSignal::new(),
        timer: Box::new(NoTimer),
        say: Arc::new(|_: Level, _: &str| {}),
    }
}

fn sample() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lane_sample")
}

fn config() -> Config {
    let mut cfg = Config::default();
    cfg.detect.enabled = false;
    cfg
}

/// A camera that delivers 640×480 frames while the car is configured for 320×240.
struct WrongSize;
impl Grabber for WrongSize {
    fn open(&mut self) -> Result<(), GrabError> {
        Ok(())
    }
    fn grab(&mut self) -> Result<image::RgbImage, GrabError> {
        std::thread::sleep(Duration::from_millis(10));
        Ok(image::RgbImage::new(640, 480))
    }
    fn label(&self) -> String {
        "/dev/video9".into()
    }
}

/// Issue 24: a wrong-size camera ended `rccar drive` with exit 0 and no reason (the error sat
/// in `CaptureSource::fatal()`, read only by a unit test). The session now makes it the run's
/// fatal camera fault, which `drive` prints and turns into exit 3.
#[test]
fn a_camera_of_the_wrong_size_is_a_camera_fault() {
    let cfg = config();
    let spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: CameraSpec::Folder(sample()),
            right: None,
            timing: Timing::WallClock,
        },
        SinkSpec::DryRun,
    );
    let e = env();
    let clock = e.clock.clone();
    let mut s = Session::build(&cfg, spec, e).unwrap();
    let cam = CaptureSource::start(
        || Box::new(WrongSize),
        "/dev/video9".into(),
        (cfg.camera.width, cfg.camera.height),
        clock,
        Duration::from_millis(500),
        Duration::from_millis(50),
    );
    s.set_source(Box::new(cam), true);
    let end = s.run(&mut NoObserver).unwrap();
    let out = s.finish().unwrap();
    let f = out.fault.expect("a camera fault");
    println!("ended {end:?}: fault {f}");
    assert_eq!(end, LoopEnd::SourceEnded);
    assert_eq!(f.part, Part::Camera);
    assert!(f.message.contains("640x480") || f.message.contains("640×480"), "{f}");
}

/// The car, in-process, from a folder of frames: one record per frame, the same commands as
/// the replay golden file's (tests/data/lane_sample.golden.jsonl), neutral at the end.
#[test]
fn a_folder_replays_in_process_like_the_golden_file() {
    let cfg = Config::load(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/car.toml"), &[], &[]).unwrap();
    let dir = std::env::temp_dir().join(format!("rccar-session-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: CameraSpec::Folder(sample()),
            right: None,
            timing: Timing::LockStep,
        },
        SinkSpec::DryRun,
    );
    spec.telemetry = Some(dir.join("telemetry.jsonl"));
    let mut e = env();
    e.clock = Arc::new(rccar::drive::NoClock);
    let mut s = Session::build(&cfg, spec, e).unwrap();
    assert_eq!(s.run(&mut NoObserver).unwrap(), LoopEnd::SourceEnded);
    let out = s.finish().unwrap();
    assert!(out.fault.is_none());
    let got = std::fs::read_to_string(dir.join("telemetry.jsonl")).unwrap();
    let want = std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lane_sample.golden.jsonl")).unwrap();
    let (g, w): (Vec<serde_json::Value>, Vec<serde_json::Value>) = (
        got.lines().map(|l| serde_json::from_str(l).unwrap()).collect(),
        want.lines().map(|l| serde_json::from_str(l).unwrap()).collect(),
    );
    assert_eq!(g.len(), w.len());
    for (a, b) in g.iter().zip(&w) {
        for k in ["frame", "status"] {
            assert_eq!(a[k], b[k], "{k}");
        }
        for k in ["steer", "throttle", "error"] {
            let (x, y) = (a[k].as_f64().unwrap_or(0.0), b[k].as_f64().unwrap_or(0.0));
            assert!((x - y).abs() < 1e-9, "{k}: {x} vs {y}");
        }
    }
    println!("{} frames in-process, the same commands as the golden file", g.len());
}

/// Frames of a lock-step simulated `drive` (the world may end the run, as under `drive
/// --camera sim`) with the car held by `hold` from frame `at`; how the world ended, if it did.
fn held_sim(overrides: &[&str], at: u64, hold: impl Fn(&rccar::drive::Arming)) -> (Option<rccar::sim::run::EndReason>, u64) {
    use rccar::session::{ArmAt, SceneSpec};
    use rccar::drive::Step;
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut o: Vec<String> = vec!["detect.enabled=false".into()];
    o.extend(overrides.iter().map(|s| s.to_string()));
    let cfg = Config::load(&root.join("config/car.toml"), &[], &o).unwrap();
    let mut spec = SessionSpec::new(
        SourceSpec::Sim {
            scene: SceneSpec::Track(PathBuf::from(&cfg.sim.track)),
            timing: Timing::LockStep,
            stall: None,
            start_offset_m: None,
        },
        SinkSpec::DryRun,
    );
    spec.arm = ArmAt::Operator;
    let mut s = Session::build(&cfg, spec, env()).unwrap();
    let arming = s.arming().clone();
    // 10 s of frame time: the stall ending takes 5 s of standing after the first second.
    for k in 0..300u64 {
        if k == at {
            hold(&arming);
        }
        if let Step::End(_) = s.step(&mut NoObserver).unwrap() {
            return (s.world().and_then(|w| rccar::sim::world::lock(w).ended()), k);
        }
    }
    (s.world().and_then(|w| rccar::sim::world::lock(w).ended()), 300)
}

/// Issue 26: `drive --camera sim --dry-run --dashboard` ended by itself after 6 s ("ended:
/// Stalled") while the car waited to be armed or sat e-stopped. Standing still on purpose —
/// disarmed, e-stopped, or a human holding the throttle at 0 — is not a stall; a pipeline
/// that stops the car by itself still is.
#[test]
fn a_car_held_on_purpose_is_not_stalled_but_a_pipeline_that_stops_is() {
    use rccar::drive::{Actor, DriveMode};
    use rccar::sim::run::EndReason;
    let disarmed = held_sim(&[], 0, |_| {});
    assert_eq!(disarmed, (None, 300), "waiting to be armed for 10 s");
    let estopped = held_sim(&[], 0, |a| {
        a.arm(Actor::Page).unwrap();
        a.estop(Actor::Page);
    });
    assert_eq!(estopped, (None, 300), "e-stopped for 10 s");
    let by_hand = held_sim(&[], 0, |a| {
        a.arm(Actor::Page).unwrap();
        a.controls().set_mode(DriveMode::Manual, Actor::Page, 0.0);
    });
    assert_eq!(by_hand, (None, 300), "armed in manual mode, nobody at the stick");
    // Armed, autopilot, and the pipeline's throttle is 0: the stall ending still works.
    let (end, k) = held_sim(&["throttle.base=0", "throttle.min=0"], 0, |a| a.arm(Actor::Page).unwrap());
    assert_eq!(end, Some(EndReason::Stalled), "ended at frame {k}");
    assert!((170..200).contains(&k), "stalled after 1 + 5 s of standing, at frame {k}");
}
