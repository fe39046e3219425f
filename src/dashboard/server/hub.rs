//! The server's own threads and the stream: the hub (takes the loop's snapshots, keeps the
//! plot history, renders and encodes the stream image once for every viewer), the heartbeat
//! watchdog, and the MJPEG body. (The logger thread is [`super::log`].)

use super::conn::Caller;
use super::reply::error;
use super::state::{Shared, HISTORY_S};
use crate::dashboard::messages::{Control, Snapshot};
use crate::drive::{Actor, Latest, StopSignal};
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{header, Response, StatusCode};
use hyper::body::Frame;
use image::{Rgb, RgbImage};
use std::convert::Infallible;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::sync::watch;

/// The web's threads yield to the control loop: nice 10 for this thread (Linux; elsewhere a
/// no-op). The hub's annotation and JPEG encoding then take CPU only when the loop does not.
fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: plain system calls on the calling thread's own id; no memory is passed.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, 10);
    }
}

/// Disarms when the page that armed the car stops sending heartbeats; once a second tells
/// the telemetry how many requests were refused.
pub fn watchdog(sh: Arc<Shared>, stop: StopSignal) {
    // The watchdog disarms the car: it keeps normal priority.
    let mut tick = 0u64;
    while !sh.closed.load(Ordering::SeqCst) && !stop.is_set() {
        std::thread::sleep(Duration::from_millis(20));
        tick += 1;
        if tick.is_multiple_of(50) {
            note_refusals(&sh);
        }
        if sh.heartbeat_ms == 0 || !sh.armed_by_page.load(Ordering::SeqCst) || !sh.arm.is_armed() {
            continue;
        }
        let age = sh.now_ms().saturating_sub(sh.last_heartbeat_ms.load(Ordering::SeqCst));
        if age > sh.heartbeat_ms {
            sh.arm.disarm(Actor::Heartbeat);
            sh.armed_by_page.store(false, Ordering::SeqCst);
            let msg = format!(
                "disarmed: no heartbeat from the dashboard for {age} ms (limit {} ms) at wall {:.3} s",
                sh.heartbeat_ms,
                sh.sent.now()
            );
            super::log::out(&format!("dashboard: {msg}"));
            sh.tx.send(Control::Note(msg));
        }
    }
}

/// One telemetry event (and, past the print limit, one stderr line) for the requests
/// refused since the last one.
fn note_refusals(sh: &Shared) {
    let a = &sh.access;
    let quiet = a.unprinted.swap(0, Ordering::SeqCst);
    if quiet > 0 {
        sh.log.err(format!(
            "dashboard: … and {quiet} more refused request(s) not printed (over 100 a second)"
        ));
    }
    let n = a.refused.load(Ordering::SeqCst);
    let before = a.noted.swap(n, Ordering::SeqCst);
    if n > before {
        let last = a.last.lock().unwrap_or_else(|e| e.into_inner()).clone();
        sh.tx.send(Control::Note(format!(
            "dashboard refused {} request(s) ({n} in all); last: {last}",
            n - before
        )));
    }
}

/// Takes the loop's snapshots, keeps the plot history, renders and encodes the stream image.
pub fn hub(slot: Arc<Latest<Arc<Snapshot>>>, sh: Arc<Shared>) {
    lower_priority();
    while !sh.closed.load(Ordering::SeqCst) {
        let Some(snap) = slot.wait_take(Duration::from_millis(200)) else {
            if slot.is_closed() {
                break;
            }
            continue;
        };
        {
            let mut v = sh.view.lock().unwrap_or_else(|e| e.into_inner());
            if let Some(first) = snap.points.first() {
                // A restarted clock (a new run) clears the plots.
                if v.history.back().is_some_and(|b| first.t < b.t) {
                    v.history.clear();
                }
            }
            v.history.extend(snap.points.iter().cloned());
            let newest = v.history.back().map_or(0.0, |p| p.t);
            while v.history.front().is_some_and(|p| p.t < newest - HISTORY_S) {
                v.history.pop_front();
            }
            v.snap = Some(snap.clone());
        }
        sh.poke();
        if sh.viewers.load(Ordering::SeqCst) == 0 {
            continue; // nobody watches: no JPEG work
        }
        let img = render(&snap);
        let mut buf = Vec::with_capacity(32 * 1024);
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, 75);
        if img.write_with_encoder(enc).is_err() {
            continue;
        }
        sh.jpeg.send_replace(Arc::new(buf));
    }
    sh.close();
}

/// The annotated camera frame and, to its right, the bird's-eye view (grey, the binary image
/// in red, the column histogram in yellow, the lines found in green) at the same height.
fn render(s: &Snapshot) -> RgbImage {
    // No inset: the bird's-eye view is drawn beside the frame, the scene stays visible.
    let mut ann = crate::annotate::annotate_with(&s.image, &s.roi, &s.homography, &s.lane_images, &s.lane, &s.command, false);
    draw_objects(&mut ann, &s.objects);
    if let Some(j) = &s.record.junction {
        crate::annotate::junction(&mut ann, j);
    }
    let li = &s.lane_images;
    let (bw, bh) = li.bird.dimensions();
    let h = ann.height();
    let scale = h as f64 / bh.max(1) as f64;
    let w2 = ((bw as f64 * scale).round() as u32).max(1);
    let mut out = RgbImage::new(ann.width() + w2, h);
    image::imageops::replace(&mut out, &ann, 0, 0);
    let hist_max = li.hist.iter().copied().max().unwrap_or(1).max(1) as f64;
    for y in 0..h {
        let sy = ((y as f64 / scale) as u32).min(bh - 1);
        for x in 0..w2 {
            let sx = ((x as f64 / scale) as u32).min(bw - 1);
            let g = li.bird.get_pixel(sx, sy)[0];
            let on = li.binary.dimensions() == (bw, bh) && li.binary.get_pixel(sx, sy)[0] > 0;
            let px = if on { Rgb([255, g / 3, g / 3]) } else { Rgb([g, g, g]) };
            out.put_pixel(ann.width() + x, y, px);
        }
    }
    // Histogram along the bottom, a quarter of the height at its highest column.
    if li.hist.len() == bw as usize {
        for x in 0..w2 {
            let sx = ((x as f64 / scale) as usize).min(li.hist.len() - 1);
            let bar = (li.hist[sx] as f64 / hist_max * h as f64 / 4.0) as u32;
            for y in h.saturating_sub(bar)..h {
                out.put_pixel(ann.width() + x, y, Rgb([255, 220, 0]));
            }
        }
    }
    for (c, col) in [
        (s.lane.p_left, Rgb([255, 40, 40])),
        (s.lane.p_right, Rgb([255, 40, 40])),
        (s.lane.lane_center, Rgb([40, 230, 60])),
    ] {
        if let Some(c) = c {
            let x = (c * scale).round();
            if x >= 0.0 && (x as u32) < w2 {
                for y in 0..h {
                    out.put_pixel(ann.width() + x as u32, y, col);
                }
            }
        }
    }
    out
}

/// Each detected object's box in magenta with its class and range ("STOP 0.84M"; a light
/// with its colour, a turn sign with its arrow: "TURN SIGN LEFT 0.84M"), the label above the
/// box or inside it at the top edge.
fn draw_objects(img: &mut RgbImage, objects: &[crate::pipeline::RangedObject]) {
    use crate::annotate::{line, text};
    let c = Rgb([255, 0, 255]);
    for o in objects {
        let [l, t, r, b] = o.bbox;
        for (x0, y0, x1, y1) in [(l, t, r, t), (r, t, r, b), (r, b, l, b), (l, b, l, t)] {
            line(img, x0, y0, x1, y1, c);
        }
        let mut label = o.class.name().replace('_', " ").to_uppercase();
        if let Some(light) = o.light {
            label = format!("{label} {light:?}").to_uppercase();
        }
        if let Some(arrow) = o.arrow {
            label = format!("{label} {}", arrow.name()).to_uppercase();
        }
        if let Some(d) = o.distance_m {
            label = format!("{label} {d:.2}M");
        }
        let y = if t >= 10.0 { t - 9.0 } else { t + 2.0 };
        text(img, l.max(0.0) as i64, y as i64, &label, c);
    }
}

/// `GET /stream.mjpg`: MJPEG to one viewer, the newest JPEG whenever it is ready for one.
pub async fn stream(State(sh): State<Arc<Shared>>, axum::Extension(c): axum::Extension<Caller>) -> Response<Body> {
    if sh.viewers.fetch_add(1, Ordering::SeqCst) >= sh.max_viewers {
        sh.viewers.fetch_sub(1, Ordering::SeqCst);
        return error(StatusCode::SERVICE_UNAVAILABLE, "too many viewers");
    }
    c.ctl.streaming();
    let mut rx = sh.jpeg.subscribe();
    rx.mark_changed(); // the frame there is now goes out first
    let next = Box::pin(next_part(rx, sh.shutdown.subscribe()));
    let body = Mjpeg { sh, next: Some(next) };
    Response::builder()
        .header(header::CONTENT_TYPE, "multipart/x-mixed-replace; boundary=rccarframe")
        .header(header::CONNECTION, "close")
        .body(Body::new(body))
        .unwrap_or_else(|_| error(StatusCode::INTERNAL_SERVER_ERROR, "stream"))
}

type Part = Option<(watch::Receiver<Arc<Vec<u8>>>, watch::Receiver<bool>, Bytes)>;

/// Waits for a JPEG newer than the last one sent; `None` when the server closes.
async fn next_part(mut rx: watch::Receiver<Arc<Vec<u8>>>, mut shut: watch::Receiver<bool>) -> Part {
    loop {
        tokio::select! {
            r = rx.changed() => r.ok()?,
            _ = shut.wait_for(|v| *v) => return None,
        }
        let jpeg = rx.borrow_and_update().clone();
        if jpeg.is_empty() {
            continue;
        }
        let head = format!(
            "--rccarframe\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
            jpeg.len()
        );
        let mut part = Vec::with_capacity(head.len() + jpeg.len() + 2);
        part.extend_from_slice(head.as_bytes());
        part.extend_from_slice(&jpeg);
        part.extend_from_slice(b"\r\n");
        return Some((rx, shut, Bytes::from(part)));
    }
}

/// The stream's body: asks for the next part only when hyper has taken the previous one, so
/// frames a slow viewer could not take are skipped, never queued.
struct Mjpeg {
    sh: Arc<Shared>,
    next: Option<Pin<Box<dyn Future<Output = Part> + Send>>>,
}

impl Drop for Mjpeg {
    fn drop(&mut self) {
        self.sh.viewers.fetch_sub(1, Ordering::SeqCst);
    }
}

impl hyper::body::Body for Mjpeg {
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
            Poll::Ready(Some((rx, shut, part))) => {
                this.next = Some(Box::pin(next_part(rx, shut)));
                this.sh.frames_sent.fetch_add(1, Ordering::Relaxed);
                Poll::Ready(Some(Ok(Frame::data(part))))
            }
        }
    }
}
