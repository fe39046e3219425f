//! Frames from a camera program's stdout: the Raspberry Pi camera module through `rpicam-vid`
//! (`--camera picam:0`, [`rpicam`]) and any command that writes raw frames (`--camera
//! 'pipe:FORMAT:COMMAND'`: ffmpeg, GStreamer, a phone stream, the simulator itself).
//!
//! ```text
//!  camera program ──stdout pipe──► reader thread ──► FrameReader (cut, bounded, convert)
//!  (own process group,                   │               │
//!   killed with rccar)                   │       wall clock: CaptureSource — newest frame only,
//!                                        │       stall → neutral (as the V4L2 camera)
//!                                        └──►    lock-step: every frame in order (a replay)
//! ```
//!
//! - [`child`]: the program as a child process, ended on every way out (its own process group,
//!   SIGTERM then SIGKILL on drop, the kernel's parent-death signal if rccar is killed).
//! - [`format`]: the frame formats (rgb24, yuv420, yuvj420, mjpeg), each frame cut from the
//!   stream with a stated bound; garbage or a short frame is an unusable frame, never a panic.
//! - On the wall clock ([`open_wallclock`]): the car. A frozen program is a stall after
//!   [`stall_time`] (neutral sent, the loop waits); when it continues, driving resumes. The
//!   program exiting ends the source as a fault (the car stops; rccar does not restart it).
//! - Lock-step ([`open_lockstep`]): `rccar replay 'pipe:…'` takes every frame, in order, at
//!   the configured fps (frame *i* at *i*/fps seconds), as a folder of frames is replayed.
//! - `rccar camera check` builds a session on these sources: [`crate::session::camera_check`].

pub mod child;
pub mod export;
pub mod format;
pub mod rpicam;

use crate::capture::{CaptureSource, GrabError, Grabber};
use crate::drive::{Clock, StopSignal};
use crate::source::{Frame, FrameError, FrameSource};
use child::Producer;
use format::{FrameReader, Item, RawFormat};
use image::RgbImage;
use std::process::ChildStdout;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How long a camera program gets to deliver its first frame (rpicam-vid needs 1–3 s to
/// start on a Pi).
pub const START_TIMEOUT: Duration = Duration::from_secs(10);

/// No frame for this long is a stall: 0.4 s, or 2.5 frame periods at a low fps. Below the
/// V4L2 camera's 0.5 s so that neutral goes out within 0.5 s of a freeze even when the freeze
/// comes while the loop is still busy with the last frame.
pub fn stall_time(fps: f64) -> Duration {
    Duration::from_secs_f64(0.4f64.max(2.5 / fps.max(1.0)))
}

/// A camera program and how to read it.
#[derive(Debug, Clone, PartialEq)]
pub struct PipeCommand {
    /// Program and arguments (no shell; `sh -c '…'` when one is needed).
    pub argv: Vec<String>,
    /// The frames' format.
    pub format: RawFormat,
    /// How messages name it (`pipe`, `picam:0`).
    pub label: String,
}

impl PipeCommand {
    /// `COMMAND` of `pipe:FORMAT:COMMAND`, split as a POSIX shell would split it (quotes,
    /// backslashes; no variables, globs or pipes: write `sh -c '…'` for those).
    pub fn parse(format: RawFormat, command: &str) -> Result<PipeCommand, String> {
        let argv = shlex::split(command).ok_or_else(|| format!("`{command}`: unbalanced quotes"))?;
        if argv.is_empty() {
            return Err("an empty command".into());
        }
        Ok(PipeCommand {
            argv,
            format,
            label: "pipe".into(),
        })
    }

    /// The command as one line a shell would read back.
    pub fn line(&self) -> String {
        shlex::try_join(self.argv.iter().map(String::as_str)).unwrap_or_else(|_| self.argv.join(" "))
    }
}

type Cell = Arc<Mutex<Option<Arc<Producer>>>>;

fn cell_pid(cell: &Cell) -> Option<u32> {
    cell.lock().unwrap_or_else(|e| e.into_inner()).as_ref().map(|p| p.pid())
}

fn cell_stop(cell: &Cell) {
    let p = cell.lock().unwrap_or_else(|e| e.into_inner()).take();
    if let Some(p) = p {
        p.stop();
    }
}

/// The capture thread's side: starts the program once, reads its frames.
struct PipeGrabber {
    cmd: PipeCommand,
    size: (u32, u32),
    cell: Cell,
    closed: Arc<AtomicBool>,
    reader: Option<FrameReader<ChildStdout>>,
    started: bool,
}

impl PipeGrabber {
    fn ended(&mut self) -> GrabError {
        self.reader = None;
        let p = self.cell.lock().unwrap_or_else(|e| e.into_inner()).take();
        GrabError::Fatal(match p {
            // A short grace: the loop is waiting (and reports a stall meanwhile).
            Some(p) => format!("{}: {}", self.cmd.label, p.ended_line(Duration::from_millis(200))),
            None => format!("{}: closed", self.cmd.label),
        })
    }
}

impl Grabber for PipeGrabber {
    fn open(&mut self) -> Result<(), GrabError> {
        if self.closed.load(Ordering::SeqCst) || self.started {
            return Err(GrabError::Fatal(format!("{}: closed", self.cmd.label)));
        }
        self.started = true;
        let (p, out) =
            Producer::spawn(&self.cmd.argv).map_err(|e| GrabError::Fatal(format!("{}: {e}", self.cmd.label)))?;
        *self.cell.lock().unwrap_or_else(|e| e.into_inner()) = Some(p);
        // Closed while it started: end it at once.
        if self.closed.load(Ordering::SeqCst) {
            cell_stop(&self.cell);
        }
        self.reader = Some(FrameReader::new(out, self.cmd.format, self.size.0, self.size.1));
        Ok(())
    }

    fn grab(&mut self) -> Result<RgbImage, GrabError> {
        let Some(r) = self.reader.as_mut() else {
            return Err(self.ended());
        };
        match r.next_item() {
            Ok(Item::Frame(img)) => Ok(img),
            Ok(Item::Bad(why)) => Err(GrabError::Bad(why)),
            Ok(Item::End) | Err(_) => Err(self.ended()),
        }
    }

    fn close(&mut self) {
        self.reader = None;
        cell_stop(&self.cell);
    }

    fn label(&self) -> String {
        self.cmd.label.clone()
    }
}

/// A camera program on the wall clock: newest frame only, stall detection (see the module
/// notes). Dropping it ends the program.
pub struct PipeSource {
    capture: CaptureSource,
    cell: Cell,
    closed: Arc<AtomicBool>,
}

/// Starts `cmd` on a capture thread and waits for its first frame (up to [`START_TIMEOUT`],
/// or until `stop` is raised): a program that cannot start, exits or stays silent is an error
/// naming it, with what it wrote to stderr, before the car does anything.
pub fn open_wallclock(
    cmd: PipeCommand,
    size: (u32, u32),
    fps: f64,
    clock: Arc<dyn Clock + Send + Sync>,
    stop: &StopSignal,
) -> Result<PipeSource, String> {
    let cell: Cell = Arc::new(Mutex::new(None));
    let closed = Arc::new(AtomicBool::new(false));
    let (c, q, k) = (cell.clone(), closed.clone(), cmd.clone());
    let label = cmd.label.clone();
    let capture = CaptureSource::start(
        move || {
            Box::new(PipeGrabber {
                cmd: k,
                size,
                cell: c,
                closed: q,
                reader: None,
                started: false,
            })
        },
        label.clone(),
        size,
        clock,
        stall_time(fps),
        Duration::from_millis(100),
    );
    let src = PipeSource { capture, cell, closed };
    match src.capture.wait_first(START_TIMEOUT, || stop.is_set()) {
        Ok(()) => Ok(src),
        Err(Some(why)) => Err(why),
        Err(None) if stop.is_set() => Err(format!("{label}: interrupted while waiting for the first frame")),
        Err(None) => {
            let tail = src
                .cell
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .as_ref()
                .map(|p| p.stderr_tail())
                .unwrap_or_default();
            Err(format!(
                "{label}: no frame from `{}` in {} s{}",
                cmd.line(),
                START_TIMEOUT.as_secs(),
                if tail.is_empty() {
                    String::new()
                } else {
                    format!("; it said: {tail}")
                }
            ))
        }
    }
}

impl PipeSource {
    /// The program's process id (its process group id too), while it runs.
    pub fn pid(&self) -> Option<u32> {
        cell_pid(&self.cell)
    }

    /// Unusable frames so far (garbage, short frames, JPEGs that do not decode).
    pub fn bad_frames(&self) -> u64 {
        self.capture.bad_frames()
    }

    /// Frames the program delivered that the loop never saw (newest frame only).
    pub fn dropped(&self) -> u64 {
        self.capture.dropped()
    }
}

impl FrameSource for PipeSource {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        self.capture.next_frame()
    }
    fn fatal(&self) -> Option<String> {
        self.capture.fatal_reason()
    }
}

impl Drop for PipeSource {
    fn drop(&mut self) {
        self.closed.store(true, Ordering::SeqCst);
        cell_stop(&self.cell);
    }
}

enum Msg {
    Item(Item),
    /// The stream ended; `Some`: the program failed (its exit status and stderr).
    Ended(Option<String>),
}

/// A camera program read lock-step: every frame in order, frame *i* at *i*/fps seconds (see
/// the module notes). Dropping it ends the program.
pub struct PipeLockStep {
    rx: Receiver<Msg>,
    cell: Cell,
    label: String,
    size: (u32, u32),
    fps: f64,
    index: u64,
    stop: StopSignal,
    fatal: Option<String>,
    done: bool,
}

/// Starts `cmd` for a lock-step run (a replay). `stop`: while waiting for a frame, a raised
/// stop signal makes the source report a stall, so the loop sees the stop at once.
pub fn open_lockstep(cmd: PipeCommand, size: (u32, u32), fps: f64, stop: StopSignal) -> Result<PipeLockStep, String> {
    let cell: Cell = Arc::new(Mutex::new(None));
    let (tx, rx) = std::sync::mpsc::sync_channel::<Msg>(2);
    let (started_tx, started_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    let c = cell.clone();
    let k = cmd.clone();
    std::thread::Builder::new()
        .name("rccar-cam-read".into())
        .spawn(move || read_all(k, size, c, tx, started_tx))
        .map_err(|e| format!("{}: no reader thread: {e}", cmd.label))?;
    started_rx
        .recv()
        .unwrap_or_else(|_| Err(format!("{}: the reader thread ended", cmd.label)))?;
    Ok(PipeLockStep {
        rx,
        cell,
        label: cmd.label,
        size,
        fps: if fps.is_finite() && fps > 0.0 { fps } else { 30.0 },
        index: 0,
        stop,
        fatal: None,
        done: false,
    })
}

/// The reader thread of a lock-step source: spawns the program (so that its parent-death
/// signal is tied to this thread), then hands on every item, blocking while the loop is busy.
fn read_all(
    cmd: PipeCommand,
    size: (u32, u32),
    cell: Cell,
    tx: SyncSender<Msg>,
    started: std::sync::mpsc::Sender<Result<(), String>>,
) {
    let (p, out) = match Producer::spawn(&cmd.argv) {
        Ok(x) => x,
        Err(e) => {
            let _ = started.send(Err(format!("{}: {e}", cmd.label)));
            return;
        }
    };
    *cell.lock().unwrap_or_else(|e| e.into_inner()) = Some(p.clone());
    let _ = started.send(Ok(()));
    let mut reader = FrameReader::new(out, cmd.format, size.0, size.1);
    loop {
        match reader.next_item() {
            Ok(Item::End) | Err(_) => break,
            Ok(item) => {
                if tx.send(Msg::Item(item)).is_err() {
                    return;
                }
            }
        }
    }
    // The end of the stream: the program should be exiting; its status decides.
    let line = p.ended_line(Duration::from_secs(5));
    let failed = !p.status().is_some_and(|s| s.success());
    let _ = tx.send(Msg::Ended(failed.then(|| format!("{}: {line}", cmd.label))));
}

impl PipeLockStep {
    /// The program's process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        cell_pid(&self.cell)
    }
}

impl FrameSource for PipeLockStep {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        if self.done {
            return None;
        }
        loop {
            let msg = match self.rx.recv_timeout(Duration::from_millis(100)) {
                Ok(m) => m,
                Err(RecvTimeoutError::Timeout) if self.stop.is_set() => {
                    return Some(Err(FrameError::stalled(
                        self.index,
                        self.label.clone(),
                        "stopping while waiting for a frame",
                    )));
                }
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => {
                    self.done = true;
                    return None;
                }
            };
            let i = self.index;
            let name = format!("{}_{i:06}", self.label.replace(':', ""));
            return match msg {
                Msg::Item(Item::Frame(img)) if img.dimensions() != self.size => {
                    self.fatal = Some(format!(
                        "{}: delivers {}×{} frames, the configuration asks for {}×{} ([camera] width/height)",
                        self.label,
                        img.width(),
                        img.height(),
                        self.size.0,
                        self.size.1
                    ));
                    self.done = true;
                    None
                }
                Msg::Item(Item::Frame(img)) => {
                    self.index += 1;
                    Some(Ok(Frame::new(i, i as f64 / self.fps, name, img)))
                }
                Msg::Item(Item::Bad(why)) => {
                    self.index += 1;
                    Some(Err(FrameError::bad(i, name, why)))
                }
                Msg::Item(Item::End) => continue,
                Msg::Ended(failed) => {
                    self.fatal = failed;
                    self.done = true;
                    None
                }
            };
        }
    }

    fn fatal(&self) -> Option<String> {
        self.fatal.clone()
    }
}

impl Drop for PipeLockStep {
    fn drop(&mut self) {
        cell_stop(&self.cell);
    }
}
