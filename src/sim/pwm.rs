//! What moves the simulated car on the wall clock (`rccar drive --camera sim`):
//!
//! - in a dry run, [`SimActuators`]: the gate's commands themselves (the simulated car does
//!   exactly what a perfect servo and ESC would do with them);
//! - with the firmware in the loop, [`PwmWatcher`]: the firmware emulator's report (its stdout,
//!   `PULSE servo|esc WIDTH_US T_US` lines, written by firmware/sim/rccar_sim.c) followed as it
//!   grows; the newest pulse widths become the actuators' command: servo 1000..2000 µs → steer
//!   −1..1, ESC 1000..2000 µs → throttle −1..1 (the firmware's default end points). It also
//!   measures capture → pulse latency: [`PwmWatcher::observer`] notes each frame's commanded
//!   servo width and capture time, and the watcher matches the pulse that shows that width.
//!
//! This is an adapter (a file read by a thread, the clock handed in); the world itself is
//! advanced by [`super::camera::SimCamera`] at each tick.

use super::camera::ActuatorState;
use crate::control::Command;
use crate::drive::{Clock, Flow, FrameContext, LoopError, LoopStats, Observer};
use crate::link::protocol::{permille_to_us, to_permille};
use crate::sink::{Actuators, CommandSink, SinkError};
use std::io::{BufRead, Seek};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The simulated car's actuators in a dry run: they do what the gate sends.
pub struct SimActuators(pub ActuatorState);

impl CommandSink for SimActuators {
    fn send(&mut self, c: Command, _t: f64) -> Result<Command, SinkError> {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = c;
        Ok(c)
    }
}

impl Actuators for SimActuators {}

/// Frames whose commanded servo width is waiting to show up as a pulse: (capture time, µs).
type Pending = Arc<Mutex<Vec<(f64, f64)>>>;

/// Follows the firmware emulator's report (see the module notes).
pub struct PwmWatcher {
    latencies: Arc<Mutex<Vec<f64>>>,
    pending: Pending,
    quit: Arc<AtomicBool>,
}

/// Turns one report line into (is servo, value −1..1); other lines are `None`.
pub fn parse_pulse(line: &str) -> Option<(bool, f64, f64)> {
    let t: Vec<&str> = line.split_whitespace().collect();
    if let ["PULSE", pin, w, _t] = t.as_slice() {
        let w: f64 = w.parse().ok()?;
        let v = ((w - 1500.0) / 500.0).clamp(-1.0, 1.0);
        return match *pin {
            "servo" => Some((true, v, w)),
            "esc" => Some((false, v, w)),
            _ => None,
        };
    }
    None
}

impl PwmWatcher {
    /// Starts following `path` from its current end (older pulses are not this run's).
    pub fn start(path: &Path, actuators: ActuatorState, clock: Arc<dyn Clock + Send + Sync>) -> std::io::Result<Self> {
        let mut f = std::fs::File::open(path)?;
        f.seek(std::io::SeekFrom::End(0))?;
        let latencies = Arc::new(Mutex::new(Vec::new()));
        let pending: Pending = Arc::new(Mutex::new(Vec::new()));
        let quit = Arc::new(AtomicBool::new(false));
        let (lat, q, pend) = (latencies.clone(), quit.clone(), pending.clone());
        std::thread::Builder::new().name("rccar-pwm".into()).spawn(move || {
            let mut r = std::io::BufReader::new(f);
            let mut line = String::new();
            while !q.load(Ordering::SeqCst) {
                line.clear();
                match r.read_line(&mut line) {
                    Ok(0) => {
                        clock.sleep_s(0.001);
                        continue;
                    }
                    Ok(_) if !line.ends_with('\n') => {
                        // a line being written: wait for its end
                        let mut rest = String::new();
                        while !rest.ends_with('\n') && !q.load(Ordering::SeqCst) {
                            clock.sleep_s(0.001);
                            let _ = r.read_line(&mut rest);
                        }
                        line.push_str(&rest);
                    }
                    Ok(_) => {}
                    Err(_) => break,
                }
                let Some((servo, v, w)) = parse_pulse(&line) else { continue };
                let now = clock.now_s();
                let mut a = actuators.lock().unwrap_or_else(|e| e.into_inner());
                if servo {
                    a.steer = v;
                    let mut p = pend.lock().unwrap_or_else(|e| e.into_inner());
                    if let Some(i) = p.iter().rposition(|&(_, us)| (us - w).abs() <= 1.0) {
                        lat.lock().unwrap_or_else(|e| e.into_inner()).push((now - p[i].0) * 1e3);
                        p.drain(..=i);
                    }
                } else {
                    a.throttle = v;
                }
            }
        })?;
        Ok(Self { latencies, pending, quit })
    }

    /// Capture → servo pulse latency so far: (median, max) milliseconds.
    pub fn latency_ms(&self) -> Option<(f64, f64)> {
        LoopStats::median_max(&self.latencies.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// The loop's side: notes each frame's commanded servo width and capture time.
    pub fn observer(&self) -> PulseLatency {
        PulseLatency(self.pending.clone())
    }
}

impl Drop for PwmWatcher {
    fn drop(&mut self) {
        self.quit.store(true, Ordering::SeqCst);
    }
}

/// Notes each frame's commanded servo width (firmware default end points) with its capture
/// time, for [`PwmWatcher::latency_ms`].
pub struct PulseLatency(Pending);

impl Observer for PulseLatency {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        if let Some(c) = ctx.frame.captured_s {
            let us = f64::from(permille_to_us(to_permille(ctx.record.steer), 1000, 1500, 2000));
            let mut p = self.0.lock().unwrap_or_else(|e| e.into_inner());
            p.push((c, us));
            let n = p.len();
            if n > 300 {
                p.drain(..n - 300);
            }
        }
        Ok(Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_lines_become_actuator_values() {
        assert_eq!(parse_pulse("PULSE servo 2000 1234\n"), Some((true, 1.0, 2000.0)));
        assert_eq!(parse_pulse("PULSE esc 1250 99"), Some((false, -0.5, 1250.0)));
        assert_eq!(parse_pulse("PULSE esc 3000 99"), Some((false, 1.0, 3000.0)), "clamped");
        assert_eq!(parse_pulse("PULSE horn 1500 1"), None);
        assert_eq!(parse_pulse("PULSE esc x 1"), None);
        assert_eq!(parse_pulse("pty /dev/pts/3"), None);
    }
}
