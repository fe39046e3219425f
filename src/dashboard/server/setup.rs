//! Set-up by clicking (issue 26): the page `GET /setup`, a frozen camera frame
//! (`GET /api/setup/frame`, PNG at the pipeline's frame size; `POST /api/setup/freeze` takes a
//! new one), the bird's-eye and binary images of a candidate ROI and threshold made by the
//! pipeline's own lane detector on that frame (`POST /api/setup/preview`), and
//! `POST /api/setup/apply`, which hands the new `[warp] src` and `[lane]` threshold to the loop
//! for its next frame and marks them changed for `/api/save`. Every POST passes the same access
//! checks as the other controls (`super::api::handle`); the frame, like the stream, needs the
//! login off loopback.

use super::request::{body, note};
use super::conn::Caller;
use super::reply::{error, reply};
use super::state::{Frozen, Shared};
use crate::config::{Config, ThresholdMode};
use crate::dashboard::local_toml::Saved;
use crate::report::base64;
use crate::dashboard::messages::{self, Control, SetupRequest, CORNERS};
use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderMap, HeaderValue, Response, StatusCode};
use axum::Extension;
use image::RgbImage;
use serde::Deserialize;
use serde_json::{json, Value};
use std::sync::Arc;

const SETUP_PAGE: &str = include_str!("../setup.html");

/// `GET /setup`: the set-up page (the run's secret embedded, as the main page).
pub async fn page(State(sh): State<Arc<Shared>>, h: HeaderMap) -> Response<Body> {
    let mut r = Response::new(Body::from(sh.access.page(SETUP_PAGE, &h)));
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/html; charset=utf-8"),
    );
    r
}

fn mode_name(m: ThresholdMode) -> &'static str {
    match m {
        ThresholdMode::Fixed => "fixed",
        ThresholdMode::Otsu => "otsu",
        ThresholdMode::Adaptive => "adaptive",
    }
}

fn png<P: image::PixelWithColorType>(img: &image::ImageBuffer<P, Vec<P::Subpixel>>) -> Vec<u8>
where
    [P::Subpixel]: image::EncodableLayout,
{
    let mut buf = std::io::Cursor::new(Vec::new());
    // Encoding into memory cannot fail for these sizes; an empty image shows as broken.
    let _ = img.write_to(&mut buf, image::ImageFormat::Png);
    buf.into_inner()
}

/// A frame at the pipeline's size (`[camera]` width × height), resized as the pipeline
/// resizes a frame of another size.
fn at_size(img: &RgbImage, cfg: &Config) -> RgbImage {
    let (w, h) = (cfg.camera.width, cfg.camera.height);
    if img.dimensions() == (w, h) {
        img.clone()
    } else {
        image::imageops::resize(img, w, h, image::imageops::FilterType::Triangle)
    }
}

/// Why no frame or preview: the status and the message (small, unlike a response).
type Refused = (StatusCode, String);

/// The JSON error response of `r`.
fn refused(r: Refused) -> Response<Body> {
    error(r.0, &r.1)
}

/// Freezes a frame: the given file's (`--setup-frame`) or the newest camera frame.
fn freeze(sh: &Shared, file: bool) -> Result<Arc<Frozen>, Refused> {
    let cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let (image, what) = if file {
        match &sh.setup_given {
            Some((img, name)) => (at_size(img, &cfg), format!("the file {name}")),
            None => {
                return Err((
                    StatusCode::NOT_FOUND,
                    "no set-up frame was given at start (--setup-frame FILE)".into(),
                ))
            }
        }
    } else {
        let snap = sh.view.lock().unwrap_or_else(|e| e.into_inner()).snap.clone();
        match snap {
            Some(s) => (
                at_size(&s.image, &cfg),
                format!("camera frame {} at {:.2} s", s.record.frame, s.record.time_s),
            ),
            None => {
                return Err((
                    StatusCode::SERVICE_UNAVAILABLE,
                    "no camera frame yet: try again in a moment".into(),
                ))
            }
        }
    };
    let png = png(&image);
    let f = Arc::new(Frozen { image, png, what });
    *sh.frozen.lock().unwrap_or_else(|e| e.into_inner()) = Some(f.clone());
    Ok(f)
}

/// The frozen frame; the first time, the given file's or else the newest camera frame.
fn frozen(sh: &Shared) -> Result<Arc<Frozen>, Refused> {
    if let Some(f) = sh.frozen.lock().unwrap_or_else(|e| e.into_inner()).clone() {
        return Ok(f);
    }
    freeze(sh, sh.setup_given.is_some())
}

/// `GET /api/setup/frame`: the frozen frame as PNG, at the pipeline's frame size.
pub async fn frame(State(sh): State<Arc<Shared>>) -> Response<Body> {
    let f = match tokio::task::spawn_blocking(move || frozen(&sh)).await {
        Ok(Ok(f)) => f,
        Ok(Err(r)) => return refused(r),
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    let mut r = Response::new(Body::from(f.png.clone()));
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
    r
}

/// `POST /api/setup/freeze` body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FreezeRequest {
    /// `camera` (the newest frame, the default) or `file` (the `--setup-frame` image).
    #[serde(default)]
    source: Option<String>,
}

/// `POST /api/setup/freeze`: freezes the newest camera frame (or the given file) for the page.
pub async fn freeze_now(
    State(sh): State<Arc<Shared>>,
    Extension(c): Extension<Caller>,
    h: HeaderMap,
    b: Body,
) -> Response<Body> {
    let bytes = match body(&h, b, &c).await {
        Ok(b) => b,
        Err(r) => return r,
    };
    let q: FreezeRequest = if bytes.iter().all(u8::is_ascii_whitespace) {
        FreezeRequest { source: None }
    } else {
        match messages::parse_body(&bytes) {
            Ok(q) => q,
            Err(e) => return error(StatusCode::BAD_REQUEST, &e.to_string()),
        }
    };
    let file = match q.source.as_deref() {
        None | Some("camera") => false,
        Some("file") => true,
        Some(other) => {
            let msg = format!(
                "source `{}` is not one of camera, file",
                other.chars().take(32).collect::<String>()
            );
            return error(StatusCode::BAD_REQUEST, &msg);
        }
    };
    let sh2 = sh.clone();
    match tokio::task::spawn_blocking(move || freeze(&sh2, file)).await {
        Ok(Ok(f)) => reply(StatusCode::OK, &json!({"frozen": f.what})),
        Ok(Err(r)) => refused(r),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    }
}

/// `GET /api/setup/state`: the frame size, the corner order, the values in force and the
/// frozen frame's origin.
pub async fn state(State(sh): State<Arc<Shared>>, Extension(c): Extension<Caller>) -> Response<Body> {
    let cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let frozen = sh
        .frozen
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .as_ref()
        .map(|f| f.what.clone());
    let changed = sh.changed.lock().unwrap_or_else(|e| e.into_inner()).clone();
    reply(
        StatusCode::OK,
        &json!({
            "read_only": !c.session,
            "frame": {"width": cfg.camera.width, "height": cfg.camera.height},
            "bird": {"width": cfg.warp.out_width, "height": cfg.warp.out_height},
            "corners": CORNERS,
            "src": cfg.warp.src,
            "threshold": cfg.lane.threshold,
            "threshold_mode": mode_name(cfg.lane.threshold_mode),
            "adaptive_c": cfg.lane.adaptive_c,
            "frozen": frozen,
            "file_given": sh.setup_given.as_ref().map(|(_, n)| n.clone()),
            "changed": changed,
        }),
    )
}

/// The request's body checked against the configuration in force: the new configuration.
async fn checked(sh: &Shared, c: &Caller, h: &HeaderMap, b: Body) -> Result<(SetupRequest, Config), Response<Body>> {
    let bytes = body(h, b, c).await?;
    let req: SetupRequest = messages::parse_body(&bytes).map_err(|e| error(StatusCode::BAD_REQUEST, &e.to_string()))?;
    let cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let new = messages::validate_setup(&cfg, &req).map_err(|e| error(StatusCode::BAD_REQUEST, &e.to_string()))?;
    Ok((req, new))
}

/// The bird's-eye and binary images of `cfg`'s lane stage on `frame`, made by the pipeline's
/// own lane detector (the same warp map, threshold and Canny), as PNG `data:` URLs, with the
/// threshold level used and the lane measured.
fn preview_images(cfg: &Config, frame: &RgbImage) -> Result<Value, String> {
    let mut det = cfg.lane_detector().map_err(|e| e.to_string())?;
    let mut times = crate::timing::StageTimes::default();
    let lane = det.measure(frame, &mut crate::timing::NoTimer, &mut times);
    let im = det.images();
    let url = |bytes: Vec<u8>| format!("data:image/png;base64,{}", base64(&bytes));
    Ok(json!({
        "src": cfg.warp.src,
        "bird": url(png(&im.bird)),
        "binary": url(png(&im.binary)),
        "level": im.level,
        "band_rows": im.band_rows,
        "lane": lane,
    }))
}

/// `POST /api/setup/preview`: the bird's-eye view and the binary image of the body's ROI and
/// threshold on the frozen frame (nothing changes for the car).
pub async fn preview(
    State(sh): State<Arc<Shared>>,
    Extension(c): Extension<Caller>,
    h: HeaderMap,
    b: Body,
) -> Response<Body> {
    let (_, new) = match checked(&sh, &c, &h, b).await {
        Ok(v) => v,
        Err(r) => return r,
    };
    let sh2 = sh.clone();
    let r = tokio::task::spawn_blocking(move || {
        let f = frozen(&sh2)?;
        preview_images(&new, &f.image).map_err(|e| (StatusCode::BAD_REQUEST, e))
    })
    .await;
    match r {
        Ok(Ok(v)) => reply(StatusCode::OK, &v),
        Ok(Err(r)) => refused(r),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    }
}

/// `POST /api/setup/apply`: the body's ROI and threshold for the running pipeline from its
/// next frame on (an event in that frame's telemetry record), marked changed for `/api/save`.
pub async fn apply(
    State(sh): State<Arc<Shared>>,
    Extension(c): Extension<Caller>,
    h: HeaderMap,
    b: Body,
) -> Response<Body> {
    let (req, new) = match checked(&sh, &c, &h, b).await {
        Ok(v) => v,
        Err(r) => return r,
    };
    // A new ROI changes what the car steers by: only on a car that cannot move.
    if sh.arm.is_armed() {
        return error(
            StatusCode::CONFLICT,
            "the car is armed: disarm it before applying a new ROI or threshold",
        );
    }
    let mut cfg = sh.cfg.lock().unwrap_or_else(|e| e.into_inner());
    let (old_w, old_l) = (&cfg.warp, &cfg.lane);
    let what = format!(
        "set-up: warp.src={:?} lane.threshold={} lane.threshold_mode={} lane.adaptive_c={} (was {:?}, {}, {}, {})",
        new.warp.src,
        new.lane.threshold,
        mode_name(new.lane.threshold_mode),
        new.lane.adaptive_c,
        old_w.src,
        old_l.threshold,
        mode_name(old_l.threshold_mode),
        old_l.adaptive_c
    );
    let queued = sh.tx.send(Control::Lane {
        cfg: Box::new(new.clone()),
        note: note(&sh, &c, &what),
    });
    if !queued {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the loop is not taking changes (inbox full)",
        );
    }
    *cfg = new.clone();
    drop(cfg);
    {
        let mut ch = sh.changed.lock().unwrap_or_else(|e| e.into_inner());
        ch.insert("warp.src".into(), Saved::Points(new.warp.src));
        if req.threshold.is_some() {
            ch.insert("lane.threshold".into(), Saved::Int(i64::from(new.lane.threshold)));
        }
        if req.threshold_mode.is_some() {
            ch.insert(
                "lane.threshold_mode".into(),
                Saved::Text(mode_name(new.lane.threshold_mode).into()),
            );
        }
        if req.adaptive_c.is_some() {
            ch.insert("lane.adaptive_c".into(), Saved::Int(i64::from(new.lane.adaptive_c)));
        }
    }
    reply(
        StatusCode::OK,
        &json!({
            "src": new.warp.src,
            "threshold": new.lane.threshold,
            "threshold_mode": mode_name(new.lane.threshold_mode),
            "adaptive_c": new.lane.adaptive_c,
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The preview is the pipeline's own lane stage: the same images as a `LaneDetector` of
    /// that configuration measuring the frame.
    #[test]
    fn the_preview_is_the_pipelines_lane_stage() {
        let cfg = Config::default();
        let frame = image::open(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/lane_sample/frame_000.png"
        ))
        .unwrap()
        .to_rgb8();
        let v = preview_images(&cfg, &frame).unwrap();
        let mut det = cfg.lane_detector().unwrap();
        det.measure(
            &frame,
            &mut crate::timing::NoTimer,
            &mut crate::timing::StageTimes::default(),
        );
        let want = format!("data:image/png;base64,{}", base64(&png(&det.images().binary)));
        assert_eq!(v["binary"].as_str().unwrap(), want);
        // The shipped adaptive threshold has no one level (0); a fixed one reports its own.
        assert_eq!(v["level"], 0);
        assert!(v["lane"]["p_left"].as_f64().is_some());
        let fixed = cfg.with_override("lane.threshold_mode=fixed").unwrap();
        assert_eq!(preview_images(&fixed, &frame).unwrap()["level"], 170);
    }
}
