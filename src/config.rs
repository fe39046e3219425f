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
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File that failed.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
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
    /// One or more values outside their allowed range.
    #[error("{}", .errors.iter().map(|e| format!("{origin}: {e}")).collect::<Vec<_>>().join("\n"))]
    Invalid {
        /// The file(s) the values came from.
        origin: String,
        /// Every bad value.
        errors: Vec<InvalidValue>,
    },
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
    /// Low-pass time constant of the derivative, seconds (0 = none).
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
            derivative_tau: 0.05,
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
    /// Track file, relative to the working directory.
    pub track: String,
    /// Laps to drive before the run ends.
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
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            track: "config/tracks/default.toml".into(),
            laps: 3,
            max_seconds: 600.0,
            substeps: 4,
            seed: 1,
            noise_sigma: 2.0,
            blur_px: 0.0,
            exposure: 1.0,
            light_variation: 0.0,
            light_period_s: 10.0,
        }
    }
}

/// Checks that collect every out-of-range value instead of stopping at the first.
struct Checker(Vec<InvalidValue>);

impl Checker {
    fn range<T: PartialOrd + fmt::Display + Copy>(&mut self, key: &str, v: T, lo: T, hi: T) {
        if !(v >= lo && v <= hi) {
            self.0.push(InvalidValue {
                key: key.into(),
                value: v.to_string(),
                allowed: format!("{lo} ..= {hi}"),
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

        let d = &self.detect;
        c.range("detect.scale_factor", d.scale_factor, 1.01, 2.0);
        c.range("detect.min_neighbors", d.min_neighbors, 0, 100);
        c.range("detect.min_size_px", d.min_size_px, 0, 4096);

        let r = &self.ranging;
        c.range("ranging.v0_offset_px", r.v0_offset_px, -200.0, 200.0);
        c.range("ranging.a_y_scale", r.a_y_scale, 0.5, 2.0);
        c.range("ranging.stop_sign_bottom_m", r.stop_sign_bottom_m, 0.0, 3.0);
        c.range("ranging.traffic_light_bottom_m", r.traffic_light_bottom_m, 0.0, 3.0);
        c.range("ranging.obstacle_bottom_m", r.obstacle_bottom_m, 0.0, 3.0);
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

        let st = &self.stereo;
        c.range("stereo.base_m", st.base_m, 0.01, 2.0);
        if st.reference != "left" && st.reference != "right" {
            c.fail("stereo.reference", format!("{:?}", st.reference), "\"left\" or \"right\"");
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
    pub fn load(base: &Path, override_files: &[PathBuf], overrides: &[String]) -> Result<Config, ConfigError> {
        let mut layers = vec![Layer::from_file(base)?];
        for f in override_files {
            layers.push(Layer::from_file(f)?);
        }
        for o in overrides {
            layers.push(Layer::from_assignment(o)?);
        }
        Self::from_layers(&layers)
    }

    /// Parses one TOML text (e.g. a test's inline config) on top of the defaults.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Config, ConfigError> {
        let table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: origin.into(),
            message: e.to_string(),
        })?;
        Self::from_layers(&[Layer {
            origin: origin.to_string(),
            table,
        }])
    }

    /// This config with one dotted numeric or boolean key set, e.g. `steering.kp=0.8`;
    /// used by gain sweeps. Validated like a file.
    pub fn with_override(&self, assignment: &str) -> Result<Config, ConfigError> {
        let base = Layer {
            origin: "config".into(),
            table: to_table(self),
        };
        Self::from_layers(&[base, Layer::from_assignment(assignment)?])
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
        let cfg: Config =
            serde_path_to_error::deserialize(toml::Value::Table(merged)).map_err(|e| ConfigError::Type {
                origin: origin.clone(),
                message: format!("`{}`: {}", e.path(), e.inner().message().trim()),
            })?;
        cfg.validate().map_err(|e| match e {
            ConfigError::Invalid { errors, .. } => ConfigError::Invalid { origin, errors },
            other => other,
        })?;
        Ok(cfg)
    }

    /// The resolved configuration as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot print config: {e}"))
    }
}

/// One source of settings: a file or a command-line assignment.
struct Layer {
    origin: String,
    table: toml::Table,
}

impl Layer {
    fn from_file(path: &Path) -> Result<Layer, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.into(),
            source,
        })?;
        let table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: path.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        Ok(Layer {
            origin: path.display().to_string(),
            table,
        })
    }

    fn from_assignment(text: &str) -> Result<Layer, ConfigError> {
        let (key, value) = text
            .split_once('=')
            .ok_or_else(|| ConfigError::BadOverride(text.into()))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(ConfigError::BadOverride(text.into()));
        }
        // Parse the value as TOML so numbers, booleans, arrays and quoted strings all work;
        // an unquoted word is taken as a string (`lane.threshold_mode=otsu`).
        let value = format!("v = {}", value.trim())
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.trim().to_string()));
        let mut table = toml::Table::new();
        let parts: Vec<&str> = key.split('.').collect();
        let mut cur = &mut table;
        for p in &parts[..parts.len() - 1] {
            cur = cur
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .expect("just inserted a table");
        }
        cur.insert(parts[parts.len() - 1].to_string(), value);
        Ok(Layer {
            origin: "command line".into(),
            table,
        })
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

    #[test]
    fn defaults_are_valid() {
        Config::default().validate().unwrap();
    }

    #[test]
    fn shipped_car_toml_equals_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/car.toml");
        let cfg = Config::load(&path, &[], &[]).unwrap();
        assert_eq!(
            cfg,
            Config::default(),
            "config/car.toml and Config::default() drifted apart"
        );
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
    /// Stop-sign cascade (OpenCV XML), relative to the working directory.
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
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            stop_sign: "config/cascades/stop_sign.xml".into(),
            traffic_light: "config/cascades/traffic_light.xml".into(),
            obstacle: "config/cascades/obstacle.xml".into(),
            scale_factor: 1.1,
            min_neighbors: 3,
            min_size_px: 0,
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
}

impl Default for RangingConfig {
    fn default() -> Self {
        Self {
            v0_offset_px: 0.0,
            a_y_scale: 1.0,
            stop_sign_bottom_m: 0.12,
            traffic_light_bottom_m: 0.10,
            obstacle_bottom_m: 0.0,
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
