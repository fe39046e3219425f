//! Who may do what: same-origin proof for every request that changes something, on
//! localhost too (issue 24).
//!
//! A web page open in the student's browser can send requests to the dashboard (another tab,
//! an advert, another local server on another port: 127.0.0.1:9000 is the same *site* as
//! 127.0.0.1:8080, so SameSite cookies alone do not help). So every state-changing request
//! (everything but `POST /api/estop`) must carry all of:
//!
//! 1. a `Host` naming this server (an IP literal it listens on, `localhost` on loopback, the
//!    machine's host name off loopback): a DNS-rebinding page has its own name there;
//! 2. an `Origin`, when the browser sends one, equal to `http://` + that Host;
//! 3. `Content-Type: application/json`, which a cross-origin page can only send after a CORS
//!    preflight, and preflights (`OPTIONS`) are always refused;
//! 4. `X-Rccar-Secret`: the run's random secret, which only a page served by this server
//!    carries (a cross-origin page cannot read it);
//! 5. off loopback, the session cookie from `POST /login` with the token printed at start
//!    (HttpOnly, SameSite=Strict) — or, for scripts, `X-Token: TOKEN` in place of 4 and 5.
//!
//! The Host check applies to every request (the page carries the secret). Refusals answer
//! 403 with the reason, are printed on stderr with the origin and path, counted in
//! `/api/state` (`refused`) and noted in the telemetry once a second. The e-stop needs none of
//! this: stopping is the safe direction; it is logged with its origin.

use super::log::{out, Log};
use super::reply::error;
use axum::body::Body;
use axum::http::{header, HeaderMap, HeaderValue, Method, Response, StatusCode};
use std::io::Read;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// The header that carries the page's secret.
pub const SECRET_HEADER: &str = "x-rccar-secret";
/// The header that carries the printed token (scripts; off loopback only).
pub const TOKEN_HEADER: &str = "x-token";
/// Refusal lines printed per second at most (the rest are counted, and their number printed
/// once a second).
const LINES_PER_S: u64 = 100;

/// How the server is reached.
enum Mode {
    /// 127.0.0.1 / ::1: the machine's own users; the page's secret is the proof.
    Loopback,
    /// Any other address: the printed token, proven once for a session cookie.
    Token {
        /// Printed at start; proven on the login form (or `X-Token`).
        token: String,
        /// The cookie's value after a good login.
        session: String,
    },
}

/// The access rules of one run.
pub struct Access {
    mode: Mode,
    secret: String,
    bound: SocketAddr,
    hostname: Option<String>,
    cookie: String,
    /// Refused requests so far.
    pub refused: AtomicU64,
    /// … of which the telemetry has been told.
    pub noted: AtomicU64,
    /// The last refusal, for the page and the telemetry (a lock of the server's only).
    pub last: Mutex<String>,
    line_window: AtomicU64,
    lines: AtomicU64,
    /// Refusals not printed (over [`LINES_PER_S`]) since the last summary line.
    pub unprinted: AtomicU64,
}

/// 128 random bits as hex, from /dev/urandom.
pub fn random_hex() -> String {
    let mut b = [0u8; 16];
    if std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut b))
        .is_err()
    {
        // No /dev/urandom: the clock's nanoseconds, the process id and an address (not
        // cryptographic; every Linux has /dev/urandom).
        let n = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let x = n ^ (u128::from(std::process::id()) << 64) ^ (&b as *const _ as usize as u128);
        b.copy_from_slice(&x.to_le_bytes());
    }
    b.iter().map(|v| format!("{v:02x}")).collect()
}

/// Constant-time comparison (the lengths are not secret).
pub fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// A header value as printable ASCII, at most 80 characters (`-` when absent).
pub fn shown(v: Option<&HeaderValue>) -> String {
    match v {
        None => "-".into(),
        Some(v) => v
            .as_bytes()
            .iter()
            .take(80)
            .map(|&c| if (0x20..0x7f).contains(&c) { c as char } else { '?' })
            .collect(),
    }
}

fn header<'a>(h: &'a HeaderMap, name: &str) -> Option<&'a str> {
    h.get(name).and_then(|v| v.to_str().ok())
}

fn machine_hostname() -> Option<String> {
    let n = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
    let n = n.trim().to_ascii_lowercase();
    (!n.is_empty()).then_some(n)
}

impl Access {
    /// The rules for a server bound to `bound`; `token`: `dashboard.token` (empty: random).
    pub fn new(bound: SocketAddr, token: &str) -> Access {
        // Exactly 127.0.0.1 or ::1: any other address (127.0.0.2 too) is treated as the
        // car's network address (the tests use 127.0.0.2 for that).
        let own = match bound.ip() {
            IpAddr::V4(ip) => ip == std::net::Ipv4Addr::LOCALHOST,
            IpAddr::V6(ip) => ip == std::net::Ipv6Addr::LOCALHOST,
        };
        let mode = if own {
            Mode::Loopback
        } else {
            Mode::Token {
                token: if token.is_empty() {
                    random_hex()
                } else {
                    token.to_string()
                },
                session: random_hex(),
            }
        };
        Access {
            mode,
            secret: random_hex(),
            bound,
            hostname: machine_hostname(),
            // Cookies are kept per host, not per port: one name per dashboard port.
            cookie: format!("rccar_session_{}", bound.port()),
            refused: AtomicU64::new(0),
            noted: AtomicU64::new(0),
            last: Mutex::new(String::new()),
            line_window: AtomicU64::new(0),
            lines: AtomicU64::new(0),
            unprinted: AtomicU64::new(0),
        }
    }

    /// The start-up lines: the plain URL, and off loopback the token on a line of its own.
    pub fn print_start_up(&self, bound: SocketAddr) {
        match &self.mode {
            Mode::Loopback => out(&format!("dashboard: http://{bound}/")),
            Mode::Token { token, .. } => {
                out(&format!("dashboard: http://{bound}/  (not loopback: enter the token below once on the page; it is never put in a URL)"));
                out(&format!("dashboard token: {token}"));
            }
        }
    }

    /// Whether the server listens on a loopback address.
    pub fn loopback(&self) -> bool {
        matches!(self.mode, Mode::Loopback)
    }

    /// `Host` names this server (DNS rebinding: a page on another name is refused).
    pub fn host_ok(&self, h: &HeaderMap) -> Result<(), String> {
        let Some(host) = header(h, "host") else {
            return Err("no Host header".into());
        };
        let host = host.to_ascii_lowercase();
        let (name, port) = match host.strip_prefix('[') {
            Some(rest) => match rest.split_once(']') {
                Some((n, p)) => (n.to_string(), p.strip_prefix(':')),
                None => return Err(format!("Host `{host}` is malformed")),
            },
            None => match host.rsplit_once(':') {
                Some((n, p)) => (n.to_string(), Some(p)),
                None => (host.clone(), None),
            },
        };
        let port: Option<u16> = match port {
            None => Some(80),
            Some(p) => p.parse().ok(),
        };
        let ip = self.bound.ip();
        let name = name.trim_end_matches('.');
        let name_ok = match name.parse::<IpAddr>() {
            Ok(a) => ip.is_unspecified() || a == ip,
            Err(_) if name == "localhost" => ip.is_loopback() || ip.is_unspecified(),
            Err(_) => {
                !ip.is_loopback()
                    && self
                        .hostname
                        .as_deref()
                        .is_some_and(|hn| name == hn || name.strip_suffix(".local") == Some(hn))
            }
        };
        if name_ok && port == Some(self.bound.port()) {
            Ok(())
        } else {
            Err(format!(
                "Host `{}` does not name this server ({})",
                shown(h.get("host")),
                self.bound
            ))
        }
    }

    /// `Origin`, when sent, is this server's own (`http://` + Host).
    pub fn origin_ok(&self, h: &HeaderMap) -> Result<(), String> {
        let Some(o) = h.get(header::ORIGIN) else {
            return Ok(());
        };
        let own = format!("http://{}", header(h, "host").unwrap_or(""));
        match o.to_str() {
            Ok(o) if o.eq_ignore_ascii_case(&own) => Ok(()),
            _ => Err(format!("Origin {} is not this server's ({own})", shown(Some(o)))),
        }
    }

    /// The login cookie or the token header (always true on loopback).
    pub fn has_session(&self, h: &HeaderMap) -> bool {
        let Mode::Token { token, session } = &self.mode else {
            return true;
        };
        if header(h, TOKEN_HEADER).is_some_and(|t| same(t, token)) {
            return true;
        }
        h.get_all(header::COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|kv| kv.trim().split_once('='))
            .any(|(k, v)| k == self.cookie && same(v, session))
    }

    /// Everything a state-changing request must carry (Host is checked before).
    pub fn control_ok(&self, h: &HeaderMap) -> Result<(), String> {
        self.origin_ok(h)?;
        let ct = header(h, "content-type").unwrap_or("");
        let media = ct.split(';').next().unwrap_or("").trim();
        if !media.eq_ignore_ascii_case("application/json") {
            return Err(format!(
                "Content-Type `{}` (controls take application/json only)",
                shown(h.get("content-type"))
            ));
        }
        let by_token = matches!(&self.mode, Mode::Token { token, .. }
            if header(h, TOKEN_HEADER).is_some_and(|t| same(t, token)));
        if !by_token && !header(h, SECRET_HEADER).is_some_and(|s| same(s, &self.secret)) {
            return Err("missing or wrong X-Rccar-Secret (only this server's page has it)".into());
        }
        if !self.has_session(h) {
            return Err("not logged in (enter the token printed at start on the page)".into());
        }
        Ok(())
    }

    /// The page: with the secret for a session, else (off loopback) the login form.
    pub fn page(&self, template: &str, h: &HeaderMap) -> String {
        let (secret, login) = if self.has_session(h) {
            (self.secret.as_str(), "")
        } else {
            ("", "1")
        };
        template
            .replace("__RCCAR_SECRET__", secret)
            .replace("__RCCAR_LOGIN__", login)
    }

    /// Checks a login form's token; `Some(Set-Cookie value)` when right.
    pub fn login(&self, body: &[u8]) -> Option<String> {
        let Mode::Token { token, session } = &self.mode else {
            return None;
        };
        let given = std::str::from_utf8(body)
            .ok()?
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .find(|(k, _)| *k == "token")
            .map(|(_, v)| v.trim().to_string())?;
        same(&given, token).then(|| format!("{}={session}; HttpOnly; SameSite=Strict; Path=/", self.cookie))
    }
}

/// Answers 403 with `why`, counts it in `a` and prints it through `log` (at most
/// [`LINES_PER_S`] lines in the second `now_s` falls in, seconds on the dashboard's clock).
#[allow(clippy::too_many_arguments)]
pub fn refuse(
    a: &Access,
    log: &Log,
    now_s: f64,
    method: &Method,
    path: &str,
    h: &HeaderMap,
    peer: SocketAddr,
    why: &str,
) -> Response<Body> {
    let n = a.refused.fetch_add(1, Ordering::SeqCst) + 1;
    let line = format!(
        "refused {method} {} from {peer} (Origin {}, Host {}): {why}",
        path.chars().take(80).collect::<String>(),
        shown(h.get(header::ORIGIN)),
        shown(h.get("host")),
    );
    *a.last.lock().unwrap_or_else(|e| e.into_inner()) = line.clone();
    let second = now_s as u64;
    if a.line_window.swap(second, Ordering::SeqCst) != second {
        a.lines.store(0, Ordering::SeqCst);
    }
    if a.lines.fetch_add(1, Ordering::SeqCst) < LINES_PER_S {
        log.err(format!("dashboard: {line} [{n} refused so far]"));
    } else {
        a.unprinted.fetch_add(1, Ordering::SeqCst);
    }
    error(StatusCode::FORBIDDEN, why)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hm(pairs: &[(&str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(
                axum::http::HeaderName::from_bytes(k.as_bytes()).unwrap(),
                HeaderValue::from_str(v).unwrap(),
            );
        }
        h
    }

    #[test]
    fn host_must_name_this_server() {
        let a = Access::new("127.0.0.1:8080".parse().unwrap(), "");
        for ok in ["127.0.0.1:8080", "localhost:8080", "LOCALHOST:8080"] {
            assert!(a.host_ok(&hm(&[("host", ok)])).is_ok(), "{ok}");
        }
        for bad in [
            "evil.example:8080",
            "127.0.0.1:9000",
            "127.0.0.2:8080",
            "127.0.0.1",
            "[::1]:8080",
            "a:b:c",
        ] {
            let e = a.host_ok(&hm(&[("host", bad)])).unwrap_err();
            assert!(e.contains("does not name this server"), "{bad}: {e}");
        }
        assert!(a.host_ok(&hm(&[])).is_err());
        let any = Access::new("0.0.0.0:80".parse().unwrap(), "");
        for ok in ["192.168.1.7", "10.0.0.2:80", "[fe80::1]:80", "localhost"] {
            assert!(any.host_ok(&hm(&[("host", ok)])).is_ok(), "{ok}");
        }
        assert!(any.host_ok(&hm(&[("host", "rebind.evil.example")])).is_err());
    }

    #[test]
    fn controls_need_origin_json_secret_and_off_loopback_a_session() {
        let a = Access::new("127.0.0.1:8080".parse().unwrap(), "");
        let s = a.secret.clone();
        let good = [
            ("host", "127.0.0.1:8080"),
            ("content-type", "application/json"),
            (SECRET_HEADER, s.as_str()),
        ];
        assert!(a.control_ok(&hm(&good)).is_ok());
        let with = |extra: (&str, &str)| {
            let mut v: Vec<(&str, &str)> = good.iter().copied().filter(|(k, _)| *k != extra.0).collect();
            v.push(extra);
            a.control_ok(&hm(&v))
        };
        assert!(with(("origin", "http://127.0.0.1:8080")).is_ok());
        assert!(with(("origin", "http://127.0.0.1:9000"))
            .unwrap_err()
            .contains("Origin"));
        assert!(with(("origin", "null")).is_err());
        assert!(with(("content-type", "text/plain"))
            .unwrap_err()
            .contains("Content-Type"));
        assert!(with(("content-type", "application/json; charset=utf-8")).is_ok());
        assert!(with((SECRET_HEADER, "0123")).unwrap_err().contains("Secret"));
        let r = Access::new("127.0.0.2:8080".parse().unwrap(), "abcdefgh12");
        let rs = r.secret.clone();
        let base = [
            ("host", "127.0.0.2:8080"),
            ("content-type", "application/json"),
            (SECRET_HEADER, rs.as_str()),
        ];
        assert!(r.control_ok(&hm(&base)).unwrap_err().contains("not logged in"));
        let cookie = r.login(b"token=abcdefgh12").unwrap();
        assert!(cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"));
        assert!(r.login(b"token=abcdefgh13").is_none());
        let kv = cookie.split(';').next().unwrap().to_string();
        let mut v = base.to_vec();
        v.push(("cookie", &kv));
        assert!(r.control_ok(&hm(&v)).is_ok());
        let tok = [
            ("host", "127.0.0.2:8080"),
            ("content-type", "application/json"),
            ("x-token", "abcdefgh12"),
        ];
        assert!(r.control_ok(&hm(&tok)).is_ok());
    }
}
