//! `rccar camera check`: the first thing to run on a new car. It lists the cameras it can see
//! (V4L2 devices, the camera module's capture program and its cameras), opens one as `rccar
//! drive` would (the same session, nothing armed, no port), and measures over a few seconds:
//! time to the first frame, the real frame size, frames per second, capture → command latency
//! (the lane pipeline), dropped, unusable and stalled frames; and it keeps the last frame.

use crate::config::Config;
use crate::drive::{Clock, Flow, FrameContext, LoopError, Observer, StopReason, StopSignal};
use super::{
    ArmAt, CameraSpec, DetectorSpec, Session, SessionEnv, SessionError, SessionSpec, SinkSpec, SourceSpec, Timing,
};
use crate::source::FrameError;
use image::RgbImage;
use std::sync::Arc;

/// What the machine offers, a line each.
pub fn found() -> Vec<String> {
    let mut out = Vec::new();
    let mut v4l: Vec<(String, String)> = std::fs::read_dir("/sys/class/video4linux")
        .map(|d| {
            d.flatten()
                .map(|e| {
                    let name = std::fs::read_to_string(e.path().join("name")).unwrap_or_default();
                    (e.file_name().to_string_lossy().into_owned(), name.trim().to_string())
                })
                .collect()
        })
        .unwrap_or_default();
    v4l.sort();
    if v4l.is_empty() {
        out.push("V4L2: no /dev/video* devices".into());
    }
    for (dev, name) in &v4l {
        let hint = match dev.strip_prefix("video") {
            // The Pi's ISP, codec and unicam nodes are not webcams (the camera module goes
            // through rpicam-vid).
            Some(_)
                if name.contains("bcm2835")
                    || name.contains("unicam")
                    || name.contains("pispbe")
                    || name.contains("rp1-cfe") =>
            {
                " (Raspberry Pi camera/ISP node: use picam:N)".to_string()
            }
            Some(n) => format!(" (--camera v4l:{n})"),
            None => String::new(),
        };
        out.push(format!("V4L2: /dev/{dev}: {name}{hint}"));
    }
    match crate::pipecam::rpicam::find_program() {
        None => out.push(
            "camera module: no rpicam-vid or libcamera-vid on PATH (Raspberry Pi OS: sudo apt install rpicam-apps-lite)"
                .into(),
        ),
        Some(p) => match crate::pipecam::rpicam::list_cameras(&p) {
            Ok((list, _)) if list.is_empty() => out.push(format!(
                "camera module: {} lists no camera (cable, or camera_auto_detect in config.txt)",
                p.display()
            )),
            Ok((list, _)) => {
                for c in list {
                    out.push(format!(
                        "camera module: {} camera {}: {} {}×{}, {} modes (--camera picam:{})",
                        p.display(),
                        c.index,
                        c.sensor,
                        c.full_size.0,
                        c.full_size.1,
                        c.modes.len(),
                        c.index
                    ));
                }
            }
            Err(e) => out.push(format!("camera module: {e}")),
        },
    }
    out
}

/// The camera to check when none is named: the camera module when its program is there,
/// else the first V4L2 device.
pub fn default_camera() -> CameraSpec {
    if crate::pipecam::rpicam::find_program().is_some() {
        CameraSpec::Picam { index: 0, mjpeg: false }
    } else {
        CameraSpec::V4l(0)
    }
}

/// What the check measured.
#[derive(Debug, Clone, Default)]
pub struct CheckReport {
    /// The camera, as `--camera` names it.
    pub camera: String,
    /// What the session said when it opened the camera (the command line, its process).
    pub notes: Vec<String>,
    /// Seconds from starting the camera to the first frame the loop took.
    pub first_frame_s: Option<f64>,
    /// Frames processed, and over how many seconds (first to last capture).
    pub frames: u64,
    /// Seconds between the first and the last frame's capture.
    pub span_s: f64,
    /// The frames' size as delivered.
    pub size: Option<(u32, u32)>,
    /// Capture → command latency, median and max, ms.
    pub latency_ms: Option<(f64, f64)>,
    /// Frames the camera delivered that the loop never saw (it takes the newest).
    pub dropped: u64,
    /// Unusable frames (garbage, short, undecodable).
    pub skipped: u64,
    /// Stalls (no frame for the stall time; neutral was sent).
    pub stalls: u64,
    /// Why the camera stopped, if it did.
    pub fault: Option<String>,
}

impl CheckReport {
    /// Frames per second between the first and last frame.
    pub fn fps(&self) -> Option<f64> {
        (self.frames > 1 && self.span_s > 0.0).then(|| (self.frames - 1) as f64 / self.span_s)
    }

    /// The report, a line each.
    pub fn lines(&self, configured: (u32, u32, f64)) -> Vec<String> {
        let mut l: Vec<String> = self.notes.iter().map(|n| format!("  {n}")).collect();
        l.insert(
            0,
            format!(
                "camera {}: first frame after {}",
                self.camera,
                self.first_frame_s.map_or("- (none)".into(), |t| format!("{t:.2} s"))
            ),
        );
        l.push(format!(
            "  size: {} (configured {}×{})",
            self.size.map_or("-".into(), |(w, h)| format!("{w}×{h}")),
            configured.0,
            configured.1
        ));
        l.push(format!(
            "  frames: {} in {:.2} s = {} fps (configured {})",
            self.frames,
            self.span_s,
            self.fps().map_or("-".into(), |f| format!("{f:.1}")),
            configured.2
        ));
        l.push(format!(
            "  latency capture -> command (lane pipeline): {}",
            self.latency_ms
                .map_or("-".into(), |(m, x)| format!("median {m:.1} ms, max {x:.1} ms"))
        ));
        l.push(format!(
            "  dropped {} (newest frame only), unusable {}, stalls {}",
            self.dropped, self.skipped, self.stalls
        ));
        if let Some(f) = &self.fault {
            l.push(format!("  fault: {f}"));
        }
        l
    }
}

/// Watches the check: ends it after `seconds` on the clock, keeps the last frame.
struct Watch {
    clock: Arc<dyn Clock + Send + Sync>,
    stop: StopSignal,
    until: f64,
    first: Option<f64>,
    last: f64,
    size: Option<(u32, u32)>,
    image: Option<RgbImage>,
}

impl Watch {
    fn time_up(&self) {
        if self.clock.now_s() >= self.until {
            self.stop.request(StopReason::Requested);
        }
    }
}

impl Observer for Watch {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let t = ctx.frame.captured_s.unwrap_or_else(|| self.clock.now_s());
        self.first.get_or_insert(t);
        self.last = t;
        self.size = Some(ctx.frame.image.dimensions());
        self.image = Some(ctx.frame.image.clone());
        self.time_up();
        Ok(Flow::Continue)
    }
    fn on_stall(&mut self, _e: &FrameError) {
        self.time_up();
    }
    fn on_skip(&mut self, _e: &FrameError) {
        self.time_up();
    }
}

/// Opens `camera` as `rccar drive --dry-run` would (the lane pipeline, no detector, never
/// armed), runs it for `seconds` on `env`'s clock and reports; with the last frame.
pub fn run(
    cfg: &Config,
    camera: CameraSpec,
    seconds: f64,
    env: SessionEnv,
) -> Result<(CheckReport, Option<RgbImage>), SessionError> {
    let label = camera.label();
    let mut spec = SessionSpec::new(
        SourceSpec::Cameras {
            left: camera,
            right: None,
            timing: Timing::WallClock,
        },
        SinkSpec::DryRun,
    );
    spec.arm = ArmAt::Operator;
    spec.detector = DetectorSpec::Off;
    let (clock, stop) = (env.clock.clone(), env.stop.clone());
    let t0 = clock.now_s();
    let mut session = Session::build(cfg, spec, env)?;
    let started = clock.now_s();
    let notes = session.notes().iter().map(|(_, l)| l.clone()).collect();
    let mut watch = Watch {
        clock: clock.clone(),
        stop: stop.clone(),
        until: started + seconds,
        first: None,
        last: 0.0,
        size: None,
        image: None,
    };
    let end = session.run(&mut watch);
    let outcome = session.finish()?;
    let s = &outcome.stats;
    let report = CheckReport {
        camera: label,
        notes,
        first_frame_s: watch.first.map(|f| (f - t0).max(0.0)),
        frames: s.frames,
        span_s: watch.first.map_or(0.0, |f| watch.last - f),
        size: watch.size,
        latency_ms: crate::drive::LoopStats::median_max(&s.latency_ms),
        dropped: s.dropped,
        skipped: s.skipped,
        stalls: s.stalls,
        fault: outcome
            .fault
            .map(|f| f.to_string())
            .or_else(|| end.err().map(|e| e.to_string())),
    };
    Ok((report, watch.image))
}
