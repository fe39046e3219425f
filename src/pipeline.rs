//! The one pipeline the car, replay and the simulator all run: frame → lane measurement →
//! command. Nothing in here knows which of the three is calling.

use crate::config::Config;
use crate::control::{Command, Controller};
use crate::lane::warp::WarpError;
use crate::lane::{LaneDetector, LaneMeasurement};
use crate::timing::{StageTimer, StageTimes};
use image::RgbImage;

/// Why a pipeline cannot be built from a configuration.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The ROI does not define a bird's-eye view.
    #[error("warp.src: {0}")]
    Warp(#[from] WarpError),
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
}

/// Lane detection + control, with all buffers allocated once.
#[derive(Debug, Clone)]
pub struct Pipeline {
    lane: LaneDetector,
    control: Controller,
    width: u32,
    height: u32,
}

impl Pipeline {
    /// Builds the pipeline for `cfg` (precomputes the warp map).
    pub fn new(cfg: &Config) -> Result<Self, PipelineError> {
        Ok(Self {
            lane: LaneDetector::from_config(cfg)?,
            control: Controller::from_config(cfg),
            width: cfg.camera.width,
            height: cfg.camera.height,
        })
    }

    /// Frame size the pipeline expects, pixels.
    pub fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Processes one frame taken `dt_s` seconds after the previous one. A frame of another
    /// size is resized first (that allocates; sources should deliver the configured size).
    pub fn step(&mut self, image: &RgbImage, dt_s: f64, timer: &mut dyn StageTimer) -> FrameOutput {
        let mut stage_us = StageTimes::default();
        let resized;
        let frame = if image.dimensions() == (self.width, self.height) {
            image
        } else {
            resized = image::imageops::resize(image, self.width, self.height, image::imageops::FilterType::Triangle);
            &resized
        };
        timer.lap_us();
        let lane = self.lane.measure(frame, timer, &mut stage_us);
        let command = self.control.step(&lane, dt_s);
        stage_us.control_us = timer.lap_us();
        stage_us.sum();
        FrameOutput {
            lane,
            command,
            stage_us,
        }
    }

    /// The lane detector (its intermediate images, for annotation).
    pub fn lane(&self) -> &LaneDetector {
        &self.lane
    }

    /// The controller state.
    pub fn controller(&self) -> &Controller {
        &self.control
    }
}
