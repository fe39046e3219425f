//! `[dashboard]`: the live page of `rccar sim|drive --dashboard`: where it listens (IP:PORT),
//! its token, the heartbeat timeout (milliseconds), the stream rate (frames per second) and the
//! number of viewers.

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[dashboard]`: the live page of `rccar sim|drive --dashboard` (issue 11).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DashboardConfig {
    /// Address to listen on (`--listen` overrides). Anything but 127.0.0.1 / ::1 needs the token.
    pub listen: String,
    /// Access token for a dashboard on another address; empty = a random one printed at start.
    pub token: String,
    /// Disarm when the page that armed the car sends no heartbeat for this long, ms (0 = never).
    pub heartbeat_ms: u64,
    /// Frames per second sent to the viewers (the loop publishes at most this often).
    pub stream_fps: f64,
    /// Concurrent stream viewers; more get 503.
    pub max_viewers: u32,
}

impl Default for DashboardConfig {
    fn default() -> Self {
        Self {
            listen: "127.0.0.1:8080".into(),
            token: String::new(),
            heartbeat_ms: 1000,
            stream_fps: 15.0,
            max_viewers: 32,
        }
    }
}

impl DashboardConfig {
    /// Checks of `[dashboard]`: a socket address, a usable token, the ranges.
    pub(super) fn check(&self, c: &mut Checker) {
        let d = self;
        if d.listen.parse::<std::net::SocketAddr>().is_err() {
            c.fail(
                "dashboard.listen",
                format!("{:?}", d.listen),
                "IP:PORT, e.g. 127.0.0.1:8080",
            );
        }
        if !d.token.is_empty() && (d.token.len() < 8 || !d.token.chars().all(|ch| ch.is_ascii_alphanumeric())) {
            c.fail("dashboard.token", "(hidden)".into(), "empty, or 8+ letters and digits");
        }
        c.range("dashboard.heartbeat_ms", d.heartbeat_ms, 0, 60_000);
        c.range("dashboard.stream_fps", d.stream_fps, 1.0, 60.0);
        c.range("dashboard.max_viewers", d.max_viewers, 1, 256);
    }
}
