//! Connections: the bound on their number, the reserve kept for the e-stop, and the
//! deadlines that close idle and slow clients ([`GuardedIo`]); the loop that accepts them is
//! [`super::accept`]. Imports none of the server's other modules.
//!
//! - **Bound**: at most [`MAX_CONNECTIONS`] (1,024) connections, fewer when the open-file
//!   limit is low (see [`Limits::for_nofile`]). At the bound a new connection closes the one
//!   that has waited longest for a request head (an idle or slow client, never a request being
//!   handled or a stream), so the newest client — someone pressing the e-stop — gets in.
//! - **Reserve**: when nothing can be closed (every connection inside a handler or a stream) a
//!   new connection takes one of [`RESERVE`] (64) extra slots that serve only `POST /api/estop`
//!   and must send it within 1 s; past those it is answered 503 and closed.
//! - **Deadlines** ([`GuardedIo`]): a request head must be complete within 3 s of the server
//!   starting to wait for it (408, closed; an idle keep-alive connection is closed silently);
//!   a connection whose socket takes no byte for 2 s (a viewer or a client that stopped
//!   reading) is closed.
//! - **Open files**: the soft `RLIMIT_NOFILE` is raised to the hard limit at start (a Pi's soft
//!   limit is 1024). Should `accept` still fail for lack of descriptors (EMFILE/ENFILE), the
//!   longest-waiting idle connection is closed and `accept` tried again 10 ms later; the new
//!   client waits in the kernel's listen queue meanwhile (logged at most once a second).

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio::sync::Notify;
use tokio::time::Sleep;

/// Connections served at most (before the e-stop's reserve).
pub const MAX_CONNECTIONS: usize = 1024;
/// Extra connections kept for the e-stop when no connection can be closed for a new one.
pub const RESERVE: usize = 64;
/// Descriptors left for everything else the process opens (camera, serial port, files).
const OTHER_FILES: u64 = 128;
/// Largest request head, bytes (hyper answers 431 past it).
pub const MAX_HEAD: usize = 8192;
/// A request head must be complete within this long of the server waiting for it.
pub const HEAD_DEADLINE: Duration = Duration::from_secs(3);
/// … on a reserve connection (the e-stop only).
const RESERVE_HEAD_DEADLINE: Duration = Duration::from_secs(1);
/// A socket that takes no byte for this long is closed.
pub const WRITE_STALL: Duration = Duration::from_secs(2);

/// The connection bound in force.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Connections served.
    pub max: usize,
    /// Extra e-stop-only connections.
    pub reserve: usize,
    /// `max` is below [`MAX_CONNECTIONS`] for lack of open files.
    pub reduced: bool,
}

impl Limits {
    /// 1,024 connections, or what the open-file limit leaves after the reserve and 128 other
    /// files (at least 16).
    pub fn for_nofile(nofile: Option<u64>) -> Limits {
        let room = nofile.map_or(u64::MAX, |n| n.saturating_sub(OTHER_FILES + RESERVE as u64));
        let max = (MAX_CONNECTIONS as u64).min(room).max(16) as usize;
        Limits {
            max,
            reserve: RESERVE,
            reduced: max < MAX_CONNECTIONS,
        }
    }
}

/// Raises the soft open-file limit to the hard one; returns the soft limit now in force.
pub fn raise_nofile_limit() -> Option<u64> {
    #[cfg(unix)]
    // SAFETY: getrlimit/setrlimit with a pointer to a local, initialised struct.
    unsafe {
        let mut r = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut r) != 0 {
            return None;
        }
        // An unlimited hard limit cannot be the soft one for files: 1 Mi is plenty.
        let want = if r.rlim_max == libc::RLIM_INFINITY {
            1 << 20
        } else {
            r.rlim_max
        };
        if want > r.rlim_cur {
            let new = libc::rlimit {
                rlim_cur: want,
                rlim_max: r.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &new) == 0 {
                r.rlim_cur = want;
            }
        }
        #[allow(clippy::useless_conversion)] // rlim_t is u32 on 32-bit ARM
        Some(u64::from(r.rlim_cur))
    }
    #[cfg(not(unix))]
    None
}

/// What a connection is doing (for the eviction choice and the deadlines).
pub const WAITING: u8 = 0;
/// A handler runs.
pub const HANDLING: u8 = 1;
/// An MJPEG stream is being sent.
pub const STREAMING: u8 = 2;

/// One connection's state, shared by its task, its socket wrapper and the accept loop.
pub struct ConnCtl {
    id: u64,
    /// The client's address.
    pub peer: std::net::SocketAddr,
    /// Serves only the e-stop (taken when the bound was reached and nothing could be closed).
    pub reserve: bool,
    state: AtomicU8,
    /// When the state was entered, ms since [`Conns::t0`].
    since_ms: AtomicU64,
    /// Requests handled on this connection.
    requests: AtomicU64,
    /// Some bytes of the awaited head have arrived.
    head_bytes: AtomicBool,
    kill: Notify,
    t0: Instant,
}

impl ConnCtl {
    fn now_ms(&self) -> u64 {
        self.t0.elapsed().as_millis() as u64
    }
    /// A request head was read: its handler runs.
    pub fn handling(&self) {
        self.requests.fetch_add(1, Ordering::SeqCst);
        self.set(HANDLING);
    }
    /// The handler answered; the response is being written, then the next head awaited.
    pub fn waiting(&self) {
        if self.state.load(Ordering::SeqCst) != STREAMING {
            self.head_bytes.store(false, Ordering::SeqCst);
            self.set(WAITING);
        }
    }
    /// The response is an endless stream.
    pub fn streaming(&self) {
        self.set(STREAMING);
    }
    /// Completes when the connection is closed to make room for another.
    pub async fn evicted(&self) {
        self.kill.notified().await
    }
    fn set(&self, s: u8) {
        self.since_ms.store(self.now_ms(), Ordering::SeqCst);
        self.state.store(s, Ordering::SeqCst);
    }
    fn head_deadline(&self) -> Instant {
        let limit = if self.reserve {
            RESERVE_HEAD_DEADLINE
        } else {
            HEAD_DEADLINE
        };
        self.t0 + Duration::from_millis(self.since_ms.load(Ordering::SeqCst)) + limit
    }
}

/// The open connections and the counters the page shows.
pub struct Conns {
    t0: Instant,
    limits: Limits,
    open: Mutex<HashMap<u64, Arc<ConnCtl>>>,
    next_id: AtomicU64,
    /// Idle or slow connections closed to make room at the bound.
    pub evicted: AtomicU64,
    /// Connections answered 503 (the bound and the reserve full).
    pub refused: AtomicU64,
    /// Connections taken into the e-stop reserve.
    pub reserve_used: AtomicU64,
    /// Connections closed by a deadline (head not in time, socket stalled).
    pub timed_out: AtomicU64,
    /// Most connections open at once.
    pub peak: AtomicU64,
}

impl Conns {
    /// No connections yet.
    pub fn new(limits: Limits) -> Conns {
        Conns {
            t0: Instant::now(),
            limits,
            open: Mutex::new(HashMap::new()),
            next_id: AtomicU64::new(0),
            evicted: AtomicU64::new(0),
            refused: AtomicU64::new(0),
            reserve_used: AtomicU64::new(0),
            timed_out: AtomicU64::new(0),
            peak: AtomicU64::new(0),
        }
    }
    /// The bound in force.
    pub fn limits(&self) -> Limits {
        self.limits
    }
    /// Connections open now.
    pub fn open(&self) -> usize {
        self.lock().len()
    }
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Arc<ConnCtl>>> {
        self.open.lock().unwrap_or_else(|e| e.into_inner())
    }
    /// Forgets connection `ctl` (it has ended).
    pub fn remove(&self, ctl: &ConnCtl) {
        self.lock().remove(&ctl.id);
    }
    /// Closes the connection that has waited longest for a request head, to make room (the
    /// process is out of open files).
    pub fn make_room(&self) {
        self.evict_longest_waiting(&mut self.lock());
    }
    /// Closes the connection that has waited longest for a request head; false: none waits.
    fn evict_longest_waiting(&self, open: &mut HashMap<u64, Arc<ConnCtl>>) -> bool {
        let victim = open
            .values()
            .filter(|c| c.state.load(Ordering::SeqCst) == WAITING)
            .min_by_key(|c| (c.since_ms.load(Ordering::SeqCst), c.id))
            .map(|c| c.id);
        match victim.and_then(|id| open.remove(&id)) {
            Some(c) => {
                c.kill.notify_one();
                self.evicted.fetch_add(1, Ordering::Relaxed);
                true
            }
            None => false,
        }
    }
    /// Registers a new connection: `None` when the bound and the reserve are both full.
    pub fn admit(&self, peer: std::net::SocketAddr) -> Option<Arc<ConnCtl>> {
        let mut open = self.lock();
        let mut reserve = false;
        if open.len() >= self.limits.max && !self.evict_longest_waiting(&mut open) {
            if open.len() >= self.limits.max + self.limits.reserve {
                self.refused.fetch_add(1, Ordering::Relaxed);
                return None;
            }
            reserve = true;
            self.reserve_used.fetch_add(1, Ordering::Relaxed);
        }
        let c = Arc::new(ConnCtl {
            id: self.next_id.fetch_add(1, Ordering::Relaxed),
            peer,
            reserve,
            state: AtomicU8::new(WAITING),
            since_ms: AtomicU64::new(self.t0.elapsed().as_millis() as u64),
            requests: AtomicU64::new(0),
            head_bytes: AtomicBool::new(false),
            kill: Notify::new(),
            t0: self.t0,
        });
        open.insert(c.id, c.clone());
        self.peak.fetch_max(open.len() as u64, Ordering::Relaxed);
        Some(c)
    }
}

/// Who sent a request (an extension of every request the router sees).
#[derive(Clone)]
pub struct Caller {
    /// The connection.
    pub ctl: Arc<ConnCtl>,
    /// When its head was read (the body must follow within the head deadline).
    pub at: Instant,
    /// Logged in (always on loopback).
    pub session: bool,
}

/// Connections the kernel queues before the accept loop takes them (capped by
/// `net.core.somaxconn`, 4096 on current Linux). tokio's default of 128 overflowed when a
/// burst of 1,000 connections met a busy machine: the kernel then dropped SYNs and clients
/// (the e-stop's too) waited 1 s for the retransmission.
const BACKLOG: u32 = 4096;

/// A listening socket on `addr` with a backlog of [`BACKLOG`].
pub fn listen(addr: std::net::SocketAddr) -> io::Result<tokio::net::TcpListener> {
    let s = if addr.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    s.set_reuseaddr(true)?;
    s.bind(addr)?;
    s.listen(BACKLOG)
}

/// A whole response written straight to the socket (outside hyper: refusals before or
/// after it serves the connection).
pub fn canned(status: &str, msg: &str) -> Vec<u8> {
    let body = format!("{{\"error\":\"{msg}\"}}\n");
    format!(
        "HTTP/1.1 {status}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// The socket with the server's deadlines: a head not complete in time ends the connection
/// (with a 408 when a request was begun or none was made yet); a write that makes no
/// progress for [`WRITE_STALL`] ends it too.
pub struct GuardedIo {
    inner: TcpStream,
    ctl: Arc<ConnCtl>,
    conns: Arc<Conns>,
    head_timer: Pin<Box<Sleep>>,
    head_deadline: Option<Instant>,
    write_timer: Pin<Box<Sleep>>,
    write_stalled: bool,
}

impl GuardedIo {
    /// `inner` with the deadlines of connection `ctl` of `conns`.
    pub fn new(inner: TcpStream, ctl: Arc<ConnCtl>, conns: Arc<Conns>) -> Self {
        let far = tokio::time::Instant::now() + Duration::from_secs(3600);
        Self {
            inner,
            ctl,
            conns,
            head_timer: Box::pin(tokio::time::sleep_until(far)),
            head_deadline: None,
            write_timer: Box::pin(tokio::time::sleep_until(far)),
            write_stalled: false,
        }
    }

    fn timed_out(&self, what: &str) -> io::Error {
        self.conns.timed_out.fetch_add(1, Ordering::Relaxed);
        io::Error::new(io::ErrorKind::TimedOut, what.to_string())
    }

    /// Polled while a write cannot go on: `Ready(Err)` once it has stalled too long.
    fn stalled<T>(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        if !self.write_stalled {
            self.write_stalled = true;
            let at = tokio::time::Instant::now() + WRITE_STALL;
            self.write_timer.as_mut().reset(at);
        }
        if self.write_timer.as_mut().poll(cx).is_ready() {
            return Poll::Ready(Err(self.timed_out("the client took nothing for 2 s")));
        }
        Poll::Pending
    }

    fn wrote<T>(&mut self, r: Poll<io::Result<T>>, cx: &mut Context<'_>) -> Poll<io::Result<T>> {
        match r {
            Poll::Ready(r) => {
                self.write_stalled = false;
                Poll::Ready(r)
            }
            Poll::Pending => self.stalled(cx),
        }
    }
}

impl AsyncRead for GuardedIo {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        if let Poll::Ready(r) = Pin::new(&mut this.inner).poll_read(cx, buf) {
            if buf.filled().len() > before {
                this.ctl.head_bytes.store(true, Ordering::SeqCst);
            }
            return Poll::Ready(r);
        }
        if this.ctl.state.load(Ordering::SeqCst) != WAITING {
            return Poll::Pending;
        }
        let deadline = this.ctl.head_deadline();
        if this.head_deadline != Some(deadline) {
            this.head_deadline = Some(deadline);
            this.head_timer.as_mut().reset(deadline.into());
        }
        if this.head_timer.as_mut().poll(cx).is_ready() {
            // A client that began a request (or never made one) is told why; an idle
            // keep-alive connection just closes, as any server's keep-alive timeout.
            let begun = this.ctl.head_bytes.load(Ordering::SeqCst);
            if begun || this.ctl.requests.load(Ordering::SeqCst) == 0 {
                let _ = this
                    .inner
                    .try_write(&canned("408 Request Timeout", "request head not complete within 3 s"));
            }
            return Poll::Ready(Err(this.timed_out("request head not complete within 3 s")));
        }
        Poll::Pending
    }
}

impl AsyncWrite for GuardedIo {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write(cx, data);
        this.wrote(r, cx)
    }
    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write_vectored(cx, bufs);
        this.wrote(r, cx)
    }
    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }
    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_follows_the_open_file_limit() {
        let l = Limits::for_nofile(Some(1 << 20));
        assert_eq!((l.max, l.reserve, l.reduced), (1024, 64, false));
        // A Pi's default soft limit, had it not been raised: 1024 - 128 - 64.
        let l = Limits::for_nofile(Some(1024));
        assert_eq!((l.max, l.reduced), (832, true));
        assert_eq!(Limits::for_nofile(Some(10)).max, 16);
        assert_eq!(Limits::for_nofile(None).max, 1024);
    }

    fn peer() -> std::net::SocketAddr {
        "127.0.0.1:1".parse().unwrap()
    }

    #[test]
    fn at_the_bound_the_longest_waiting_connection_gives_way_then_the_reserve_is_used() {
        let c = Conns::new(Limits {
            max: 3,
            reserve: 1,
            reduced: true,
        });
        let a = c.admit(peer()).unwrap();
        let b = c.admit(peer()).unwrap();
        let d = c.admit(peer()).unwrap();
        std::thread::sleep(Duration::from_millis(3));
        // `a` is in a handler, `b` has just been answered (waiting again): `d` waited longest.
        a.handling();
        b.handling();
        b.waiting();
        let e = c.admit(peer()).unwrap();
        assert!(!e.reserve);
        let open: Vec<u64> = {
            let mut v: Vec<u64> = c.lock().keys().copied().collect();
            v.sort();
            v
        };
        assert_eq!(open, vec![a.id, b.id, e.id], "d (longest waiting) was closed");
        assert_eq!(c.evicted.load(Ordering::SeqCst), 1);
        // Nothing waits any more: the next one is a reserve connection, then refusal.
        b.handling();
        e.streaming();
        let f = c.admit(peer()).unwrap();
        assert!(f.reserve);
        f.handling();
        assert!(c.admit(peer()).is_none());
        assert_eq!(c.refused.load(Ordering::SeqCst), 1);
        let _ = d;
    }
}
