//! The car's configuration: `config/car.toml`, the one file students edit.
//!
//! Loading goes in three steps:
//! 1. the base file is parsed as TOML (a syntax error names its line);
//! 2. an optional personal override file (git-ignored, e.g. `config/local.toml`) is merged on
//!    top, table by table, and `key=value` overrides from the command line after it;
//! 3. the merged tree is checked for unknown keys (a typo such as `steering.kpp` is an error
//!    naming it, never silently ignored), deserialised into [`Config`] and every value is
//!    range-checked by [`Config::validate`]; an error names the key, the value and the range.
//!
//! Every section has defaults ([`Default`]), so tests and the simulator can start from
//! `Config::default()` and a file only needs the keys it changes. The shipped `car.toml` lists
//! them all, with units and advice.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// Everything that can go wrong while loading a configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read. The OS error is part of the message (and not repeated as
    /// a source, so `{:#}` prints it once).
    #[error("{path}: cannot read: {error}")]
    Io {
        /// File that failed.
        path: PathBuf,
        /// Underlying error.
        error: std::io::Error,
    },
    /// The configuration file does not exist; the message says how to point at one.
    #[error("{path}: cannot read: {error}; {HOW_TO_POINT}")]
    Missing {
        /// The file that was looked for.
        path: PathBuf,
        /// Underlying error (in the message, not repeated as a source).
        error: std::io::Error,
    },
    /// No `config/car.toml` in the starting folder or any folder above it.
    #[error("no config/car.toml in {start} or any folder above it; {HOW_TO_POINT}")]
    NotFound {
        /// Where the search started (the working directory).
        start: PathBuf,
    },
    /// TOML syntax error (the message carries the line and column).
    #[error("{path}: {message}")]
    Syntax {
        /// File that failed.
        path: PathBuf,
        /// Parser message with line and column.
        message: String,
    },
    /// A key that no section knows, most likely a typo.
    #[error("{origin}: unknown key `{key}`{hint}")]
    UnknownKey {
        /// File (or `command line`) where the key was found.
        origin: String,
        /// Full dotted key, e.g. `steering.kpp`.
        key: String,
        /// ", did you mean ...?" when a close key exists.
        hint: String,
    },
    /// A value of the wrong type.
    #[error("{origin}: {message}")]
    Type {
        /// Where the value came from.
        origin: String,
        /// Deserialiser message, naming the key.
        message: String,
    },
    /// A `key=value` override that cannot be parsed.
    #[error("bad override `{0}`: expected key=value, e.g. steering.kp=0.8")]
    BadOverride(String),
    /// A number that is not finite (inf, NaN, or too large for a 64-bit float, e.g. 1e309).
    #[error("{origin}: `{key}` = `{typed}` is not a finite number (inf and NaN are not allowed)")]
    NotFinite {
        /// Where the value came from (`command line` or a file).
        origin: String,
        /// Dotted key.
        key: String,
        /// What was typed.
        typed: String,
    },
    /// One or more values outside their allowed range.
    #[error("{}", .errors.iter().map(|e| format!("{origin}: {e}")).collect::<Vec<_>>().join("\n"))]
    Invalid {
        /// The file(s) the values came from.
        origin: String,
        /// Every bad value.
        errors: Vec<InvalidValue>,
    },
}

/// How to name a configuration when none is found (part of the error messages).
pub const HOW_TO_POINT: &str =
    "run rccar inside the project folder, or name a file with --config FILE or RCCAR_CONFIG=FILE";

/// The keys whose values are file paths. A relative path written in a file is resolved
/// against that file's folder; one given on the command line (`--set`) against the working
/// directory; a default (a key set nowhere) against the base configuration's folder.
/// Add a new path key here and it is resolved like the others.
pub const PATH_KEYS: &[&str] = &[
    "sim.track",
    "detect.stop_sign",
    "detect.traffic_light",
    "detect.obstacle",
    "stereo.calibration",
];

/// Bounds on sizes that files and flags control, checked before anything is allocated.
pub mod limits {
    /// Largest image a frame source, `stages` or `detect` decodes, pixels (width × height).
    pub const MAX_IMAGE_PIXELS: u64 = 40_000_000;
    /// Largest image side, pixels.
    pub const MAX_IMAGE_SIDE: u32 = 16_384;
}

/// One value outside its allowed range or inconsistent with another.
#[derive(Debug, Clone, PartialEq)]
pub struct InvalidValue {
    /// Dotted key, e.g. `steering.kp`.
    pub key: String,
    /// The offending value as written.
    pub value: String,
    /// What is allowed, e.g. `0 ..= 10`.
    pub allowed: String,
}

impl fmt::Display for InvalidValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} = {} is out of range (allowed: {})",
            self.key, self.value, self.allowed
        )
    }
}

/// The whole configuration, one struct per `[section]` of `car.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// The camera: resolution, frame rate and how it is mounted.
    pub camera: CameraConfig,
    /// Region of interest and bird's-eye warp.
    pub warp: WarpConfig,
    /// Lane-line extraction: threshold, Canny, histogram.
    pub lane: LaneConfig,
    /// PID steering on the lane error.
    pub steering: SteeringConfig,
    /// Throttle policy.
    pub throttle: ThrottleConfig,
    /// Replay of recorded frames.
    pub replay: ReplayConfig,
    /// The simulated car's chassis (kinematic bicycle model).
    pub vehicle: VehicleConfig,
    /// The closed-loop simulator: track, run length, camera effects.
    pub sim: SimConfig,
    /// Object detection: which cascades the pipeline runs.
    pub detect: DetectConfig,
    /// Monocular tilt ranging of detected boxes: calibration corrections, contact heights.
    pub ranging: RangingConfig,
    /// The behaviour state machine: stop signs, lights, obstacles, lane lost.
    pub behaviour: BehaviourConfig,
    /// The Raspberry Pi's GPIO: start/stop button, status LED, HC-SR04 ultrasonic brake.
    pub gpio: GpioConfig,
    /// Recording on the car (`--record DIR`): JPEG quality, disk budget, segments.
    pub record: RecordConfig,
    /// `[dashboard]`: the live page of `sim|drive --dashboard`.
    pub dashboard: DashboardConfig,
    /// Stereo ranging with a second camera (src/stereo/, docs/stereo.md).
    pub stereo: StereoConfig,
}

/// `[camera]`: the image the pipeline works on and the camera's pose on the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Width of the frames the pipeline processes, pixels (frames are resized to it).
    pub width: u32,
    /// Height of the frames the pipeline processes, pixels.
    pub height: u32,
    /// Frames per second; the controller's time step is 1/fps.
    pub fps: f64,
    /// Height of the lens above the floor, metres.
    pub height_m: f64,
    /// Downward tilt of the optical axis below horizontal, degrees.
    pub tilt_deg: f64,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width: 320,
            height: 240,
            fps: 30.0,
            height_m: 0.20,
            tilt_deg: 20.0,
            hfov_deg: 62.2,
        }
    }
}

/// `[warp]`: the region of interest and its bird's-eye (top-down) view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WarpConfig {
    /// The ROI's four corners in the camera frame, pixels, in the order
    /// top-left, top-right, bottom-right, bottom-left.
    pub src: [[f64; 2]; 4],
    /// Width of the bird's-eye image, pixels.
    pub out_width: u32,
    /// Height of the bird's-eye image, pixels.
    pub out_height: u32,
    /// Interpolate each colour channel and then convert to grey, exactly as OpenCV's
    /// `warpPerspective` + `cvtColor` (bit-identical), instead of grey first (3× faster, within
    /// one grey level).
    pub exact: bool,
}

impl Default for WarpConfig {
    fn default() -> Self {
        // The ground rectangle 0.40..1.00 m ahead, 0.25 m either side, seen by the default
        // camera (see `camera::PinholeCamera`); regenerate with `rccar config roi`.
        Self {
            src: [[93.72, 78.96], [225.28, 78.96], [308.75, 150.02], [10.25, 150.02]],
            out_width: 320,
            out_height: 240,
            exact: false,
        }
    }
}

/// How the binary image is thresholded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ThresholdMode {
    /// Fixed grey level (`lane.threshold`).
    Fixed,
    /// Otsu's method picks the level per frame.
    Otsu,
}

/// How a line's column is read from its histogram peak (`lane.peak`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PeakMode {
    /// Centroid of the run of columns around the highest that reach half its height
    /// (sub-pixel; a wide bright blob next to the line drags it).
    #[default]
    Centroid,
    /// The highest column (the paper's argmax; the middle of a flat top), whole pixels.
    Argmax,
}

/// `[lane]`: extracting the lane lines from the bird's-eye image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaneConfig {
    /// `fixed` or `otsu`.
    pub threshold_mode: ThresholdMode,
    /// Grey level, 0..=255: pixels strictly brighter are "line".
    pub threshold: u8,
    /// Canny hysteresis low threshold (L1 gradient magnitude of the 3x3 Sobel).
    pub canny_low: u16,
    /// Canny hysteresis high threshold.
    pub canny_high: u16,
    /// Run a 5x5 Gaussian blur before Canny.
    pub blur: bool,
    /// Fraction of the bird's-eye height, from the bottom, summed by the histogram, 0..1.
    pub band: f64,
    /// A line is found only where its histogram peak reaches this fraction of the band height.
    pub min_peak: f64,
    /// `centroid` or `argmax`: how a line's column is read from its peak.
    pub peak: PeakMode,
    /// Lane width between the two line centres in the bird's-eye image, pixels; used to
    /// estimate a lost line from the other.
    pub lane_width_px: f64,
    /// Two lines whose distance differs from `lane_width_px` by more than this fraction are
    /// implausible: the weaker is dropped and estimated from the stronger.
    pub width_tolerance: f64,
    /// L_F, the car's centre in the bird's-eye image, as an offset from the image centre,
    /// pixels (positive = right). Non-zero when the camera is mounted off-centre.
    pub center_offset_px: f64,
}

impl Default for LaneConfig {
    fn default() -> Self {
        Self {
            threshold_mode: ThresholdMode::Fixed,
            threshold: 170,
            canny_low: 100,
            canny_high: 200,
            blur: true,
            band: 0.4,
            min_peak: 0.3,
            peak: PeakMode::Centroid,
            lane_width_px: 191.4,
            width_tolerance: 0.35,
            center_offset_px: 0.0,
        }
    }
}

/// `[steering]`: PID on the normalised lane error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringConfig {
    /// Proportional gain: steer per unit of normalised error.
    pub kp: f64,
    /// Integral gain: steer per (unit error x second).
    pub ki: f64,
    /// Derivative gain: steer per (unit error / second), on the measurement.
    pub kd: f64,
    /// Largest contribution of the integral term, steer units (anti-windup).
    pub integral_limit: f64,
    /// Output clamp, steer units 0..=1.
    pub max_steer: f64,
    /// Largest change of the steering command per second, steer units per second.
    pub slew_rate: f64,
    /// Low-pass time constant of the derivative, seconds (0 = none; default 0.2, measured
    /// in docs/sim.md "Steering chatter").
    pub derivative_tau: f64,
}

impl Default for SteeringConfig {
    fn default() -> Self {
        Self {
            kp: 1.0,
            ki: 0.0,
            kd: 0.05,
            integral_limit: 0.3,
            max_steer: 1.0,
            slew_rate: 8.0,
            derivative_tau: 0.2,
        }
    }
}

/// `[throttle]`: speed policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThrottleConfig {
    /// Throttle on a straight with zero error, 0..=1.
    pub base: f64,
    /// Throttle never drops below this while the lane is seen, 0..=base.
    pub min: f64,
    /// How much the throttle drops per unit of |normalised error|.
    pub error_slowdown: f64,
    /// After the lane has been lost this long, seconds, the throttle is zero.
    pub lost_timeout_s: f64,
}

impl Default for ThrottleConfig {
    fn default() -> Self {
        Self {
            base: 0.5,
            min: 0.2,
            error_slowdown: 0.6,
            lost_timeout_s: 0.5,
        }
    }
}

/// `[replay]`: running the pipeline over a folder of images.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayConfig {
    /// Write an annotated PNG for every frame.
    pub annotate: bool,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self { annotate: true }
    }
}

/// `[dashboard]`: the live page of `rccar sim|drive --dashboard` (issue 11).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DashboardConfig {
    /// Address to listen on (`--listen` overrides). Anything but 127.0.0.1 / ::1 needs the token.
    pub listen: String,
    /// Access token for a dashboard on another address; empty = a random one printed at start.
    pub token: String,
    /// Disarm when the page that armed the car sends no heartbeat for this long, ms (0 = never).
    pub heartbeat_ms: u64,
    /// Frames per second sent to the viewers (the loop publishes at most this often).
    pub stream_fps: f64,
    /// Concurrent stream viewers; more get 503.
    pub max_viewers: u32,
}

impl Default for DashboardConfig {
    fn default() -> Self {
        Self {
            listen: "127.0.0.1:8080".into(),
            token: String::new(),
            heartbeat_ms: 1000,
            stream_fps: 15.0,
            max_viewers: 32,
        }
    }
}

/// `[vehicle]`: the simulated car, a kinematic bicycle (rear-axle reference point).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleConfig {
    /// Distance between the front and rear axles, metres.
    pub wheelbase_m: f64,
    /// Distance between the left and right wheels' centres, metres (lane-departure check).
    pub track_m: f64,
    /// How far the camera lens is ahead of the rear axle, metres.
    pub camera_x_m: f64,
    /// Front-wheel angle at full steering command (|steer| = 1), degrees.
    pub max_steer_deg: f64,
    /// Fastest the steering servo turns the wheels, degrees per second.
    pub servo_rate_dps: f64,
    /// Dead time between a steering command and the servo starting to move, seconds.
    pub servo_delay_s: f64,
    /// Speed at full throttle, metres per second.
    pub max_speed_mps: f64,
    /// Time constant of the speed's first-order response to the throttle, seconds (0 = instant).
    pub speed_tau_s: f64,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            wheelbase_m: 0.26,
            track_m: 0.16,
            camera_x_m: 0.24,
            max_steer_deg: 14.0,
            servo_rate_dps: 300.0,
            servo_delay_s: 0.03,
            max_speed_mps: 1.0,
            speed_tau_s: 0.3,
        }
    }
}

/// `[sim]`: the closed-loop simulator (`rccar sim`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Track file; a relative path is relative to the folder of the config file that names it
    /// (the default, `tracks/default.toml`, to the base config's folder).
    pub track: String,
    /// Laps to drive before the run ends; 0 = no lap target, drive until `max_seconds`.
    pub laps: u32,
    /// The run ends after this much simulated time even if the laps are not done, seconds.
    pub max_seconds: f64,
    /// Vehicle-model steps per camera frame (the physics step is 1 / (fps × substeps)).
    pub substeps: u32,
    /// Seed of every random choice (camera noise); the same seed gives the same run.
    pub seed: i64,
    /// Standard deviation of the camera's pixel noise, grey levels (0 = none).
    pub noise_sigma: f64,
    /// Gaussian blur of the rendered frame, sigma in pixels (0 = sharp).
    pub blur_px: f64,
    /// Exposure gain on the rendered frame (1 = as lit).
    pub exposure: f64,
    /// Peak relative change of the scene's brightness over time (0 = steady lighting).
    pub light_variation: f64,
    /// Period of the brightness change, seconds.
    pub light_period_s: f64,
    /// How a stereo pair's second camera is turned from ideal: yaw, pitch, roll, degrees
    /// (`ranging.method = "stereo"`; src/sim/stereo.rs `LensWarp`).
    pub stereo_error_deg: [f64; 3],
    /// Radial distortion k₁ of the stereo pair's second camera (0 = none).
    pub stereo_error_k1: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            track: "tracks/default.toml".into(),
            laps: 3,
            max_seconds: 600.0,
            substeps: 4,
            seed: 1,
            noise_sigma: 2.0,
            blur_px: 0.0,
            exposure: 1.0,
            light_variation: 0.0,
            light_period_s: 10.0,
            stereo_error_deg: [0.0; 3],
            stereo_error_k1: 0.0,
        }
    }
}

/// Checks that collect every out-of-range value instead of stopping at the first.
struct Checker(Vec<InvalidValue>);

impl Checker {
    fn range<T: PartialOrd + fmt::Display + Copy>(&mut self, key: &str, v: T, lo: T, hi: T) {
        if !(v >= lo && v <= hi) {
            let value = v.to_string();
            let not_finite = matches!(value.as_str(), "inf" | "-inf" | "NaN");
            self.0.push(InvalidValue {
                key: key.into(),
                allowed: if not_finite {
                    format!("{lo} ..= {hi}; inf and NaN are not allowed")
                } else {
                    format!("{lo} ..= {hi}")
                },
                value,
            });
        }
    }
    fn finite(&mut self, key: &str, v: f64) {
        if !v.is_finite() {
            self.0.push(InvalidValue {
                key: key.into(),
                value: v.to_string(),
                allowed: "a finite number".into(),
            });
        }
    }
    fn fail(&mut self, key: &str, value: String, allowed: &str) {
        self.0.push(InvalidValue {
            key: key.into(),
            value,
            allowed: allowed.into(),
        });
    }
}

impl Config {
    /// Checks every value against its range; returns all problems at once.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let mut c = Checker(Vec::new());
        let cam = &self.camera;
        c.range("camera.width", cam.width, 16, 4096);
        c.range("camera.height", cam.height, 16, 4096);
        c.range("camera.fps", cam.fps, 1.0, 240.0);
        c.range("camera.height_m", cam.height_m, 0.01, 5.0);
        c.range("camera.tilt_deg", cam.tilt_deg, -10.0, 89.0);
        c.range("camera.hfov_deg", cam.hfov_deg, 10.0, 170.0);

        let w = &self.warp;
        for (i, p) in w.src.iter().enumerate() {
            c.finite(&format!("warp.src[{i}]"), p[0]);
            c.finite(&format!("warp.src[{i}]"), p[1]);
        }
        c.range("warp.out_width", w.out_width, 16, 4096);
        c.range("warp.out_height", w.out_height, 16, 4096);
        if let Err(e) = crate::lane::warp::Homography::from_quad_to_rect(&w.src, w.out_width, w.out_height) {
            c.fail("warp.src", format!("{:?}", w.src), &e.to_string());
        } else {
            // The bird's-eye image puts src[0..2] (the far edge) at its top: a quad whose far
            // edge is below its near edge warps the floor upside down (and mirrored when left
            // and right are swapped); the histogram band then reads the wrong end of the lane.
            let [tl, tr, br, bl] = w.src;
            if !(tl[1] < bl[1] && tr[1] < br[1]) {
                c.fail(
                    "warp.src",
                    format!("{:?}", w.src),
                    "top corners [0], [1] (far edge) above the bottom corners [3], [2] (near edge); this ROI looks at the floor upside down (make one with `rccar config roi`)",
                );
            }
            if !(tl[0] < tr[0] && bl[0] < br[0]) {
                c.fail(
                    "warp.src",
                    format!("{:?}", w.src),
                    "left corners [0], [3] left of the right corners [1], [2]; this ROI is mirrored (make one with `rccar config roi`)",
                );
            }
        }

        let l = &self.lane;
        c.range("lane.canny_low", l.canny_low, 0, 2040);
        c.range("lane.canny_high", l.canny_high, 0, 2040);
        if l.canny_low > l.canny_high {
            c.fail("lane.canny_low", l.canny_low.to_string(), "<= lane.canny_high");
        }
        c.range("lane.band", l.band, 0.01, 1.0);
        c.range("lane.min_peak", l.min_peak, 0.0, 1.0);
        c.range("lane.lane_width_px", l.lane_width_px, 1.0, w.out_width as f64);
        c.range("lane.width_tolerance", l.width_tolerance, 0.05, 1.0);
        c.range(
            "lane.center_offset_px",
            l.center_offset_px,
            -(w.out_width as f64) / 2.0,
            w.out_width as f64 / 2.0,
        );

        let s = &self.steering;
        c.range("steering.kp", s.kp, 0.0, 20.0);
        c.range("steering.ki", s.ki, 0.0, 20.0);
        c.range("steering.kd", s.kd, 0.0, 5.0);
        c.range("steering.integral_limit", s.integral_limit, 0.0, 1.0);
        c.range("steering.max_steer", s.max_steer, 0.0, 1.0);
        c.range("steering.slew_rate", s.slew_rate, 0.1, 1000.0);
        c.range("steering.derivative_tau", s.derivative_tau, 0.0, 5.0);

        let t = &self.throttle;
        c.range("throttle.base", t.base, 0.0, 1.0);
        c.range("throttle.min", t.min, 0.0, t.base.max(0.0));
        c.range("throttle.error_slowdown", t.error_slowdown, 0.0, 5.0);
        c.range("throttle.lost_timeout_s", t.lost_timeout_s, 0.0, 60.0);

        let v = &self.vehicle;
        c.range("vehicle.wheelbase_m", v.wheelbase_m, 0.02, 2.0);
        c.range("vehicle.track_m", v.track_m, 0.02, 2.0);
        c.range("vehicle.camera_x_m", v.camera_x_m, -2.0, 2.0);
        c.range("vehicle.max_steer_deg", v.max_steer_deg, 1.0, 60.0);
        c.range("vehicle.servo_rate_dps", v.servo_rate_dps, 1.0, 10000.0);
        c.range("vehicle.servo_delay_s", v.servo_delay_s, 0.0, 1.0);
        c.range("vehicle.max_speed_mps", v.max_speed_mps, 0.01, 20.0);
        c.range("vehicle.speed_tau_s", v.speed_tau_s, 0.0, 10.0);

        let m = &self.sim;
        if m.track.trim().is_empty() {
            c.fail("sim.track", format!("{:?}", m.track), "a path to a track file");
        }
        c.range("sim.laps", m.laps, 0, 1000);
        c.range("sim.max_seconds", m.max_seconds, 0.1, 36000.0);
        c.range("sim.substeps", m.substeps, 1, 100);
        c.range("sim.seed", m.seed, 0, i64::MAX);
        c.range("sim.noise_sigma", m.noise_sigma, 0.0, 64.0);
        c.range("sim.blur_px", m.blur_px, 0.0, 3.0);
        c.range("sim.exposure", m.exposure, 0.1, 4.0);
        c.range("sim.light_variation", m.light_variation, 0.0, 0.9);
        c.range("sim.light_period_s", m.light_period_s, 0.1, 3600.0);
        for (i, v) in m.stereo_error_deg.iter().enumerate() {
            c.range(&format!("sim.stereo_error_deg[{i}]"), *v, -5.0, 5.0);
        }
        c.range("sim.stereo_error_k1", m.stereo_error_k1, -0.5, 0.5);

        let d = &self.detect;
        c.range("detect.scale_factor", d.scale_factor, 1.01, 2.0);
        c.range("detect.min_neighbors", d.min_neighbors, 0, 100);
        c.range("detect.min_size_px", d.min_size_px, 0, 4096);
        for (key, r) in [
            ("detect.stop_sign_region", d.stop_sign_region),
            ("detect.traffic_light_region", d.traffic_light_region),
            ("detect.obstacle_region", d.obstacle_region),
        ] {
            if !(r.iter().all(|v| (0.0..=1.0).contains(v)) && r[0] < r[2] && r[1] < r[3]) {
                c.fail(
                    key,
                    format!("{r:?}"),
                    "[left, top, right, bottom] in 0..=1 with left < right, top < bottom",
                );
            }
        }
        if !(d.range_m[0] >= 0.05 && d.range_m[0] < d.range_m[1] && d.range_m[1] <= 20.0) {
            c.fail(
                "detect.range_m",
                format!("{:?}", d.range_m),
                "[near, far] metres, 0.05 <= near < far <= 20",
            );
        }
        for (key, b) in [
            ("detect.stop_sign_box_m", d.stop_sign_box_m),
            ("detect.traffic_light_box_m", d.traffic_light_box_m),
            ("detect.obstacle_box_m", d.obstacle_box_m),
        ] {
            if !(b[0] > 0.0 && b[0] <= b[1] && b[1] <= 5.0) {
                c.fail(key, format!("{b:?}"), "[min, max] metres, 0 < min <= max <= 5");
            }
        }
        c.range("detect.every_n_frames", d.every_n_frames, 1, 30);

        let r = &self.ranging;
        c.range("ranging.v0_offset_px", r.v0_offset_px, -200.0, 200.0);
        c.range("ranging.a_y_scale", r.a_y_scale, 0.5, 2.0);
        c.range("ranging.stop_sign_bottom_m", r.stop_sign_bottom_m, 0.0, 3.0);
        c.range("ranging.traffic_light_bottom_m", r.traffic_light_bottom_m, 0.0, 3.0);
        c.range("ranging.obstacle_bottom_m", r.obstacle_bottom_m, 0.0, 3.0);
        for (key, v) in [
            ("ranging.stop_sign_size_m", r.stop_sign_size_m),
            ("ranging.traffic_light_size_m", r.traffic_light_size_m),
            ("ranging.obstacle_size_m", r.obstacle_size_m),
        ] {
            c.range(&format!("{key}[0]"), v[0], 0.0, 3.0);
            c.range(&format!("{key}[1]"), v[1], 0.0, 3.0);
        }
        c.range("ranging.stop_sign_box_margin", r.stop_sign_box_margin, 0.5, 3.0);
        c.range("ranging.traffic_light_box_margin", r.traffic_light_box_margin, 0.5, 3.0);
        c.range("ranging.obstacle_box_margin", r.obstacle_box_margin, 0.5, 3.0);
        c.range("ranging.box_centre_sigma_px", r.box_centre_sigma_px, 0.01, 100.0);
        c.range("ranging.box_size_sigma", r.box_size_sigma, 0.001, 1.0);
        c.range("ranging.track_accel_sigma", r.track_accel_sigma, 0.0, 100.0);
        c.range("ranging.track_odometry_sigma", r.track_odometry_sigma, 0.0, 1.0);
        c.range("ranging.track_max_missed", r.track_max_missed, 0, 100);
        c.range("ranging.stop_sign_red_fraction", r.stop_sign_red_fraction, 0.1, 1.0);
        if r.method != "mono" && r.method != "stereo" {
            c.fail("ranging.method", format!("{:?}", r.method), "\"mono\" or \"stereo\"");
        }
        if r.stop_sign_bottom_m >= self.camera.height_m || r.traffic_light_bottom_m >= self.camera.height_m {
            c.fail(
                "ranging.stop_sign_bottom_m",
                format!("{} / {}", r.stop_sign_bottom_m, r.traffic_light_bottom_m),
                "box bottoms below camera.height_m (a ray through them must go down)",
            );
        }

        let b = &self.behaviour;
        c.range("behaviour.window_frames", b.window_frames, 1, 32);
        c.range(
            "behaviour.confirm_frames",
            b.confirm_frames,
            1,
            b.window_frames.clamp(1, 32),
        );
        c.range("behaviour.standstill_mps", b.standstill_mps, 0.0, 1.0);
        c.range("behaviour.stop_trigger_m", b.stop_trigger_m, 0.05, 10.0);
        c.range(
            "behaviour.stop_window_m[0]",
            b.stop_window_m[0],
            0.0,
            b.stop_window_m[1],
        );
        c.range("behaviour.stop_window_m[1]", b.stop_window_m[1], 0.0, 10.0);
        c.range("behaviour.stop_hold_s", b.stop_hold_s, 0.0, 600.0);
        c.range("behaviour.stop_ignore_m", b.stop_ignore_m, 0.0, 100.0);
        c.range("behaviour.stop_ignore_s", b.stop_ignore_s, 0.0, 600.0);
        c.range("behaviour.light_trigger_m", b.light_trigger_m, 0.05, 10.0);
        c.range("behaviour.green_confirm_frames", b.green_confirm_frames, 1, 32);
        c.range("behaviour.light_lost_s", b.light_lost_s, 0.0, 600.0);
        c.range("behaviour.obstacle_stop_m", b.obstacle_stop_m, 0.05, 10.0);
        c.range("behaviour.obstacle_lane_half_m", b.obstacle_lane_half_m, 0.0, 2.0);
        c.range("behaviour.pass_trigger_m", b.pass_trigger_m, 0.05, 10.0);
        c.range("behaviour.pass_wait_s", b.pass_wait_s, 0.0, 60.0);
        c.range("behaviour.pass_steer", b.pass_steer, 0.05, 1.0);
        c.range("behaviour.pass_turn_m", b.pass_turn_m, 0.05, 5.0);
        c.range("behaviour.pass_along_m", b.pass_along_m, 0.0, 10.0);
        c.range("behaviour.pass_throttle", b.pass_throttle, 0.0, 1.0);
        c.range("behaviour.pass_return_m", b.pass_return_m, 0.1, 50.0);
        c.range("behaviour.lost_throttle", b.lost_throttle, 0.0, 1.0);
        c.range("behaviour.lost_stop_s", b.lost_stop_s, 0.0, 60.0);

        let g = &self.gpio;
        // BCM GPIO 2..27 are on the 40-pin header; 0 and 1 are reserved for HAT EEPROMs.
        let mut pins = vec![("gpio.button_pin", g.button_pin), ("gpio.led_pin", g.led_pin)];
        if g.ultrasonic {
            pins.push(("gpio.trig_pin", g.trig_pin));
            pins.push(("gpio.echo_pin", g.echo_pin));
        }
        for (i, &(key, pin)) in pins.iter().enumerate() {
            c.range(key, pin, 2, 27);
            if let Some(&(first, _)) = pins[..i].iter().find(|(_, p)| *p == pin) {
                c.fail(key, pin.to_string(), &format!("a pin not already used by {first}"));
            }
        }
        c.range("gpio.debounce_ms", g.debounce_ms, 1.0, 500.0);
        if g.long_press_ms != 0.0 {
            c.range("gpio.long_press_ms", g.long_press_ms, 200.0, 10000.0);
        }
        c.range("gpio.brake_m", g.brake_m, 0.03, 3.9);
        c.range("gpio.release_m", g.release_m, g.brake_m.clamp(0.03, 3.9), 4.0);
        c.range("gpio.sensor_temp_c", g.sensor_temp_c, -20.0, 60.0);
        c.range("gpio.median_n", g.median_n, 1, 15);
        c.range("gpio.period_ms", g.period_ms, 60.0, 1000.0);

        let r = &self.record;
        c.range("record.jpeg_quality", r.jpeg_quality, 1, 100);
        c.range("record.max_mb", r.max_mb, 1.0, 1_000_000.0);
        c.range("record.segment_frames", r.segment_frames, 1, 100_000);
        let d = &self.dashboard;
        if d.listen.parse::<std::net::SocketAddr>().is_err() {
            c.fail(
                "dashboard.listen",
                format!("{:?}", d.listen),
                "IP:PORT, e.g. 127.0.0.1:8080",
            );
        }
        if !d.token.is_empty() && (d.token.len() < 8 || !d.token.chars().all(|ch| ch.is_ascii_alphanumeric())) {
            c.fail("dashboard.token", "(hidden)".into(), "empty, or 8+ letters and digits");
        }
        c.range("dashboard.heartbeat_ms", d.heartbeat_ms, 0, 60_000);
        c.range("dashboard.stream_fps", d.stream_fps, 1.0, 60.0);
        c.range("dashboard.max_viewers", d.max_viewers, 1, 256);
        let st = &self.stereo;
        c.range("stereo.base_m", st.base_m, 0.01, 2.0);
        if st.reference != "left" && st.reference != "right" {
            c.fail(
                "stereo.reference",
                format!("{:?}", st.reference),
                "\"left\" or \"right\"",
            );
        }
        c.range("stereo.min_ncc", st.min_ncc, -1.0, 1.0);
        c.range("stereo.max_disparity_px", st.max_disparity_px, 1, cam.width.max(1));
        c.range("stereo.max_skew_ms", st.max_skew_ms, 0.0, 1000.0);
        c.range("stereo.near_peak_ratio", st.near_peak_ratio, 0.5, 1.0);

        if c.0.is_empty() {
            Ok(())
        } else {
            Err(ConfigError::Invalid {
                origin: "config".into(),
                errors: c.0,
            })
        }
    }

    /// Loads `base`, then each override file, then `key=value` overrides; checks everything.
    /// Relative path keys ([`PATH_KEYS`]) come back absolute, as [`LoadedConfig::load`].
    pub fn load(base: &Path, override_files: &[PathBuf], overrides: &[String]) -> Result<Config, ConfigError> {
        LoadedConfig::load(base, override_files, overrides).map(|l| l.cfg)
    }

    /// Parses one TOML text (e.g. a test's inline config) on top of the defaults. Paths are
    /// kept as written.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Config, ConfigError> {
        let table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: origin.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let layer = Layer {
            origin: origin.to_string(),
            table,
        };
        layer.check_numbers()?;
        Self::from_layers(&[layer])
    }

    /// This config with one dotted numeric or boolean key set, e.g. `steering.kp=0.8`;
    /// used by gain sweeps. Validated like a file. A path value is kept as typed.
    pub fn with_override(&self, assignment: &str) -> Result<Config, ConfigError> {
        let base = Layer {
            origin: "config".into(),
            table: to_table(self),
        };
        Self::from_layers(&[base, Layer::from_assignment(assignment, None)?])
    }

    fn from_layers(layers: &[Layer]) -> Result<Config, ConfigError> {
        let known = to_table(&Config::default());
        let mut merged = toml::Table::new();
        for layer in layers {
            check_known(&layer.table, &known, "", &layer.origin)?;
            merge(&mut merged, &layer.table);
        }
        let origin = layers.iter().map(|l| l.origin.as_str()).collect::<Vec<_>>().join(" + ");
        // serde_path_to_error remembers which key was being read when a type is wrong.
        let cfg: Config = serde_path_to_error::deserialize(toml::Value::Table(merged.clone())).map_err(|e| {
            let key = e.path().to_string();
            let typed = lookup(&merged, &key).map(show_value).unwrap_or_default();
            ConfigError::Type {
                origin: origin.clone(),
                message: if typed.is_empty() {
                    format!("`{key}`: {}", e.inner().message().trim())
                } else {
                    format!("`{key}` = {typed}: {}", e.inner().message().trim())
                },
            }
        })?;
        cfg.validate().map_err(|e| match e {
            ConfigError::Invalid { errors, .. } => ConfigError::Invalid { origin, errors },
            other => other,
        })?;
        Ok(cfg)
    }

    /// Makes every relative path key ([`PATH_KEYS`]) absolute against `dir` (e.g. the folder of
    /// the file the defaults stand for). Empty values are left alone.
    pub fn resolve_paths(&mut self, dir: &Path) {
        for p in [
            &mut self.sim.track,
            &mut self.detect.stop_sign,
            &mut self.detect.traffic_light,
            &mut self.detect.obstacle,
            &mut self.stereo.calibration,
        ] {
            if !p.is_empty() && Path::new(p.as_str()).is_relative() {
                *p = absolute(&dir.join(p.as_str())).display().to_string();
            }
        }
    }

    /// The resolved configuration as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot print config: {e}"))
    }
}

/// A configuration as loaded for a command: the values (path keys absolute), the folder of
/// the base file and every file that was read.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedConfig {
    /// The merged, validated configuration; every [`PATH_KEYS`] value is an absolute path.
    pub cfg: Config,
    /// The folder of the base configuration file, absolute.
    pub dir: PathBuf,
    /// Every file read, base first, then the override files in order.
    pub files: Vec<PathBuf>,
    /// How many values the files set (0: every value is a default).
    pub values_in_files: usize,
}

impl LoadedConfig {
    /// Loads `base`, then each override file (each must exist), then `key=value` overrides,
    /// and checks everything. Relative paths in a file resolve against that file's folder,
    /// those in `overrides` against the working directory, defaults against `base`'s folder.
    pub fn load(base: &Path, override_files: &[PathBuf], overrides: &[String]) -> Result<LoadedConfig, ConfigError> {
        let base_layer = Layer::from_file(base).map_err(|e| match e {
            ConfigError::Io { path, error } if error.kind() == std::io::ErrorKind::NotFound => {
                ConfigError::Missing { path, error }
            }
            other => other,
        })?;
        let mut layers = vec![base_layer];
        for f in override_files {
            layers.push(Layer::from_file(f)?);
        }
        let values_in_files = layers.iter().map(|l| count_values(&l.table)).sum();
        let cwd = absolute(Path::new("."));
        for o in overrides {
            layers.push(Layer::from_assignment(o, Some(&cwd))?);
        }
        let mut cfg = Config::from_layers(&layers)?;
        let dir = absolute(
            base.parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        );
        cfg.resolve_paths(&dir);
        let mut files = vec![base.to_path_buf()];
        files.extend(override_files.iter().cloned());
        Ok(LoadedConfig {
            cfg,
            dir,
            files,
            values_in_files,
        })
    }
}

impl LoadedConfig {
    /// Checks what the configuration would be if the override file `path` held `text`
    /// (before writing it): `base`, then `override_files` without `path`, then `text` as
    /// `path`. Nothing is written.
    pub fn check_with_text(
        base: &Path,
        override_files: &[PathBuf],
        path: &Path,
        text: &str,
    ) -> Result<Config, ConfigError> {
        let mut layers = vec![Layer::from_file(base)?];
        for f in override_files.iter().filter(|f| !same_file(f, path)) {
            layers.push(Layer::from_file(f)?);
        }
        layers.push(Layer::from_text(path, text)?);
        Config::from_layers(&layers)
    }
}

/// The same path, compared after making both absolute (the files need not exist).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => absolute(a) == absolute(b),
    }
}

/// Finds the configuration: `env` (the value of `RCCAR_CONFIG`, relative to `start`) when
/// given and non-empty, else `config/car.toml` in `start` or the nearest folder above it.
pub fn find_config(start: &Path, env: Option<&std::ffi::OsStr>) -> Result<PathBuf, ConfigError> {
    if let Some(e) = env.filter(|e| !e.is_empty()) {
        // Loading it reports a missing file, with the OS error and how to point elsewhere.
        return Ok(start.join(e));
    }
    let start = absolute(start);
    for dir in start.ancestors() {
        let p = dir.join("config").join("car.toml");
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(ConfigError::NotFound { start })
}

/// `p` made absolute against the working directory (no symlinks resolved; unchanged if the
/// working directory cannot be read).
fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

fn count_values(t: &toml::Table) -> usize {
    t.values()
        .map(|v| match v {
            toml::Value::Table(s) => count_values(s),
            _ => 1,
        })
        .sum()
}

/// The value at a serde path such as `steering.kp` or `warp.src[1][0]`.
fn lookup<'a>(t: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut cur: Option<&toml::Value> = None;
    for part in path.split('.') {
        let (name, idx) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        cur = match cur {
            None => t.get(name),
            Some(toml::Value::Table(s)) => s.get(name),
            _ => None,
        };
        for i in idx.split(['[', ']']).filter(|s| !s.is_empty()) {
            cur = match (cur, i.parse::<usize>()) {
                (Some(toml::Value::Array(a)), Ok(i)) => a.get(i),
                _ => None,
            };
        }
    }
    cur
}

fn show_value(v: &toml::Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 60 {
        format!("{}…", s.chars().take(60).collect::<String>())
    } else {
        s
    }
}

/// One source of settings: a file or a command-line assignment.
struct Layer {
    origin: String,
    table: toml::Table,
}

impl Layer {
    fn from_file(path: &Path) -> Result<Layer, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io {
            path: path.into(),
            error,
        })?;
        Self::from_text(path, &text)
    }

    /// The text of a file at `path` (relative paths in it resolve against its folder).
    fn from_text(path: &Path, text: &str) -> Result<Layer, ConfigError> {
        let mut table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: path.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let dir = absolute(
            path.parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        );
        resolve_table_paths(&mut table, &dir);
        let layer = Layer {
            origin: path.display().to_string(),
            table,
        };
        layer.check_numbers()?;
        Ok(layer)
    }

    /// `key=value`; a relative path value resolves against `cwd` when given.
    fn from_assignment(text: &str, cwd: Option<&Path>) -> Result<Layer, ConfigError> {
        let (key, value) = text
            .split_once('=')
            .ok_or_else(|| ConfigError::BadOverride(text.into()))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(ConfigError::BadOverride(text.into()));
        }
        let typed = value.trim();
        // Parse the value as TOML so numbers, booleans, arrays and quoted strings all work;
        // an unquoted word is taken as a string (`lane.threshold_mode=otsu`), unless it reads
        // as a number that is not finite (`1e309`, `NaN`, `inf`): that is refused here.
        let parsed = format!("v = {typed}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"));
        let not_finite = match &parsed {
            Some(toml::Value::Float(f)) => !f.is_finite(),
            Some(_) => false,
            None => typed.parse::<f64>().is_ok_and(|f| !f.is_finite()),
        };
        if not_finite {
            return Err(ConfigError::NotFinite {
                origin: "command line".into(),
                key: key.into(),
                typed: typed.into(),
            });
        }
        let value = parsed.unwrap_or_else(|| toml::Value::String(typed.to_string()));
        let mut table = toml::Table::new();
        let parts: Vec<&str> = key.split('.').collect();
        let mut cur = &mut table;
        for p in &parts[..parts.len() - 1] {
            cur = cur
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .ok_or_else(|| ConfigError::BadOverride(text.into()))?;
        }
        cur.insert(parts[parts.len() - 1].to_string(), value);
        if let Some(cwd) = cwd {
            resolve_table_paths(&mut table, cwd);
        }
        Ok(Layer {
            origin: "command line".into(),
            table,
        })
    }

    /// Refuses inf and NaN anywhere (TOML allows `inf` and `nan` literals).
    fn check_numbers(&self) -> Result<(), ConfigError> {
        fn walk(v: &toml::Value, key: &str, origin: &str) -> Result<(), ConfigError> {
            match v {
                toml::Value::Float(f) if !f.is_finite() => Err(ConfigError::NotFinite {
                    origin: origin.into(),
                    key: key.into(),
                    typed: f.to_string(),
                }),
                toml::Value::Table(t) => {
                    for (k, v) in t {
                        let full = if key.is_empty() {
                            k.clone()
                        } else {
                            format!("{key}.{k}")
                        };
                        walk(v, &full, origin)?;
                    }
                    Ok(())
                }
                toml::Value::Array(a) => {
                    for (i, v) in a.iter().enumerate() {
                        walk(v, &format!("{key}[{i}]"), origin)?;
                    }
                    Ok(())
                }
                _ => Ok(()),
            }
        }
        walk(&toml::Value::Table(self.table.clone()), "", &self.origin)
    }
}

/// Makes the relative string values of [`PATH_KEYS`] in one layer absolute against `dir`.
fn resolve_table_paths(table: &mut toml::Table, dir: &Path) {
    for key in PATH_KEYS {
        let Some((section, name)) = key.split_once('.') else {
            continue;
        };
        if let Some(toml::Value::String(s)) = table
            .get_mut(section)
            .and_then(toml::Value::as_table_mut)
            .and_then(|t| t.get_mut(name))
        {
            if !s.is_empty() && Path::new(s.as_str()).is_relative() {
                *s = absolute(&dir.join(s.as_str())).display().to_string();
            }
        }
    }
}

fn to_table<T: Serialize>(v: &T) -> toml::Table {
    toml::Table::try_from(v).expect("config types always serialise")
}

/// Every key of `layer` must exist in `known` (the default config's tree).
fn check_known(layer: &toml::Table, known: &toml::Table, prefix: &str, origin: &str) -> Result<(), ConfigError> {
    for (k, v) in layer {
        let full = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match known.get(k) {
            None => {
                let hint = closest(k, known.keys())
                    .map(|c| format!(", did you mean `{c}`?"))
                    .unwrap_or_default();
                return Err(ConfigError::UnknownKey {
                    origin: origin.into(),
                    key: full,
                    hint,
                });
            }
            Some(toml::Value::Table(sub)) => {
                if let toml::Value::Table(vt) = v {
                    check_known(vt, sub, &full, origin)?;
                } else {
                    return Err(ConfigError::Type {
                        origin: origin.into(),
                        message: format!("`{full}` is a section ([{full}]), not a value"),
                    });
                }
            }
            Some(_) => {}
        }
    }
    Ok(())
}

fn merge(into: &mut toml::Table, from: &toml::Table) {
    for (k, v) in from {
        match (into.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge(a, b),
            _ => {
                into.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The known key closest to a misspelt one (edit distance ≤ 2).
fn closest<'a>(word: &str, candidates: impl Iterator<Item = &'a String>) -> Option<&'a String> {
    candidates
        .map(|c| (edit_distance(word, c), c))
        .filter(|(d, _)| *d <= 2)
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur.push(sub.min(prev[j + 1] + 1).min(cur[j] + 1));
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Outside any project (and without RCCAR_CONFIG) the search names the folder it started
    /// from and says how to point at a file; the CLI may then fall back to its source tree.
    #[test]
    fn no_config_anywhere_above_is_a_named_error() {
        let t = tempfile::tempdir().unwrap();
        let e = find_config(t.path(), None).unwrap_err();
        let m = e.to_string();
        assert!(m.starts_with("no config/car.toml in ") && m.contains("--config FILE or RCCAR_CONFIG=FILE"), "{m}");
        assert!(matches!(e, ConfigError::NotFound { .. }));
        std::fs::create_dir_all(t.path().join("config/sub")).unwrap();
        std::fs::write(t.path().join("config/car.toml"), "").unwrap();
        assert_eq!(find_config(&t.path().join("config/sub"), None).unwrap(), t.path().join("config/car.toml"));
        assert_eq!(find_config(t.path(), Some(std::ffi::OsStr::new("x.toml"))).unwrap(), t.path().join("x.toml"));
    }

    #[test]
    fn defaults_are_valid() {
        Config::default().validate().unwrap();
    }

    #[test]
    fn shipped_car_toml_equals_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/car.toml");
        let cfg = Config::load(&path, &[], &[]).unwrap();
        let mut def = Config::default();
        def.resolve_paths(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config"));
        assert_eq!(cfg, def, "config/car.toml and Config::default() drifted apart");
    }

    #[test]
    fn unknown_key_is_named_with_a_hint() {
        let e = Config::from_toml_str("[steering]\nkpp = 1.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("steering.kpp") && e.contains("did you mean `kp`"), "{e}");
        let e = Config::from_toml_str("[steer]\nkp = 1.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown key `steer`"), "{e}");
    }

    #[test]
    fn out_of_range_names_key_value_and_range() {
        let e = Config::from_toml_str("[steering]\nkp = -3.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: steering.kp = -3 is out of range (allowed: 0 ..= 20)");
    }

    #[test]
    fn wrong_type_names_key() {
        let e = Config::from_toml_str("[steering]\nkp = \"high\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("kp"), "{e}");
    }

    #[test]
    fn collinear_roi_is_rejected() {
        let e = Config::from_toml_str(
            "[warp]\nsrc = [[0.0,0.0],[10.0,10.0],[20.0,20.0],[30.0,30.0]]\n",
            "t.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("warp.src"), "{e}");
    }

    #[test]
    fn gpio_pin_used_twice_names_both_keys() {
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 17\nled_pin = 5\nechO_pin = 1\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gpio.echO_pin") && e.contains("did you mean `echo_pin`"),
            "{e}"
        );
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 23\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: gpio.trig_pin = 23 is out of range (allowed: a pin not already used by gpio.button_pin)"
        );
        let e = Config::from_toml_str("[gpio]\nled_pin = 24\ntrig_pin = 24\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gpio.trig_pin = 24") && e.contains("used by gpio.led_pin"),
            "{e}"
        );
        assert!(e.contains("gpio.echo_pin = 24") && e.lines().count() == 2, "{e}");
        // Without an ultrasonic sensor its pins are free for other uses.
        Config::from_toml_str("[gpio]\nultrasonic = false\nled_pin = 23\n", "t.toml").unwrap();
        let e = Config::from_toml_str("[gpio]\nbutton_pin = 40\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: gpio.button_pin = 40 is out of range (allowed: 2 ..= 27)");
    }

    #[test]
    fn gpio_and_record_ranges() {
        let bad = [
            ("gpio.debounce_ms=0", "gpio.debounce_ms"),
            ("gpio.long_press_ms=50", "gpio.long_press_ms"),
            ("gpio.release_m=0.2", "gpio.release_m"), // below brake_m
            ("gpio.brake_m=5", "gpio.brake_m"),
            ("gpio.sensor_temp_c=90", "gpio.sensor_temp_c"),
            ("gpio.median_n=0", "gpio.median_n"),
            ("gpio.period_ms=10", "gpio.period_ms"),
            ("record.jpeg_quality=0", "record.jpeg_quality"),
            ("record.jpeg_quality=101", "record.jpeg_quality"),
            ("record.max_mb=0", "record.max_mb"),
            ("record.segment_frames=0", "record.segment_frames"),
        ];
        for (set, key) in bad {
            let e = Config::default().with_override(set).unwrap_err().to_string();
            assert!(e.contains(key), "{set}: {e}");
        }
        let g = Config::default().gpio.options();
        assert_eq!((g.button_pin, g.led_pin, g.trig_pin, g.echo_pin), (17, 27, 23, 24));
        assert!((g.button.debounce_s - 0.03).abs() < 1e-12 && g.button.long_press_s.is_none());
        assert!((g.sonar.brake_m - 0.35).abs() < 1e-12 && (g.sonar_period_s - 0.06).abs() < 1e-12);
        let r = Config::default().record.options();
        assert_eq!((r.jpeg_quality, r.segment_frames), (90, 300));
        assert_eq!(r.max_bytes, 2_000_000_000);
    }

    #[test]
    fn overrides_layer_in_order() {
        let cfg = Config::default().with_override("steering.kp=2.5").unwrap();
        assert_eq!(cfg.steering.kp, 2.5);
        let cfg = cfg.with_override("lane.threshold_mode=otsu").unwrap();
        assert_eq!(cfg.lane.threshold_mode, ThresholdMode::Otsu);
        assert!(Config::default().with_override("steering.kq=1").is_err());
        assert!(Config::default().with_override("nonsense").is_err());
    }
}

/// `[detect]`: the cascades the pipeline runs on every frame (docs/detect.md). A missing file
/// switches that detector off (the pipeline says so once and keeps lane keeping).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DetectConfig {
    /// Run detection at all.
    pub enabled: bool,
    /// Stop-sign cascade (OpenCV XML); a relative path is relative to the folder of the config
    /// file that names it.
    pub stop_sign: String,
    /// Traffic-light cascade; the light's state is read inside its boxes.
    pub traffic_light: String,
    /// Obstacle cascade.
    pub obstacle: String,
    /// Ratio between successive detection scales (> 1; OpenCV's scaleFactor).
    pub scale_factor: f64,
    /// A box needs more than this many raw hits (OpenCV's minNeighbors).
    pub min_neighbors: u32,
    /// Smallest window, pixels (both sides; 0 = the cascade's own size).
    pub min_size_px: u32,
    /// Where stop signs are searched: [left, top, right, bottom], fractions of the frame
    /// (0..1); a box must lie inside.
    pub stop_sign_region: [f64; 4],
    /// Where traffic lights are searched (as `stop_sign_region`).
    pub traffic_light_region: [f64; 4],
    /// Where obstacles are searched (as `stop_sign_region`).
    pub obstacle_region: [f64; 4],
    /// Distances at which objects must be found, [near, far] metres along the floor; with the
    /// box widths below they bound each cascade's window size.
    pub range_m: [f64; 2],
    /// Width of what the stop-sign cascade's box frames, [min, max] metres (its box, not the
    /// sign: trained boxes include a margin).
    pub stop_sign_box_m: [f64; 2],
    /// Width of a traffic-light box, [min, max] metres.
    pub traffic_light_box_m: [f64; 2],
    /// Width of an obstacle box, [min, max] metres.
    pub obstacle_box_m: [f64; 2],
    /// Run the cascades on every Nth frame only; the object tracker (src/ranging/track.rs)
    /// predicts boxes and ranges from odometry on the frames between. 1 = every frame.
    pub every_n_frames: u32,
    /// Search each class only where its box can stand for its size: the box bottom at the
    /// class's height (`[ranging] *_bottom_m`) seen at the distances within `range_m` that its
    /// width allows (`*_box_m`), give or take `pipeline::BAND_SLACK` of the window height.
    pub ground_band: bool,
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            stop_sign: "cascades/stop_sign.xml".into(),
            traffic_light: "cascades/traffic_light.xml".into(),
            obstacle: "cascades/obstacle.xml".into(),
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size_px: 0,
            stop_sign_region: [0.45, 0.0, 1.0, 0.6],
            traffic_light_region: [0.45, 0.0, 1.0, 0.6],
            obstacle_region: [0.0, 0.08, 1.0, 1.0],
            range_m: [0.2, 1.6],
            stop_sign_box_m: [0.11, 0.16],
            traffic_light_box_m: [0.065, 0.10],
            obstacle_box_m: [0.18, 0.45],
            every_n_frames: 2,
            ground_band: true,
        }
    }
}

/// `[ranging]`: distance of each detected box by tilt ranging (src/ranging.rs, docs/ranging.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RangingConfig {
    /// Calibrated principal-point row minus the image centre row, pixels
    /// (`rccar calibrate ranging` writes it).
    pub v0_offset_px: f64,
    /// Calibrated a_y divided by the nominal focal length from camera.hfov_deg.
    pub a_y_scale: f64,
    /// Height above the floor of a stop sign box's bottom edge (the face's lower edge), metres.
    pub stop_sign_bottom_m: f64,
    /// Height of a traffic-light box's bottom edge (the housing's lower edge), metres.
    pub traffic_light_bottom_m: f64,
    /// Height of an obstacle box's bottom edge, metres (0: it stands on the floor).
    pub obstacle_bottom_m: f64,
    /// [width, height] of the face a stop-sign box frames, metres (0 = unknown: not used).
    pub stop_sign_size_m: [f64; 2],
    /// [width, height] of the face a traffic-light box frames (the housing), metres.
    pub traffic_light_size_m: [f64; 2],
    /// [width, height] of an obstacle's face, metres (0, 0: obstacles differ; contact row only).
    pub obstacle_size_m: [f64; 2],
    /// A stop-sign detector box's size over the face's outline (the training margin).
    pub stop_sign_box_margin: f64,
    /// A traffic-light detector box's size over the housing's outline.
    pub traffic_light_box_margin: f64,
    /// An obstacle detector box's size over the obstacle's outline.
    pub obstacle_box_margin: f64,
    /// σ of a detector box's centre row, pixels.
    pub box_centre_sigma_px: f64,
    /// σ of a detector box's size, relative.
    pub box_size_sigma: f64,
    /// Object tracker: σ of an object's own acceleration along the line of sight, m/s².
    pub track_accel_sigma: f64,
    /// Object tracker: σ of the odometry's distance per frame, relative to that distance.
    pub track_odometry_sigma: f64,
    /// Object tracker: a track not matched on this many detection frames in a row is dropped.
    pub track_max_missed: u32,
    /// Refine stop-sign and traffic-light boxes by colour (red area, dark housing) before
    /// ranging them.
    pub refine_by_colour: bool,
    /// Share of a stop sign's face (across the flats) that is red inside its white rim.
    pub stop_sign_red_fraction: f64,
    /// Where the behaviours' distances come from: "mono" (the tilt and box size of one
    /// camera) or "stereo" (the pair's disparity, `[stereo]`; docs/stereo.md).
    pub method: String,
}

impl Default for RangingConfig {
    fn default() -> Self {
        Self {
            v0_offset_px: 0.0,
            a_y_scale: 1.0,
            stop_sign_bottom_m: 0.12,
            traffic_light_bottom_m: 0.10,
            obstacle_bottom_m: 0.0,
            stop_sign_size_m: [0.10, 0.10],
            traffic_light_size_m: [0.0, 0.12],
            obstacle_size_m: [0.0, 0.0],
            stop_sign_box_margin: 1.085,
            traffic_light_box_margin: 1.21,
            obstacle_box_margin: 1.36,
            box_centre_sigma_px: 1.0,
            box_size_sigma: 0.06,
            track_accel_sigma: 0.5,
            track_odometry_sigma: 0.1,
            track_max_missed: 3,
            refine_by_colour: true,
            stop_sign_red_fraction: 0.9,
            method: "mono".into(),
        }
    }
}

/// `[stereo]`: a second camera for stereo ranging (src/stereo/, docs/stereo.md; Zaarane et
/// al. 2020, Abdollahi 2011).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StereoConfig {
    /// Distance between the two lenses, metres (used when `calibration` is empty).
    pub base_m: f64,
    /// Which camera detection runs on: `left` or `right`.
    pub reference: String,
    /// Results file of `rccar calibrate stereo` (JSON); empty = an ideal pair of `[camera]`.
    pub calibration: String,
    /// Lowest normalised cross-correlation that counts as a match (-1..1).
    pub min_ncc: f64,
    /// Largest disparity searched, pixels.
    pub max_disparity_px: u32,
    /// Of the correlation peaks scoring at least this fraction of the best, the nearest is
    /// taken (an object hides what is behind it); 1 = always the best.
    pub near_peak_ratio: f64,
    /// A box that matches a copy of itself along its own rows as well as it matches the other
    /// image (wallpaper, tiles) gets no range (`stereo::NoRange::Repeated`).
    pub reject_repeats: bool,
    /// Largest time between the two cameras' frames paired as one stereo frame, milliseconds.
    pub max_skew_ms: f64,
}

impl Default for StereoConfig {
    fn default() -> Self {
        Self {
            base_m: 0.06,
            reference: "left".into(),
            calibration: String::new(),
            min_ncc: 0.6,
            max_disparity_px: 120,
            near_peak_ratio: 0.9,
            reject_repeats: true,
            max_skew_ms: 20.0,
        }
    }
}

/// `[behaviour]`: the state machine of src/control/behaviour.rs (docs/behaviour.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BehaviourConfig {
    /// A detection is confirmed when seen in `confirm_frames` of the last `window_frames`.
    pub confirm_frames: u32,
    /// Length of the confirmation window, frames.
    pub window_frames: u32,
    /// Below this estimated speed the car counts as stopped, m/s.
    pub standstill_mps: f64,
    /// Stop for a stop sign once it is confirmed nearer than this, metres (forward distance).
    pub stop_trigger_m: f64,
    /// Where the car should come to rest before a stop sign, metres from the lens [near, far]
    /// (the simulator's scenario score).
    pub stop_window_m: [f64; 2],
    /// How long to stand at a stop sign, counted from standstill, seconds.
    pub stop_hold_s: f64,
    /// After leaving a stop sign, ignore stop signs until the car has driven this far, metres...
    pub stop_ignore_m: f64,
    /// ...and for at least this long, seconds.
    pub stop_ignore_s: f64,
    /// Stop for a red (or amber) light confirmed nearer than this, metres.
    pub light_trigger_m: f64,
    /// Green seen in this many consecutive frames releases a red-light stop.
    pub green_confirm_frames: u32,
    /// A red-light stop also ends when no light has been seen for this long, seconds.
    pub light_lost_s: f64,
    /// Stop while an obstacle in the lane is nearer than this, metres.
    pub obstacle_stop_m: f64,
    /// An obstacle counts as in the lane when its centre is within this of the car's axis, metres.
    pub obstacle_lane_half_m: f64,
    /// Pass a blocking obstacle through the other (left) lane.
    pub pass_enabled: bool,
    /// With passing enabled, stop this far before an obstacle instead (room to swing out), metres.
    pub pass_trigger_m: f64,
    /// Stand this long before starting to pass, seconds.
    pub pass_wait_s: f64,
    /// Steering used for each half of the lane change (0..1).
    pub pass_steer: f64,
    /// Distance driven for each half of the lane change, metres.
    pub pass_turn_m: f64,
    /// Distance driven in the other lane (lane keeping) before changing back, metres.
    pub pass_along_m: f64,
    /// Throttle while passing.
    pub pass_throttle: f64,
    /// The car must be back in its lane within this distance from the start of the pass, metres.
    pub pass_return_m: f64,
    /// Throttle while the lane is lost, before stopping.
    pub lost_throttle: f64,
    /// Stop after the lane has been lost this long, seconds.
    pub lost_stop_s: f64,
}

impl Default for BehaviourConfig {
    fn default() -> Self {
        Self {
            confirm_frames: 3,
            window_frames: 5,
            standstill_mps: 0.01,
            stop_trigger_m: 0.9,
            stop_window_m: [0.5, 1.0],
            stop_hold_s: 5.0,
            stop_ignore_m: 1.0,
            stop_ignore_s: 2.0,
            light_trigger_m: 1.0,
            green_confirm_frames: 2,
            light_lost_s: 3.0,
            obstacle_stop_m: 0.45,
            obstacle_lane_half_m: 0.12,
            pass_enabled: false,
            pass_trigger_m: 0.85,
            pass_wait_s: 1.0,
            pass_steer: 0.8,
            pass_turn_m: 0.6,
            pass_along_m: 0.3,
            pass_throttle: 0.35,
            pass_return_m: 3.5,
            lost_throttle: 0.2,
            lost_stop_s: 1.0,
        }
    }
}

/// `[gpio]`: the Raspberry Pi's GPIO (feature `gpio`, src/gpio/): a start/stop push button, a
/// status LED and an HC-SR04 ultrasonic sensor as an emergency brake. Pins are BCM numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpioConfig {
    /// Use the GPIO at all (false on a desk computer).
    pub enabled: bool,
    /// Push button to ground, BCM pin (internal pull-up).
    pub button_pin: u8,
    /// Status LED with its resistor, BCM pin.
    pub led_pin: u8,
    /// An HC-SR04 is wired (false: no ultrasonic brake; its pins are not used).
    pub ultrasonic: bool,
    /// HC-SR04 TRIG, BCM pin.
    pub trig_pin: u8,
    /// HC-SR04 ECHO through a 5 V -> 3.3 V divider, BCM pin.
    pub echo_pin: u8,
    /// A button level must hold this long to count, milliseconds.
    pub debounce_ms: f64,
    /// Holding the button this long is a long press, milliseconds (0 = off).
    pub long_press_ms: f64,
    /// Brake when the ultrasonic distance is nearer than this, metres.
    pub brake_m: f64,
    /// Release the brake beyond this distance, metres (> brake_m).
    pub release_m: f64,
    /// Air temperature at the sensor, degrees Celsius (speed of sound).
    pub sensor_temp_c: f64,
    /// Ultrasonic readings in the median filter.
    pub median_n: u32,
    /// Time between two ultrasonic measurements, milliseconds.
    pub period_ms: f64,
}

impl Default for GpioConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            button_pin: 17,
            led_pin: 27,
            ultrasonic: true,
            trig_pin: 23,
            echo_pin: 24,
            debounce_ms: 30.0,
            long_press_ms: 0.0,
            brake_m: 0.35,
            release_m: 0.50,
            sensor_temp_c: 20.0,
            median_n: 3,
            period_ms: 60.0,
        }
    }
}

impl GpioConfig {
    /// The GPIO layer's options (ms -> s; the sensor's fixed limits from its datasheet).
    pub fn options(&self) -> crate::gpio::GpioOptions {
        use crate::gpio::{ButtonOptions, EchoTimeouts, GpioOptions, UltrasonicOptions};
        GpioOptions {
            button_pin: self.button_pin,
            led_pin: self.led_pin,
            ultrasonic: self.ultrasonic,
            trig_pin: self.trig_pin,
            echo_pin: self.echo_pin,
            button: ButtonOptions {
                debounce_s: self.debounce_ms / 1000.0,
                long_press_s: (self.long_press_ms > 0.0).then_some(self.long_press_ms / 1000.0),
            },
            sonar: UltrasonicOptions {
                temp_c: self.sensor_temp_c,
                median_n: self.median_n as usize,
                brake_m: self.brake_m,
                release_m: self.release_m,
                ..UltrasonicOptions::default()
            },
            sonar_period_s: self.period_ms / 1000.0,
            timeouts: EchoTimeouts::default(),
        }
    }
}

/// `[record]`: recording frames and telemetry on the car (src/record.rs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecordConfig {
    /// JPEG quality of recorded frames, 1..=100.
    pub jpeg_quality: u8,
    /// Disk budget of one recording, megabytes (10^6 bytes); the oldest frames go first.
    pub max_mb: f64,
    /// Frames per segment folder (the unit that is deleted when over budget).
    pub segment_frames: u32,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            jpeg_quality: 90,
            max_mb: 2000.0,
            segment_frames: 300,
        }
    }
}

impl RecordConfig {
    /// The recorder's options.
    pub fn options(&self) -> crate::record::RecordOptions {
        crate::record::RecordOptions {
            jpeg_quality: self.jpeg_quality,
            max_bytes: (self.max_mb * 1e6).round() as u64,
            segment_frames: self.segment_frames,
        }
    }
}
