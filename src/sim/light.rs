//! Changing light along the route (`sim.light_level` and `sim.light_*`, docs/light.md): what
//! a class room does to a camera that a lamp-lit floor does not.
//!
//! - **Shadows** across the road, fixed in the world: bands (a window frame's bar, a table's
//!   edge) and blotches (a chair, a box), soft-edged; each darkens the floor under it by up
//!   to `shadows` (a fraction of the light).
//! - **Bright patches**: sun through a window on the floor, brighter by `glare` (a fraction of
//!   the light added) with a hot spot in the middle, so the floor there can outshine tape in
//!   the shade.
//! - **Dusk**: the whole picture dimmer by `dusk` (a fraction) and warmer (less blue, a
//!   little less green).
//! - **Sensor noise at low light**: `noise` grey levels of extra noise (standard deviation).
//!
//! Shadows and patches are baked into a [`LightMap`] (one factor per 2 cm cell of the floor)
//! that multiplies the scene's own illumination where the renderer samples it; dusk is a gain
//! and a per-channel table ([`Tint`]). Everything is placed from the seed, so the same seed gives
//! the same room. With every strength 0 nothing is built and the renderer draws exactly what it
//! drew before (the default track's telemetry is byte-identical).
//!
//! Units: metres (world frame), fractions of the light, grey levels.

use super::rng::SplitMix64;
use super::track::Track;

/// Side of one cell of the light map, metres.
const CELL_M: f64 = 0.02;
/// Half width of a shadow's or patch's soft edge (penumbra), metres.
const SOFT_M: f64 = 0.03;
/// Distance along the route between shadows, metres (jittered).
const SHADOW_EVERY_M: f64 = 1.6;
/// Distance along the route between bright patches, metres (jittered).
const PATCH_EVERY_M: f64 = 6.5;

/// The strengths of the light variation (all 0 = none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightOptions {
    /// Darkening in the core of a shadow, fraction of the light, 0..0.9.
    pub shadows: f64,
    /// Extra light in the core of a bright patch, fraction, 0..3.
    pub glare: f64,
    /// Global dimming, fraction, 0..0.9 (with a warmer colour).
    pub dusk: f64,
    /// Extra sensor noise, standard deviation in grey levels, 0..32.
    pub noise: f64,
    /// Places the shadows and patches.
    pub seed: u64,
}

/// `[shadows, glare, dusk, noise]` of `sim.light_level` 0..=3.
pub const PRESETS: [[f64; 4]; 4] = [
    [0.0, 0.0, 0.0, 0.0],
    [0.35, 0.5, 0.0, 0.0],
    [0.55, 0.9, 0.3, 2.0],
    [0.7, 1.3, 0.55, 4.0],
];

impl LightOptions {
    /// No light variation.
    pub fn off() -> LightOptions {
        LightOptions {
            shadows: 0.0,
            glare: 0.0,
            dusk: 0.0,
            noise: 0.0,
            seed: 0,
        }
    }

    /// The strengths of preset `level` (clamped to 0..=3), each replaced by its override when
    /// that is ≥ 0 (`sim.light_shadows` …; −1 = the level's).
    pub fn from_level(level: u32, overrides: [f64; 4], seed: u64) -> LightOptions {
        let p = PRESETS[(level as usize).min(PRESETS.len() - 1)];
        let v: Vec<f64> = p
            .iter()
            .zip(overrides)
            .map(|(&p, o)| if o >= 0.0 { o } else { p })
            .collect();
        LightOptions {
            shadows: v[0],
            glare: v[1],
            dusk: v[2],
            noise: v[3],
            seed,
        }
    }

    /// Whether there are shadows or patches to bake into a map.
    pub fn has_map(&self) -> bool {
        self.shadows > 0.0 || self.glare > 0.0
    }

    /// The global gain dusk leaves (1 without dusk).
    pub fn dim(&self) -> f32 {
        (1.0 - self.dusk) as f32
    }
}

/// One soft shape on the floor: a rectangle (`round` false) or an ellipse, centred at `c`,
/// turned by (cos, sin) `dir`, half sizes `half`; `gain` is its factor's change in its core
/// (−0.7 = 70 % darker, +1.3 = 130 % brighter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    /// Centre, world metres.
    pub c: [f64; 2],
    /// (cos, sin) of its turn.
    pub dir: [f64; 2],
    /// Half sizes along its own axes, metres.
    pub half: [f64; 2],
    /// Ellipse (true) or rectangle.
    pub round: bool,
    /// Change of the light factor in its core.
    pub gain: f64,
    /// A hot spot: the change grows towards the centre (a sun patch's glare).
    pub hot: bool,
}

impl Shape {
    /// How much of the shape is at `p`, 0..1, with a smooth edge `SOFT_M` wide either side.
    pub fn cover(&self, p: [f64; 2]) -> f64 {
        let (dx, dy) = (p[0] - self.c[0], p[1] - self.c[1]);
        let [c, s] = self.dir;
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        // Signed distance to the outline (approximate for the ellipse), metres.
        let d = if self.round {
            let (a, b) = (self.half[0], self.half[1]);
            let r = ((lx / a).powi(2) + (ly / b).powi(2)).sqrt();
            (r - 1.0) * a.min(b)
        } else {
            (lx.abs() - self.half[0]).max(ly.abs() - self.half[1])
        };
        let t = ((SOFT_M - d) / (2.0 * SOFT_M)).clamp(0.0, 1.0);
        let mut m = t * t * (3.0 - 2.0 * t);
        if self.hot && m > 0.0 {
            // Brightest in the middle: 0.6 of the gain at the rim, 1.0 at the centre.
            let q = ((lx / self.half[0]).powi(2) + (ly / self.half[1]).powi(2)).min(1.0);
            m *= 1.0 - 0.4 * q;
        }
        m
    }

    /// Half the side of a square round the centre that holds the shape and its soft edge.
    fn reach(&self) -> f64 {
        self.half[0].hypot(self.half[1]) + SOFT_M
    }
}

/// The shadows and patches of `opts` along `track`'s route, placed from `opts.seed`.
pub fn shapes(track: &Track, opts: &LightOptions) -> Vec<Shape> {
    let mut out = Vec::new();
    let mut rng = SplitMix64::new(opts.seed ^ 0x004C_4947_4854);
    let len = track.length;
    let turn = |a: f64| [a.cos(), a.sin()];
    if opts.shadows > 0.0 {
        let n = (len / SHADOW_EVERY_M).floor().max(1.0) as usize;
        for k in 0..n {
            let s = (k as f64 + 0.3 + 0.4 * rng.next_f64()) * len / n as f64;
            let (p, heading) = track.pose_at(s);
            let across = [-heading.sin(), heading.cos()];
            let off = (rng.next_f64() - 0.5) * 0.3;
            let c = [p[0] + across[0] * off, p[1] + across[1] * off];
            let depth = opts.shadows * (0.75 + 0.25 * rng.next_f64());
            let kind = rng.next_f64();
            let shape = if kind < 0.6 {
                // A band across the road: a bar's or an edge's shadow, up to 40° off square.
                let a = heading + (rng.next_f64() - 0.5) * 80f64.to_radians();
                Shape {
                    c,
                    dir: turn(a),
                    half: [0.03 + 0.09 * rng.next_f64(), 0.8],
                    round: false,
                    gain: -depth,
                    hot: false,
                }
            } else {
                // A blotch: a chair's or a box's shadow.
                let a = rng.next_f64() * std::f64::consts::PI;
                Shape {
                    c,
                    dir: turn(a),
                    half: [0.12 + 0.2 * rng.next_f64(), 0.1 + 0.15 * rng.next_f64()],
                    round: true,
                    gain: -depth,
                    hot: false,
                }
            };
            out.push(shape);
        }
    }
    if opts.glare > 0.0 {
        let n = (len / PATCH_EVERY_M).floor().max(1.0) as usize;
        for k in 0..n {
            let s = (k as f64 + 0.2 + 0.6 * rng.next_f64()) * len / n as f64;
            let (p, heading) = track.pose_at(s);
            let across = [-heading.sin(), heading.cos()];
            let off = (rng.next_f64() - 0.5) * 0.2;
            out.push(Shape {
                c: [p[0] + across[0] * off, p[1] + across[1] * off],
                dir: turn(heading + (rng.next_f64() - 0.5)),
                half: [0.2 + 0.15 * rng.next_f64(), 0.3 + 0.15 * rng.next_f64()],
                round: false,
                gain: opts.glare,
                hot: true,
            });
        }
    }
    out
}

/// The light factor of shadows and patches over the floor, on a `CELL_M` grid.
#[derive(Debug, Clone)]
pub struct LightMap {
    x0: f64,
    y0: f64,
    w: usize,
    h: usize,
    cells: Vec<f32>,
}

impl LightMap {
    /// The map of `shapes` over `track`'s floor (a few ms).
    pub fn new(track: &Track, shapes: &[Shape]) -> LightMap {
        let [x0, y0, x1, y1] = track.floor_rect;
        let w = ((x1 - x0) / CELL_M).ceil() as usize + 2;
        let h = ((y1 - y0) / CELL_M).ceil() as usize + 2;
        let mut cells = vec![1f32; w * h];
        for sh in shapes {
            let r = sh.reach();
            let cell = |v: f64, o: f64, n: usize| (((v - o) / CELL_M).floor().max(0.0) as usize).min(n - 1);
            let (i0, i1) = (cell(sh.c[0] - r, x0, w), cell(sh.c[0] + r, x0, w) + 1);
            let (j0, j1) = (cell(sh.c[1] - r, y0, h), cell(sh.c[1] + r, y0, h) + 1);
            for j in j0..j1.min(h) {
                for i in i0..i1.min(w) {
                    let p = [x0 + i as f64 * CELL_M, y0 + j as f64 * CELL_M];
                    let m = sh.cover(p);
                    if m > 0.0 {
                        cells[j * w + i] *= (1.0 + sh.gain * m) as f32;
                    }
                }
            }
        }
        LightMap { x0, y0, w, h, cells }
    }

    /// The factor at a floor point (bilinear; points off the floor take the nearest edge's).
    #[inline]
    pub fn at(&self, p: [f64; 2]) -> f32 {
        let x = (((p[0] - self.x0) / CELL_M) as f32).clamp(0.0, (self.w - 2) as f32);
        let y = (((p[1] - self.y0) / CELL_M) as f32).clamp(0.0, (self.h - 2) as f32);
        let (i, j) = (x as usize, y as usize);
        let (ax, ay) = (x - i as f32, y - j as f32);
        let (w, l) = (self.w, &self.cells);
        let top = l[j * w + i] * (1.0 - ax) + l[j * w + i + 1] * ax;
        let bot = l[(j + 1) * w + i] * (1.0 - ax) + l[(j + 1) * w + i + 1] * ax;
        top * (1.0 - ay) + bot * ay
    }
}

/// Dusk's warmer colour: one table per channel (grey level → graded level).
#[derive(Debug, Clone)]
pub struct Tint([[u8; 256]; 3]);

impl Tint {
    /// The tint of `dusk` (0..0.9), or `None` when there is no dusk.
    pub fn new(dusk: f64) -> Option<Tint> {
        if dusk <= 0.0 {
            return None;
        }
        let k = [1.0, 1.0 - 0.25 * dusk, 1.0 - 0.6 * dusk];
        let mut t = [[0u8; 256]; 3];
        for (tab, k) in t.iter_mut().zip(k) {
            for (v, o) in tab.iter_mut().enumerate() {
                *o = (v as f64 * k).round() as u8;
            }
        }
        Some(Tint(t))
    }

    /// Grades the bytes of interleaved RGB pixels in place.
    pub fn apply(&self, rgb: &mut [u8]) {
        for px in rgb.chunks_exact_mut(3) {
            px[0] = self.0[0][px[0] as usize];
            px[1] = self.0[1][px[1] as usize];
            px[2] = self.0[2][px[2] as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn track() -> Track {
        Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).unwrap()
    }

    #[test]
    fn level_zero_is_off_and_overrides_win() {
        let o = LightOptions::from_level(0, [-1.0; 4], 1);
        assert!(!o.has_map() && o.dim() == 1.0 && o.noise == 0.0 && Tint::new(o.dusk).is_none());
        let o = LightOptions::from_level(3, [0.2, -1.0, 0.0, -1.0], 1);
        assert_eq!(
            (o.shadows, o.glare, o.dusk, o.noise),
            (0.2, PRESETS[3][1], 0.0, PRESETS[3][3])
        );
    }

    /// A shadow darkens the floor at its core by its depth, leaves the floor well outside it
    /// alone, and the edge is soft (between the two over `2 SOFT_M`).
    #[test]
    fn a_shadow_darkens_the_floor_where_it_is_by_its_depth() {
        let t = track();
        let sh = Shape {
            c: [1.0, -0.15],
            dir: [1.0, 0.0],
            half: [0.1, 0.5],
            round: false,
            gain: -0.6,
            hot: false,
        };
        let map = LightMap::new(&t, &[sh]);
        assert!((map.at([1.0, -0.15]) - 0.4).abs() < 1e-6, "{}", map.at([1.0, -0.15]));
        assert!((map.at([1.05, 0.2]) - 0.4).abs() < 1e-6);
        assert_eq!(map.at([1.0 + 0.1 + SOFT_M + CELL_M, -0.15]), 1.0);
        assert_eq!(map.at([2.0, -0.15]), 1.0);
        let edge = map.at([1.1, -0.15]);
        assert!(edge > 0.6 && edge < 0.8, "edge {edge}");
    }

    #[test]
    fn shapes_follow_the_route_and_the_seed() {
        let t = track();
        let o = LightOptions::from_level(3, [-1.0; 4], 1);
        let a = shapes(&t, &o);
        assert_eq!(a, shapes(&t, &o));
        assert_ne!(a, shapes(&t, &LightOptions { seed: 2, ..o }));
        let shadows = a.iter().filter(|s| s.gain < 0.0).count();
        assert!(shadows >= (t.length / SHADOW_EVERY_M) as usize, "{shadows}");
        assert!(a.iter().any(|s| s.gain > 0.0));
        // Each one on the road: its centre within 0.2 m of the centre line.
        for s in &a {
            assert!(t.lateral(s.c).abs() < 0.2, "{s:?}");
        }
    }

    #[test]
    fn dusk_is_warmer() {
        let t = Tint::new(0.5).unwrap();
        let mut px = [200u8, 200, 200];
        t.apply(&mut px);
        assert!(px[0] == 200 && px[1] < 200 && px[2] < px[1], "{px:?}");
    }
}
