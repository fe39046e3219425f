//! Training and held-out data rendered by rccar's simulator (`rccar::sim::render`): the car's
//! camera looking at stop signs, traffic lights (red or green lit) and obstacles at 0.2–1.5 m,
//! from varied angles, under varied exposure, noise and blur, on the default track with the
//! other kinds of objects standing around as distractors. Obstacles get random colours at
//! least 30 grey levels away from the floor's (a box as grey as the floor has no Haar
//! features to find).
//!
//! Per object kind and seed:
//! * `positives`: crops around the object's *target box* (below) with a small seeded jitter,
//!   one PNG each plus an `info.dat` giving the box inside the crop;
//! * `negatives`: full grey frames (driving along the lane, or looking at some object) with
//!   an info.dat-style `bg.txt` naming the target object's box where it is in view, so the
//!   trainer never takes it as a negative;
//! * `eval`: full grey frames with exactly one target object at 0.2–1.5 m, fully in view, and
//!   an `info.dat` of its box (the held-out set: use seeds not used for training); for a turn
//!   sign also the colour frames (`rgb/`) and each sign's arrow (`arrows.txt`).
//!
//! The target box is what the cascade window covers: the sign's face square, the light's
//! housing, the obstacle's projected bounding box with a 20% margin, widened to the window's aspect ratio about
//! its centre. Every random choice comes from a [`SplitMix64`] seeded by the `seed` argument.
//! Units: metres, radians, pixels.

use image::{GrayImage, RgbImage};
use rccar::camera::PinholeCamera;
use rccar::classes::{ObjectClass, SimShape};
use rccar::config::Config;
use rccar::sim::render::{CameraMount, RenderOptions, Renderer};
use rccar::sim::rng::{mix, SplitMix64};
use rccar::sim::scene::Scene;
use rccar::sim::track::{Object, ObjectSpec, Track, TrackFile};
use rccar::sim::vehicle::Pose;
use std::f64::consts::PI;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why data could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    /// A file could not be written or read.
    #[error("{path}: {message}")]
    Io {
        /// File.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The track did not load.
    #[error("{0}")]
    Track(String),
    /// An option is out of its bounds (the message names the flag and the bound).
    #[error("{0}")]
    Options(String),
    /// No view of the object fits the window within the distances, scene after scene.
    #[error("no view of the {kind} at {near}..{far} m gives a box of at least {w}x{h} px inside the {cw}x{ch} image ({scenes} placements in a row gave none): use a smaller --window or nearer --min-distance/--max-distance")]
    NoView {
        /// The object kind.
        kind: String,
        /// Nearest distance, metres.
        near: f64,
        /// Farthest distance, metres.
        far: f64,
        /// Window width, pixels.
        w: u32,
        /// Window height, pixels.
        h: u32,
        /// Camera width, pixels.
        cw: u32,
        /// Camera height, pixels.
        ch: u32,
        /// Placements tried in a row.
        scenes: usize,
    },
}

/// Smallest window side, pixels (as `rccar-train train -W/-H`).
pub const MIN_WINDOW: u32 = 3;
/// Largest window side, pixels (as `rccar-train train -W/-H`); also at most the camera's size.
pub const MAX_WINDOW: u32 = 256;
/// Most samples or frames of one `gen` (each is a PNG file).
pub const MAX_COUNT: usize = 1_000_000;
/// Most object placements of one `gen`.
pub const MAX_SCENES: usize = 10_000;
/// Object distances allowed, metres (`--min-distance`, `--max-distance`).
pub const DISTANCE_M: (f64, f64) = (0.05, 20.0);
/// Placements in a row that give no usable view before `generate` gives up.
pub const MAX_EMPTY_SCENES: usize = 20;

fn io_err(path: &Path, e: impl std::fmt::Display) -> GenError {
    GenError::Io {
        path: path.into(),
        message: e.to_string(),
    }
}

/// An obstacle's target box is its projected bounding box times this (floor around it).
pub const OBSTACLE_MARGIN: f64 = 1.2;

/// OpenCV's integer BT.601 grey of a colour.
fn grey(c: [u8; 3]) -> f64 {
    ((9798 * c[0] as u32 + 19235 * c[1] as u32 + 3735 * c[2] as u32 + 16384) >> 15) as f64
}

/// Window aspect (width / height) the target box is widened to.
pub fn default_window(kind: ObjectClass) -> (u32, u32) {
    kind.info().train_window
}

/// Parses `stop_sign`, `traffic_light`, `obstacle` (and short forms).
pub fn parse_kind(s: &str) -> Option<ObjectClass> {
    ObjectClass::from_label(s)
}

/// The image box [x0, y0, x1, y1] of the part of `ob` a cascade window covers, widened to
/// aspect `aspect` (w/h); `None` if a corner is behind the camera.
pub fn target_box(mount: &CameraMount, pose: &Pose, ob: &Object, aspect: f64) -> Option<[f64; 4]> {
    let (s, c) = ob.yaw.sin_cos();
    let [x, y] = ob.pos;
    let mut pts: Vec<[f64; 3]> = Vec::with_capacity(8);
    match ob.kind.info().shape {
        SimShape::Octagon | SimShape::Triangle | SimShape::ArrowDisc => {
            // The face's bounding rectangle (a triangle is √3/2 as high as wide).
            let half = ob.size[0] / 2.0;
            let half_h = Scene::face_half_height(ob);
            let (fx, fy) = (x + 0.007 * c, y + 0.007 * s);
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                pts.push([fx - a * half * s, fy + a * half * c, ob.height + b * half_h]);
            }
        }
        SimShape::LightHousing => {
            let h = ob.size[0];
            let (hw, hd) = (h * 0.38 / 2.0, h * 0.33 / 2.0);
            for k in 0..8 {
                let lx = if k & 1 == 0 { -hd } else { hd };
                let ly = if k & 2 == 0 { -hw } else { hw };
                let z = ob.height + if k & 4 == 0 { -h / 2.0 } else { h / 2.0 };
                pts.push([x + c * lx - s * ly, y + s * lx + c * ly, z]);
            }
        }
        SimShape::Box => pts.extend(Scene::object_bounds(ob)),
    }
    let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for p in pts {
        let (u, v) = mount.project_world(pose, p)?;
        bb = [bb[0].min(u), bb[1].min(v), bb[2].max(u), bb[3].max(v)];
    }
    let (cx, cy) = ((bb[0] + bb[2]) / 2.0, (bb[1] + bb[3]) / 2.0);
    let (mut w, mut h) = (bb[2] - bb[0], bb[3] - bb[1]);
    if ob.kind.info().shape == SimShape::Box {
        // A margin of floor around the box: its outline is what the features see.
        w *= OBSTACLE_MARGIN;
        h *= OBSTACLE_MARGIN;
    }
    if w / h > aspect {
        h = w / aspect;
    } else {
        w = h * aspect;
    }
    Some([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0])
}

/// Which part of the data to make.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Split {
    /// Positive crops.
    Positives,
    /// Background frames.
    Negatives,
    /// Held-out labelled frames.
    Eval,
}

/// What to generate.
#[derive(Debug, Clone)]
pub struct GenOptions {
    /// Object kind.
    pub kind: ObjectClass,
    /// Which data.
    pub split: Split,
    /// How many samples (positives) or frames.
    pub count: usize,
    /// Seed.
    pub seed: u64,
    /// Nearest and farthest object distance, metres.
    pub distance_m: (f64, f64),
    /// Window size (for the target box's aspect and the smallest usable box).
    pub window: (u32, u32),
    /// Different object placements (scenes) to spread the frames over.
    pub scenes: usize,
    /// Peak relative change of the scene's lighting (`[sim] light_variation`), drawn per
    /// frame at a random phase on top of the exposure; 0 = off (the shipped three kinds).
    pub light_variation: f64,
    /// Strongest `sim.light_level` drawn (docs/light.md: shadows, sun patches, dusk, noise):
    /// each frame takes a level 0..=this at random, its shadows and patches placed by a
    /// seed of its own; 0 = off (no random number drawn: the data as before).
    pub light_level: u32,
}

impl GenOptions {
    /// Refuses options out of their bounds for a `cam_w`×`cam_h` camera: the window
    /// [`MIN_WINDOW`]..=[`MAX_WINDOW`] a side and inside the image, the count 1..=[`MAX_COUNT`],
    /// the scenes 1..=[`MAX_SCENES`], the distances within [`DISTANCE_M`] and near < far.
    pub fn check(&self, cam_w: u32, cam_h: u32) -> Result<(), GenError> {
        let bad = |m: String| Err(GenError::Options(m));
        let (w, h) = self.window;
        if !(MIN_WINDOW..=MAX_WINDOW).contains(&w) || !(MIN_WINDOW..=MAX_WINDOW).contains(&h) {
            return bad(format!(
                "--window {w}x{h}: each side must be {MIN_WINDOW}..={MAX_WINDOW} px"
            ));
        }
        if w > cam_w || h > cam_h {
            return bad(format!(
                "--window {w}x{h}: larger than the {cam_w}x{cam_h} camera image"
            ));
        }
        if !(1..=MAX_COUNT).contains(&self.count) {
            return bad(format!("--count {}: must be 1..={MAX_COUNT}", self.count));
        }
        if !(self.light_variation.is_finite() && (0.0..=0.9).contains(&self.light_variation)) {
            return bad(format!("--light-variation {}: must be 0..=0.9", self.light_variation));
        }
        if self.light_level > 3 {
            return bad(format!("--light-level {}: must be 0..=3", self.light_level));
        }
        if !(1..=MAX_SCENES).contains(&self.scenes) {
            return bad(format!("--scenes {}: must be 1..={MAX_SCENES}", self.scenes));
        }
        let (near, far) = self.distance_m;
        let ok = |d: f64| d.is_finite() && (DISTANCE_M.0..=DISTANCE_M.1).contains(&d);
        if !(ok(near) && ok(far) && near < far) {
            return bad(format!(
                "--min-distance {near} --max-distance {far}: each must be {}..={} m, min < max",
                DISTANCE_M.0, DISTANCE_M.1
            ));
        }
        Ok(())
    }
}

/// The generator: a base track, the car's camera, and the scenes built so far.
pub struct SimGen {
    base: TrackFile,
    cfg: Config,
    mount: CameraMount,
}

fn uniform(r: &mut SplitMix64, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * r.next_f64()
}

fn spec(kind: ObjectClass, x: f64, y: f64, yaw: f64) -> ObjectSpec {
    ObjectSpec {
        kind,
        x,
        y,
        yaw_deg: yaw.to_degrees(),
        enabled: true,
        size_m: vec![],
        height_m: None,
        color: [60, 90, 160],
        cycle_s: [4.0, 1.0, 4.0],
        phase_s: 0.0,
        arrow: None,
    }
}

/// A scene: the track with a target object, distractors, and the target's index.
struct Placed {
    scene: Arc<Scene>,
    target: Object,
}

impl SimGen {
    /// The generator over `track_file` (TOML) with the camera of `cfg`.
    pub fn new(track_file: &Path, cfg: Config) -> Result<SimGen, GenError> {
        let track = Track::load(track_file).map_err(|e| GenError::Track(e.to_string()))?;
        let mount = CameraMount {
            camera: PinholeCamera::from(&cfg.camera),
            x_m: cfg.vehicle.camera_x_m,
        };
        Ok(SimGen {
            base: track.spec,
            cfg,
            mount,
        })
    }

    /// The camera.
    pub fn mount(&self) -> &CameraMount {
        &self.mount
    }

    /// A scene with one target of `kind` beside the road and distractors of the other kinds.
    fn place(&self, kind: ObjectClass, rng: &mut SplitMix64) -> Result<Placed, GenError> {
        let base = Track::from_spec(self.base.clone(), "base").map_err(|e| GenError::Track(e.to_string()))?;
        let mut spec_file = self.base.clone();
        spec_file.objects.clear();
        spec_file.floor.seed = rng.next_u64() % 1000;
        let fl = uniform(rng, 0.8, 1.15);
        spec_file.floor.color = self.base.floor.color.map(|c| (c as f64 * fl).clamp(0.0, 255.0) as u8);
        let spec_file_floor = spec_file.floor.color;
        let half_road = base.spec.road.lane_width_m * base.spec.road.lanes as f64 / 2.0;
        let verge = |rng: &mut SplitMix64, s: f64, kind: ObjectClass| -> ObjectSpec {
            let (p, hd) = base.pose_at(s);
            let side = if rng.next_f64() < 0.75 { -1.0 } else { 1.0 };
            let off = if kind.info().shape == SimShape::Box && rng.next_f64() < 0.5 {
                // In the lane.
                uniform(rng, -half_road * 0.8, half_road * 0.8)
            } else {
                side * (half_road + uniform(rng, 0.08, 0.3))
            };
            let (x, y) = (p[0] - off * hd.sin(), p[1] + off * hd.cos());
            // Facing the oncoming car (right side) or the other way, ± 25°.
            let facing = if side < 0.0 { hd + PI } else { hd } + uniform(rng, -0.45, 0.45);
            let yaw = if kind.info().shape == SimShape::Box {
                uniform(rng, -PI, PI)
            } else {
                facing
            };
            let mut o = spec(kind, x, y, yaw);
            match kind.info().shape {
                SimShape::Box => {
                    o.size_m = vec![
                        uniform(rng, 0.12, 0.22),
                        uniform(rng, 0.10, 0.18),
                        uniform(rng, 0.08, 0.14),
                    ];
                    // A box as grey as the floor is invisible to a grey-level cascade (the
                    // detector skips windows with a grey std dev ≤ 10): keep 30 levels apart.
                    let fg = grey(spec_file_floor);
                    loop {
                        o.color = [0, 1, 2].map(|_| (rng.next_u64() % 220) as u8 + 20);
                        if (grey(o.color) - fg).abs() >= 30.0 {
                            break;
                        }
                    }
                }
                SimShape::Octagon => o.size_m = vec![uniform(rng, 0.095, 0.105)],
                SimShape::Triangle => o.size_m = vec![uniform(rng, 0.114, 0.126)],
                SimShape::ArrowDisc => {
                    o.size_m = vec![uniform(rng, 0.095, 0.105)];
                    o.arrow = Some(if rng.next_f64() < 0.5 {
                        rccar::classes::TurnArrow::Left
                    } else {
                        rccar::classes::TurnArrow::Right
                    });
                }
                SimShape::LightHousing => {
                    o.size_m = vec![uniform(rng, 0.115, 0.125)];
                    o.phase_s = uniform(rng, 0.0, 9.0);
                }
            }
            o
        };
        let s_t = uniform(rng, 0.0, base.length);
        spec_file.objects.push(verge(rng, s_t, kind));
        let others: Vec<ObjectClass> = ObjectClass::ALL.into_iter().filter(|k| *k != kind).collect();
        for i in 0..8 {
            let k = others[i % others.len()];
            // Two near the target (views that hide it are not used), the rest anywhere.
            let s = if i < 2 {
                s_t + uniform(rng, 0.4, 1.5) * if rng.next_f64() < 0.5 { -1.0 } else { 1.0 }
            } else {
                uniform(rng, 0.0, base.length)
            };
            spec_file.objects.push(verge(rng, s, k));
        }
        let track = Track::from_spec(spec_file, "generated").map_err(|e| GenError::Track(e.to_string()))?;
        let target = track.objects[0].0.clone();
        Ok(Placed {
            scene: Arc::new(Scene::new(&track)),
            target,
        })
    }

    /// Random camera effects (with `o.light_variation`, the lighting's gain over the time
    /// the frame is rendered at).
    fn options(&self, o: &GenOptions, rng: &mut SplitMix64) -> RenderOptions {
        RenderOptions {
            noise_sigma: uniform(rng, 0.0, 4.0),
            blur_px: if rng.next_f64() < 0.4 {
                uniform(rng, 0.3, 0.9)
            } else {
                0.0
            },
            exposure: uniform(rng, 0.6, 1.4),
            light_variation: o.light_variation,
            light_period_s: 10.0,
            seed: rng.next_u64(),
            // Shadows, patches and dusk of a random level (none at `light_level` 0: then
            // no number is drawn, and the data is the same as before the option existed).
            light: if o.light_level > 0 {
                let level = (rng.next_u64() % u64::from(o.light_level + 1)) as u32;
                rccar::sim::light::LightOptions::from_level(level, [-1.0; 4], rng.next_u64())
            } else {
                rccar::sim::light::LightOptions::off()
            },
        }
    }

    /// A car pose whose camera sees `ob` at distance `d` from `view` (angle from the object's
    /// facing), with the object at bearing `bearing` off the optical axis.
    fn pose_looking_at(&self, ob: &Object, d: f64, view: f64, bearing: f64) -> Pose {
        let dir = ob.yaw + view;
        let lens = [ob.pos[0] + d * dir.cos(), ob.pos[1] + d * dir.sin()];
        let yaw = dir + PI + bearing;
        let lat = self.mount.camera.lateral_m;
        // Lens = rear axle + R(yaw)·(x_m, lateral).
        let (s, c) = yaw.sin_cos();
        Pose {
            x: lens[0] - (c * self.mount.x_m - s * lat),
            y: lens[1] - (s * self.mount.x_m + c * lat),
            yaw,
        }
    }

    /// A time at which a traffic light shows red or green.
    fn light_time(ob: &Object, rng: &mut SplitMix64) -> f64 {
        let [g, a, r] = ob.cycle_s;
        let p = if rng.next_f64() < 0.5 {
            uniform(rng, 0.05 * g, 0.95 * g)
        } else {
            g + a + uniform(rng, 0.05 * r, 0.95 * r)
        };
        (p - ob.phase_s).rem_euclid(g + a + r)
    }

    /// Renders one view of a target: (frame, pose, t, target box) with the box fully inside
    /// the image and at least the window's size, or `None` after a few tries.
    fn view_of_target(
        &self,
        placed: &Placed,
        o: &GenOptions,
        rng: &mut SplitMix64,
    ) -> Option<(Pose, f64, [f64; 4], RenderOptions)> {
        let cam = &self.mount.camera;
        let aspect = o.window.0 as f64 / o.window.1 as f64;
        let t = &placed.target;
        let floor = placed.scene.track.floor_rect;
        for _ in 0..50 {
            let d = uniform(rng, o.distance_m.0, o.distance_m.1);
            let view = if t.kind.info().shape == SimShape::Box {
                uniform(rng, -PI, PI)
            } else {
                uniform(rng, -0.8, 0.8)
            };
            let bearing = uniform(rng, -0.5, 0.5);
            let pose = self.pose_looking_at(t, d, view, bearing);
            let lens = self.mount.origin(&pose);
            if lens[0] < floor[0] + 0.05
                || lens[0] > floor[2] - 0.05
                || lens[1] < floor[1] + 0.05
                || lens[1] > floor[3] - 0.05
            {
                continue;
            }
            // Not standing inside another object.
            if placed
                .scene
                .track
                .enabled_objects()
                .any(|ob| (ob.pos[0] - lens[0]).hypot(ob.pos[1] - lens[1]) < 0.15)
            {
                continue;
            }
            let Some(b) = target_box(&self.mount, &pose, t, aspect) else {
                continue;
            };
            // Nothing nearer may cover it (the ground truth knows no occlusion).
            let dist = |p: [f64; 2]| (p[0] - lens[0]).hypot(p[1] - lens[1]);
            let covered = placed.scene.track.enabled_objects().any(|ob| {
                ob.index != t.index
                    && dist(ob.pos) < dist(t.pos) + 0.15
                    && bounds_box(&self.mount, &pose, ob)
                        .is_none_or(|o| o[0] < b[2] && o[2] > b[0] && o[1] < b[3] && o[3] > b[1])
            });
            if covered {
                continue;
            }
            let inside =
                b[0] >= 0.0 && b[1] >= 0.0 && b[2] <= cam.width as f64 - 1.0 && b[3] <= cam.height as f64 - 1.0;
            if !inside || b[2] - b[0] < o.window.0 as f64 || b[3] - b[1] < o.window.1 as f64 {
                continue;
            }
            let time = if t.kind.info().shape == SimShape::LightHousing {
                Self::light_time(t, rng)
            } else if o.light_variation > 0.0 {
                // Any phase of the lighting's change (10 s period).
                uniform(rng, 0.0, 10.0)
            } else {
                0.0
            };
            return Some((pose, time, b, self.options(o, rng)));
        }
        None
    }

    fn render(&self, placed: &Placed, pose: &Pose, t: f64, opts: RenderOptions, frame: u64) -> RgbImage {
        let mut r = Renderer::new(placed.scene.clone(), self.mount, opts);
        r.render_new(pose, t, frame)
    }

    /// Writes `o.count` samples or frames into `dir` (created); returns the list file written.
    pub fn generate(&self, o: &GenOptions, dir: &Path, progress: &mut dyn FnMut(usize)) -> Result<PathBuf, GenError> {
        let (cw, ch) = (self.mount.camera.width, self.mount.camera.height);
        o.check(cw, ch)?;
        std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
        let list = dir.join(if o.split == Split::Negatives {
            "bg.txt"
        } else {
            "info.dat"
        });
        let mut out = std::io::BufWriter::new(std::fs::File::create(&list).map_err(|e| io_err(&list, e))?);
        // Held-out frames of a class that reads an arrow: the colour frames too (rgb/) and the
        // true arrow of each (arrows.txt), to score the arrow reading.
        let arrows_path = dir.join("arrows.txt");
        let mut arrows = if o.split == Split::Eval && o.kind.info().reads_arrow {
            std::fs::create_dir_all(dir.join("rgb")).map_err(|e| io_err(dir, e))?;
            Some(std::io::BufWriter::new(
                std::fs::File::create(&arrows_path).map_err(|e| io_err(&arrows_path, e))?,
            ))
        } else {
            None
        };
        let mut rng = SplitMix64::new(mix(o.seed ^ 0x5EED_0000 ^ (o.kind as u64) << 8 ^ o.split as u64));
        let scenes = o.scenes.max(1);
        let per_scene = o.count.div_ceil(scenes);
        let aspect = o.window.0 as f64 / o.window.1 as f64;
        let mut n = 0usize;
        let mut gray = GrayImage::new(self.mount.camera.width, self.mount.camera.height);
        let mut empty_scenes = 0usize;
        while n < o.count {
            // A window no view can fill would otherwise place scenes forever.
            if empty_scenes >= MAX_EMPTY_SCENES {
                return Err(GenError::NoView {
                    kind: format!("{:?}", o.kind),
                    near: o.distance_m.0,
                    far: o.distance_m.1,
                    w: o.window.0,
                    h: o.window.1,
                    cw,
                    ch,
                    scenes: empty_scenes,
                });
            }
            let placed = self.place(o.kind, &mut rng)?;
            let mut in_scene = 0;
            let mut misses = 0;
            while in_scene < per_scene && n < o.count && misses < 100 {
                let name = format!("{n:06}.png");
                let path = dir.join(&name);
                let line = match o.split {
                    Split::Positives | Split::Eval => {
                        let Some((pose, t, b, ro)) = self.view_of_target(&placed, o, &mut rng) else {
                            misses += 1;
                            continue;
                        };
                        let img = self.render(&placed, &pose, t, ro, n as u64);
                        rccar::detect::gray_from_rgb(&img, &mut gray);
                        if o.split == Split::Eval {
                            gray.save(&path).map_err(|e| io_err(&path, e))?;
                            if let (Some(a), Some(arrow)) = (arrows.as_mut(), placed.target.arrow) {
                                let rgb = dir.join("rgb").join(&name);
                                img.save(&rgb).map_err(|e| io_err(&rgb, e))?;
                                writeln!(a, "{name} {}", arrow.name()).map_err(|e| io_err(&arrows_path, e))?;
                            }
                            let r = round_box(b);
                            format!("{name} 1 {} {} {} {}", r[0], r[1], r[2], r[3])
                        } else {
                            match self.positive_crop(&gray, b, o, &mut rng, &path, &name)? {
                                Some(l) => l,
                                None => {
                                    misses += 1;
                                    continue;
                                }
                            }
                        }
                    }
                    Split::Negatives => {
                        match self.negative_frame(&placed, o, &mut rng, &mut gray, aspect, &path, &name, n)? {
                            Some(l) => l,
                            None => {
                                misses += 1;
                                continue;
                            }
                        }
                    }
                };
                writeln!(out, "{line}").map_err(|e| io_err(&list, e))?;
                n += 1;
                in_scene += 1;
                progress(n);
            }
            empty_scenes = if in_scene == 0 { empty_scenes + 1 } else { 0 };
        }
        out.flush().map_err(|e| io_err(&list, e))?;
        if let Some(mut a) = arrows {
            a.flush().map_err(|e| io_err(&arrows_path, e))?;
        }
        Ok(list)
    }

    /// A positive sample from the frame `gray` whose target box is `b`: the box jittered
    /// (±6% shift, ±7% size) and a crop 1.5× the box saved to `path`; its info.dat line, or
    /// `None` when the jittered box leaves the frame or is below the window.
    fn positive_crop(
        &self,
        gray: &GrayImage,
        b: [f64; 4],
        o: &GenOptions,
        rng: &mut SplitMix64,
        path: &Path,
        name: &str,
    ) -> Result<Option<String>, GenError> {
        // Jitter: ±6% shift, ±7% size (the detector's grid: 2 px steps, 1.1× scales); then a crop 1.5× the box.
        let (w, h) = (b[2] - b[0], b[3] - b[1]);
        let k = uniform(rng, 0.93, 1.07);
        let (cx, cy) = (
            (b[0] + b[2]) / 2.0 + uniform(rng, -0.06, 0.06) * w,
            (b[1] + b[3]) / 2.0 + uniform(rng, -0.06, 0.06) * h,
        );
        let (w, h) = (w * k, h * k);
        let jb = [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0];
        let r = round_box(jb);
        let (iw, ih) = (gray.width() as i64, gray.height() as i64);
        if r[0] < 0
            || r[1] < 0
            || r[0] + r[2] > iw
            || r[1] + r[3] > ih
            || r[2] < o.window.0 as i64
            || r[3] < o.window.1 as i64
        {
            return Ok(None);
        }
        let cx0 = (r[0] - r[2] / 4).max(0);
        let cy0 = (r[1] - r[3] / 4).max(0);
        let cx1 = (r[0] + r[2] + r[2] / 4).min(iw);
        let cy1 = (r[1] + r[3] + r[3] / 4).min(ih);
        let crop =
            image::imageops::crop_imm(gray, cx0 as u32, cy0 as u32, (cx1 - cx0) as u32, (cy1 - cy0) as u32).to_image();
        crop.save(path).map_err(|e| io_err(path, e))?;
        Ok(Some(format!(
            "{name} 1 {} {} {} {}",
            r[0] - cx0,
            r[1] - cy0,
            r[2],
            r[3]
        )))
    }

    /// A negative frame of the scene `placed` saved to `path`: driving along the lane (40%),
    /// looking at the target (40%: its surroundings are the hardest negatives) or at some other
    /// object, with the target's box listed where it is in view; its bg.txt line, or `None`
    /// when the lens is off the floor.
    #[allow(clippy::too_many_arguments)]
    fn negative_frame(
        &self,
        placed: &Placed,
        o: &GenOptions,
        rng: &mut SplitMix64,
        gray: &mut GrayImage,
        aspect: f64,
        path: &Path,
        name: &str,
        n: usize,
    ) -> Result<Option<String>, GenError> {
        // Driving along the lane (40%), looking at the target (40%: its
        // surroundings are the hardest negatives) or at some other object.
        let track = &placed.scene.track;
        let r = rng.next_f64();
        let near_target = if (0.4..0.8).contains(&r) {
            self.view_of_target(placed, o, rng).map(|v| v.0)
        } else {
            None
        };
        let pose = if let Some(p) = near_target {
            p
        } else if r < 0.4 {
            let s = uniform(rng, 0.0, track.length);
            let (p, hd) = track.lane_pose_at(s);
            let lat = uniform(rng, -0.12, 0.12);
            Pose {
                x: p[0] - lat * hd.sin(),
                y: p[1] + lat * hd.cos(),
                yaw: hd + uniform(rng, -0.3, 0.3),
            }
        } else {
            let objs: Vec<&Object> = track.enabled_objects().collect();
            let ob = objs[(rng.next_u64() % objs.len() as u64) as usize];
            let view = uniform(rng, -1.2, 1.2);
            self.pose_looking_at(ob, uniform(rng, 0.2, 2.0), view, uniform(rng, -0.5, 0.5))
        };
        let lens = self.mount.origin(&pose);
        let fr = track.floor_rect;
        if lens[0] < fr[0] || lens[0] > fr[2] || lens[1] < fr[1] || lens[1] > fr[3] {
            return Ok(None);
        }
        let t = uniform(rng, 0.0, 9.0);
        let ro = self.options(o, rng);
        let img = self.render(placed, &pose, t, ro, n as u64);
        rccar::detect::gray_from_rgb(&img, gray);
        gray.save(path).map_err(|e| io_err(path, e))?;
        // Keep the target out of the negatives where it is in view.
        let boxes: Vec<[i64; 4]> = target_box(&self.mount, &pose, &placed.target, aspect)
            .filter(|b| b[2] > 0.0 && b[3] > 0.0 && b[0] < gray.width() as f64 && b[1] < gray.height() as f64)
            .map(round_box)
            .into_iter()
            .collect();
        let mut l = format!("{name} {}", boxes.len());
        for r in boxes {
            l += &format!(" {} {} {} {}", r[0], r[1], r[2], r[3]);
        }
        Ok(Some(l))
    }

    /// The configuration the camera came from.
    pub fn config(&self) -> &Config {
        &self.cfg
    }
}

/// The projected bounding box of a whole object, or `None` if a corner is behind the camera.
fn bounds_box(mount: &CameraMount, pose: &Pose, ob: &Object) -> Option<[f64; 4]> {
    let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for p in Scene::object_bounds(ob) {
        let (u, v) = mount.project_world(pose, p)?;
        bb = [bb[0].min(u), bb[1].min(v), bb[2].max(u), bb[3].max(v)];
    }
    Some(bb)
}

/// [x0, y0, x1, y1] → integer (x, y, w, h).
pub fn round_box(b: [f64; 4]) -> [i64; 4] {
    let x = b[0].round() as i64;
    let y = b[1].round() as i64;
    [x, y, (b[2].round() as i64 - x).max(1), (b[3].round() as i64 - y).max(1)]
}
