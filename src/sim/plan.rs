//! Routes on a track's road network (docs/junctions.md): the path a route gives
//! ([`Track::plan`], the steps taken at the forks in driving order from the start line, one per
//! fork), the junctions a driven car really passes ([`PassageLog`], from its true position),
//! and the report lines of both. The network itself (roads, forks, merges, crossings) is
//! src/sim/network.rs.
//!
//! Units: metres.

use super::network::JunctionKind;
use super::track::Track;
use crate::route::{Step, Why};
use serde::Serialize;

/// A turn sign decides the fork at most this far after it along the road, metres.
pub const SIGN_REACH_M: f64 = 3.0;

/// One junction passed on a planned (or a driven) path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Passage {
    /// Index in [`Track::junctions`].
    pub junction: usize,
    /// Fork, merge or crossing.
    pub kind: JunctionKind,
    /// At a fork: the route step used (its index, from 0), if any.
    pub step: Option<usize>,
    /// At a fork: the way taken.
    pub way: Option<Step>,
    /// Why that way.
    pub why: Option<Why>,
    /// The road driven on after the junction (its name).
    pub road: String,
}

impl Track {
    /// The junction index of each fork on `road`, sorted by distance along it.
    pub fn forks_on(&self, road: usize) -> Vec<usize> {
        let mut v: Vec<usize> = (0..self.junctions.len())
            .filter(|&j| self.junctions[j].kind == JunctionKind::Fork && self.junctions[j].road == road)
            .collect();
        v.sort_by(|&a, &b| self.junctions[a].s.total_cmp(&self.junctions[b].s));
        v
    }

    /// The path a route gives from the start line for `laps` passes of it: every junction
    /// passed, in order, with the way taken at each fork. A step that names neither way of its
    /// fork is an error naming the step and the fork; with no step left, a fork is passed the
    /// `straight` way (or, at a Y fork, the `right` one), as the car does. A turn sign is not
    /// considered here (the pipeline obeys it; the simulator reports what was driven).
    pub fn plan(&self, route: &[Step], laps: u32) -> Result<Vec<Passage>, String> {
        let mut out = Vec::new();
        let (mut road, mut s, mut step) = (0usize, 0.0f64, 0usize);
        let mut laps_left = laps.max(1);
        // Events along the current road from `s` on: forks, merges (as the road passed),
        // crossings; the road's end.
        for _ in 0..10_000 {
            let mut events: Vec<(f64, usize)> = self
                .junctions
                .iter()
                .enumerate()
                .filter_map(|(j, jn)| {
                    let at = match jn.kind {
                        JunctionKind::Fork if jn.road == road => jn.s,
                        JunctionKind::Merge if jn.road == road => jn.s,
                        JunctionKind::Crossing if jn.road == road => jn.s,
                        JunctionKind::Crossing if jn.other == road => jn.other_s,
                        _ => return None,
                    };
                    (at > s + 1e-6).then_some((at, j))
                })
                .collect();
            events.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut left_road = None;
            for (_, j) in events {
                let jn = &self.junctions[j];
                match jn.kind {
                    JunctionKind::Fork => {
                        let (want, why) = match (self.turn_sign_before(j), route.get(step)) {
                            (Some(w), _) => (w, Why::Sign),
                            (None, Some(&w)) => (w, Why::Route),
                            (None, None) => (Self::default_way(jn.ways), Why::Default),
                        };
                        let idx = jn.ways.iter().position(|&w| w == want).ok_or_else(|| {
                            format!(
                                "{} is `{want}`, but fork {j} at ({:.2}, {:.2}) m on `{}` offers {} and {}",
                                if why == Why::Sign { "the turn sign before it".to_string() } else { format!("route step {}", step + 1) },
                                jn.pos[0],
                                jn.pos[1],
                                self.roads[jn.road].name,
                                jn.ways[0],
                                jn.ways[1]
                            )
                        })?;
                        // A sign uses up the fork's step as the route's word would (as the car does).
                        let used = (why != Why::Default && step < route.len()).then_some(step);
                        if why != Why::Default {
                            step += 1;
                        }
                        let next = if idx == 0 { road } else { jn.other };
                        out.push(Passage {
                            junction: j,
                            kind: jn.kind,
                            step: used,
                            way: Some(want),
                            why: Some(why),
                            road: self.roads[next].name.clone(),
                        });
                        if idx == 1 {
                            left_road = Some((jn.other, 0.0));
                            break;
                        }
                    }
                    _ => {
                        out.push(Passage {
                            junction: j,
                            kind: jn.kind,
                            step: None,
                            way: None,
                            why: None,
                            road: self.roads[road].name.clone(),
                        });
                    }
                }
            }
            match left_road {
                Some((r, s1)) => {
                    road = r;
                    s = s1;
                }
                None if road == 0 => {
                    laps_left -= 1;
                    if laps_left == 0 {
                        return Ok(out);
                    }
                    s = -1e-3;
                }
                None => {
                    let (r, s1) = self.roads[road].joins.expect("a branch joins a road");
                    // The merge itself is listed on the road merged into.
                    if let Some(j) = self.junctions.iter().position(|jn| {
                        jn.kind == JunctionKind::Merge && jn.other == road && jn.road == r
                    }) {
                        out.push(Passage {
                            junction: j,
                            kind: JunctionKind::Merge,
                            step: None,
                            way: None,
                            why: None,
                            road: self.roads[r].name.clone(),
                        });
                    }
                    road = r;
                    s = s1;
                }
            }
        }
        Err("the route does not come back to the start line (a loop of branches without the main road?)".into())
    }

    /// The way an enabled turn sign standing before fork `j` shows: beside its road (within
    /// 0.8 m of the centre line) and at most [`SIGN_REACH_M`] before the fork. The pipeline obeys
    /// such a sign whatever the route says (src/lane/junction.rs); so does the plan.
    pub fn turn_sign_before(&self, j: usize) -> Option<Step> {
        let jn = &self.junctions[j];
        let len = self.roads[jn.road].length;
        self.enabled_objects().find_map(|o| {
            let arrow = o.arrow?;
            let (s, lat) = self.project_on(jn.road, o.pos);
            let mut before = jn.s - s;
            if jn.road == 0 {
                before = before.rem_euclid(len);
            }
            (before > 0.0 && before <= SIGN_REACH_M && lat.abs() < 0.8).then_some(match arrow {
                crate::classes::TurnArrow::Left => Step::Left,
                crate::classes::TurnArrow::Right => Step::Right,
            })
        })
    }

    /// The way the car keeps on a fork with no step and no sign: `straight`, else `right`.
    pub fn default_way(ways: [Step; 2]) -> Step {
        if ways.contains(&Step::Straight) {
            Step::Straight
        } else {
            Step::Right
        }
    }
}

/// Gives the junction rule its route and, with `route.junctions = "auto"`, turns it on for a
/// track with junctions: the steps are `route` (a `--route` flag) if given, else `[route]
/// steps` of the config if any, else the track file's `route`. Returns the steps used. A track
/// without junctions and no `--route` leaves `cfg` as it is.
pub fn configure_route(cfg: &mut crate::config::Config, track: &Track, route: Option<Vec<Step>>) -> Vec<Step> {
    if track.junctions.is_empty() && route.is_none() {
        return cfg.route.steps.clone();
    }
    if cfg.route.junctions == crate::config::Junctions::Auto {
        cfg.route.junctions = crate::config::Junctions::On;
    }
    if let Some(r) = route {
        cfg.route.steps = r;
    } else if cfg.route.steps.is_empty() {
        cfg.route.steps = track.spec.route.clone();
    }
    cfg.route.steps.clone()
}

/// The forks of `passages` as (fork index in the track, way taken), for comparing a driven
/// path with a planned one.
pub fn fork_ways_of(passages: &[Passage]) -> Vec<(usize, Step)> {
    passages
        .iter()
        .filter(|p| p.kind == JunctionKind::Fork)
        .filter_map(|p| Some((p.junction, p.way?)))
        .collect()
}

/// The junctions a driven car passes, from its true position frame by frame (the simulator's
/// report of which way it really went). The road it is on changes only after it has driven
/// [`PassageLog::SWITCH_M`] nearer another road's centre line, so crossing a road at a crossing
/// is not taking it.
#[derive(Debug, Clone, Default)]
pub struct PassageLog {
    road: usize,
    s: f64,
    started: bool,
    candidate: Option<(usize, f64)>,
    /// Forks passed on the current road, decided once the car is this far past them.
    pending: Vec<(usize, f64)>,
    /// Every junction passed, in order.
    pub passages: Vec<Passage>,
    /// Forks seen so far (for the step numbers of the report).
    forks: usize,
}

impl PassageLog {
    /// Distance driven nearer another road before the car counts as on it, metres.
    pub const SWITCH_M: f64 = 0.5;
    /// Distance past a fork after which staying on the road counts as keeping on, metres.
    pub const DECIDE_M: f64 = 1.5;

    /// The road the car is on (index into [`Track::roads`]).
    pub fn road(&self) -> usize {
        self.road
    }

    /// One frame: the car's centre `c` after it drove `ds` metres. Returns true when the car
    /// crossed the start line of the main road going forward (a lap).
    pub fn update(&mut self, track: &Track, c: [f64; 2], ds: f64) -> bool {
        if !self.started {
            self.started = true;
            self.road = track.project(c).road;
            self.s = track.project_on(self.road, c).0;
            return false;
        }
        let (s_now, _) = track.project_on(self.road, c);
        let len = track.roads[self.road].length;
        let wrapped = self.road == 0 && s_now < self.s - len / 2.0;
        let passed = |at: f64| {
            if wrapped {
                at > self.s || at <= s_now
            } else {
                at > self.s && at <= s_now
            }
        };
        let mut ahead: Vec<(f64, usize)> = Vec::new();
        for (j, jn) in track.junctions.iter().enumerate() {
            let at = match jn.kind {
                JunctionKind::Crossing if jn.other == self.road => jn.other_s,
                _ if jn.road == self.road => jn.s,
                _ => continue,
            };
            if passed(at) {
                ahead.push((if wrapped && at > self.s { at - len } else { at }, j));
            }
        }
        ahead.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (at, j) in ahead {
            let jn = &track.junctions[j];
            match jn.kind {
                JunctionKind::Fork => self.pending.push((j, at + Self::DECIDE_M)),
                kind => self.passages.push(Passage {
                    junction: j,
                    kind,
                    step: None,
                    way: None,
                    why: None,
                    road: track.roads[self.road].name.clone(),
                }),
            }
        }
        if wrapped {
            for p in &mut self.pending {
                p.1 -= len;
            }
        }
        self.s = s_now;
        // Forks the car kept on past.
        let keep: Vec<usize> = self.pending.iter().filter(|p| p.1 <= s_now).map(|p| p.0).collect();
        self.pending.retain(|p| p.1 > s_now);
        for j in keep {
            self.fork(track, j, 0);
        }
        // Another road nearer?
        let near = track.project(c).road;
        if near == self.road {
            self.candidate = None;
        } else {
            let d = match self.candidate {
                Some((r, d)) if r == near => d + ds.abs(),
                _ => ds.abs(),
            };
            self.candidate = Some((near, d));
            if d >= Self::SWITCH_M {
                if let Some(i) = self.pending.iter().position(|&(j, _)| track.junctions[j].other == near) {
                    let (j, _) = self.pending.remove(i);
                    self.fork(track, j, 1);
                } else if let Some(j) = track.junctions.iter().position(|jn| {
                    jn.kind == JunctionKind::Merge && jn.road == near && jn.other == self.road
                }) {
                    self.passages.push(Passage {
                        junction: j,
                        kind: JunctionKind::Merge,
                        step: None,
                        way: None,
                        why: None,
                        road: track.roads[near].name.clone(),
                    });
                }
                self.pending.clear();
                self.road = near;
                self.s = track.project_on(near, c).0;
                self.candidate = None;
            }
        }
        wrapped
    }

    fn fork(&mut self, track: &Track, j: usize, way: usize) {
        let jn = &track.junctions[j];
        let road = if way == 0 { jn.road } else { jn.other };
        self.passages.push(Passage {
            junction: j,
            kind: JunctionKind::Fork,
            step: Some(self.forks),
            way: Some(jn.ways[way]),
            why: None,
            road: track.roads[road].name.clone(),
        });
        self.forks += 1;
    }
}

/// One line per passage: `fork 0 (1.50, 0.00): straight → main`.
pub fn passage_lines(track: &Track, passages: &[Passage]) -> Vec<String> {
    passages
        .iter()
        .map(|p| {
            let jn = &track.junctions[p.junction];
            let kind = match p.kind {
                JunctionKind::Fork => "fork",
                JunctionKind::Merge => "merge",
                JunctionKind::Crossing => "crossing",
            };
            let way = p.way.map(|w| format!("{w} ")).unwrap_or_default();
            let why = p.why.map(|w| format!(" ({})", w.name())).unwrap_or_default();
            format!(
                "{kind} {} at ({:.2}, {:.2}): {way}→ {}{why}",
                p.junction, jn.pos[0], jn.pos[1], p.road
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn town() -> Track {
        Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/town.toml")).unwrap()
    }

    #[test]
    fn town_has_its_forks_merges_and_crossing() {
        let t = town();
        let names: Vec<&str> = t.roads.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["main", "A", "C", "B"]);
        let kinds = |k| t.junctions.iter().filter(|j| j.kind == k).count();
        assert_eq!((kinds(JunctionKind::Fork), kinds(JunctionKind::Merge), kinds(JunctionKind::Crossing)), (3, 3, 1));
        let forks = t.forks_on(0);
        let ways: Vec<[Step; 2]> = forks.iter().map(|&j| t.junctions[j].ways).collect();
        assert_eq!(
            ways,
            [[Step::Straight, Step::Left], [Step::Left, Step::Right], [Step::Straight, Step::Left]]
        );
        let x = t.junctions.iter().find(|j| j.kind == JunctionKind::Crossing).unwrap();
        assert!((x.pos[0] - 4.5).abs() < 0.01 && (x.pos[1] - 6.5).abs() < 0.01, "{:?}", x.pos);
        // Branch pieces project onto their own road, with s along it.
        let (p, _) = t.road_pose_at(1, 2.0);
        let pr = t.project(p);
        assert_eq!(pr.road, 1);
        assert!((pr.s - 2.0).abs() < 1e-9 && pr.lateral.abs() < 1e-9);
    }

    #[test]
    fn the_shipped_route_passes_six_forks() {
        let t = town();
        let plan = t.plan(&t.spec.route, 3).unwrap();
        let forks: Vec<(&str, Step)> = plan
            .iter()
            .filter(|p| p.kind == JunctionKind::Fork)
            .map(|p| (p.road.as_str(), p.way.unwrap()))
            .collect();
        assert_eq!(
            forks,
            [
                ("main", Step::Straight),
                ("main", Step::Left),
                ("B", Step::Left),
                ("A", Step::Left),
                ("main", Step::Straight),
                ("C", Step::Right),
            ]
        );
        assert!(plan.iter().any(|p| p.kind == JunctionKind::Crossing));
        // A step that names neither way is refused, naming the step and the fork.
        let e = t.plan(&[Step::Right], 1).unwrap_err();
        assert!(e.contains("route step 1 is `right`") && e.contains("straight and left"), "{e}");
    }

    #[test]
    fn a_branch_must_end_on_a_road() {
        let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/town.toml"))
            .unwrap()
            .replace("{ type = \"straight\", length_m = 2.0521209 }", "{ type = \"straight\", length_m = 1.5 }");
        let e = Track::from_toml_str(&text, "t.toml").unwrap_err().to_string();
        assert!(e.contains("branches[1].segments") && e.contains("must end on a road"), "{e}");
    }
}
