//! The rccar serial link protocol, version 1: framing, CRC, a resynchronising byte-at-a-time
//! decoder and the typed messages. `docs/protocol.md` is the one table; this file mirrors it
//! field for field, as does `firmware/rccar_fw/protocol.h`, and both sides' tests read the same
//! vectors (`tests/data/protocol_vectors.txt`).
//!
//! Frame: `START 0xA5 | LEN | ID | SEQ | PAYLOAD (LEN bytes) | CRC16 (LE)`, the CRC being
//! CRC-16/CCITT-FALSE (polynomial 0x1021, init 0xFFFF) over LEN, ID, SEQ and PAYLOAD. Fields are
//! little-endian. Units: µs for pulse widths, ms for times, per-mille (−1000..=1000) for steer
//! and throttle.

/// Protocol version carried by HELLO / HELLO_ACK.
pub const PROTOCOL_VERSION: u8 = 1;
/// First byte of every frame.
pub const START: u8 = 0xA5;
/// Largest payload, bytes.
pub const MAX_PAYLOAD: usize = 32;
/// START, LEN, ID, SEQ.
pub const HEADER_LEN: usize = 4;
/// Largest frame, bytes.
pub const MAX_FRAME: usize = HEADER_LEN + MAX_PAYLOAD + 2;

/// Message ids (docs/protocol.md); ids ≥ 0x80 go firmware → host.
pub mod id {
    /// `u8 protocol_version`.
    pub const HELLO: u8 = 0x01;
    /// `i16 steer, i16 throttle`, per-mille.
    pub const DRIVE: u8 = 0x02;
    /// No payload.
    pub const ARM: u8 = 0x03;
    /// No payload.
    pub const DISARM: u8 = 0x04;
    /// No payload; answered by TELEMETRY with the PING_REPLY flag.
    pub const PING: u8 = 0x05;
    /// `u8 flags` + config.
    pub const CONFIG_SET: u8 = 0x06;
    /// No payload; answered by CONFIG.
    pub const CONFIG_GET: u8 = 0x07;
    /// `u8 re_seq, status, protocol_version, fw_major, fw_minor, fw_patch`.
    pub const HELLO_ACK: u8 = 0x81;
    /// `u8 re_id, re_seq, status`.
    pub const STATUS: u8 = 0x82;
    /// 26 bytes, see [`super::Telemetry`].
    pub const TELEMETRY: u8 = 0x83;
    /// `u8 flags` + config.
    pub const CONFIG: u8 = 0x84;
}

/// Fixed payload length of a message id; `None` for an id outside the table.
pub fn payload_len(id: u8) -> Option<usize> {
    Some(match id {
        id::HELLO => 1,
        id::DRIVE => 4,
        id::ARM | id::DISARM | id::PING | id::CONFIG_GET => 0,
        id::CONFIG_SET | id::CONFIG => 1 + CONFIG_WIRE_LEN,
        id::HELLO_ACK => 6,
        id::STATUS => 3,
        id::TELEMETRY => 26,
        _ => return None,
    })
}

/// Status codes (STATUS.status, HELLO_ACK.status).
pub mod status {
    /// Done.
    pub const OK: u8 = 0;
    /// A valid frame the firmware does not act on.
    pub const UNKNOWN_MESSAGE: u8 = 1;
    /// DRIVE while disarmed or in failsafe.
    pub const NOT_ARMED: u8 = 2;
    /// ARM before a successful HELLO.
    pub const NO_HANDSHAKE: u8 = 3;
    /// HELLO with another protocol version.
    pub const VERSION_MISMATCH: u8 = 4;
    /// DRIVE outside ±1000 or inconsistent CONFIG.
    pub const OUT_OF_RANGE: u8 = 5;
    /// CONFIG_SET while armed or while the EEPROM is being written.
    pub const BUSY: u8 = 6;

    /// The documented name of a status code.
    pub fn name(code: u8) -> &'static str {
        match code {
            OK => "OK",
            UNKNOWN_MESSAGE => "UNKNOWN_MESSAGE",
            NOT_ARMED => "NOT_ARMED",
            NO_HANDSHAKE => "NO_HANDSHAKE",
            VERSION_MISMATCH => "VERSION_MISMATCH",
            OUT_OF_RANGE => "OUT_OF_RANGE",
            BUSY => "BUSY",
            _ => "UNDOCUMENTED",
        }
    }
}

/// TELEMETRY flag: this telemetry answers a PING.
pub const TF_PING_REPLY: u8 = 0x01;
/// TELEMETRY flag: the configuration came from EEPROM (else defaults).
pub const TF_CONFIG_FROM_EEPROM: u8 = 0x02;
/// TELEMETRY flag: the last reset was the watchdog's.
pub const TF_WATCHDOG_RESET: u8 = 0x04;
/// TELEMETRY flag: HELLO succeeded since power-up.
pub const TF_HANDSHAKE_DONE: u8 = 0x08;
/// TELEMETRY flag: armed and a DRIVE arrived after the ARM.
pub const TF_DRIVE_FRESH: u8 = 0x10;
/// CONFIG_SET flag: also store in EEPROM.
pub const CF_PERSIST: u8 = 0x01;

/// Firmware state reported in TELEMETRY.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Servo centred, ESC neutral; power-up state.
    Disarmed,
    /// Following DRIVE.
    Armed,
    /// No DRIVE for `failsafe_ms`: neutral until ARM + DRIVE.
    Failsafe,
    /// A value outside the table (from a newer firmware).
    Unknown(u8),
}

impl State {
    fn from_u8(v: u8) -> State {
        match v {
            0 => State::Disarmed,
            1 => State::Armed,
            2 => State::Failsafe,
            x => State::Unknown(x),
        }
    }
    fn to_u8(self) -> u8 {
        match self {
            State::Disarmed => 0,
            State::Armed => 1,
            State::Failsafe => 2,
            State::Unknown(x) => x,
        }
    }
}

/// Bytes of the seven configuration fields.
pub const CONFIG_WIRE_LEN: usize = 14;

/// The firmware's configuration (CONFIG_SET / CONFIG), pulse widths in µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkConfig {
    /// Servo pulse at steer −1000 (full left), µs.
    pub servo_min_us: u16,
    /// Servo pulse at steer 0, µs (the trim).
    pub servo_center_us: u16,
    /// Servo pulse at steer +1000 (full right), µs.
    pub servo_max_us: u16,
    /// ESC pulse at throttle −1000 (full reverse), µs.
    pub esc_min_us: u16,
    /// ESC pulse at throttle 0 (stop), µs.
    pub esc_neutral_us: u16,
    /// ESC pulse at throttle +1000 (full forward), µs.
    pub esc_max_us: u16,
    /// Armed and no DRIVE for this long → failsafe, ms.
    pub failsafe_ms: u16,
}

impl Default for LinkConfig {
    /// The firmware's defaults (blank or corrupt EEPROM).
    fn default() -> Self {
        LinkConfig {
            servo_min_us: 1000,
            servo_center_us: 1500,
            servo_max_us: 2000,
            esc_min_us: 1000,
            esc_neutral_us: 1500,
            esc_max_us: 2000,
            failsafe_ms: 250,
        }
    }
}

impl LinkConfig {
    /// The firmware's acceptance rule: 500 ≤ min < centre < max ≤ 2500 for servo and ESC,
    /// failsafe 20..=5000 ms.
    pub fn is_valid(&self) -> bool {
        let ordered = |lo: u16, mid: u16, hi: u16| 500 <= lo && lo < mid && mid < hi && hi <= 2500;
        ordered(self.servo_min_us, self.servo_center_us, self.servo_max_us)
            && ordered(self.esc_min_us, self.esc_neutral_us, self.esc_max_us)
            && (20..=5000).contains(&self.failsafe_ms)
    }

    fn fields(&self) -> [(&'static str, u16); 7] {
        [
            ("servo_min_us", self.servo_min_us),
            ("servo_center_us", self.servo_center_us),
            ("servo_max_us", self.servo_max_us),
            ("esc_min_us", self.esc_min_us),
            ("esc_neutral_us", self.esc_neutral_us),
            ("esc_max_us", self.esc_max_us),
            ("failsafe_ms", self.failsafe_ms),
        ]
    }

    fn put(&self, out: &mut Vec<u8>) {
        for (_, v) in self.fields() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }

    fn get(b: &[u8]) -> LinkConfig {
        let u = |i: usize| u16::from_le_bytes([b[2 * i], b[2 * i + 1]]);
        LinkConfig {
            servo_min_us: u(0),
            servo_center_us: u(1),
            servo_max_us: u(2),
            esc_min_us: u(3),
            esc_neutral_us: u(4),
            esc_max_us: u(5),
            failsafe_ms: u(6),
        }
    }
}

/// HELLO_ACK payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HelloAck {
    /// SEQ of the HELLO answered.
    pub re_seq: u8,
    /// Status code ([`status`]).
    pub status: u8,
    /// The firmware's protocol version.
    pub protocol_version: u8,
    /// Firmware version, major.
    pub fw_major: u8,
    /// Firmware version, minor.
    pub fw_minor: u8,
    /// Firmware version, patch.
    pub fw_patch: u8,
}

/// TELEMETRY payload (26 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Telemetry {
    /// Disarmed / armed / failsafe.
    pub state: State,
    /// `TF_*` bits.
    pub flags: u8,
    /// SEQ of the last host frame accepted (any id).
    pub last_rx_seq: u8,
    /// SEQ of the last DRIVE applied.
    pub drive_seq: u8,
    /// Servo pulse width applied, µs.
    pub servo_us: u16,
    /// ESC pulse width applied, µs.
    pub esc_us: u16,
    /// Frames with a wrong CRC (wrapping).
    pub crc_errors: u16,
    /// Bad headers and runs of stray bytes (wrapping).
    pub framing_errors: u16,
    /// Bytes lost because the UART or the receive buffer was full (wrapping).
    pub overruns: u16,
    /// Armed → failsafe transitions (wrapping).
    pub failsafe_trips: u16,
    /// Host frames missing from the SEQ sequence (wrapping).
    pub lost_frames: u16,
    /// Host frames accepted.
    pub rx_frames: u32,
    /// Time since the firmware started, ms.
    pub uptime_ms: u32,
}

/// One message, typed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Version handshake request.
    Hello {
        /// The host's protocol version.
        protocol_version: u8,
    },
    /// Steer and throttle, per-mille.
    Drive {
        /// −1000 full left ..= 1000 full right.
        steer: i16,
        /// −1000 full reverse ..= 0 stop ..= 1000 full forward.
        throttle: i16,
    },
    /// Arm (the ESC follows the next DRIVE).
    Arm,
    /// Disarm (neutral at once).
    Disarm,
    /// Ask for a TELEMETRY now.
    Ping,
    /// Set (and with `CF_PERSIST` store) the configuration.
    ConfigSet {
        /// `CF_*` bits.
        flags: u8,
        /// The new configuration.
        config: LinkConfig,
    },
    /// Ask for the configuration.
    ConfigGet,
    /// Answer to HELLO.
    HelloAck(HelloAck),
    /// Answer to ARM, DISARM, CONFIG_SET, or a rejected DRIVE.
    Status {
        /// Id answered.
        re_id: u8,
        /// SEQ answered.
        re_seq: u8,
        /// Status code ([`status`]).
        status: u8,
    },
    /// Firmware state and counters.
    Telemetry(Telemetry),
    /// The configuration in use.
    Config {
        /// Bit 0: loaded from EEPROM (else defaults).
        flags: u8,
        /// The configuration.
        config: LinkConfig,
    },
}

impl Message {
    /// The message id.
    pub fn id(&self) -> u8 {
        match self {
            Message::Hello { .. } => id::HELLO,
            Message::Drive { .. } => id::DRIVE,
            Message::Arm => id::ARM,
            Message::Disarm => id::DISARM,
            Message::Ping => id::PING,
            Message::ConfigSet { .. } => id::CONFIG_SET,
            Message::ConfigGet => id::CONFIG_GET,
            Message::HelloAck(_) => id::HELLO_ACK,
            Message::Status { .. } => id::STATUS,
            Message::Telemetry(_) => id::TELEMETRY,
            Message::Config { .. } => id::CONFIG,
        }
    }

    /// The payload bytes, little-endian.
    pub fn payload(&self) -> Vec<u8> {
        let mut p = Vec::with_capacity(MAX_PAYLOAD);
        match *self {
            Message::Hello { protocol_version } => p.push(protocol_version),
            Message::Drive { steer, throttle } => {
                p.extend_from_slice(&steer.to_le_bytes());
                p.extend_from_slice(&throttle.to_le_bytes());
            }
            Message::Arm | Message::Disarm | Message::Ping | Message::ConfigGet => {}
            Message::ConfigSet { flags, config } | Message::Config { flags, config } => {
                p.push(flags);
                config.put(&mut p);
            }
            Message::HelloAck(a) => p.extend_from_slice(&[
                a.re_seq,
                a.status,
                a.protocol_version,
                a.fw_major,
                a.fw_minor,
                a.fw_patch,
            ]),
            Message::Status { re_id, re_seq, status } => p.extend_from_slice(&[re_id, re_seq, status]),
            Message::Telemetry(t) => {
                p.extend_from_slice(&[t.state.to_u8(), t.flags, t.last_rx_seq, t.drive_seq]);
                for v in [
                    t.servo_us,
                    t.esc_us,
                    t.crc_errors,
                    t.framing_errors,
                    t.overruns,
                    t.failsafe_trips,
                    t.lost_frames,
                ] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                p.extend_from_slice(&t.rx_frames.to_le_bytes());
                p.extend_from_slice(&t.uptime_ms.to_le_bytes());
            }
        }
        p
    }

    /// Parses a payload whose id and length the framing has already checked; `None` if they
    /// do not fit.
    pub fn from_payload(msg_id: u8, b: &[u8]) -> Option<Message> {
        if payload_len(msg_id) != Some(b.len()) {
            return None;
        }
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Some(match msg_id {
            id::HELLO => Message::Hello { protocol_version: b[0] },
            id::DRIVE => Message::Drive {
                steer: u16_at(0) as i16,
                throttle: u16_at(2) as i16,
            },
            id::ARM => Message::Arm,
            id::DISARM => Message::Disarm,
            id::PING => Message::Ping,
            id::CONFIG_GET => Message::ConfigGet,
            id::CONFIG_SET => Message::ConfigSet {
                flags: b[0],
                config: LinkConfig::get(&b[1..]),
            },
            id::CONFIG => Message::Config {
                flags: b[0],
                config: LinkConfig::get(&b[1..]),
            },
            id::HELLO_ACK => Message::HelloAck(HelloAck {
                re_seq: b[0],
                status: b[1],
                protocol_version: b[2],
                fw_major: b[3],
                fw_minor: b[4],
                fw_patch: b[5],
            }),
            id::STATUS => Message::Status {
                re_id: b[0],
                re_seq: b[1],
                status: b[2],
            },
            id::TELEMETRY => Message::Telemetry(Telemetry {
                state: State::from_u8(b[0]),
                flags: b[1],
                last_rx_seq: b[2],
                drive_seq: b[3],
                servo_us: u16_at(4),
                esc_us: u16_at(6),
                crc_errors: u16_at(8),
                framing_errors: u16_at(10),
                overruns: u16_at(12),
                failsafe_trips: u16_at(14),
                lost_frames: u16_at(16),
                rx_frames: u32_at(18),
                uptime_ms: u32_at(22),
            }),
            _ => return None,
        })
    }

    /// The fields by their documented names, in wire order (for the shared vectors).
    pub fn fields(&self) -> Vec<(&'static str, i64)> {
        match *self {
            Message::Hello { protocol_version } => vec![("protocol_version", protocol_version.into())],
            Message::Drive { steer, throttle } => vec![("steer", steer.into()), ("throttle", throttle.into())],
            Message::Arm | Message::Disarm | Message::Ping | Message::ConfigGet => vec![],
            Message::ConfigSet { flags, config } | Message::Config { flags, config } => {
                let mut v = vec![("flags", i64::from(flags))];
                v.extend(config.fields().iter().map(|&(k, x)| (k, i64::from(x))));
                v
            }
            Message::HelloAck(a) => vec![
                ("re_seq", a.re_seq.into()),
                ("status", a.status.into()),
                ("protocol_version", a.protocol_version.into()),
                ("fw_major", a.fw_major.into()),
                ("fw_minor", a.fw_minor.into()),
                ("fw_patch", a.fw_patch.into()),
            ],
            Message::Status { re_id, re_seq, status } => vec![
                ("re_id", re_id.into()),
                ("re_seq", re_seq.into()),
                ("status", status.into()),
            ],
            Message::Telemetry(t) => vec![
                ("state", t.state.to_u8().into()),
                ("flags", t.flags.into()),
                ("last_rx_seq", t.last_rx_seq.into()),
                ("drive_seq", t.drive_seq.into()),
                ("servo_us", t.servo_us.into()),
                ("esc_us", t.esc_us.into()),
                ("crc_errors", t.crc_errors.into()),
                ("framing_errors", t.framing_errors.into()),
                ("overruns", t.overruns.into()),
                ("failsafe_trips", t.failsafe_trips.into()),
                ("lost_frames", t.lost_frames.into()),
                ("rx_frames", t.rx_frames.into()),
                ("uptime_ms", t.uptime_ms.into()),
            ],
        }
    }
}

/// CRC-16/CCITT-FALSE: polynomial 0x1021, init 0xFFFF, MSB first, no final xor.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Encodes one frame: START, LEN, ID, SEQ, payload, CRC (little-endian).
pub fn encode(seq: u8, msg: &Message) -> Vec<u8> {
    let payload = msg.payload();
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len() + 2);
    out.extend_from_slice(&[START, payload.len() as u8, msg.id(), seq]);
    out.extend_from_slice(&payload);
    let crc = crc16(&out[1..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// A decoded frame: the sender's sequence number and the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// The sender's SEQ.
    pub seq: u8,
    /// The message.
    pub msg: Message,
}

/// Receiver counters (same meaning as the firmware's).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecoderCounters {
    /// Complete frames with a wrong CRC.
    pub crc_errors: u64,
    /// Bad LEN, unknown id or LEN not matching it, runs of stray bytes.
    pub framing_errors: u64,
    /// Frames accepted.
    pub frames_ok: u64,
}

/// Byte-at-a-time decoder with resynchronisation, the twin of `rc_parser` in protocol.c:
///
/// 1. bytes before a START are discarded (one framing error per run);
/// 2. LEN > 32, an id outside the table or a LEN that is not the id's → framing error, at once;
/// 3. a complete frame with a wrong CRC → CRC error;
/// 4. after any error the buffered bytes are rescanned from the byte after the rejected START,
///    so a damaged frame never hides the valid frame that follows it.
#[derive(Debug, Clone, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    in_garbage: bool,
    /// Counters since creation.
    pub counters: DecoderCounters,
}

impl Decoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Decoder {
            buf: Vec::with_capacity(MAX_FRAME),
            in_garbage: false,
            counters: DecoderCounters::default(),
        }
    }

    /// Appends one byte; returns the frame it completes, if any. Later frames it uncovered by
    /// resynchronisation come out of [`Decoder::pop`].
    pub fn push(&mut self, byte: u8) -> Option<Frame> {
        if self.buf.is_empty() {
            if byte != START {
                self.garbage_run();
            } else {
                self.buf.push(byte);
            }
            return None;
        }
        self.buf.push(byte);
        self.pop()
    }

    /// Feeds a slice, returning every frame it completes, in order.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<Frame> {
        let mut out = Vec::new();
        for &b in bytes {
            if let Some(f) = self.push(b) {
                out.push(f);
                while let Some(f) = self.pop() {
                    out.push(f);
                }
            }
        }
        out
    }

    fn garbage_run(&mut self) {
        if !self.in_garbage {
            self.in_garbage = true;
            self.counters.framing_errors += 1;
        }
    }

    fn skip_to_start(&mut self) {
        let k = self.buf.iter().position(|&b| b == START).unwrap_or(self.buf.len());
        if k > 0 {
            self.garbage_run();
            self.buf.drain(..k);
        }
    }

    fn reject(&mut self, crc: bool) {
        if crc {
            self.counters.crc_errors += 1;
        } else {
            self.counters.framing_errors += 1;
        }
        self.in_garbage = true;
        self.buf.remove(0);
        self.skip_to_start();
    }

    /// The next complete valid frame already buffered, if any.
    pub fn pop(&mut self) -> Option<Frame> {
        loop {
            // 1. START + LEN
            if self.buf.len() < 2 {
                return None;
            }
            let len = usize::from(self.buf[1]);
            if len > MAX_PAYLOAD {
                self.reject(false);
                continue;
            }
            // 2. the id fixes the length
            if self.buf.len() < 3 {
                return None;
            }
            if payload_len(self.buf[2]) != Some(len) {
                self.reject(false);
                continue;
            }
            // 3. CRC over LEN, ID, SEQ, PAYLOAD
            let total = HEADER_LEN + len + 2;
            if self.buf.len() < total {
                return None;
            }
            let crc = crc16(&self.buf[1..HEADER_LEN + len]);
            if crc != u16::from_le_bytes([self.buf[HEADER_LEN + len], self.buf[HEADER_LEN + len + 1]]) {
                self.reject(true);
                continue;
            }
            // 4. accept
            let msg = Message::from_payload(self.buf[2], &self.buf[HEADER_LEN..HEADER_LEN + len]);
            let seq = self.buf[3];
            self.buf.drain(..total);
            self.in_garbage = false;
            self.counters.frames_ok += 1;
            self.skip_to_start();
            // payload_len() accepted the id, so from_payload cannot fail; stay total anyway
            if let Some(msg) = msg {
                return Some(Frame { seq, msg });
            }
        }
    }
}

/// Per-mille → pulse width, linear on each side of the centre and clamped to [min, max]
/// (the firmware's `rc_permille_to_us`, rounded to the nearest µs).
pub fn permille_to_us(permille: i16, min_us: u16, center_us: u16, max_us: u16) -> u16 {
    let v = i32::from(permille).clamp(-1000, 1000);
    let (c, lo, hi) = (i32::from(center_us), i32::from(min_us), i32::from(max_us));
    let span = if v >= 0 { hi - c } else { c - lo };
    let off = (v.abs() * span + 500) / 1000;
    let us = if v >= 0 { c + off } else { c - off };
    us.clamp(lo, hi) as u16
}

/// A value in [−1, 1] as per-mille (NaN → 0, rounded, clamped).
pub fn to_permille(v: f64) -> i16 {
    if v.is_nan() {
        0
    } else {
        (v.clamp(-1.0, 1.0) * 1000.0).round() as i16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// One line of tests/data/protocol_vectors.txt.
    enum Vector {
        Ok {
            name: String,
            id: u8,
            seq: u8,
            bytes: Vec<u8>,
            fields: Vec<(String, i64)>,
        },
        Bad {
            name: String,
            crc: u64,
            framing: u64,
            bytes: Vec<u8>,
        },
    }

    fn unhex(s: &str) -> Vec<u8> {
        (0..s.len() / 2)
            .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).expect("hex"))
            .collect()
    }

    fn vectors() -> Vec<Vector> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/protocol_vectors.txt");
        let text = std::fs::read_to_string(path).expect("tests/data/protocol_vectors.txt");
        let mut out = Vec::new();
        for line in text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
            let t: Vec<&str> = line.split_whitespace().collect();
            if t[0] == "ok" {
                out.push(Vector::Ok {
                    name: t[1].into(),
                    id: u8::from_str_radix(t[2].trim_start_matches("0x"), 16).expect("id"),
                    seq: t[3].parse().expect("seq"),
                    bytes: unhex(t[4]),
                    fields: t[5..]
                        .iter()
                        .map(|kv| {
                            let (k, v) = kv.split_once('=').expect("key=value");
                            (k.to_string(), v.parse().expect("number"))
                        })
                        .collect(),
                });
            } else {
                out.push(Vector::Bad {
                    name: t[1].into(),
                    crc: t[2].parse().expect("crc"),
                    framing: t[3].parse().expect("framing"),
                    bytes: unhex(t[4]),
                });
            }
        }
        out
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn every_vector_decodes_and_encodes() {
        let vs = vectors();
        assert!(vs.len() >= 20, "only {} vectors", vs.len());
        for v in &vs {
            match v {
                Vector::Ok {
                    name,
                    id,
                    seq,
                    bytes,
                    fields,
                } => {
                    let mut d = Decoder::new();
                    let early = d.feed(&bytes[..bytes.len() - 1]);
                    assert!(early.is_empty(), "{name}: frame before the last byte");
                    let f = d.feed(&bytes[bytes.len() - 1..]);
                    assert_eq!(f.len(), 1, "{name}");
                    assert_eq!((f[0].msg.id(), f[0].seq), (*id, *seq), "{name}");
                    let got: Vec<(String, i64)> = f[0].msg.fields().into_iter().map(|(k, v)| (k.into(), v)).collect();
                    assert_eq!(&got, fields, "{name}");
                    assert_eq!(&encode(*seq, &f[0].msg), bytes, "{name}: encode");
                }
                Vector::Bad {
                    name,
                    crc,
                    framing,
                    bytes,
                } => {
                    let mut d = Decoder::new();
                    assert!(d.feed(bytes).is_empty(), "{name}");
                    assert_eq!(
                        (d.counters.crc_errors, d.counters.framing_errors),
                        (*crc, *framing),
                        "{name}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_single_bit_corruption_is_rejected_and_the_next_frame_survives() {
        let vs = vectors();
        let ping = encode(6, &Message::Ping);
        let mut cases = 0;
        for v in &vs {
            let Vector::Ok { name, bytes, .. } = v else { continue };
            for i in 0..bytes.len() {
                for bit in 0..8 {
                    let mut b = bytes.clone();
                    b[i] ^= 1 << bit;
                    b.extend_from_slice(&ping);
                    let mut d = Decoder::new();
                    let f = d.feed(&b);
                    assert_eq!(f.len(), 1, "{name} byte {i} bit {bit}: {f:?}");
                    assert_eq!(f[0].msg, Message::Ping, "{name} byte {i} bit {bit}");
                    assert!(d.counters.crc_errors + d.counters.framing_errors >= 1);
                    cases += 1;
                }
            }
        }
        assert!(cases > 1500, "{cases}");
    }

    #[test]
    fn permille_mapping_matches_the_firmware_and_clamps() {
        assert_eq!(permille_to_us(0, 1000, 1500, 2000), 1500);
        assert_eq!(permille_to_us(500, 1100, 1480, 1900), 1690);
        assert_eq!(permille_to_us(-500, 1100, 1480, 1900), 1290);
        assert_eq!(permille_to_us(i16::MAX, 1100, 1480, 1900), 1900);
        assert_eq!(permille_to_us(i16::MIN, 1100, 1480, 1900), 1100);
        assert_eq!(to_permille(0.25), 250);
        assert_eq!(to_permille(f64::NAN), 0);
        assert_eq!(to_permille(-7.0), -1000);
    }

    fn any_message() -> impl Strategy<Value = Message> {
        prop_oneof![
            any::<u8>().prop_map(|protocol_version| Message::Hello { protocol_version }),
            (any::<i16>(), any::<i16>()).prop_map(|(steer, throttle)| Message::Drive { steer, throttle }),
            Just(Message::Arm),
            Just(Message::Ping),
            proptest::collection::vec(any::<u8>(), 26).prop_map(|b| Message::from_payload(id::TELEMETRY, &b).unwrap()),
            proptest::collection::vec(any::<u8>(), 15).prop_map(|b| Message::from_payload(id::CONFIG_SET, &b).unwrap()),
        ]
    }

    /// Number of proptest cases: `RCCAR_FUZZ_CASES` (e.g. 1000000 for the long run), else 2000.
    fn cases() -> u32 {
        std::env::var("RCCAR_FUZZ_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(2000)
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, ..ProptestConfig::default() })]

        /// Fuzz: arbitrary bytes never panic, and every frame the decoder returns re-encodes to
        /// a CRC-valid frame (it never invents a frame that the framing rules would refuse).
        #[test]
        fn decoder_survives_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let mut d = Decoder::new();
            for f in d.feed(&bytes) {
                let e = encode(f.seq, &f.msg);
                prop_assert_eq!(Message::from_payload(f.msg.id(), &e[4..e.len() - 2]), Some(f.msg));
            }
            prop_assert!(d.buf.len() < MAX_FRAME);
        }

        /// Valid frames surrounded by garbage all come out, in order.
        #[test]
        fn frames_in_garbage_are_recovered(
            msgs in proptest::collection::vec((any_message(), any::<u8>()), 1..5),
            garbage in proptest::collection::vec(proptest::collection::vec(prop_oneof![Just(START), any::<u8>()], 0..40), 5),
        ) {
            let mut stream = Vec::new();
            for (i, (m, seq)) in msgs.iter().enumerate() {
                stream.extend_from_slice(&garbage[i]);
                stream.extend_from_slice(&encode(*seq, m));
            }
            stream.extend_from_slice(&[0u8; MAX_FRAME]);
            let got: Vec<Frame> = Decoder::new().feed(&stream);
            let want: Vec<Frame> = msgs.iter().map(|&(msg, seq)| Frame { seq, msg }).collect();
            // a garbage START can, with probability ~2^-16 per candidate, form a valid frame;
            // the wanted frames must still all be there, in order
            let mut w = 0;
            for f in &got {
                if w < want.len() && *f == want[w] { w += 1; }
            }
            prop_assert_eq!(w, want.len(), "got {:?}", got);
        }
    }
}
