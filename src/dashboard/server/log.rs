//! The server's printing: the handlers, the hub and the watchdog queue their lines ([`Log`])
//! for one logger thread ([`start_logger`]), so no request ever waits on stdout; notes for
//! the telemetry go to the loop's inbox from there. Lines go out through [`out`] and [`err`],
//! which never panic: a closed terminal (SIGHUP, a reader that went away) must not stop the
//! car. Imports none of the server's modules.

use crate::dashboard::messages::{Control, ControlSender};
use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};

/// A line for stdout or stderr, or a note for the telemetry.
pub enum Msg {
    /// stdout.
    Out(String),
    /// stderr.
    Err(String),
    /// An event in the telemetry record of the next frame.
    Note(String),
}

/// The handlers' way to print: a bounded queue to the logger thread (never waits; a full
/// queue drops the line and counts it).
pub struct Log {
    tx: SyncSender<Msg>,
    /// Lines dropped because the queue was full (stdout blocked).
    pub dropped: AtomicU64,
}

impl Log {
    /// The queue and its receiving end (for [`start_logger`]).
    pub fn new() -> (Log, Receiver<Msg>) {
        let (tx, rx) = sync_channel(256);
        (
            Log {
                tx,
                dropped: AtomicU64::new(0),
            },
            rx,
        )
    }
    /// Queues `m`.
    pub fn send(&self, m: Msg) {
        if self.tx.try_send(m).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
    /// A line on stderr.
    pub fn err(&self, s: String) {
        self.send(Msg::Err(s));
    }
}

/// Prints the queued lines and hands the notes to the loop; ends with the server.
pub fn start_logger(rx: Receiver<Msg>, tx: ControlSender) -> std::io::Result<()> {
    std::thread::Builder::new().name("dash-log".into()).spawn(move || {
        for m in rx {
            match m {
                Msg::Out(s) => out(&s),
                Msg::Err(s) => err(&s),
                Msg::Note(s) => {
                    tx.send(Control::Note(s));
                }
            }
        }
    })?;
    Ok(())
}

/// One line on stdout; a closed stdout is not an error (the line is dropped).
pub fn out(line: &str) {
    let mut o = std::io::stdout().lock();
    let _ = writeln!(o, "{line}");
    let _ = o.flush();
}

/// One line on stderr; a closed stderr is not an error.
pub fn err(line: &str) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}
