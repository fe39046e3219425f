//! The car's gamepad (issue 26) tested with recorded event sequences (tests/data/pad/*.txt,
//! format in tests/data/pad/README.md): each sequence goes through the mapping
//! (`rccar::pad::PadMachine`) and onto a real arming state and its controls
//! (`rccar::pad::PadLink`), and every step's actions, mode, arming and input are checked; then
//! through the controls and the one gate, as the loop does; then the configuration and the
//! command line's errors. The device thread itself (evdev, feature `gamepad`) needs a pad.

use rccar::config::Config;
use rccar::control::Command;
use rccar::drive::{Actor, Arming, DriveMode, Gate, GateOptions, NoClock, StopSignal};
use rccar::health::{Health, Part, PartState};
use rccar::pad::machine::RESEND_MS;
use rccar::pad::{script, PadAction, PadEvent, PadLink, PadMachine, PadOptions};
use rccar::sink::{CommandSink, NullSink};
use std::path::Path;
use std::sync::Arc;

fn fixture(name: &str) -> Vec<(u64, PadEvent)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/pad").join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    script::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// One event's outcome: what the pad asked for, and the car after it.
#[derive(Debug)]
struct Step {
    t: u64,
    actions: Vec<PadAction>,
    mode: DriveMode,
    armed: bool,
    estop: bool,
    /// The human's input as the loop would take it now (ceiling 1: as given, as f32).
    input: Option<(f64, f64)>,
}

/// A pad on a car: the mapping, the arming state and its controls (deadline 250 ms, no
/// ceiling), timed by the sequence.
struct Car {
    machine: PadMachine,
    link: PadLink,
    arming: Arc<Arming>,
}

impl Car {
    fn new(disarm_on_disconnect: bool) -> Self {
        let arming = Arming::new(Health::new());
        arming.controls().configure(0.25, 1.0);
        Car {
            machine: PadMachine::new(PadOptions::default()),
            link: PadLink::new(arming.clone(), Arc::new(NoClock), disarm_on_disconnect),
            arming,
        }
    }

    fn feed(&mut self, t: u64, ev: &PadEvent) -> Step {
        let mut actions = Vec::new();
        self.machine.feed(t, ev, &mut actions);
        let now = t as f64 / 1e3;
        self.link.apply(&actions, now);
        let c = self.arming.controls();
        Step {
            t,
            actions,
            mode: c.mode(),
            armed: self.arming.is_armed(),
            estop: self.arming.is_estopped(),
            input: c.input(now).map(|(s, th, _)| (s, th)),
        }
    }

    fn run(&mut self, seq: &[(u64, PadEvent)]) -> Vec<Step> {
        seq.iter().map(|(t, ev)| self.feed(*t, ev)).collect()
    }
}

/// The step of the (last) event at `t`.
fn at(steps: &[Step], t: u64) -> &Step {
    steps
        .iter()
        .rev()
        .find(|s| s.t == t)
        .unwrap_or_else(|| panic!("no event at {t} ms"))
}

fn input(steer: f64, throttle: f64) -> PadAction {
    PadAction::Input { steer, throttle }
}

/// Inputs compared to 1e-6 (the controls keep f32), everything else exactly.
fn same(got: &[PadAction], want: &[PadAction]) -> bool {
    got.len() == want.len()
        && got.iter().zip(want).all(|(g, w)| match (g, w) {
            (PadAction::Input { steer: a, throttle: b }, PadAction::Input { steer: c, throttle: d }) => {
                (a - c).abs() < 1e-6 && (b - d).abs() < 1e-6
            }
            _ => g == w,
        })
}

#[track_caller]
fn expect(steps: &[Step], t: u64, want: &[PadAction]) {
    let s = at(steps, t);
    assert!(same(&s.actions, want), "at {t} ms: {:?}, expected {want:?}", s.actions);
}

#[track_caller]
fn expect_input(steps: &[Step], t: u64, want: Option<(f64, f64)>) {
    let got = at(steps, t).input;
    let ok = match (got, want) {
        (Some((a, b)), Some((c, d))) => (a - c).abs() < 1e-6 && (b - d).abs() < 1e-6,
        (None, None) => true,
        _ => false,
    };
    assert!(ok, "input at {t} ms: {got:?}, expected {want:?}");
}

#[test]
fn drive_with_the_deadman_and_let_go_mid_stick() {
    let mut car = Car::new(true);
    let s = car.run(&fixture("drive.txt"));
    expect(&s, 0, &[]);
    assert_eq!(at(&s, 100).mode, DriveMode::Manual, "A takes over");
    expect(&s, 1180, &[]);
    assert!(!at(&s, 1180).armed, "980 ms of Start is not enough");
    expect(&s, 1200, &[PadAction::Arm]);
    assert!(at(&s, 1200).armed);
    expect(&s, 1400, &[]);
    expect_input(&s, 1400, None);
    // The dead-man: the sticks as they are, at once.
    expect(&s, 1500, &[input(0.0, 0.5)]);
    expect_input(&s, 1500, Some((0.0, 0.5)));
    expect(&s, 1520, &[input(1.0, 0.5)]);
    expect(&s, 1560, &[input(1.0, 0.5)]);
    expect(&s, 1580, &[]);
    expect(&s, 1600, &[input(1.0, 0.5)]);
    expect(&s, 1700, &[input(1.0, 1.0)]);
    expect(&s, 1710, &[]);
    expect_input(&s, 1710, Some((1.0, 1.0)));
    // Let go mid-stick: neutral at that event, then silence.
    expect(&s, 1800, &[input(0.0, 0.0)]);
    expect_input(&s, 1800, Some((0.0, 0.0)));
    expect(&s, 1820, &[]);
    expect(&s, 1900, &[]);
    expect_input(&s, 1900, Some((0.0, 0.0)));
    // RB drives too, from where the sticks are now (-800: 0.8 → 0.777… after the dead zone).
    expect(&s, 2000, &[input(1.0, (0.8 - 0.1) / 0.9)]);
    expect(&s, 2100, &[input(0.0, 0.0)]);
    assert!(
        s.iter().all(|st| st.armed == (st.t >= 1200)),
        "armed from 1200 ms on, never disarmed"
    );
    assert_eq!(car.arming.last_actor(), Actor::Pad);
}

#[test]
fn held_still_the_input_never_goes_stale() {
    // The dead-man held with the sticks at rest for 3 s: the car's pad thread ticks every 20 ms,
    // and the input must be fresh (younger than the 250 ms deadline) at every moment.
    let mut car = Car::new(true);
    let mut seq = fixture("drive.txt");
    seq.retain(|(t, _)| *t <= 1520);
    let mut steps = car.run(&seq);
    let mut sent = 0;
    for t in (1540..=4540).step_by(20) {
        let st = car.feed(t, &PadEvent::Tick);
        sent += st.actions.len();
        steps.push(st);
    }
    for st in steps.iter().filter(|s| s.t >= 1500) {
        assert_eq!(
            st.input.map(|i| i.1 > 0.4),
            Some(true),
            "stale at {} ms: {:?}",
            st.t,
            st.input
        );
    }
    // at least 20 a second
    assert!(sent as f64 >= 3.0 * 20.0, "{sent} inputs in 3 s");
    const { assert!(RESEND_MS <= 50) };
}

#[test]
fn unplugged_mid_drive_is_neutral_at_once_and_visible() {
    let mut car = Car::new(true);
    let events = car.link.events();
    let s = car.run(&fixture("unplug.txt"));
    expect(&s, 1320, &[input(-0.5, 1.0)]);
    assert!(at(&s, 1320).armed);
    let gone = at(&s, 1400);
    assert!(
        same(
            &gone.actions,
            &[
                input(0.0, 0.0),
                PadAction::Disconnected("ENODEV: the pad was unplugged".into())
            ]
        ),
        "{:?}",
        gone.actions
    );
    expect_input(&s, 1400, Some((0.0, 0.0)));
    assert!(!gone.armed, "disarm_on_disconnect");
    expect(&s, 1500, &[]);
    let ev = events.take();
    assert!(
        ev.iter().any(|e| e
            == "pad: disconnected (ENODEV: the pad was unplugged); neutral, disarmed; waiting for it to come back"),
        "{ev:?}"
    );
    assert_eq!(car.arming.last_actor(), Actor::Pad);
    // Back again, LB still held: nothing drives until LB is let go and pressed again.
    expect(&s, 2000, &[]);
    assert_eq!(at(&s, 2000).actions.len(), 0);
    expect(&s, 2100, &[]);
    expect(&s, 2200, &[]);
    expect(&s, 2300, &[input(0.0, 0.5)]);
    assert!(!at(&s, 2300).armed, "still disarmed: arming is a gesture of its own");
    assert_eq!(car.arming.health().state(Part::Pad), PartState::Ok);
    // Without disarm_on_disconnect the car stays armed, the input neutral.
    let mut car = Car::new(false);
    let s = car.run(&fixture("unplug.txt"));
    assert!(at(&s, 1400).armed);
    expect_input(&s, 1400, Some((0.0, 0.0)));
    assert_eq!(car.arming.health().state(Part::Pad), PartState::Ok);
    let mut car = Car::new(false);
    let seq = fixture("unplug.txt");
    car.run(&seq[..seq.iter().position(|(t, _)| *t == 1500).unwrap()]);
    assert_eq!(car.arming.health().state(Part::Pad), PartState::Lost);
    assert!(car.arming.health().note(Part::Pad).contains("ENODEV"));
    assert!(car.arming.health().interlock().is_none(), "a lost pad is no interlock");
}

#[test]
fn mode_cycle_take_over_and_the_recording_button() {
    let mut car = Car::new(true);
    let events = car.link.events();
    let s = car.run(&fixture("modes.txt"));
    let modes: Vec<(u64, DriveMode)> = s.iter().map(|st| (st.t, st.mode)).collect();
    let mode = |t| modes.iter().rev().find(|(u, _)| *u == t).unwrap().1;
    assert_eq!(mode(0), DriveMode::Autopilot);
    expect(&s, 100, &[PadAction::NextMode]);
    assert_eq!(mode(100), DriveMode::Manual);
    assert_eq!(mode(200), DriveMode::Assisted);
    assert_eq!(mode(300), DriveMode::Autopilot);
    expect(&s, 310, &[]);
    expect(&s, 400, &[PadAction::TakeOver]);
    assert_eq!(mode(400), DriveMode::Manual);
    assert_eq!(mode(500), DriveMode::Manual);
    let c = car.arming.controls();
    assert_eq!(c.mode_version(), 4, "four changes (the fifth press changed nothing)");
    assert_eq!(c.last_change().1, Actor::Pad);
    expect(&s, 600, &[PadAction::ToggleRecording]);
    let ev = events.take();
    assert_eq!(
        ev,
        vec![
            "pad: connected: Test pad",
            "pad: recording button: this run has no recorder: start it with --record DIR to record"
        ]
    );
    assert!(
        s.iter().all(|st| !st.armed && st.input.is_none()),
        "no gesture here arms or drives"
    );
    // A run with a recorder (`--record DIR` starts it on): X pauses it, as the page's button.
    let mut car = Car::new(true);
    let events = car.link.events();
    car.arming.controls().record().make_available();
    car.run(&fixture("modes.txt"));
    let r = car.arming.controls().record();
    assert!(!r.is_on(), "X paused the recording");
    assert_eq!(r.last_change().1, Actor::Pad);
    assert_eq!(events.take().last().map(String::as_str), Some("pad: recording paused"));
}

#[test]
fn estop_latches_and_only_a_long_back_releases_it() {
    let mut car = Car::new(true);
    let events = car.link.events();
    let s = car.run(&fixture("estop.txt"));
    assert!(at(&s, 1410).armed);
    expect(&s, 1410, &[input(0.0, 1.0)]);
    // (the held input goes out again with any event 40 ms after the last)
    expect(&s, 1500, &[PadAction::EStop, input(0.0, 1.0)]);
    expect(&s, 1510, &[]);
    expect(&s, 1550, &[input(0.0, 0.0)]);
    assert!(at(&s, 1500).estop && !at(&s, 1500).armed);
    // Start held 1 s while e-stopped: the arming state refuses.
    expect(&s, 2600, &[PadAction::Arm]);
    assert!(!at(&s, 2600).armed);
    assert!(events
        .take()
        .iter()
        .any(|e| e == "pad: not armed: the emergency stop is pressed: release it first"));
    expect(&s, 2800, &[PadAction::Disarm]);
    assert!(at(&s, 3800).estop, "1 s of Back: not yet");
    expect(&s, 3800, &[]);
    expect(&s, 4800, &[PadAction::ReleaseEStop]);
    assert!(!at(&s, 4800).estop && !at(&s, 4800).armed, "released, still disarmed");
    // the throttle stick pushed: the arm gesture is refused by the pad itself
    expect(&s, 4950, &[]);
    expect(&s, 6000, &[PadAction::Refused("arm: centre the throttle stick first")]);
    assert!(!at(&s, 6000).armed);
    expect(&s, 6200, &[]);
    expect(&s, 7300, &[PadAction::Arm]);
    assert!(at(&s, 7300).armed);
}

#[test]
fn arming_from_the_pad_is_deliberate() {
    let mut car = Car::new(true);
    let s = car.run(&fixture("arm.txt"));
    expect(
        &s,
        600,
        &[PadAction::Refused("arm: hold Start longer (gamepad.arm_hold_ms)")],
    );
    expect(&s, 1800, &[PadAction::Refused("arm: centre the throttle stick first")]);
    expect(&s, 2000, &[]);
    expect(&s, 2250, &[]);
    expect(&s, 3199, &[]);
    assert!(!at(&s, 3199).armed);
    expect(&s, 3200, &[PadAction::Arm]);
    assert!(at(&s, 3200).armed);
    expect(&s, 3300, &[]);
    expect(&s, 3400, &[]);
    expect(&s, 3500, &[PadAction::Disarm]);
    assert!(!at(&s, 3500).armed);
    assert!(s.iter().all(|st| st.input.is_none()), "no dead-man: nothing drove");
}

/// The loop's side: the pad's sequence through the controls (by mode) and the one gate, a
/// frame every 20 ms: neutral while disarmed or e-stopped, whatever the pad holds.
#[test]
fn through_the_gate_a_disarmed_or_estopped_car_never_moves() {
    const AUTO: Command = Command {
        steer: -0.3,
        throttle: 0.4,
    };
    let mut seq = fixture("estop.txt");
    // before arming (manual mode, dead-man held, full stick): insert a drive while disarmed
    seq.extend([
        (7500, PadEvent::Key { code: 0x136, value: 1 }),
        (
            7510,
            PadEvent::Abs {
                code: 0x04,
                value: -1000,
            },
        ),
        (8000, PadEvent::Key { code: 0x131, value: 1 }),
        (8100, PadEvent::Key { code: 0x136, value: 0 }),
    ]);
    let pre = [
        (50, PadEvent::Key { code: 0x136, value: 1 }),
        (
            60,
            PadEvent::Abs {
                code: 0x04,
                value: -1000,
            },
        ),
        (70, PadEvent::Key { code: 0x136, value: 0 }),
        (75, PadEvent::Abs { code: 0x04, value: 0 }),
    ];
    // drive while disarmed, before the first arming (the sequence then goes on as recorded)
    let mut all: Vec<(u64, PadEvent)> = seq[..2].to_vec();
    all.push((40, PadEvent::Key { code: 0x130, value: 1 }));
    all.push((45, PadEvent::Key { code: 0x130, value: 0 }));
    all.extend(pre);
    all.extend(seq[2..].iter().cloned());
    let mut car = Car::new(true);
    let mut gate = Gate::new(
        NullSink,
        GateOptions {
            arming: car.arming.clone(),
            stop: StopSignal::new(),
            clock: Arc::new(NoClock),
            give_up_s: 3.0,
        },
    );
    let mut events = all.iter().peekable();
    let mut sent: Vec<(u64, Command, bool, bool, bool)> = Vec::new();
    for t in (0..=8200u64).step_by(20) {
        while let Some((te, ev)) = events.peek() {
            if *te > t {
                break;
            }
            car.feed(*te, ev);
            events.next();
        }
        // the pad's thread ticks as often as the frames come here
        car.feed(t, &PadEvent::Tick);
        let chosen = car.arming.controls().choose_at(AUTO, t as f64 / 1e3);
        let out = gate.send(chosen.command, t as f64 / 1e3).unwrap();
        let human_moves = chosen.command.throttle != 0.0;
        sent.push((t, out, car.arming.is_armed(), car.arming.is_estopped(), human_moves));
    }
    let at_t = |t: u64| sent.iter().find(|s| s.0 == t).unwrap();
    // 60..70 ms: the pad gives full throttle, disarmed: the gate sends neutral
    assert!(at_t(60).4, "the controls chose the pad's throttle");
    assert_eq!(at_t(60).1, Command::NEUTRAL);
    // armed at 1200, driving from 1410: the pad's command goes through
    assert_eq!(
        at_t(1420).1,
        Command {
            steer: 0.0,
            throttle: 1.0
        }
    );
    // e-stopped from 1500 to 4800 (the stick still full until 1550): neutral
    for s in sent.iter().filter(|s| (1500..4800).contains(&s.0)) {
        assert!(s.4 || s.0 >= 1550, "the pad still holds full throttle at {} ms", s.0);
        assert_eq!(s.1, Command::NEUTRAL, "e-stopped at {} ms", s.0);
    }
    // released but disarmed until 7300: neutral
    for s in sent.iter().filter(|s| (4800..7300).contains(&s.0)) {
        assert_eq!(s.1, Command::NEUTRAL, "disarmed at {} ms", s.0);
    }
    // armed again, dead-man, full stick from 7510: through; e-stop at 8000: neutral
    assert_eq!(
        at_t(7520).1,
        Command {
            steer: 0.0,
            throttle: 1.0
        }
    );
    for s in sent.iter().filter(|s| s.0 >= 8000) {
        assert_eq!(s.1, Command::NEUTRAL, "e-stopped at {} ms", s.0);
    }
    // and nothing but neutral ever left the gate while disarmed or e-stopped
    for s in &sent {
        if !s.2 || s.3 {
            assert_eq!(s.1, Command::NEUTRAL, "{s:?}");
        }
    }
}

#[test]
fn bad_gamepad_config_names_the_key_and_file() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, body: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    let err = |p: &Path| Config::load(p, &[], &[]).unwrap_err().to_string();
    let p = write("typo.toml", "[gamepad]\ndeadzone = 0.2\n");
    let e = err(&p);
    assert!(e.contains("gamepad.deadzone") && e.contains("typo.toml"), "{e}");
    let p = write("axis.toml", "[gamepad]\nsteer_axis = \"ABS_Q\"\n");
    let e = err(&p);
    assert!(
        e.contains("gamepad.steer_axis") && e.contains("ABS_Q") && e.contains("ABS_RY"),
        "{e}"
    );
    let p = write("same.toml", "[gamepad]\nsteer_axis = \"ABS_RY\"\n");
    assert!(err(&p).contains("gamepad.throttle_axis"), "{}", err(&p));
    let p = write("dev.toml", "[gamepad]\ndevice = \"event3\"\n");
    let e = err(&p);
    assert!(e.contains("gamepad.device") && e.contains("/dev/input/event3"), "{e}");
    let p = write("dz.toml", "[gamepad]\ndead_zone = 0.7\narm_hold_ms = 10\n");
    let e = err(&p);
    assert!(
        e.contains("gamepad.dead_zone") && e.contains("gamepad.arm_hold_ms"),
        "{e}"
    );
    let good = write("good.toml", "[gamepad]\nthrottle_axis = \"ABS_RZ\"\ndead_zone = 0.2\n");
    let cfg = Config::load(&good, &[], &[]).unwrap();
    assert_eq!(cfg.gamepad.options().throttle_axis, 0x05);
    assert_eq!(cfg.gamepad.options().dead_zone, 0.2);
}

#[test]
fn a_pad_that_cannot_be_opened_is_a_clear_error() {
    let out = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        let dir = out
            .path()
            .join(format!("run{}", extra.len() * 7 + extra.concat().len()));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_rccar"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["drive", "--camera", "sim", "--dry-run", "--seconds", "1", "-o"])
            .arg(dir)
            .args(extra)
            .output()
            .unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).to_string())
    };
    let (code, err) = run(&["--pad", "/dev/input/event-none"]);
    assert_ne!(code, Some(0));
    if cfg!(feature = "gamepad") {
        assert!(
            err.contains("--pad = /dev/input/event-none: cannot open") && err.contains("no such device"),
            "{err}"
        );
        let (code, err) = run(&["--pad", "/dev/null"]);
        assert_ne!(code, Some(0));
        assert!(
            err.contains("--pad = /dev/null: cannot open") && err.contains("not an input event device"),
            "{err}"
        );
    } else {
        assert!(err.contains("--pad: this rccar was built without the gamepad"), "{err}");
    }
    let (code, err) = run(&["--set", "gamepad.steer_axis=\"ABS_Q\"", "--pad"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("gamepad.steer_axis"), "{err}");
}
