//! The host end of the serial link over a real port or the emulator's pty (feature `serial`).
//!
//! One I/O thread owns the port. It (1) opens the port, with exponential back-off while it is
//! missing; (2) handshakes (HELLO → HELLO_ACK, protocol version checked); (3) re-arms when the
//! application had armed; (4) then loops: writes queued requests and the *newest* DRIVE only
//! (a slot that each [`Link::drive`] overwrites, so a stale command is never queued behind a
//! newer one, a DRIVE older than `max_drive_age` is dropped rather than sent late, and nothing
//! is ever repeated by the link itself: if the application stops, the firmware's failsafe stops
//! the car), reads with a short timeout and decodes byte by byte.
//! A read or write error, or 500 ms without telemetry, closes the port and goes back to (1); a
//! firmware reset (uptime going backwards, or telemetry without the handshake flag) goes back
//! to (2). Dropping the [`Link`] writes DISARM and a neutral DRIVE before the thread ends.
//!
//! This adapter is the one place of the library that reads the clock (timeouts, back-off).
//! Times are in ms unless a `Duration`; steer/throttle in per-mille.

use super::protocol::{self, status, Decoder, DecoderCounters, Frame, HelloAck, LinkConfig, Message, Telemetry};
use crate::control::Command;
use crate::sink::{CommandSink, SinkError};
use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What can go wrong on the link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// No answer in time (port missing, emulator not running, wrong device...).
    #[error("{port}: no {what} within {ms} ms{detail}")]
    Timeout {
        /// The port path.
        port: String,
        /// What was awaited.
        what: &'static str,
        /// How long, ms.
        ms: u128,
        /// The last I/O error seen, if any.
        detail: String,
    },
    /// The firmware answered with a status other than OK.
    #[error("{port}: firmware refused {what}: status {code} {}", status::name(*.code))]
    Refused {
        /// The port path.
        port: String,
        /// The request.
        what: &'static str,
        /// The status code.
        code: u8,
    },
}

/// Fault injection on the host → firmware wire (tests only): called with each encoded frame
/// before it is written, may flip bits in it.
pub type WireFault = Box<dyn FnMut(&mut Vec<u8>) + Send>;

/// How many times an idempotent request ([`Link::arm`], [`Link::get_config`],
/// [`Link::set_config`]) is asked before the link gives up on one that gets no answer.
pub const IDEMPOTENT_ATTEMPTS: u32 = 3;

/// Transport settings.
pub struct LinkOptions {
    /// Baud rate (the firmware uses 115200).
    pub baud: u32,
    /// How long a request waits for its answer.
    pub reply_timeout: Duration,
    /// First reconnect delay; doubles up to `backoff_max`.
    pub backoff_min: Duration,
    /// Longest reconnect delay.
    pub backoff_max: Duration,
    /// No telemetry for this long → the port is considered dead and reopened.
    pub silence_timeout: Duration,
    /// A DRIVE not written within this age (e.g. while the port was gone) is discarded, never
    /// sent late: the application must send a fresh one.
    pub max_drive_age: Duration,
    /// Optional fault injection (tests).
    pub wire_fault: Option<WireFault>,
    /// After a reconnect or a firmware reset, arm again if the application had armed (`true`,
    /// the bench tool's behaviour) or stay disarmed until the application arms again (`false`:
    /// `rccar drive`, where a car that lost its link must not drive off on its own).
    pub rearm_after_reconnect: bool,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            baud: 115_200,
            reply_timeout: Duration::from_millis(300),
            backoff_min: Duration::from_millis(50),
            backoff_max: Duration::from_millis(1000),
            silence_timeout: Duration::from_millis(500),
            max_drive_age: Duration::from_millis(100),
            wire_fault: None,
            rearm_after_reconnect: true,
        }
    }
}

/// Counters of the host side.
#[derive(Debug, Clone, Copy, Default)]
pub struct LinkStats {
    /// Successful port opens after the first.
    pub reconnects: u64,
    /// Successful handshakes.
    pub handshakes: u64,
    /// Firmware resets noticed (uptime backwards or handshake flag gone).
    pub firmware_resets: u64,
    /// Frames written.
    pub tx_frames: u64,
    /// DRIVEs written.
    pub drives_sent: u64,
    /// DRIVEs overwritten by a newer one before they could be written.
    pub drives_superseded: u64,
    /// DRIVEs discarded because they were older than `max_drive_age` when the port was ready.
    pub drives_expired: u64,
    /// The host decoder's counters (firmware → host direction).
    pub rx: DecoderCounters,
    /// Telemetry frames received.
    pub telemetry: u64,
}

#[derive(Debug, Clone, Copy)]
enum Reply {
    Status(u8),
    Telemetry(Telemetry),
    Config(u8, LinkConfig),
}

/// The ticket of a request nobody waits for ([`Link::request_arm`]): its answer is not kept.
const UNAWAITED: u64 = u64::MAX;

#[derive(Default)]
struct Inner {
    drive: Option<(Message, Instant)>,
    requests: VecDeque<(u64, Message)>,
    /// (seq sent, id, ticket) awaiting an answer
    pending: Vec<(u8, u8, u64)>,
    replies: HashMap<u64, (Reply, Instant)>,
    sent_at: HashMap<u64, Instant>,
    next_ticket: u64,
    want_armed: bool,
    telemetry: Option<Telemetry>,
    telemetry_log: Vec<Telemetry>,
    hello: Option<HelloAck>,
    connected: bool,
    shutdown: bool,
    stats: LinkStats,
    last_error: String,
}

struct Shared {
    inner: Mutex<Inner>,
    cv: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        // a panic in the I/O thread must not stop the application from disarming
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The serial link to the firmware. Cheap to share behind `&`; dropping it disarms.
pub struct Link {
    port: String,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    reply_timeout: Duration,
}

impl Link {
    /// Starts the I/O thread on `port` (a device or pty path). Returns at once; see
    /// [`Link::wait_connected`].
    pub fn open(port: &str, options: LinkOptions) -> Link {
        let shared = Arc::new(Shared {
            inner: Mutex::new(Inner::default()),
            cv: Condvar::new(),
        });
        let reply_timeout = options.reply_timeout;
        let s = shared.clone();
        let p = port.to_string();
        let thread = std::thread::Builder::new()
            .name("rccar-link".into())
            .spawn(move || io_thread(&p, options, &s))
            .ok();
        Link {
            port: port.to_string(),
            shared,
            thread,
            reply_timeout,
        }
    }

    /// The port path.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// Waits until the handshake is done; returns the firmware's HELLO_ACK.
    pub fn wait_connected(&self, timeout: Duration) -> Result<HelloAck, LinkError> {
        let deadline = Instant::now() + timeout;
        let mut g = self.shared.lock();
        loop {
            if let (true, Some(h)) = (g.connected, g.hello) {
                if h.status != status::OK {
                    return Err(LinkError::Refused {
                        port: self.port.clone(),
                        what: "HELLO",
                        code: h.status,
                    });
                }
                return Ok(h);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.timeout(&g, "handshake", timeout));
            }
            g = self
                .shared
                .cv
                .wait_timeout(g, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    fn timeout(&self, g: &Inner, what: &'static str, t: Duration) -> LinkError {
        LinkError::Timeout {
            port: self.port.clone(),
            what,
            ms: t.as_millis(),
            detail: if g.last_error.is_empty() {
                String::new()
            } else {
                format!(" (last error: {})", g.last_error)
            },
        }
    }

    /// Whether the port is open and the handshake done.
    pub fn is_connected(&self) -> bool {
        self.shared.lock().connected
    }

    /// The last I/O error or timeout seen by the I/O thread (empty when none): why the link
    /// is down.
    pub fn last_error(&self) -> String {
        self.shared.lock().last_error.clone()
    }

    /// Sets the newest DRIVE (per-mille). It replaces any DRIVE not yet written.
    pub fn drive(&self, steer: i16, throttle: i16) {
        let mut g = self.shared.lock();
        if g.drive.is_some() {
            g.stats.drives_superseded += 1;
        }
        g.drive = Some((Message::Drive { steer, throttle }, Instant::now()));
        drop(g);
        self.shared.cv.notify_all();
    }

    fn request(&self, msg: Message, what: &'static str) -> Result<(Reply, Duration), LinkError> {
        let mut g = self.shared.lock();
        let ticket = g.next_ticket;
        g.next_ticket += 1;
        g.requests.push_back((ticket, msg));
        self.shared.cv.notify_all();
        let deadline = Instant::now() + self.reply_timeout;
        loop {
            if let Some((r, at)) = g.replies.remove(&ticket) {
                let sent = g.sent_at.remove(&ticket).unwrap_or(at);
                return Ok((r, at.saturating_duration_since(sent)));
            }
            let now = Instant::now();
            if now >= deadline {
                g.requests.retain(|(t, _)| *t != ticket);
                g.pending.retain(|p| p.2 != ticket);
                g.sent_at.remove(&ticket);
                return Err(self.timeout(&g, what, self.reply_timeout));
            }
            g = self
                .shared
                .cv
                .wait_timeout(g, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    fn expect_ok(&self, msg: Message, what: &'static str) -> Result<(), LinkError> {
        match self.request(msg, what)?.0 {
            Reply::Status(status::OK) => Ok(()),
            Reply::Status(code) => Err(LinkError::Refused {
                port: self.port.clone(),
                what,
                code,
            }),
            _ => Err(LinkError::Refused {
                port: self.port.clone(),
                what,
                code: status::UNKNOWN_MESSAGE,
            }),
        }
    }

    /// Queues an ARM without waiting for its answer, so a control loop never blocks on it:
    /// arming again after a failsafe trip while the loop goes on sending DRIVEs (the io thread
    /// writes requests before the newest DRIVE, so the ARM precedes it). The answer shows in
    /// the telemetry's state; a lost ARM is simply requested again. Like [`Link::arm`], the
    /// link then re-arms after a reconnect or firmware reset.
    pub fn request_arm(&self) {
        let mut g = self.shared.lock();
        g.want_armed = true;
        // one is enough while it waits to be written (a stuck port must not pile them up)
        if !g.requests.iter().any(|(t, _)| *t == UNAWAITED) {
            g.requests.push_back((UNAWAITED, Message::Arm));
        }
        drop(g);
        self.shared.cv.notify_all();
    }

    /// Runs an idempotent request again when it gets no answer in time (a busy machine, a
    /// reply frame lost to a bad checksum) while the link is up, [`IDEMPOTENT_ATTEMPTS`] times
    /// in all; any other outcome is returned at once.
    fn idempotent<T>(&self, once: impl Fn() -> Result<T, LinkError>) -> Result<T, LinkError> {
        let mut attempt = 1;
        loop {
            match once() {
                Err(LinkError::Timeout { .. }) if attempt < IDEMPOTENT_ATTEMPTS && self.is_connected() => attempt += 1,
                r => return r,
            }
        }
    }

    /// Arms the firmware (it stays armed across reconnects and firmware resets: the link
    /// re-arms after the new handshake). The ESC follows from the next DRIVE. ARM is
    /// idempotent, so one that gets no answer in time is asked again (`idempotent`).
    pub fn arm(&self) -> Result<(), LinkError> {
        self.shared.lock().want_armed = true;
        self.idempotent(|| self.arm_once())
    }

    fn arm_once(&self) -> Result<(), LinkError> {
        match self.expect_ok(Message::Arm, "ARM") {
            // the firmware has just reset and the link is handshaking again: the ARM is
            // repeated once the handshake is done
            Err(LinkError::Refused {
                code: status::NO_HANDSHAKE,
                ..
            }) => {
                std::thread::sleep(Duration::from_millis(50));
                self.wait_connected(self.reply_timeout * 3)?;
                self.expect_ok(Message::Arm, "ARM")
            }
            r => r,
        }
    }

    /// Disarms: servo centre, ESC neutral, DRIVE ignored.
    pub fn disarm(&self) -> Result<(), LinkError> {
        {
            let mut g = self.shared.lock();
            g.want_armed = false;
            g.drive = None;
        }
        self.expect_ok(Message::Disarm, "DISARM")
    }

    /// Sends a configuration (refused while armed); `persist` also stores it in EEPROM.
    /// Idempotent (the same values again): asked again when unanswered.
    pub fn set_config(&self, config: LinkConfig, persist: bool) -> Result<(), LinkError> {
        let flags = if persist { protocol::CF_PERSIST } else { 0 };
        self.idempotent(|| self.expect_ok(Message::ConfigSet { flags, config }, "CONFIG_SET"))
    }

    /// Reads the configuration in use and whether it came from EEPROM; asked again when
    /// unanswered.
    pub fn get_config(&self) -> Result<(LinkConfig, bool), LinkError> {
        self.idempotent(|| match self.request(Message::ConfigGet, "CONFIG")?.0 {
            Reply::Config(flags, c) => Ok((c, flags & 1 != 0)),
            _ => Err(self.timeout(&self.shared.lock(), "CONFIG", self.reply_timeout)),
        })
    }

    /// PING → TELEMETRY; returns it with the round trip (write → answer decoded).
    pub fn ping(&self) -> Result<(Telemetry, Duration), LinkError> {
        match self.request(Message::Ping, "PING reply")? {
            (Reply::Telemetry(t), rtt) => Ok((t, rtt)),
            _ => Err(self.timeout(&self.shared.lock(), "PING reply", self.reply_timeout)),
        }
    }

    /// The latest telemetry and how many have arrived.
    pub fn telemetry(&self) -> Option<(Telemetry, u64)> {
        let g = self.shared.lock();
        g.telemetry.map(|t| (t, g.stats.telemetry))
    }

    /// Waits for a telemetry satisfying `pred`.
    pub fn wait_telemetry(&self, timeout: Duration, pred: impl Fn(&Telemetry) -> bool) -> Option<Telemetry> {
        let deadline = Instant::now() + timeout;
        let mut g = self.shared.lock();
        loop {
            if let Some(t) = g.telemetry.filter(|t| g.connected && pred(t)) {
                return Some(t);
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            g = self
                .shared
                .cv
                .wait_timeout(g, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    /// Every telemetry received since the last call (at most 100,000 are kept).
    pub fn take_telemetry_log(&self) -> Vec<Telemetry> {
        std::mem::take(&mut self.shared.lock().telemetry_log)
    }

    /// Host-side counters.
    pub fn stats(&self) -> LinkStats {
        self.shared.lock().stats
    }

    /// Whether a DRIVE is still waiting to be written.
    pub fn drive_pending(&self) -> bool {
        self.shared.lock().drive.is_some()
    }
}

impl CommandSink for Link {
    fn send(&mut self, cmd: Command, _now_s: f64) -> Result<Command, SinkError> {
        self.drive(protocol::to_permille(cmd.steer), protocol::to_permille(cmd.throttle));
        Ok(cmd)
    }

    fn stop(&mut self) -> Result<(), SinkError> {
        self.drive(0, 0);
        self.disarm().map_err(|e| SinkError(e.to_string()))
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        {
            let mut g = self.shared.lock();
            g.shutdown = true;
            g.want_armed = false;
        }
        self.shared.cv.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

// ---- the I/O thread ---------------------------------------------------------------------------

struct Conn {
    port: Box<dyn serialport::SerialPort>,
    decoder: Decoder,
    seq: u8,
}

enum Exit {
    /// Port broken or silent: reopen.
    Reopen,
    /// Firmware reset: handshake again on the same port.
    Rehandshake,
    /// Link dropped.
    Shutdown,
}

fn io_thread(path: &str, mut opt: LinkOptions, shared: &Shared) {
    let mut backoff = opt.backoff_min;
    let mut opened_before = false;
    loop {
        if shared.lock().shutdown {
            return;
        }
        // 1. open, with back-off while the port is missing
        let port = match serialport::new(path, opt.baud).timeout(Duration::from_millis(1)).open() {
            Ok(p) => p,
            Err(e) => {
                shared.lock().last_error = format!("open: {e}");
                let g = shared.lock();
                let _ = shared.cv.wait_timeout_while(g, backoff, |g| !g.shutdown);
                backoff = (backoff * 2).min(opt.backoff_max);
                continue;
            }
        };
        if opened_before {
            shared.lock().stats.reconnects += 1;
        }
        opened_before = true;
        let mut conn = Conn {
            port,
            decoder: Decoder::new(),
            seq: 0,
        };
        let _ = conn.port.clear(serialport::ClearBuffer::All);
        loop {
            // 2. handshake; 3. re-arm
            match handshake(&mut conn, shared, &mut opt) {
                Ok(()) => backoff = opt.backoff_min,
                Err(e) => {
                    shared.lock().last_error = e;
                    break;
                }
            }
            // 4. run
            match run(&mut conn, shared, &mut opt) {
                Exit::Rehandshake => continue,
                Exit::Reopen => break,
                Exit::Shutdown => {
                    // every exit path: DISARM and a neutral DRIVE
                    let _ = write_msg(&mut conn, shared, &mut opt, &Message::Disarm);
                    let _ = write_msg(&mut conn, shared, &mut opt, &Message::Drive { steer: 0, throttle: 0 });
                    let _ = conn.port.flush();
                    shared.lock().connected = false;
                    return;
                }
            }
        }
        {
            let mut g = shared.lock();
            g.connected = false;
            g.pending.clear();
        }
        shared.cv.notify_all();
        let g = shared.lock();
        let _ = shared.cv.wait_timeout_while(g, backoff, |g| !g.shutdown);
        backoff = (backoff * 2).min(opt.backoff_max);
    }
}

fn write_msg(conn: &mut Conn, shared: &Shared, opt: &mut LinkOptions, msg: &Message) -> std::io::Result<u8> {
    let seq = conn.seq;
    let mut bytes = protocol::encode(seq, msg);
    conn.seq = conn.seq.wrapping_add(1);
    if let Some(f) = opt.wire_fault.as_mut() {
        f(&mut bytes);
    }
    write_all_patiently(conn.port.as_mut(), &bytes)?;
    shared.lock().stats.tx_frames += 1;
    Ok(seq)
}

/// Writes all of `bytes`. The port's 1 ms timeout is for reads; a write that times out is
/// back-pressure (the receiver is slower than us), not a lost port, so it is retried for up to
/// a second before giving up.
fn write_all_patiently(port: &mut dyn serialport::SerialPort, bytes: &[u8]) -> std::io::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(1);
    let mut off = 0;
    while off < bytes.len() {
        match port.write(&bytes[off..]) {
            Ok(0) => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::WriteZero,
                    "port accepted no bytes",
                ))
            }
            Ok(n) => off += n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted | std::io::ErrorKind::WouldBlock
                ) && Instant::now() < deadline => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Reads what is there (≤ 1 ms wait) into the decoder; Err on a broken port.
fn read_frames(conn: &mut Conn) -> Result<Vec<Frame>, String> {
    let mut buf = [0u8; 256];
    match conn.port.read(&mut buf) {
        Ok(n) => Ok(conn.decoder.feed(&buf[..n])),
        Err(e) if e.kind() == std::io::ErrorKind::TimedOut || e.kind() == std::io::ErrorKind::Interrupted => {
            Ok(Vec::new())
        }
        Err(e) => Err(format!("read: {e}")),
    }
}

fn handshake(conn: &mut Conn, shared: &Shared, opt: &mut LinkOptions) -> Result<(), String> {
    for _attempt in 0..5 {
        if shared.lock().shutdown {
            return Err("shutdown".into());
        }
        let seq = write_msg(
            conn,
            shared,
            opt,
            &Message::Hello {
                protocol_version: protocol::PROTOCOL_VERSION,
            },
        )
        .map_err(|e| format!("write: {e}"))?;
        let deadline = Instant::now() + opt.reply_timeout;
        while Instant::now() < deadline {
            for f in read_frames(conn)? {
                if let Message::HelloAck(a) = f.msg {
                    if a.re_seq == seq {
                        let rearm = {
                            let mut g = shared.lock();
                            g.hello = Some(a);
                            g.stats.handshakes += 1;
                            if g.stats.handshakes > 1 && !opt.rearm_after_reconnect {
                                // A new handshake after the first: the application re-arms.
                                g.want_armed = false;
                                g.drive = None;
                            }
                            g.telemetry = None;
                            g.connected = a.status == status::OK;
                            g.want_armed && g.connected
                        };
                        shared.cv.notify_all();
                        if a.status != status::OK {
                            return Err(format!("HELLO refused: status {}", status::name(a.status)));
                        }
                        if rearm {
                            write_msg(conn, shared, opt, &Message::Arm).map_err(|e| format!("write: {e}"))?;
                        }
                        return Ok(());
                    }
                }
            }
        }
    }
    Err("no HELLO_ACK".into())
}

/// Writes the queued requests, then the newest DRIVE (unless too old); `Some` when the
/// connection must end (shut down, or a write failed).
fn write_pending(conn: &mut Conn, shared: &Shared, opt: &mut LinkOptions) -> Option<Exit> {
    let (requests, drive, shutdown) = {
        let mut g = shared.lock();
        (std::mem::take(&mut g.requests), g.drive.take(), g.shutdown)
    };
    if shutdown {
        return Some(Exit::Shutdown);
    }
    for (ticket, msg) in requests {
        match write_msg(conn, shared, opt, &msg) {
            Ok(seq) if ticket != UNAWAITED => {
                let mut g = shared.lock();
                g.pending.push((seq, msg.id(), ticket));
                g.sent_at.insert(ticket, Instant::now());
            }
            Ok(_) => {}
            Err(e) => {
                shared.lock().last_error = format!("write: {e}");
                return Some(Exit::Reopen);
            }
        }
    }
    if let Some((d, at)) = drive {
        if at.elapsed() > opt.max_drive_age {
            shared.lock().stats.drives_expired += 1;
        } else if let Err(e) = write_msg(conn, shared, opt, &d) {
            shared.lock().last_error = format!("write: {e}");
            return Some(Exit::Reopen);
        } else {
            shared.lock().stats.drives_sent += 1;
        }
    }
    None
}

fn run(conn: &mut Conn, shared: &Shared, opt: &mut LinkOptions) -> Exit {
    let mut last_telemetry = Instant::now();
    let mut last_uptime: Option<u32> = None;
    loop {
        // 1. write: requests first (ARM must precede the DRIVE after it), then the newest DRIVE
        if let Some(exit) = write_pending(conn, shared, opt) {
            return exit;
        }
        // 2. read and dispatch
        let frames = match read_frames(conn) {
            Ok(f) => f,
            Err(e) => {
                shared.lock().last_error = e;
                return Exit::Reopen;
            }
        };
        let now = Instant::now();
        let mut g = shared.lock();
        g.stats.rx = conn.decoder.counters;
        let mut reset = false;
        for f in frames {
            match f.msg {
                Message::Telemetry(t) => {
                    last_telemetry = now;
                    g.stats.telemetry += 1;
                    // a firmware reset: uptime backwards, or the handshake forgotten
                    // (the firmware sends in order, so every telemetry after our HELLO_ACK was
                    // written after it accepted the HELLO and must carry the flag)
                    let flag = t.flags & protocol::TF_HANDSHAKE_DONE != 0;
                    if last_uptime.is_some_and(|u| t.uptime_ms < u) || !flag {
                        reset = true;
                    }
                    last_uptime = Some(t.uptime_ms);
                    if t.flags & protocol::TF_PING_REPLY != 0 {
                        if let Some(i) = g
                            .pending
                            .iter()
                            .position(|p| p.1 == protocol::id::PING && p.0 == t.last_rx_seq)
                        {
                            let (_, _, ticket) = g.pending.remove(i);
                            g.replies.insert(ticket, (Reply::Telemetry(t), now));
                        }
                    }
                    g.telemetry = Some(t);
                    if g.telemetry_log.len() < 100_000 {
                        g.telemetry_log.push(t);
                    }
                }
                Message::Status { re_id, re_seq, status } => {
                    if let Some(i) = g.pending.iter().position(|p| p.0 == re_seq && p.1 == re_id) {
                        let (_, _, ticket) = g.pending.remove(i);
                        g.replies.insert(ticket, (Reply::Status(status), now));
                    }
                    if status == status::NO_HANDSHAKE {
                        reset = true;
                    }
                }
                Message::Config { flags, config } => {
                    if let Some(i) = g.pending.iter().position(|p| p.1 == protocol::id::CONFIG_GET) {
                        let (_, _, ticket) = g.pending.remove(i);
                        g.replies.insert(ticket, (Reply::Config(flags, config), now));
                    }
                }
                _ => {}
            }
        }
        if reset {
            g.stats.firmware_resets += 1;
            g.connected = false;
        }
        drop(g);
        shared.cv.notify_all();
        if reset {
            return Exit::Rehandshake;
        }
        if now.duration_since(last_telemetry) > opt.silence_timeout {
            shared.lock().last_error = "no telemetry".into();
            return Exit::Reopen;
        }
    }
}
