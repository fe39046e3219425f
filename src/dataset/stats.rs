//! Label counts of a dataset: how many frames, how long, who drove, the steering and throttle
//! histograms, and warnings when the labels are so unbalanced that a pilot trained on them
//! learns the imbalance (AutoRCCar's pilots that "only go right", hamuchiwa/AutoRCCar #187).
//!
//! Thresholds (a frame is *straight* when −[`STRAIGHT`] ≤ steer < [`STRAIGHT`], the histogram's
//! middle bin; *stopped* when throttle ≤ [`STOPPED`]):
//! - one side: of the turning frames, more than [`ONE_SIDE`] steer the same way;
//! - straight: more than [`MOSTLY_STRAIGHT`] of all frames are straight;
//! - stopped: more than [`MOSTLY_STOPPED`] of all frames have the car stopped.

use super::Sample;
use crate::control::pilot::DriveMode;
use serde::Serialize;

/// |steer| below this counts as straight.
pub const STRAIGHT: f64 = 0.05;
/// Throttle at or below this counts as stopped.
pub const STOPPED: f64 = 0.01;
/// Warn when more than this share of the turning frames turn one way.
pub const ONE_SIDE: f64 = 0.8;
/// Warn when more than this share of the frames are straight.
pub const MOSTLY_STRAIGHT: f64 = 0.7;
/// Warn when more than this share of the frames have the car stopped.
pub const MOSTLY_STOPPED: f64 = 0.25;
/// Histogram bins over −1..1: 0.2 wide, but the middle one is the straight band
/// −STRAIGHT..STRAIGHT, so the histogram shows the straight frames apart (1.0 falls in the last).
pub const BINS: usize = 11;
/// The bins' edges, from −1 to 1.
pub const EDGES: [f64; BINS + 1] = [
    -1.0, -0.8, -0.6, -0.4, -0.2, -STRAIGHT, STRAIGHT, 0.2, 0.4, 0.6, 0.8, 1.0,
];

/// Counts of one dataset's labels.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LabelStats {
    /// Samples.
    pub frames: usize,
    /// First frame number, last frame number.
    pub frame_span: Option<(u64, u64)>,
    /// Last time minus first time, seconds.
    pub duration_s: f64,
    /// Frames per driving mode (manual, assisted, autopilot), in that order.
    pub modes: Vec<(String, usize)>,
    /// Frames steering left (steer < −STRAIGHT), straight, right (steer ≥ STRAIGHT).
    pub steer_left_straight_right: [usize; 3],
    /// Frames with the car stopped (throttle ≤ STOPPED).
    pub stopped: usize,
    /// Steering histogram: bin k counts EDGES\[k\] ≤ steer < EDGES\[k+1\].
    pub steer_hist: [usize; BINS],
    /// Throttle histogram, the same bins.
    pub throttle_hist: [usize; BINS],
    /// Mean steer, mean throttle.
    pub mean: (f64, f64),
    /// Balance warnings, one sentence each (empty: balanced by these rules).
    pub warnings: Vec<String>,
}

fn bin(x: f64) -> usize {
    EDGES[1..BINS].iter().take_while(|&&e| x >= e).count()
}

fn pct(a: usize, b: usize) -> f64 {
    if b == 0 {
        0.0
    } else {
        100.0 * a as f64 / b as f64
    }
}

impl LabelStats {
    /// Counts `samples`.
    pub fn of(samples: &[Sample]) -> LabelStats {
        let n = samples.len();
        let mut s = LabelStats {
            frames: n,
            frame_span: samples.first().zip(samples.last()).map(|(a, b)| (a.frame, b.frame)),
            duration_s: samples
                .first()
                .zip(samples.last())
                .map_or(0.0, |(a, b)| b.time_s - a.time_s),
            modes: Vec::new(),
            steer_left_straight_right: [0; 3],
            stopped: 0,
            steer_hist: [0; BINS],
            throttle_hist: [0; BINS],
            mean: (0.0, 0.0),
            warnings: Vec::new(),
        };
        let mut mode_n = [0usize; 3];
        let (mut ss, mut st) = (0.0, 0.0);
        for x in samples {
            s.steer_hist[bin(x.steer)] += 1;
            s.throttle_hist[bin(x.throttle)] += 1;
            let side = if x.steer < -STRAIGHT {
                0
            } else if x.steer < STRAIGHT {
                1
            } else {
                2
            };
            s.steer_left_straight_right[side] += 1;
            s.stopped += usize::from(x.throttle <= STOPPED);
            mode_n[match x.mode {
                DriveMode::Manual => 0,
                DriveMode::Assisted => 1,
                DriveMode::Autopilot => 2,
            }] += 1;
            ss += x.steer;
            st += x.throttle;
        }
        if n > 0 {
            s.mean = (ss / n as f64, st / n as f64);
        }
        for (m, k) in [DriveMode::Manual, DriveMode::Assisted, DriveMode::Autopilot]
            .into_iter()
            .zip(mode_n)
        {
            if k > 0 {
                s.modes.push((m.name().to_string(), k));
            }
        }
        s.warnings = s.balance_warnings();
        s
    }

    fn balance_warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let n = self.frames;
        if n == 0 {
            return vec!["no frames".into()];
        }
        let [l, straight, r] = self.steer_left_straight_right;
        let turning = l + r;
        if turning >= 10 && (l.max(r) as f64) > ONE_SIDE * turning as f64 {
            let (side, other) = if l > r { ("left", "right") } else { ("right", "left") };
            w.push(format!(
                "{:.0} % of the turning frames steer {side} ({} of {turning}): a pilot trained on this learns to turn {side} and hardly {other} (AutoRCCar's \"only goes right\"); drive the track the other way round too, or train with flip-and-negate",
                pct(l.max(r), turning),
                l.max(r)
            ));
        }
        if straight as f64 > MOSTLY_STRAIGHT * n as f64 {
            w.push(format!(
                "{:.0} % of the frames steer straight (|steer| < {STRAIGHT}): a pilot may learn to ignore the curves; cut long straights (`rccar data cut --drop`) or record more curves",
                pct(straight, n)
            ));
        }
        if self.stopped as f64 > MOSTLY_STOPPED * n as f64 {
            w.push(format!(
                "{:.0} % of the frames have the car stopped (throttle ≤ {STOPPED}): cut the start, the end and the waits, or the pilot learns to stand",
                pct(self.stopped, n)
            ));
        }
        w
    }

    /// The text `rccar data ls` prints (one line per item, indented by two spaces).
    pub fn lines(&self) -> Vec<String> {
        let mut out = Vec::new();
        let n = self.frames;
        let modes: Vec<String> = self.modes.iter().map(|(m, k)| format!("{m} {k}")).collect();
        out.push(format!(
            "modes: {}",
            if modes.is_empty() { "-".into() } else { modes.join(", ") }
        ));
        let [l, s, r] = self.steer_left_straight_right;
        out.push(format!(
            "steer: left {:.1} %, straight {:.1} %, right {:.1} % (|steer| < {STRAIGHT} is straight); mean {:+.3}",
            pct(l, n),
            pct(s, n),
            pct(r, n),
            self.mean.0
        ));
        out.push(format!(
            "throttle: stopped {:.1} % (≤ {STOPPED}); mean {:+.3}",
            pct(self.stopped, n),
            self.mean.1
        ));
        let most = self
            .steer_hist
            .iter()
            .chain(&self.throttle_hist)
            .copied()
            .max()
            .unwrap_or(0)
            .max(1);
        out.push(format!("{:<13} {:>7} {:<20} {:>7}", "bin", "steer", "", "throttle"));
        for k in 0..BINS {
            let (lo, hi) = (EDGES[k], EDGES[k + 1]);
            let bar = |c: usize| "#".repeat((c * 20).div_ceil(most));
            out.push(
                format!(
                    "{:>+5.2}..{:<+5.2}  {:>7} {:<20} {:>7} {}",
                    lo,
                    hi,
                    self.steer_hist[k],
                    bar(self.steer_hist[k]),
                    self.throttle_hist[k],
                    bar(self.throttle_hist[k])
                )
                .trim_end()
                .to_string(),
            );
        }
        for w in &self.warnings {
            out.push(format!("warning: {w}"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn sample(steer: f64, throttle: f64) -> Sample {
        Sample {
            frame: 0,
            time_s: 0.0,
            steer,
            throttle,
            mode: DriveMode::Manual,
            image: PathBuf::new(),
            session: None,
            telemetry: None,
        }
    }

    #[test]
    fn bins_cover_minus_one_to_one() {
        assert_eq!(bin(-1.0), 0);
        assert_eq!(bin(-0.81), 0);
        assert_eq!(bin(-0.79), 1);
        assert_eq!(bin(0.0), 5);
        assert_eq!(bin(-0.0001), 5);
        assert_eq!(bin(-0.05), 5);
        assert_eq!(bin(-0.0501), 4);
        assert_eq!(bin(0.05), 6);
        assert_eq!(bin(1.0), 10);
    }

    #[test]
    fn a_one_sided_drive_is_warned_about_and_a_balanced_one_is_not() {
        // 80 left, 10 straight, 10 right: 89 % of the turning frames go left.
        let mut v: Vec<Sample> = (0..80).map(|_| sample(-0.4, 0.5)).collect();
        v.extend((0..10).map(|_| sample(0.0, 0.5)));
        v.extend((0..10).map(|_| sample(0.4, 0.5)));
        let s = LabelStats::of(&v);
        assert_eq!(s.steer_left_straight_right, [80, 10, 10]);
        assert_eq!(s.steer_hist[3], 80);
        assert_eq!(s.steer_hist[5], 10);
        assert_eq!(s.steer_hist[8], 10);
        assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
        assert!(
            s.warnings[0].starts_with("89 % of the turning frames steer left (80 of 90)"),
            "{:?}",
            s.warnings
        );
        // 40/20/40 with the car moving: no warning.
        let mut v: Vec<Sample> = (0..40).map(|_| sample(-0.4, 0.5)).collect();
        v.extend((0..20).map(|_| sample(0.0, 0.5)));
        v.extend((0..40).map(|_| sample(0.4, 0.5)));
        assert!(LabelStats::of(&v).warnings.is_empty());
        // Mostly straight and mostly stopped: two warnings.
        let mut v: Vec<Sample> = (0..90).map(|_| sample(0.0, 0.0)).collect();
        v.extend((0..5).map(|_| sample(-0.4, 0.5)));
        v.extend((0..5).map(|_| sample(0.4, 0.5)));
        let w = LabelStats::of(&v).warnings;
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].starts_with("90 % of the frames steer straight")
                && w[1].starts_with("90 % of the frames have the car stopped"),
            "{w:?}"
        );
    }
}
