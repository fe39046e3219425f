//! Routes and handlers. [`handle`] sees every request first: the e-stop is answered there
//! before anything else is looked at; every other request passes the checks of
//! [`super::access`] before it reaches the axum router.

use super::access;
use super::conn::{Caller, ConnCtl};
use super::hub;
use super::log::Msg;
use super::reply::{error, reply};
use super::setup;
use super::state::Shared;
use super::request::{body, note};
use super::status::state_json;
use super::push;
use crate::dashboard::local_toml;
use crate::dashboard::messages::{self, Control, DriveRequest, ModeRequest, PlaceRequest, RecordRequest, SetRequest};
use crate::drive::{Actor, DriveMode};
use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderMap, HeaderValue, Method, Request, Response, StatusCode, Uri};
use axum::routing::{get, post};
use axum::{Extension, Router};
use serde_json::{json, Value};
use std::convert::Infallible;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;
use tower_service::Service;

const PAGE: &str = include_str!("../page.html");

/// [`access::refuse`] with the server's log and clock.
fn refuse(sh: &Shared, m: &Method, path: &str, h: &HeaderMap, peer: std::net::SocketAddr, why: &str) -> Response<Body> {
    access::refuse(&sh.access, &sh.log, sh.sent.now(), m, path, h, peer, why)
}

/// Every route; the checks before them are in [`handle`].
pub fn router(sh: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/index.html", get(page))
        .route("/login", post(login))
        .route("/api/state", get(state))
        .route("/api/events", get(push::events))
        .route("/stream.mjpg", get(hub::stream))
        .route("/api/release", post(release))
        .route("/api/arm", post(arm))
        .route("/api/disarm", post(disarm))
        .route("/api/heartbeat", post(heartbeat))
        .route("/api/set", post(set))
        .route("/api/save", post(save))
        .route("/api/drive", post(drive))
        .route("/api/mode", post(mode))
        .route("/api/record", post(record))
        .route("/api/sim/pause", post(sim))
        .route("/api/sim/resume", post(sim))
        .route("/api/sim/step", post(sim))
        .route("/api/sim/reset", post(sim))
        .route("/api/sim/place", post(sim))
        .route("/setup", get(setup::page))
        .route("/api/setup/state", get(setup::state))
        .route("/api/setup/frame", get(setup::frame))
        .route("/api/setup/freeze", post(setup::freeze_now))
        .route("/api/setup/preview", post(setup::preview))
        .route("/api/setup/apply", post(setup::apply))
        // Only exact routes exist: `..`, `%2e`, `//` and the like are simply not found.
        .fallback(|| async { error(StatusCode::NOT_FOUND, "no such page") })
        .method_not_allowed_fallback(|| async { error(StatusCode::METHOD_NOT_ALLOWED, "wrong method") })
        .with_state(sh)
}

/// One request of a connection: the e-stop first, then the access checks, then the router.
pub async fn handle(
    req: Request<hyper::body::Incoming>,
    ctl: Arc<ConnCtl>,
    mut router: Router,
    sh: Arc<Shared>,
) -> Result<Response<Body>, Infallible> {
    ctl.handling();
    let mut resp = if req.method() == Method::POST && req.uri().path() == "/api/estop" {
        estop(&sh, &ctl, req.headers())
    } else {
        match check(&req, &ctl, &sh) {
            Err(r) => *r,
            Ok(session) => {
                let (mut parts, body) = req.into_parts();
                parts.extensions.insert(Caller {
                    ctl: ctl.clone(),
                    at: Instant::now(),
                    session,
                });
                let req = Request::from_parts(parts, Body::new(body));
                match router.call(req).await {
                    Ok(r) => r,
                    Err(e) => match e {},
                }
            }
        }
    };
    ctl.waiting();
    let h = resp.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    // No other page may frame this one (a framed page's clicks would pass every check).
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static("frame-ancestors 'none'"),
    );
    h.insert(header::REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    Ok(resp)
}

/// The access checks of [`super::access`]; `Ok(logged in)` or the refusal.
fn check(req: &Request<hyper::body::Incoming>, ctl: &ConnCtl, sh: &Shared) -> Result<bool, Box<Response<Body>>> {
    let (m, path, h) = (req.method(), req.uri().path(), req.headers());
    let no = |why: &str| Box::new(refuse(sh, m, path, h, ctl.peer, why));
    if ctl.reserve {
        return Err(Box::new(error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the server is at its connection bound: this connection serves the e-stop only",
        )));
    }
    let a = &sh.access;
    a.host_ok(h).map_err(|w| no(&w))?;
    if m == Method::OPTIONS {
        return Err(no("cross-origin requests are not allowed (CORS preflight refused)"));
    }
    let session = a.has_session(h);
    if m == Method::POST && path == "/login" {
        a.origin_ok(h).map_err(|w| no(&w))?;
    } else if m != Method::GET && m != Method::HEAD {
        a.control_ok(h).map_err(|w| no(&w))?;
    } else if (path == "/stream.mjpg" || path == "/api/setup/frame") && !session {
        return Err(no("not logged in (enter the token printed at start on the page)"));
    }
    Ok(session)
}

/// `POST /api/estop`: atomics only, no lock that the loop, the hub or another request holds;
/// from anyone who can reach the server. Its log line and telemetry note go through a queue.
fn estop(sh: &Shared, ctl: &ConnCtl, h: &HeaderMap) -> Response<Body> {
    sh.sent.mark_estop();
    sh.arm.estop(Actor::Page);
    sh.armed_by_page.store(false, Ordering::SeqCst);
    sh.poke();
    let who = format!(
        "{} (Origin {}, Host {})",
        ctl.peer,
        access::shown(h.get(header::ORIGIN)),
        access::shown(h.get("host"))
    );
    sh.log.send(Msg::Out(format!("dashboard: EMERGENCY STOP from {who}")));
    sh.log.send(Msg::Note(format!(
        "EMERGENCY STOP from dashboard {who} at wall {:.3} s",
        sh.sent.estop_clock_s.get()
    )));
    reply(StatusCode::OK, &json!({"estop": true}))
}

async fn page(State(sh): State<Arc<Shared>>, h: HeaderMap) -> Response<Body> {
    let mut r = Response::new(Body::from(sh.access.page(PAGE, &h)));
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/html; charset=utf-8"),
    );
    r
}

/// `POST /login` (off loopback): the printed token, once, for the session cookie.
async fn login(
    State(sh): State<Arc<Shared>>,
    Extension(c): Extension<Caller>,
    h: HeaderMap,
    b: Body,
) -> Response<Body> {
    if sh.access.loopback() {
        return error(StatusCode::NOT_FOUND, "no login on loopback: the page needs none");
    }
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    match sh.access.login(&bytes) {
        Some(cookie) => {
            let mut r = Response::new(Body::empty());
            *r.status_mut() = StatusCode::SEE_OTHER;
            r.headers_mut().insert(header::LOCATION, HeaderValue::from_static("/"));
            if let Ok(v) = HeaderValue::from_str(&cookie) {
                r.headers_mut().insert(header::SET_COOKIE, v);
            }
            r
        }
        None => refuse(&sh, &Method::POST, "/login", &h, c.ctl.peer, "wrong token"),
    }
}


async fn release(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>) -> Response<Body> {
    sh.arm.release(Actor::Page);
    sh.poke();
    sh.tx.send(Control::Note(note(&sh, &c, "e-stop released")));
    reply(StatusCode::OK, &json!({"estop": false}))
}

async fn arm(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>) -> Response<Body> {
    sh.last_heartbeat_ms.store(sh.now_ms(), Ordering::SeqCst);
    if let Err(why) = sh.arm.arm(Actor::Page) {
        return error(StatusCode::CONFLICT, &why.to_string());
    }
    sh.armed_by_page.store(true, Ordering::SeqCst);
    sh.poke();
    sh.tx.send(Control::Note(note(&sh, &c, "armed")));
    reply(StatusCode::OK, &json!({"armed": true}))
}

async fn disarm(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>) -> Response<Body> {
    sh.arm.disarm(Actor::Page);
    sh.armed_by_page.store(false, Ordering::SeqCst);
    sh.poke();
    sh.tx.send(Control::Note(note(&sh, &c, "disarmed")));
    reply(StatusCode::OK, &json!({"armed": false}))
}

async fn heartbeat(State(sh): State<Arc<Shared>>) -> Response<Body> {
    sh.last_heartbeat_ms.store(sh.now_ms(), Ordering::SeqCst);
    reply(StatusCode::OK, &json!({"armed": sh.arm.is_armed()}))
}

/// `POST /api/drive`: the human's newest steering and throttle (−1..1 each). Only atomics:
/// the loop takes the newest at its next frame, by the mode, before the gate; an input older
/// than `manual.input_timeout_ms` counts as released.
async fn drive(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, h: HeaderMap, b: Body) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    let q: DriveRequest = match messages::parse_body(&bytes) {
        Ok(q) => q,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
    };
    let controls = sh.arm.controls();
    if let Err(e) = controls.set_input(q.steer, q.throttle) {
        return error(StatusCode::BAD_REQUEST, &e.to_string());
    }
    reply(
        StatusCode::OK,
        &json!({"mode": controls.mode().name(), "armed": sh.arm.is_armed()}),
    )
}

/// `POST /api/mode`: `manual`, `assisted` or `autopilot`, from the next frame on (the loop
/// notes the change in the telemetry with who and when).
async fn mode(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, h: HeaderMap, b: Body) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    let q: ModeRequest = match messages::parse_body(&bytes) {
        Ok(q) => q,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
    };
    let Some(m) = DriveMode::parse(&q.mode) else {
        let msg = format!(
            "mode `{}` is not one of {}",
            q.mode.chars().take(32).collect::<String>(),
            DriveMode::ALL.map(DriveMode::name).join(", ")
        );
        return error(StatusCode::BAD_REQUEST, &msg);
    };
    let before = sh.arm.controls().set_mode(m, Actor::Page, sh.sent.now());
    sh.poke();
    if before != m {
        sh.log.send(Msg::Out(format!("dashboard: mode {} (was {}) from {}", m.name(), before.name(), c.ctl.peer)));
    }
    reply(StatusCode::OK, &json!({"mode": m.name()}))
}

/// `POST /api/record`: `{"on": true}` records frames from the next one on, `false` pauses (a
/// run started with `--record DIR` only: 409 otherwise). Noted in the telemetry with who and when.
async fn record(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, h: HeaderMap, b: Body) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    let q: RecordRequest = match messages::parse_body(&bytes) {
        Ok(q) => q,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
    };
    let sw = sh.arm.controls().record();
    match sw.set(q.on, Actor::Page, sh.sent.now()) {
        Err(e) => error(StatusCode::CONFLICT, &e.to_string()),
        Ok(before) => {
            if before != q.on {
                sh.log.send(Msg::Out(format!(
                    "dashboard: recording {} from {}",
                    if q.on { "on" } else { "paused" },
                    c.ctl.peer
                )));
            }
            sh.poke();
            reply(StatusCode::OK, &json!({"recording": q.on}))
        }
    }
}

async fn set(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, h: HeaderMap, b: Body) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    let req: SetRequest = match messages::parse_body(&bytes) {
        Ok(q) => q,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
    };
    let mut cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner());
    let new = match messages::validate_set(&cfg, &req.key, req.value) {
        Ok(n) => n,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
    };
    let queued = sh.tx.send(Control::Set {
        key: req.key.clone(),
        value: req.value,
        note: format!("dashboard {} at wall {:.3} s", c.ctl.peer.ip(), sh.sent.now()),
    });
    if !queued {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the loop is not taking changes (inbox full)",
        );
    }
    *cfg = new;
    drop(cfg);
    sh.changed
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(req.key.clone(), req.value.into());
    reply(StatusCode::OK, &json!({"key": req.key, "value": req.value}))
}

async fn save(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, h: HeaderMap, b: Body) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    // No parameters: the file is the one given at start (--local), never the client's.
    if bytes.iter().any(|b| !b.is_ascii_whitespace())
        && serde_json::from_slice::<serde_json::Map<String, Value>>(&bytes).map_or(true, |m| !m.is_empty())
    {
        return error(StatusCode::BAD_REQUEST, "save takes no parameters");
    }
    let keys: Vec<(String, local_toml::Saved)> = sh
        .changed
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let (sh2, keys2) = (sh.clone(), keys.clone());
    let r = tokio::task::spawn_blocking(move || local_toml::save(&sh2.local, &keys2)).await;
    match r {
        Ok(Ok(())) => {
            let list = keys
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(", ");
            let what = format!("saved {list} to {}", sh.local.display());
            sh.tx.send(Control::Note(note(&sh, &c, &what)));
            let saved: Vec<&String> = keys.iter().map(|(k, _)| k).collect();
            reply(
                StatusCode::OK,
                &json!({"saved": saved, "file": sh.local.display().to_string()}),
            )
        }
        Ok(Err(e)) => error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    }
}

async fn sim(
    State(sh): State<Arc<Shared>>,
    Extension(c): Extension<Caller>,
    uri: Uri,
    h: HeaderMap,
    b: Body,
) -> Response<Body> {
    let Some(len) = sh.track_length else {
        return error(StatusCode::NOT_FOUND, "not a simulation");
    };
    let ctl = match uri.path() {
        "/api/sim/pause" => Control::Pause,
        "/api/sim/resume" => Control::Resume,
        "/api/sim/step" => Control::Step,
        "/api/sim/reset" => Control::Reset,
        _ => {
            let bytes = match body(&h, b, &c).await {
                Ok(b) => b,
                Err(r) => return r,
            };
            let q: PlaceRequest = match messages::parse_body(&bytes) {
                Ok(q) => q,
                Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
            };
            if !(q.s.is_finite() && q.s >= 0.0 && q.s <= len) {
                let msg = format!(
                    "s = {} is out of range (allowed: 0 ..= {len:.3}, the track's length in metres)",
                    q.s
                );
                return error(StatusCode::BAD_REQUEST, &msg);
            }
            Control::PlaceAt(q.s)
        }
    };
    if sh.tx.send(ctl) {
        reply(StatusCode::OK, &json!({"ok": true}))
    } else {
        error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the loop is not taking commands (inbox full)",
        )
    }
}

/// `GET /api/state?since=T`.
async fn state(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>, uri: Uri) -> Response<Body> {
    let since = uri.query().unwrap_or("").split('&').find_map(|kv| {
        let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
        (k == "since").then_some(v)
    });
    let since = match since.map(|s| s.parse::<f64>()) {
        None => f64::NEG_INFINITY,
        Some(Ok(t)) if t.is_finite() => t,
        Some(_) => return error(StatusCode::BAD_REQUEST, "since: expected a finite number of seconds"),
    };
    reply(StatusCode::OK, &state_json(&sh, since, c.session, true))
}

