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
use serde::Deserialize;
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// Bounds on what a track file may ask for, checked before anything is allocated: the
/// simulator's scene keeps a 2 cm grid over the whole floor (4 bytes a cell), so a 50 m ×
/// 50 m floor is 25 MB; a classroom track is a few metres.
pub mod limits {
    /// Most `[[segments]]`.
    pub const MAX_SEGMENTS: usize = 1000;
    /// Most `[[objects]]`.
    pub const MAX_OBJECTS: usize = 1000;
    /// Longest straight, metres.
    pub const MAX_STRAIGHT_M: f64 = 50.0;
    /// Largest arc radius, metres.
    pub const MAX_RADIUS_M: f64 = 20.0;
    /// Longest centre line (sum of all segments), metres.
    pub const MAX_LENGTH_M: f64 = 500.0;
    /// Largest floor side (the road's extent plus `floor.margin_m` each way), metres.
    pub const MAX_FLOOR_SIDE_M: f64 = 50.0;
    /// Largest distance of `[start]` from the origin, metres.
    pub const MAX_COORD_M: f64 = 10_000.0;
}

/// Everything that can be wrong with a track file.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    /// The file could not be read.
    #[error("{path}: cannot read: {error}")]
    Io {
        /// The track file.
        path: PathBuf,
        /// Underlying error (in the message, not repeated as a source).
        error: std::io::Error,
    },
    /// TOML syntax, an unknown key or a value of the wrong type (the message names the key
    /// and the line).
    #[error("{origin}: {message}")]
    Parse {
        /// File name.
        origin: String,
        /// What is wrong and where.
        message: String,
    },
    /// A value outside what makes sense.
    #[error("{origin}: `{key}` = {value}: {problem}")]
    Invalid {
        /// File name.
        origin: String,
        /// Dotted key, e.g. `segments[3].radius` (indices from 0, in file order).
        key: String,
        /// The value as read.
        value: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The chain of segments does not end where it began.
    #[error("{origin}: the segments do not join up into a closed loop: {detail}")]
    NotClosed {
        /// File name.
        origin: String,
        /// Where the last segment ends compared with the start.
        detail: String,
    },
    /// An object stands outside the floor.
    #[error("{origin}: objects[{index}] ({kind}) at ({x:.2}, {y:.2}) m is off the map; the floor spans x {x0:.2}..{x1:.2}, y {y0:.2}..{y1:.2} m")]
    OffMap {
        /// File name.
        origin: String,
        /// Index of the object in file order, from 0.
        index: usize,
        /// `stop_sign`, `traffic_light` or `obstacle`.
        kind: &'static str,
        /// Its position, metres.
        x: f64,
        /// Its position, metres.
        y: f64,
        /// Floor extent, metres.
        x0: f64,
        /// Floor extent, metres.
        x1: f64,
        /// Floor extent, metres.
        y0: f64,
        /// Floor extent, metres.
        y1: f64,
    },
}

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

/// One `[[segments]]` table: a straight or an arc.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum SegmentSpec {
    /// A straight of `length_m`.
    Straight {
        /// Metres, > 0.
        length_m: f64,
    },
    /// A circular arc of `radius_m` turning `angle_deg` (positive = left, negative = right).
    Arc {
        /// Radius of the road's centre line, metres, > 0.
        radius_m: f64,
        /// Degrees turned; positive turns left (counter-clockwise).
        angle_deg: f64,
    },
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

/// A piece of the centre line, placed in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Piece {
    /// From `p0` along unit direction `dir` for `len` metres.
    Line {
        /// Start point.
        p0: [f64; 2],
        /// Unit direction.
        dir: [f64; 2],
        /// Length, metres.
        len: f64,
    },
    /// Around `center` at `radius`, from angle `a0` (of the start point seen from the
    /// centre) sweeping `sweep` radians (positive = counter-clockwise = left turn).
    Arc {
        /// Centre of the circle.
        center: [f64; 2],
        /// Radius, metres.
        radius: f64,
        /// Polar angle of the start point around `center`.
        a0: f64,
        /// Signed angle swept.
        sweep: f64,
    },
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
}

impl Piece {
    /// Length along the centre line, metres.
    pub fn length(&self) -> f64 {
        match *self {
            Piece::Line { len, .. } => len,
            Piece::Arc { radius, sweep, .. } => radius * sweep.abs(),
        }
    }

    /// Point and heading at distance `t` (0..length) along this piece.
    pub fn pose_at(&self, t: f64) -> ([f64; 2], f64) {
        match *self {
            Piece::Line { p0, dir, .. } => ([p0[0] + dir[0] * t, p0[1] + dir[1] * t], dir[1].atan2(dir[0])),
            Piece::Arc {
                center,
                radius,
                a0,
                sweep,
            } => {
                let sg = sweep.signum();
                let a = a0 + sg * t / radius;
                (
                    [center[0] + radius * a.cos(), center[1] + radius * a.sin()],
                    a + sg * PI / 2.0,
                )
            }
        }
    }

    /// Projects `p` onto this piece: (t along it, clamped to 0..length; signed lateral
    /// offset, left positive; distance from the piece's infinite extension's clamp point).
    /// Also returns how far outside the piece's range the foot falls (0 when inside).
    #[inline]
    pub fn project(&self, p: [f64; 2]) -> (f64, f64, f64) {
        match *self {
            Piece::Line { p0, dir, len } => {
                let (dx, dy) = (p[0] - p0[0], p[1] - p0[1]);
                let t = dx * dir[0] + dy * dir[1];
                let lat = dir[0] * dy - dir[1] * dx;
                let out = if t < 0.0 {
                    -t
                } else if t > len {
                    t - len
                } else {
                    0.0
                };
                (t.clamp(0.0, len), lat, out)
            }
            Piece::Arc {
                center,
                radius,
                a0,
                sweep,
            } => {
                let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
                let r = (dx * dx + dy * dy).sqrt();
                let sg = sweep.signum();
                // Angle travelled from the start, in the direction of travel, in (-π, π]
                // around the arc's middle so points before the start come out negative.
                let mid = a0 + sweep / 2.0;
                let rel = wrap_pi(dy.atan2(dx) - mid) * sg + sweep.abs() / 2.0;
                let t = rel * radius;
                let len = radius * sweep.abs();
                // Left of travel is towards the centre on a left turn, away on a right turn.
                let lat = sg * (radius - r);
                let out = if t < 0.0 {
                    -t
                } else if t > len {
                    t - len
                } else {
                    0.0
                };
                (t.clamp(0.0, len), lat, out)
            }
        }
    }

    /// Curvature, 1/m, positive when turning left.
    pub fn curvature(&self) -> f64 {
        match *self {
            Piece::Line { .. } => 0.0,
            Piece::Arc { radius, sweep, .. } => sweep.signum() / radius,
        }
    }
}

/// Wraps an angle into (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    let mut a = a % TAU;
    if a <= -PI {
        a += TAU;
    } else if a > PI {
        a -= TAU;
    }
    a
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
    /// The centre line, in driving order.
    pub pieces: Vec<Piece>,
    /// Distance along the centre line at the start of each piece, metres.
    pub piece_s0: Vec<f64>,
    /// Total length of the road's centre line, metres.
    pub length: f64,
    /// Lateral offsets (left positive) of the painted line centres from the road's centre
    /// line, metres, with whether each is the dashed centre line.
    pub lines: Vec<(f64, bool)>,
    /// Lateral offset of the centre of the lane the car drives in, metres (negative = right).
    pub drive_offset: f64,
    /// The floor's rectangle [x0, y0, x1, y1], metres.
    pub floor_rect: [f64; 4],
    /// Every object in the file (disabled ones too; see [`Object`] and `enabled`).
    pub objects: Vec<(Object, bool)>,
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
        let (pieces, piece_s0, total) = Self::chain(&spec, outer, origin)?;

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

        Ok(Track {
            name: if spec.name.is_empty() {
                origin.to_string()
            } else {
                spec.name.clone()
            },
            pieces,
            piece_s0,
            length: total,
            lines,
            drive_offset,
            floor_rect,
            objects,
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
            let piece = Self::segment_piece(i, seg, p, h, outer, origin)?;
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

    /// Segment `i` as a piece starting at `p` with heading `h` (radians), checked (`outer` =
    /// the outer lines' distance from the centre line, which an arc's radius must exceed).
    fn segment_piece(
        i: usize,
        seg: &SegmentSpec,
        p: [f64; 2],
        h: f64,
        outer: f64,
        origin: &str,
    ) -> Result<Piece, TrackError> {
        let bad = |key: String, value: String, problem: &str| TrackError::Invalid {
            origin: origin.into(),
            key,
            value,
            problem: problem.into(),
        };
        Ok(match *seg {
            SegmentSpec::Straight { length_m } => {
                if !(length_m > 1e-6 && length_m.is_finite()) {
                    return Err(bad(
                        format!("segments[{i}].length_m"),
                        length_m.to_string(),
                        "a straight must be longer than zero",
                    ));
                }
                if length_m > limits::MAX_STRAIGHT_M {
                    return Err(bad(
                        format!("segments[{i}].length_m"),
                        length_m.to_string(),
                        &format!("a straight may be at most {} m long", limits::MAX_STRAIGHT_M),
                    ));
                }
                Piece::Line {
                    p0: p,
                    dir: [h.cos(), h.sin()],
                    len: length_m,
                }
            }
            SegmentSpec::Arc { radius_m, angle_deg } => {
                if !(radius_m > 1e-6 && radius_m.is_finite()) {
                    return Err(bad(
                        format!("segments[{i}].radius_m"),
                        radius_m.to_string(),
                        "an arc needs a radius greater than zero",
                    ));
                }
                if radius_m > limits::MAX_RADIUS_M {
                    return Err(bad(
                        format!("segments[{i}].radius_m"),
                        radius_m.to_string(),
                        &format!("an arc's radius may be at most {} m", limits::MAX_RADIUS_M),
                    ));
                }
                if !(angle_deg.abs() > 1e-6 && angle_deg.abs() <= 360.0) {
                    return Err(bad(
                        format!("segments[{i}].angle_deg"),
                        angle_deg.to_string(),
                        "an arc must turn by a non-zero angle of at most 360 degrees",
                    ));
                }
                if radius_m <= outer {
                    return Err(bad(
                        format!("segments[{i}].radius_m"),
                        radius_m.to_string(),
                        &format!("the road's outer lines are {outer:.3} m from its centre line, so the radius must be larger"),
                    ));
                }
                let sg = angle_deg.signum();
                // The centre lies to the left of travel on a left turn.
                let center = [p[0] - sg * radius_m * h.sin(), p[1] + sg * radius_m * h.cos()];
                Piece::Arc {
                    center,
                    radius: radius_m,
                    a0: (p[1] - center[1]).atan2(p[0] - center[0]),
                    sweep: angle_deg.to_radians(),
                }
            }
        })
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
        let i = self.piece_s0.partition_point(|&s0| s0 <= s).saturating_sub(1);
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
}
