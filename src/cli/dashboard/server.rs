//! The dashboard's HTTP server: std only (no HTTP crate, no async runtime), one short-lived
//! thread per connection, one request per connection.
//!
//! - `GET /` the page; `GET /stream.mjpg` the annotated camera view and the bird's-eye view
//!   as MJPEG (`multipart/x-mixed-replace`): each viewer is sent the newest JPEG when it is
//!   ready for one, older ones are skipped (never queued); a viewer that cannot take a frame
//!   within 2 s is dropped.
//! - `GET /api/state?since=T` the newest state and the plot samples after frame time `T`.
//! - `POST /api/{estop,release,arm,disarm,heartbeat,set,save}`, and in the simulator
//!   `POST /api/sim/{pause,resume,step,reset,place}`.
//!
//! Limits: request head 8 KiB and 3 s (slow clients are answered 408 and closed), bodies
//! 4 KiB (413), 128 connections (503), `dashboard.max_viewers` streams (503). One hub thread
//! takes the loop's snapshots, annotates and encodes them once for every viewer.
//!
//! Access: on 127.0.0.1 / ::1 everything is open to the machine's own users. On any other
//! address every request but the page and `GET /api/state` needs the token (`X-Token` header
//! or `?token=`), else 401; the e-stop needs none from a loopback client. The e-stop handler
//! touches only atomics (no lock the loop or the hub holds), so it works while everything
//! else is stuck.

use super::Sent;
use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use rccar::config::Config;
use rccar::dashboard::{self, Control, ControlSender, Live, PlaceRequest, PlotPoint, SetRequest, Snapshot};
use rccar::drive::{Actor, Arming, Latest, StopSignal};
use rccar::sim::world::{lock, SharedWorld};
use serde_json::{json, Value};
use std::collections::{BTreeMap, VecDeque};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

const PAGE: &str = include_str!("page.html");
const MAX_HEAD: usize = 8192;
const HEAD_DEADLINE: Duration = Duration::from_secs(3);
const MAX_CONNECTIONS: usize = 128;
/// Plot history kept for the page, seconds of frame time.
const HISTORY_S: f64 = 30.0;

/// What the server needs from the run.
pub struct Options {
    /// Address to listen on.
    pub listen: String,
    /// The run's configuration (the starting values and their ranges).
    pub cfg: Config,
    /// `config/local.toml` (or `--local`): where "save" writes.
    pub local: PathBuf,
    /// The loop's snapshots.
    pub slot: Arc<Latest<Arc<Snapshot>>>,
    /// The loop's per-frame counters.
    pub live: Arc<Live>,
    /// The loop's inbox.
    pub tx: ControlSender,
    /// Arming and e-stop.
    pub arm: Arc<Arming>,
    /// What the sink sent.
    pub sent: Arc<Sent>,
    /// The simulator's world (sim controls), `None` on the car.
    pub world: Option<SharedWorld>,
    /// The run's stop signal (the server's threads end with it).
    pub stop: StopSignal,
}

/// The newest state for `GET /api/state`.
#[derive(Default)]
struct View {
    snap: Option<Arc<Snapshot>>,
    history: VecDeque<PlotPoint>,
}

/// The newest JPEG and its number.
#[derive(Default)]
struct Jpeg {
    bytes: Arc<Vec<u8>>,
    version: u64,
}

struct Shared {
    cfg: Mutex<Config>,
    changed: Mutex<BTreeMap<String, f64>>,
    local: PathBuf,
    tx: ControlSender,
    arm: Arc<Arming>,
    sent: Arc<Sent>,
    track_length: Option<f64>,
    need_token: bool,
    token: String,
    view: Mutex<View>,
    jpeg: Mutex<Jpeg>,
    jpeg_cv: Condvar,
    heartbeat_ms: u64,
    last_heartbeat_ms: AtomicU64,
    armed_by_page: AtomicBool,
    viewers: AtomicUsize,
    max_viewers: usize,
    connections: AtomicUsize,
    frames_sent: AtomicU64,
    closed: AtomicBool,
    live: Arc<Live>,
}

/// The running server; its threads end when the run's stop signal is set or it is dropped.
pub struct Server {
    shared: Arc<Shared>,
    slot: Arc<Latest<Arc<Snapshot>>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shared.closed.store(true, Ordering::SeqCst);
        self.slot.close();
        self.shared.jpeg_cv.notify_all();
    }
}

fn is_local_bind(addr: &SocketAddr) -> bool {
    match addr.ip() {
        std::net::IpAddr::V4(ip) => ip == std::net::Ipv4Addr::LOCALHOST,
        std::net::IpAddr::V6(ip) => ip == std::net::Ipv6Addr::LOCALHOST,
    }
}

fn random_token() -> String {
    let mut b = [0u8; 16];
    if std::fs::File::open("/dev/urandom").and_then(|mut f| f.read_exact(&mut b)).is_err() {
        // No /dev/urandom: the clock's nanoseconds and the process id (still unguessable
        // enough for a classroom, and the token is printed anyway).
        let n = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let x = n ^ (u128::from(std::process::id()) << 64);
        b.copy_from_slice(&x.to_le_bytes());
    }
    b.iter().map(|v| format!("{v:02x}")).collect()
}

impl Server {
    /// Binds and starts the accept, hub and heartbeat threads.
    pub fn start(o: Options) -> Result<Server> {
        let addr: SocketAddr = o
            .listen
            .parse()
            .with_context(|| format!("--listen `{}`: expected IP:PORT, e.g. 127.0.0.1:8080", o.listen))?;
        let listener = TcpListener::bind(addr).with_context(|| format!("dashboard: cannot listen on {addr}"))?;
        let bound = listener.local_addr()?;
        let need_token = !is_local_bind(&bound);
        let token = if o.cfg.dashboard.token.is_empty() {
            random_token()
        } else {
            o.cfg.dashboard.token.clone()
        };
        let track_length = o.world.as_ref().map(|w| lock(w).scene().track.length);
        let shared = Arc::new(Shared {
            heartbeat_ms: o.cfg.dashboard.heartbeat_ms,
            max_viewers: o.cfg.dashboard.max_viewers as usize,
            cfg: Mutex::new(o.cfg),
            changed: Mutex::new(BTreeMap::new()),
            local: o.local,
            tx: o.tx,
            arm: o.arm,
            sent: o.sent,
            track_length,
            need_token,
            token,
            view: Mutex::new(View::default()),
            jpeg: Mutex::new(Jpeg::default()),
            jpeg_cv: Condvar::new(),
            last_heartbeat_ms: AtomicU64::new(0),
            armed_by_page: AtomicBool::new(false),
            viewers: AtomicUsize::new(0),
            connections: AtomicUsize::new(0),
            frames_sent: AtomicU64::new(0),
            closed: AtomicBool::new(false),
            live: o.live,
        });
        if need_token {
            println!(
                "dashboard: http://{bound}/?token={}  (not localhost: the token is needed to control or watch; without it the page is read-only)",
                shared.token
            );
        } else {
            println!("dashboard: http://{bound}/");
        }
        {
            let sh = shared.clone();
            std::thread::Builder::new()
                .name("dash-accept".into())
                .spawn(move || accept_loop(listener, sh))?;
        }
        {
            let sh = shared.clone();
            let slot = o.slot.clone();
            std::thread::Builder::new().name("dash-hub".into()).spawn(move || hub(slot, sh))?;
        }
        {
            let sh = shared.clone();
            let stop = o.stop.clone();
            std::thread::Builder::new()
                .name("dash-watchdog".into())
                .spawn(move || watchdog(sh, stop))?;
        }
        Ok(Server { shared, slot: o.slot })
    }
}

/// The web's threads yield to the control loop: nice 10 for this thread (Linux; elsewhere a
/// no-op). A busy page or a flood of requests then takes CPU only when the loop does not.
fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: plain system calls on the calling thread's own id; no memory is passed.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, 10);
    }
}

fn now_ms(sh: &Shared) -> u64 {
    (sh.sent.now() * 1e3) as u64
}

/// Disarms when the page that armed the car stops sending heartbeats.
fn watchdog(sh: Arc<Shared>, stop: StopSignal) {
    // The watchdog disarms the car: it keeps normal priority.
    while !sh.closed.load(Ordering::SeqCst) && !stop.is_set() {
        std::thread::sleep(Duration::from_millis(20));
        if sh.heartbeat_ms == 0 || !sh.armed_by_page.load(Ordering::SeqCst) || !sh.arm.is_armed() {
            continue;
        }
        let age = now_ms(&sh).saturating_sub(sh.last_heartbeat_ms.load(Ordering::SeqCst));
        if age > sh.heartbeat_ms {
            sh.arm.disarm(Actor::Heartbeat);
            sh.armed_by_page.store(false, Ordering::SeqCst);
            let msg = format!(
                "disarmed: no heartbeat from the dashboard for {age} ms (limit {} ms) at wall {:.3} s",
                sh.heartbeat_ms,
                sh.sent.now()
            );
            println!("dashboard: {msg}");
            sh.tx.send(Control::Note(msg));
        }
    }
}

/// Takes the loop's snapshots, keeps the plot history, renders and encodes the stream image.
fn hub(slot: Arc<Latest<Arc<Snapshot>>>, sh: Arc<Shared>) {
    lower_priority();
    while !sh.closed.load(Ordering::SeqCst) {
        let Some(snap) = slot.wait_take(Duration::from_millis(200)) else {
            if slot.is_closed() {
                break;
            }
            continue;
        };
        {
            let mut v = sh.view.lock().unwrap_or_else(|e| e.into_inner());
            if let Some(first) = snap.points.first() {
                // A restarted clock (a new run) clears the plots.
                if v.history.back().is_some_and(|b| first.t < b.t) {
                    v.history.clear();
                }
            }
            v.history.extend(snap.points.iter().copied());
            let newest = v.history.back().map_or(0.0, |p| p.t);
            while v.history.front().is_some_and(|p| p.t < newest - HISTORY_S) {
                v.history.pop_front();
            }
            v.snap = Some(snap.clone());
        }
        if sh.viewers.load(Ordering::SeqCst) == 0 {
            continue; // nobody watches: no JPEG work
        }
        let img = render(&snap);
        let mut buf = Vec::with_capacity(32 * 1024);
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, 75);
        if img.write_with_encoder(enc).is_err() {
            continue;
        }
        let mut j = sh.jpeg.lock().unwrap_or_else(|e| e.into_inner());
        j.bytes = Arc::new(buf);
        j.version += 1;
        drop(j);
        sh.jpeg_cv.notify_all();
    }
    sh.closed.store(true, Ordering::SeqCst);
    sh.jpeg_cv.notify_all();
}

/// The annotated camera frame and, to its right, the bird's-eye view (grey, the binary image
/// in red, the column histogram in yellow, the lines found in green) at the same height.
fn render(s: &Snapshot) -> RgbImage {
    let ann = rccar::annotate::annotate(&s.image, &s.roi, &s.homography, &s.lane_images, &s.lane, &s.command);
    let li = &s.lane_images;
    let (bw, bh) = li.bird.dimensions();
    let h = ann.height();
    let scale = h as f64 / bh.max(1) as f64;
    let w2 = ((bw as f64 * scale).round() as u32).max(1);
    let mut out = RgbImage::new(ann.width() + w2, h);
    image::imageops::replace(&mut out, &ann, 0, 0);
    let hist_max = li.hist.iter().copied().max().unwrap_or(1).max(1) as f64;
    for y in 0..h {
        let sy = ((y as f64 / scale) as u32).min(bh - 1);
        for x in 0..w2 {
            let sx = ((x as f64 / scale) as u32).min(bw - 1);
            let g = li.bird.get_pixel(sx, sy)[0];
            let on = li.binary.dimensions() == (bw, bh) && li.binary.get_pixel(sx, sy)[0] > 0;
            let px = if on { Rgb([255, g / 3, g / 3]) } else { Rgb([g, g, g]) };
            out.put_pixel(ann.width() + x, y, px);
        }
    }
    // Histogram along the bottom, a quarter of the height at its highest column.
    if li.hist.len() == bw as usize {
        for x in 0..w2 {
            let sx = ((x as f64 / scale) as usize).min(li.hist.len() - 1);
            let bar = (li.hist[sx] as f64 / hist_max * h as f64 / 4.0) as u32;
            for y in h.saturating_sub(bar)..h {
                out.put_pixel(ann.width() + x, y, Rgb([255, 220, 0]));
            }
        }
    }
    for (c, col) in [
        (s.lane.p_left, Rgb([255, 40, 40])),
        (s.lane.p_right, Rgb([255, 40, 40])),
        (s.lane.lane_center, Rgb([40, 230, 60])),
    ] {
        if let Some(c) = c {
            let x = (c * scale).round();
            if x >= 0.0 && (x as u32) < w2 {
                for y in 0..h {
                    out.put_pixel(ann.width() + x as u32, y, col);
                }
            }
        }
    }
    out
}

fn accept_loop(listener: TcpListener, sh: Arc<Shared>) {
    for conn in listener.incoming() {
        if sh.closed.load(Ordering::SeqCst) {
            break;
        }
        let Ok(mut stream) = conn else { continue };
        if sh.connections.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
            sh.connections.fetch_sub(1, Ordering::SeqCst);
            let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
            let _ = respond(&mut stream, 503, "text/plain", b"too many connections\n");
            continue;
        }
        let sh2 = sh.clone();
        let spawned = std::thread::Builder::new()
            .name("dash-conn".into())
            .stack_size(256 * 1024)
            .spawn(move || {
                handle(stream, &sh2);
                sh2.connections.fetch_sub(1, Ordering::SeqCst);
            });
        if spawned.is_err() {
            sh.connections.fetch_sub(1, Ordering::SeqCst);
        }
    }
}

/// One parsed request.
struct Request {
    method: String,
    path: String,
    query: BTreeMap<String, String>,
    headers: BTreeMap<String, String>,
    body: Vec<u8>,
    peer: Option<SocketAddr>,
}

/// Why a request could not be read: the status to answer with.
struct Refuse(u16, &'static str);

fn read_request(stream: &mut TcpStream) -> Result<Request, Refuse> {
    let start = Instant::now();
    let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let head_end = loop {
        if let Some(i) = find(&buf, b"\r\n\r\n") {
            break i;
        }
        if buf.len() > MAX_HEAD {
            return Err(Refuse(431, "request head larger than 8 KiB"));
        }
        if start.elapsed() > HEAD_DEADLINE {
            return Err(Refuse(408, "request head not complete within 3 s"));
        }
        match stream.read(&mut chunk) {
            Ok(0) => return Err(Refuse(0, "closed")),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => return Err(Refuse(0, "read error")),
        }
    };
    let head = std::str::from_utf8(&buf[..head_end]).map_err(|_| Refuse(400, "request head is not UTF-8"))?;
    let mut lines = head.split("\r\n");
    let first = lines.next().unwrap_or("");
    let mut parts = first.split(' ');
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(Refuse(400, "bad request line"));
    };
    if !version.starts_with("HTTP/1.") || parts.next().is_some() {
        return Err(Refuse(400, "bad request line"));
    }
    let mut headers = BTreeMap::new();
    for l in lines {
        let Some((k, v)) = l.split_once(':') else {
            return Err(Refuse(400, "bad header line"));
        };
        headers.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
    }
    if headers.contains_key("transfer-encoding") {
        return Err(Refuse(411, "chunked bodies are not accepted; send Content-Length"));
    }
    let len: usize = match headers.get("content-length") {
        None => 0,
        Some(v) => v.parse().map_err(|_| Refuse(400, "bad Content-Length"))?,
    };
    if len > dashboard::MAX_BODY {
        return Err(Refuse(413, "body larger than 4096 bytes"));
    }
    let mut body = buf[head_end + 4..].to_vec();
    if body.len() > len {
        return Err(Refuse(400, "more body than Content-Length"));
    }
    while body.len() < len {
        if start.elapsed() > HEAD_DEADLINE {
            return Err(Refuse(408, "body not complete within 3 s"));
        }
        match stream.read(&mut chunk) {
            Ok(0) => return Err(Refuse(400, "body shorter than Content-Length")),
            Ok(n) => body.extend_from_slice(&chunk[..n]),
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => return Err(Refuse(0, "read error")),
        }
        if body.len() > len {
            return Err(Refuse(400, "more body than Content-Length"));
        }
    }
    let (path, q) = target.split_once('?').unwrap_or((target, ""));
    let mut query = BTreeMap::new();
    for kv in q.split('&').filter(|s| !s.is_empty()) {
        let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
        query.insert(k.to_string(), v.to_string());
    }
    Ok(Request {
        method: method.to_string(),
        path: path.to_string(),
        query,
        headers,
        body,
        peer: stream.peer_addr().ok(),
    })
}

fn find(h: &[u8], n: &[u8]) -> Option<usize> {
    h.windows(n.len()).position(|w| w == n)
}

fn reason(code: u16) -> &'static str {
    match code {
        200 => "OK",
        400 => "Bad Request",
        401 => "Unauthorized",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    }
}

fn respond(s: &mut TcpStream, code: u16, ctype: &str, body: &[u8]) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {code} {}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        reason(code),
        body.len()
    );
    s.write_all(head.as_bytes())?;
    s.write_all(body)?;
    s.flush()
}

fn json_reply(s: &mut TcpStream, code: u16, v: &Value) {
    let _ = respond(s, code, "application/json", v.to_string().as_bytes());
}

fn error_reply(s: &mut TcpStream, code: u16, msg: &str) {
    json_reply(s, code, &json!({ "error": msg }));
}

/// Constant-time comparison (the token's length is not secret).
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn authorized(sh: &Shared, r: &Request) -> bool {
    if !sh.need_token {
        return true;
    }
    let given = r.headers.get("x-token").or_else(|| r.query.get("token"));
    given.is_some_and(|t| same(t, &sh.token))
}

fn handle(mut stream: TcpStream, sh: &Shared) {
    let _ = stream.set_write_timeout(Some(Duration::from_secs(2)));
    let _ = stream.set_nodelay(true);
    let r = match read_request(&mut stream) {
        Ok(r) => r,
        Err(Refuse(0, _)) => return,
        Err(Refuse(code, msg)) => {
            error_reply(&mut stream, code, msg);
            return;
        }
    };
    let path = r.path.as_str();
    // Everything but the e-stop yields to the control loop from here on.
    if path != "/api/estop" {
        lower_priority();
    }
    let who = r.peer.map_or("?".to_string(), |p| p.ip().to_string());
    // Only exact routes exist: `..`, `%2e`, `//` and the like are simply not found.
    let get = r.method == "GET";
    let post = r.method == "POST";
    match path {
        "/" | "/index.html" if get => {
            let _ = respond(&mut stream, 200, "text/html; charset=utf-8", PAGE.as_bytes());
            return;
        }
        "/api/state" if get => {
            let since = match r.query.get("since").map(|s| s.parse::<f64>()) {
                None => f64::NEG_INFINITY,
                Some(Ok(t)) if t.is_finite() => t,
                Some(_) => {
                    error_reply(&mut stream, 400, "since: expected a finite number of seconds");
                    return;
                }
            };
            let v = state_json(sh, since, authorized(sh, &r));
            json_reply(&mut stream, 200, &v);
            return;
        }
        "/api/estop" if post => {
            // Atomics only: no lock that the loop, the hub or a stuck handler could hold.
            let local_peer = r.peer.is_some_and(|p| p.ip().is_loopback());
            if !(local_peer || authorized(sh, &r)) {
                error_reply(&mut stream, 401, "token required");
                return;
            }
            sh.sent.mark_estop();
            sh.arm.estop(Actor::Page);
            sh.armed_by_page.store(false, Ordering::SeqCst);
            let _ = respond(&mut stream, 200, "application/json", b"{\"estop\":true}");
            println!("dashboard: EMERGENCY STOP from {who}");
            sh.tx.send(Control::Note(format!(
                "EMERGENCY STOP from dashboard {who} at wall {:.3} s",
                sh.sent.estop_clock_s.get()
            )));
            return;
        }
        _ => {}
    }
    let known_get = matches!(path, "/stream.mjpg");
    let known_post = matches!(
        path,
        "/api/release"
            | "/api/arm"
            | "/api/disarm"
            | "/api/heartbeat"
            | "/api/set"
            | "/api/save"
            | "/api/sim/pause"
            | "/api/sim/resume"
            | "/api/sim/step"
            | "/api/sim/reset"
            | "/api/sim/place"
    );
    let known = known_get || known_post || matches!(path, "/" | "/index.html" | "/api/state" | "/api/estop");
    if !known {
        error_reply(&mut stream, 404, "no such page");
        return;
    }
    if (known_get && !get) || (known_post && !post) || (!known_get && !known_post) {
        error_reply(&mut stream, 405, "wrong method");
        return;
    }
    if !authorized(sh, &r) {
        error_reply(&mut stream, 401, "token required (X-Token header or ?token=)");
        return;
    }
    if known_get {
        stream_mjpeg(stream, sh);
        return;
    }
    let note = |what: &str| format!("{what} from dashboard {who} at wall {:.3} s", sh.sent.now());
    match path {
        "/api/release" => {
            sh.arm.release(Actor::Page);
            sh.tx.send(Control::Note(note("e-stop released")));
            json_reply(&mut stream, 200, &json!({"estop": false}));
        }
        "/api/arm" => {
            sh.last_heartbeat_ms.store(now_ms(sh), Ordering::SeqCst);
            match sh.arm.arm(Actor::Page) {
                Ok(()) => {
                    sh.armed_by_page.store(true, Ordering::SeqCst);
                    sh.tx.send(Control::Note(note("armed")));
                    json_reply(&mut stream, 200, &json!({"armed": true}));
                }
                Err(why) => error_reply(&mut stream, 409, &why.to_string()),
            }
        }
        "/api/disarm" => {
            sh.arm.disarm(Actor::Page);
            sh.armed_by_page.store(false, Ordering::SeqCst);
            sh.tx.send(Control::Note(note("disarmed")));
            json_reply(&mut stream, 200, &json!({"armed": false}));
        }
        "/api/heartbeat" => {
            sh.last_heartbeat_ms.store(now_ms(sh), Ordering::SeqCst);
            json_reply(&mut stream, 200, &json!({"armed": sh.arm.is_armed()}));
        }
        "/api/set" => {
            let req: SetRequest = match dashboard::parse_body(&r.body) {
                Ok(q) => q,
                Err(e) => return error_reply(&mut stream, 400, &e.to_string()),
            };
            let mut cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner());
            match dashboard::validate_set(&cfg, &req.key, req.value) {
                Ok(new) => {
                    let queued = sh.tx.send(Control::Set {
                        key: req.key.clone(),
                        value: req.value,
                        note: format!("dashboard {who} at wall {:.3} s", sh.sent.now()),
                    });
                    if !queued {
                        drop(cfg);
                        return error_reply(&mut stream, 503, "the loop is not taking changes (inbox full)");
                    }
                    *cfg = new;
                    drop(cfg);
                    sh.changed
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .insert(req.key.clone(), req.value);
                    json_reply(&mut stream, 200, &json!({"key": req.key, "value": req.value}));
                }
                Err(e) => error_reply(&mut stream, 400, &e.to_string()),
            }
        }
        "/api/save" => {
            if !r.body.is_empty() && r.body.iter().any(|b| !b.is_ascii_whitespace()) {
                // No parameters: the file is the one given at start (--local), never the client's.
                if serde_json::from_slice::<serde_json::Map<String, Value>>(&r.body).map_or(true, |m| !m.is_empty()) {
                    return error_reply(&mut stream, 400, "save takes no parameters");
                }
            }
            let keys: Vec<(String, f64)> = sh
                .changed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .iter()
                .map(|(k, v)| (k.clone(), *v))
                .collect();
            match dashboard::local_toml::save(&sh.local, &keys) {
                Ok(()) => {
                    sh.tx.send(Control::Note(note(&format!(
                        "saved {} to {}",
                        keys.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", "),
                        sh.local.display()
                    ))));
                    json_reply(
                        &mut stream,
                        200,
                        &json!({"saved": keys.iter().map(|(k, _)| k.clone()).collect::<Vec<_>>(), "file": sh.local.display().to_string()}),
                    )
                }
                Err(e) => error_reply(&mut stream, 500, &e.to_string()),
            }
        }
        p if p.starts_with("/api/sim/") => {
            let Some(len) = sh.track_length else {
                return error_reply(&mut stream, 404, "not a simulation");
            };
            let c = match p {
                "/api/sim/pause" => Control::Pause,
                "/api/sim/resume" => Control::Resume,
                "/api/sim/step" => Control::Step,
                "/api/sim/reset" => Control::Reset,
                _ => {
                    let q: PlaceRequest = match dashboard::parse_body(&r.body) {
                        Ok(q) => q,
                        Err(e) => return error_reply(&mut stream, 400, &e.to_string()),
                    };
                    if !(q.s.is_finite() && q.s >= 0.0 && q.s <= len) {
                        return error_reply(
                            &mut stream,
                            400,
                            &format!("s = {} is out of range (allowed: 0 ..= {len:.3}, the track's length in metres)", q.s),
                        );
                    }
                    Control::PlaceAt(q.s)
                }
            };
            if sh.tx.send(c) {
                json_reply(&mut stream, 200, &json!({"ok": true}));
            } else {
                error_reply(&mut stream, 503, "the loop is not taking commands (inbox full)");
            }
        }
        _ => error_reply(&mut stream, 404, "no such page"),
    }
}

fn opt(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn state_json(sh: &Shared, since: f64, authorized: bool) -> Value {
    let (snap, points) = {
        let v = sh.view.lock().unwrap_or_else(|e| e.into_inner());
        let pts: Vec<PlotPoint> = v.history.iter().filter(|p| p.t > since).copied().collect();
        (v.snap.clone(), pts)
    };
    let s = &sh.sent;
    let mut o = json!({
        "read_only": !authorized,
        "sim": sh.track_length.is_some(),
        "track_length": sh.track_length,
        "armed": sh.arm.is_armed(),
        "estop": sh.arm.is_estopped(),
        "viewers": sh.viewers.load(Ordering::SeqCst),
        "stream_frames": sh.frames_sent.load(Ordering::SeqCst),
        "wall_s": s.now(),
        "epoch_ms": std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64() * 1e3),
        "sent": {"throttle": opt(s.throttle.get()), "steer": opt(s.steer.get()), "wall_s": opt(s.clock_s.get()), "sim_s": opt(s.frame_s.get())},
        "estop_timing": {
            "pressed_wall_s": opt(s.estop_clock_s.get()), "pressed_sim_s": opt(s.estop_frame_s.get()),
            "neutral_clock_s": opt(s.neutral_clock_s.get()), "neutral_frame_s": opt(s.neutral_frame_s.get()),
        },
        "points": points,
        "changed": *sh.changed.lock().unwrap_or_else(|e| e.into_inner()),
        "ranges": {
            "steering.kp": [0.0, 20.0], "steering.ki": [0.0, 20.0], "steering.kd": [0.0, 5.0],
            "throttle.base": [0.0, 1.0], "throttle.min": [0.0, 1.0],
        },
    });
    if let Some(sn) = snap {
        let r = &sn.record;
        // Exact between snapshots: the loop's own counters.
        o["frame"] = json!(sh.live.frame.load(Ordering::SeqCst));
        o["t"] = json!(sh.live.time_s());
        o["snapshot_frame"] = json!(r.frame);
        o["error"] = json!(r.error);
        o["steer"] = json!(r.steer);
        o["throttle"] = json!(r.throttle);
        o["speed"] = json!(r.speed_est_mps);
        o["status"] = json!(r.status);
        o["behaviour"] = json!(r.behaviour);
        o["latency_ms"] = json!(r.latency_ms);
        o["period_ms"] = json!(r.period_ms);
        o["paused"] = json!(sh.live.paused.load(Ordering::SeqCst));
        o["dropped_snapshots"] = json!(sn.dropped);
        o["objects"] = json!(sn.objects);
        o["transition"] = match &sn.last_transition {
            Some((t, tr)) => json!({"t": t, "from": tr.from, "to": tr.to, "reason": tr.reason}),
            None => Value::Null,
        };
        o["values"] = Value::Object(sn.values.iter().map(|(k, v)| (k.clone(), json!(v))).collect());
    }
    o
}

/// MJPEG to one viewer: the newest JPEG whenever the viewer is ready for one.
fn stream_mjpeg(mut s: TcpStream, sh: &Shared) {
    if sh.viewers.fetch_add(1, Ordering::SeqCst) >= sh.max_viewers {
        sh.viewers.fetch_sub(1, Ordering::SeqCst);
        error_reply(&mut s, 503, "too many viewers");
        return;
    }
    let head = "HTTP/1.1 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=rccarframe\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n";
    let mut last = 0u64;
    let mut ok = s.write_all(head.as_bytes()).is_ok();
    while ok && !sh.closed.load(Ordering::SeqCst) {
        let (bytes, ver) = {
            let mut j = sh.jpeg.lock().unwrap_or_else(|e| e.into_inner());
            let deadline = Instant::now() + Duration::from_secs(1);
            while j.version == last && !sh.closed.load(Ordering::SeqCst) {
                let now = Instant::now();
                if now >= deadline {
                    break;
                }
                j = sh.jpeg_cv.wait_timeout(j, deadline - now).unwrap_or_else(|e| e.into_inner()).0;
            }
            (j.bytes.clone(), j.version)
        };
        if ver == last || bytes.is_empty() {
            continue; // paused or no frames yet: keep the connection, check closed again
        }
        last = ver;
        let part = format!(
            "--rccarframe\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
            bytes.len()
        );
        ok = s.write_all(part.as_bytes()).is_ok() && s.write_all(&bytes).is_ok() && s.write_all(b"\r\n").is_ok() && s.flush().is_ok();
        if ok {
            sh.frames_sent.fetch_add(1, Ordering::Relaxed);
        }
    }
    sh.viewers.fetch_sub(1, Ordering::SeqCst);
}
