//! What the control loop and the web server say to each other (no sockets, no clock): the
//! snapshot the loop publishes ([`Snapshot`], [`PlotPoint`], [`Live`]), the messages the page
//! sends the loop ([`Control`] through [`ControlSender`]), and their checks: the settable keys
//! ([`settable`]), bodies ([`parse_body`]) and values ([`validate_set`], with the
//! configuration's own ranges). Both sides import this; it imports neither.

use crate::config::Config;
use crate::control::behaviour::Transition;
use crate::control::catalog::{self, unused_by};
use crate::control::params::ParamInfo;
use crate::control::Command;
use crate::lane::warp::Homography;
use crate::lane::{LaneImages, LaneMeasurement};
use crate::pipeline::RangedObject;
use crate::telemetry::FrameRecord;
use image::RgbImage;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};

/// The keys the page may change while the car runs (the rest needs a restart): the
/// parameter table of the run's steering method, then the throttle's
/// ([`crate::control::catalog::of_method`]), with their units, ranges, sliders and docs.
pub fn settable(cfg: &Config) -> Vec<ParamInfo> {
    catalog::of_method(cfg.steering.method)
}

/// Largest control message body the server reads, bytes.
pub const MAX_BODY: usize = 4096;

/// Messages queued for the loop at most; more are refused (HTTP 503), never queued.
pub const INBOX_CAPACITY: usize = 64;

/// A refused control message: the HTTP server answers 400 with this text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    /// The body is not the JSON the endpoint takes.
    #[error("malformed request: {0}")]
    Malformed(String),
    /// A key the dashboard may not change.
    #[error("unknown key `{key}` (settable: {settable})")]
    UnknownKey {
        /// The key as given (at most 64 characters).
        key: String,
        /// The settable keys, comma-separated.
        settable: String,
    },
    /// A parameter of another steering method than the run's.
    #[error("{0}; the steering method cannot change while the car runs")]
    OtherMethod(String),
    /// NaN or infinite.
    #[error("{key} = {value} is not a finite number")]
    NotFinite {
        /// The key.
        key: String,
        /// The value as given.
        value: String,
    },
    /// Outside the configuration's range: the config's own message (key, value, range).
    #[error("{0}")]
    OutOfRange(String),
}

/// `POST /api/set` body: one key and its new value.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetRequest {
    /// Dotted config key, one of [`settable`].
    pub key: String,
    /// The new value.
    pub value: f64,
}

/// `POST /api/sim/place` body: where along the track, metres.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaceRequest {
    /// Arc length along the track's centre line, metres (0 ..= track length).
    pub s: f64,
}

/// `POST /api/drive` body: the human's steering and throttle, each in −1..1 (issue 26).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriveRequest {
    /// −1 (full left) ..= 1 (full right).
    pub steer: f64,
    /// −1 (full reverse) ..= 1 (full forward), scaled by `manual.max_throttle`.
    pub throttle: f64,
}

/// `POST /api/mode` body: `manual`, `assisted` or `autopilot`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModeRequest {
    /// The mode's name.
    pub mode: String,
}

/// `POST /api/record` body: record (`true`) or pause (`false`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordRequest {
    /// Record frames from the next one on.
    pub on: bool,
}

/// The ROI corners' names, in `warp.src` order (config/car.toml's).
pub const CORNERS: [&str; 4] = ["top-left", "top-right", "bottom-right", "bottom-left"];

/// `POST /api/setup/preview` and `/api/setup/apply` body (issue 26, set-up by clicking): the
/// ROI's four corners in frame pixels, in `warp.src` order ([`CORNERS`]), and optionally the
/// lane threshold, its mode and the adaptive threshold's C (absent: the values in force).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetupRequest {
    /// The corners, frame pixels (pixel (i, j) has its centre at (i, j)).
    pub src: [[f64; 2]; 4],
    /// `lane.threshold`, a grey level 0..=255.
    #[serde(default)]
    pub threshold: Option<f64>,
    /// `lane.threshold_mode`: `fixed`, `otsu` or `adaptive`.
    #[serde(default)]
    pub threshold_mode: Option<String>,
    /// `lane.adaptive_c`, whole grey levels −255..=255 (the adaptive threshold's C: a pixel
    /// is line when brighter than its square's mean minus C).
    #[serde(default)]
    pub adaptive_c: Option<f64>,
}

/// Checks a set-up request against the frame (every corner inside it, pixel centres
/// `0 ..= width − 1`, `0 ..= height − 1`), the homography (it must exist: no three corners on
/// one line, a convex quadrilateral in order) and the configuration's own checks (far edge
/// above the near edge, not mirrored, the steering method still builds). Corners are kept to
/// 1/100 pixel. Returns the configuration with `warp.src`, `lane.threshold`,
/// `lane.threshold_mode` and `lane.adaptive_c` set; the error names the corner or the key and
/// what is wrong.
pub fn validate_setup(cfg: &Config, req: &SetupRequest) -> Result<Config, ControlError> {
    let (w, h) = (cfg.camera.width, cfg.camera.height);
    let mut src = req.src;
    for (i, p) in src.iter_mut().enumerate() {
        let name = CORNERS[i];
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(ControlError::OutOfRange(format!(
                "warp.src[{i}] ({name}) is not a finite number"
            )));
        }
        let (xmax, ymax) = (f64::from(w - 1), f64::from(h - 1));
        if !(0.0..=xmax).contains(&p[0]) || !(0.0..=ymax).contains(&p[1]) {
            return Err(ControlError::OutOfRange(format!(
                "warp.src[{i}] ({name}) = [{}, {}] lies outside the {w}x{h} frame (x 0 ..= {xmax}, y 0 ..= {ymax})",
                p[0], p[1]
            )));
        }
        *p = p.map(|v| (v * 100.0).round() / 100.0);
    }
    if let Err(e) = crate::lane::warp::Homography::from_quad_to_rect(&src, cfg.warp.out_width, cfg.warp.out_height) {
        return Err(ControlError::OutOfRange(format!(
            "warp.src: no bird's-eye view of these corners ({e}); click them in the order {}",
            CORNERS.join(", ")
        )));
    }
    let mut new = cfg.clone();
    new.warp.src = src;
    if let Some(t) = req.threshold {
        if !(t.is_finite() && t.fract() == 0.0 && (0.0..=255.0).contains(&t)) {
            return Err(ControlError::OutOfRange(format!(
                "lane.threshold = {t} is out of range (allowed: a whole grey level 0 ..= 255)"
            )));
        }
        new.lane.threshold = t as u8;
    }
    if let Some(c) = req.adaptive_c {
        if !(c.is_finite() && c.fract() == 0.0 && (-255.0..=255.0).contains(&c)) {
            return Err(ControlError::OutOfRange(format!(
                "lane.adaptive_c = {c} is out of range (allowed: whole grey levels -255 ..= 255)"
            )));
        }
        new.lane.adaptive_c = c as i32;
    }
    if let Some(m) = &req.threshold_mode {
        new.lane.threshold_mode = match m.as_str() {
            "fixed" => crate::config::ThresholdMode::Fixed,
            "otsu" => crate::config::ThresholdMode::Otsu,
            "adaptive" => crate::config::ThresholdMode::Adaptive,
            _ => {
                return Err(ControlError::OutOfRange(format!(
                    "lane.threshold_mode `{}` is not one of fixed, otsu, adaptive",
                    m.chars().take(32).collect::<String>()
                )))
            }
        };
    }
    new.validate().map_err(|e| match e {
        crate::config::ConfigError::Invalid { errors, .. } => ControlError::OutOfRange(
            errors
                .iter()
                .map(|v| format!("{} must have: {}", v.key, v.allowed))
                .collect::<Vec<_>>()
                .join("; "),
        ),
        other => ControlError::OutOfRange(other.to_string()),
    })?;
    Ok(new)
}

/// Parses a JSON body into `T`, refusing oversized bodies and unknown fields.
pub fn parse_body<T: for<'de> Deserialize<'de>>(body: &[u8]) -> Result<T, ControlError> {
    if body.len() > MAX_BODY {
        return Err(ControlError::Malformed(format!(
            "body of {} bytes (at most {MAX_BODY})",
            body.len()
        )));
    }
    serde_json::from_slice(body).map_err(|e| ControlError::Malformed(e.to_string()))
}

/// Checks `key = value` against the configuration's ranges; returns the configuration with
/// the value set (the caller keeps it as the dashboard's view of the settings).
pub fn validate_set(cfg: &Config, key: &str, value: f64) -> Result<Config, ControlError> {
    let keys = settable(cfg);
    if !keys.iter().any(|p| p.key == key) {
        if let Some(why) = unused_by(cfg.steering.method, key) {
            return Err(ControlError::OtherMethod(why));
        }
        return Err(ControlError::UnknownKey {
            key: key.chars().take(64).collect(),
            settable: keys.iter().map(|p| p.key).collect::<Vec<_>>().join(", "),
        });
    }
    if !value.is_finite() {
        return Err(ControlError::NotFinite {
            key: key.into(),
            value: value.to_string(),
        });
    }
    cfg.with_override(&format!("{key}={value:?}"))
        .map_err(|e| ControlError::OutOfRange(e.to_string().replace("config + override: ", "")))
}

/// The value of a settable key in `cfg`.
pub fn get_value(cfg: &Config, key: &str) -> Option<f64> {
    settable(cfg)
        .iter()
        .any(|p| p.key == key)
        .then(|| cfg.number(key))
        .flatten()
}

/// A message from the page to the loop (already validated by the server).
#[derive(Debug, Clone, PartialEq)]
pub enum Control {
    /// Set a [`settable`] key. `note` says who asked and when (wall clock), for telemetry.
    Set {
        /// Dotted key.
        key: String,
        /// New value.
        value: f64,
        /// Who and when, e.g. `dashboard 127.0.0.1 at wall 12.345 s`.
        note: String,
    },
    /// Simulator: stop taking frames until `Resume` or `Step`.
    Pause,
    /// Simulator: run again.
    Resume,
    /// Simulator, paused: process exactly one frame.
    Step,
    /// Simulator: the car back to the start, at rest.
    Reset,
    /// Simulator: the car to `s` metres along the track, at rest.
    PlaceAt(f64),
    /// Set-up by clicking: the lane stage of this configuration (its `[warp]` and `[lane]`,
    /// checked by [`validate_setup`]) from the next frame on.
    Lane {
        /// The configuration with the new ROI and threshold.
        cfg: Box<Config>,
        /// What changed, who asked and when, for telemetry.
        note: String,
    },
    /// Something that happened elsewhere (arm, disarm, e-stop), for the telemetry.
    Note(String),
}

/// The server's end of the inbox: never blocks.
#[derive(Debug, Clone)]
pub struct ControlSender(SyncSender<Control>);

impl ControlSender {
    /// The server's end of the inbox whose loop's end is `rx` ([`super::observer::channel`]).
    pub(super) fn new(tx: SyncSender<Control>) -> ControlSender {
        ControlSender(tx)
    }

    /// Queues `c` for the loop's next `before_frame`; `false` when the inbox is full (the loop
    /// is paused or stuck) or the loop has ended.
    pub fn send(&self, c: Control) -> bool {
        !matches!(
            self.0.try_send(c),
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_))
        )
    }
}

/// One plot sample per frame: what the pipeline wanted **and** what the gate really sent, the
/// gate's state (disarmed, e-stop, brake, paused: shaded on the page), and in the simulator the
/// true speed and cross-track error. A plot of the wish alone showed a parked car "driving" at
/// 0.5 m/s and an e-stopped one still at throttle 0.62 (issue 26).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlotPoint {
    /// Frame time, seconds.
    pub t: f64,
    /// Lane error L_c − L_F, bird's-eye pixels (`None`: lane lost) — the one unit of the page
    /// and the overlay.
    pub error_px: Option<f64>,
    /// Steering the pipeline wanted, −1..1.
    pub steer: f64,
    /// Throttle the pipeline wanted, −1..1.
    pub throttle: f64,
    /// Steering the gate sent to the car, −1..1.
    pub sent_steer: f64,
    /// Throttle the gate sent to the car, −1..1 (0 while disarmed or e-stopped).
    pub sent_throttle: f64,
    /// Speed, m/s: the simulator's true speed, else dead-reckoned from what was sent.
    pub speed: Option<f64>,
    /// `true` when `speed` is the simulator's truth.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub speed_true: bool,
    /// The simulator's true cross-track error, metres (positive: car left of the lane centre).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cte_m: Option<f64>,
    /// The gate: `armed`, `disarmed`, `estop` or `brake`.
    pub gate: &'static str,
    /// The simulator was paused at this frame.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub paused: bool,
    /// Who drove (`manual`, `assisted`, `autopilot`), once a human input is attached.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode: Option<&'static str>,
    /// The frame's events (a gain change, a move, a mode switch, arming): a marker each.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<String>,
}

/// What the loop publishes for the page, at most `stream_fps` times per second of frame time.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The frame's telemetry record (behaviour, transition, objects, timing).
    pub record: FrameRecord,
    /// The camera frame.
    pub image: RgbImage,
    /// The lane detector's intermediate images (bird's-eye view, binary, histogram).
    pub lane_images: LaneImages,
    /// The lane measurement.
    pub lane: LaneMeasurement,
    /// The pipeline's command.
    pub command: Command,
    /// Camera → bird's-eye homography (for annotation).
    pub homography: Homography,
    /// The ROI trapezoid in the camera image, pixels.
    pub roi: [[f64; 2]; 4],
    /// Plot samples since the previous snapshot (every frame).
    pub points: Vec<PlotPoint>,
    /// The settable values in force, in [`settable`] order.
    pub values: Vec<(String, f64)>,
    /// The last behaviour transition, with the frame time it happened at.
    pub last_transition: Option<(f64, Transition)>,
    /// Ranged objects of the frame.
    pub objects: Vec<RangedObject>,
    /// The simulator is paused.
    pub paused: bool,
    /// Snapshots replaced before the server took them (slow server threads).
    pub dropped: u64,
}

/// What the loop updates on every frame (a few atomics, cheaper than a snapshot): the page's
/// frame counter and pause state are exact even between snapshots.
#[derive(Debug, Default)]
pub struct Live {
    /// The last processed frame's number.
    pub frame: AtomicU64,
    /// Its time, seconds (f64 bits).
    pub time_bits: AtomicU64,
    /// The loop is waiting in pause.
    pub paused: AtomicBool,
    /// Frames processed since the start.
    pub frames: AtomicU64,
}

impl Live {
    /// The last frame's time, seconds.
    pub fn time_s(&self) -> f64 {
        f64::from_bits(self.time_bits.load(Ordering::SeqCst))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_checked_with_the_config_ranges() {
        let cfg = Config::default();
        let ok = validate_set(&cfg, "steering.kp", 0.8).unwrap();
        assert_eq!(ok.steering.kp, 0.8);
        let e = validate_set(&cfg, "steering.kp", 25.0).unwrap_err().to_string();
        assert!(e.contains("steering.kp") && e.contains("0 ..= 20"), "{e}");
        let e = validate_set(&cfg, "throttle.min", 0.9).unwrap_err().to_string();
        assert!(e.contains("throttle.min"), "{e}");
        assert!(matches!(
            validate_set(&cfg, "steering.kp", f64::NAN),
            Err(ControlError::NotFinite { .. })
        ));
        assert!(matches!(
            validate_set(&cfg, "steering.kp", f64::INFINITY),
            Err(ControlError::NotFinite { .. })
        ));
        assert!(matches!(
            validate_set(&cfg, "camera.fps", 10.0),
            Err(ControlError::UnknownKey { .. })
        ));
    }

    /// The settable keys are the run's steering method's table and the throttle's: another
    /// method's key is refused with its owner named.
    #[test]
    fn settable_keys_follow_the_steering_method() {
        let keys = |c: &Config| settable(c).iter().map(|p| p.key).collect::<Vec<_>>();
        let pid = Config::default();
        assert!(keys(&pid).contains(&"steering.kd") && !keys(&pid).contains(&"steering.lookahead_m"));
        assert!(keys(&pid).contains(&"throttle.base"));
        let pp = pid.with_override("steering.method=pure_pursuit").unwrap();
        assert!(keys(&pp).contains(&"steering.lookahead_m") && !keys(&pp).contains(&"steering.kp"));
        assert_eq!(
            validate_set(&pp, "steering.lookahead_m", 1.0)
                .unwrap()
                .steering
                .lookahead_m,
            1.0
        );
        let e = validate_set(&pp, "steering.kp", 1.0).unwrap_err().to_string();
        assert!(
            e.contains("steering.method = pid") && e.contains("cannot change while the car runs"),
            "{e}"
        );
        let e = validate_set(&pp, "camera.fps", 1.0).unwrap_err().to_string();
        assert!(
            e.contains("settable: steering.lookahead_m, steering.lookahead_band_m"),
            "{e}"
        );
        assert_eq!(get_value(&pp, "steering.lookahead_m"), Some(0.9));
        assert_eq!(get_value(&pp, "steering.kp"), None);
    }

    #[test]
    fn bodies_refuse_unknown_fields_nan_and_size() {
        assert!(parse_body::<SetRequest>(br#"{"key":"steering.kp","value":0.5}"#).is_ok());
        assert!(parse_body::<SetRequest>(br#"{"key":"steering.kp","value":0.5,"x":1}"#).is_err());
        assert!(parse_body::<SetRequest>(br#"{"key":"steering.kp","value":NaN}"#).is_err());
        assert!(parse_body::<SetRequest>(br#"{"key":"steering.kp","value":1e999}"#).is_err());
        assert!(parse_body::<SetRequest>(br#"{"key":"steering.kp""#).is_err());
        let big = vec![b' '; MAX_BODY + 1];
        assert!(parse_body::<SetRequest>(&big).is_err());
    }

    /// The set-up request's checks: corners inside the frame, a homography that exists, the
    /// far edge above the near one, a whole grey level; each refusal names what is wrong.
    #[test]
    fn setup_requests_are_checked_and_name_what_is_wrong() {
        let cfg = Config::default();
        let ok = SetupRequest {
            src: cfg.warp.src,
            threshold: Some(150.0),
            threshold_mode: Some("fixed".into()),
            adaptive_c: Some(-8.0),
        };
        let new = validate_setup(&cfg, &ok).unwrap();
        assert_eq!((new.warp.src, new.lane.threshold), (cfg.warp.src, 150));
        assert_eq!(new.lane.adaptive_c, -8);
        // Corners kept to 1/100 pixel.
        let mut r = ok.clone();
        r.src[0] = [93.7249, 78.955];
        assert_eq!(validate_setup(&cfg, &r).unwrap().warp.src[0], [93.72, 78.96]);
        let err = |r: &SetupRequest| validate_setup(&cfg, r).unwrap_err().to_string();
        let mut r = ok.clone();
        r.src[2] = [320.0, 150.0];
        let e = err(&r);
        assert!(
            e.contains("warp.src[2] (bottom-right)") && e.contains("outside the 320x240 frame"),
            "{e}"
        );
        r.src[2] = [f64::NAN, 1.0];
        assert!(err(&r).contains("not a finite number"));
        // Three corners on one line: no homography.
        let mut r = ok.clone();
        r.src = [[10.0, 10.0], [20.0, 10.0], [30.0, 10.0], [10.0, 100.0]];
        let e = err(&r);
        assert!(
            e.contains("warp.src: no bird's-eye view") && e.contains("collinear"),
            "{e}"
        );
        // Crossed (the order of two corners swapped).
        let mut r = ok.clone();
        r.src.swap(2, 3);
        assert!(err(&r).contains("convex"), "{}", err(&r));
        // Upside down: the homography exists, the configuration's own check refuses it.
        let mut r = ok.clone();
        r.src = [cfg.warp.src[3], cfg.warp.src[2], cfg.warp.src[1], cfg.warp.src[0]];
        let e = err(&r);
        assert!(e.contains("warp.src must have") && e.contains("upside down"), "{e}");
        let mut r = ok.clone();
        r.threshold = Some(300.0);
        assert!(err(&r).contains("lane.threshold = 300"));
        r.threshold = Some(12.5);
        assert!(err(&r).contains("whole grey level"));
        let mut r = ok.clone();
        r.adaptive_c = Some(-300.0);
        assert!(err(&r).contains("lane.adaptive_c = -300"), "{}", err(&r));
        r.adaptive_c = Some(-2.5);
        assert!(err(&r).contains("whole grey levels"), "{}", err(&r));
        let mut r = ok;
        r.threshold_mode = Some("auto".into());
        assert!(err(&r).contains("not one of fixed, otsu"));
        assert!(parse_body::<SetupRequest>(br#"{"src":[[1,2],[3,4],[5,6]]}"#).is_err());
        assert!(parse_body::<SetupRequest>(br#"{"src":[[1,2],[3,4],[5,6],[7,8]],"x":1}"#).is_err());
    }
}
