//! What the handlers, the hub, the watchdog and the accept loop share ([`Shared`]), and the
//! page's newest state ([`View`]). Above the leaves (access, conn, log); every other module of
//! the server imports it, it imports none of them.

use super::access::Access;
use super::conn::Conns;
use super::log::Log;
use crate::config::Config;
use crate::dashboard::local_toml::Saved;
use crate::dashboard::messages::{ControlSender, Live, PlotPoint, Snapshot};
use crate::dashboard::shared::Sent;
use crate::drive::Arming;
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// Plot history kept for the page, seconds of frame time.
pub const HISTORY_S: f64 = 30.0;

/// The newest state for `GET /api/state`.
#[derive(Default)]
pub struct View {
    /// The newest snapshot.
    pub snap: Option<Arc<Snapshot>>,
    /// The plot samples of the last [`HISTORY_S`] seconds.
    pub history: VecDeque<PlotPoint>,
}

/// The set-up page's frozen frame (issue 26).
pub struct Frozen {
    /// The frame, at the pipeline's size.
    pub image: image::RgbImage,
    /// … as PNG.
    pub png: Vec<u8>,
    /// Where it came from, e.g. `camera frame 412 at 13.73 s`.
    pub what: String,
}

/// Everything the handlers, the hub and the watchdog share.
pub struct Shared {
    /// The run's configuration with the page's changes applied.
    pub cfg: Mutex<Config>,
    /// The keys the page changed, and their values (what "save" writes).
    pub changed: Mutex<BTreeMap<String, Saved>>,
    /// The set-up page's frozen frame (`None` until the page first asks for it).
    pub frozen: Mutex<Option<Arc<Frozen>>>,
    /// The set-up frame given at start (`--setup-frame`), and its file name.
    pub setup_given: Option<(image::RgbImage, String)>,
    /// The override file "save" writes (`local.toml` or `--local`).
    pub local: PathBuf,
    /// The loop's inbox.
    pub tx: ControlSender,
    /// The car's one arming state.
    pub arm: Arc<Arming>,
    /// What the sink sent, and the dashboard's clock.
    pub sent: Arc<Sent>,
    /// The simulated track's length, metres (`None` on the car).
    pub track_length: Option<f64>,
    /// Who may do what.
    pub access: Access,
    /// The page's newest state.
    pub view: Mutex<View>,
    /// The newest JPEG of the stream (newest only: a viewer that was busy skips the rest).
    pub jpeg: tokio::sync::watch::Sender<Arc<Vec<u8>>>,
    /// The operator's heartbeat limit, ms (0: none).
    pub heartbeat_ms: u64,
    /// When the page's last heartbeat came, ms on the dashboard's clock.
    pub last_heartbeat_ms: AtomicU64,
    /// The page armed the car (the heartbeat watchdog then watches it).
    pub armed_by_page: AtomicBool,
    /// Streams being sent.
    pub viewers: AtomicUsize,
    /// Pages subscribed to the pushed state (`GET /api/events`).
    pub subscribers: AtomicUsize,
    /// Bumped when there is something new to push (a snapshot, a control's change).
    pub tick: tokio::sync::watch::Sender<u64>,
    /// Pushed events and their bytes, all subscribers (the page's traffic).
    pub events_sent: AtomicU64,
    /// See `events_sent`.
    pub event_bytes: AtomicU64,
    /// Most streams at once.
    pub max_viewers: usize,
    /// Stream frames sent to all viewers.
    pub frames_sent: AtomicU64,
    /// Set when the server closes: the threads end.
    pub closed: AtomicBool,
    /// `true` once the server is closing: every connection and stream ends.
    pub shutdown: tokio::sync::watch::Sender<bool>,
    /// The loop's per-frame counters.
    pub live: Arc<Live>,
    /// The queue to the logger thread.
    pub log: Log,
    /// The open connections and their counters.
    pub conns: Arc<Conns>,
}

impl Shared {
    /// Closes the server: every connection, stream and thread ends.
    pub fn close(&self) {
        self.closed.store(true, Ordering::SeqCst);
        self.shutdown.send_replace(true);
    }

    /// Something changed: every subscribed page gets an event now.
    pub fn poke(&self) {
        self.tick.send_modify(|v| *v = v.wrapping_add(1));
    }

    /// Milliseconds on the dashboard's clock.
    pub fn now_ms(&self) -> u64 {
        (self.sent.now() * 1e3) as u64
    }
}
