//! Reading a control request: its body (Content-Length only, bounded, within the head
//! deadline) and the telemetry note naming who asked. Below the handlers ([`super::api`],
//! [`super::setup`]), which both use it.

use super::conn::{Caller, HEAD_DEADLINE};
use super::reply::error;
use super::state::Shared;
use crate::dashboard::messages;
use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, Response, StatusCode};

/// Reads a control body: Content-Length only (no chunks), at most `MAX_BODY`, complete
/// within the head deadline of the request's arrival.
pub(super) async fn body(h: &HeaderMap, b: Body, c: &Caller) -> Result<Bytes, Response<Body>> {
    if h.contains_key(header::TRANSFER_ENCODING) {
        return Err(error(
            StatusCode::LENGTH_REQUIRED,
            "chunked bodies are not accepted; send Content-Length",
        ));
    }
    let len: usize = match h
        .get(header::CONTENT_LENGTH)
        .map(|v| v.to_str().ok().and_then(|s| s.parse().ok()))
    {
        None => 0,
        Some(Some(n)) => n,
        Some(None) => return Err(error(StatusCode::BAD_REQUEST, "bad Content-Length")),
    };
    if len > messages::MAX_BODY {
        return Err(error(StatusCode::PAYLOAD_TOO_LARGE, "body larger than 4096 bytes"));
    }
    let left = HEAD_DEADLINE.saturating_sub(c.at.elapsed());
    match tokio::time::timeout(left, axum::body::to_bytes(b, messages::MAX_BODY)).await {
        Err(_) => Err(error(StatusCode::REQUEST_TIMEOUT, "body not complete within 3 s")),
        Ok(Err(_)) => Err(error(StatusCode::BAD_REQUEST, "body shorter than Content-Length")),
        Ok(Ok(b)) => Ok(b),
    }
}

pub(super) fn note(sh: &Shared, c: &Caller, what: &str) -> String {
    format!(
        "{what} from dashboard {} at wall {:.3} s",
        c.ctl.peer.ip(),
        sh.sent.now()
    )
}
