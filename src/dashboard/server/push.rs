//! `GET /api/events`: the page's state pushed as server-sent events (`text/event-stream`)
//! instead of the page polling `/api/state` ten times a second. The first event carries the
//! whole plot history and the parameter table; every later one only the samples since the
//! last and the keys whose values changed (the page merges them into what it has). An event goes out when the hub has a new snapshot, when a handler changed something
//! (arm, e-stop, mode: [`Shared::poke`]) and, within 20 ms, when anyone else changed the
//! arming state (a pad, the link, the heartbeat watchdog) — so the e-stop shows on every open
//! page in one round trip, not at the next poll. A comment line every second keeps idle
//! connections and proxies from closing the stream.
//!
//! Like the MJPEG stream it holds a connection: at most `dashboard.max_viewers` at once
//! (503 past that), and it ends when the server closes.

use super::conn::Caller;
use super::reply::error;
use super::state::Shared;
use super::status::state_json;
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{header, Response, StatusCode};
use axum::Extension;
use hyper::body::Frame;
use std::convert::Infallible;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

/// How often a subscriber looks at the arming state between pushes.
const ARMING_POLL: Duration = Duration::from_millis(20);
/// A comment line this often when nothing else was sent.
const KEEPALIVE: Duration = Duration::from_secs(1);

/// `GET /api/events`.
pub async fn events(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>) -> Response<Body> {
    if sh.subscribers.fetch_add(1, Ordering::SeqCst) >= sh.max_viewers {
        sh.subscribers.fetch_sub(1, Ordering::SeqCst);
        return error(StatusCode::SERVICE_UNAVAILABLE, "too many pages subscribed");
    }
    c.ctl.streaming();
    let sub = Sub {
        sh: sh.clone(),
        session: c.session,
        since: f64::NEG_INFINITY,
        first: true,
        tick: sh.tick.subscribe(),
        shut: sh.shutdown.subscribe(),
        arming: u64::MAX,
        told: serde_json::Map::new(),
    };
    let body = Events {
        sh,
        next: Some(Box::pin(sub.next())),
    };
    Response::builder()
        .header(header::CONTENT_TYPE, "text/event-stream")
        .header(header::CONNECTION, "close")
        .body(Body::new(body))
        .unwrap_or_else(|_| error(StatusCode::INTERNAL_SERVER_ERROR, "events"))
}

/// One subscriber's position: the last frame time sent and the arming version seen.
struct Sub {
    sh: Arc<Shared>,
    session: bool,
    since: f64,
    first: bool,
    tick: tokio::sync::watch::Receiver<u64>,
    shut: tokio::sync::watch::Receiver<bool>,
    arming: u64,
    /// What this page was last told, key by key: later events carry only what changed.
    told: serde_json::Map<String, serde_json::Value>,
}

type Next = Option<(Sub, Bytes)>;

impl Sub {
    /// Waits for something to tell, then makes the event; `None` when the server closes.
    async fn next(mut self) -> Next {
        if !self.first {
            enum Woke {
                News,
                Closed,
                Quiet,
            }
            let quiet = tokio::time::sleep(KEEPALIVE);
            tokio::pin!(quiet);
            let woke = loop {
                tokio::select! {
                    r = self.tick.changed() => break if r.is_ok() { Woke::News } else { Woke::Closed },
                    _ = self.shut.wait_for(|v| *v) => break Woke::Closed,
                    _ = &mut quiet => break Woke::Quiet,
                    _ = tokio::time::sleep(ARMING_POLL) => {
                        if self.sh.arm.version() != self.arming { break Woke::News; }
                    }
                }
            };
            match woke {
                Woke::News => {}
                Woke::Closed => return None,
                Woke::Quiet => return Some((self, Bytes::from_static(b": keep-alive\n\n"))),
            }
        }
        if *self.shut.borrow() {
            return None;
        }
        self.tick.borrow_and_update();
        self.arming = self.sh.arm.version();
        let v = state_json(&self.sh, self.since, self.session, self.first);
        if let Some(t) = v["points"].as_array().and_then(|p| p.last()).and_then(|p| p["t"].as_f64()) {
            self.since = t;
        }
        self.first = false;
        // Only the keys whose values changed since this page was last told (the page merges
        // them into what it has); the new plot samples always.
        let mut news = serde_json::Map::new();
        if let serde_json::Value::Object(all) = v {
            for (k, val) in all {
                if k == "points" || self.told.get(&k) != Some(&val) {
                    if k != "points" {
                        self.told.insert(k.clone(), val.clone());
                    }
                    news.insert(k, val);
                }
            }
        }
        let text = format!("data: {}\n\n", serde_json::Value::Object(news));
        self.sh.events_sent.fetch_add(1, Ordering::Relaxed);
        self.sh.event_bytes.fetch_add(text.len() as u64, Ordering::Relaxed);
        Some((self, Bytes::from(text)))
    }
}

/// The stream's body: the next event is made only when hyper has taken the previous one, so
/// a slow page gets fewer, larger events (the samples since the last), never a queue.
struct Events {
    sh: Arc<Shared>,
    next: Option<Pin<Box<dyn Future<Output = Next> + Send>>>,
}

impl Drop for Events {
    fn drop(&mut self) {
        self.sh.subscribers.fetch_sub(1, Ordering::SeqCst);
    }
}

impl hyper::body::Body for Events {
    type Data = Bytes;
    type Error = Infallible;
    fn poll_frame(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<Frame<Bytes>, Infallible>>> {
        let this = self.get_mut();
        let Some(fut) = this.next.as_mut() else {
            return Poll::Ready(None);
        };
        match fut.as_mut().poll(cx) {
            Poll::Pending => Poll::Pending,
            Poll::Ready(None) => {
                this.next = None;
                Poll::Ready(None)
            }
            Poll::Ready(Some((sub, bytes))) => {
                this.next = Some(Box::pin(sub.next()));
                Poll::Ready(Some(Ok(Frame::data(bytes))))
            }
        }
    }
}
