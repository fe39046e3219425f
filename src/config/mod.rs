//! The car's configuration: `config/car.toml`, the one file students edit.
//!
//! Loading goes in three steps (`layers.rs`):
//! 1. the base file is parsed as TOML (a syntax error names its line) and merged over the
//!    defaults, table by table;
//! 2. an optional personal override file (git-ignored, e.g. `config/local.toml`) is merged on
//!    top, and `key=value` overrides from the command line after it;
//! 3. the merged tree is checked for unknown keys (a typo such as `steering.kpp` is an error
//!    naming it, never silently ignored), deserialised into [`Config`] and every value is
//!    range-checked by [`Config::validate`] (`check.rs`); an error names the key, the value and
//!    the range.
//!
//! One file per `[section]` holds its struct, its defaults ([`Default`]), its own checks and its
//! conversion into the option type of the stage it configures (which lives in the stage: the
//! stages never read the configuration). Every section has defaults, so tests and the
//! simulator can start from `Config::default()` and a file only needs the keys it changes. The
//! shipped `car.toml` lists them all, with units and advice. The object classes' sections
//! (`[classes.<name>]`, `classes.rs`) are one table keyed by class name, each class's defaults
//! from its entry in the registry (src/classes.rs).

mod behaviour;
mod camera;
mod check;
mod classes;
mod colour_template;
mod dashboard;
mod detect;
mod gamepad;
mod gpio;
mod lane;
mod layers;
mod manual;
mod route;
mod ranging;
mod record;
mod replay;
mod sim;
mod steering;
mod stereo;
mod throttle;
mod value;
mod vehicle;
mod warp;

pub use behaviour::BehaviourConfig;
pub use camera::{CameraConfig, LensError};
pub use classes::{ClassConfig, ClassesConfig, DetectMethod};
pub use colour_template::ColourTemplateConfig;
pub use dashboard::DashboardConfig;
pub use detect::DetectConfig;
pub use gamepad::{axis_code, GamepadConfig};
pub use gpio::GpioConfig;
pub use lane::{LaneConfig, LaneSetupError, PeakMode, ThresholdMode};
pub use layers::{find_config, find_local, local_beside, path_keys, source_tree_config, LoadedConfig, MissingLocal};
pub use manual::ManualConfig;
pub use route::{Junctions, RouteConfig};
pub use ranging::{RangingConfig, RangingMethod};
pub use record::RecordConfig;
pub use replay::ReplayConfig;
pub use sim::SimConfig;
pub use steering::SteeringConfig;
pub use stereo::{StereoConfig, StereoReference};
pub use throttle::ThrottleConfig;
pub use vehicle::VehicleConfig;
pub use warp::{RoiError, WarpConfig};

use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::PathBuf;

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
    /// Monocular tilt ranging of detected boxes: calibration corrections, box noise, tracks.
    pub ranging: RangingConfig,
    /// `[classes.<name>]`: each object class's model file, search region, box width and what
    /// its box frames (one section per entry of src/classes.rs).
    pub classes: ClassesConfig,
    /// `[colour_template]`: Abdollahi's colour + template stop-sign detector, for a class whose
    /// `detect` is `colour_template`.
    pub colour_template: ColourTemplateConfig,
    /// The behaviour state machine: stop signs, lights, obstacles, lane lost.
    pub behaviour: BehaviourConfig,
    /// The Raspberry Pi's GPIO: start/stop button, status LED, HC-SR04 ultrasonic brake.
    pub gpio: GpioConfig,
    /// Recording on the car (`--record DIR`): JPEG quality, disk budget, segments.
    pub record: RecordConfig,
    /// `[dashboard]`: the live page of `sim|drive --dashboard`.
    pub dashboard: DashboardConfig,
    /// `[manual]`: driving by hand (the input's deadline, the human's throttle ceiling).
    pub manual: ManualConfig,
    /// `[route]`: the way at each fork and the junction rule (src/lane/junction.rs).
    pub route: RouteConfig,
    /// `[gamepad]`: a gamepad read on the car (`rccar drive --pad`, feature `gamepad`).
    pub gamepad: GamepadConfig,
    /// Stereo ranging with a second camera (src/stereo/, docs/stereo.md).
    pub stereo: StereoConfig,
}

impl Config {
    /// The resolved configuration as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot print config: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn shipped_car_toml_equals_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/car.toml");
        let cfg = Config::load(&path, &[], &[]).unwrap();
        let mut def = Config::default();
        def.resolve_paths(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config"));
        assert_eq!(cfg, def, "config/car.toml and Config::default() drifted apart");
    }
}
