//! The dashboard's HTTP server: axum routes on hyper's HTTP/1, in a small tokio runtime on
//! threads of its own, so the control loop never waits on it (the loop's side,
//! `crate::dashboard`, is a newest-only slot and a bounded inbox).
//!
//! - `GET /` the page (the run's secret embedded); `GET /stream.mjpg` the annotated camera
//!   view and the bird's-eye view as MJPEG (`multipart/x-mixed-replace`): each viewer is sent
//!   the newest JPEG when it is ready for one, older ones are skipped (never queued); a viewer
//!   whose socket takes nothing for 2 s is dropped; at most `dashboard.max_viewers` viewers.
//! - `GET /api/state?since=T` the newest state and the plot samples after frame time `T`.
//! - `POST /api/estop`: stops the car, from anyone who can reach the server (the safe way).
//! - `POST /api/{release,arm,disarm,heartbeat,set,save,drive,mode}`, and in the simulator
//!   `POST /api/sim/{pause,resume,step,reset,place}`: need the same-origin proof of
//!   [`access`] (Host, Origin, `Content-Type: application/json`, the page's secret and, off
//!   loopback, the login cookie); refusals answer 403 and are logged.
//! - `GET /setup` the set-up page (issue 26, [`setup`]): `GET /api/setup/frame` (a frozen
//!   frame as PNG; needs the login off loopback, as the stream), `GET /api/setup/state`,
//!   `POST /api/setup/{freeze,preview,apply}` under the same proof as the other controls.
//! - `POST /login` (not on loopback): the printed token once, for an HttpOnly,
//!   SameSite=Strict session cookie.
//!
//! Limits ([`conn`]): request head 8 KiB (431) within 3 s of waiting for it (408 and closed),
//! bodies 4 KiB (413) within 3 s, 1,024 connections (fewer under a low open-file limit) plus
//! 64 kept for the e-stop; at the bound the connection that has waited longest for a request
//! head is closed for the new one. One hub thread takes the loop's snapshots, annotates and
//! encodes them once for every viewer.
//!
//! The e-stop handler touches only atomics (no lock the loop, the hub or another request
//! holds) and its log line goes through a queue, so it works while everything else is stuck.

//!
//! The modules import one another one way only, from the bottom up: [`reply`], [`log`] and
//! [`conn`] (the connection table) import none of the others; [`access`] uses `reply` and
//! `log`; [`state`] (what everything shares) holds an `access`, a `log` and a `conn`; then
//! [`status`] (what the page is told), [`request`] (reading a control body), [`hub`],
//! [`push`] (the pushed state), [`setup`] (set-up by clicking), [`api`] (the routes),
//! [`accept`], and this file, which starts them.

mod accept;
mod access;
mod api;
mod conn;
mod hub;
mod log;
mod push;
mod request;
mod reply;
mod setup;
mod state;
mod status;

use super::shared::{DashboardError, Sent};
use crate::config::Config;
use crate::dashboard::messages::{ControlSender, Live, Snapshot};
use crate::drive::{Arming, Latest, StopSignal};
use crate::sim::world::{lock, SharedWorld};
use state::{Shared, View};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize};
use std::sync::{Arc, Mutex};

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
    /// The set-up page's frame instead of the newest camera frame (`--setup-frame`), with
    /// its file name.
    pub setup_frame: Option<(image::RgbImage, String)>,
}

/// The running server; its threads end when the run's stop signal is set or it is dropped.
pub struct Server {
    shared: Arc<Shared>,
    slot: Arc<Latest<Arc<Snapshot>>>,
    web: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shared.close();
        self.slot.close();
        if let Some(t) = self.web.take() {
            let _ = t.join();
        }
    }
}

impl Server {
    /// Binds, then starts the web runtime's thread, the hub, the watchdog and the logger.
    pub fn start(o: Options) -> Result<Server, DashboardError> {
        let addr: SocketAddr = o.listen.parse().map_err(|source| DashboardError::Listen {
            listen: o.listen.clone(),
            source,
        })?;
        let nofile = conn::raise_nofile_limit();
        let limits = conn::Limits::for_nofile(nofile);
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .max_blocking_threads(4)
            .thread_name("dash-web")
            .enable_io()
            .enable_time()
            .build()
            .map_err(DashboardError::Runtime)?;
        let listener = rt
            .block_on(async { conn::listen(addr) })
            .map_err(|source| DashboardError::Bind { addr, source })?;
        let bound = listener.local_addr()?;
        let access = access::Access::new(bound, &o.cfg.dashboard.token);
        // A human may drive from now on: every record says the mode and who drove.
        o.arm.controls().attach();
        let (log, log_rx) = log::Log::new();
        let track_length = o.world.as_ref().map(|w| lock(w).scene().track.length);
        let shared = Arc::new(Shared {
            heartbeat_ms: o.cfg.dashboard.heartbeat_ms,
            max_viewers: o.cfg.dashboard.max_viewers as usize,
            cfg: Mutex::new(o.cfg),
            changed: Mutex::new(BTreeMap::new()),
            frozen: Mutex::new(None),
            setup_given: o.setup_frame,
            local: o.local,
            tx: o.tx.clone(),
            arm: o.arm,
            sent: o.sent,
            track_length,
            access,
            view: Mutex::new(View::default()),
            jpeg: tokio::sync::watch::Sender::new(Arc::new(Vec::new())),
            last_heartbeat_ms: AtomicU64::new(0),
            armed_by_page: AtomicBool::new(false),
            viewers: AtomicUsize::new(0),
            subscribers: AtomicUsize::new(0),
            tick: tokio::sync::watch::Sender::new(0),
            events_sent: AtomicU64::new(0),
            event_bytes: AtomicU64::new(0),
            frames_sent: AtomicU64::new(0),
            closed: AtomicBool::new(false),
            shutdown: tokio::sync::watch::Sender::new(false),
            live: o.live,
            log,
            conns: Arc::new(conn::Conns::new(limits)),
        });
        shared.access.print_start_up(bound);
        if let Some(n) = nofile.filter(|_| limits.reduced) {
            log::out(&format!(
                "dashboard: open-file limit {n}: at most {} connections (+{} for the e-stop)",
                limits.max, limits.reserve
            ));
        }
        log::start_logger(log_rx, o.tx)?;
        {
            let sh = shared.clone();
            let slot = o.slot.clone();
            std::thread::Builder::new()
                .name("dash-hub".into())
                .spawn(move || hub::hub(slot, sh))?;
        }
        {
            let sh = shared.clone();
            let stop = o.stop.clone();
            std::thread::Builder::new()
                .name("dash-watchdog".into())
                .spawn(move || hub::watchdog(sh, stop))?;
        }
        let web = {
            let sh = shared.clone();
            let router = api::router(shared.clone());
            std::thread::Builder::new().name("dash-accept".into()).spawn(move || {
                rt.block_on(accept::accept_loop(listener, router, sh));
                // Connections still open end with the runtime (no waiting for slow clients).
                rt.shutdown_timeout(std::time::Duration::from_millis(200));
            })?
        };
        Ok(Server {
            shared,
            slot: o.slot,
            web: Some(web),
        })
    }
}
