//! The car in-process against the real firmware (issue 25): the library's session builder
//! wires a folder of frames as the camera (paced on the wall clock) to the serial link, and
//! the firmware in simavr, over a real pty, turns the gate's commands into pulse widths. No
//! `rccar` process: the test holds the session, as a tool or a future fleet node would.
#![cfg(feature = "serial")]

use super::sim::Sim;
use rccar::config::Config;
use rccar::drive::{Level, LoopEnd, NoObserver, StopSignal};
use rccar::link::protocol::{id, permille_to_us, to_permille};
use rccar::session::{ArmAt, CameraSpec, Session, SessionEnv, SessionSpec, SinkSpec, SourceSpec, Timing};
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

#[test]
fn a_folder_camera_drives_the_firmware_in_process() {
    let sim = Sim::start(&format!("session-fil-{}", std::process::id()));
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let cfg = Config::load(&root.join("config/car.toml"), &[], &["detect.enabled=false".into()]).unwrap();
    let dir = std::env::temp_dir().join(format!("rccar-session-fil-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: CameraSpec::Folder(root.join("tests/data/lane_sample")),
            right: None,
            timing: Timing::WallClock,
        },
        SinkSpec::Link {
            port: sim.tty.clone(),
            pwm_log: None,
            bit_errors: 0.0,
        },
    );
    spec.arm = ArmAt::Flag;
    spec.telemetry = Some(dir.join("telemetry.jsonl"));
    let env = SessionEnv {
        clock: Arc::new(Wall(Instant::now())),
        stop: StopSignal::new(),
        timer: Box::new(NoTimer),
        say: Arc::new(|_: Level, l: &str| println!("{l}")),
    };
    let mut s = Session::build(&cfg, spec, env).expect("the session builds against the emulator");
    assert_eq!(s.run(&mut NoObserver).unwrap(), LoopEnd::SourceEnded);
    let out = s.finish().unwrap();
    assert!(out.fault.is_none(), "{:?}", out.fault);
    let tel: Vec<serde_json::Value> = std::fs::read_to_string(dir.join("telemetry.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(tel.len(), 32, "one record per frame of the folder (32 PNG)");
    // The firmware drove what the pipeline asked: the servo widths of the frames' steering
    // (firmware default end points) show up at D9 within 1 µs. The link sends the newest DRIVE
    // only, so a frame whose DRIVE was superseded before it was written never shows: most do.
    let width = |r: &serde_json::Value| f64::from(permille_to_us(to_permille(r["steer"].as_f64().unwrap()), 1000, 1500, 2000));
    let got_disarm = sim.wait_until(Duration::from_secs(5), || (), |s| !s.rx_times(id::DISARM).is_empty());
    let servo = sim.pulses(true);
    let shown = tel.iter().filter(|r| servo.iter().any(|&(w, _)| (w - width(r)).abs() <= 1.0)).count();
    let drives = sim.rx_times(id::DRIVE).len();
    let esc = sim.pulses(false);
    println!(
        "{} frames; {drives} DRIVE frames at the firmware; {shown} frames' steering seen at the servo; {} servo changes",
        tel.len(),
        servo.len()
    );
    assert!(got_disarm, "no DISARM at the end of the session");
    assert!(drives >= 30, "{drives} DRIVE frames for 32 frames");
    assert!(shown * 10 >= tel.len() * 8, "only {shown} of {} frames' steering reached the servo", tel.len());
    assert!(esc.iter().any(|&(w, _)| w > 1550.0), "the ESC drove");
    // ... and the session's end sent DISARM and neutral: the ESC ends at 1500 µs.
    let neutral = sim.wait_until(Duration::from_secs(2), || (), |s| s.last_width(false).is_some_and(|w| (w - 1500.0).abs() <= 1.0));
    assert!(neutral, "ESC not at neutral after the session: {:?}", sim.last_width(false));
}
