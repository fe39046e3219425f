//! Through a junction the lane method keeps working: at a fork it follows the line on the side
//! of the chosen branch while the other line is missing or bends away, at a merge the line on
//! the far side of the road coming in (docs/junctions.md).
//!
//! The paper's lane centre (Eq. 3, `L_c = (P_R − P_L)/2 + P_L`) assumes the two peaks of the
//! column histogram are one lane's two lines. At a junction they are not: at a fork the lines
//! of the two ways part (the histogram's two peaks drift apart), at a merge the line on the
//! side of the road coming in jumps out to that road's far line. Taking the midpoint there
//! steers the car into the gore between the roads. The rule, frame by frame:
//!
//! 1. On the road, the raw peaks P_L, P_R (each half of the histogram, as in Eq. 3) are
//!    remembered while they are a lane apart (within 10 % of the lane width).
//! 2. When they are more than `fork_width` lane widths apart, the line that moved further from
//!    where it was then is the odd one (not the one that moved more since the last frame: by
//!    then the car may be following the odd line, and the steady one moves in the image). If
//!    a line moved by more than `jump` lane widths since the last frame it jumped, or if it leans in (its column in the upper half of the band is nearer
//!    the lane than in the lower half: a road coming in), it is a **merge** (the car keeps the
//!    other, steady line). If it leans out by more than `lean` lane widths it is bending away:
//!    a **fork**, and the car chooses — a turn sign seen at most `sign_reach_m` before the fork first, else the
//!    route's next step, else `straight` — and keeps the line on that side (`left` → P_L,
//!    `right` → P_R, `straight` → the steady line).
//! 3. While at the junction the kept line gives the lane (the other is estimated from the lane
//!    width, Sec. 3.2 v, unless it is a lane away where it should be); after `settle_frames`
//!    frames with both lines a lane apart again the car is back on the road.
//!
//! The rule has no map: it counts forks as it meets them, so a route's steps are the forks in
//! the order the car reaches them. Units: bird's-eye pixels, frames.

use super::lines::{column_histogram_rows, peak_with, LaneMeasurement, LaneStatus, LineOptions};
use crate::route::{Step, Why};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Lines whose distance is within this fraction of the lane width of it are "a lane apart":
/// where the rule remembers them, and what ends a junction.
const SETTLED: f64 = 0.1;

/// A side of the lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// P_L.
    Left,
    /// P_R.
    Right,
}

impl Side {
    fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// Tunables of the rule (`[route]` in car.toml).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JunctionOptions {
    /// Peaks further apart than this many lane widths: a junction (> 1).
    pub fork_width: f64,
    /// The odd line moved by more than this many lane widths since the last frame: a merge.
    pub jump: f64,
    /// Frames with both lines a lane apart before the car is back on the road.
    pub settle_frames: u32,
    /// The odd line leans out (fork) or in (merge) by more than this many lane widths between
    /// the lower and the upper half of the band; less: undecided, keep the steady line.
    pub lean: f64,
    /// Most frames a junction may last (then back on the road whatever the lines say).
    pub max_frames: u32,
    /// A turn sign decides a fork the car meets at most this far (odometry, metres) past the
    /// sign.
    pub sign_reach_m: f64,
    /// Lines parting again within this distance (odometry, metres) after a junction ended are
    /// the same junction seen again (its far line back in view after a shadow or a bump hid
    /// it): its line is kept again and no route step is used.
    pub rejoin_m: f64,
}

impl Default for JunctionOptions {
    fn default() -> Self {
        Self {
            fork_width: 1.2,
            jump: 0.25,
            lean: 0.03,
            settle_frames: 8,
            max_frames: 300,
            sign_reach_m: 3.0,
            rejoin_m: 1.0,
        }
    }
}

/// What the rule is doing this frame (the `junction` field of telemetry).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JunctionReport {
    /// `fork` or `merge`.
    pub kind: JunctionKind,
    /// The line kept.
    pub keep: Side,
    /// At a fork: the way chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub way: Option<Step>,
    /// At a fork: why that way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub why: Option<Why>,
    /// At a fork decided by the route: the step's index (from 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<usize>,
    /// Forks met so far (this one included).
    pub forks: u32,
    /// True on the frame the junction was met.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub new: bool,
}

/// A fork or a merge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JunctionKind {
    /// The lines part: two ways on.
    Fork,
    /// A road comes in.
    Merge,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct At {
    report: JunctionReport,
    frames: u32,
    settled: u32,
}

/// The rule's state: the route, where the lines were, the junction the car is in.
#[derive(Debug, Clone)]
pub struct JunctionRule {
    opts: JunctionOptions,
    route: Vec<Step>,
    next: usize,
    forks: u32,
    last: [Option<f64>; 2],
    /// Where the lines were when last seen a lane apart.
    apart: [Option<f64>; 2],
    at: Option<At>,
    /// A turn sign's way, until the odometry passes this (metres).
    sign: Option<(Step, f64)>,
    /// The last junction and the odometry (metres) until which lines parting again are it.
    ended: Option<(JunctionReport, f64)>,
    /// Scratch: a column histogram of half the band.
    half: Vec<u16>,
}

impl JunctionRule {
    /// A rule following `route` (one step per fork).
    pub fn new(route: Vec<Step>, opts: JunctionOptions) -> JunctionRule {
        JunctionRule {
            opts,
            route,
            next: 0,
            forks: 0,
            last: [None, None],
            apart: [None, None],
            at: None,
            sign: None,
            ended: None,
            half: Vec::new(),
        }
    }

    /// The route's steps not yet used.
    pub fn steps_left(&self) -> &[Step] {
        &self.route[self.next.min(self.route.len())..]
    }

    /// A turn sign seen this frame (`Left` or `Right`), `sign_m` ahead of the lens at odometry
    /// `odometry_m`: it decides the next fork met at most `sign_reach_m` past the sign, whatever
    /// the route says.
    pub fn sign(&mut self, way: Step, odometry_m: f64, sign_m: f64) {
        self.sign = Some((way, odometry_m + sign_m + self.opts.sign_reach_m));
    }

    /// One frame: the binary bird's-eye image and the histogram the lane was measured from
    /// (`binary`, `hist`, `band_rows`, `lines`) and that measurement `m`; returns the lane to
    /// steer by and, at a junction, the report. `odometry_m`: the distance driven so far (for
    /// a turn sign's reach).
    pub fn step(
        &mut self,
        binary: &GrayImage,
        hist: &[u16],
        band_rows: u32,
        lines: &LineOptions,
        m: LaneMeasurement,
        odometry_m: f64,
    ) -> (LaneMeasurement, Option<JunctionReport>) {
        let (w, mid) = (hist.len(), hist.len() / 2);
        let min_count = (lines.min_peak * band_rows as f64).ceil().max(1.0) as u16;
        let raw = [
            peak_with(lines.peak, hist, 0..mid, min_count),
            peak_with(lines.peak, hist, mid..w, min_count),
        ];
        let lane = lines.lane_width_px;
        if self.sign.is_some_and(|(_, until)| odometry_m > until) {
            self.sign = None;
        }
        let Some(mut at) = self.at else {
            // 1–2. On the road: remember the lines; meet a junction when they part.
            if let [Some(l), Some(r)] = raw {
                if r - l > self.opts.fork_width * lane {
                    if let Some((last, _)) = self.ended.filter(|&(_, until)| odometry_m <= until) {
                        // The same junction seen again, just after it ended: keep its line
                        // again and use no route step.
                        let report = JunctionReport { new: false, ..last };
                        self.at = Some(At {
                            report,
                            frames: 0,
                            settled: 0,
                        });
                        return self.keep(raw, lines, m, report);
                    }
                    let moved = |from: &[Option<f64>; 2], i: usize, p: f64| from[i].map_or(0.0, |q: f64| (p - q).abs());
                    // The odd line: the one further from where it was while the lines were a lane apart.
                    let odd = if moved(&self.apart, 0, l) >= moved(&self.apart, 1, r) {
                        Side::Left
                    } else {
                        Side::Right
                    };
                    let outward = self.lean_out(binary, band_rows, lines, odd);
                    // A jump: a line moved that far since the frame before.
                    let jumped = moved(&self.last, 0, l).max(moved(&self.last, 1, r)) > self.opts.jump * lane;
                    let lean = self.opts.lean * lane;
                    if !jumped && outward.is_none_or(|o| o.abs() <= lean) {
                        // Undecided: keep the steady line this frame, decide on a later one.
                        let report = JunctionReport {
                            kind: JunctionKind::Merge,
                            keep: odd.other(),
                            way: None,
                            why: None,
                            step: None,
                            forks: self.forks,
                            new: false,
                        };
                        let saved = (self.last, self.apart);
                        let (m, _) = self.keep(raw, lines, m, report);
                        (self.last, self.apart) = saved;
                        return (m, None);
                    }
                    let report = if jumped || outward.is_some_and(|o| o < 0.0) {
                        JunctionReport {
                            kind: JunctionKind::Merge,
                            keep: odd.other(),
                            way: None,
                            why: None,
                            step: None,
                            forks: self.forks,
                            new: true,
                        }
                    } else {
                        self.fork(odd)
                    };
                    self.at = Some(At {
                        report,
                        frames: 0,
                        settled: 0,
                    });
                    return self.keep(raw, lines, m, report);
                }
            }
            // Remember where the lines are while they are a lane apart (or where the one line
            // seen is): the odd line at a fork is the one that moved away from there. Updating
            // on every frame would compare a frame with the one before, where both lines have
            // moved a pixel and noise decides (a fork in a shadow taken the wrong way).
            let a_lane_apart = match (m.status, m.p_left, m.p_right) {
                (LaneStatus::Both, Some(l), Some(r)) => ((r - l) - lane).abs() < SETTLED * lane,
                _ => true,
            };
            for (i, p) in [m.p_left, m.p_right].into_iter().enumerate() {
                let estimated = if i == 0 { m.left_estimated } else { m.right_estimated };
                if let (Some(p), false) = (p, estimated) {
                    self.last[i] = Some(p);
                    if a_lane_apart {
                        self.apart[i] = Some(p);
                    }
                }
            }
            return (m, None);
        };
        // 3. At a junction: keep the chosen line until the lane is a lane wide again.
        at.frames += 1;
        at.report.new = false;
        let apart = match raw {
            [Some(l), Some(r)] => ((r - l) - lane).abs() < SETTLED * lane,
            _ => false,
        };
        at.settled = if apart { at.settled + 1 } else { 0 };
        let report = at.report;
        if at.settled >= self.opts.settle_frames || at.frames >= self.opts.max_frames {
            self.at = None;
            self.ended = Some((report, odometry_m + self.opts.rejoin_m));
        } else {
            self.at = Some(at);
        }
        self.keep(raw, lines, m, report)
    }

    /// How far the `side` line leans out of the lane from the lower to the upper half of the
    /// band, pixels (positive: it bends away ahead, a fork; negative: it comes in, a merge);
    /// `None` when either half does not show it.
    fn lean_out(&mut self, binary: &GrayImage, band_rows: u32, lines: &LineOptions, side: Side) -> Option<f64> {
        let (w, h) = (binary.width() as usize, binary.height() as usize);
        let band = (band_rows as usize).min(h);
        let half_rows = band / 2;
        if half_rows == 0 {
            return None;
        }
        let range = match side {
            Side::Left => 0..w / 2,
            Side::Right => w / 2..w,
        };
        let min_count = (lines.min_peak * half_rows as f64).ceil().max(1.0) as u16;
        self.half.resize(w, 0);
        let peak_of = |rows: std::ops::Range<usize>, half: &mut Vec<u16>| {
            column_histogram_rows(binary, rows, half);
            peak_with(lines.peak, half, range.clone(), min_count)
        };
        let mut half = std::mem::take(&mut self.half);
        let top = peak_of(h - band..h - band + half_rows, &mut half);
        let bottom = peak_of(h - half_rows..h, &mut half);
        self.half = half;
        let (t, b) = (top?, bottom?);
        Some(match side {
            Side::Left => b - t,
            Side::Right => t - b,
        })
    }

    /// A fork met with `odd` the line bending away: the way, why, and the line to keep.
    fn fork(&mut self, odd: Side) -> JunctionReport {
        let (way, why, step) = if let Some((way, _)) = self.sign.take() {
            // A sign decides; the route's step for this fork is used up all the same.
            let step = (self.next < self.route.len()).then_some(self.next);
            self.next += 1;
            (way, Why::Sign, step)
        } else if let Some(&way) = self.route.get(self.next) {
            self.next += 1;
            (way, Why::Route, Some(self.next - 1))
        } else {
            (Step::Straight, Why::Default, None)
        };
        self.forks += 1;
        let keep = match way {
            Step::Left => Side::Left,
            Step::Right => Side::Right,
            Step::Straight => odd.other(),
        };
        JunctionReport {
            kind: JunctionKind::Fork,
            keep,
            way: Some(way),
            why: Some(why),
            step,
            forks: self.forks,
            new: true,
        }
    }

    /// The lane from the kept line (the other one where it is a lane away, else estimated).
    fn keep(
        &mut self,
        raw: [Option<f64>; 2],
        lines: &LineOptions,
        m: LaneMeasurement,
        report: JunctionReport,
    ) -> (LaneMeasurement, Option<JunctionReport>) {
        let lane = lines.lane_width_px;
        // The other line counts where a lane is no wider than it is at a junction's start.
        let tol = (self.opts.fork_width - 1.0) * lane;
        let plausible = |l: f64, r: f64| ((r - l) - lane).abs() <= tol;
        let (k, o) = match report.keep {
            Side::Left => (0, 1),
            Side::Right => (1, 0),
        };
        let Some(kept) = raw[k] else {
            // The kept line is not seen: steer by what the lane method found.
            return (m, Some(report));
        };
        let other = raw[o].filter(|&p| {
            let (l, r) = if k == 0 { (kept, p) } else { (p, kept) };
            plausible(l, r)
        });
        let sign = if k == 0 { 1.0 } else { -1.0 };
        let (pl, pr, status) = match (k, other) {
            (0, Some(r)) => (kept, r, LaneStatus::Both),
            (1, Some(l)) => (l, kept, LaneStatus::Both),
            (0, None) => (kept, kept + sign * lane, LaneStatus::LeftOnly),
            _ => (kept + sign * lane, kept, LaneStatus::RightOnly),
        };
        self.last = [Some(pl), Some(pr)];
        if ((pr - pl) - lane).abs() < SETTLED * lane {
            self.apart = self.last;
        }
        let lane_center = (pr - pl) / 2.0 + pl;
        let error_px = lane_center - m.frame_center;
        // The image is 2·(L_F − offset) + 1 columns wide; the error is normalised by half of it.
        let half = m.frame_center - lines.center_offset_px;
        (
            LaneMeasurement {
                p_left: Some(pl),
                p_right: Some(pr),
                left_estimated: status == LaneStatus::RightOnly,
                right_estimated: status == LaneStatus::LeftOnly,
                lane_center: Some(lane_center),
                frame_center: m.frame_center,
                error_px: Some(error_px),
                error: Some((error_px / half).clamp(-1.0, 1.0)),
                status,
            },
            Some(report),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lane::lines::{band_rows, column_histogram, measure, PeakMode};

    const W: u32 = 320;
    const H: u32 = 240;
    const LINES: LineOptions = LineOptions {
        band: 0.4,
        min_peak: 0.3,
        peak: PeakMode::Centroid,
        lane_width_px: 190.0,
        width_tolerance: 0.35,
        center_offset_px: 0.0,
    };

    /// A binary bird's-eye image with a right line at 254.5 and a left line whose column is
    /// `left + lean · (rows above the bottom) / band` (4 px wide).
    fn frame(left: f64, lean: f64) -> GrayImage {
        frame_with_right(left, lean, 254.5)
    }

    /// As [`frame`], with the right line (straight) at column `right`.
    fn frame_with_right(left: f64, lean: f64, right: f64) -> GrayImage {
        let band = band_rows(H, LINES.band) as f64;
        GrayImage::from_fn(W, H, |x, y| {
            let up = (H - 1 - y) as f64;
            let l = left + lean * up / band;
            let on = |c: f64| (x as f64 - c).abs() < 6.0;
            image::Luma([if on(l) || on(right) { 255 } else { 0 }])
        })
    }

    fn run(rule: &mut JunctionRule, img: &GrayImage) -> (LaneMeasurement, Option<JunctionReport>) {
        let rows = band_rows(H, LINES.band);
        let mut hist = vec![0; W as usize];
        column_histogram(img, rows, &mut hist);
        let m = measure(&hist, rows, &LINES);
        rule.step(img, &hist, rows, &LINES, m, 0.0)
    }

    /// As [`run`], at odometry `odometry_m`.
    fn run_at(rule: &mut JunctionRule, img: &GrayImage, odometry_m: f64) -> Option<JunctionReport> {
        let rows = band_rows(H, LINES.band);
        let mut hist = vec![0; W as usize];
        column_histogram(img, rows, &mut hist);
        let m = measure(&hist, rows, &LINES);
        rule.step(img, &hist, rows, &LINES, m, odometry_m).1
    }

    /// The left line bends away over 40 frames (1 cm of odometry each), then the lines are a
    /// lane apart for 10 frames; the junctions met on the way (`new` reports).
    fn part_and_settle(rule: &mut JunctionRule, odometry_m: &mut f64) -> Vec<JunctionReport> {
        let mut met = Vec::new();
        for i in 0..50 {
            let drift = if i < 40 { (i as f64 - 5.0).max(0.0) * 2.0 } else { 0.0 };
            *odometry_m += 0.01;
            met.extend(run_at(rule, &frame(64.5 - drift, -drift), *odometry_m).filter(|r| r.new));
        }
        met
    }

    #[test]
    fn lines_parting_again_just_after_a_junction_are_the_same_junction() {
        let mut rule = JunctionRule::new(vec![Step::Left, Step::Right], JunctionOptions::default());
        let mut odo = 0.0;
        let first = part_and_settle(&mut rule, &mut odo);
        assert_eq!(first.len(), 1);
        assert_eq!(
            (first[0].kind, first[0].way, first[0].step),
            (JunctionKind::Fork, Some(Step::Left), Some(0))
        );
        // The lines part again 0.3 m after the junction ended (within rejoin_m = 1 m): the same
        // fork, its left line kept, the route's next step not used.
        let again = part_and_settle(&mut rule, &mut odo);
        assert!(again.is_empty(), "{again:?}");
        assert_eq!(rule.steps_left(), &[Step::Right]);
        // 1 m of road later the lines part: a new fork, and the next step decides it.
        for _ in 0..100 {
            odo += 0.01;
            run_at(&mut rule, &frame(64.5, 0.0), odo);
        }
        let next = part_and_settle(&mut rule, &mut odo);
        assert_eq!(next.len(), 1);
        assert_eq!(
            (next[0].way, next[0].step, next[0].forks),
            (Some(Step::Right), Some(1), 2)
        );
    }

    #[test]
    fn a_line_bending_away_is_a_fork_and_the_route_picks_the_line() {
        for (step, keep) in [(Step::Left, Side::Left), (Step::Straight, Side::Right)] {
            let mut rule = JunctionRule::new(vec![step], JunctionOptions::default());
            let mut met = None;
            for i in 0..40 {
                // The left line drifts out 2 px a frame and leans out more the further ahead.
                let drift = (i as f64 - 5.0).max(0.0) * 2.0;
                let (m, r) = run(&mut rule, &frame(64.5 - drift, -drift));
                if let Some(r) = r.filter(|r| r.new) {
                    met = Some((i, r, m));
                }
            }
            let (_, r, m) = met.expect("a fork was met");
            assert_eq!(
                (r.kind, r.way, r.why, r.keep),
                (JunctionKind::Fork, Some(step), Some(Why::Route), keep)
            );
            assert_eq!(r.step, Some(0));
            // Keeping the right line: the left is estimated a lane width away.
            if keep == Side::Right {
                assert_eq!(m.status, LaneStatus::RightOnly);
                assert!((m.p_left.unwrap() - (254.5 - 190.0)).abs() < 1.0);
            }
            assert!(rule.steps_left().is_empty());
        }
    }

    #[test]
    fn the_odd_line_is_the_one_that_left_where_it_was_not_the_one_that_moved_last() {
        // The left line bends away at a fork; near the point where the lines are far enough
        // apart to call it a junction the car has begun to follow it, so in the image the left
        // line hardly moves any more and the straight right line moves faster (the town's
        // first fork in dusk and shadow, where the right line had been lost for a frame). The
        // left line is the odd one: it is far from where it was while the lines were a lane
        // apart. Judged from the last frame's movement alone it is the right one, which does
        // not lean out, and the fork is never taken the way the route says.
        let mut rule = JunctionRule::new(vec![Step::Straight], JunctionOptions::default());
        let (mut left, mut right) = (64.5, 254.5);
        let mut met = None;
        for i in 0..60 {
            // Drawn leaning out by 16 px over the band, the left line's peak is 8 px left of
            // `left`: the lines are measured 228 px apart (1.2 lane widths) when drawn 220.
            if i >= 5 && right - left < 217.0 {
                left -= 3.0;
            } else if i >= 5 {
                left -= 0.3;
                right += 1.0;
            }
            let lean = if i >= 5 { -16.0 } else { 0.0 };
            if let (m, Some(r)) = run(&mut rule, &frame_with_right(left, lean, right)) {
                met = Some((i, m, r));
                break;
            }
        }
        let (i, m, r) = met.expect("a fork was met");
        assert_eq!(
            (r.kind, r.way, r.keep),
            (JunctionKind::Fork, Some(Step::Straight), Side::Right),
            "frame {i}"
        );
        assert_eq!(m.status, LaneStatus::RightOnly);
    }

    #[test]
    fn a_line_that_jumps_out_or_leans_in_is_a_merge_and_uses_no_step() {
        for jump in [true, false] {
            let mut rule = JunctionRule::new(vec![Step::Left], JunctionOptions::default());
            for _ in 0..5 {
                run(&mut rule, &frame(64.5, 0.0));
            }
            // Jumps out to another road's line at once, or drifts out leaning in towards the
            // lane ahead (a road coming in).
            let mut met = None;
            for i in 1..40 {
                let (left, lean) = if jump {
                    (10.0, 0.0)
                } else {
                    (64.5 - 2.0 * i as f64, 30.0)
                };
                if let (m, Some(r)) = run(&mut rule, &frame(left, lean)) {
                    met = Some((m, r));
                    break;
                }
            }
            let (m, r) = met.unwrap_or_else(|| panic!("jump {jump}: no junction"));
            assert_eq!((r.kind, r.keep), (JunctionKind::Merge, Side::Right), "jump {jump}");
            assert_eq!(r.way, None);
            assert_eq!(rule.steps_left(), [Step::Left]);
            assert!((m.lane_center.unwrap() - (254.5 - 95.0)).abs() < 1.0, "{m:?}");
        }
    }

    #[test]
    fn a_turn_sign_overrides_the_route() {
        let mut rule = JunctionRule::new(vec![Step::Straight], JunctionOptions::default());
        rule.sign(Step::Left, 0.0, 1.0);
        let mut got = None;
        for i in 0..40 {
            let drift = (i as f64 - 5.0).max(0.0) * 2.0;
            if let (_, Some(r)) = run(&mut rule, &frame(64.5 - drift, -drift)) {
                got = got.or(Some(r));
            }
        }
        let r = got.unwrap();
        assert_eq!((r.way, r.why, r.keep), (Some(Step::Left), Some(Why::Sign), Side::Left));
        // The route's step for that fork is used up.
        assert!(rule.steps_left().is_empty());
    }

    #[test]
    fn the_road_back_to_a_lane_width_ends_the_junction() {
        let mut rule = JunctionRule::new(vec![], JunctionOptions::default());
        for i in 0..25 {
            let drift = (i as f64 - 5.0).max(0.0) * 2.0;
            run(&mut rule, &frame(64.5 - drift, -drift));
        }
        assert!(rule.at.is_some());
        for _ in 0..JunctionOptions::default().settle_frames {
            run(&mut rule, &frame(64.5, 0.0));
        }
        assert!(rule.at.is_none());
    }
}
