//! Test support: starts the simavr harness (`firmware/build/rccar_sim`) on the real firmware
//! .elf, each instance on its own pty link path, and collects what it reports (pulse widths on
//! D9/D10 and host frames at the UART, in simulated µs). Shared by tests/link_hil.rs,
//! tests/drive_fil.rs and benches/link_bench.rs.
//!
//! Waiting: the emulator runs at about wall-clock speed, slower on a busy machine. A test
//! never sleeps a fixed wall-clock time to let the firmware do something: it waits for the
//! report to show it ([`Sim::wait_until`]) or for the firmware's own clock to pass a time
//! ([`Sim::now_us`], [`Sim::wait_sim_us`]: the harness's `mark` command), each with a generous
//! wall-clock deadline.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// One line of the harness's report.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A pulse width change on a pin: (true = servo D9, false = ESC D10), width µs, rise time µs.
    Pulse { servo: bool, width_us: f64, t_us: f64 },
    /// A host frame delivered to the UART: id, seq, time µs.
    Rx { id: u8, seq: u8, t_us: f64 },
    /// Emulator reset at time µs.
    Reset { t_us: f64 },
    /// The CPU was sent into a `cli; rjmp .` loop at time µs (a hung firmware).
    Hang { t_us: f64 },
    /// The simulated time µs when the harness handled a `mark` from stdin.
    Mark { t_us: f64 },
}

/// How long a wait for the emulator may take on a busy machine before the test fails.
pub const SIM_DEADLINE: Duration = Duration::from_secs(60);

/// Builds the firmware and the harness once per test binary (`make -C firmware all sim`).
pub fn build_firmware() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware");
            let out = Command::new("make")
                .arg("-C")
                .arg(&dir)
                .args(["all", "sim"])
                .output()
                .expect("make");
            assert!(
                out.status.success(),
                "make -C firmware failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            dir.join("build")
        })
        .clone()
}

/// A running emulator. Killed on drop.
/// The priority the car's service gives rccar (docs/rccar.service: `Nice=-5`).
pub const SERVICE_NICE: i32 = -5;

/// The thread that starts the emulator is the host side of the link (a test's own `Link`, or
/// the thread that spawns `rccar`): it and the threads it starts from now on (the link's reader,
/// the report reader) run at the car service's priority, where the test may raise it (root,
/// CAP_SYS_NICE); elsewhere nothing changes. On a machine whose cores are all busy, a host at
/// normal priority was measured late by more than the firmware's 250 ms failsafe, so the
/// firmware (rightly) tripped again between a test's ARM and its DRIVE.
pub fn host_as_the_car() {
    // SAFETY: setpriority on the calling thread (Linux: PRIO_PROCESS with 0 is this thread).
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, SERVICE_NICE);
    }
}

/// `cmd` (an `rccar` the test starts against the emulator) runs at the car service's priority
/// where allowed, as [`host_as_the_car`]; every thread of it inherits the priority.
pub fn as_the_car(cmd: &mut Command) -> &mut Command {
    use std::os::unix::process::CommandExt;
    // SAFETY: setpriority is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            libc::setpriority(libc::PRIO_PROCESS, 0, SERVICE_NICE);
            Ok(())
        })
    }
}

pub struct Sim {
    child: Child,
    stdin: Mutex<ChildStdin>,
    /// The pty path to open (a symlink of our own).
    pub tty: String,
    events: Arc<Mutex<Vec<Event>>>,
}

impl Sim {
    /// Starts the harness with its pty linked at `tty`.
    pub fn start_at(tty: &str) -> Sim {
        Self::start_logged(tty, None)
    }

    /// Like [`Sim::start_at`], also appending every report line to `log` (flushed per line),
    /// the file `rccar drive --pwm-log` follows.
    pub fn start_logged(tty: &str, log: Option<&Path>) -> Sim {
        host_as_the_car();
        let mut log = log.map(|p| {
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .expect("open the pulse log")
        });
        let build = build_firmware();
        let mut child = Command::new(build.join("rccar_sim"))
            .arg(build.join("rccar_fw.elf"))
            .args(["--link", tty, "--sniff"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start rccar_sim");
        let stdin = child.stdin.take().expect("stdin");
        let stdout = child.stdout.take().expect("stdout");
        let events = Arc::new(Mutex::new(Vec::new()));
        let (tx, rx) = std::sync::mpsc::channel();
        let ev = events.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Some(f) = log.as_mut() {
                    let _ = writeln!(f, "{line}");
                    let _ = f.flush();
                }
                let t: Vec<&str> = line.split_whitespace().collect();
                let e = match t.as_slice() {
                    ["PTY", p] => {
                        let _ = tx.send(p.to_string());
                        continue;
                    }
                    ["PULSE", pin, w, at] => Event::Pulse {
                        servo: *pin == "servo",
                        width_us: w.parse().unwrap_or(f64::NAN),
                        t_us: at.parse().unwrap_or(f64::NAN),
                    },
                    ["RX", id, seq, at] => Event::Rx {
                        id: id.parse().unwrap_or(0),
                        seq: seq.parse().unwrap_or(0),
                        t_us: at.parse().unwrap_or(f64::NAN),
                    },
                    ["RESET", at] => Event::Reset {
                        t_us: at.parse().unwrap_or(f64::NAN),
                    },
                    ["HANG", at] => Event::Hang {
                        t_us: at.parse().unwrap_or(f64::NAN),
                    },
                    ["MARK", at] => Event::Mark {
                        t_us: at.parse().unwrap_or(f64::NAN),
                    },
                    _ => continue,
                };
                ev.lock().unwrap().push(e);
            }
        });
        let tty = rx.recv_timeout(SIM_DEADLINE).expect("harness printed no PTY line");
        Sim {
            child,
            stdin: Mutex::new(stdin),
            tty,
            events,
        }
    }

    /// Starts the harness on a fresh path of its own under /tmp.
    pub fn start(name: &str) -> Sim {
        Sim::start_at(&Self::fresh_path(name))
    }

    /// A pty link path no other test uses.
    pub fn fresh_path(name: &str) -> String {
        let dir = std::env::temp_dir().join(format!("rccar-hil-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        dir.join(format!("{name}.tty")).to_string_lossy().into_owned()
    }

    /// Everything reported so far.
    pub fn events(&self) -> Vec<Event> {
        self.events.lock().unwrap().clone()
    }

    /// Pulse widths (µs) of one pin, with their rise times (µs), in order.
    pub fn pulses(&self, servo: bool) -> Vec<(f64, f64)> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::Pulse {
                    servo: s,
                    width_us,
                    t_us,
                } if s == servo && width_us > 400.0 => Some((width_us, t_us)),
                _ => None,
            })
            .collect()
    }

    /// The latest pulse width on a pin.
    pub fn last_width(&self, servo: bool) -> Option<f64> {
        self.pulses(servo).last().map(|p| p.0)
    }

    /// Waits until `pred` holds for the events, calling `tick` every 20 ms meanwhile.
    pub fn wait_until(&self, timeout: Duration, mut tick: impl FnMut(), pred: impl Fn(&Sim) -> bool) -> bool {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if pred(self) {
                return true;
            }
            tick();
            std::thread::sleep(Duration::from_millis(20));
        }
        pred(self)
    }

    /// Hangs the firmware (interrupts off, endless loop): only the watchdog can save it.
    pub fn hang(&mut self) {
        self.command("hang");
    }

    fn command(&self, line: &str) {
        let mut s = self.stdin.lock().unwrap();
        let _ = writeln!(s, "{line}");
        let _ = s.flush();
    }

    /// The MARK times reported so far (simulated µs).
    fn marks(&self) -> Vec<f64> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::Mark { t_us } => Some(t_us),
                _ => None,
            })
            .collect()
    }

    /// The firmware's clock now (simulated µs): asks the harness (`mark`) and waits for its
    /// answer. Called right after something the test did (a kill, a write), it bounds in the
    /// firmware's time when that happened: no earlier than the answer.
    pub fn now_us(&self) -> f64 {
        let n = self.marks().len();
        self.command("mark");
        let end = Instant::now() + SIM_DEADLINE;
        loop {
            if let Some(&t) = self.marks().get(n) {
                return t;
            }
            assert!(
                Instant::now() < end,
                "the harness did not answer `mark` in {SIM_DEADLINE:?}"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Waits until the firmware's clock has passed `t_us` (simulated µs), however slowly the
    /// emulator runs on a busy machine (fails after [`SIM_DEADLINE`] of wall-clock time).
    /// Returns the simulated time reached.
    pub fn wait_sim_us(&self, t_us: f64) -> f64 {
        let end = Instant::now() + SIM_DEADLINE;
        loop {
            let now = self.now_us();
            if now >= t_us {
                return now;
            }
            assert!(
                Instant::now() < end,
                "the emulator did not reach {t_us:.0} µs in {SIM_DEADLINE:?} (at {now:.0} µs)"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The harness's process id (to kill it as a pulled plug would).
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Simulated times (µs) at which the UART received host frames with this id.
    pub fn rx_times(&self, id: u8) -> Vec<f64> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::Rx { id: i, t_us, .. } if i == id => Some(t_us),
                _ => None,
            })
            .collect()
    }

    /// Resets the emulated AVR (as a reset button would).
    pub fn reset(&mut self) {
        self.command("reset");
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.tty);
    }
}
