//! What a session is built from: where frames come from ([`SourceSpec`]), where commands go
//! ([`SinkSpec`]), what is kept ([`SessionSpec`]) and what the caller lends ([`SessionEnv`]).
//! Plain data: `rccar drive`, `replay` and `sim` fill it from their flags, a test fills it by
//! hand.

pub use crate::drive::{Level, Say};
use crate::drive::{Clock, StopSignal};
use crate::sim::scene::Scene;
use crate::timing::StageTimer;
use std::path::PathBuf;
use std::sync::Arc;

/// One camera of the car.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraSpec {
    /// A V4L2 camera, `/dev/videoN` (feature `camera`).
    V4l(u32),
    /// A folder of PNG/JPEG frames (name order; a recording's own frame times when it has
    /// its telemetry).
    Folder(PathBuf),
    /// Frames a command writes to its stdout, `pipe:FORMAT:COMMAND` (src/pipecam/).
    Pipe {
        /// rgb24, yuv420, yuvj420 or mjpeg.
        format: String,
        /// The command line (split as a shell would, run without one).
        command: String,
    },
    /// The Raspberry Pi camera module through rpicam-vid, `picam:N` (raw YUV 4:2:0) or
    /// `picam:N:mjpeg` (src/pipecam/rpicam.rs).
    Picam {
        /// The camera's index (`rpicam-vid --list-cameras`).
        index: u32,
        /// Motion JPEG instead of raw frames.
        mjpeg: bool,
    },
}

impl CameraSpec {
    /// Reads `v4l:N`, `picam:N[:mjpeg]`, `pipe:FORMAT:COMMAND` or a folder path (what
    /// `--camera` takes).
    pub fn parse(spec: &str) -> Result<CameraSpec, String> {
        if let Some(n) = spec.strip_prefix("v4l:") {
            return n
                .parse()
                .map(CameraSpec::V4l)
                .map_err(|_| format!("--camera {spec}: expected v4l:INDEX, e.g. v4l:0"));
        }
        if let Some(rest) = spec.strip_prefix("picam:") {
            let (n, codec) = rest.split_once(':').unwrap_or((rest, "yuv420"));
            return match (n.parse(), codec) {
                (Ok(index), "yuv420" | "mjpeg") => Ok(CameraSpec::Picam { index, mjpeg: codec == "mjpeg" }),
                _ => Err(format!("--camera {spec}: expected picam:INDEX or picam:INDEX:mjpeg, e.g. picam:0")),
            };
        }
        if let Some(rest) = spec.strip_prefix("pipe:") {
            let form = || {
                format!(
                    "--camera {spec}: expected pipe:FORMAT:COMMAND with FORMAT rgb24, yuv420, yuvj420 or mjpeg, e.g. \
                     'pipe:yuv420:ffmpeg -loglevel error -re -f lavfi -i testsrc=size=320x240:rate=30 -pix_fmt yuv420p -f rawvideo -'"
                )
            };
            let (format, command) = rest.split_once(':').ok_or_else(form)?;
            if !matches!(format, "rgb24" | "yuv420" | "yuvj420" | "mjpeg") {
                return Err(form());
            }
            if shlex::split(command).is_none_or(|a| a.is_empty()) {
                return Err(format!("--camera {spec}: the command is empty or its quotes do not close"));
            }
            return Ok(CameraSpec::Pipe { format: format.into(), command: command.into() });
        }
        Ok(CameraSpec::Folder(PathBuf::from(spec)))
    }

    /// How the command line names it.
    pub fn label(&self) -> String {
        match self {
            CameraSpec::V4l(n) => format!("v4l:{n}"),
            CameraSpec::Folder(p) => p.display().to_string(),
            CameraSpec::Pipe { format, command } => format!("pipe:{format}:{command}"),
            CameraSpec::Picam { index, mjpeg } => format!("picam:{index}{}", if *mjpeg { ":mjpeg" } else { "" }),
        }
    }

    /// A device that runs on the wall clock (a V4L2 camera, a camera program), not a folder.
    pub fn is_device(&self) -> bool {
        !matches!(self, CameraSpec::Folder(_))
    }
}

/// When frames are taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timing {
    /// As fast as the pipeline goes, each frame at its own time (replay, `rccar sim`): the
    /// run is reproducible to the bit.
    LockStep,
    /// Lock-step, but held back to real time between frames (the simulator watched on a
    /// dashboard).
    RealTime,
    /// On the wall clock: the camera delivers the newest frame when it has one (the car; the
    /// simulator as the car's camera, with its physics running on the clock).
    WallClock,
}

/// Where the simulated world comes from.
#[derive(Clone)]
pub enum SceneSpec {
    /// A track file (`config/tracks/*.toml`).
    Track(PathBuf),
    /// A scene built once and shared (gain sweeps run many worlds of one scene).
    Shared(Arc<Scene>),
}

/// Where frames come from.
#[derive(Clone)]
pub enum SourceSpec {
    /// The car's camera(s): a camera or a folder, and the right camera of a stereo pair.
    Cameras {
        /// The camera (the left one of a pair).
        left: CameraSpec,
        /// The right camera of a pair (`ranging.method = "stereo"`).
        right: Option<CameraSpec>,
        /// [`Timing::LockStep`] for a replay, [`Timing::WallClock`] for the car.
        timing: Timing,
    },
    /// The simulator's camera (a stereo pair of them with `ranging.method = "stereo"`).
    Sim {
        /// The track.
        scene: SceneSpec,
        /// Lock-step, real time, or physics on the wall clock.
        timing: Timing,
        /// `(T, D)`: the camera delivers nothing from T for D seconds (a test of the stall
        /// handling, wall clock only).
        stall: Option<(f64, f64)>,
        /// Start this many metres left (+) or right (−) of the lane centre.
        start_offset_m: Option<f64>,
    },
}

/// Where commands go.
#[derive(Debug, Clone, PartialEq)]
pub enum SinkSpec {
    /// Nothing leaves the computer (a replay, a dry run). With the simulator as the camera,
    /// the simulated car does what the gate sends.
    DryRun,
    /// The serial link to the Arduino (feature `serial`).
    Link {
        /// The port (`/dev/ttyACM0`, or the firmware emulator's pty).
        port: String,
        /// With the simulator as camera on the wall clock: the firmware emulator's report
        /// (`PULSE servo|esc WIDTH T` lines), whose pulses move the simulated car.
        pwm_log: Option<PathBuf>,
        /// Test hook: probability of flipping each bit written once armed.
        bit_errors: f64,
    },
}

/// Which detector the pipeline runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetectorSpec {
    /// The `[detect]` cascades of the configuration.
    FromConfig,
    /// None (lane keeping only; or the simulator's true boxes).
    Off,
}

/// When the car is armed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmAt {
    /// From the first frame, by rccar itself (the simulator, a replay).
    Start,
    /// From the first frame, because `--arm` said so (the car: the gate still waits for the
    /// link).
    Flag,
    /// Only when someone arms it (the button, the page).
    Operator,
}

/// Everything a session is built from.
#[derive(Clone)]
pub struct SessionSpec {
    /// Frames.
    pub source: SourceSpec,
    /// Commands.
    pub sink: SinkSpec,
    /// When the car is armed.
    pub arm: ArmAt,
    /// The detector.
    pub detector: DetectorSpec,
    /// The simulator gives the pipeline the objects' true boxes (no detector).
    pub truth_boxes: bool,
    /// Someone looks at whole frames (a recording, a dashboard): the simulator renders
    /// every row, not just the ones the pipeline reads.
    pub frames_viewed: bool,
    /// The operator ends the run (a dashboard): the simulator's laps and endings do not.
    pub operator_ends_run: bool,
    /// Write telemetry (one JSON line per frame) into this file.
    pub telemetry: Option<PathBuf>,
    /// Keep the camera's frames (JPEG, `[record]`) and telemetry in this folder, and a pair's
    /// other camera in the second.
    pub record: Option<(PathBuf, Option<PathBuf>)>,
    /// End the run after this many seconds on the clock.
    pub seconds: Option<f64>,
    /// Print a status line every so many seconds on the clock (the car's terminal).
    pub status_every_s: Option<f64>,
    /// A link down for longer than this, seconds, ends the run as a fault.
    pub link_give_up_s: f64,
}

impl SessionSpec {
    /// A spec with everything off but the source and sink: lock-step armed from the start,
    /// no telemetry, detector from the configuration.
    pub fn new(source: SourceSpec, sink: SinkSpec) -> Self {
        Self {
            source,
            sink,
            arm: ArmAt::Start,
            detector: DetectorSpec::FromConfig,
            truth_boxes: false,
            frames_viewed: false,
            operator_ends_run: false,
            telemetry: None,
            record: None,
            seconds: None,
            status_every_s: None,
            link_give_up_s: 3.0,
        }
    }
}

/// What the caller lends the session: the clock, the stop signal, the stage timer and where
/// lines go. The library reads no clock and prints nothing itself.
pub struct SessionEnv {
    /// The run's clock (latency, pacing, timeouts): the wall clock on the car, [`crate::drive::NoClock`]
    /// for reproducible runs.
    pub clock: Arc<dyn Clock + Send + Sync>,
    /// Raised by signals, the button, a fault or the deadline.
    pub stop: StopSignal,
    /// Measures the pipeline's stages (`NoTimer` for reproducible telemetry).
    pub timer: Box<dyn StageTimer + Send>,
    /// Where status lines, events and warnings go.
    pub say: Say,
}
