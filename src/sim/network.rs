//! Junctions: a track's roads joined into a small road network (docs/junctions.md).
//!
//! The `[[segments]]` of a track file are the **main road**, a closed loop. Each
//! `[[branches]]` table is one more road, one lane wide and driven one way: it leaves a road
//! (the main one or an earlier branch) at a distance along it, tangent to it — a **fork** —
//! and runs its own segments until it ends on a road, tangent to it and in its direction — a
//! **merge**. Where two roads' centre lines cross at an angle without joining there is a
//! **crossing**. All three are found when the track loads.
//!
//! At a fork the two ways on are named the way a driver would: the one that bends more to the
//! left is `left` — or `straight` when it turns by less than [`STRAIGHT_DEG`] over the first
//! metre — the other `right` (or `straight`). A T fork off a straight road offers `left` and
//! `straight` (or `straight` and `right`); a Y fork, where both bend away, `left` and `right`.
//!
//! Painting needs no junction code: the scene paints each floor point with the lines of the
//! road whose centre line is nearest (src/sim/scene.rs). So at a fork the outer lines follow
//! their own roads, the inner lines of the two ways appear only where the roads are more than a
//! lane apart (the nose of the gore), and at a crossing each road's lines stop at the other's
//! lines — the gaps a junction has on a real floor track.
//!
//! [`Track::plan`] predicts the path a route gives: the steps are taken at the forks in driving
//! order from the start line, one per fork.
//!
//! Units: metres, radians (degrees in files and messages).

use super::track::{wrap_pi, Piece, SegmentSpec, Track, TrackError};
use crate::route::{Step, Why};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// A way on that turns by less than this over its first metre is `straight`, degrees.
pub const STRAIGHT_DEG: f64 = 10.0;

/// Most `[[branches]]`.
pub const MAX_BRANCHES: usize = 50;

/// One `[[branches]]` table: a road that leaves another and joins one.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BranchSpec {
    /// Its name (reports, telemetry); `branch<N>` when left out.
    #[serde(default)]
    pub name: String,
    /// The road it leaves: `main` or an earlier branch's name.
    #[serde(default = "main_name")]
    pub from: String,
    /// Where it leaves: distance along that road's centre line from its start, metres.
    pub at_m: f64,
    /// Its centre line, piece by piece, from the fork on.
    pub segments: Vec<SegmentSpec>,
}

fn main_name() -> String {
    "main".into()
}

/// One road of the network after checks.
#[derive(Debug, Clone, PartialEq)]
pub struct Road {
    /// `main` for the loop of `[[segments]]`, else the branch's name.
    pub name: String,
    /// Its pieces in [`Track::pieces`].
    pub pieces: Range<usize>,
    /// Length of its centre line, metres.
    pub length: f64,
    /// Where it ends: (road, distance along it) it merges into; `None` for the main loop.
    pub joins: Option<(usize, f64)>,
}

/// What kind of junction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JunctionKind {
    /// A road splits in two.
    Fork,
    /// A road ends on another.
    Merge,
    /// Two roads cross without joining.
    Crossing,
}

/// A junction of the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Junction {
    /// Fork, merge or crossing.
    pub kind: JunctionKind,
    /// Where the centre lines meet, metres.
    pub pos: [f64; 2],
    /// The road it stands on: the one that forks, the one merged into, the first of the two
    /// crossing.
    pub road: usize,
    /// Distance along `road`, metres.
    pub s: f64,
    /// The other road: the branch that leaves or merges, the second crossing road.
    pub other: usize,
    /// Distance along `other` (0 at a fork, its end at a merge), metres.
    pub other_s: f64,
    /// At a fork: the names of [keeping on `road`, taking `other`].
    pub ways: [Step; 2],
}

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
    /// The road a piece belongs to.
    pub fn road_of(&self, piece: usize) -> usize {
        self.roads.iter().position(|r| r.pieces.contains(&piece)).unwrap_or(0)
    }

    /// Point and heading of road `road`'s centre line at distance `s` along it (clamped to
    /// its length; wrapped on the main loop).
    pub fn road_pose_at(&self, road: usize, s: f64) -> ([f64; 2], f64) {
        let r = &self.roads[road];
        let s = if road == 0 { s.rem_euclid(r.length) } else { s.clamp(0.0, r.length) };
        let pieces = r.pieces.clone();
        let s0 = &self.piece_s0[pieces.clone()];
        let i = s0.partition_point(|&a| a <= s).saturating_sub(1);
        let k = pieces.start + i;
        self.pieces[k].pose_at((s - self.piece_s0[k]).min(self.pieces[k].length()))
    }

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
                        let (want, why) = match route.get(step) {
                            Some(&w) => (w, Why::Route),
                            None => (Self::default_way(jn.ways), Why::Default),
                        };
                        let idx = jn.ways.iter().position(|&w| w == want).ok_or_else(|| {
                            format!(
                                "route step {} is `{want}`, but fork {j} at ({:.2}, {:.2}) m on `{}` offers {} and {}",
                                step + 1,
                                jn.pos[0],
                                jn.pos[1],
                                self.roads[jn.road].name,
                                jn.ways[0],
                                jn.ways[1]
                            )
                        })?;
                        let used = (why == Why::Route).then_some(step);
                        if why == Why::Route {
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

    /// The way the car keeps on a fork with no step and no sign: `straight`, else `right`.
    pub fn default_way(ways: [Step; 2]) -> Step {
        if ways.contains(&Step::Straight) {
            Step::Straight
        } else {
            Step::Right
        }
    }
}

/// Builds the branches after the main loop: their pieces appended to `pieces` (with their
/// start distances in `piece_s0`), the roads, and the junctions. `outer` is the outer lines'
/// distance from a centre line.
pub(super) fn build(
    branches: &[BranchSpec],
    pieces: &mut Vec<Piece>,
    piece_s0: &mut Vec<f64>,
    main_len: f64,
    outer: f64,
    origin: &str,
) -> Result<(Vec<Road>, Vec<Junction>), TrackError> {
    let bad = |key: String, value: String, problem: String| TrackError::Invalid {
        origin: origin.into(),
        key,
        value,
        problem,
    };
    if branches.len() > MAX_BRANCHES {
        return Err(bad(
            "branches".into(),
            format!("{} branches", branches.len()),
            format!("at most {MAX_BRANCHES}"),
        ));
    }
    let mut roads = vec![Road {
        name: "main".into(),
        pieces: 0..pieces.len(),
        length: main_len,
        joins: None,
    }];
    let mut junctions = Vec::new();
    let road_pose = |roads: &[Road], pieces: &[Piece], piece_s0: &[f64], r: usize, s: f64| {
        let rd: &Road = &roads[r];
        let k = rd.pieces.start
            + piece_s0[rd.pieces.clone()]
                .partition_point(|&a| a <= s)
                .saturating_sub(1);
        pieces[k].pose_at((s - piece_s0[k]).clamp(0.0, pieces[k].length()))
    };
    for (b, br) in branches.iter().enumerate() {
        let key = |k: &str| format!("branches[{b}].{k}");
        let name = if br.name.is_empty() { format!("branch{}", b + 1) } else { br.name.clone() };
        if roads.iter().any(|r| r.name == name) {
            return Err(bad(key("name"), name, "another road has this name".into()));
        }
        let from = roads.iter().position(|r| r.name == br.from).ok_or_else(|| {
            bad(
                key("from"),
                br.from.clone(),
                format!(
                    "no road of that name before it (roads so far: {})",
                    roads.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        let flen = roads[from].length;
        if !(br.at_m.is_finite() && br.at_m >= 0.0 && br.at_m < flen) {
            return Err(bad(
                key("at_m"),
                br.at_m.to_string(),
                format!("must be within road `{}`: 0 ≤ at_m < {flen:.3} m", br.from),
            ));
        }
        if br.segments.is_empty() || br.segments.len() > super::track::limits::MAX_SEGMENTS {
            return Err(bad(
                key("segments"),
                format!("{} segments", br.segments.len()),
                format!("a branch needs 1..={} segments", super::track::limits::MAX_SEGMENTS),
            ));
        }
        // Chain from the fork.
        let (mut p, mut h) = road_pose(&roads, pieces, piece_s0, from, br.at_m);
        let fork_pos = p;
        let first = pieces.len();
        let mut s = 0.0;
        for (i, seg) in br.segments.iter().enumerate() {
            let piece = Track::segment_piece(i, seg, p, h, outer, origin).map_err(|e| match e {
                TrackError::Invalid {
                    origin,
                    key: k,
                    value,
                    problem,
                } => TrackError::Invalid {
                    origin,
                    key: format!("branches[{b}].{k}"),
                    value,
                    problem,
                },
                e => e,
            })?;
            piece_s0.push(s);
            s += piece.length();
            if s > super::track::limits::MAX_LENGTH_M {
                return Err(bad(key("segments"), format!("{s:.1} m"), "too long".into()));
            }
            let (end, heading) = piece.pose_at(piece.length());
            p = end;
            h = heading;
            pieces.push(piece);
        }
        // Where it ends: on a road (not itself), tangent, the same way.
        let mut join = None;
        for (r, rd) in roads.iter().enumerate() {
            for k in rd.pieces.clone() {
                let (t, lat, out) = pieces[k].project(p);
                if lat.abs() < 0.005 && out < 1e-3 {
                    let (_, hr) = pieces[k].pose_at(t);
                    if wrap_pi(hr - h).abs() < 1f64.to_radians() {
                        join = Some((r, piece_s0[k] + t));
                    }
                }
            }
        }
        let Some((jr, js)) = join else {
            return Err(bad(
                key("segments"),
                format!("ends at ({:.3}, {:.3}) heading {:.1} deg", p[0], p[1], h.to_degrees().rem_euclid(360.0)),
                "a branch must end on a road's centre line (within 5 mm), heading its way (within 1 deg): adjust its last segments".into(),
            ));
        };
        let me = roads.len();
        roads.push(Road {
            name,
            pieces: first..pieces.len(),
            length: s,
            joins: Some((jr, js)),
        });
        // The fork's two ways, by how far each turns over its first metre.
        let ahead = |roads: &[Road], r: usize, s0: f64| {
            let len = roads[r].length;
            let s1 = if r == 0 { (s0 + 1.0).rem_euclid(len) } else { (s0 + 1.0).min(len) };
            let (_, h0) = road_pose(roads, pieces, piece_s0, r, s0);
            let (_, h1) = road_pose(roads, pieces, piece_s0, r, s1);
            wrap_pi(h1 - h0).to_degrees()
        };
        let keep = ahead(&roads, from, br.at_m);
        let take = ahead(&roads, me, 0.0);
        if (keep - take).abs() < 3.0 {
            return Err(bad(
                key("segments"),
                format!("turns {take:.1} deg over its first metre, the road it leaves {keep:.1} deg"),
                "a branch must bend away from the road it leaves (start it with an arc)".into(),
            ));
        }
        let ways = fork_ways(keep, take);
        junctions.push(Junction {
            kind: JunctionKind::Fork,
            pos: fork_pos,
            road: from,
            s: br.at_m,
            other: me,
            other_s: 0.0,
            ways,
        });
        junctions.push(Junction {
            kind: JunctionKind::Merge,
            pos: p,
            road: jr,
            s: js,
            other: me,
            other_s: s,
            ways: [Step::Straight, Step::Straight],
        });
    }
    // Crossings: sign changes of one road's lateral offset along another, at an angle.
    for a in 0..roads.len() {
        for b in a + 1..roads.len() {
            crossings(&roads, pieces, piece_s0, a, b, &mut junctions);
        }
    }
    Ok((roads, junctions))
}

/// The names of a fork's two ways [keep on, take the branch] from how far each turns over its
/// first metre, degrees (left positive): within ±[`STRAIGHT_DEG`] `straight`, else `left` or
/// `right`; when both would get the same name, the one further left becomes `left` (both go
/// straight on) or `straight` (both bend right), or the one further right becomes `straight`
/// (both bend left).
pub fn fork_ways(keep: f64, take: f64) -> [Step; 2] {
    let name = |dh: f64| {
        if dh.abs() < STRAIGHT_DEG {
            Step::Straight
        } else if dh > 0.0 {
            Step::Left
        } else {
            Step::Right
        }
    };
    let (mut k, mut t) = (name(keep), name(take));
    if k == t {
        let keep_is_left = keep > take;
        let (l, r) = if keep_is_left { (&mut k, &mut t) } else { (&mut t, &mut k) };
        match *l {
            Step::Left => *r = Step::Straight,
            Step::Right => *l = Step::Straight,
            Step::Straight => *l = Step::Left,
        }
    }
    [k, t]
}

/// Appends the crossings of roads `a` and `b` (centre lines meeting at more than 20 degrees).
fn crossings(roads: &[Road], pieces: &[Piece], piece_s0: &[f64], a: usize, b: usize, out: &mut Vec<Junction>) {
    let lat_on = |p: [f64; 2]| -> Option<(f64, f64, f64)> {
        // Lateral from road a, if p projects inside one of its pieces (nearest such).
        let mut best: Option<(f64, f64, f64)> = None;
        for k in roads[a].pieces.clone() {
            let (t, lat, o) = pieces[k].project(p);
            if o < 1e-9 && best.is_none_or(|(l, _, _)| lat.abs() < l.abs()) {
                best = Some((lat, piece_s0[k] + t, pieces[k].pose_at(t).1));
            }
        }
        best
    };
    let step = 0.01;
    let mut prev: Option<(f64, [f64; 2])> = None;
    for k in roads[b].pieces.clone() {
        let n = (pieces[k].length() / step).ceil() as usize;
        for i in 0..=n {
            let t = pieces[k].length() * i as f64 / n as f64;
            let (p, hb) = pieces[k].pose_at(t);
            let cur = lat_on(p);
            if let (Some((l0, _)), Some((l1, sa, ha))) = (prev, cur) {
                if l0.signum() != l1.signum() && l1.abs() < 0.05 && wrap_pi(ha - hb).abs().min(std::f64::consts::PI - wrap_pi(ha - hb).abs()) > 20f64.to_radians() {
                    out.push(Junction {
                        kind: JunctionKind::Crossing,
                        pos: p,
                        road: a,
                        s: sa,
                        other: b,
                        other_s: piece_s0[k] + t,
                        ways: [Step::Straight, Step::Straight],
                    });
                }
            }
            prev = cur.map(|(l, _, _)| (l, p));
        }
    }
}

impl Track {
    /// The nearest point of road `road`'s centre line to `p`: (distance along it, signed
    /// lateral offset, left positive).
    pub fn project_on(&self, road: usize, p: [f64; 2]) -> (f64, f64) {
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for k in self.roads[road].pieces.clone() {
            let (t, lat, out) = self.pieces[k].project(p);
            let d = lat * lat + out * out;
            if d < best.0 {
                best = (d, self.piece_s0[k] + t, lat);
            }
        }
        (best.1, best.2)
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
    fn fork_ways_are_named_like_a_driver_would() {
        assert_eq!(fork_ways(0.0, 19.0), [Step::Straight, Step::Left]);
        assert_eq!(fork_ways(0.0, -19.0), [Step::Straight, Step::Right]);
        assert_eq!(fork_ways(19.0, -19.0), [Step::Left, Step::Right]);
        assert_eq!(fork_ways(19.0, 30.0), [Step::Straight, Step::Left]);
        assert_eq!(fork_ways(-12.0, -30.0), [Step::Straight, Step::Right]);
        assert_eq!(fork_ways(2.0, -3.0), [Step::Left, Step::Straight]);
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
