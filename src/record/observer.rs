//! A recording as a part of the drive loop: every processed frame (JPEG) and its telemetry
//! line go into the [`Recorder`] (and, for a camera pair, the other camera's frame into a
//! second one under the same name). A failed write is counted and reported once, never the
//! end of the run: the car must not stop because a USB stick is full.

use super::{RecordError, RecordStats, Recorder};
use crate::drive::{Arming, Flow, FrameContext, LoopError, Observer};
use std::sync::Arc;

/// Keeps each frame and its telemetry line (see the module notes).
pub struct RecordObserver {
    rec: Recorder,
    /// The other camera of a pair: its frames under the reference frame's index (the same
    /// names) and the same telemetry lines.
    right: Option<Recorder>,
    /// The first write error, kept for the caller to report once.
    failed: Option<String>,
    warned: bool,
    /// The record switch (page, pad): frames are kept only while it is on.
    switch: Option<Arc<Arming>>,
}

/// What a finished recording wrote.
#[derive(Debug)]
pub struct Recorded {
    /// The recording's folder and what it holds.
    pub main: (std::path::PathBuf, Result<RecordStats, RecordError>),
    /// The other camera's folder, for a pair.
    pub right: Option<(std::path::PathBuf, Result<RecordStats, RecordError>)>,
}

impl RecordObserver {
    /// Records into `rec` (and `right` for the other camera of a pair).
    pub fn new(rec: Recorder, right: Option<Recorder>) -> Self {
        Self {
            rec,
            right,
            failed: None,
            warned: false,
            switch: None,
        }
    }

    /// Keeps frames only while `arming`'s record switch is on (the page's and the pad's
    /// toggle); the switch is made available and on, and told what was recorded.
    pub fn switched_by(mut self, arming: Arc<Arming>) -> Self {
        arming.controls().record().make_available();
        self.switch = Some(arming);
        self
    }

    /// The first write error, once (for a warning line); later calls return `None`.
    pub fn take_warning(&mut self) -> Option<String> {
        if self.warned {
            return None;
        }
        let w = self.failed.clone()?;
        self.warned = true;
        Some(format!("recording: {w} (counted; the run goes on)"))
    }

    /// Closes the recordings (index and telemetry flushed).
    pub fn finish(self) -> Recorded {
        let dir = self.rec.dir().to_path_buf();
        Recorded {
            main: (dir, self.rec.finish()),
            right: self.right.map(|r| (r.dir().to_path_buf(), r.finish())),
        }
    }
}

impl Observer for RecordObserver {
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        if self.switch.as_ref().is_some_and(|a| !a.controls().record().is_on()) {
            return Ok(Flow::Continue); // paused from the page or the pad
        }
        let line = ctx.record.to_json_line();
        let a = self.rec.write_frame(ctx.frame.index, &ctx.frame.image);
        let b = self.rec.write_telemetry_line(&line);
        let c = match (&mut self.right, &ctx.frame.other) {
            (Some(r), Some(o)) => r.write_frame(ctx.frame.index, &o.image).and(r.write_telemetry_line(&line)),
            _ => Ok(()),
        };
        if let Err(e) = a.and(b).and(c) {
            self.failed.get_or_insert_with(|| e.to_string());
        }
        if let Some(a) = &self.switch {
            let st = self.rec.stats();
            a.controls()
                .record()
                .report(st.frames_written.saturating_sub(st.frames_deleted), self.rec.bytes_left());
        }
        Ok(Flow::Continue)
    }
}
