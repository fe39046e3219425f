//! The server's JSON answers: a value with a status ([`reply`]) and `{"error": …}`
//! ([`error`]). The bottom of the server's modules: it imports none of them.

use axum::body::Body;
use axum::http::{header, HeaderValue, Response, StatusCode};
use serde_json::{json, Value};

/// A JSON response.
pub fn reply(code: StatusCode, v: &Value) -> Response<Body> {
    let mut r = Response::new(Body::from(v.to_string()));
    *r.status_mut() = code;
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    r
}

/// `{"error": msg}` with `code`.
pub fn error(code: StatusCode, msg: &str) -> Response<Body> {
    reply(code, &json!({ "error": msg }))
}
