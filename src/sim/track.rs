//! Tracks for the simulator: a TOML file (see `docs/sim.md`) describing the road's centre line
//! as a chain of straight segments and circular arcs, its lane lines, the floor, and the
//! objects placed beside it (stop signs, traffic lights, obstacles).
//!
//! Loading goes in three steps:
//! 1. parse the TOML into [`TrackFile`] (an unknown key or a wrong type is an error naming the
//!    key and its line);
//! 2. check every number (no zero-length segment, a lane wider than its lines, ...);
//! 3. chain the segments into [`Piece`]s from the start pose and check that the chain closes
//!    on itself (the last piece ends where the first begins, with the same heading), then
//!    check that every object stands on the floor.
//!
//! Units: metres and radians inside, degrees in the file. World frame: x east, y north, z up;
//! headings counter-clockwise from +x. Lateral offsets are positive to the left of the
//! direction of travel.

use crate::classes::{ObjectClass, TurnArrow};
pub use super::geometry::{limits, segment_piece, wrap_pi, Piece, SegmentSpec, TrackError};
use serde::Deserialize;
use std::path::Path;


/// An RGB colour, 0..=255 per channel.
pub type Rgb = [u8; 3];

/// The track file as written (before checks).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackFile {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// Where the centre line begins and which way it heads.
    #[serde(default)]
    pub start: StartPose,
    /// Lanes and their painted lines.
    pub road: RoadSpec,
    /// The floor around the road.
    #[serde(default)]
    pub floor: FloorSpec,
    /// The centre line, piece by piece, in driving order.
    pub segments: Vec<SegmentSpec>,
    /// Things placed on the floor.
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
    /// Roads that leave a road and join one: junctions (src/sim/network.rs, docs/junctions.md).
    #[serde(default)]
    pub branches: Vec<super::network::BranchSpec>,
    /// The route: the way to take at each fork reached, in driving order (`rccar sim --route`
    /// replaces it).
    #[serde(default)]
    pub route: Vec<crate::route::Step>,
    /// Markings painted on the floor (stop and give-way lines), independent of the road's
    /// chain: see [`MarkSpec`].
    #[serde(default)]
    pub marks: Vec<MarkSpec>,
}

/// `[start]`: the beginning of the centre line, which is also where laps are counted.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StartPose {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Direction of travel, degrees counter-clockwise from +x.
    pub heading_deg: f64,
}

/// How the middle line of a two-lane road is painted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CentreLine {
    /// No middle line.
    None,
    /// A continuous line.
    Solid,
    /// Dashes of `dash_m` separated by `gap_m`.
    Dashed,
}

/// `[road]`: lanes and lines.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoadSpec {
    /// 1 or 2. With 2 lanes the car drives in the right-hand lane.
    #[serde(default = "one")]
    pub lanes: u32,
    /// Width of one lane between the centres of its two lines, metres.
    pub lane_width_m: f64,
    /// Width of the painted (taped) lines, metres.
    #[serde(default = "line_width")]
    pub line_width_m: f64,
    /// Colour of the outer lines.
    #[serde(default = "white")]
    pub line_color: Rgb,
    /// The line between two lanes.
    #[serde(default = "dashed")]
    pub centre_line: CentreLine,
    /// Colour of the centre line.
    #[serde(default = "white")]
    pub centre_line_color: Rgb,
    /// Length of one dash, metres.
    #[serde(default = "dash")]
    pub dash_m: f64,
    /// Gap between dashes, metres.
    #[serde(default = "gap")]
    pub gap_m: f64,
}

fn one() -> u32 {
    1
}
fn line_width() -> f64 {
    0.02
}
fn white() -> Rgb {
    [235, 235, 228]
}
fn dashed() -> CentreLine {
    CentreLine::Dashed
}
fn dash() -> f64 {
    0.10
}
fn gap() -> f64 {
    0.06
}

/// `[floor]`: the floor's look and extent.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FloorSpec {
    /// Mean colour.
    pub color: Rgb,
    /// Strength of the texture (mottling), as a fraction of the brightness, 0..1.
    pub texture: f64,
    /// Size of the texture's largest blotches, metres.
    pub texture_scale_m: f64,
    /// Seed of the texture pattern.
    pub seed: u64,
    /// The floor reaches this far beyond the road's outer lines, metres; walls stand there.
    pub margin_m: f64,
    /// Colour of the walls.
    pub wall_color: Rgb,
}

impl Default for FloorSpec {
    fn default() -> Self {
        Self {
            color: [112, 104, 96],
            texture: 0.18,
            texture_scale_m: 0.15,
            seed: 7,
            margin_m: 1.0,
            wall_color: [190, 186, 176],
        }
    }
}


/// One `[[objects]]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// `stop_sign`, `traffic_light`, `obstacle`, `yield_sign` or `turn_sign`.
    #[serde(rename = "type")]
    pub kind: ObjectClass,
    /// Position on the floor, metres.
    pub x: f64,
    /// Position on the floor, metres.
    pub y: f64,
    /// Direction the object faces (a sign's face, a light's lamps), degrees from +x.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Whether it is drawn (so a track can carry objects for later behaviours, switched off).
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Size, metres: the sign face's width (stop sign), the housing's height (traffic
    /// light), or `[length, width, height]` for an obstacle (only obstacles take three).
    #[serde(default)]
    pub size_m: Vec<f64>,
    /// Height of the sign's or light's centre above the floor, metres.
    #[serde(default)]
    pub height_m: Option<f64>,
    /// Obstacle colour.
    #[serde(default = "box_color")]
    pub color: Rgb,
    /// Traffic light: seconds of green, amber and red.
    #[serde(default = "cycle")]
    pub cycle_s: [f64; 3],
    /// Traffic light: where in its cycle it is at t = 0, seconds.
    #[serde(default)]
    pub phase_s: f64,
    /// Turn sign: the way its arrow points, `left` or `right` (default right; other kinds
    /// refuse the key).
    #[serde(default)]
    pub arrow: Option<TurnArrow>,
}

fn yes() -> bool {
    true
}
fn box_color() -> Rgb {
    [60, 90, 160]
}
fn cycle() -> [f64; 3] {
    [4.0, 1.0, 4.0]
}

// ---- Floor markings (`[[marks]]`): stop and give-way lines across a lane. ----

/// What a `[[marks]]` table paints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkKind {
    /// A solid line across the lane: stop here.
    StopLine,
    /// A dashed give-way line: dashes of [`YIELD_DASH_M`] with gaps of [`YIELD_GAP_M`] across
    /// the lane.
    YieldLine,
}

/// Length of one dash of a yield line (across the lane), metres.
pub const YIELD_DASH_M: f64 = 0.04;
/// Gap between the dashes of a yield line, metres.
pub const YIELD_GAP_M: f64 = 0.03;

/// One `[[marks]]` table: a line painted across a lane, in world coordinates like an object.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkSpec {
    /// `stop_line` or `yield_line`.
    #[serde(rename = "type")]
    pub kind: MarkKind,
    /// The middle of the line on the floor, metres.
    pub x: f64,
    /// The middle of the line on the floor, metres.
    pub y: f64,
    /// The direction of travel the line stops, degrees from +x; the line lies across it.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Length across the lane, metres (default: `road.lane_width_m + road.line_width_m`).
    #[serde(default)]
    pub length_m: Option<f64>,
    /// Width along the road, metres (default 0.05).
    #[serde(default)]
    pub width_m: Option<f64>,
}

/// A mark after checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mark {
    /// What it is.
    pub kind: MarkKind,
    /// Index in the file's `[[marks]]` list.
    pub index: usize,
    /// The line's middle, metres.
    pub pos: [f64; 2],
    /// (cos, sin) of the direction of travel it stops (the line lies across it).
    pub dir: [f64; 2],
    /// Across the lane, metres.
    pub length: f64,
    /// Along the road, metres.
    pub width: f64,
}

impl Mark {
    /// The point `p` in the mark's frame: (along the direction of travel from the line's
    /// middle, to the left of it), metres.
    #[inline]
    pub fn local(&self, p: [f64; 2]) -> (f64, f64) {
        let (dx, dy) = (p[0] - self.pos[0], p[1] - self.pos[1]);
        (dx * self.dir[0] + dy * self.dir[1], self.dir[0] * dy - self.dir[1] * dx)
    }

    /// Whether the mark is dashed (a yield line).
    pub fn dashed(&self) -> bool {
        self.kind == MarkKind::YieldLine
    }

    /// Mark `i` of a track file checked: finite, on the floor `floor_rect`, sizes within
    /// [`limits`]; `road` gives the default length.
    fn place(i: usize, m: &MarkSpec, road: &RoadSpec, floor_rect: [f64; 4], origin: &str) -> Result<Mark, TrackError> {
        let bad = |k: &str, value: String, problem: String| TrackError::Invalid {
            origin: origin.into(),
            key: format!("marks[{i}].{k}"),
            value,
            problem,
        };
        if !(m.x.is_finite() && m.y.is_finite() && m.yaw_deg.is_finite()) {
            let v = format!("({}, {}, {})", m.x, m.y, m.yaw_deg);
            return Err(bad("x/y/yaw_deg", v, "must be finite".into()));
        }
        let [x0, y0, x1, y1] = floor_rect;
        if m.x < x0 || m.x > x1 || m.y < y0 || m.y > y1 {
            let v = format!("({:.2}, {:.2})", m.x, m.y);
            let why = format!("off the map; the floor spans x {x0:.2}..{x1:.2}, y {y0:.2}..{y1:.2} m");
            return Err(bad("x/y", v, why));
        }
        let length = m.length_m.unwrap_or(road.lane_width_m + road.line_width_m);
        if !(0.02..=limits::MAX_MARK_LENGTH_M).contains(&length) {
            let why = format!("must be 0.02..={} m", limits::MAX_MARK_LENGTH_M);
            return Err(bad("length_m", length.to_string(), why));
        }
        let width = m.width_m.unwrap_or(0.05);
        if !(0.005..=limits::MAX_MARK_WIDTH_M).contains(&width) {
            let why = format!("must be 0.005..={} m", limits::MAX_MARK_WIDTH_M);
            return Err(bad("width_m", width.to_string(), why));
        }
        let (s, c) = m.yaw_deg.to_radians().sin_cos();
        Ok(Mark {
            kind: m.kind,
            index: i,
            pos: [m.x, m.y],
            dir: [c, s],
            length,
            width,
        })
    }
}

/// The next mark ahead of a point, as the simulator's truth reports it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MarkAhead {
    /// Index in `[[marks]]`.
    pub index: usize,
    /// What it is.
    pub kind: MarkKind,
    /// Forward distance from the point to the line's near edge, metres (negative while the
    /// point is over the line).
    pub distance_m: f64,
}

impl Track {
    /// The nearest mark ahead of floor point `p` for travel along `heading` (radians): one
    /// that stops this direction (its yaw within 60° of `heading`), whose extent across the
    /// lane holds `p`, and whose far edge `p` has not passed.
    pub fn mark_ahead(&self, p: [f64; 2], heading: f64) -> Option<MarkAhead> {
        let (hs, hc) = heading.sin_cos();
        self.marks
            .iter()
            .filter(|m| m.dir[0] * hc + m.dir[1] * hs > 0.5)
            .filter_map(|m| {
                let (along, across) = m.local(p);
                let d = -along - m.width / 2.0;
                (across.abs() <= m.length / 2.0 && d > -m.width).then_some(MarkAhead {
                    index: m.index,
                    kind: m.kind,
                    distance_m: d,
                })
            })
            .min_by(|a, b| a.distance_m.total_cmp(&b.distance_m))
    }
}


/// Where a point lies relative to the centre line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Distance along the centre line from the start, metres, 0..length.
    pub s: f64,
    /// Signed lateral offset of the point, metres, positive to the left of travel.
    pub lateral: f64,
    /// Heading of the centre line there, radians.
    pub heading: f64,
    /// Curvature of the centre line there, 1/m (positive = turning left).
    pub curvature: f64,
    /// Which piece.
    pub piece: usize,
    /// Which road (0 = the main loop; `s` is along this road).
    pub road: usize,
}


/// A placed object after checks, in world units.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// What it is.
    pub kind: ObjectClass,
    /// Index in the file's `[[objects]]` list (enabled or not), for messages and telemetry.
    pub index: usize,
    /// Position on the floor, metres.
    pub pos: [f64; 2],
    /// Facing direction, radians.
    pub yaw: f64,
    /// Stop sign: face width; light: housing height; obstacle: [length, width, height].
    pub size: [f64; 3],
    /// Height of the sign face's or light housing's centre, metres.
    pub height: f64,
    /// Obstacle colour.
    pub color: Rgb,
    /// Traffic light: green, amber, red durations, seconds.
    pub cycle_s: [f64; 3],
    /// Traffic light phase at t = 0, seconds.
    pub phase_s: f64,
    /// Turn sign: the way its arrow points (`None` for other kinds).
    pub arrow: Option<TurnArrow>,
}

/// A traffic light's lamp state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightState {
    /// Go.
    Green,
    /// About to turn red.
    Amber,
    /// Stop.
    Red,
}

impl Object {
    /// A traffic light's state at time `t_s`.
    pub fn light_state(&self, t_s: f64) -> LightState {
        let total: f64 = self.cycle_s.iter().sum();
        let p = (t_s + self.phase_s).rem_euclid(total);
        if p < self.cycle_s[0] {
            LightState::Green
        } else if p < self.cycle_s[0] + self.cycle_s[1] {
            LightState::Amber
        } else {
            LightState::Red
        }
    }
}

/// A checked track, ready to render and drive.
#[derive(Debug, Clone)]
pub struct Track {
    /// Name for reports.
    pub name: String,
    /// The file as read (colours, floor settings).
    pub spec: TrackFile,
    /// The centre lines: the main loop's pieces in driving order, then each branch's
    /// (see [`Track::roads`]).
    pub pieces: Vec<Piece>,
    /// Distance along its road's centre line at the start of each piece, metres.
    pub piece_s0: Vec<f64>,
    /// Total length of the main road's centre line (the loop laps are counted on), metres.
    pub length: f64,
    /// The roads: the main loop first, then the branches (src/sim/network.rs).
    pub roads: Vec<super::network::Road>,
    /// Forks, merges and crossings.
    pub junctions: Vec<super::network::Junction>,
    /// Lateral offsets (left positive) of the painted line centres from the road's centre
    /// line, metres, with whether each is the dashed centre line.
    pub lines: Vec<(f64, bool)>,
    /// Lateral offset of the centre of the lane the car drives in, metres (negative = right).
    pub drive_offset: f64,
    /// The floor's rectangle [x0, y0, x1, y1], metres.
    pub floor_rect: [f64; 4],
    /// Every object in the file (disabled ones too; see [`Object`] and `enabled`).
    pub objects: Vec<(Object, bool)>,
    /// The floor markings, in file order.
    pub marks: Vec<Mark>,
}

impl Track {
    /// Reads and checks a track file.
    pub fn load(path: &Path) -> Result<Track, TrackError> {
        let text = std::fs::read_to_string(path).map_err(|error| TrackError::Io {
            path: path.into(),
            error,
        })?;
        Track::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and checks a track from TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Track, TrackError> {
        // 1. Parse; serde_path_to_error keeps the key path, toml's error the line.
        let de = toml::Deserializer::new(text);
        let spec: TrackFile = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.inner().to_string();
            let inner = inner.trim().replace('\n', "\n  ");
            TrackError::Parse {
                origin: origin.into(),
                message: if path.is_empty() || path == "." {
                    inner
                } else {
                    format!("at `{path}`: {inner}")
                },
            }
        })?;
        Track::from_spec(spec, origin)
    }

    /// Checks a parsed track file and builds its geometry.
    pub fn from_spec(spec: TrackFile, origin: &str) -> Result<Track, TrackError> {
        // 2. Numbers.
        Self::check_numbers(&spec, origin)?;
        let (r, f) = (&spec.road, &spec.floor);

        // 3. Chain the pieces.
        let outer = if r.lanes == 2 {
            r.lane_width_m + r.line_width_m / 2.0
        } else {
            r.lane_width_m / 2.0 + r.line_width_m / 2.0
        };
        let (mut pieces, mut piece_s0, total) = Self::chain(&spec, outer, origin)?;
        let (roads, junctions) =
            super::network::build(&spec.branches, &mut pieces, &mut piece_s0, total, outer, origin)?;

        // Lines and the driven lane.
        let w = r.lane_width_m;
        let (lines, drive_offset) = if r.lanes == 2 {
            let mut l = vec![(w, false), (-w, false)];
            if r.centre_line != CentreLine::None {
                l.push((0.0, r.centre_line == CentreLine::Dashed));
            }
            (l, -w / 2.0)
        } else {
            (vec![(w / 2.0, false), (-w / 2.0, false)], 0.0)
        };

        let floor_rect = Self::floor_rect(&pieces, total, outer, f.margin_m, origin)?;

        // Objects.
        let mut objects = Vec::new();
        for (i, o) in spec.objects.iter().enumerate() {
            objects.push((Self::place_object(i, o, floor_rect, origin)?, o.enabled));
        }
        // Floor markings.
        if spec.marks.len() > limits::MAX_MARKS {
            return Err(TrackError::Invalid {
                origin: origin.into(),
                key: "marks".into(),
                value: format!("{} marks", spec.marks.len()),
                problem: format!("at most {} marks", limits::MAX_MARKS),
            });
        }
        let marks = (spec.marks.iter().enumerate())
            .map(|(i, m)| Mark::place(i, m, r, floor_rect, origin))
            .collect::<Result<Vec<_>, _>>()?;

        Ok(Track {
            name: if spec.name.is_empty() {
                origin.to_string()
            } else {
                spec.name.clone()
            },
            pieces,
            piece_s0,
            length: total,
            roads,
            junctions,
            lines,
            drive_offset,
            floor_rect,
            objects,
            marks,
            spec,
        })
    }

    /// Step 2 of [`Track::from_spec`]: the road's, floor's and start's numbers and the
    /// counts within their limits.
    fn check_numbers(spec: &TrackFile, origin: &str) -> Result<(), TrackError> {
        let bad = |key: String, value: String, problem: &str| TrackError::Invalid {
            origin: origin.into(),
            key,
            value,
            problem: problem.into(),
        };
        let r = &spec.road;
        if !(r.lanes == 1 || r.lanes == 2) {
            return Err(bad("road.lanes".into(), r.lanes.to_string(), "must be 1 or 2"));
        }
        if !(r.lane_width_m > 0.0 && r.lane_width_m <= 5.0) {
            return Err(bad(
                "road.lane_width_m".into(),
                r.lane_width_m.to_string(),
                "must be > 0 and <= 5 m",
            ));
        }
        if !(r.line_width_m > 0.0 && r.line_width_m < r.lane_width_m / 2.0) {
            return Err(bad(
                "road.line_width_m".into(),
                r.line_width_m.to_string(),
                "must be > 0 and less than half the lane width",
            ));
        }
        if r.centre_line == CentreLine::Dashed && !(r.dash_m > 0.0 && r.gap_m > 0.0) {
            return Err(bad(
                "road.dash_m / road.gap_m".into(),
                format!("{} / {}", r.dash_m, r.gap_m),
                "both must be > 0 for a dashed centre line",
            ));
        }
        let f = &spec.floor;
        if !(0.0..=1.0).contains(&f.texture) {
            return Err(bad("floor.texture".into(), f.texture.to_string(), "must be 0..=1"));
        }
        if !(f.texture_scale_m > 0.0 && f.texture_scale_m.is_finite()) {
            return Err(bad(
                "floor.texture_scale_m".into(),
                f.texture_scale_m.to_string(),
                "must be > 0",
            ));
        }
        if !(f.margin_m >= 0.2 && f.margin_m <= 50.0) {
            return Err(bad(
                "floor.margin_m".into(),
                f.margin_m.to_string(),
                "must be 0.2..=50 m",
            ));
        }
        let st = spec.start;
        if !(st.x.is_finite() && st.y.is_finite() && st.heading_deg.is_finite()) {
            return Err(bad(
                "start".into(),
                format!("({}, {}, {})", st.x, st.y, st.heading_deg),
                "must be finite",
            ));
        }
        if st.x.abs() > limits::MAX_COORD_M || st.y.abs() > limits::MAX_COORD_M {
            return Err(bad(
                "start".into(),
                format!("({}, {})", st.x, st.y),
                &format!("x and y must be within ±{} m", limits::MAX_COORD_M),
            ));
        }
        if spec.segments.len() > limits::MAX_SEGMENTS {
            return Err(bad(
                "segments".into(),
                format!("{} segments", spec.segments.len()),
                &format!("at most {} segments", limits::MAX_SEGMENTS),
            ));
        }
        if spec.objects.len() > limits::MAX_OBJECTS {
            return Err(bad(
                "objects".into(),
                format!("{} objects", spec.objects.len()),
                &format!("at most {} objects", limits::MAX_OBJECTS),
            ));
        }
        if spec.segments.is_empty() {
            return Err(bad(
                "segments".into(),
                "[]".into(),
                "a track needs at least one segment",
            ));
        }

        Ok(())
    }

    /// Step 3 of [`Track::from_spec`]: the segments chained into pieces from the start pose
    /// (each checked; `outer` = the outer lines' distance from the centre line), their start
    /// arc lengths and the total length; the chain must close on the start.
    fn chain(spec: &TrackFile, outer: f64, origin: &str) -> Result<(Vec<Piece>, Vec<f64>, f64), TrackError> {
        let bad = |key: String, value: String, problem: &str| TrackError::Invalid {
            origin: origin.into(),
            key,
            value,
            problem: problem.into(),
        };
        let st = spec.start;
        let mut pieces = Vec::with_capacity(spec.segments.len());
        let mut piece_s0 = Vec::with_capacity(spec.segments.len());
        let mut p = [st.x, st.y];
        let mut h = st.heading_deg.to_radians();
        let mut s = 0.0;
        for (i, seg) in spec.segments.iter().enumerate() {
            let piece = segment_piece(i, seg, p, h, outer, origin)?;
            piece_s0.push(s);
            s += piece.length();
            if s > limits::MAX_LENGTH_M {
                return Err(bad(
                    format!("segments[0..={i}]"),
                    format!("{s:.1} m"),
                    &format!("the centre line may be at most {} m long in all", limits::MAX_LENGTH_M),
                ));
            }
            let (end, heading) = piece.pose_at(piece.length());
            p = end;
            h = heading;
            pieces.push(piece);
        }
        let gap = ((p[0] - st.x).powi(2) + (p[1] - st.y).powi(2)).sqrt();
        let dh = wrap_pi(h - st.heading_deg.to_radians()).to_degrees();
        if gap > 0.005 || dh.abs() > 0.5 {
            return Err(TrackError::NotClosed {
                origin: origin.into(),
                detail: format!(
                    "segments[{}] ends at ({:.3}, {:.3}) heading {:.1} deg, but the start is ({:.3}, {:.3}) heading {:.1} deg ({:.3} m and {:.1} deg apart); adjust lengths, radii or angles so the turns add up to 360 deg and the ends meet",
                    spec.segments.len() - 1,
                    p[0],
                    p[1],
                    h.to_degrees().rem_euclid(360.0),
                    st.x,
                    st.y,
                    st.heading_deg.rem_euclid(360.0),
                    gap,
                    dh
                ),
            });
        }

        Ok((pieces, piece_s0, s))
    }

    /// The floor: the road's bounding box (the outer lines, `outer` from the centre line) plus
    /// `margin_m`, at most `limits::MAX_FLOOR_SIDE_M` a side.
    fn floor_rect(
        pieces: &[Piece],
        total: f64,
        outer: f64,
        margin_m: f64,
        origin: &str,
    ) -> Result<[f64; 4], TrackError> {
        let bad = |key: String, value: String, problem: &str| TrackError::Invalid {
            origin: origin.into(),
            key,
            value,
            problem: problem.into(),
        };
        let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        let n = (total / 0.02).ceil().max(8.0) as usize;
        for piece in pieces {
            let len = piece.length();
            let m = ((len / total) * n as f64).ceil().max(2.0) as usize;
            for j in 0..=m {
                let (q, hh) = piece.pose_at(len * j as f64 / m as f64);
                for side in [-outer, outer] {
                    let x = q[0] - side * hh.sin();
                    let y = q[1] + side * hh.cos();
                    bb = [bb[0].min(x), bb[1].min(y), bb[2].max(x), bb[3].max(y)];
                }
            }
        }
        let floor_rect = [bb[0] - margin_m, bb[1] - margin_m, bb[2] + margin_m, bb[3] + margin_m];
        let (fw, fh) = (floor_rect[2] - floor_rect[0], floor_rect[3] - floor_rect[1]);
        if !(fw <= limits::MAX_FLOOR_SIDE_M && fh <= limits::MAX_FLOOR_SIDE_M) {
            return Err(bad(
                "segments / floor.margin_m".into(),
                format!("a floor of {fw:.1} × {fh:.1} m"),
                &format!(
                    "the floor (the road's extent plus floor.margin_m each way) may be at most {0} × {0} m",
                    limits::MAX_FLOOR_SIDE_M
                ),
            ));
        }
        Ok(floor_rect)
    }

    /// Object `i` of a track file, checked (finite, on the floor `floor_rect`, sizes and
    /// heights in range, a light's phases > 0), with the registry's defaults filled in.
    fn place_object(i: usize, o: &ObjectSpec, floor_rect: [f64; 4], origin: &str) -> Result<Object, TrackError> {
        let bad = |key: String, value: String, problem: &str| TrackError::Invalid {
            origin: origin.into(),
            key,
            value,
            problem: problem.into(),
        };
        let key = |k: &str| format!("objects[{i}].{k}");
        if !(o.x.is_finite() && o.y.is_finite() && o.yaw_deg.is_finite()) {
            return Err(bad(
                key("x/y/yaw_deg"),
                format!("({}, {}, {})", o.x, o.y, o.yaw_deg),
                "must be finite",
            ));
        }
        if o.x < floor_rect[0] || o.x > floor_rect[2] || o.y < floor_rect[1] || o.y > floor_rect[3] {
            return Err(TrackError::OffMap {
                origin: origin.into(),
                index: i,
                kind: o.kind.name(),
                x: o.x,
                y: o.y,
                x0: floor_rect[0],
                x1: floor_rect[2],
                y0: floor_rect[1],
                y1: floor_rect[3],
            });
        }
        let info = o.kind.info();
        let used = info.shape.size_numbers();
        let size = match o.size_m.len() {
            0 => info.sim_size_m,
            n if n == used => {
                let mut size = [0.0; 3];
                size[..n].copy_from_slice(&o.size_m);
                size
            }
            n => {
                return Err(bad(
                    key("size_m"),
                    format!("{:?}", o.size_m),
                    &format!(
                        "a {} takes {} (got {n} numbers)",
                        o.kind.name(),
                        if used == 3 {
                            "[length, width, height]"
                        } else {
                            "one number"
                        }
                    ),
                ))
            }
        };
        if size[..used].iter().any(|v| !(*v > 0.005 && *v <= 3.0)) {
            return Err(bad(
                key("size_m"),
                format!("{:?}", o.size_m),
                "sizes must be 0.005..=3 m",
            ));
        }
        let height = o.height_m.unwrap_or(info.sim_height_m.unwrap_or(size[2] / 2.0));
        if !(height > 0.0 && height <= 3.0) {
            return Err(bad(key("height_m"), height.to_string(), "must be > 0 and <= 3 m"));
        }
        if info.reads_light && o.cycle_s.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
            return Err(bad(
                key("cycle_s"),
                format!("{:?}", o.cycle_s),
                "every phase must last > 0 s",
            ));
        }
        if o.arrow.is_some() && !info.reads_arrow {
            return Err(bad(
                key("arrow"),
                format!("{:?}", o.arrow.map_or("", |a| a.name())),
                &format!("only a turn sign takes `arrow`, not a {}", o.kind.name()),
            ));
        }
        Ok(Object {
            kind: o.kind,
            index: i,
            pos: [o.x, o.y],
            yaw: o.yaw_deg.to_radians(),
            size,
            height,
            color: o.color,
            cycle_s: o.cycle_s,
            phase_s: o.phase_s,
            arrow: info.reads_arrow.then(|| o.arrow.unwrap_or(TurnArrow::Right)),
        })
    }

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

    /// Half the width of one lane (centre to line centre), metres.
    pub fn half_lane(&self) -> f64 {
        self.spec.road.lane_width_m / 2.0
    }

    /// Objects that are drawn.
    pub fn enabled_objects(&self) -> impl Iterator<Item = &Object> {
        self.objects.iter().filter(|(_, e)| *e).map(|(o, _)| o)
    }

    /// Point and heading of the road's centre line at distance `s` (wrapped to the loop).
    pub fn pose_at(&self, s: f64) -> ([f64; 2], f64) {
        let s = s.rem_euclid(self.length);
        let main = self.roads[0].pieces.clone();
        let i = self.piece_s0[main].partition_point(|&s0| s0 <= s).saturating_sub(1);
        self.pieces[i].pose_at(s - self.piece_s0[i])
    }

    /// Point and heading of the centre of the driven lane at `s` (s measured on the road's
    /// centre line).
    pub fn lane_pose_at(&self, s: f64) -> ([f64; 2], f64) {
        let (p, h) = self.pose_at(s);
        let o = self.drive_offset;
        ([p[0] - o * h.sin(), p[1] + o * h.cos()], h)
    }

    /// The nearest point of the centre line to `p` (searching every piece).
    pub fn project(&self, p: [f64; 2]) -> Projection {
        let mut best = (f64::INFINITY, 0usize, 0.0, 0.0);
        for (i, piece) in self.pieces.iter().enumerate() {
            let (t, lat, out) = piece.project(p);
            let d = lat * lat + out * out;
            if d < best.0 {
                best = (d, i, t, lat);
            }
        }
        let (_, i, t, lat) = best;
        let (_, heading) = self.pieces[i].pose_at(t);
        Projection {
            s: self.piece_s0[i] + t,
            lateral: lat,
            heading,
            curvature: self.pieces[i].curvature(),
            piece: i,
            road: self.road_of(i),
        }
    }

    /// Signed lateral offset of `p` from the nearest point of the centre line (left
    /// positive), without the heading (cheaper than [`Track::project`]).
    pub fn lateral(&self, p: [f64; 2]) -> f64 {
        let mut best = (f64::INFINITY, 0.0);
        for piece in &self.pieces {
            let (_, lat, out) = piece.project(p);
            let d = lat * lat + out * out;
            if d < best.0 {
                best = (d, lat);
            }
        }
        best.1
    }

    /// The tightest radius of the driven lane's centre, metres.
    pub fn tightest_lane_radius(&self) -> f64 {
        self.pieces
            .iter()
            .filter_map(|p| match *p {
                Piece::Arc { radius, sweep, .. } => Some(radius - sweep.signum() * self.drive_offset),
                _ => None,
            })
            .fold(f64::INFINITY, f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const OVAL: &str = r#"
name = "oval"
[road]
lane_width_m = 0.3
lanes = 1
[[segments]]
type = "straight"
length_m = 2.0
[[segments]]
type = "arc"
radius_m = 1.0
angle_deg = 180
[[segments]]
type = "straight"
length_m = 2.0
[[segments]]
type = "arc"
radius_m = 1.0
angle_deg = 180
"#;

    #[test]
    fn oval_closes_and_measures() {
        let t = Track::from_toml_str(OVAL, "oval").unwrap();
        assert!((t.length - (4.0 + 2.0 * PI)).abs() < 1e-9);
        // Half way round the first arc: the top of the circle centred at (2, 1).
        let (p, h) = t.pose_at(2.0 + PI / 2.0);
        assert!((p[0] - 3.0).abs() < 1e-9 && (p[1] - 1.0).abs() < 1e-9, "{p:?}");
        assert!((wrap_pi(h - PI / 2.0)).abs() < 1e-9);
        // A point 0.1 m left of the first straight (inside the oval).
        let pr = t.project([1.0, 0.1]);
        assert!((pr.s - 1.0).abs() < 1e-9 && (pr.lateral - 0.1).abs() < 1e-9, "{pr:?}");
        // Inside the first arc, 0.05 m towards its centre: left of travel.
        let pr = t.project([2.0 + 0.95, 1.0]);
        assert!(
            (pr.lateral - 0.05).abs() < 1e-9 && (pr.s - (2.0 + PI / 2.0)).abs() < 1e-9,
            "{pr:?}"
        );
    }

    #[test]
    fn right_turns_have_negative_curvature_and_lateral_sign_follows_travel() {
        let text = OVAL.replace("angle_deg = 180", "angle_deg = -180");
        let t = Track::from_toml_str(&text, "cw").unwrap();
        let pr = t.project([2.0 + 0.95, -1.0]);
        assert!(pr.curvature < 0.0);
        // Towards the centre of a right turn is the right side: negative.
        assert!((pr.lateral + 0.05).abs() < 1e-9, "{pr:?}");
    }

    #[test]
    fn default_track_loads_with_curves_both_ways_and_objects() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml");
        let t = Track::load(&path).unwrap();
        let curv: Vec<f64> = t.pieces.iter().map(|p| p.curvature()).collect();
        assert!(curv.iter().any(|&c| c > 0.0) && curv.iter().any(|&c| c < 0.0));
        let kinds: Vec<ObjectClass> = t.enabled_objects().map(|o| o.kind).collect();
        for k in [ObjectClass::StopSign, ObjectClass::TrafficLight, ObjectClass::Obstacle] {
            assert!(kinds.contains(&k), "{k:?} missing");
        }
        assert!(t.tightest_lane_radius() >= 2.8, "{}", t.tightest_lane_radius());
    }

    #[test]
    fn traffic_light_cycles() {
        let t = Track::from_toml_str(
            &format!("{OVAL}\n[[objects]]\ntype = \"traffic_light\"\nx = 1.0\ny = -0.5\ncycle_s = [2.0, 1.0, 3.0]\n"),
            "t",
        )
        .unwrap();
        let o = &t.objects[0].0;
        assert_eq!(o.light_state(0.5), LightState::Green);
        assert_eq!(o.light_state(2.5), LightState::Amber);
        assert_eq!(o.light_state(4.0), LightState::Red);
        assert_eq!(o.light_state(6.5), LightState::Green);
    }

    #[test]
    fn marks_parse_default_check_and_lie_ahead() {
        let mark = |extra: &str| format!("{OVAL}\n[[marks]]\ntype = \"stop_line\"\nx = 1.5\ny = 0.0\n{extra}");
        let t = Track::from_toml_str(&mark(""), "m").unwrap();
        let m = t.marks[0];
        assert_eq!(m.kind, MarkKind::StopLine);
        assert!(
            (m.length - 0.32).abs() < 1e-12 && (m.width - 0.05).abs() < 1e-12,
            "{m:?}"
        );
        // From (1.0, 0.0) heading east the near edge is 0.475 m ahead; heading west none.
        let a = t.mark_ahead([1.0, 0.0], 0.0).unwrap();
        assert!((a.distance_m - 0.475).abs() < 1e-12, "{a:?}");
        assert!(t.mark_ahead([1.0, 0.0], PI).is_none());
        assert!(t.mark_ahead([1.0, 0.3], 0.0).is_none(), "beside the line");
        assert!(t.mark_ahead([1.6, 0.0], 0.0).is_none(), "passed");
        let t = Track::from_toml_str(
            &mark("type = \"yield_line\"").replace("type = \"stop_line\"\n", ""),
            "m",
        )
        .unwrap();
        assert!(t.marks[0].dashed());
        // Checks name the key (and an unknown key its line).
        let e = Track::from_toml_str(&mark("length_m = 9.0"), "m")
            .unwrap_err()
            .to_string();
        assert!(e.contains("marks[0].length_m"), "{e}");
        let e = Track::from_toml_str(&mark("width_m = 0.0"), "m")
            .unwrap_err()
            .to_string();
        assert!(e.contains("marks[0].width_m"), "{e}");
        let e = Track::from_toml_str(&mark("").replace("x = 1.5", "x = 40.0"), "m")
            .unwrap_err()
            .to_string();
        assert!(e.contains("marks[0].x/y") && e.contains("off the map"), "{e}");
        let e = Track::from_toml_str(&mark("colour = 3"), "m").unwrap_err().to_string();
        assert!(e.contains("colour") && e.contains("line"), "{e}");
    }
}
