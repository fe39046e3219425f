//! The firmware in the loop, closed: `rccar drive --camera sim --port <pty>` on the wall clock.
//! The simulator renders the car's view, `drive` runs the pipeline and sends DRIVE frames over
//! the pty, the real firmware (.elf in simavr) produces servo/ESC pulse widths, and those widths
//! (`--pwm-log`, the harness's report) move the simulated car. Faults are injected into this
//! same setup: kill -9, Ctrl-C, a stalled camera, a vanished pty, bit errors on the wire.
//!
//! Run: `cargo test --release --features serial --test car drive_fil:: -- --nocapture --test-threads 1`
//! (the timed faults need the machine to themselves: a late frame would be measured as the
//! car's latency). The two whole-lap tests, lane keeping only, assert laps, departures and RMS,
//! not timings; tests/all.sh runs them one after the other (side by side, two emulators and two
//! drives on a machine with both cores already busy fell behind real time and left the road).
//! `drive` runs at the priority the car's service gives it (docs/rccar.service: Nice=-5) where
//! the test may raise it (root, CAP_SYS_NICE). `RCCAR_FIL_LAPS=3` drives 3 laps in the
//! closed-loop test; `RCCAR_FIL_DETECT=1` turns detection on.
#![cfg(feature = "serial")]

use super::sim;

use serde_json::Value;
use sim::{Event, Sim};
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Proc, Stdio};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_rccar");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A scratch folder per test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rccar-fil-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The emulator (its report teed into `dir/pwm.log`) and the path `drive` should follow.
fn start_sim(dir: &Path, name: &str) -> (Sim, PathBuf) {
    let log = dir.join("pwm.log");
    std::fs::write(&log, "").unwrap();
    let sim = Sim::start_logged(&Sim::fresh_path(name), Some(&log));
    (sim, log)
}

/// Starts `rccar drive --camera sim` against the emulator; lane keeping only unless `extra`
/// says otherwise.
fn drive(sim: &Sim, log: &Path, out: &Path, extra: &[&str]) -> Child {
    let mut c = Proc::new(EXE);
    c.current_dir(root())
        .args(["drive", "--camera", "sim", "--port", &sim.tty, "--pwm-log"])
        .arg(log)
        .arg("--out")
        .arg(out)
        .args(["--arm", "--status-every", "5"])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(out.with_extension("stdout")).unwrap())
        .stderr(std::fs::File::create(out.with_extension("stderr")).unwrap());
    std::fs::create_dir_all(out).unwrap();
    // As the car's service runs it (docs/rccar.service, Nice=-5), where allowed.
    sim::as_the_car(&mut c);
    c.spawn().expect("start rccar drive")
}


/// Waits for `drive` (its output went to `out.stdout` / `out.stderr`).
fn wait(child: &mut Child, out: &Path, limit: Duration) -> (Option<i32>, String, String) {
    let end = Instant::now() + limit;
    let read = |ext: &str| std::fs::read_to_string(out.with_extension(ext)).unwrap_or_default();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return (st.code(), read("stdout"), read("stderr"));
        }
        if Instant::now() > end {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "rccar drive did not end in {limit:?}\nstdout:\n{}\nstderr:\n{}",
                read("stdout"),
                read("stderr")
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn telemetry(out: &Path) -> Vec<Value> {
    std::fs::read_to_string(out.join("telemetry.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

fn summary(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary.json")).unwrap()
}

/// Waits until `drive` has processed `n` frames (telemetry lines).
fn wait_frames(out: &Path, n: usize, limit: Duration) {
    let end = Instant::now() + limit;
    while Instant::now() < end {
        if telemetry(out).len() >= n {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("drive did not reach {n} frames in {limit:?}");
}

/// ESC pulses (width µs, simulated µs).
fn esc(sim: &Sim) -> Vec<(f64, f64)> {
    sim.pulses(false)
}

/// `rccar sim` on the same track, same settings: the pure simulation to compare with.
fn pure_sim(laps: u32, detect: bool, out: &Path) -> Value {
    let st = Proc::new(EXE)
        .current_dir(root())
        .args(["sim", "--laps", &laps.to_string(), "--no-timing", "--out"])
        .arg(out)
        .args(["--set", &format!("detect.enabled={detect}")])
        .output()
        .unwrap();
    assert!(
        st.status.success() || st.status.code() == Some(1),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    summary(out)
}

fn detect_on() -> bool {
    std::env::var("RCCAR_FIL_DETECT").is_ok_and(|v| v == "1")
}

#[test]
fn firmware_in_the_loop_drives_a_lap_like_the_pure_simulation() {
    let laps: u32 = std::env::var("RCCAR_FIL_LAPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let detect = detect_on();
    let dir = scratch("closed");
    let (sim, log) = start_sim(&dir, "closed");
    let out = dir.join("drive");
    let mut child = drive(
        &sim,
        &log,
        &out,
        &[
            "--laps",
            &laps.to_string(),
            "--set",
            &format!("detect.enabled={detect}"),
        ],
    );
    let (code, stdout, stderr) = wait(&mut child, &out, Duration::from_secs(150 * laps as u64 + 120));
    println!("{stdout}");
    assert_eq!(code, Some(0), "stderr: {stderr}");
    let fil = summary(&out);
    let pure = pure_sim(laps, detect, &dir.join("sim"));
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    println!(
        "FIL  : laps {} rms {:.4} m max {:.4} m departures {} lap times {}",
        fil["laps"],
        f(&fil, "xte_rms_m"),
        f(&fil, "xte_max_m"),
        fil["lane_departures"],
        fil["lap_times_s"]
    );
    println!(
        "sim  : laps {} rms {:.4} m max {:.4} m departures {} lap times {}",
        pure["laps"],
        f(&pure, "xte_rms_m"),
        f(&pure, "xte_max_m"),
        pure["lane_departures"],
        pure["lap_times_s"]
    );
    let ratio = f(&fil, "xte_rms_m") / f(&pure, "xte_rms_m");
    println!("FIL RMS / sim RMS = {ratio:.3} (bound 1.25)");
    assert_eq!(fil["laps"].as_u64(), Some(laps as u64));
    assert_eq!(fil["lane_departures"].as_u64(), Some(0));
    assert!(ratio <= 1.25, "FIL RMS {ratio:.3}x the pure simulation's");
    // Latency: capture -> pulse, from drive's own report.
    let line = stdout
        .lines()
        .find(|l| l.contains("capture -> pulse latency"))
        .expect("latency line");
    println!("{line}");
    // The pulses moved the car: the ESC went well above neutral.
    assert!(esc(&sim).iter().any(|&(w, _)| w > 1550.0));
}

/// Neutral pulse widths as the emulator reports them: servo centre and ESC neutral of the
/// firmware's default configuration (1500 µs), plus the hardware's one 0.5 µs timer tick.
const NEUTRAL_US: f64 = 1500.0;
/// How far a reported width may be from neutral and still be neutral (µs).
const NEUTRAL_TOL_US: f64 = 1.0;

/// The time (simulated µs) from which a pin has been at neutral, judged over the whole report:
/// `None` if its last width is not neutral. A pin never moved off neutral reports its first pulse.
fn neutral_since(pulses: &[(f64, f64)]) -> Option<f64> {
    let last = pulses.last()?;
    if (last.0 - NEUTRAL_US).abs() > NEUTRAL_TOL_US {
        return None;
    }
    // the first pulse of the final run of neutral widths
    let i = pulses
        .iter()
        .rposition(|&(w, _)| (w - NEUTRAL_US).abs() > NEUTRAL_TOL_US)
        .map_or(0, |i| i + 1);
    Some(pulses[i].1)
}

/// `rccar drive` killed with SIGKILL (no neutral, no DISARM) while driving: the real firmware's
/// failsafe brings both pins back to neutral. Proved from the emulator's report only: the ESC
/// was driving when the process died, and the ESC and the servo are at their neutral widths no
/// later than `failsafe_ms` (250 ms) + one 20 ms PWM period + 5 ms (the firmware's 1 ms tick,
/// a frame's bytes) after the kill, measured in the firmware's own clock from the kill — or,
/// when the emulator still had bytes of the dead process's last frames to read (it runs behind
/// the wall clock on a busy machine, so a DRIVE written before the kill can reach the firmware
/// after the kill's time in its clock), from the last of those — and stay there for the next
/// second.
#[test]
fn kill_9_mid_lap_the_firmware_failsafe_holds_the_car() {
    let dir = scratch("kill9");
    let (sim, log) = start_sim(&dir, "kill9");
    let out = dir.join("drive");
    let mut child = drive(&sim, &log, &out, &["--laps", "1", "--set", "detect.enabled=false"]);
    wait_frames(&out, 150, Duration::from_secs(60));
    // driving into the first curve: the ESC above neutral and the servo turned (so that both
    // pins have to come back); the curve begins ~10 s into the lap
    let off = |w: Option<f64>| w.is_some_and(|w| (w - NEUTRAL_US).abs() > 20.0);
    let driving = sim.wait_until(
        Duration::from_secs(90),
        || (),
        |s| s.last_width(false).is_some_and(|w| w > 1550.0) && off(s.last_width(true)),
    );
    assert!(
        driving,
        "not driving in a curve: ESC {:?}, servo {:?}",
        sim.last_width(false),
        sim.last_width(true)
    );
    // The kill, then at once the firmware's clock: the kill happened no later than `t_kill`.
    let killed = Instant::now();
    // SAFETY: kill(2) on the pid of our own child, which has not been waited for yet.
    let r = unsafe { libc::kill(child.id() as i32, libc::SIGKILL) };
    assert_eq!(r, 0, "kill -9 failed");
    let t_kill = sim.now_us();
    let _ = child.wait();
    // The failsafe's answer: both pins back at neutral (wait for it; the emulator may be slow).
    let at_neutral = |s: &Sim| neutral_since(&s.pulses(false)).is_some() && neutral_since(&s.pulses(true)).is_some();
    let seen = sim.wait_until(sim::SIM_DEADLINE, || (), at_neutral);
    let seen_wall = killed.elapsed();
    assert!(
        seen,
        "ESC {:?} / servo {:?} not back at neutral after the kill",
        sim.last_width(false),
        sim.last_width(true)
    );
    let esc_at = neutral_since(&sim.pulses(false)).unwrap();
    let servo_at = neutral_since(&sim.pulses(true)).unwrap();
    // the ESC was driving at the kill: its width at t_kill was above neutral
    let esc_before = esc(&sim).into_iter().rfind(|&(_, t)| t <= t_kill).map(|p| p.0);
    assert!(
        esc_before.is_some_and(|w| w > 1550.0),
        "ESC {esc_before:?} at the kill: not driving"
    );
    let servo_before = sim.pulses(true).into_iter().rfind(|&(_, t)| t <= t_kill).map(|p| p.0);
    let failsafe_ms = f64::from(rccar::link::protocol::LinkConfig::default().failsafe_ms);
    let bound_ms = failsafe_ms + 20.0 + 5.0;
    let esc_ms = (esc_at - t_kill) / 1e3;
    let servo_ms = (servo_at - t_kill) / 1e3;
    // also from the last DRIVE the firmware received (the failsafe's own reference)
    let last_drive = sim
        .rx_times(rccar::link::protocol::id::DRIVE)
        .into_iter()
        .filter(|&t| t <= esc_at)
        .fold(f64::NAN, f64::max);
    let from_drive_ms = (esc_at - last_drive) / 1e3;
    // The dead process's bytes the emulator read after the kill's time in its clock (0 on an
    // idle machine): the failsafe counts from the last of them.
    let backlog_ms = ((last_drive - t_kill) / 1e3).max(0.0);
    let bound_ms = bound_ms + backlog_ms;
    println!(
        "kill -9: ESC {:.1} µs, servo {servo_before:?} µs at the kill; ESC neutral {esc_ms:.1} ms, servo neutral {servo_ms:.1} ms after the kill \
         (firmware clock, bound {bound_ms:.0} ms with {backlog_ms:.1} ms of the pty's bytes read after the kill); \
         ESC neutral {from_drive_ms:.1} ms after the last DRIVE (bound {:.0} ms); seen in the report {:.0} ms (wall) after the kill",
        esc_before.unwrap(),
        failsafe_ms + 21.0,
        seen_wall.as_secs_f64() * 1e3
    );
    assert!(
        esc_ms > 0.0,
        "ESC neutral {esc_ms:.1} ms before the kill: the failsafe had tripped already"
    );
    assert!(
        esc_ms <= bound_ms,
        "ESC neutral {esc_ms:.1} ms after the kill (bound {bound_ms} ms)"
    );
    assert!(
        off(servo_before),
        "servo {servo_before:?} at the kill: already centred, its return proves nothing"
    );
    assert!(
        servo_ms > 0.0 && servo_ms <= bound_ms,
        "servo neutral {servo_ms:.1} ms after the kill (bound {bound_ms} ms)"
    );
    assert!(
        (failsafe_ms - 1.0..=failsafe_ms + 21.0).contains(&from_drive_ms),
        "ESC neutral {from_drive_ms:.1} ms after the last DRIVE: not the {failsafe_ms} ms failsafe"
    );
    // ... and both stay neutral: one more second of the firmware's time, no pulse change.
    let n = (esc(&sim).len(), sim.pulses(true).len());
    sim.wait_sim_us(esc_at.max(servo_at) + 1e6);
    assert_eq!(
        (esc(&sim).len(), sim.pulses(true).len()),
        n,
        "a pin moved after the failsafe"
    );
}

#[test]
fn ctrl_c_sends_neutral_before_exit() {
    let dir = scratch("ctrlc");
    let (sim, log) = start_sim(&dir, "ctrlc");
    let out = dir.join("drive");
    let mut child = drive(&sim, &log, &out, &["--set", "detect.enabled=false"]);
    wait_frames(&out, 120, Duration::from_secs(60));
    // driving (the emulator's report may lag the frames on a busy machine: wait for it)
    assert!(
        sim.wait_until(Duration::from_secs(60), || (), |s| s.last_width(false).is_some_and(|w| w > 1550.0)),
        "not driving before Ctrl-C: ESC {:?}",
        sim.last_width(false)
    );
    let n_before = esc(&sim).len();
    let t0 = Instant::now();
    let _ = Proc::new("kill").args(["-INT", &child.id().to_string()]).status();
    let (code, stdout, _) = wait(&mut child, &out, Duration::from_secs(30));
    let exit_wall = t0.elapsed();
    // the ESC's neutral pulse in the emulator's report (the emulator may lag on a busy machine)
    let neutral = |s: &Sim| {
        esc(s)[n_before..]
            .iter()
            .copied()
            .find(|&(w, _)| (w - NEUTRAL_US).abs() <= NEUTRAL_TOL_US)
    };
    assert!(
        sim.wait_until(sim::SIM_DEADLINE, || (), |s| neutral(s).is_some()),
        "ESC not neutral after Ctrl-C"
    );
    let neutral_wall = t0.elapsed();
    let t_neutral = neutral(&sim).unwrap().1;
    assert_eq!(code, Some(130));
    assert!(stdout.contains("neutral sent"), "{stdout}");
    let disarms = sim.rx_times(rccar::link::protocol::id::DISARM);
    assert!(!disarms.is_empty(), "no DISARM frame reached the firmware");
    // Neutral came from drive's own last frames (its neutral DRIVE, or the DISARM), not from
    // the 250 ms failsafe: in the firmware's clock the pulse follows one of them within one
    // 20 ms PWM period (+1 ms), and comes well before the failsafe could have tripped.
    let before = |id: u8| {
        sim.rx_times(id)
            .into_iter()
            .filter(|&t| t <= t_neutral)
            .fold(f64::NAN, f64::max)
    };
    let last_drive = before(rccar::link::protocol::id::DRIVE);
    let last_frame = last_drive.max(before(rccar::link::protocol::id::DISARM));
    let after_frame_ms = (t_neutral - last_frame) / 1e3;
    let after_drive_ms = (t_neutral - last_drive) / 1e3;
    println!(
        "Ctrl-C: exited after {:.0} ms (wall), code {code:?}; ESC neutral {after_frame_ms:.1} ms after drive's last \
         frame (bound 21 ms) and {after_drive_ms:.1} ms after its last DRIVE (the failsafe would take 250 ms; firmware \
         clock); seen after {:.0} ms (wall)",
        exit_wall.as_secs_f64() * 1e3,
        neutral_wall.as_secs_f64() * 1e3
    );
    assert!(
        after_frame_ms <= 21.0,
        "ESC neutral {after_frame_ms:.1} ms after drive's last frame"
    );
    assert!(
        after_drive_ms < 200.0,
        "ESC neutral {after_drive_ms:.1} ms after the last DRIVE: the failsafe's, not drive's"
    );
}

#[test]
fn a_stalled_camera_sends_neutral_within_half_a_second_and_driving_resumes() {
    let dir = scratch("stall");
    let (sim, log) = start_sim(&dir, "stall");
    let out = dir.join("drive");
    let mut child = drive(
        &sim,
        &log,
        &out,
        &["--seconds", "9", "--sim-stall", "4:1", "--set", "detect.enabled=false"],
    );
    let (code, stdout, stderr) = wait(&mut child, &out, Duration::from_secs(60));
    assert_eq!(code, Some(0), "{stderr}");
    let stall_line = stdout
        .lines()
        .find(|l| l.contains("camera stalled"))
        .expect("stall reported");
    println!("{stall_line}");
    let tel = telemetry(&out);
    // the last frame before the stall and the first after it (frame time, s)
    let times: Vec<f64> = tel.iter().map(|r| r["time_s"].as_f64().unwrap()).collect();
    let (gap_at, gap) = times
        .windows(2)
        .map(|w| (w[0], w[1] - w[0]))
        .fold((0.0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
    println!("camera gap: {gap:.3} s from t={gap_at:.2} s");
    assert!(gap >= 0.9, "no stall seen in the frames: largest gap {gap}");
    // ESC: neutral within 0.5 s of the last frame before the stall (simulated time of the
    // emulator runs with the wall clock; compare with the first pulse after the stall began)
    let pulses = esc(&sim);
    let driving_before = pulses.iter().any(|&(w, _)| w > 1550.0);
    assert!(driving_before);
    let neutral_idx = pulses
        .iter()
        .position(|&(w, t)| (w - 1500.0).abs() <= 1.0 && t > 1e6)
        .expect("ESC neutral during the stall");
    let last_drive_before = pulses[..neutral_idx].last().map_or(0.0, |p| p.1);
    let resumed = pulses[neutral_idx..].iter().any(|&(w, _)| w > 1550.0);
    println!(
        "stall: ESC neutral at {:.3} s (previous change {:.3} s), driving resumed: {resumed}",
        pulses[neutral_idx].1 / 1e6,
        last_drive_before / 1e6
    );
    assert!(resumed, "driving did not resume after the stall");
    // Neutral within 0.5 s of the last frame's command (both in the emulator's time): the last
    // DRIVE at the UART more than 50 ms before the neutral pulse is the last frame's.
    let t_neutral = pulses[neutral_idx].1;
    let last_frame_drive = sim
        .rx_times(rccar::link::protocol::id::DRIVE)
        .into_iter()
        .filter(|&t| t < t_neutral - 50e3)
        .fold(f64::NAN, f64::max);
    let after_ms = (t_neutral - last_frame_drive) / 1e3;
    println!("stall: ESC neutral {after_ms:.0} ms after the last frame's DRIVE (bound 500 ms + one 20 ms PWM period)");
    assert!(after_ms <= 520.0, "neutral {after_ms} ms after the last frame");
    let lat = tel.iter().filter_map(|r| r["latency_ms"].as_f64()).fold(0.0, f64::max);
    assert!(lat < 500.0, "a frame's latency {lat} ms");
}

#[test]
fn a_vanished_pty_reconnects_and_nothing_moves_until_armed_again() {
    let dir = scratch("vanish");
    let log = dir.join("pwm.log");
    std::fs::write(&log, "").unwrap();
    let path = Sim::fresh_path("vanish-drive");
    let sim = Sim::start_logged(&path, Some(&log));
    let out = dir.join("drive");
    let mut child = drive(&sim, &log, &out, &["--seconds", "40", "--set", "detect.enabled=false"]);
    wait_frames(&out, 90, Duration::from_secs(60));
    let driving = sim.wait_until(
        sim::SIM_DEADLINE,
        || (),
        |s| s.last_width(false).is_some_and(|w| w > 1550.0),
    );
    assert!(
        driving,
        "not driving before the unplug: ESC {:?}",
        sim.last_width(false)
    );
    drop(sim); // unplugged: the emulator and its pty are gone
               // The cable stays out for 1.5 s: a duration of the scenario, not a wait for anything (the
               // link notices the loss whenever it next writes, and reconnects when the port is back).
    std::thread::sleep(Duration::from_millis(1500));
    let sim = Sim::start_logged(&path, Some(&log)); // plugged in again: a fresh firmware boot
                                                    // reconnected: drive's HELLO reached the new firmware ...
    let hello = |s: &Sim| s.rx_times(rccar::link::protocol::id::HELLO).first().copied();
    assert!(
        sim.wait_until(sim::SIM_DEADLINE, || (), |s| hello(s).is_some()),
        "drive did not reconnect"
    );
    // ... but for the next 3 s of the firmware's clock nothing moves: the ESC stays at neutral
    sim.wait_sim_us(hello(&sim).unwrap() + 3e6);
    let moved = esc(&sim).iter().any(|&(w, _)| (w - NEUTRAL_US).abs() > NEUTRAL_TOL_US);
    let drives = sim.rx_times(rccar::link::protocol::id::DRIVE).len();
    println!("3 s after the reconnect, before re-arming: ESC moved {moved}, DRIVE frames received {drives}");
    assert!(!moved, "the car moved after a reconnect without being armed again");
    // the button (SIGUSR1 at the desk) arms again: driving resumes
    let _ = Proc::new("kill").args(["-USR1", &child.id().to_string()]).status();
    let ok = sim.wait_until(
        sim::SIM_DEADLINE,
        || (),
        |s| s.last_width(false).is_some_and(|w| w > 1550.0),
    );
    println!("after the button: driving again {ok}");
    assert!(ok, "not driving after re-arming");
    let _ = Proc::new("kill").args(["-INT", &child.id().to_string()]).status();
    let (code, _, _) = wait(&mut child, &out, Duration::from_secs(30));
    assert_eq!(code, Some(130));
}

/// The bit-error rate the lap test asks `rccar drive --link-bit-errors` for.
const BER: f64 = 1e-3;

/// Host frames the firmware's parser lost, from the emulator's report: the harness decodes the
/// bytes that reach the UART with the firmware's own protocol.c (`RX id seq t`), so a frame with
/// a flipped bit fails its CRC (or its header) there as in the firmware and leaves a gap in the
/// host's sequence numbers. Returns (frames decoded, frames lost).
fn frames_lost(sim: &Sim) -> (u64, u64) {
    let seqs: Vec<u8> = sim
        .events()
        .into_iter()
        .filter_map(|e| match e {
            Event::Rx { seq, .. } => Some(seq),
            _ => None,
        })
        .collect();
    let lost = seqs
        .windows(2)
        .map(|w| u64::from(w[1].wrapping_sub(w[0]).wrapping_sub(1)))
        .sum();
    (seqs.len() as u64, lost)
}

/// A lap with 1e-3 of the bits flipped on the way to the firmware: the flips happen at the rate
/// asked for (seen by the firmware's parser, not taken from the injector), and the car still
/// drives the lap without leaving its lane.
///
/// A DRIVE frame is 10 bytes: with bit-error rate p it is corrupted with probability
/// q = 1 − (1 − p)^80 (7.7 % at 1e-3). Over n frames the lost count is binomial; the test
/// accepts n·q ± 5 standard deviations (about ±28 % for a lap's ~3,900 frames), i.e. an
/// implied bit-error rate of roughly 0.7e-3 … 1.3e-3. Without injection nothing is lost and the
/// test fails.
#[test]
fn bit_errors_at_1e_3_for_a_lap_cause_no_departure() {
    let dir = scratch("ber");
    let (sim, log) = start_sim(&dir, "ber");
    let out = dir.join("drive");
    let ber = BER.to_string();
    let mut child = drive(
        &sim,
        &log,
        &out,
        &[
            "--laps",
            "1",
            "--link-bit-errors",
            &ber,
            "--set",
            "detect.enabled=false",
        ],
    );
    let (code, stdout, stderr) = wait(&mut child, &out, Duration::from_secs(300));
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    let s = summary(&out);
    let (decoded, lost) = frames_lost(&sim);
    let n = (decoded + lost) as f64;
    let q = 1.0 - (1.0 - BER).powi(80);
    let expected = n * q;
    let sd = (n * q * (1.0 - q)).sqrt();
    let implied_ber = 1.0 - (1.0 - lost as f64 / n).powf(1.0 / 80.0);
    println!(
        "{BER:e} bit errors: {n} host frames, {lost} lost at the firmware's parser (expected {expected:.0} ± {sd:.0}), \
         implied bit-error rate {implied_ber:.2e}; laps {} departures {} rms {:.4} m",
        s["laps"],
        s["lane_departures"],
        s["xte_rms_m"].as_f64().unwrap()
    );
    assert!(n > 1000.0, "only {n} host frames reached the emulator");
    assert!(
        (lost as f64 - expected).abs() <= 5.0 * sd,
        "{lost} of {n} frames lost, expected {expected:.0} ± {:.0} (5 sd) for bit-error rate {BER:e}: implied rate {implied_ber:.2e}",
        5.0 * sd
    );
    assert_eq!(s["laps"].as_u64(), Some(1));
    assert_eq!(s["lane_departures"].as_u64(), Some(0));
}

/// Issue 24: SIGHUP (an SSH session closing — how students start the car) ended `drive` with
/// 129, no neutral, no DISARM, no summary; only the firmware's watchdog stopped the car. Now
/// it is handled like Ctrl-C: DISARM and a neutral pulse from `drive` itself, long before the
/// failsafe, then the summary.
#[test]
fn sighup_sends_neutral_and_disarm_then_writes_the_summary() {
    let dir = scratch("hup");
    let (sim, log) = start_sim(&dir, "hup");
    let out = dir.join("drive");
    let mut child = drive(&sim, &log, &out, &["--set", "detect.enabled=false"]);
    wait_frames(&out, 120, Duration::from_secs(60));
    assert!(sim.last_width(false).is_some_and(|w| w > 1550.0), "driving before SIGHUP");
    let n_before = esc(&sim).len();
    let t0 = Instant::now();
    let _ = Proc::new("kill").args(["-HUP", &child.id().to_string()]).status();
    let mut neutral_wall = None;
    while t0.elapsed() < Duration::from_secs(5) {
        if esc(&sim)[n_before..].iter().any(|&(w, _)| (w - 1500.0).abs() <= 1.0) {
            neutral_wall = Some(t0.elapsed());
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let (code, stdout, _) = wait(&mut child, &out, Duration::from_secs(10));
    let neutral_wall = neutral_wall.expect("ESC neutral after SIGHUP");
    let disarms = sim.rx_times(rccar::link::protocol::id::DISARM);
    println!(
        "SIGHUP: ESC neutral after {:.0} ms, code {code:?}, DISARM frames {}",
        neutral_wall.as_secs_f64() * 1e3,
        disarms.len()
    );
    assert_eq!(code, Some(129));
    assert!(stdout.contains("neutral sent"), "{stdout}");
    assert!(!disarms.is_empty(), "no DISARM frame reached the firmware");
    let s = summary(&out);
    assert_eq!(s["drive"]["frames"].as_u64(), Some(telemetry(&out).len() as u64));
}

/// Issue 24: a serial port that vanished mid-drive went unnoticed (the status line kept
/// printing "throttle +0.50" for 4.5 s, then exit 0). Now the lost link is reported within
/// 300 ms of the emulator's death (measured from the kill to the line on stderr), the car is
/// disarmed, and when it stays lost for `--link-timeout` the run ends as a fault (exit 3)
/// naming it.
#[test]
fn killing_the_emulator_is_reported_within_300_ms_and_ends_the_run_as_a_fault() {
    let dir = scratch("lost");
    let (sim, log) = start_sim(&dir, "lost");
    let out = dir.join("drive");
    let mut child = drive(&sim, &log, &out, &["--set", "detect.enabled=false", "--link-timeout", "2"]);
    wait_frames(&out, 120, Duration::from_secs(60));
    assert!(sim.last_width(false).is_some_and(|w| w > 1550.0), "driving before the kill");
    let stderr_path = out.with_extension("stderr");
    let t0 = Instant::now();
    drop(sim); // the emulator is killed: its pty is gone
    let mut reported = None;
    while t0.elapsed() < Duration::from_secs(5) {
        if std::fs::read_to_string(&stderr_path).unwrap_or_default().contains("link lost") {
            reported = Some(t0.elapsed());
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let (code, _, stderr) = wait(&mut child, &out, Duration::from_secs(15));
    let ended = t0.elapsed();
    let reported = reported.unwrap_or_else(|| panic!("the lost link was not reported:\n{stderr}"));
    println!(
        "emulator killed: 'link lost' on stderr after {:.0} ms (bound 300 ms), exit {code:?} after {:.1} s\n{}",
        reported.as_secs_f64() * 1e3,
        ended.as_secs_f64(),
        stderr.lines().filter(|l| l.contains("link") || l.contains("fault")).collect::<Vec<_>>().join("\n")
    );
    assert!(reported <= Duration::from_millis(300), "reported after {reported:?}");
    assert_eq!(code, Some(3), "{stderr}");
    assert!(stderr.contains("drive: fault: link: lost for"), "{stderr}");
    let s = summary(&out);
    assert!(s["drive"]["fault"].as_str().is_some_and(|f| f.starts_with("link:")), "{s}");
    // every record after the loss says what the car did: nothing
    let tel = telemetry(&out);
    let lost = tel
        .iter()
        .position(|r| r["events"].as_array().is_some_and(|e| e.iter().any(|e| e.as_str().is_some_and(|e| e.contains("link lost")))))
        .expect("the loss is in telemetry");
    assert!(tel[lost..].iter().all(|r| r["car"] == "fault" && r["sent"]["throttle"].as_f64().or(r["throttle"].as_f64()) == Some(0.0)));
}
