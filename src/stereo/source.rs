//! Two frame sources as one stereo source: frames are paired by their timestamps (`time_s`)
//! and the pair's skew is reported. Any two [`FrameSource`]s work: two V4L2 cameras
//! (`camera_source::CameraSource`, feature `camera`), two recorded folders
//! (`source::ReplayDir`), or two simulator cameras.
//!
//! Pairing: take the next frame of each side; while they are more than `max_skew_s` apart,
//! drop the older one (counted in [`StereoSource::dropped`]) and take that side's next frame.
//! A frame one side cannot deliver is passed on as that frame's error, so the caller can name
//! it, count it and go on; its name is prefixed by the side's label (`left/`, `right/` or the
//! folder given to [`StereoSource::with_labels`]). Units: seconds.

use crate::source::{Frame, FrameError, FrameSource};

/// A left and a right frame taken at (about) the same time.
#[derive(Debug, Clone)]
pub struct StereoFrame {
    /// The left camera's frame.
    pub left: Frame,
    /// The right camera's frame.
    pub right: Frame,
    /// Right time minus left time, seconds.
    pub skew_s: f64,
}

/// Pairs the frames of two sources by time.
#[derive(Debug)]
pub struct StereoSource<L, R> {
    left: L,
    right: R,
    max_skew_s: f64,
    dropped: u64,
    labels: [String; 2],
}

impl<L: FrameSource, R: FrameSource> StereoSource<L, R> {
    /// Pairs `left` and `right`, accepting frames at most `max_skew_s` apart.
    pub fn new(left: L, right: R, max_skew_s: f64) -> Self {
        Self {
            left,
            right,
            max_skew_s,
            dropped: 0,
            labels: ["left".into(), "right".into()],
        }
    }

    /// Names the two sides in the errors passed on (`LABEL/frame name`; default `left` and
    /// `right`), e.g. the two folders of a replay, so a bad frame is named with its camera.
    pub fn with_labels(mut self, left: impl Into<String>, right: impl Into<String>) -> Self {
        self.labels = [left.into(), right.into()];
        self
    }

    fn named(&self, side: usize, mut e: FrameError) -> FrameError {
        e.name = format!("{}/{}", self.labels[side], e.name);
        e
    }

    /// Frames dropped so far because they had no partner within the skew.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Why either side cannot be used at all (see [`FrameSource::fatal`]).
    pub fn fatal(&self) -> Option<String> {
        self.left.fatal().map(|e| format!("{}: {e}", self.labels[0])).or_else(|| {
            self.right.fatal().map(|e| format!("{}: {e}", self.labels[1]))
        })
    }

    /// The next pair, an error for one unusable frame, or `None` when either side ends.
    pub fn next_pair(&mut self) -> Option<Result<StereoFrame, FrameError>> {
        let mut l = match self.left.next_frame()? {
            Ok(f) => f,
            Err(e) => return Some(Err(self.named(0, e))),
        };
        let mut r = match self.right.next_frame()? {
            Ok(f) => f,
            Err(e) => return Some(Err(self.named(1, e))),
        };
        loop {
            let skew = r.time_s - l.time_s;
            if skew.abs() <= self.max_skew_s {
                return Some(Ok(StereoFrame {
                    left: l,
                    right: r,
                    skew_s: skew,
                }));
            }
            self.dropped += 1;
            if skew > 0.0 {
                l = match self.left.next_frame()? {
                    Ok(f) => f,
                    Err(e) => return Some(Err(self.named(0, e))),
                };
            } else {
                r = match self.right.next_frame()? {
                    Ok(f) => f,
                    Err(e) => return Some(Err(self.named(1, e))),
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Times(Vec<f64>, usize);

    impl FrameSource for Times {
        fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
            let t = *self.0.get(self.1)?;
            self.1 += 1;
            Some(if t < 0.0 {
                Err(FrameError::bad(self.1 as u64 - 1, "bad", "unreadable"))
            } else {
                Ok(Frame::new(self.1 as u64 - 1, t, format!("{t}"), image::RgbImage::new(1, 1)))
            })
        }
    }

    #[test]
    fn pairs_by_time_drops_the_unpaired_and_passes_errors_on() {
        // The right camera starts 4 ms late and misses the frame at 0.066 s.
        let left = Times(vec![0.0, 0.033, 0.066, 0.100, -1.0, 0.166], 0);
        let right = Times(vec![0.004, 0.037, 0.104, 0.137, 0.170], 0);
        let mut s = StereoSource::new(left, right, 0.010);
        let mut got = vec![];
        while let Some(p) = s.next_pair() {
            match p {
                Ok(p) => got.push((p.left.time_s, p.right.time_s, p.skew_s)),
                Err(e) => got.push((-1.0, -1.0, e.index as f64)),
            }
        }
        assert_eq!(got.len(), 5, "{got:?}");
        assert_eq!((got[0].0, got[0].1), (0.0, 0.004));
        assert!((got[0].2 - 0.004).abs() < 1e-12);
        assert_eq!((got[1].0, got[1].1), (0.033, 0.037));
        // 0.066 had no partner: dropped; 0.100 pairs with 0.104.
        assert_eq!((got[2].0, got[2].1), (0.100, 0.104));
        // The unreadable left frame is passed on as an error; its partner (right 0.137) is
        // then dropped as unpaired.
        assert_eq!(got[3].0, -1.0);
        assert_eq!((got[4].0, got[4].1), (0.166, 0.170));
        assert_eq!(s.dropped(), 2);
    }
}
