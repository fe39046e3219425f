//! The serial link as the drive loop's actuators (feature `serial`): [`LinkSink`] turns the
//! gate's commands into DRIVE frames and its arming into ARM / DISARM, and tells the gate when
//! the link is down or came back ([`Connection`]).
//!
//! Rules (docs/drive.md):
//! 1. DRIVE is sent only while armed; the firmware moves nothing otherwise.
//! 2. A reconnect or a firmware reset forgets the arming: the gate is told
//!    [`Connection::Reconnected`] and disarms; nothing moves until someone arms again.
//! 3. Our own pause (a stalled camera) may let the firmware's failsafe trip (no DRIVE for its
//!    timeout): the car stood at neutral; this run armed it and still wants to drive, so the
//!    next non-neutral command arms the firmware again (a reconnect, by contrast, disarms).
//! 4. A test hook flips bits on the wire once armed (`bit_errors`, a noisy cable), reproducibly
//!    seeded; the number of bits flipped is counted.

use super::protocol::{to_permille, HelloAck, State};
use super::transport::{Link, LinkError, LinkOptions, WireFault};
use crate::control::Command;
use crate::sink::{Actuators, CommandSink, Connection, SinkError};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Why the link cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LinkOpenError {
    /// The port does not exist.
    #[error("{0}: no such serial port (is the Arduino plugged in? `ls /dev/ttyACM* /dev/ttyUSB*`)")]
    NoPort(String),
    /// Nothing answered the handshake.
    #[error("{port}: no rccar firmware answering (busy port, wrong device, or not flashed: make -C firmware flash): {error}")]
    NoFirmware {
        /// The port.
        port: String,
        /// What the transport saw.
        error: LinkError,
    },
    /// A bad test-hook value.
    #[error("--link-bit-errors {0}: must be in 0 ..< 0.5")]
    BitErrors(f64),
}

/// The serial link as actuators (see the module notes).
pub struct LinkSink {
    link: Arc<Link>,
    armed: bool,
    handshakes: u64,
    inject: Arc<AtomicBool>,
    flipped: Arc<AtomicU64>,
    /// When (loop time, s) the last ARM after a failsafe trip was queued.
    rearm_at: Option<f64>,
    /// ARMs queued after failsafe trips.
    rearms: u64,
}

/// How often (s of loop time) an ARM is asked again while the firmware still reports failsafe.
const REARM_EVERY_S: f64 = 0.1;

impl LinkSink {
    /// Opens `port`, waits up to `connect` for the firmware's handshake, and returns the sink
    /// and the firmware's answer. `bit_errors`: probability that each bit written once armed is
    /// flipped (a test hook; 0 for a real car).
    pub fn open(port: &str, bit_errors: f64, connect: Duration) -> Result<(LinkSink, HelloAck), LinkOpenError> {
        if !std::path::Path::new(port).exists() {
            return Err(LinkOpenError::NoPort(port.into()));
        }
        if !(0.0..0.5).contains(&bit_errors) {
            return Err(LinkOpenError::BitErrors(bit_errors));
        }
        let inject = Arc::new(AtomicBool::new(false));
        let flipped = Arc::new(AtomicU64::new(0));
        let wire_fault = (bit_errors > 0.0).then(|| noisy_wire(bit_errors, inject.clone(), flipped.clone()));
        let link = Arc::new(Link::open(
            port,
            LinkOptions {
                rearm_after_reconnect: false,
                wire_fault,
                ..LinkOptions::default()
            },
        ));
        let hello = link.wait_connected(connect).map_err(|error| LinkOpenError::NoFirmware {
            port: port.into(),
            error,
        })?;
        let handshakes = link.stats().handshakes;
        Ok((
            LinkSink {
                link,
                armed: false,
                handshakes,
                inject,
                flipped,
                rearm_at: None,
                rearms: 0,
            },
            hello,
        ))
    }

    /// The link (e.g. for an emergency hook that sends neutral from another thread).
    pub fn link(&self) -> Arc<Link> {
        self.link.clone()
    }

    /// ARMs queued so far to leave a failsafe trip (rule 3).
    pub fn failsafe_rearms(&self) -> u64 {
        self.rearms
    }

    /// Bits flipped so far by the `bit_errors` test hook.
    pub fn bits_flipped(&self) -> Arc<AtomicU64> {
        self.flipped.clone()
    }
}

/// The test hook's noise: xorshift64*, each bit flipped with probability `ber` while `on`.
fn noisy_wire(ber: f64, on: Arc<AtomicBool>, flipped: Arc<AtomicU64>) -> WireFault {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    Box::new(move |bytes: &mut Vec<u8>| {
        if !on.load(Ordering::SeqCst) {
            return;
        }
        for b in bytes.iter_mut() {
            for bit in 0..8 {
                state ^= state >> 12;
                state ^= state << 25;
                state ^= state >> 27;
                let u = (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
                if u < ber {
                    *b ^= 1 << bit;
                    flipped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    })
}

impl CommandSink for LinkSink {
    fn send(&mut self, c: Command, t: f64) -> Result<Command, SinkError> {
        if !self.armed {
            return Ok(Command::NEUTRAL);
        }
        // Rule 3: the firmware's failsafe tripped during our own pause. The ARM is queued, not
        // awaited (the loop must not block on a busy or noisy link); the DRIVE below follows it
        // on the wire. Asked again at most every REARM_EVERY_S while the telemetry still says
        // failsafe (a lost ARM, or a telemetry older than the ARM).
        if let Some((tm, _)) = self.link.telemetry() {
            let due = self.rearm_at.is_none_or(|t0| t - t0 >= REARM_EVERY_S || t < t0);
            if tm.state == State::Failsafe && c != Command::NEUTRAL && due {
                self.link.request_arm();
                self.rearm_at = Some(t);
                self.rearms += 1;
            }
        }
        self.link.drive(to_permille(c.steer), to_permille(c.throttle));
        Ok(c)
    }

    fn stop(&mut self) -> Result<(), SinkError> {
        self.disarm()
    }
}

impl Actuators for LinkSink {
    fn arm(&mut self) -> Result<(), SinkError> {
        self.link.arm().map_err(|e| SinkError(e.to_string()))?;
        self.handshakes = self.link.stats().handshakes;
        self.armed = true;
        self.inject.store(true, Ordering::SeqCst);
        Ok(())
    }

    fn disarm(&mut self) -> Result<(), SinkError> {
        self.inject.store(false, Ordering::SeqCst);
        self.armed = false;
        self.link.drive(0, 0);
        if !self.link.is_connected() {
            // Nobody to tell: the firmware's failsafe holds a car whose link is gone.
            return Ok(());
        }
        self.link.disarm().map_err(|e| SinkError(e.to_string()))
    }

    fn connection(&mut self) -> Connection {
        if !self.link.is_connected() {
            self.armed = false;
            let e = self.link.last_error();
            return Connection::Down(if e.is_empty() { "not connected".into() } else { e });
        }
        let h = self.link.stats().handshakes;
        if h != self.handshakes {
            self.handshakes = h;
            self.armed = false;
            return Connection::Reconnected;
        }
        Connection::Up
    }
}
