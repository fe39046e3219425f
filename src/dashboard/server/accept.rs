//! The accept loop: every connection admitted to the table of [`super::conn`] (or answered
//! 503 when it is full) and served by hyper in a task of its own, each request going to
//! [`super::api::handle`]; out of open files, the longest-idle connection makes room.

use super::api;
use super::conn::{canned, ConnCtl, GuardedIo, MAX_HEAD};
use super::state::Shared;
use hyper::server::conn::http1;
use hyper_util::rt::TokioIo;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::net::TcpStream;

/// Accepts until the server closes; every connection runs in a task of its own.
pub async fn accept_loop(listener: tokio::net::TcpListener, router: axum::Router, sh: Arc<Shared>) {
    let mut shut = sh.shutdown.subscribe();
    let mut last_emfile_log: Option<Instant> = None;
    loop {
        let r = tokio::select! {
            r = listener.accept() => r,
            _ = shut.wait_for(|v| *v) => break,
        };
        let (sock, peer) = match r {
            Ok(x) => x,
            Err(e) if matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE)) => {
                // Out of descriptors despite the bound (other files): make room, try again.
                sh.conns.make_room();
                if last_emfile_log.is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
                    last_emfile_log = Some(Instant::now());
                    sh.log.err(format!(
                        "dashboard: out of open files ({e}) with {} connections: closed the longest-idle one",
                        sh.conns.open()
                    ));
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
            Err(_) => continue, // the client gave up before we took it (ECONNABORTED …)
        };
        let Some(ctl) = sh.conns.admit(peer) else {
            let _ = sock.try_write(&canned("503 Service Unavailable", "too many connections"));
            continue;
        };
        tokio::spawn(serve(sock, ctl, router.clone(), sh.clone()));
    }
}

/// Serves one connection until it closes, is evicted or the server closes.
async fn serve(sock: TcpStream, ctl: Arc<ConnCtl>, router: axum::Router, sh: Arc<Shared>) {
    let _ = sock.set_nodelay(true);
    let io = TokioIo::new(GuardedIo::new(sock, ctl.clone(), sh.conns.clone()));
    let svc = {
        let ctl = ctl.clone();
        let sh = sh.clone();
        hyper::service::service_fn(move |req| api::handle(req, ctl.clone(), router.clone(), sh.clone()))
    };
    let conn = http1::Builder::new()
        .max_buf_size(MAX_HEAD)
        .keep_alive(true)
        .serve_connection(io, svc);
    let mut shut = sh.shutdown.subscribe();
    tokio::select! {
        _ = conn => {}
        _ = ctl.evicted() => {}
        _ = shut.wait_for(|v| *v) => {}
    }
    sh.conns.remove(&ctl);
}
