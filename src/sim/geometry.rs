//! The geometry a track is built from, below the track (src/sim/track.rs) and its road
//! network (src/sim/network.rs): the segments a file lists, the pieces they become in the
//! world (straights and circular arcs), the bounds on what a file may ask for, and the errors
//! loading reports.
//!
//! Units: metres and radians inside, degrees in files. World frame: x east, y north, z up;
//! headings counter-clockwise from +x. Lateral offsets are positive to the left of travel.

use serde::Deserialize;
use std::f64::consts::{PI, TAU};
use std::path::PathBuf;

/// Bounds on what a track file may ask for, checked before anything is allocated: the
/// simulator's scene keeps a 2 cm grid over the whole floor (4 bytes a cell), so a 50 m ×
/// 50 m floor is 25 MB; a classroom track is a few metres.
pub mod limits {
    /// Most `[[segments]]`.
    pub const MAX_SEGMENTS: usize = 1000;
    /// Most `[[marks]]`.
    pub const MAX_MARKS: usize = 1000;
    /// A mark's `length_m` (across the lane): 0.02..=this, metres.
    pub const MAX_MARK_LENGTH_M: f64 = 5.0;
    /// A mark's `width_m` (along the road): 0.005..=this, metres.
    pub const MAX_MARK_WIDTH_M: f64 = 0.5;
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

/// Segment `i` as a piece starting at `p` with heading `h` (radians), checked (`outer` =
/// the outer lines' distance from the centre line, which an arc's radius must exceed).
pub fn segment_piece(
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

