//! What the simulated camera looks at: the floor with its texture and lighting, the painted
//! lane lines, the room's walls, and the placed objects as simple solids (boxes and flat
//! panels). Everything here is static for a track and shared by every camera that renders
//! it (a second, stereo camera builds its own [`super::render::Renderer`] on the same scene).
//!
//! Shading, in order:
//! 1. floor: a mottled texture (value noise, several octaves, tiled) times a smooth
//!    illumination map (a few soft overhead lamps), so the floor is not a flat colour;
//! 2. lines: analytic box-filter coverage of each line across the pixel's footprint on the
//!    floor (the footprint comes from the pixel's Jacobian), which anti-aliases the edges at
//!    any distance; dashes are filtered along the line the same way;
//! 3. walls: where a ray leaves the floor's rectangle it meets a wall (a skirting board, then
//!    plain paint), above the walls a ceiling;
//! 4. objects: ray–box and ray–panel intersections, shaded by a fixed light direction.
//!
//! Units: metres, world frame (x east, y north, z up); colours linear 0..255 as f32.

use super::glyphs;
use super::rng::{mix, SplitMix64};
use super::track::{FloorSpec, Mark, Object, Piece, Track, YIELD_DASH_M, YIELD_GAP_M};
use crate::classes::SimShape;

/// Side of one cell of the grid that tells which centre-line piece is near, metres.
const CELL_M: f64 = 0.02;
/// Texels of the floor texture tile per side (a power of two).
const TEX_N: usize = 512;
/// Size of one texel, metres.
const TEX_M: f64 = 0.01;
/// Side of one cell of the illumination map, metres.
const ILLUM_M: f64 = 0.1;
const INV_CELL: f64 = 1.0 / CELL_M;
const INV_TEX: f64 = 1.0 / TEX_M;
const INV_ILLUM: f64 = 1.0 / ILLUM_M;
/// Height of the walls, metres.
const WALL_H: f64 = 1.2;
/// Height of the skirting board, metres.
const SKIRT_H: f64 = 0.06;

/// The static scene for one track.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The track it was built from.
    pub track: Track,
    floor_rgb: [f32; 3],
    wall_rgb: [f32; 3],
    texture_amp: f32,
    /// The tile, −1..1 scaled to i8 (a quarter of the memory of f32, stays in cache).
    texture: Vec<i8>,
    illum: Vec<f32>,
    illum_w: usize,
    illum_h: usize,
    /// For each grid cell: the index of the nearest piece (`u16::MAX` when no line is near),
    /// and how far every point of the cell is from the nearest line's edge, in 0.1 mm (0 when
    /// a line may touch it; a pixel whose footprint is smaller skips the lines). One 4-byte
    /// load per pixel.
    grid: Vec<(u16, u16)>,
    /// Lower bound of the distance from any point of a cell with no piece near to the nearest
    /// line's edge, metres.
    far_clear: f32,
    /// For each piece: the unit vector from an arc's centre to its middle ([1, 0] for lines).
    arc_mid: Vec<[f64; 2]>,
    grid_w: usize,
    grid_h: usize,
    /// Line centre offsets, half widths, dashed flag and colour.
    lines: Vec<LinePaint>,
    /// The track's floor markings (`[[marks]]`) and their paint.
    marks: Vec<(Mark, [f32; 3])>,
}

#[derive(Debug, Clone, Copy)]
struct LinePaint {
    offset: f64,
    half_width: f64,
    dashed: bool,
    rgb: [f32; 3],
}

/// A pixel's footprint on the floor, world frame.
#[derive(Debug, Clone, Copy)]
pub struct Footprint {
    /// World metres per pixel step in u.
    pub ju: [f64; 2],
    /// World metres per pixel step in v.
    pub jv: [f64; 2],
    /// |ju| + |jv|, metres: an upper bound of the footprint's width in any direction.
    pub size: f32,
    /// How much floor texture survives filtering at this footprint, 0..1.
    pub fade: f32,
}

impl Footprint {
    /// Size of one texture texel, metres.
    pub const TEXEL_M: f64 = TEX_M;

    /// The fade of a texture of `TEX_M` texels under a footprint of `size` metres.
    pub fn fade_for(size: f64) -> f32 {
        (3.0 * TEX_M / size.max(1e-9)).min(1.0) as f32
    }
}

/// A solid the renderer can intersect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Prim {
    /// A box turned by `dir` about the vertical through `center`.
    Box {
        /// Centre, metres.
        center: [f64; 3],
        /// Half sizes along its own x, y, z, metres.
        half: [f64; 3],
        /// (cos, sin) of its turn about z.
        dir: [f64; 2],
        /// Base colour.
        rgb: [f32; 3],
    },
    /// A flat vertical panel facing `dir` (its front normal), centred at `center`.
    Panel {
        /// Centre, metres.
        center: [f64; 3],
        /// (cos, sin) of the direction of its front normal.
        dir: [f64; 2],
        /// Outline and paint.
        kind: PanelKind,
    },
}

impl Prim {
    /// Eight points whose convex hull holds the solid (world frame, metres), for the renderer
    /// to bound the pixels it can cover.
    pub fn bounds(&self) -> [[f64; 3]; 8] {
        let (center, [c, s], h) = match *self {
            Prim::Box { center, half, dir, .. } => (center, dir, half),
            Prim::Panel { center, dir, kind } => {
                // A flat panel: depth 0 along its normal; half size across and up.
                let r = match kind {
                    PanelKind::StopFace { width } | PanelKind::YieldFace { width } => width / 2.0,
                    PanelKind::Lamp { radius, .. } => radius,
                    PanelKind::ArrowDisc { diameter, .. } => diameter / 2.0,
                };
                (center, dir, [0.0, r, r])
            }
        };
        let mut out = [[0.0; 3]; 8];
        for (k, p) in out.iter_mut().enumerate() {
            let lx = if k & 1 == 0 { -h[0] } else { h[0] };
            let ly = if k & 2 == 0 { -h[1] } else { h[1] };
            let lz = if k & 4 == 0 { -h[2] } else { h[2] };
            *p = [center[0] + c * lx - s * ly, center[1] + s * lx + c * ly, center[2] + lz];
        }
        out
    }
}

/// The outlines and paints of panels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PanelKind {
    /// A stop sign's face: a regular octagon `width` across the flats, red with a white rim
    /// and STOP in white.
    StopFace {
        /// Across the flats, metres.
        width: f64,
    },
    /// A yield sign's face: an inverted equilateral triangle whose top edge is `width` long,
    /// white with a red border, centred on its bounding box.
    YieldFace {
        /// The top edge, metres.
        width: f64,
    },
    /// A turn sign's face: a blue disc with a white rim and a white arrow pointing left
    /// (`right` false) or right.
    ArrowDisc {
        /// The disc's diameter, metres.
        diameter: f64,
        /// The arrow points to the viewer's right.
        right: bool,
    },
    /// A round lamp of `radius`; bright when lit.
    Lamp {
        /// Radius, metres.
        radius: f64,
        /// Lamp colour when lit.
        rgb: [f32; 3],
        /// Whether it is on.
        lit: bool,
    },
}

/// A hit of a ray on a primitive.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Ray parameter (distance for a unit direction).
    pub t: f64,
    /// Colour, already shaded (not yet exposed).
    pub rgb: [f32; 3],
}

impl Scene {
    /// Builds the scene for `track` (textures, lighting and the piece grid; tens of ms).
    pub fn new(track: &Track) -> Scene {
        let spec = &track.spec;
        let f = |c: [u8; 3]| [c[0] as f32, c[1] as f32, c[2] as f32];
        let texture = floor_texture(&spec.floor);
        let (illum, illum_w, illum_h) = illumination(track.floor_rect, spec.floor.seed);

        // 3. Lines, and the grid of nearest pieces where any line is near.
        let r = &spec.road;
        let hw = r.line_width_m / 2.0;
        let lines: Vec<LinePaint> = track
            .lines
            .iter()
            .map(|&(offset, dashed)| LinePaint {
                offset,
                half_width: hw,
                dashed,
                rgb: f(if offset == 0.0 {
                    r.centre_line_color
                } else {
                    r.line_color
                }),
            })
            .collect();
        let (grid, grid_w, grid_h, far_clear) = piece_grid(track, &lines);

        Scene {
            track: track.clone(),
            floor_rgb: f(spec.floor.color),
            wall_rgb: f(spec.floor.wall_color),
            texture_amp: spec.floor.texture as f32,
            texture,
            illum,
            illum_w,
            illum_h,
            grid,
            far_clear,
            arc_mid: track
                .pieces
                .iter()
                .map(|p| match *p {
                    Piece::Arc { a0, sweep, .. } => {
                        let (s, c) = (a0 + sweep / 2.0).sin_cos();
                        [c, s]
                    }
                    Piece::Line { .. } => [1.0, 0.0],
                })
                .collect(),
            grid_w,
            grid_h,
            lines,
            marks: track.marks.iter().map(|m| (*m, f(r.line_color))).collect(),
        }
    }

    /// Texture value at a world point, −1..1 (bilinear on the tiled texture).
    #[inline]
    pub fn texture_at(&self, p: [f64; 2]) -> f32 {
        // Shift to positive coordinates so truncation is floor (the tile repeats anyway).
        const SHIFT: f64 = (TEX_N * 1024) as f64;
        let (x, y) = (p[0] * INV_TEX + SHIFT, p[1] * INV_TEX + SHIFT);
        let (ix, iy) = (x as usize, y as usize);
        let (ax, ay) = ((x - ix as f64) as f32, (y - iy as f64) as f32);
        let m = TEX_N - 1;
        let (i, j) = (ix & m, iy & m);
        let (i1, j1) = ((i + 1) & m, (j + 1) & m);
        let t = &self.texture;
        let at = |k: usize| t[k] as f32;
        let top = at(j * TEX_N + i) + (at(j * TEX_N + i1) - at(j * TEX_N + i)) * ax;
        let bot = at(j1 * TEX_N + i) + (at(j1 * TEX_N + i1) - at(j1 * TEX_N + i)) * ax;
        (top + (bot - top) * ay) * (1.0 / 127.0)
    }

    /// Illumination factor at a floor point (about 0.85..1.2).
    #[inline]
    pub fn illumination(&self, p: [f64; 2]) -> f32 {
        let [x0, y0, _, _] = self.track.floor_rect;
        // The map reaches two cells past the floor; `min` only guards points off it.
        let x = (((p[0] - x0) * INV_ILLUM) as f32)
            .max(0.0)
            .min((self.illum_w - 2) as f32);
        let y = (((p[1] - y0) * INV_ILLUM) as f32)
            .max(0.0)
            .min((self.illum_h - 2) as f32);
        let (i, j) = (x as usize, y as usize);
        let (ax, ay) = (x - i as f32, y - j as f32);
        let w = self.illum_w;
        let l = &self.illum;
        let top = l[j * w + i] * (1.0 - ax) + l[j * w + i + 1] * ax;
        let bot = l[(j + 1) * w + i] * (1.0 - ax) + l[(j + 1) * w + i + 1] * ax;
        top * (1.0 - ay) + bot * ay
    }

    /// Whether a world point is on the floor (inside the walls).
    #[inline]
    pub fn on_floor(&self, p: [f64; 2]) -> bool {
        let r = &self.track.floor_rect;
        p[0] >= r[0] && p[0] <= r[2] && p[1] >= r[1] && p[1] <= r[3]
    }

    /// Colour of bare floor (no line near) with texture value `tex`, lit by `light`: what
    /// [`Scene::floor_color`] gives where it does not probe for lines.
    #[inline(always)]
    pub fn plain_floor(&self, light: f32, tex: f32) -> [f32; 3] {
        let b = 1.0 + self.texture_amp * tex;
        let c = [self.floor_rgb[0] * b, self.floor_rgb[1] * b, self.floor_rgb[2] * b];
        [c[0] * light, c[1] * light, c[2] * light]
    }

    /// Colour of the floor at world point `p`, seen by a pixel whose footprint on the floor is
    /// `fp` (see [`Footprint`]), lit by `light` (see [`Scene::illumination`]; smooth, so the
    /// renderer interpolates it along a row).
    ///
    /// `tex` is the texture there, already faded for the footprint (see
    /// [`Scene::texture_at`] and [`Footprint::fade`]); the renderer samples it about once
    /// per texel along a row and interpolates, which is what bilinear filtering does anyway.
    ///
    /// With `probe` false the lines are not looked up (the caller knows none is within the
    /// footprint). Also returns a lower bound of the distance from `p` to the nearest line's
    /// edge, metres, when it exceeds the footprint (else 0): every floor point within that
    /// distance minus the footprint needs no probe either.
    #[inline]
    pub fn floor_color(&self, p: [f64; 2], fp: &Footprint, light: f32, tex: f32, probe: bool) -> ([f32; 3], f32) {
        // 1. Texture.
        let b = 1.0 + self.texture_amp * tex;
        let mut c = [self.floor_rgb[0] * b, self.floor_rgb[1] * b, self.floor_rgb[2] * b];
        // 2. Lines, only where the cell is not clear of them by more than the footprint.
        if !probe {
            return ([c[0] * light, c[1] * light, c[2] * light], 0.0);
        }
        let [x0, y0, _, _] = self.track.floor_rect;
        let gi = ((p[0] - x0) * INV_CELL) as usize;
        let gj = ((p[1] - y0) * INV_CELL) as usize;
        let cell = if gi < self.grid_w && gj < self.grid_h {
            gj * self.grid_w + gi
        } else {
            usize::MAX
        };
        let (k, clear) = if cell != usize::MAX {
            self.grid[cell]
        } else {
            (u16::MAX, 0)
        };
        let clear_m = if k == u16::MAX {
            if cell == usize::MAX {
                0.0
            } else {
                self.far_clear
            }
        } else {
            clear as f32 * 1e-4
        };
        if clear_m > fp.size {
            return ([c[0] * light, c[1] * light, c[2] * light], clear_m);
        }
        if k != u16::MAX {
            let k = k as usize;
            let piece = &self.track.pieces[k];
            let (lat, n, tan) = match *piece {
                Piece::Line { p0, dir, .. } => {
                    let (dx, dy) = (p[0] - p0[0], p[1] - p0[1]);
                    (dir[0] * dy - dir[1] * dx, [-dir[1], dir[0]], dir)
                }
                Piece::Arc {
                    center, radius, sweep, ..
                } => {
                    let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
                    let r = (dx * dx + dy * dy).sqrt().max(1e-9);
                    let n = [dx / r, dy / r];
                    (sweep.signum() * (radius - r), n, [-n[1], n[0]])
                }
            };
            let (ju, jv) = (fp.ju, fp.jv);
            let fw = ((n[0] * ju[0] + n[1] * ju[1]).abs() + (n[0] * jv[0] + n[1] * jv[1]).abs()).max(1e-5);
            let tape = 1.0 + 0.25 * self.texture_amp * tex;
            for line in &self.lines {
                let d = lat - line.offset;
                if d.abs() > line.half_width + fw {
                    continue;
                }
                let mut cov = box_coverage(d, fw, line.half_width);
                if line.dashed && cov > 0.0 {
                    let ft =
                        ((tan[0] * ju[0] + tan[1] * ju[1]).abs() + (tan[0] * jv[0] + tan[1] * jv[1]).abs()).max(1e-5);
                    // Distance along the piece; on an arc the angle from the arc's middle by a
                    // fast atan2 (the exact one costs more than the rest of the pixel).
                    let t = match *piece {
                        Piece::Line { p0, dir, .. } => (p[0] - p0[0]) * dir[0] + (p[1] - p0[1]) * dir[1],
                        Piece::Arc { radius, sweep, .. } => {
                            let m = self.arc_mid[k];
                            let rel = fast_atan2(m[0] * n[1] - m[1] * n[0], m[0] * n[0] + m[1] * n[1]);
                            (sweep.signum() * rel + sweep.abs() / 2.0) * radius
                        }
                    };
                    let s = self.track.piece_s0[k] + t;
                    let r = &self.track.spec.road;
                    cov *= dash_coverage(s, ft, r.dash_m, r.dash_m + r.gap_m);
                }
                if cov > 0.0 {
                    let cf = cov as f32;
                    for (ch, lc) in c.iter_mut().zip(line.rgb) {
                        *ch += (lc * tape - *ch) * cf;
                    }
                }
            }
            if !self.marks.is_empty() {
                self.paint_marks(p, fp, tape, &mut c);
            }
        }
        // 3. Light.
        ([c[0] * light, c[1] * light, c[2] * light], 0.0)
    }

    /// The floor markings over `c` at `p`: the same box-filter coverage as the lane lines, along
    /// the road (the line's width) and across it (its length; a yield line's dashes filtered
    /// the same way as the centre line's).
    fn paint_marks(&self, p: [f64; 2], fp: &Footprint, tape: f32, c: &mut [f32; 3]) {
        let (ju, jv) = (fp.ju, fp.jv);
        for (m, rgb) in &self.marks {
            let (d, n) = (m.dir, [-m.dir[1], m.dir[0]]);
            let fa = ((d[0] * ju[0] + d[1] * ju[1]).abs() + (d[0] * jv[0] + d[1] * jv[1]).abs()).max(1e-5);
            let fc = ((n[0] * ju[0] + n[1] * ju[1]).abs() + (n[0] * jv[0] + n[1] * jv[1]).abs()).max(1e-5);
            let (along, across) = m.local(p);
            if along.abs() > m.width / 2.0 + fa || across.abs() > m.length / 2.0 + fc {
                continue;
            }
            let mut cov = box_coverage(along, fa, m.width / 2.0) * box_coverage(across, fc, m.length / 2.0);
            if m.dashed() && cov > 0.0 {
                cov *= dash_coverage(across + m.length / 2.0, fc, YIELD_DASH_M, YIELD_DASH_M + YIELD_GAP_M);
            }
            if cov > 0.0 {
                let cf = cov as f32;
                for (ch, lc) in c.iter_mut().zip(rgb) {
                    *ch += (lc * tape - *ch) * cf;
                }
            }
        }
    }

    /// Signed lateral offset of a floor point from the road's centre line (left positive),
    /// through the piece grid: no search and no trigonometry. Within 0.2 mm of
    /// [`Track::lateral`](super::track::Track::lateral) near the road; falls back to it
    /// elsewhere.
    pub fn lateral(&self, p: [f64; 2]) -> f64 {
        let [x0, y0, _, _] = self.track.floor_rect;
        let (gi, gj) = (((p[0] - x0) * INV_CELL), ((p[1] - y0) * INV_CELL));
        if gi >= 0.0 && gj >= 0.0 && (gi as usize) < self.grid_w && (gj as usize) < self.grid_h {
            let k = self.grid[gj as usize * self.grid_w + gi as usize].0;
            if k != u16::MAX {
                return match self.track.pieces[k as usize] {
                    Piece::Line { p0, dir, .. } => dir[0] * (p[1] - p0[1]) - dir[1] * (p[0] - p0[0]),
                    Piece::Arc {
                        center, radius, sweep, ..
                    } => sweep.signum() * (radius - (p[0] - center[0]).hypot(p[1] - center[1])),
                };
            }
        }
        self.track.lateral(p)
    }

    /// Colour where a ray from `o` along `d` leaves the room: wall or ceiling.
    pub fn wall_color(&self, o: [f64; 3], d: [f64; 3]) -> [f32; 3] {
        let r = &self.track.floor_rect;
        let tx = if d[0] > 0.0 {
            (r[2] - o[0]) / d[0]
        } else if d[0] < 0.0 {
            (r[0] - o[0]) / d[0]
        } else {
            f64::INFINITY
        };
        let ty = if d[1] > 0.0 {
            (r[3] - o[1]) / d[1]
        } else if d[1] < 0.0 {
            (r[1] - o[1]) / d[1]
        } else {
            f64::INFINITY
        };
        let t = tx.min(ty).max(0.0);
        let z = o[2] + t * d[2];
        let w = self.wall_rgb;
        if z > WALL_H || !t.is_finite() {
            // Ceiling: a little darker than the walls.
            return [w[0] * 0.8, w[1] * 0.8, w[2] * 0.82];
        }
        if z < SKIRT_H {
            return [w[0] * 0.35, w[1] * 0.33, w[2] * 0.3];
        }
        // Light falls off up the wall; the two wall orientations are lit differently.
        let side = if tx < ty { 1.0 } else { 0.9 };
        let k = (side * (0.95 - 0.2 * (z / WALL_H))) as f32;
        [w[0] * k, w[1] * k, w[2] * k]
    }

    /// The solids of one object at time `t_s` (a traffic light's lamps change), appended to
    /// `out`.
    pub fn object_prims(&self, o: &Object, t_s: f64, out: &mut Vec<Prim>) {
        let [x, y] = o.pos;
        let (s, c) = o.yaw.sin_cos();
        match o.kind.info().shape {
            SimShape::Octagon => {
                let w = o.size[0];
                out.push(Prim::Box {
                    center: [x, y, (o.height - w / 2.0) / 2.0],
                    half: [0.006, 0.006, (o.height - w / 2.0) / 2.0],
                    dir: [c, s],
                    rgb: [150.0, 150.0, 155.0],
                });
                out.push(Prim::Panel {
                    center: [x + 0.007 * c, y + 0.007 * s, o.height],
                    dir: [c, s],
                    kind: PanelKind::StopFace { width: w },
                });
            }
            SimShape::LightHousing => {
                let h = o.size[0];
                let (hw, hd) = (h * 0.38, h * 0.33);
                out.push(Prim::Box {
                    center: [x, y, (o.height - h / 2.0) / 2.0],
                    half: [0.007, 0.007, (o.height - h / 2.0) / 2.0],
                    dir: [c, s],
                    rgb: [70.0, 72.0, 75.0],
                });
                out.push(Prim::Box {
                    center: [x, y, o.height],
                    half: [hd / 2.0, hw / 2.0, h / 2.0],
                    dir: [c, s],
                    rgb: [28.0, 28.0, 30.0],
                });
                let state = o.light_state(t_s);
                let lamps = [
                    (h * 0.3, [255.0, 40.0, 30.0], super::track::LightState::Red),
                    (0.0, [255.0, 170.0, 20.0], super::track::LightState::Amber),
                    (-h * 0.3, [40.0, 255.0, 110.0], super::track::LightState::Green),
                ];
                for (dz, rgb, st) in lamps {
                    out.push(Prim::Panel {
                        center: [x + (hd / 2.0 + 0.001) * c, y + (hd / 2.0 + 0.001) * s, o.height + dz],
                        dir: [c, s],
                        kind: PanelKind::Lamp {
                            radius: h * 0.12,
                            rgb,
                            lit: st == state,
                        },
                    });
                }
            }
            SimShape::Triangle | SimShape::ArrowDisc => {
                // A sign on a post like the stop sign; its face's half height below the centre.
                let (w, half_h) = (o.size[0], Self::face_half_height(o));
                let kind = if o.kind.info().shape == SimShape::Triangle {
                    PanelKind::YieldFace { width: w }
                } else {
                    let right = o.arrow != Some(crate::classes::TurnArrow::Left);
                    PanelKind::ArrowDisc { diameter: w, right }
                };
                out.push(Prim::Box {
                    center: [x, y, (o.height - half_h) / 2.0],
                    half: [0.006, 0.006, (o.height - half_h) / 2.0],
                    dir: [c, s],
                    rgb: [150.0, 150.0, 155.0],
                });
                out.push(Prim::Panel {
                    center: [x + 0.007 * c, y + 0.007 * s, o.height],
                    dir: [c, s],
                    kind,
                });
            }
            SimShape::Box => {
                let [l, w, h] = o.size;
                let rgb = [o.color[0] as f32, o.color[1] as f32, o.color[2] as f32];
                out.push(Prim::Box {
                    center: [x, y, h / 2.0],
                    half: [l / 2.0, w / 2.0, h / 2.0],
                    dir: [c, s],
                    rgb,
                });
            }
        }
    }

    /// Half the height of a sign's face or a light's housing (a yield sign's triangle is √3/2
    /// as high as its top edge is long), metres.
    pub fn face_half_height(o: &Object) -> f64 {
        match o.kind.info().shape {
            SimShape::Triangle => o.size[0] * 0.75f64.sqrt() / 2.0,
            _ => o.size[0] / 2.0,
        }
    }

    /// The corners of the smallest upright box (turned with the object) that contains it,
    /// world metres: screen bounds for rendering and ground-truth image boxes.
    pub fn object_bounds(o: &Object) -> [[f64; 3]; 8] {
        // Half extents along the facing direction and across it, and the top.
        let (hx, hy, top) = match o.kind.info().shape {
            SimShape::Octagon | SimShape::ArrowDisc => (0.015, o.size[0] / 2.0, o.height + o.size[0] / 2.0),
            SimShape::Triangle => (0.015, o.size[0] / 2.0, o.height + Self::face_half_height(o)),
            SimShape::LightHousing => (o.size[0] * 0.17, o.size[0] * 0.19, o.height + o.size[0] / 2.0),
            SimShape::Box => (o.size[0] / 2.0, o.size[1] / 2.0, o.size[2]),
        };
        let (s, c) = o.yaw.sin_cos();
        let mut out = [[0.0; 3]; 8];
        for (k, corner) in out.iter_mut().enumerate() {
            let lx = if k & 1 == 0 { -hx } else { hx };
            let ly = if k & 2 == 0 { -hy } else { hy };
            let z = if k & 4 == 0 { 0.0 } else { top };
            *corner = [o.pos[0] + c * lx - s * ly, o.pos[1] + s * lx + c * ly, z];
        }
        out
    }

    /// The nearest hit of the ray `o + t d` (d unit length) on `prims`, with `t < t_max`.
    pub fn intersect(&self, prims: &[Prim], o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        for p in prims {
            if let Some(h) = self.intersect_one(p, o, d, t_best) {
                t_best = h.t;
                best = Some(h);
            }
        }
        best
    }

    fn intersect_one(&self, p: &Prim, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<Hit> {
        match *p {
            Prim::Box { center, half, dir, rgb } => self.intersect_box(center, half, dir, rgb, o, d, t_max),
            Prim::Panel { center, dir, kind } => self.intersect_panel(center, dir, kind, o, d, t_max),
        }
    }

    /// [`Scene::intersect_one`] for a [`Prim::Box`].
    #[allow(clippy::too_many_arguments)]
    fn intersect_box(
        &self,
        center: [f64; 3],
        half: [f64; 3],
        dir: [f64; 2],
        rgb: [f32; 3],
        o: [f64; 3],
        d: [f64; 3],
        t_max: f64,
    ) -> Option<Hit> {
        // Ray in the box's frame; slab test; the entering face gives the normal.
        let [c, s] = dir;
        let rel = [o[0] - center[0], o[1] - center[1], o[2] - center[2]];
        let lo = [c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], rel[2]];
        let ld = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
        let (mut t0, mut t1, mut axis) = (0.0f64, t_max, usize::MAX);
        for a in 0..3 {
            if ld[a].abs() < 1e-12 {
                if lo[a].abs() > half[a] {
                    return None;
                }
                continue;
            }
            let (mut ta, mut tb) = ((-half[a] - lo[a]) / ld[a], (half[a] - lo[a]) / ld[a]);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            if ta > t0 {
                t0 = ta;
                axis = a;
            }
            t1 = t1.min(tb);
            if t0 > t1 {
                return None;
            }
        }
        if axis == usize::MAX || t0 >= t_max {
            return None;
        }
        // World normal of the entering face.
        let sign = -ld[axis].signum();
        let n = match axis {
            0 => [c * sign, s * sign, 0.0],
            1 => [-s * sign, c * sign, 0.0],
            _ => [0.0, 0.0, sign],
        };
        let hit = [o[0] + t0 * d[0], o[1] + t0 * d[1]];
        let k = shade(n) * self.illumination(hit);
        Some(Hit {
            t: t0,
            rgb: [rgb[0] * k, rgb[1] * k, rgb[2] * k],
        })
    }

    /// [`Scene::intersect_one`] for a [`Prim::Panel`].
    fn intersect_panel(
        &self,
        center: [f64; 3],
        dir: [f64; 2],
        kind: PanelKind,
        o: [f64; 3],
        d: [f64; 3],
        t_max: f64,
    ) -> Option<Hit> {
        let [c, s] = dir;
        let n = [c, s, 0.0];
        let dn = d[0] * n[0] + d[1] * n[1];
        if dn.abs() < 1e-12 {
            return None;
        }
        let t = ((center[0] - o[0]) * n[0] + (center[1] - o[1]) * n[1]) / dn;
        if t <= 0.0 || t >= t_max {
            return None;
        }
        let hit = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
        // Face coordinates: u to the viewer's right when facing the panel, w up.
        let rel = [hit[0] - center[0], hit[1] - center[1], hit[2] - center[2]];
        let u = -s * rel[0] + c * rel[1];
        let w = rel[2];
        let front = dn < 0.0;
        let light = self.illumination([hit[0], hit[1]]);
        match kind {
            PanelKind::StopFace { width } => {
                let r = width / 2.0;
                // Regular octagon with flats at 0°, 45°, ...: the max over the four
                // axis pairs of |projection|.
                let k = std::f64::consts::FRAC_1_SQRT_2;
                let m = u.abs().max(w.abs()).max((u + w).abs() * k).max((u - w).abs() * k);
                if m > r {
                    return None;
                }
                if !front {
                    let g = 120.0 * light;
                    return Some(Hit {
                        t,
                        rgb: [g, g, g * 1.03],
                    });
                }
                let white = [235.0 * light, 235.0 * light, 232.0 * light];
                let red = [196.0 * light, 22.0 * light, 28.0 * light];
                if m > r * 0.9 {
                    return Some(Hit { t, rgb: white });
                }
                // "STOP" across the middle: 4 letters, 0.34 r high.
                let lh = r * 0.42;
                let lw = lh * 0.62;
                let adv = lw * 1.3;
                let total = adv * 3.0 + lw;
                let (bx, by) = ((u + total / 2.0) / lh, (w + lh / 2.0) / lh);
                let dist = glyphs::text_distance("STOP", (lw / lh) as f32, (adv / lh) as f32, bx as f32, by as f32);
                Some(Hit {
                    t,
                    rgb: if dist < 0.09 { white } else { red },
                })
            }
            PanelKind::YieldFace { width } => {
                // Distance inside the triangle's nearest edge (top edge at +h/2, vertex down).
                let h = width * 0.75f64.sqrt();
                let half_w = (w + h / 2.0) / h * width / 2.0;
                let m = (h / 2.0 - w).min((half_w - u.abs()) * 0.75f64.sqrt());
                if m < 0.0 || w < -h / 2.0 {
                    return None;
                }
                if !front {
                    let g = 120.0 * light;
                    return Some(Hit {
                        t,
                        rgb: [g, g, g * 1.03],
                    });
                }
                // The border: a third of the inradius (h / 3).
                let rgb = if m < h / 9.0 {
                    [196.0 * light, 22.0 * light, 28.0 * light]
                } else {
                    [235.0 * light, 235.0 * light, 232.0 * light]
                };
                Some(Hit { t, rgb })
            }
            PanelKind::ArrowDisc { diameter, right } => {
                let r = diameter / 2.0;
                let r2 = u * u + w * w;
                if r2 > r * r {
                    return None;
                }
                if !front {
                    let g = 120.0 * light;
                    return Some(Hit {
                        t,
                        rgb: [g, g, g * 1.03],
                    });
                }
                let white = [235.0 * light, 235.0 * light, 232.0 * light];
                let blue = [22.0 * light, 70.0 * light, 190.0 * light];
                // A thin white rim; the arrow: a shaft and a head, pointing along +a.
                let a = if right { u / r } else { -u / r };
                let b = (w / r).abs();
                let shaft = (-0.55..=0.05).contains(&a) && b <= 0.14;
                let head = (0.0..=0.6).contains(&a) && b <= 0.45 * (0.6 - a) / 0.6;
                let rgb = if r2 > (0.92 * r) * (0.92 * r) || shaft || head {
                    white
                } else {
                    blue
                };
                Some(Hit { t, rgb })
            }
            PanelKind::Lamp { radius, rgb, lit } => {
                let r2 = u * u + w * w;
                if r2 > radius * radius || !front {
                    return None;
                }
                if lit {
                    // Emissive; the centre saturates towards white, as a camera sees it.
                    let q = (1.0 - r2 / (radius * radius)) as f32;
                    let wt = (q * q).min(1.0) * 0.7;
                    Some(Hit {
                        t,
                        rgb: [
                            rgb[0] + (255.0 - rgb[0]) * wt,
                            rgb[1] + (255.0 - rgb[1]) * wt,
                            rgb[2] + (255.0 - rgb[2]) * wt,
                        ],
                    })
                } else {
                    Some(Hit {
                        t,
                        rgb: [rgb[0] * 0.16 + 8.0, rgb[1] * 0.16 + 8.0, rgb[2] * 0.16 + 8.0],
                    })
                }
            }
        }
    }
}

/// atan2 to within 2e-4 rad (a cubic-in-a² polynomial for atan on [0, 1] and octant folding):
/// 0.6 mm along a 3 m arc, plenty for the phase of a dash.
#[inline]
pub fn fast_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (a, swap) = if ay > ax {
        (ax / ay, true)
    } else {
        (ay / ax.max(1e-300), false)
    };
    let s = a * a;
    let mut r = ((-0.046_496_474_9 * s + 0.159_314_22) * s - 0.327_622_764) * s * a + a;
    if swap {
        r = FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 {
        r = -r;
    }
    r
}

/// Lambert shading of a face with normal `n` under a fixed high light, plus ambient.
fn shade(n: [f64; 3]) -> f32 {
    const L: [f64; 3] = [0.32, 0.42, 0.85];
    let norm = (L[0] * L[0] + L[1] * L[1] + L[2] * L[2]).sqrt();
    let d = (n[0] * L[0] + n[1] * L[1] + n[2] * L[2]) / norm;
    (0.55 + 0.5 * d.max(0.0)) as f32
}

/// Fraction of the interval `[d − w/2, d + w/2]` inside `[−h, h]` (a box filter of width
/// `w` over a line of half width `h`, at distance `d` from its centre).
#[inline]
pub fn box_coverage(d: f64, w: f64, h: f64) -> f64 {
    let lo = (d - w / 2.0).max(-h);
    let hi = (d + w / 2.0).min(h);
    ((hi - lo) / w).clamp(0.0, 1.0)
}

/// Fraction of `[s − w/2, s + w/2]` covered by dashes `[k P, k P + dash]`.
#[inline]
pub fn dash_coverage(s: f64, w: f64, dash: f64, period: f64) -> f64 {
    let f = |x: f64| {
        let k = (x / period).floor();
        k * dash + (x - k * period).min(dash)
    };
    ((f(s + w / 2.0) - f(s - w / 2.0)) / w).clamp(0.0, 1.0)
}

/// Step 1 of [`Scene::new`]: the floor's texture tile, value noise with octaves from
/// `texture_scale_m` down to 2 texels, −127..127.
fn floor_texture(spec_floor: &FloorSpec) -> Vec<i8> {
    let seed = spec_floor.seed;
    let mut texture = vec![0f32; TEX_N * TEX_N];
    let mut period = ((spec_floor.texture_scale_m / TEX_M).round() as usize).clamp(2, TEX_N);
    period = period.next_power_of_two().min(TEX_N);
    let mut amp = 1.0f32;
    let mut total = 0.0f32;
    let mut octave = 0u64;
    while period >= 2 {
        let n = TEX_N / period;
        let lattice: Vec<f32> = (0..n * n)
            .map(|i| (mix(seed ^ (octave << 40) ^ i as u64) >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0)
            .collect();
        for y in 0..TEX_N {
            let (gy, fy) = (y / period, (y % period) as f32 / period as f32);
            let sy = fy * fy * (3.0 - 2.0 * fy);
            for x in 0..TEX_N {
                let (gx, fx) = (x / period, (x % period) as f32 / period as f32);
                let sx = fx * fx * (3.0 - 2.0 * fx);
                let at = |i: usize, j: usize| lattice[(j % n) * n + (i % n)];
                let top = at(gx, gy) * (1.0 - sx) + at(gx + 1, gy) * sx;
                let bot = at(gx, gy + 1) * (1.0 - sx) + at(gx + 1, gy + 1) * sx;
                texture[y * TEX_N + x] += amp * (top * (1.0 - sy) + bot * sy);
            }
        }
        total += amp;
        amp *= 0.6;
        period /= 2;
        octave += 1;
    }
    texture
        .iter()
        .map(|t| (t / total * 127.0).round().clamp(-127.0, 127.0) as i8)
        .collect()
}

/// Step 2 of [`Scene::new`]: illumination, ambient plus a few soft lamps over the floor
/// `floor_rect`, on a grid of `ILLUM_M` cells: (values, width, height).
fn illumination(floor_rect: [f64; 4], seed: u64) -> (Vec<f32>, usize, usize) {
    let [x0, y0, x1, y1] = floor_rect;
    let illum_w = ((x1 - x0) / ILLUM_M).ceil() as usize + 2;
    let illum_h = ((y1 - y0) / ILLUM_M).ceil() as usize + 2;
    let mut rng = SplitMix64::new(seed ^ 0x11u64);
    let lamps: Vec<([f64; 2], f64)> = (0..4)
        .map(|_| {
            (
                [x0 + (x1 - x0) * rng.next_f64(), y0 + (y1 - y0) * rng.next_f64()],
                1.2 + 1.5 * rng.next_f64(),
            )
        })
        .collect();
    let mut illum = vec![0f32; illum_w * illum_h];
    for j in 0..illum_h {
        for i in 0..illum_w {
            let p = [x0 + i as f64 * ILLUM_M, y0 + j as f64 * ILLUM_M];
            let mut l = 0.86;
            for (c, s) in &lamps {
                let r2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
                l += 0.16 * (-r2 / (2.0 * s * s)).exp();
            }
            illum[j * illum_w + i] = l as f32;
        }
    }
    (illum, illum_w, illum_h)
}

/// Step 3 of [`Scene::new`]: per `CELL_M` cell of the floor, the nearest piece where any of
/// `lines` is within reach and the clearance to the nearest line (1e-4 m units); with the
/// grid's width and height and the far-clear distance.
fn piece_grid(track: &Track, lines: &[LinePaint]) -> (Vec<(u16, u16)>, usize, usize, f32) {
    let [x0, y0, x1, y1] = track.floor_rect;
    let reach = lines.iter().map(|l| l.offset.abs() + l.half_width).fold(0.0, f64::max);
    let grid_w = ((x1 - x0) / CELL_M).ceil() as usize + 1;
    let grid_h = ((y1 - y0) / CELL_M).ceil() as usize + 1;
    let near = reach + CELL_M + 0.05;
    let mut grid = vec![(u16::MAX, u16::MAX); grid_w * grid_h];
    let half_diag = CELL_M * std::f64::consts::FRAC_1_SQRT_2;
    let mark_c = mark_clearance(track, grid_w, grid_h, near);
    for j in 0..grid_h {
        for i in 0..grid_w {
            let p = [x0 + (i as f64 + 0.5) * CELL_M, y0 + (j as f64 + 0.5) * CELL_M];
            let mut best = (f64::INFINITY, u16::MAX);
            for (k, piece) in track.pieces.iter().enumerate() {
                let (_, lat, out) = piece.project(p);
                let d2 = lat * lat + out * out;
                if d2 < best.0 {
                    best = (d2, k as u16);
                }
            }
            // A cell near a floor mark probes too (it takes its nearest piece, and the mark
            // counts in its clearance).
            let mark_c = mark_c.get(j * grid_w + i).map_or(f64::INFINITY, |&c| c as f64);
            if best.0 <= near * near || mark_c <= near {
                grid[j * grid_w + i].0 = best.1;
                let (_, lat, _) = track.pieces[best.1 as usize].project(p);
                let c = lines
                    .iter()
                    .map(|l| (lat - l.offset).abs() - l.half_width)
                    .fold(mark_c, f64::min);
                grid[j * grid_w + i].1 = ((c - half_diag - 1e-4).max(0.0) * 1e4).floor().min(65535.0) as u16;
            }
        }
    }
    (grid, grid_w, grid_h, (near - reach - half_diag).max(0.0) as f32)
}

/// For each grid cell (none without marks): the distance from its centre to the nearest mark,
/// metres, for the cells near a mark (at least `reach` beyond its rectangle; infinite
/// elsewhere). Each mark visits only the cells of its bounding box.
fn mark_clearance(track: &Track, grid_w: usize, grid_h: usize, reach: f64) -> Vec<f32> {
    if track.marks.is_empty() {
        return Vec::new();
    }
    let [x0, y0, _, _] = track.floor_rect;
    let mut out = vec![f32::INFINITY; grid_w * grid_h];
    let cell = |v: f64, o: f64, n: usize| (((v - o) / CELL_M).floor().max(0.0) as usize).min(n - 1);
    for m in &track.marks {
        let r = m.length.hypot(m.width) / 2.0 + reach + CELL_M;
        let (i0, i1) = (cell(m.pos[0] - r, x0, grid_w), cell(m.pos[0] + r, x0, grid_w));
        let (j0, j1) = (cell(m.pos[1] - r, y0, grid_h), cell(m.pos[1] + r, y0, grid_h));
        for j in j0..=j1 {
            for i in i0..=i1 {
                let p = [x0 + (i as f64 + 0.5) * CELL_M, y0 + (j as f64 + 0.5) * CELL_M];
                let c = &mut out[j * grid_w + i];
                *c = c.min(mark_distance(m, p) as f32);
            }
        }
    }
    out
}

/// Distance from `p` to mark `m`'s rectangle (0 inside), metres.
fn mark_distance(m: &Mark, p: [f64; 2]) -> f64 {
    let (along, across) = m.local(p);
    let a = (along.abs() - m.width / 2.0).max(0.0);
    let b = (across.abs() - m.length / 2.0).max(0.0);
    a.hypot(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_atan2_is_close() {
        let mut worst = 0.0f64;
        for i in 0..3600 {
            let a = (i as f64 / 10.0 - 180.0).to_radians();
            for r in [0.01, 1.0, 30.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                worst = worst.max((fast_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst < 3e-4, "{worst}");
    }

    #[test]
    fn coverage_filters() {
        assert_eq!(box_coverage(0.0, 0.001, 0.01), 1.0);
        assert_eq!(box_coverage(0.02, 0.001, 0.01), 0.0);
        assert!((box_coverage(0.01, 0.002, 0.01) - 0.5).abs() < 1e-9);
        assert!((dash_coverage(0.05, 0.01, 0.1, 0.16) - 1.0).abs() < 1e-9);
        assert!((dash_coverage(0.13, 0.01, 0.1, 0.16)).abs() < 1e-9);
        // A footprint much longer than a period sees the average.
        assert!((dash_coverage(3.0, 1.6, 0.1, 0.16) - 0.625).abs() < 1e-9);
    }

    #[test]
    fn marks_are_painted_on_and_off_the_road_and_their_cells_probe() {
        let oval = "[road]\nlane_width_m = 0.3\n[[segments]]\ntype = \"straight\"\nlength_m = 2.0\n\
                    [[segments]]\ntype = \"arc\"\nradius_m = 1.0\nangle_deg = 180\n\
                    [[segments]]\ntype = \"straight\"\nlength_m = 2.0\n\
                    [[segments]]\ntype = \"arc\"\nradius_m = 1.0\nangle_deg = 180\n";
        // A stop line across the road at x = 1, and a yield line far off it (no piece near).
        let marks = "[[marks]]\ntype = \"stop_line\"\nx = 1.0\ny = 0.0\n\
                     [[marks]]\ntype = \"yield_line\"\nx = 1.0\ny = -0.9\nlength_m = 0.29\n";
        let track = Track::from_toml_str(&format!("{oval}{marks}"), "t").unwrap();
        let scene = Scene::new(&track);
        let fp = Footprint {
            ju: [0.001, 0.0],
            jv: [0.0, 0.001],
            size: 0.002,
            fade: 1.0,
        };
        let at = |p: [f64; 2]| scene.floor_color(p, &fp, 1.0, 0.0, true).0[0];
        let floor = at([1.3, -0.05]);
        assert!(
            at([1.0, -0.05]) > 200.0 && floor < 130.0,
            "{} {floor}",
            at([1.0, -0.05])
        );
        // The yield line: a dash at its right end, a gap 0.05 m in; floor beside it.
        assert!(at([1.0, -0.9 - 0.135]) > 200.0, "{}", at([1.0, -1.035]));
        assert!(at([1.0, -0.9 - 0.095]) < 130.0, "{}", at([1.0, -0.995]));
        // Every cell's clearance is a lower bound of the distance to the marks.
        let [x0, y0, _, _] = track.floor_rect;
        for (c, &(k, clear)) in scene.grid.iter().enumerate() {
            if k == u16::MAX {
                continue;
            }
            let p = [
                x0 + ((c % scene.grid_w) as f64 + 0.5) * CELL_M,
                y0 + ((c / scene.grid_w) as f64 + 0.5) * CELL_M,
            ];
            for m in &track.marks {
                assert!(clear as f64 * 1e-4 <= mark_distance(m, p), "cell {c}");
            }
        }
    }
}
