//! What `rccar replay` keeps of a run besides the telemetry: the lane's status counts, the
//! mean lane error, the pipeline's time per frame, the stereo figures, the frames skipped,
//! and (when asked) each frame annotated, written into a folder of the run (a writer).

use crate::annotate::annotate;
use crate::drive::{Flow, FrameContext, LoopError, Observer};
use crate::lane::LaneStatus;
use crate::source::FrameError;
use crate::telemetry::FrameRecord;
use std::path::PathBuf;

/// The replay's tally; an observer of the run.
#[derive(Debug, Default)]
pub struct ReplayTally {
    /// Frames processed.
    pub frames: u64,
    /// Frames that could not be used, as said.
    pub skipped: Vec<String>,
    /// Frames per lane status (both, left only, right only, lost).
    pub status: [u64; 4],
    /// Sum of |lane error| over the frames, pixels.
    pub abs_err_sum: f64,
    /// The pipeline's time of every frame, microseconds.
    pub total_us: Vec<u32>,
    /// Stereo pairs, boxes ranged by stereo, without a match, largest |skew| ms, pairs dropped.
    pub stereo: (u64, u64, u64, f64, u64),
    annotate_dir: Option<PathBuf>,
    warp_src: [[f64; 2]; 4],
}

impl ReplayTally {
    /// A tally; with `annotate_dir`, each frame is written there annotated (the ROI drawn
    /// from `warp_src`, `warp.src` of the configuration).
    pub fn new(annotate_dir: Option<PathBuf>, warp_src: [[f64; 2]; 4]) -> ReplayTally {
        ReplayTally {
            annotate_dir,
            warp_src,
            ..Default::default()
        }
    }

    /// The summary's lines: status counts, mean error, times (with `timing`), stereo
    /// figures (with `stereo`) and the skipped frames.
    pub fn lines(&self, timing: bool, stereo: bool) -> Vec<String> {
        let s = &self.status;
        let mut out = vec![format!(
            "  lane: both lines {}, left only {}, right only {}, lost {}",
            s[0], s[1], s[2], s[3]
        )];
        let seen = s[LaneStatus::Both as usize] + s[LaneStatus::LeftOnly as usize] + s[LaneStatus::RightOnly as usize];
        if seen > 0 {
            out.push(format!(
                "  mean |error| {:.2} px over {} frames with a lane",
                self.abs_err_sum / seen as f64,
                seen
            ));
        }
        if timing && !self.total_us.is_empty() {
            let mut t = self.total_us.clone();
            t.sort_unstable();
            out.push(format!(
                "  pipeline time per frame: median {} us, max {} us (incl. first-frame warm-up)",
                t[t.len() / 2],
                t[t.len() - 1]
            ));
        }
        if stereo {
            let (pairs, ranged, unmatched, skew, dropped) = self.stereo;
            out.push(format!(
                "  stereo: {pairs} pairs (largest skew {skew:.1} ms, {dropped} frame(s) dropped without a partner); detector boxes ranged by stereo {ranged}, without a match {unmatched}"
            ));
        }
        out.push(format!("  skipped {} frame(s)", self.skipped.len()));
        out.extend(self.skipped.iter().map(|k| format!("    {k}")));
        out
    }
}

impl Observer for ReplayTally {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let out = ctx.output;
        self.frames += 1;
        self.status[out.lane.status as usize] += 1;
        self.abs_err_sum += out.lane.error_px.map_or(0.0, f64::abs);
        self.total_us.push(out.stage_us.total_us);
        if let Some(dir) = &self.annotate_dir {
            let mut img = annotate(
                &ctx.frame.image,
                &self.warp_src,
                ctx.pipeline.lane().warp_map().homography(),
                ctx.pipeline.lane().images(),
                &out.lane,
                &out.command,
            );
            if let Some(j) = &out.junction {
                crate::annotate::junction(&mut img, j);
            }
            if let Some(seen) = &out.observations.stop_line {
                let (h, w) = (
                    ctx.pipeline.lane().warp_map().homography(),
                    ctx.pipeline.lane().images().bird.width(),
                );
                crate::annotate::draw_stop_line(&mut img, h, w, seen);
            }
            let p = dir.join(crate::source::output_name(&ctx.frame.name));
            img.save(&p)
                .map_err(|e| LoopError::Observer(format!("{}: cannot write: {e}", p.display())))?;
        }
        Ok(Flow::Continue)
    }

    fn decorate(&mut self, record: &mut FrameRecord) {
        if let Some(st) = &record.stereo {
            self.stereo.0 += 1;
            self.stereo.1 += st.ranged;
            self.stereo.2 += st.unmatched;
            self.stereo.3 = self.stereo.3.max(st.skew_ms.abs());
            self.stereo.4 = st.pairs_dropped;
        }
    }

    fn on_skip(&mut self, e: &FrameError) {
        self.skipped.push(e.to_string());
    }
}
