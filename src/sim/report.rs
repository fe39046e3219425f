//! What a simulator run keeps while the loop runs: the behaviour transitions as lines, the
//! plots' series (time, cross-track error, steering, path), the camera frames as PNG (for
//! `rccar replay`; the pair's other camera into a second folder), the stereo tally, and a
//! sideways kick at a given time for step-response experiments. After the run: the step
//! response's lines and figures ([`RunReport::step_summary`]), the plots in the run folder
//! ([`RunReport::write_plots`]) and where the frames went ([`RunReport::frames_line`]).

use super::plot::{self, PlotError, Series};
use super::scene::Scene;
use super::step::{step_metrics, StepError, StepMetrics, StepOptions, StepRequest};
use super::world::{lock, SharedWorld};
use crate::drive::{Flow, FrameContext, Level, LoopError, Observer, Say};
use crate::run_dir::{RunDir, RunDirError};
use std::path::PathBuf;

/// Stereo frames and boxes of a run.
#[derive(Debug, Default, Clone, Copy)]
pub struct StereoTally {
    /// Pairs processed.
    pub pairs: u64,
    /// Detector boxes ranged by stereo.
    pub ranged: u64,
    /// Detector boxes without a stereo match.
    pub unmatched: u64,
}

impl StereoTally {
    /// The end-of-run line of a stereo run.
    pub fn line(&self) -> String {
        format!(
            "  stereo: {} pairs, detector boxes ranged by stereo {}, without a match {}",
            self.pairs, self.ranged, self.unmatched
        )
    }
}

/// The plots a run wrote ([`RunReport::write_plots`]).
#[derive(Debug, Clone)]
pub struct RunPlots {
    /// Cross-track error and steering against time (xte_steer.png).
    pub time: PathBuf,
    /// The path driven over the track (path.png).
    pub path: PathBuf,
    /// The step response (step.png), when one was measured.
    pub step: Option<PathBuf>,
}

/// A plot that could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum WritePlotError {
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// Writing into the run folder failed.
    #[error(transparent)]
    Write(#[from] RunDirError),
}

/// The run's report (see the module notes).
pub struct RunReport {
    world: SharedWorld,
    /// The (left) camera's frames as PNG.
    pub record: Option<PathBuf>,
    /// A stereo pair's right camera's frames as PNG.
    pub record_right: Option<PathBuf>,
    /// `stereo.reference = "left"`: the reference camera's frame is the left one.
    pub reference_left: bool,
    /// The stereo tally.
    pub stereo: StereoTally,
    /// The plots' series.
    pub series: Series,
    /// `(T seconds, DY metres)`: the kick, done once.
    pub kick: Option<(f64, f64)>,
    /// Time of the frame after which the kick was applied, seconds.
    pub kicked_at: Option<f64>,
    say: Say,
}

impl RunReport {
    /// The step response `st` asked for: `None` when the run ended before the kick.
    pub fn step_response(&self, st: &StepRequest) -> Option<Result<StepMetrics, StepError>> {
        // After a kick the first frame that sees it is the one after the kick's frame.
        let t0 = if st.kick { self.kicked_at.map(|t| t + 1e-6) } else { Some(0.0) };
        t0.map(|t0| step_metrics(&self.series.t, &self.series.xte, t0, &StepOptions::default()))
    }

    /// The step response `st` asked for, as the lines to print and the figures for
    /// summary.json's `"step"`; no figures when none could be taken (the line says why).
    pub fn step_summary(&self, st: &StepRequest) -> (Vec<String>, Option<StepMetrics>) {
        match self.step_response(st) {
            Some(Ok(m)) => (m.lines(), Some(m)),
            Some(Err(e)) => (vec![format!("  step response: {e}")], None),
            None => (vec![format!("  step response: the run ended before the kick at t = {} s", st.t)], None),
        }
    }

    /// Draws the run's plots into `run` (the font registered with [`plot::register_font`]):
    /// xte_steer.png (lane width `lane_width_m`), path.png over `scene`, and step.png with
    /// the step response `step`.
    pub fn write_plots(
        &self,
        run: &mut RunDir,
        lane_width_m: f64,
        scene: &Scene,
        step: Option<&StepMetrics>,
    ) -> Result<RunPlots, WritePlotError> {
        let time = run.write_png("xte_steer.png", &plot::time_plot(&self.series, lane_width_m)?)?;
        let path = run.write_png("path.png", &plot::path_plot(&self.series, scene)?)?;
        let step = match step {
            Some(m) => Some(run.write_png("step.png", &plot::step_plot(&self.series.t, &self.series.xte, m)?)?),
            None => None,
        };
        Ok(RunPlots { time, path, step })
    }

    /// Where the recorded frames went and how to replay them (`None`: not recorded).
    pub fn frames_line(&self, frames: u64) -> Option<String> {
        match (&self.record, &self.record_right) {
            (Some(dir), Some(right)) => Some(format!(
                "  frames:    {}/ and {}/ ({} PNG each; replay with `rccar replay {} --right {} --set ranging.method=stereo`)",
                dir.display(),
                right.display(),
                frames,
                dir.display(),
                right.display()
            )),
            (Some(dir), None) => Some(format!(
                "  frames:    {}/ ({} PNG; replay with `rccar replay {}`)",
                dir.display(),
                frames,
                dir.display()
            )),
            _ => None,
        }
    }

    /// A report of `world`'s run; lines (transitions, the kick) go to `say`.
    pub fn new(world: SharedWorld, say: Say) -> Self {
        Self {
            world,
            record: None,
            record_right: None,
            reference_left: true,
            stereo: StereoTally::default(),
            series: Series::default(),
            kick: None,
            kicked_at: None,
            say,
        }
    }

    fn save_frames(&self, ctx: &FrameContext<'_>) -> Result<(), LoopError> {
        // With a pair, the reference camera's image goes to its side's folder.
        let other = ctx.frame.other.as_ref().map(|o| &o.image);
        let (left, right) = match other {
            Some(o) if !self.reference_left => (o, Some(&ctx.frame.image)),
            o => (&ctx.frame.image, o),
        };
        for (dir, img) in [(&self.record, Some(left)), (&self.record_right, right)] {
            if let (Some(dir), Some(img)) = (dir, img) {
                let p = dir.join(&ctx.frame.name);
                img.save(&p)
                    .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", p.display())))?;
            }
        }
        Ok(())
    }
}

impl Observer for RunReport {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        self.save_frames(ctx)?;
        if let Some(s) = &ctx.record.stereo {
            self.stereo.pairs += 1;
            self.stereo.ranged += s.ranged;
            self.stereo.unmatched += s.unmatched;
        }
        if let Some(tr) = &ctx.record.transition {
            (self.say)(
                Level::Info,
                &format!("  t={:7.2} s  {} -> {}: {}", ctx.record.time_s, tr.from.name(), tr.to.name(), tr.reason),
            );
        }
        let mut w = lock(&self.world);
        if let Some(truth) = w.last_truth() {
            self.series.push_parts(ctx.frame.time_s, truth, ctx.output.command.steer);
        }
        if let Some((t, dy)) = self.kick {
            if self.kicked_at.is_none() && ctx.frame.time_s + 1e-9 >= t {
                w.kick(dy, 0.0);
                self.kicked_at = Some(ctx.frame.time_s);
                (self.say)(Level::Info, &format!("  t={:7.2} s  kicked {:+.3} m sideways", ctx.frame.time_s, dy));
            }
        }
        Ok(Flow::Continue)
    }
}
