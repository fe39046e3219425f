//! Telemetry: one JSON object per frame, one line each (`telemetry.jsonl`).
//!
//! The record is the contract between the pipeline and everything that reads its output:
//! golden tests, plots, the simulator's scoring and (later) the dashboard. Fields are only
//! ever added; optional ones are left out when empty.

use crate::control::behaviour::{Mode, Transition};
use crate::control::pilot::{DriveMode, Pilot};
use crate::control::Command;
use crate::lane::{LaneMeasurement, LaneStatus};
use crate::pipeline::{FrameOutput, Pipeline, RangedObject};
use crate::timing::StageTimes;
use serde::{Deserialize, Serialize};

/// One frame's record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number in the run (counting skipped frames).
    pub frame: u64,
    /// Source file name (replay) or a frame label.
    pub file: String,
    /// Time of the frame since the start of the run, seconds.
    pub time_s: f64,
    /// P_left, bird's-eye column of the left line, pixels.
    pub p_left: Option<f64>,
    /// P_right, bird's-eye column of the right line, pixels.
    pub p_right: Option<f64>,
    /// P_left was estimated from P_right.
    pub left_estimated: bool,
    /// P_right was estimated from P_left.
    pub right_estimated: bool,
    /// L_c, lane centre, pixels.
    pub lane_center: Option<f64>,
    /// L_F, car centre, pixels.
    pub frame_center: f64,
    /// L_c − L_F, pixels.
    pub error_px: Option<f64>,
    /// Normalised error, −1..1.
    pub error: Option<f64>,
    /// Which lines were seen.
    pub status: LaneStatus,
    /// Steering command, −1..1.
    pub steer: f64,
    /// Throttle command, −1..1.
    pub throttle: f64,
    /// Microseconds per stage.
    pub stage_us: StageTimes,
    /// Ground truth (simulator only): true offset, heading error, line columns, objects. Kept
    /// as JSON: telemetry does not know the simulator's types (`sim::truth::FrameTruth`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<serde_json::Value>,
    /// Behaviour state after this frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub behaviour: Option<Mode>,
    /// The behaviour transition made in this frame, with its reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transition: Option<Transition>,
    /// Detected (or, in the simulator's ground-truth mode, given) objects, ranged.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub objects: Vec<RangedObject>,
    /// Dead-reckoned speed, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_est_mps: Option<f64>,
    /// Dead-reckoned distance driven, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometry_m: Option<f64>,
    /// Detection + ranging + behaviour time, microseconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detect_us: Option<u32>,
    /// Capture → command sent, milliseconds, on the run's clock (0 without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_ms: Option<f64>,
    /// Time since the previous frame's command, milliseconds (the loop period).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub period_ms: Option<f64>,
    /// Frames the source produced that the loop never saw, so far (it takes the newest).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dropped: Option<u64>,
    /// The ultrasonic sensor's (median-filtered) distance, metres (the car's HC-SR04).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ultrasonic_m: Option<f64>,
    /// Events of the run at this frame: an operator's change (`kp=0.9 from dashboard`), a
    /// stall, the emergency brake. Explains a run afterwards.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<String>,
    /// What the gate really sent to the motors, when it differs from `steer`/`throttle` (the
    /// car disarmed, e-stopped, braking, or a fault): plots show this, not the wish.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sent: Option<Command>,
    /// Who drives: `manual`, `assisted` or `autopilot` (src/drive/manual.rs). Written once a
    /// human input is attached to the run (the dashboard); absent: the autopilot, and nobody
    /// could have taken over.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drive_mode: Option<DriveMode>,
    /// Who produced the command before the gate: `autopilot`, `human`, or `shared` (assisted:
    /// the pipeline's steering, the human's throttle). Written with `drive_mode`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pilot: Option<Pilot>,
    /// The human's input as used (after `manual.max_throttle`; neutral once released or older
    /// than `manual.input_timeout_ms`), in `manual` and `assisted`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub human: Option<Command>,
    /// How old the human's input was when the command went out, ms (real clocks only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_age_ms: Option<f64>,
    /// The car's status on a car run (waiting, disarmed, driving, fault…).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car: Option<crate::health::CarStatus>,
    /// A stereo pair's frame (`ranging.method = "stereo"` with two cameras): the other
    /// camera's frame, the skew and how many boxes were ranged by stereo.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stereo: Option<StereoRecord>,
    /// At a junction (`route.junctions`): `fork` or `merge`, the line kept, the way chosen
    /// and why (`route`, `sign`, `default`), the route step (src/lane/junction.rs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub junction: Option<crate::lane::junction::JunctionReport>,
    /// A stop or give-way line across the lane seen this frame: `distance_m` from the lens to
    /// its near edge, `dashed`, `row` (bird's-eye); absent when none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_line: Option<crate::lane::stop_line::StopLineSeen>,
}

/// The stereo part of a frame's record (src/drive/stereo.rs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StereoRecord {
    /// The other camera's frame (file name or label).
    pub other: String,
    /// Other camera's time minus the reference camera's, milliseconds.
    pub skew_ms: f64,
    /// Detector boxes of this frame ranged by stereo (found in the other image).
    pub ranged: u64,
    /// Detector boxes of this frame without a stereo match (ranged by the single camera).
    pub unmatched: u64,
    /// Frames dropped so far because they had no partner within `stereo.max_skew_ms`.
    pub pairs_dropped: u64,
    /// Whether the pair was rectified with `stereo.calibration` (false: taken as ideal).
    pub rectified: bool,
}

impl FrameRecord {
    /// The record of one processed frame.
    pub fn new(
        frame: u64,
        file: &str,
        time_s: f64,
        lane: &LaneMeasurement,
        cmd: &Command,
        stage_us: StageTimes,
    ) -> Self {
        Self {
            frame,
            file: file.to_string(),
            time_s,
            p_left: lane.p_left,
            p_right: lane.p_right,
            left_estimated: lane.left_estimated,
            right_estimated: lane.right_estimated,
            lane_center: lane.lane_center,
            frame_center: lane.frame_center,
            error_px: lane.error_px,
            error: lane.error,
            status: lane.status,
            steer: cmd.steer,
            throttle: cmd.throttle,
            stage_us,
            truth: None,
            behaviour: None,
            transition: None,
            objects: Vec::new(),
            speed_est_mps: None,
            odometry_m: None,
            detect_us: None,
            latency_ms: None,
            period_ms: None,
            dropped: None,
            ultrasonic_m: None,
            events: Vec::new(),
            sent: None,
            drive_mode: None,
            pilot: None,
            human: None,
            input_age_ms: None,
            car: None,
            stereo: None,
            junction: None,
            stop_line: None,
        }
    }

    /// Adds the behaviour, its transition, the ranged objects and the dead reckoning of the
    /// frame `out` that `pipeline` just produced.
    pub fn with_pipeline(mut self, out: &FrameOutput, pipeline: &Pipeline) -> Self {
        self.behaviour = Some(out.mode);
        self.transition = pipeline.behaviour().last_transition().cloned();
        self.objects = pipeline.objects().to_vec();
        self.speed_est_mps = Some(out.observations.speed_mps);
        self.odometry_m = Some(out.observations.odometry_m);
        self.detect_us = Some(out.detect_us);
        self.junction = out.junction;
        self.stop_line = out.observations.stop_line;
        self
    }

    /// The record as one JSON line (no newline).
    pub fn to_json_line(&self) -> String {
        serde_json::to_string(self).expect("records always serialise")
    }
}

/// Writes one record per processed frame as a JSON line, flushed after every line, so that an
/// interrupted or killed run keeps every frame it processed (each line complete).
pub struct JsonlWriter<W: std::io::Write> {
    out: W,
    /// What to call the output in errors (the file's path).
    label: String,
    lines: u64,
}

impl<W: std::io::Write> JsonlWriter<W> {
    /// Writes to `out`; errors name `label`.
    pub fn new(out: W, label: impl Into<String>) -> Self {
        Self {
            out,
            label: label.into(),
            lines: 0,
        }
    }

    /// Writes one record and flushes it.
    pub fn write(&mut self, rec: &FrameRecord) -> std::io::Result<()> {
        let mut line = rec.to_json_line();
        line.push('\n');
        self.out.write_all(line.as_bytes())?;
        self.out.flush()?;
        self.lines += 1;
        Ok(())
    }

    /// What errors call the output (the file's path).
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Lines written so far.
    pub fn lines(&self) -> u64 {
        self.lines
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}
