//! A camera pair as the drive loop's one frame source (issue 12): [`StereoFrames`] turns a
//! [`StereoSource`] (two sources paired by time, src/stereo/source.rs) into a [`FrameSource`]
//! whose frames are the reference camera's (`[stereo] reference`) carrying the other camera's
//! image in [`Frame::other`]; [`crate::drive::Driver`] then calls
//! [`crate::pipeline::Pipeline::step_stereo`] and writes the frame's [`StereoRecord`] (the
//! other frame, the pair's skew, boxes ranged by stereo, pairs dropped) to telemetry.
//!
//! Geometry in the loop: the reference camera is the car's camera of `[camera]` (on the
//! centre line, where lane keeping and mono ranging expect it); the other camera is mounted
//! `stereo.base_m` beside it (to its right when the reference is the left camera). Ranges
//! are D = b·f/d (Abdollahi's Eq. 12, src/stereo/ranging.rs), lateral offsets from the
//! reference lens. The pair is taken as rectified (an ideal pair of `[camera]`).
//! Units: seconds, metres.

use crate::config::Config;
use crate::pipeline::Pipeline;
use crate::source::{Frame, FrameError, FrameSource, OtherView};
use crate::stereo::StereoSource;
use crate::telemetry::StereoRecord;

/// A boxed source is a source (two cameras of different kinds in one pair).
impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        (**self).next_frame()
    }
    fn len_hint(&self) -> Option<usize> {
        (**self).len_hint()
    }
    fn fatal(&self) -> Option<String> {
        (**self).fatal()
    }
}

/// Two sources, left and right, as one source of reference frames carrying the other image.
pub struct StereoFrames<L, R> {
    pair: StereoSource<L, R>,
    reference_left: bool,
    len: Option<usize>,
}

impl<L: FrameSource, R: FrameSource> StereoFrames<L, R> {
    /// Pairs `left` and `right` by time (at most `max_skew_s` apart); the reference is the
    /// left camera when `reference_left`.
    pub fn new(left: L, right: R, max_skew_s: f64, reference_left: bool) -> Self {
        let len = match (left.len_hint(), right.len_hint()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            _ => None,
        };
        Self {
            pair: StereoSource::new(left, right, max_skew_s),
            reference_left,
            len,
        }
    }

    /// With `[stereo]`'s skew limit and reference.
    pub fn from_config(left: L, right: R, cfg: &Config) -> Self {
        Self::new(left, right, cfg.stereo.max_skew_ms / 1e3, cfg.stereo.reference.is_left())
    }

    /// Names the two sides in the errors of bad frames (e.g. the two folders of a replay).
    pub fn with_labels(mut self, left: impl Into<String>, right: impl Into<String>) -> Self {
        self.pair = self.pair.with_labels(left, right);
        self
    }

    /// Frames dropped so far because they had no partner within the skew.
    pub fn pairs_dropped(&self) -> u64 {
        self.pair.dropped()
    }
}

impl<L: FrameSource, R: FrameSource> FrameSource for StereoFrames<L, R> {
    fn fatal(&self) -> Option<String> {
        self.pair.fatal()
    }

    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        let p = match self.pair.next_pair()? {
            Ok(p) => p,
            Err(e) => return Some(Err(e)),
        };
        let dropped = self.pair.dropped();
        let (mut reference, other, skew_s) = if self.reference_left {
            (p.left, p.right, p.skew_s)
        } else {
            (p.right, p.left, -p.skew_s)
        };
        reference.other = Some(OtherView {
            image: other.image,
            name: other.name,
            skew_s,
            pairs_dropped: dropped,
        });
        Some(Ok(reference))
    }

    fn len_hint(&self) -> Option<usize> {
        self.len
    }
}

/// Sets the pipeline's stereo ranging (`ranging.method = "stereo"`: built by
/// [`Pipeline::new`], ideal or from `stereo.calibration`) up for the drive loop's pair: the
/// reference lens is on the car's centre line (see the module notes).
pub fn install(pipeline: &mut Pipeline) {
    if let Some(s) = pipeline.stereo_mut() {
        s.reference_lateral_m = 0.0;
    }
}

/// The line the commands print about the pair: how it is rectified (`stereo.calibration`,
/// applied to every pair) or that it is taken as ideal; `None` without stereo ranging.
pub fn calibration_line(pipeline: &Pipeline, cfg: &Config) -> Option<String> {
    let s = pipeline.stereo()?;
    let g = &s.geometry;
    Some(if s.rectified() {
        format!(
            "stereo: every pair rectified with {} (base {:.4} m, rectified focal length {:.1} px)",
            cfg.stereo.calibration, g.base_m, g.f
        )
    } else {
        format!(
            "stereo: the pair is taken as ideal and rectified (no stereo.calibration; base {} m)",
            g.base_m
        )
    })
}

/// The telemetry of a stereo frame: `before`/`after` are the pipeline's stereo match counts
/// (matched, unmatched) around the frame's step; `rectified` whether a calibration is applied.
pub fn record(o: &OtherView, before: Option<(u64, u64)>, after: Option<(u64, u64)>, rectified: bool) -> StereoRecord {
    let (ranged, unmatched) = match (before, after) {
        (Some(b), Some(a)) => (a.0.saturating_sub(b.0), a.1.saturating_sub(b.1)),
        _ => (0, 0),
    };
    StereoRecord {
        other: o.name.clone(),
        skew_ms: o.skew_s * 1e3,
        ranged,
        unmatched,
        pairs_dropped: o.pairs_dropped,
        rectified,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pair's line says whether a calibration is applied; nothing without stereo.
    #[test]
    fn the_pair_is_described() {
        let mut cfg = crate::config::Config::default();
        assert_eq!(calibration_line(&Pipeline::new(&cfg).unwrap(), &cfg), None);
        cfg.ranging.method = crate::config::RangingMethod::Stereo;
        let line = calibration_line(&Pipeline::new(&cfg).unwrap(), &cfg).unwrap();
        assert!(line.contains("taken as ideal"), "{line}");
        cfg.stereo.calibration = "/nowhere/pair.json".into();
        let e = Pipeline::new(&cfg).err().unwrap().to_string();
        assert!(e.starts_with("stereo.calibration: /nowhere/pair.json"), "{e}");
    }

    struct Times(Vec<f64>, usize, u8);

    impl FrameSource for Times {
        fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
            let t = *self.0.get(self.1)?;
            self.1 += 1;
            let img = image::RgbImage::from_pixel(2, 2, image::Rgb([self.2; 3]));
            Some(Ok(Frame::new(self.1 as u64 - 1, t, format!("{}{t}", self.2), img)))
        }
    }

    #[test]
    fn the_reference_frame_carries_the_other_image_skew_and_drops() {
        let left = Times(vec![0.0, 0.033, 0.066, 0.100], 0, 1);
        let right = Times(vec![0.004, 0.037, 0.104], 0, 2);
        for reference_left in [true, false] {
            let mut s = StereoFrames::new(
                Times(left.0.clone(), 0, 1),
                Times(right.0.clone(), 0, 2),
                0.010,
                reference_left,
            );
            assert_eq!(s.len_hint(), None);
            let mut got = vec![];
            while let Some(f) = s.next_frame() {
                let f = f.unwrap();
                let o = f.other.unwrap();
                got.push((f.image[(0, 0)][0], o.image[(0, 0)][0], o.skew_s, o.pairs_dropped));
            }
            assert_eq!(got.len(), 3);
            let (r, x) = if reference_left { (1, 2) } else { (2, 1) };
            let sign = if reference_left { 1.0 } else { -1.0 };
            assert!(got.iter().all(|g| g.0 == r && g.1 == x));
            assert!((got[0].2 - sign * 0.004).abs() < 1e-12, "{got:?}");
            // left 0.066 had no partner
            assert_eq!(got[2].3, 1);
        }
    }
}
