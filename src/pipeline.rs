//! The one pipeline the car, replay and the simulator all run: frame → lane measurement +
//! detections → ranges → behaviour → command. Nothing in here knows which of the three is
//! calling.
//!
//! One frame (`dt` seconds after the previous one):
//! 1. lane: bird's-eye warp, edges, histogram → `LaneMeasurement` (src/lane); a line across
//!    the lane in the same bird's-eye images (src/lane/stop_line.rs);
//! 2. detect: the classes' cascades on the frame (src/detect), or boxes handed in
//!    ([`Pipeline::step_with`], the simulator's ground-truth switch), light state per light box.
//!    A parallel detector ([`DetectStage::set_parallel`], as the car, replay and simulator
//!    load it) runs beside step 1 (with feature `parallel`, on rayon's threads: the two
//!    read the same frame and nothing of each other; whichever ends first helps the
//!    detector's scales), so a frame costs about the detector's time, not the sum;
//! 3. dead reckoning: speed and distance from the previous command through `[vehicle]`;
//! 4. ranging and tracking: each detector box's distance from its size and row, fused, with a
//!    σ (`BoxRanging::range_detector`, src/ranging.rs; a true box: Eq. 5 on its bottom row);
//!    then per-object tracks (src/ranging/track.rs: association, a constant-velocity Kalman
//!    filter in distance with the dead reckoning's distance as its control input). The
//!    detector runs on every `detect.every_n_frames`-th frame; in between the tracks predict
//!    boxes and ranges. The objects reported are the tracks matched this frame, and between
//!    detections the tracks matched at the last one (seen at least twice);
//! 5. behaviour: the state machine (src/control/behaviour.rs) on these observations;
//! 6. control: lane PID + throttle policy, overridden or capped by the behaviour's decision.
//!
//! Without a detector (none loaded, or the cascade files missing) steps 2–3 find nothing and
//! the car keeps its lane; the behaviour machine still handles a lost lane.

use crate::classes::{ColourCue, Reaction, TurnArrow};
use crate::config::{Config, DetectMethod};
use crate::control::behaviour::{Behaviour, DeadReckoning, Decision, LightColor, Mode, Observations, Ranged};
use crate::control::steering::SteeringInput;
use crate::control::{Command, Controller};
use crate::detect::cascade::CascadeError;
use crate::detect::detector::DetectParams;
use crate::detect::light::{LightReading, LightState};
use crate::detect::stage::{CascadeSpec, DetectStage};
use crate::detect::Rect;
use crate::lane::stop_line::StopLineDetector;
use crate::lane::warp::WarpError;
use crate::lane::{LaneDetector, LaneMeasurement};
use crate::ranging::track::{Measurement, Tracker};
use crate::ranging::{BoxRanging, ObjectClass};
use crate::source::GivenBox;
use crate::detect::colour_sign::{HsvSignDetector, HsvSignOptions};
use crate::timing::{StageTimer, StageTimes};
use image::RgbImage;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Why a pipeline cannot be built from a configuration.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The ROI does not define a bird's-eye view.
    #[error("warp.src: {0}")]
    Warp(WarpError),
    /// The camera's lens (`camera.distortion`, `camera.calibration`) cannot be folded into
    /// the bird's-eye map.
    #[error(transparent)]
    Lens(crate::config::LensError),
    /// A cascade file exists but cannot be read or parsed.
    #[error("detect: {0}")]
    Cascade(CascadeError),
    /// `stereo.calibration` names a file that cannot be read, is not a stereo calibration, or
    /// was made for another image size.
    #[error("stereo.calibration: {0}")]
    StereoCalibration(crate::calib::file::FileError),
    /// The steering method `steering.method` picks cannot be built from this configuration.
    #[error(transparent)]
    Steering(#[from] crate::control::steering::SteeringError),
}

// By hand, not `#[from]`: a `source` would print the file's error a second time.
impl From<crate::calib::file::FileError> for PipelineError {
    fn from(e: crate::calib::file::FileError) -> Self {
        PipelineError::StereoCalibration(e)
    }
}

impl From<crate::config::LaneSetupError> for PipelineError {
    fn from(e: crate::config::LaneSetupError) -> Self {
        match e {
            crate::config::LaneSetupError::Warp(w) => PipelineError::Warp(w),
            crate::config::LaneSetupError::Lens(l) => PipelineError::Lens(l),
        }
    }
}

impl From<WarpError> for PipelineError {
    fn from(e: WarpError) -> Self {
        PipelineError::Warp(e)
    }
}

impl From<CascadeError> for PipelineError {
    fn from(e: CascadeError) -> Self {
        PipelineError::Cascade(e)
    }
}

/// What one frame produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOutput {
    /// The lane as measured.
    pub lane: LaneMeasurement,
    /// The command for the car.
    pub command: Command,
    /// Microseconds per stage (zeros with `NoTimer`).
    pub stage_us: StageTimes,
    /// The detector's own time (it runs beside the lane stage) + ranging + behaviour,
    /// microseconds (0 with `NoTimer`).
    pub detect_us: u32,
    /// The behaviour state after this frame.
    pub mode: Mode,
    /// What the behaviour machine was given.
    pub observations: Observations,
    /// At a junction (`route.junctions`): fork or merge, the line kept, the way and why.
    pub junction: Option<crate::lane::junction::JunctionReport>,
}

/// One object of a frame, ranged (a telemetry field).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangedObject {
    /// What it is.
    pub class: ObjectClass,
    /// [left, top, right, bottom], pixels.
    pub bbox: [f64; 4],
    /// Forward distance from the lens, metres (`None` above the horizon).
    pub distance_m: Option<f64>,
    /// Lateral offset, metres, left positive.
    pub lateral_m: Option<f64>,
    /// A traffic light's colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light: Option<LightColor>,
    /// A turn sign's arrow, `left` or `right` (read inside its box).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arrow: Option<TurnArrow>,
    /// σ of `distance_m`, metres (the track's filter; absent for an object without a range).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_sigma_m: Option<f64>,
    /// This frame's single-box distance before tracking, metres (absent between detections).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_m: Option<f64>,
    /// The object's track (the same number across frames).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track_id: Option<u32>,
    /// `true` on frames without detection: box and range predicted by the track.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub predicted: bool,
}

/// A class's cascade (`classes.<name>.model`) that is configured (a non-empty path) but not a
/// file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MissingCascade {
    /// The config key (`classes.stop_sign.model`, …; the registry's `model_key`).
    pub key: &'static str,
    /// The path that was looked for.
    pub path: PathBuf,
}

impl std::fmt::Display for MissingCascade {
    /// The key, the file and the fix, as the binary and the session report it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} = {:?}: no such cascade file; give the cascade's path (a relative path written in a file is read from that file's folder, one given with --set from the working directory), set {} = \"\" to run without that detector, or detect.enabled = false for lane keeping only",
            self.key,
            self.path.display().to_string(),
            self.key
        )
    }
}

/// The cascade file of every class found by one (`detect = "cascade"` and a non-empty
/// `classes.<name>.model`, relative to `base`), in the registry's order: those that exist, and
/// those configured but missing. Shared by [`load_detector`] and `rccar detect`'s default.
pub fn cascade_files(cfg: &Config, base: &Path) -> (Vec<(ObjectClass, PathBuf)>, Vec<MissingCascade>) {
    let mut found = Vec::new();
    let mut missing = Vec::new();
    for (class, k) in cfg.classes.iter() {
        if k.detect == DetectMethod::ColourTemplate || k.model.is_empty() {
            continue;
        }
        let path = base.join(&k.model);
        if path.is_file() {
            found.push((class, path));
        } else {
            missing.push(MissingCascade {
                key: class.info().model_key,
                path,
            });
        }
    }
    (found, missing)
}

/// Loads the classes' cascades (`classes.<name>.model`) that exist (paths relative to `base`;
/// an empty path switches that class off), and the colour detector of every class whose
/// `detect` is `colour_template` (no file: its templates are drawn from geometry). Returns the
/// stage (`None` when nothing is detected or `detect.enabled` is off) and the configured files
/// that were missing, which the binary refuses (a configured model that is not there is an
/// error, not a silently weaker car). This is the pipeline's only filesystem access.
pub fn load_detector(cfg: &Config, base: &Path) -> Result<(Option<DetectStage>, Vec<MissingCascade>), CascadeError> {
    if !cfg.detect.enabled {
        return Ok((None, Vec::new()));
    }
    let params = DetectParams::from(&cfg.detect);
    let (found, missing) = cascade_files(cfg, base);
    let specs: Vec<CascadeSpec> = found
        .into_iter()
        .map(|(class, path)| CascadeSpec {
            label: class.name().into(),
            path,
            traffic_light: class.info().reads_light,
            params: class_params(params, cfg.classes[class].min_neighbors),
        })
        .collect();
    let colour: Vec<ObjectClass> = cfg
        .classes
        .iter()
        .filter(|(_, k)| k.detect == DetectMethod::ColourTemplate)
        .map(|(class, _)| class)
        .collect();
    if specs.is_empty() && colour.is_empty() {
        return Ok((None, missing));
    }
    let mut stage = DetectStage::load(&specs)?;
    // The pyramid levels spread over the cores (feature `parallel`; the same boxes in the same
    // order as on one thread): the frame's detection answers sooner on the car and the
    // simulator runs faster.
    stage.set_parallel(true);
    for class in colour {
        let det = HsvSignDetector::with_octagon_model(HsvSignOptions::from(&cfg.colour_template)).map_err(|err| {
            CascadeError::ColourTemplate {
                class: class.name().into(),
                err,
            }
        })?;
        stage.add_colour_sign(class.name(), det);
    }
    Ok((Some(stage), missing))
}

/// The grouping threshold the car uses for `class`: `classes.<name>.min_neighbors`, or
/// `detect.min_neighbors` when that is 0 (`rccar detect` without `--cascade` reads it here).
pub fn class_min_neighbors(cfg: &Config, class: ObjectClass) -> u32 {
    class_params(DetectParams::from(&cfg.detect), cfg.classes[class].min_neighbors).min_neighbors
}

/// `[detect]`'s scan parameters with one class's own grouping threshold
/// (`classes.<name>.min_neighbors`; 0 keeps `detect.min_neighbors`).
fn class_params(detect: DetectParams, min_neighbors: u32) -> DetectParams {
    DetectParams {
        min_neighbors: if min_neighbors > 0 { min_neighbors } else { detect.min_neighbors },
        ..detect
    }
}

/// Where and at which sizes one class is searched (from `[classes.<name>]`, `[detect]` and the
/// camera).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DetectLimits {
    /// The class (its name is the cascade's label).
    pub class: ObjectClass,
    /// Boxes must lie inside this rectangle, frame pixels.
    pub region: Rect,
    /// Smallest window (width, height), pixels.
    pub min_size: (u32, u32),
    /// Largest window (width, height), pixels.
    pub max_size: (u32, u32),
}

/// The regions and size limits of each class (`classes.<name>.region`, `box_m`) in frame
/// pixels. An object `W` metres wide at `d` metres is about `f·W/d` pixels wide (pinhole, `f`
/// from `camera.hfov_deg`), so a box of width `[W_min, W_max]` seen within
/// `range_m = [near, far]` is at least `⌊f·W_min/far⌋` and at most `⌈f·W_max/near⌉` pixels
/// wide; `min_size_px` still applies. Only widths are limited (the window's aspect is the
/// cascade's).
pub fn detect_limits(cfg: &Config) -> [DetectLimits; ObjectClass::COUNT] {
    let d = &cfg.detect;
    let f = crate::camera::PinholeCamera::from(&cfg.camera).f_px;
    let (w, h) = (cfg.camera.width as f64, cfg.camera.height as f64);
    ObjectClass::ALL.map(|class| {
        let (r, b) = (cfg.classes[class].region, cfg.classes[class].box_m);
        let (x0, y0) = ((r[0] * w).floor() as i32, (r[1] * h).floor() as i32);
        let (x1, y1) = ((r[2] * w).ceil() as i32, (r[3] * h).ceil() as i32);
        let min_w = ((f * b[0] / d.range_m[1]).floor() as u32).max(d.min_size_px);
        let max_w = ((f * b[1] / d.range_m[0]).ceil().min(1e6) as u32).max(min_w).max(1);
        DetectLimits {
            class,
            region: Rect::new(x0, y0, x1 - x0, y1 - y0),
            min_size: (min_w, d.min_size_px),
            max_size: (max_w, u32::MAX),
        }
    })
}

/// Slack of the ground-plane band ([`detect_bands`]): a box's bottom edge may lie this
/// fraction of its height, plus [`BAND_SLACK_PX`], beyond where geometry puts it (trained
/// boxes carry a margin below the object; raw hits of one object spread by a few pixels).
pub const BAND_SLACK: f64 = 0.35;
/// Fixed part of the band's slack, pixels.
pub const BAND_SLACK_PX: f64 = 4.0;
/// Size slack of the band: the raw hits of one object come from windows up to a few scales
/// larger or smaller than its box, so the band is made for box widths `W_min/k ..= W_max·k` and
/// distances up to `far·k`, with this `k`.
pub const BAND_SIZE_SLACK: f64 = 1.25;

/// The ground-plane band of each class, in the order of [`detect_limits`] (`None` for all
/// when `detect.ground_band` is off). An object whose box is `W ∈ [W_min, W_max]` metres wide
/// (`classes.<name>.box_m`) and whose box bottom is `z` metres above the floor
/// (`classes.<name>.bottom_m`), at a forward distance `d` within `detect.range_m` (from
/// 0.7·near, for objects off to the side; both `W` and `far` widened by [`BAND_SIZE_SLACK`]),
/// is `f·W/Z(d)` pixels wide and has its box bottom on row `v(d, z)` of the calibrated
/// pinhole camera (`Z` = depth along the optical axis; Rivera & Andaluz Eq. 5 read backwards).
/// For every box width the band is the span of those rows, widened by [`BAND_SLACK`] of the
/// window height plus [`BAND_SLACK_PX`]; windows whose box bottom lies outside are not
/// scanned. Units: pixels, metres.
pub fn detect_bands(cfg: &Config) -> [Option<crate::detect::RowBand>; ObjectClass::COUNT] {
    if !cfg.detect.ground_band {
        return std::array::from_fn(|_| None);
    }
    let d = &cfg.detect;
    let cam = cfg.box_ranging().camera;
    let w_img = cfg.camera.width as usize;
    let band = |box_m: [f64; 2], z: f64| {
        // (lowest, highest) box-bottom row per box width; width up to twice the frame's.
        let n = 2 * w_img + 2;
        let mut rows = vec![(f64::INFINITY, f64::NEG_INFINITY); n];
        let (near, far) = (0.7 * d.range_m[0], BAND_SIZE_SLACK * d.range_m[1]);
        let box_m = [box_m[0] / BAND_SIZE_SLACK, box_m[1] * BAND_SIZE_SLACK];
        let steps = 2000;
        for k in 0..=steps {
            let dist = near * (far / near).powf(k as f64 / steps as f64);
            let (Some((_, v)), Some((ua, _)), Some((ub, _))) = (
                cam.project([dist, 0.0, z]),
                cam.project([dist, -0.5, z]),
                cam.project([dist, 0.5, z]),
            ) else {
                continue;
            };
            // Pixels per metre across at that depth.
            let ppm = (ua - ub).abs();
            let (w0, w1) = ((ppm * box_m[0]).floor() as usize, (ppm * box_m[1]).ceil() as usize);
            for e in rows.iter_mut().take(w1.min(n - 1) + 1).skip(w0) {
                *e = (e.0.min(v), e.1.max(v));
            }
        }
        let by_width = rows
            .iter()
            .map(|&(lo, hi)| {
                if lo > hi {
                    (1, 0)
                } else {
                    (lo.floor() as i32, hi.ceil() as i32)
                }
            })
            .collect();
        crate::detect::RowBand {
            by_width,
            slack: BAND_SLACK,
            slack_px: BAND_SLACK_PX,
        }
    };
    ObjectClass::ALL.map(|c| Some(band(cfg.classes[c].box_m, cfg.classes[c].bottom_m)))
}

/// The frame rows a [`Pipeline`] reads step by step ([`Pipeline::row_plan`]): the lane
/// warp's rows on every step, and the detection rows too on steps where detection runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RowPlan {
    /// Rows read on steps without detection (sorted, disjoint, half-open).
    pub lane: Vec<std::ops::Range<usize>>,
    /// Rows read on steps with detection (the lane's included).
    pub detect: Vec<std::ops::Range<usize>>,
    /// Detection runs on pipeline steps whose index is a multiple of this.
    pub every_n: u64,
    /// The pipeline's step index when the plan was made.
    pub next_index: u64,
}

impl RowPlan {
    /// The rows read on the `k`-th step after the plan was made (k = 0: the next one).
    pub fn rows(&self, k: u64) -> &[std::ops::Range<usize>] {
        if (self.next_index + k).is_multiple_of(self.every_n.max(1)) {
            &self.detect
        } else {
            &self.lane
        }
    }
}

/// Lane detection, detection, ranging, behaviour and control, with buffers allocated once.
#[derive(Debug, Clone)]
pub struct Pipeline {
    lane: LaneDetector,
    control: Controller,
    width: u32,
    height: u32,
    detect: Option<DetectStage>,
    ranging: BoxRanging,
    behaviour: Behaviour,
    dead: DeadReckoning,
    obstacle_lane_half_m: f64,
    /// `detect.shadow_tolerance`: obstacle boxes the floor's colour are dropped.
    shadow_tolerance: f64,
    time_s: f64,
    last_throttle: f64,
    objects: Vec<RangedObject>,
    detect_limits: [DetectLimits; ObjectClass::COUNT],
    /// The ground-plane band of each class ([`detect_bands`]).
    detect_bands: [Option<crate::detect::RowBand>; ObjectClass::COUNT],
    /// Frame rows detection reads (set with the detector).
    detect_rows: Vec<std::ops::Range<usize>>,
    tracker: Tracker<Cues>,
    measurements: Vec<Measurement<Cues>>,
    every_n: u64,
    frame_index: u64,
    /// Stereo ranging (`ranging.method = "stereo"`), used by [`Pipeline::step_stereo`].
    stereo: Option<crate::stereo::ranging::StereoRanging>,
    /// The junction rule and the route (`route.junctions`), after the lane measurement.
    junction: Option<crate::lane::junction::JunctionRule>,
    /// Lines across the lane in the bird's-eye image (`None` when the ROI's corners do not
    /// all see the floor).
    stop_line: Option<StopLineDetector>,
    stop_line_seen: Option<crate::lane::stop_line::StopLineSeen>,
}

/// A turn sign nearer than this (lens to sign, metres) decides the next fork: far enough to see
/// it before the car is at the fork, near enough not to take a sign at the fork after.
pub const TURN_SIGN_NEAR_M: f64 = 2.0;

/// Runs `a` and `b` side by side when `parallel` (on rayon's threads with feature
/// `parallel`, the caller waiting), else one after the other, and returns both results.
fn side_by_side<A: Send, B: Send>(
    parallel: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    #[cfg(feature = "parallel")]
    if parallel {
        return rayon::join(a, b);
    }
    let _ = parallel;
    (a(), b())
}

/// The stop-line detector of `cfg`'s `[camera]`, `[warp]` and `lane.lane_width_px`.
fn stop_line_detector(cfg: &Config) -> Option<StopLineDetector> {
    let cam = crate::camera::PinholeCamera::from(&cfg.camera);
    let h = crate::lane::warp::bird_to_floor(&cam, &cfg.warp.src, cfg.warp.out_width, cfg.warp.out_height)?;
    Some(StopLineDetector::new(h, cfg.lane.lane_width_px, Default::default()))
}

/// The stereo ranging of `cfg` (`ranging.method = "stereo"`): a calibrated pair when
/// `stereo.calibration` names a file (read here, once; its image size must be the camera's),
/// else an ideal pair of `[camera]` with `stereo.base_m`.
fn stereo_ranging(cfg: &Config) -> Result<Option<crate::stereo::ranging::StereoRanging>, PipelineError> {
    if cfg.ranging.method != crate::config::RangingMethod::Stereo {
        return Ok(None);
    }
    if cfg.stereo.calibration.is_empty() {
        return Ok(Some(cfg.stereo_ranging()));
    }
    let path = std::path::Path::new(&cfg.stereo.calibration);
    let st = crate::calib::file::CalibrationFile::load_stereo(path, cfg.camera.width, cfg.camera.height)?;
    Ok(Some(cfg.stereo_ranging_calibrated(&st)))
}

impl Pipeline {
    /// Builds the pipeline for `cfg` (precomputes the warp map), without a detector: see
    /// [`Pipeline::set_detector`] and [`load_detector`].
    pub fn new(cfg: &Config) -> Result<Self, PipelineError> {
        let ranging = cfg.box_ranging();
        let mut behaviour = Behaviour::new((&cfg.behaviour).into());
        behaviour.set_car(cfg.vehicle.wheelbase_m - cfg.vehicle.camera_x_m, (&cfg.vehicle).into());
        Ok(Self {
            lane: cfg.lane_detector()?,
            control: cfg.controller()?,
            width: cfg.camera.width,
            height: cfg.camera.height,
            detect: None,
            ranging,
            behaviour,
            dead: (&cfg.vehicle).into(),
            obstacle_lane_half_m: cfg.behaviour.obstacle_lane_half_m,
            shadow_tolerance: cfg.detect.shadow_tolerance,
            time_s: 0.0,
            last_throttle: 0.0,
            objects: Vec::with_capacity(16),
            detect_limits: detect_limits(cfg),
            detect_bands: detect_bands(cfg),
            detect_rows: Vec::new(),
            tracker: Tracker::new((&cfg.ranging).into(), ranging.camera),
            measurements: Vec::with_capacity(16),
            every_n: cfg.detect.every_n_frames.max(1) as u64,
            frame_index: 0,
            stereo: stereo_ranging(cfg)?,
            junction: cfg
                .route
                .rule_on()
                .then(|| crate::lane::junction::JunctionRule::new(cfg.route.steps.clone(), cfg.route.options())),
            stop_line: stop_line_detector(cfg),
            stop_line_seen: None,
        })
    }

    /// Installs (or removes) the detection stage, with the `[classes.<name>]` regions and size
    /// limits of each class ([`detect_limits`]).
    pub fn set_detector(&mut self, detect: Option<DetectStage>) {
        self.detect = detect;
        self.detect_rows.clear();
        if let Some(d) = &mut self.detect {
            for (l, b) in self.detect_limits.iter().zip(self.detect_bands.iter()) {
                d.set_limits(l.class.name(), Some(l.region), l.min_size, l.max_size);
                d.set_band(l.class.name(), b.clone());
            }
            self.detect_rows = d.rows_needed(self.width, self.height);
        }
    }

    /// A new region of interest and lane threshold from the next frame on (the dashboard's
    /// set-up page, between frames): the lane detector of `cfg`'s `[camera]`, `[warp]` and
    /// `[lane]`, and, when the steering method reads the warp (pure pursuit's bird's-eye →
    /// floor map), the steering method of `cfg` too (its state starts afresh). On an error
    /// nothing changes. A camera that renders only the rows the pipeline reads
    /// ([`Pipeline::row_plan`]) must be told again; the dashboard's runs render whole frames.
    pub fn set_lane_config(&mut self, cfg: &Config) -> Result<(), PipelineError> {
        let lane = cfg.lane_detector()?;
        if self.control.steering().method() == crate::control::steering::SteeringMethod::PurePursuit {
            let steering = cfg.steering_method()?;
            self.control.set_steering(steering);
        }
        self.lane = lane;
        self.stop_line = stop_line_detector(cfg);
        Ok(())
    }

    /// Installs (or removes) stereo ranging; [`Pipeline::new`] installs an ideal pair of
    /// `[camera]` when `ranging.method = "stereo"` (replace it to use a calibration's geometry).
    pub fn set_stereo(&mut self, stereo: Option<crate::stereo::ranging::StereoRanging>) {
        self.stereo = stereo;
    }

    /// The stereo ranging, if installed (its match counts).
    pub fn stereo(&self) -> Option<&crate::stereo::ranging::StereoRanging> {
        self.stereo.as_ref()
    }

    /// The stereo ranging, if installed, to adjust (e.g. where its reference lens sits).
    pub fn stereo_mut(&mut self) -> Option<&mut crate::stereo::ranging::StereoRanging> {
        self.stereo.as_mut()
    }

    /// Like [`Pipeline::step`] for a stereo pair: lane and detection on `reference` (the
    /// `[stereo] reference` camera), and with stereo ranging installed each detector box
    /// ranged by finding it in `other` (docs/stereo.md); a box without a match is ranged by
    /// the single camera. Without stereo ranging, `other` is ignored.
    pub fn step_stereo(
        &mut self,
        reference: &RgbImage,
        other: &RgbImage,
        dt_s: f64,
        timer: &mut dyn StageTimer,
    ) -> FrameOutput {
        self.step_inner(reference, Some(other), dt_s, timer, None)
    }

    /// Whether detection runs on the pipeline's step `frame_index` (counted from 0): every
    /// `detect.every_n_frames`-th step while a detector is installed.
    pub fn detects_on(&self, frame_index: u64) -> bool {
        self.detect.is_some() && frame_index.is_multiple_of(self.every_n)
    }

    /// The rows the pipeline will read on its next step (see [`Pipeline::rows_needed`]).
    pub fn rows_needed_next(&self) -> Vec<std::ops::Range<usize>> {
        self.rows_needed(self.frame_index)
    }

    /// The frame rows the pipeline reads on frame `frame_index`, as sorted, disjoint half-open
    /// ranges of row indices: the lane warp's source rows on every frame, and on frames where
    /// detection runs ([`Pipeline::detects_on`]) the rows of the detectors' pyramid levels and
    /// regions. A camera that renders (the simulator) may skip every other row: the output is
    /// the same as for the whole frame.
    pub fn rows_needed(&self, frame_index: u64) -> Vec<std::ops::Range<usize>> {
        let lane = self.lane.warp_map().src_rows();
        let lane = lane.start as usize..lane.end as usize;
        let mut spans = vec![lane];
        if self.detects_on(frame_index) {
            spans.extend(self.detect_rows.iter().cloned());
            // The shadow check (`refine::floor_coloured`) reads the floor strip under each box
            // of a class standing on the floor: up to a quarter of the box's height below it.
            if self.shadow_tolerance > 0.0 {
                let h = self.height as usize;
                let below = self.detect_limits.iter().filter(|l| l.class.info().not_floor_colour);
                if let Some(b) = below.map(|l| l.max_size.1 as usize / 4 + 2).max() {
                    spans.extend(self.detect_rows.iter().map(|r| r.end.min(h)..(r.end + b).min(h)));
                }
            }
            // The light reading looks inside boxes, which lie inside the regions; the colour
            // refinement of ranging (src/ranging/refine.rs) inside sign and light boxes grown
            // by `refine::GROW` of their height, so up to that share of the region beyond it.
            let h = self.height as i32;
            for l in &self.detect_limits {
                let info = l.class.info();
                let refined = self.ranging.refine && info.colour_cue != ColourCue::None;
                let grow = if refined {
                    (crate::ranging::refine::GROW * l.region.height as f64).ceil() as i32 + 1
                } else {
                    0
                };
                let (y0, y1) = (
                    (l.region.y - grow).clamp(0, h),
                    (l.region.y + l.region.height + grow).clamp(0, h),
                );
                if (info.reads_light || info.reads_arrow || refined) && y1 > y0 {
                    spans.push(y0 as usize..y1 as usize);
                }
            }
        }
        spans.sort_by_key(|r| r.start);
        let mut out: Vec<std::ops::Range<usize>> = Vec::with_capacity(spans.len());
        for r in spans.into_iter().filter(|r| !r.is_empty()) {
            match out.last_mut() {
                Some(l) if r.start <= l.end => l.end = l.end.max(r.end),
                _ => out.push(r),
            }
        }
        out
    }

    /// The rows the pipeline will read on each of its next steps, detached from the pipeline
    /// (for a camera that renders, e.g. the simulator's): [`RowPlan::rows`]`(k)` is
    /// [`Pipeline::rows_needed`] of the `k`-th step from now.
    pub fn row_plan(&self) -> RowPlan {
        let lane = self.lane.warp_map().src_rows();
        let lane = lane.start as usize..lane.end as usize;
        let lane = vec![lane];
        let detect = match &self.detect {
            // Frame index 0 always detects.
            Some(_) => self.rows_needed(0),
            None => lane.clone(),
        };
        RowPlan {
            lane,
            detect,
            every_n: self.every_n,
            next_index: self.frame_index,
        }
    }

    /// Whether a detector is installed.
    pub fn has_detector(&self) -> bool {
        self.detect.is_some()
    }

    /// Frame size the pipeline expects, pixels.
    pub fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Processes one frame taken `dt_s` seconds after the previous one, with the installed
    /// detector. A frame of another size is resized first (that allocates; sources should
    /// deliver the configured size).
    pub fn step(&mut self, image: &RgbImage, dt_s: f64, timer: &mut dyn StageTimer) -> FrameOutput {
        self.step_with(image, dt_s, timer, None)
    }

    /// Like [`Pipeline::step`], but with `given` boxes instead of the detector's when `Some`
    /// (the simulator's ground-truth switch).
    pub fn step_with(
        &mut self,
        image: &RgbImage,
        dt_s: f64,
        timer: &mut dyn StageTimer,
        given: Option<&[GivenBox]>,
    ) -> FrameOutput {
        self.step_inner(image, None, dt_s, timer, given)
    }

    fn step_inner(
        &mut self,
        image: &RgbImage,
        other: Option<&RgbImage>,
        dt_s: f64,
        timer: &mut dyn StageTimer,
        given: Option<&[GivenBox]>,
    ) -> FrameOutput {
        let mut stage_us = StageTimes::default();
        let resized;
        let frame = if image.dimensions() == (self.width, self.height) {
            image
        } else {
            resized = image::imageops::resize(image, self.width, self.height, image::imageops::FilterType::Triangle);
            &resized
        };
        timer.lap_us();
        // 1. Lane, and beside it (on another core with feature `parallel`) the detector on
        // detection frames: the two read the same frame and nothing of each other.
        let detect_now = given.is_some() || self.frame_index.is_multiple_of(self.every_n);
        self.frame_index += 1;
        let run_detector = given.is_none() && detect_now;
        let run_detector = run_detector && self.detect.is_some();
        let mut side = run_detector.then(|| timer.beside());
        let parallel = self.detect.as_ref().is_some_and(DetectStage::is_parallel);
        let (lane_stage, detector) = (&mut self.lane, &mut self.detect);
        let (lane, (found, found_us)) = side_by_side(
            parallel,
            || lane_stage.measure(frame, timer, &mut stage_us),
            || {
                let found = match detector {
                    Some(d) if run_detector => d.run_rgb(frame).ok(),
                    _ => None,
                };
                (found, side.as_mut().map_or(0, |t| t.lap_us()))
            },
        );
        // The wait for the slower of the two is neither's time.
        timer.lap_us();
        // 1b. At a junction, the line of the chosen way (src/lane/junction.rs).
        let (lane, junction) = match &mut self.junction {
            Some(rule) => {
                let im = self.lane.images();
                rule.step(&im.binary, &im.hist, im.band_rows, &self.lane.options().lines, lane, self.dead.odometry_m)
            }
            None => (lane, None),
        };
        let im = self.lane.images();
        self.stop_line_seen = self
            .stop_line
            .as_mut()
            .and_then(|d| d.find(&im.binary, &im.bird, &lane));
        // 2. Detections (on every n-th frame; given boxes on every frame), ranged.
        self.measure_objects(frame, other, given, found);
        self.track_objects(dt_s, detect_now);
        // 5. Behaviour.
        let obs = self.observations(lane.error.is_some());
        // A turn sign near decides the next fork (the junction rule reads it from the next frame).
        if let (Some(rule), Some((r, arrow))) = (&mut self.junction, obs.turn_sign) {
            if r.distance_m <= TURN_SIGN_NEAR_M {
                let way = match arrow {
                    crate::classes::TurnArrow::Left => crate::route::Step::Left,
                    crate::classes::TurnArrow::Right => crate::route::Step::Right,
                };
                rule.sign(way, obs.odometry_m, r.distance_m);
            }
        }
        let decision = self.behaviour.step(&obs, self.time_s);
        let detect_us = found_us.saturating_add(timer.lap_us());
        // 6. Control, then the behaviour's overrides.
        let input = SteeringInput {
            lane: &lane,
            lane_detector: &self.lane,
            frame,
        };
        let mut command = self.control.step(&input, dt_s);
        command = apply(command, &decision);
        if decision.steer.is_some() {
            // The lane error means nothing during a lane change: start afresh afterwards.
            self.control.steering_mut().reset();
        }
        self.last_throttle = command.throttle;
        stage_us.control_us = timer.lap_us();
        stage_us.sum();
        FrameOutput {
            lane,
            command,
            stage_us,
            detect_us,
            mode: decision.mode,
            observations: obs,
            junction,
        }
    }

    /// Step 2: this frame's measured objects (`given` boxes, or on detection frames the
    /// detector's boxes `found`, ranged by stereo when `other` is there, else by the tilt).
    fn measure_objects(
        &mut self,
        frame: &RgbImage,
        other: Option<&RgbImage>,
        given: Option<&[GivenBox]>,
        found: Option<Vec<crate::detect::stage::DetectedObject>>,
    ) {
        self.objects.clear();
        self.measurements.clear();
        match (given, found) {
            (Some(boxes), _) => {
                for b in boxes {
                    let r = self.ranging.range_outline(b.class, b.bbox);
                    let cues = (b.light, b.arrow);
                    push_measured(&mut self.measurements, &mut self.objects, b.class, b.bbox, r, cues);
                }
            }
            (None, Some(found)) => {
                // Stereo ranging needs the other image at the pipeline's size too;
                // only the rows of this frame's boxes are rectified and converted.
                let mut stereo = match (&mut self.stereo, other) {
                    (Some(st), Some(o)) if o.dimensions() == frame.dimensions() => {
                        let ranged = found.iter().filter(|d| ObjectClass::from_label(&d.label).is_some());
                        st.set_pair_for(frame, o, ranged.map(|d| d.rect));
                        Some(st)
                    }
                    _ => None,
                };
                for d in &found {
                    let Some(class) = ObjectClass::from_label(&d.label) else {
                        continue;
                    };
                    let r = d.rect;
                    let face = [r.x as f64 - 0.5, r.y as f64 - 0.5, (r.x + r.width) as f64 - 0.5, (r.y + r.height) as f64 - 0.5];
                    // A box without its class's face colour is the cascade's mistake.
                    if !crate::ranging::refine::shows_colour(frame, class, face) {
                        continue;
                    }
                    // An obstacle box the floor's colour is a shadow or a sun patch.
                    if crate::ranging::refine::floor_coloured(frame, class, face, self.shadow_tolerance) {
                        continue;
                    }
                    let bbox = [
                        r.x as f64 - 0.5,
                        r.y as f64 - 0.5,
                        (r.x + r.width) as f64 - 0.5,
                        (r.y + r.height) as f64 - 0.5,
                    ];
                    let light = d.light.as_ref().map(|l| light_color(l, frame, r));
                    let arrow = if class.info().reads_arrow {
                        crate::detect::arrow::read_arrow(frame, r)
                    } else {
                        None
                    };
                    let range = match stereo {
                        Some(ref mut st) => st.range(class, r),
                        None => None,
                    }
                    .or_else(|| self.ranging.range_in_image(frame, class, bbox));
                    let cues = (light, arrow);
                    push_measured(&mut self.measurements, &mut self.objects, class, bbox, range, cues);
                }
            }
            (None, None) => {}
        }
    }

    /// Steps 3 and 4: dead reckoning with the previous command, then the tracks (predicted by
    /// odometry, updated on detection frames) and the objects they report.
    fn track_objects(&mut self, dt_s: f64, detect_now: bool) {
        // 3. Dead reckoning: the previous command, held since the previous frame.
        let odometry_before = self.dead.odometry_m;
        if dt_s.is_finite() && dt_s > 0.0 {
            self.dead.advance(self.last_throttle, dt_s);
            self.time_s += dt_s;
        }
        // 4. Tracks: predicted by odometry, updated on detection frames; the objects reported.
        self.tracker.predict(dt_s, self.dead.odometry_m - odometry_before);
        if detect_now {
            self.tracker.update(&self.measurements);
        }
        for t in self.tracker.tracks() {
            if !(t.matched_now || (!detect_now && t.missed == 0 && t.hits >= 2)) {
                continue;
            }
            self.objects.push(RangedObject {
                class: t.class,
                bbox: t.bbox,
                distance_m: Some(t.distance_m),
                lateral_m: Some(t.lateral_m),
                light: t.extra.0,
                arrow: t.extra.1,
                distance_sigma_m: Some(t.sigma_m()),
                measured_m: t.matched_now.then_some(t.measured_m),
                track_id: Some(t.id),
                predicted: !t.matched_now,
            });
        }
    }

    /// The nearest object of each class (for obstacles, the nearest in the lane if any).
    fn observations(&self, lane_seen: bool) -> Observations {
        let mut o = Observations {
            lane_seen,
            speed_mps: self.dead.speed_mps,
            odometry_m: self.dead.odometry_m,
            stop_line: self.stop_line_seen,
            ..Default::default()
        };
        let nearer = |cur: Option<Ranged>, r: Ranged| match cur {
            Some(c) if c.distance_m <= r.distance_m => Some(c),
            _ => Some(r),
        };
        let mut obstacle_any = None;
        for ob in &self.objects {
            let (Some(d), Some(l)) = (ob.distance_m, ob.lateral_m) else {
                continue;
            };
            let r = Ranged {
                distance_m: d,
                lateral_m: l,
            };
            match ob.class.info().reaction {
                Reaction::StopThenGo => o.stop_sign = nearer(o.stop_sign, r),
                Reaction::WaitForGreen => {
                    if o.light.is_none_or(|(c, _)| c.distance_m > d) {
                        o.light = Some((r, ob.light.unwrap_or(LightColor::Unknown)));
                    }
                }
                Reaction::StopOrPass => {
                    if l.abs() <= self.obstacle_lane_half_m {
                        o.obstacle = nearer(o.obstacle, r);
                    }
                    obstacle_any = nearer(obstacle_any, r);
                }
                Reaction::Yield => o.yield_sign = nearer(o.yield_sign, r),
                Reaction::TakeTurn => {
                    if let (Some(a), true) = (ob.arrow, o.turn_sign.is_none_or(|(c, _)| c.distance_m > d)) {
                        o.turn_sign = Some((r, a));
                    }
                }
            }
        }
        if o.obstacle.is_none() {
            o.obstacle = obstacle_any;
        }
        o
    }

    /// What the motors were really sent for the last frame (the gate's answer): dead
    /// reckoning integrates this, so a parked, disarmed car is not "driving" at its wish.
    pub fn note_sent(&mut self, sent: Command) {
        self.last_throttle = sent.throttle;
    }

    /// The lane detector (its intermediate images, for annotation).
    pub fn lane(&self) -> &LaneDetector {
        &self.lane
    }

    /// The controller state.
    pub fn controller(&self) -> &Controller {
        &self.control
    }

    /// The controller, to change its parameters between frames (a dashboard, a lab); see
    /// [`crate::drive::Observer::before_frame`].
    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.control
    }

    /// The behaviour machine (its state and last transition).
    pub fn behaviour(&self) -> &Behaviour {
        &self.behaviour
    }

    /// The objects of the last frame, ranged.
    pub fn objects(&self) -> &[RangedObject] {
        &self.objects
    }

    /// The dead-reckoned speed and distance.
    pub fn dead_reckoning(&self) -> &DeadReckoning {
        &self.dead
    }

    /// The box ranging in use.
    pub fn ranging(&self) -> &BoxRanging {
        &self.ranging
    }
}

/// What is read inside a box and carried by its track: a light's colour, a turn sign's arrow.
type Cues = (Option<LightColor>, Option<TurnArrow>);

/// A ranged box goes to the tracker; one without a range (above the horizon) is reported as
/// it is, without a distance.
fn push_measured(
    meas: &mut Vec<Measurement<Cues>>,
    objects: &mut Vec<RangedObject>,
    class: ObjectClass,
    bbox: [f64; 4],
    range: Option<crate::ranging::BoxRange>,
    cues: Cues,
) {
    match range {
        Some(range) => meas.push(Measurement {
            class,
            bbox,
            range,
            extra: cues,
        }),
        None => objects.push(RangedObject {
            class,
            bbox,
            distance_m: None,
            lateral_m: None,
            light: cues.0,
            arrow: cues.1,
            distance_sigma_m: None,
            measured_m: None,
            track_id: None,
            predicted: false,
        }),
    }
}

/// The colour of a traffic light in box `r`: the hue of the most saturated bright pixel (the
/// lit lamp). `detect::light_state` takes the brightest spot, which in a trained cascade's
/// box that reaches past the housing can be the bright wall behind it (grey, so no hue; then
/// its position in the box decides, wrongly). Falls back to that reading when no pixel is
/// both bright (V ≥ 120) and saturated (S ≥ 0.4).
fn light_color(l: &LightReading, img: &RgbImage, r: crate::detect::Rect) -> LightColor {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let (x0, y0) = (r.x.clamp(0, w), r.y.clamp(0, h));
    let (x1, y1) = ((r.x + r.width).clamp(0, w), (r.y + r.height).clamp(0, h));
    // 1. The pixel with the largest V·S.
    let mut best = (0.0f32, [0u8; 3]);
    for y in y0..y1 {
        for x in x0..x1 {
            let p = img.get_pixel(x as u32, y as u32).0;
            let mx = p[0].max(p[1]).max(p[2]) as f32;
            let mn = p[0].min(p[1]).min(p[2]) as f32;
            if mx < 120.0 || (mx - mn) < 0.4 * mx {
                continue;
            }
            let score = mx * (mx - mn) / mx;
            if score > best.0 {
                best = (score, p);
            }
        }
    }
    if best.0 > 0.0 {
        // 2. Its hue, degrees.
        let [r, g, b] = best.1.map(|v| v as f32);
        let (mx, mn) = (r.max(g).max(b), r.min(g).min(b));
        let d = mx - mn;
        let hue = if mx == r {
            (60.0 * (g - b) / d).rem_euclid(360.0)
        } else if mx == g {
            60.0 * (b - r) / d + 120.0
        } else {
            60.0 * (r - g) / d + 240.0
        };
        return match hue {
            h if !(20.0..330.0).contains(&h) => LightColor::Red,
            h if h < 70.0 => LightColor::Amber,
            h if h < 200.0 => LightColor::Green,
            _ => LightColor::Unknown,
        };
    }
    match l.state {
        LightState::Red => LightColor::Red,
        LightState::Amber => LightColor::Amber,
        LightState::Green => LightColor::Green,
        LightState::Unknown => LightColor::Unknown,
    }
}

/// The lane controller's command with the behaviour's throttle and steering applied.
fn apply(cmd: Command, d: &Decision) -> Command {
    let throttle = d.throttle.unwrap_or(cmd.throttle).min(d.throttle_cap);
    let steer = d.steer.unwrap_or(cmd.steer);
    Command::clamped(steer, throttle)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `[colour_template]` thresholds that leave the model sign without red are an error naming
    /// the class and the section, not a panic (the options are the user's).
    #[test]
    fn colour_template_options_without_red_are_an_error() {
        let cfg = Config::default()
            .with_override("classes.stop_sign.detect=colour_template")
            .unwrap()
            .with_override("colour_template.sat_min=255")
            .unwrap();
        let err = load_detector(&cfg, Path::new(".")).expect_err("an error").to_string();
        assert!(err.contains("classes.stop_sign.detect") && err.contains("no red pixels"), "{err}");
    }

    /// `classes.stop_sign.detect = "colour_template"` loads the colour detector under the
    /// stop sign's label and reads no model file for it (a missing one is not an error); the
    /// other classes keep their cascades.
    #[test]
    fn the_colour_template_method_needs_no_model_file() {
        let mut cfg = Config::default()
            .with_override("classes.stop_sign.detect=colour_template")
            .unwrap()
            .with_override("classes.stop_sign.model=no/such.xml")
            .unwrap();
        for class in [
            ObjectClass::TrafficLight,
            ObjectClass::Obstacle,
            ObjectClass::YieldSign,
            ObjectClass::TurnSign,
        ] {
            cfg.classes[class].model.clear();
        }
        let (stage, missing) = load_detector(&cfg, Path::new(".")).unwrap();
        assert!(missing.is_empty(), "{missing:?}");
        let stage = stage.expect("a stage with the colour detector");
        assert_eq!(stage.labels().collect::<Vec<_>>(), ["stop_sign"]);
        // With the cascade method the same file is missing.
        cfg.classes[ObjectClass::StopSign].detect = DetectMethod::Cascade;
        let (stage, missing) = load_detector(&cfg, Path::new(".")).unwrap();
        assert!(stage.is_none());
        assert_eq!(missing.len(), 1);
        assert_eq!(missing[0].key, "classes.stop_sign.model");
    }
}
