//! What the dashboard's server takes from the run besides the loop's slot and inbox: what
//! the gate really sent, read on the run's clock ([`Sent`]), and why the server could not
//! start ([`DashboardError`]). Here, not beside the server, because both exist without the
//! `dashboard` feature too.

use crate::drive::Clock;
use std::sync::Arc;

/// Why the dashboard could not start.
#[derive(Debug, thiserror::Error)]
pub enum DashboardError {
    /// The binary was built without the `dashboard` cargo feature.
    #[error("--dashboard: this rccar was built without it; rebuild with `cargo build --release --features dashboard`")]
    NotBuilt,
    /// The listen address is not `IP:PORT`.
    #[error("--listen `{listen}`: expected IP:PORT, e.g. 127.0.0.1:8080")]
    Listen {
        /// The address as given.
        listen: String,
        /// Why it does not parse.
        #[source]
        source: std::net::AddrParseError,
    },
    /// The web runtime (tokio) did not start.
    #[error("dashboard: cannot start the web runtime")]
    Runtime(#[source] std::io::Error),
    /// The address could not be bound.
    #[error("dashboard: cannot listen on {addr}")]
    Bind {
        /// The address.
        addr: std::net::SocketAddr,
        /// The socket's error.
        #[source]
        source: std::io::Error,
    },
    /// A thread or the socket's address could not be had.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// What the gate really sent, on the run's clock (the e-stop's effect is measured here).
pub struct Sent {
    /// The gate's record.
    pub sent: Arc<crate::drive::Sent>,
    clock: Arc<dyn Clock + Send + Sync>,
}

impl Sent {
    /// The gate's record read on `clock`.
    pub fn new(sent: Arc<crate::drive::Sent>, clock: Arc<dyn Clock + Send + Sync>) -> Sent {
        Sent { sent, clock }
    }
    /// Seconds on the run's clock.
    pub fn now(&self) -> f64 {
        self.clock.now_s()
    }
    /// The e-stop arrived now (the server's e-stop handler, before it presses).
    pub fn mark_estop(&self) {
        self.sent.mark_estop(self.now());
    }
}

impl std::ops::Deref for Sent {
    type Target = crate::drive::Sent;
    fn deref(&self) -> &Self::Target {
        &self.sent
    }
}
