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
//! The path a route gives and the junctions a driven car passes: src/sim/plan.rs.
//!
//! Units: metres, radians (degrees in files and messages).

use super::geometry::{limits, segment_piece, wrap_pi, Piece, SegmentSpec, TrackError};
use crate::route::Step;
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
        if br.segments.is_empty() || br.segments.len() > limits::MAX_SEGMENTS {
            return Err(bad(
                key("segments"),
                format!("{} segments", br.segments.len()),
                format!("a branch needs 1..={} segments", limits::MAX_SEGMENTS),
            ));
        }
        // Chain from the fork.
        let (mut p, mut h) = road_pose(&roads, pieces, piece_s0, from, br.at_m);
        let fork_pos = p;
        let first = pieces.len();
        let mut s = 0.0;
        for (i, seg) in br.segments.iter().enumerate() {
            let piece = segment_piece(i, seg, p, h, outer, origin).map_err(|e| match e {
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
            if s > limits::MAX_LENGTH_M {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fork_ways_are_named_like_a_driver_would() {
        assert_eq!(fork_ways(0.0, 19.0), [Step::Straight, Step::Left]);
        assert_eq!(fork_ways(0.0, -19.0), [Step::Straight, Step::Right]);
        assert_eq!(fork_ways(19.0, -19.0), [Step::Left, Step::Right]);
        assert_eq!(fork_ways(19.0, 30.0), [Step::Straight, Step::Left]);
        assert_eq!(fork_ways(-12.0, -30.0), [Step::Straight, Step::Right]);
        assert_eq!(fork_ways(2.0, -3.0), [Step::Left, Step::Straight]);
    }
}
