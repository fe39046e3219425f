//! What a simulator run keeps while the loop runs: the behaviour transitions as lines, the
//! plots' series (time, cross-track error, steering, path), the camera frames as PNG (for
//! `rccar replay`; the pair's other camera into a second folder), the stereo tally, and a
//! sideways kick at a given time for step-response experiments.

use super::plot::Series;
use super::step::{step_metrics, StepError, StepMetrics, StepOptions, StepRequest};
use super::world::{lock, SharedWorld};
use crate::drive::{Flow, FrameContext, Level, LoopError, Observer, Say};
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
