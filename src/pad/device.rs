//! The car's gamepad on Linux (feature `gamepad`): an evdev event device read by a thread of
//! its own, each event through the [`PadMachine`] and its actions onto the car through the
//! [`PadLink`].
//!
//! evdev, not gilrs: evdev is Rust over the kernel's ioctls (nix, libc) and cross-builds for
//! the Pi as it is; gilrs enumerates pads through libudev, a C library to link for aarch64.
//!
//! The thread waits for the device at most [`POLL_MS`] at a time, so that it ticks the machine
//! (held buttons, the input re-sent while the dead-man is held) and sees a stop request. A read
//! error, `ENODEV` or a hang-up (the pad unplugged, Bluetooth out of range) is a
//! [`PadEvent::Disconnected`]: neutral at once, the pad's health lost, and the thread looks for
//! the pad again every [`RETRY_MS`] (the same path, or any gamepad with `device = "auto"`).

use super::link::PadLink;
use super::machine::{code, AxisRange, PadEvent, PadMachine};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The longest wait for the device before the machine is ticked, ms.
pub const POLL_MS: i32 = 20;
/// How often a pad that is gone is looked for, ms.
pub const RETRY_MS: u64 = 500;

/// Which pad to read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Which {
    /// The first input device with a gamepad's buttons.
    Auto,
    /// This event device.
    Path(PathBuf),
}

/// Why the pad cannot be used (at start: later problems are disconnections).
#[derive(Debug, thiserror::Error)]
pub enum PadError {
    /// The named device cannot be opened.
    #[error("{key} = {path}: cannot open: {error}{hint}")]
    Open {
        /// Where the path came from (`gamepad.device`, `--pad`).
        key: String,
        /// The device.
        path: String,
        /// Why.
        error: std::io::Error,
        /// What to do about it.
        hint: &'static str,
    },
    /// The named device is not a gamepad (or lacks the configured axes).
    #[error("{key} = {path} ({name}): {why}")]
    NotAPad {
        /// Where the path came from.
        key: String,
        /// The device.
        path: String,
        /// Its name.
        name: String,
        /// What it lacks.
        why: String,
    },
    /// The thread cannot be started.
    #[error("the gamepad thread: {0}")]
    Thread(std::io::Error),
}

fn hint(e: &std::io::Error) -> &'static str {
    if e.raw_os_error() == Some(libc::ENOTTY) {
        return " (not an input event device: give /dev/input/eventN, or device = \"auto\")";
    }
    match e.kind() {
        std::io::ErrorKind::NotFound => {
            " (no such device: `ls -l /dev/input/by-id/` lists the pads; or device = \"auto\")"
        }
        std::io::ErrorKind::PermissionDenied => {
            " (add the user to the `input` group: sudo usermod -aG input $USER, then log in again)"
        }
        _ => "",
    }
}

/// What a gamepad lacks for the mapping (`None`: nothing), given the steer and throttle axes.
fn lacks(dev: &evdev::Device, axes: [(&str, u16); 2]) -> Option<String> {
    let keys = dev.supported_keys();
    let has = |k: u16| keys.is_some_and(|s| s.contains(evdev::KeyCode(k)));
    if !has(code::BTN_SOUTH) {
        return Some("not a gamepad (no BTN_SOUTH button)".into());
    }
    if !(has(code::BTN_TL) || has(code::BTN_TR)) {
        return Some("no LB/RB (BTN_TL, BTN_TR): nothing to hold as the dead-man".into());
    }
    let abs = dev.supported_absolute_axes();
    for (key, a) in axes {
        if !abs.is_some_and(|s| s.contains(evdev::AbsoluteAxisCode(a))) {
            return Some(format!("no axis {a:#x} for {key} (`evtest` shows the pad's axes)"));
        }
    }
    None
}

/// The first gamepad among the input devices, by path order.
fn find_auto(axes: [(&str, u16); 2]) -> Option<(PathBuf, evdev::Device)> {
    let mut all: Vec<(PathBuf, evdev::Device)> = evdev::enumerate().collect();
    all.sort_by(|a, b| a.0.cmp(&b.0));
    all.into_iter().find(|(_, d)| lacks(d, axes).is_none())
}

/// The thread that reads the pad; stopped and joined when dropped.
pub struct PadThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Drop for PadThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Where the device came from, for errors (`gamepad.device`, `--pad`).
pub struct Source {
    /// Which pad.
    pub which: Which,
    /// The key or flag that named it.
    pub key: String,
    /// The steer and throttle axes with their keys, e.g. `("gamepad.steer_axis", 0x00)`.
    pub axes: [(&'static str, u16); 2],
}

/// Opens the pad (a named device must be there and be a gamepad now; `auto` may wait for one)
/// and starts its thread. Returns the thread and a line saying what was found.
pub fn start(src: Source, machine: PadMachine, link: PadLink) -> Result<(PadThread, String), PadError> {
    let first = match &src.which {
        Which::Path(p) => {
            let dev = evdev::Device::open(p).map_err(|error| PadError::Open {
                key: src.key.clone(),
                path: p.display().to_string(),
                hint: hint(&error),
                error,
            })?;
            if let Some(why) = lacks(&dev, src.axes) {
                return Err(PadError::NotAPad {
                    key: src.key.clone(),
                    path: p.display().to_string(),
                    name: dev.name().unwrap_or("?").to_string(),
                    why,
                });
            }
            Some((p.clone(), dev))
        }
        Which::Auto => find_auto(src.axes),
    };
    let line = match &first {
        Some((p, d)) => format!("gamepad {} ({})", p.display(), d.name().unwrap_or("?")),
        None => "gamepad: none found yet (device = \"auto\"); waiting for one (readable /dev/input/event* with a gamepad's buttons)".into(),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let st = stop.clone();
    let handle = std::thread::Builder::new()
        .name("gamepad".into())
        .spawn(move || run(src, first, machine, link, &st))
        .map_err(PadError::Thread)?;
    Ok((
        PadThread {
            stop,
            handle: Some(handle),
        },
        line,
    ))
}

/// The thread's state: the machine, the link and the clock its events are timed on.
struct Reader {
    machine: PadMachine,
    link: PadLink,
    t0: Instant,
    actions: Vec<super::machine::PadAction>,
}

impl Reader {
    fn feed(&mut self, ev: PadEvent) {
        let t = self.t0.elapsed().as_millis() as u64;
        self.actions.clear();
        self.machine.feed(t, &ev, &mut self.actions);
        if !self.actions.is_empty() {
            let now = self.link.arming().controls().now_s();
            self.link.apply(&self.actions, now);
        }
    }

    /// A pad found: connected, its axes' ranges and where they rest now.
    fn connect(&mut self, path: &Path, dev: &evdev::Device) {
        self.feed(PadEvent::Connected(format!(
            "{} ({})",
            dev.name().unwrap_or("?"),
            path.display()
        )));
        if let Ok(axes) = dev.get_absinfo() {
            let axes: Vec<_> = axes.collect();
            for (a, info) in &axes {
                let range = AxisRange {
                    min: info.minimum(),
                    max: info.maximum(),
                };
                self.feed(PadEvent::Range { code: a.0, range });
            }
            for (a, info) in axes {
                self.feed(PadEvent::Abs {
                    code: a.0,
                    value: info.value(),
                });
            }
        }
    }
}

fn run(src: Source, first: Option<(PathBuf, evdev::Device)>, machine: PadMachine, link: PadLink, stop: &AtomicBool) {
    let mut r = Reader {
        machine,
        link,
        t0: Instant::now(),
        actions: Vec::new(),
    };
    let mut dev = first;
    if let Some((p, d)) = &dev {
        r.connect(p, d);
    }
    let mut last_try = Instant::now();
    while !stop.load(Ordering::SeqCst) {
        let Some((_, d)) = dev.as_mut() else {
            std::thread::sleep(Duration::from_millis(POLL_MS as u64));
            if last_try.elapsed() >= Duration::from_millis(RETRY_MS) {
                last_try = Instant::now();
                dev = reopen(&src);
                if let Some((p, d)) = &dev {
                    r.connect(p, d);
                }
            }
            r.feed(PadEvent::Tick);
            continue;
        };
        if let Err(why) = read_some(d, &mut r) {
            dev = None;
            last_try = Instant::now();
            r.feed(PadEvent::Disconnected(why));
        } else {
            r.feed(PadEvent::Tick);
        }
    }
}

/// The pad again: the same path, or any gamepad (`auto`).
fn reopen(src: &Source) -> Option<(PathBuf, evdev::Device)> {
    match &src.which {
        Which::Path(p) => evdev::Device::open(p)
            .ok()
            .filter(|d| lacks(d, src.axes).is_none())
            .map(|d| (p.clone(), d)),
        Which::Auto => find_auto(src.axes),
    }
}

/// Waits up to [`POLL_MS`] for events and feeds them; `Err(why)`: the pad is gone.
fn read_some(d: &mut evdev::Device, r: &mut Reader) -> Result<(), String> {
    let mut fds = libc::pollfd {
        fd: d.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd, its fd owned by `d` for the whole call.
    let n = unsafe { libc::poll(&mut fds, 1, POLL_MS) };
    if n < 0 {
        let e = std::io::Error::last_os_error();
        return if e.kind() == std::io::ErrorKind::Interrupted {
            Ok(())
        } else {
            Err(format!("poll: {e}"))
        };
    }
    if n == 0 {
        return Ok(());
    }
    if fds.revents & libc::POLLIN == 0 && fds.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0 {
        return Err("the device hung up (unplugged?)".into());
    }
    let events: Vec<evdev::InputEvent> = match d.fetch_events() {
        Ok(evs) => evs.collect(),
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(()),
        Err(e) if e.raw_os_error() == Some(libc::ENODEV) => return Err("ENODEV: the pad was unplugged".into()),
        Err(e) => return Err(format!("read: {e}")),
    };
    for e in events {
        let (t, c, v) = (e.event_type().0, e.code(), e.value());
        match t {
            code::EV_KEY => r.feed(PadEvent::Key { code: c, value: v }),
            code::EV_ABS => r.feed(PadEvent::Abs { code: c, value: v }),
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::arming::Arming;
    use crate::drive::NoClock;
    use crate::health::Health;
    use crate::pad::machine::PadOptions;

    fn parts() -> (PadMachine, PadLink) {
        let arming = Arming::new(Health::new());
        (
            PadMachine::new(PadOptions::default()),
            PadLink::new(arming, Arc::new(NoClock), true),
        )
    }

    fn source(which: Which) -> Source {
        Source {
            which,
            key: "gamepad.device".into(),
            axes: [
                ("gamepad.steer_axis", code::ABS_X),
                ("gamepad.throttle_axis", code::ABS_RY),
            ],
        }
    }

    #[test]
    fn a_named_device_that_is_missing_or_no_input_device_is_an_error_naming_it() {
        let (m, l) = parts();
        let e = start(source(Which::Path("/dev/input/no-such-pad".into())), m, l)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.starts_with("gamepad.device = /dev/input/no-such-pad: cannot open") && e.contains("no such device"),
            "{e}"
        );
        let (m, l) = parts();
        let e = start(source(Which::Path("/dev/null".into())), m, l)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("/dev/null") && e.contains("not an input event device"),
            "{e}"
        );
    }

    #[test]
    fn auto_waits_for_a_pad_and_stops_when_dropped() {
        let (m, l) = parts();
        let arming = l.arming().clone();
        let (thread, line) = start(source(Which::Auto), m, l).unwrap();
        assert!(line.starts_with("gamepad"), "{line}");
        std::thread::sleep(Duration::from_millis(100));
        let t = Instant::now();
        drop(thread);
        assert!(t.elapsed() < Duration::from_millis(500), "stopped in {:?}", t.elapsed());
        assert!(!arming.is_armed());
    }
}
