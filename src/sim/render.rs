//! The simulated camera: renders what a pinhole camera on the car sees of a [`Scene`].
//!
//! 1. Once per camera: for every image row, the floor points its rays meet (in the car's
//!    frame) and their Jacobian with respect to the pixel coordinates, i.e. each pixel's
//!    footprint on the floor. With no roll these move linearly along a row, so a frame only
//!    rotates four vectors per row into the world and steps along it.
//! 2. Per frame, floor pixels are shaded by [`Scene::floor_color`] (texture, lighting and
//!    anti-aliased lines); rays that leave the room or never come down meet walls or ceiling.
//! 3. Objects: each object's bounding box is projected; pixels inside it are ray-cast against
//!    the object's solids at 2×2 samples per pixel (anti-aliased silhouettes), far objects
//!    first so near ones cover them.
//! 4. The camera: exposure, slow lighting changes, vignetting (cos⁴ falloff), optional blur
//!    (separable Gaussian) and seeded noise (triangular, per channel).
//!
//! The camera is a parameter ([`CameraMount`]), so a second (stereo) camera is a second
//! `Renderer` on the same scene, and [`Renderer::object_boxes`] gives the image box of each
//! object for training crops and ground truth. Units: metres, seconds, pixels.

use super::light::{LightMap, LightOptions, Tint};
use super::rng::{mix, SplitMix64};
use super::scene::{Footprint, Prim, Scene};
use super::track::Object;
use super::vehicle::Pose;
use crate::camera::PinholeCamera;
use crate::classes::ObjectClass;
use crate::config::SimConfig;
use image::RgbImage;
use std::ops::Range;
use std::sync::Arc;

/// Extra noise values beyond one frame's worth, so each frame can start at its own offset.
const NOISE_SLACK: usize = 1 << 16;
/// Columns between lighting samples along a row (the lighting changes over metres).
const LIGHT_STEP: usize = 8;

/// Where a camera sits on the car.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    /// Intrinsics, height, tilt and lateral offset (`lateral_m`, left positive).
    pub camera: PinholeCamera,
    /// Distance of the lens ahead of the rear axle, metres.
    pub x_m: f64,
}

impl CameraMount {
    /// The lens position in the world for the car at `pose`.
    pub fn origin(&self, pose: &Pose) -> [f64; 3] {
        let p = pose.to_world([self.x_m, self.camera.lateral_m]);
        [p[0], p[1], self.camera.height_m]
    }

    /// Projects a world point into this camera's image for the car at `pose`.
    pub fn project_world(&self, pose: &Pose, p: [f64; 3]) -> Option<(f64, f64)> {
        let (s, c) = pose.yaw.sin_cos();
        let (dx, dy) = (p[0] - pose.x, p[1] - pose.y);
        // World -> rear-axle frame -> the camera model's frame (origin below the lens' x).
        let x = c * dx + s * dy - self.x_m;
        let y = -s * dx + c * dy;
        self.camera.project([x, y, p[2]])
    }

    /// A world point given in the camera model's car frame (x forward from below the lens).
    pub fn to_world(&self, pose: &Pose, p: [f64; 2]) -> [f64; 2] {
        pose.to_world([p[0] + self.x_m, p[1]])
    }
}

/// Camera effects, from `[sim]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Pixel noise, standard deviation in grey levels.
    pub noise_sigma: f64,
    /// Gaussian blur sigma, pixels (0 = none).
    pub blur_px: f64,
    /// Exposure gain.
    pub exposure: f64,
    /// Peak relative change of the lighting over time.
    pub light_variation: f64,
    /// Period of that change, seconds.
    pub light_period_s: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Shadows, bright patches, dusk and low-light noise ([`super::light`]).
    pub light: LightOptions,
}

impl RenderOptions {
    /// The options of a `[sim]` section.
    pub fn from_config(c: &SimConfig) -> RenderOptions {
        RenderOptions {
            noise_sigma: c.noise_sigma,
            blur_px: c.blur_px,
            exposure: c.exposure,
            light_variation: c.light_variation,
            light_period_s: c.light_period_s,
            seed: c.seed as u64,
            light: c.light(),
        }
    }

    /// A clean image: no noise, blur or lighting change.
    pub fn clean() -> RenderOptions {
        RenderOptions {
            noise_sigma: 0.0,
            blur_px: 0.0,
            exposure: 1.0,
            light_variation: 0.0,
            light_period_s: 10.0,
            seed: 0,
            light: LightOptions::off(),
        }
    }
}

/// Floor geometry of one image row, in the camera model's car frame. The camera has no
/// roll, so a row's rays meet the floor on a line of constant forward distance, and the floor
/// point moves linearly with the column: `g(u) = g0 + u·dg`; likewise its derivative in v.
#[derive(Debug, Clone, Copy, Default)]
struct RowGeom {
    /// Whether the row's rays come down to the floor at all.
    floor: bool,
    /// Floor point of column 0 and its step per column.
    g0: [f64; 2],
    dg: [f64; 2],
    /// d(floor point)/dv at column 0 and its step per column.
    jv0: [f64; 2],
    djv: [f64; 2],
    /// Largest |ju| + |jv| along the row, metres.
    size: f32,
    /// Texture fade for that footprint.
    fade: f32,
}

/// Where an object appears in one frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectBox {
    /// Index of the object in the track file.
    pub index: usize,
    /// What it is.
    pub kind: ObjectClass,
    /// Horizontal distance from the lens to the object's base, metres.
    pub distance_m: f64,
    /// Image box [left, top, right, bottom], pixels, clipped to the image.
    pub bbox: [f64; 4],
    /// Whether the box was cut by the image border.
    pub clipped: bool,
}

/// Image rows per task of step 2 of [`Renderer::render_rows`] (spread over threads with
/// feature `parallel`): a few rows, so two cores share a frame's 240 rows evenly without a task
/// per row.
const ROWS_PER_TASK: usize = 8;

/// One task's scratch of step 2: a row's lighting and texture, per pixel.
type RowScratch = (Vec<f32>, Vec<f32>);

/// Where one frame is seen from, shared by the steps of [`Renderer::render_rows`].
struct View {
    /// The camera's optical centre, world metres.
    o: [f64; 3],
    /// sin and cos of the car's heading.
    yaw: (f64, f64),
    /// The lens's floor point (the camera above it), world metres.
    lens: [f64; 2],
    /// Global gain: exposure and the slow lighting change.
    gain: f32,
    /// The floor's and walls' gain: `gain` and dusk's dimming (the objects keep `gain`).
    room_gain: f32,
}

/// Renders a scene through one camera.
#[derive(Debug, Clone)]
pub struct Renderer {
    scene: Arc<Scene>,
    mount: CameraMount,
    opts: RenderOptions,
    rows: Vec<RowGeom>,
    /// Vignetting gain per pixel.
    vig: Vec<f32>,
    /// Camera noise, one signed value per channel, reused at a random offset per frame.
    noise: Vec<i8>,
    prims: Vec<Prim>,
    /// Scratch of step 2, one (lighting, texture) pair of row buffers per task of
    /// [`ROWS_PER_TASK`] rows, kept between frames.
    scratch: Vec<RowScratch>,
    /// Scratch: each solid's pixel rectangle [u0, v0, u1, v1] (see the object pass).
    prim_rects: Vec<[f64; 4]>,
    /// Scratch: the solids a pixel is cast against.
    active: Vec<Prim>,
    /// (sin, cos) of the camera's tilt.
    tilt_sc: (f64, f64),
    /// Shadows and bright patches on the floor, and dusk's colour (none at light level 0).
    light_map: Option<Arc<LightMap>>,
    tint: Option<Tint>,
}

impl Renderer {
    /// Precomputes the per-row and per-pixel tables for `mount` (a few ms).
    pub fn new(scene: Arc<Scene>, mount: CameraMount, opts: RenderOptions) -> Renderer {
        let cam = mount.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let g = |u: f64, v: f64| cam.ground_of_pixel(u, v).map(|p| [p.0, p.1]);
        let sub = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
        let mut rows = vec![RowGeom::default(); h];
        for (v, row) in rows.iter_mut().enumerate() {
            let vf = v as f64;
            // Half a pixel above must still see the floor, or the footprint is unbounded.
            let (Some(a0), Some(a1), Some(up0), Some(dn0), Some(up1), Some(dn1)) = (
                g(0.0, vf),
                g(1.0, vf),
                g(0.0, vf - 0.5),
                g(0.0, vf + 0.5),
                g(1.0, vf - 0.5),
                g(1.0, vf + 0.5),
            ) else {
                continue;
            };
            let jv0 = sub(dn0, up0);
            let jv1 = sub(dn1, up1);
            let dg = sub(a1, a0);
            let djv = sub(jv1, jv0);
            let last = (w - 1) as f64;
            let jv_end = [jv0[0] + last * djv[0], jv0[1] + last * djv[1]];
            let size = dg[0].hypot(dg[1]) + jv0[0].hypot(jv0[1]).max(jv_end[0].hypot(jv_end[1]));
            if !size.is_finite() || size > 50.0 {
                continue;
            }
            *row = RowGeom {
                floor: true,
                g0: a0,
                dg,
                jv0,
                djv,
                size: size as f32,
                fade: Footprint::fade_for(size),
            };
        }
        let mut vig = vec![0f32; w * h];
        for v in 0..h {
            for u in 0..w {
                // cos⁴ falloff off axis, softened (a real lens, not a pinhole).
                let r2 = ((u as f64 - cam.u0).powi(2) + (v as f64 - cam.v0).powi(2)) / (cam.f_px * cam.f_px);
                let cos2 = 1.0 / (1.0 + r2);
                vig[v * w + u] = (1.0 - 0.25 * (1.0 - cos2 * cos2)) as f32;
            }
        }
        // Triangular noise (two uniform bytes), standard deviation `noise_sigma`.
        let n = 3 * w * h + NOISE_SLACK;
        let sigma = opts.noise_sigma + opts.light.noise;
        let a = sigma * 6f64.sqrt() / 255.0;
        let mut rng = SplitMix64::new(opts.seed ^ 0x006E_6F69_7365);
        let noise = if sigma > 0.0 {
            (0..n)
                .map(|_| {
                    let r = rng.next_u64();
                    let (b1, b2) = ((r & 0xFF) as f64, ((r >> 8) & 0xFF) as f64);
                    ((b1 + b2 - 255.0) * a).round().clamp(-127.0, 127.0) as i8
                })
                .collect()
        } else {
            Vec::new()
        };
        let light_map = (opts.light.has_map()).then(|| {
            Arc::new(LightMap::new(
                &scene.track,
                &super::light::shapes(&scene.track, &opts.light),
            ))
        });
        let tint = Tint::new(opts.light.dusk);
        Renderer {
            scene,
            mount,
            opts,
            rows,
            vig,
            noise,
            prims: Vec::new(),
            scratch: Vec::new(),
            prim_rects: Vec::new(),
            active: Vec::new(),
            tilt_sc: cam.tilt_rad.sin_cos(),
            light_map,
            tint,
        }
    }

    /// The camera this renderer draws for.
    pub fn mount(&self) -> &CameraMount {
        &self.mount
    }

    /// The scene.
    pub fn scene(&self) -> &Arc<Scene> {
        &self.scene
    }

    /// Renders the view from the car at `pose` at time `t_s`; `frame` (the frame number)
    /// seeds the noise, so the same run gives the same images.
    pub fn render(&mut self, pose: &Pose, t_s: f64, frame: u64, img: &mut RgbImage) {
        let h = self.mount.camera.height as usize;
        self.render_rows(pose, t_s, frame, img, 0..h);
    }

    /// Like [`Renderer::render`], but only image rows `rows` (the rest of `img` is left as
    /// it was). Each row comes out exactly as in a full render (with blur, the rows within
    /// 3σ of the range are needed too), so a consumer that reads only some rows, such as the
    /// lane pipeline reading its ROI, decides exactly as on full frames.
    pub fn render_rows(&mut self, pose: &Pose, t_s: f64, frame: u64, img: &mut RgbImage, rows: Range<usize>) {
        let cam = self.mount.camera;
        let h = cam.height as usize;
        let rows = rows.start.min(h)..rows.end.min(h);
        if img.dimensions() != (cam.width, cam.height) {
            *img = RgbImage::new(cam.width, cam.height);
        }
        // 1. Global gain: exposure and the slow lighting change.
        let gain = (self.opts.exposure
            * (1.0
                + self.opts.light_variation * (std::f64::consts::TAU * t_s / self.opts.light_period_s.max(1e-3)).sin()))
            as f32;
        let view = View {
            o: self.mount.origin(pose),
            yaw: pose.yaw.sin_cos(),
            lens: pose.to_world([self.mount.x_m, 0.0]),
            gain,
            room_gain: gain * self.opts.light.dim(),
        };
        // 2. Floor, walls, ceiling, row by row: each row depends only on the view, so the
        // rows go in tasks of ROWS_PER_TASK, spread over threads with feature `parallel`, each
        // task with its own scratch pair, kept between frames (no allocation per frame);
        // every pixel comes out the same as on one thread.
        let w = cam.width as usize;
        let band = &mut img.as_mut()[3 * w * rows.start..3 * w * rows.end];
        let first = rows.start;
        let mut scratch = std::mem::take(&mut self.scratch);
        let tasks = rows.len().div_ceil(ROWS_PER_TASK);
        if scratch.len() < tasks {
            scratch.resize_with(tasks, Default::default);
        }
        let this = &*self;
        let task = |(i, (chunk, (light, tex))): (usize, (&mut [u8], &mut RowScratch))| {
            for (j, out) in chunk.chunks_exact_mut(3 * w).enumerate() {
                this.render_row(&view, first + i * ROWS_PER_TASK + j, out, light, tex);
            }
        };
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            band.par_chunks_mut(3 * w * ROWS_PER_TASK)
                .zip(scratch.par_iter_mut())
                .enumerate()
                .for_each(task);
        }
        #[cfg(not(feature = "parallel"))]
        band.chunks_mut(3 * w * ROWS_PER_TASK)
            .zip(scratch.iter_mut())
            .enumerate()
            .for_each(task);
        self.scratch = scratch;
        if let Some(t) = &self.tint {
            let w = cam.width as usize;
            t.apply(&mut img.as_mut()[3 * w * rows.start..3 * w * rows.end]);
        }
        // 3. Objects, far ones first.
        self.render_objects(pose, t_s, &view, &rows, img);
        // 4. Blur and noise.
        self.blur_and_noise(frame, &rows, img);
    }

    /// Step 2 of [`Renderer::render_rows`] for image row `v`: floor, walls or ceiling. The
    /// floor point and its footprint move by a fixed step per column.
    /// `out` is the row's pixels (RGB); `light_buf` and `tex_buf` are scratch.
    fn render_row(&self, view: &View, v: usize, out: &mut [u8], light_buf: &mut Vec<f32>, tex_buf: &mut Vec<f32>) {
        let w = self.mount.camera.width as usize;
        let scene = &*self.scene;
        let (o, (sy, cy), lens, gain) = (view.o, view.yaw, view.lens, view.room_gain);
        let rot = |x: f64, y: f64| -> [f64; 2] { [cy * x - sy * y, sy * x + cy * y] };
        let row = self.rows[v];
        let vig = &self.vig[v * w..(v + 1) * w];
        let g0 = rot(row.g0[0], row.g0[1]);
        let dg = rot(row.dg[0], row.dg[1]);
        let ju = dg;
        let jv0 = rot(row.jv0[0], row.jv0[1]);
        let djv = rot(row.djv[0], row.djv[1]);
        // The lighting every LIGHT_STEP columns, and the texture about once per texel
        // (where it is not faded out), interpolated between.
        let tstep = (Footprint::TEXEL_M / row.dg[0].hypot(row.dg[1]))
            .floor()
            .clamp(1.0, 16.0) as usize;
        let textured = row.floor && row.fade > 0.01;
        let at = |u: usize| [lens[0] + g0[0] + u as f64 * dg[0], lens[1] + g0[1] + u as f64 * dg[1]];
        // The row is a straight segment and the floor a rectangle: both ends on it means
        // every pixel is.
        let all_floor = row.floor && scene.on_floor(at(0)) && scene.on_floor(at(w - 1));
        if row.floor {
            // Samples, then per-pixel values by linear interpolation (simple loops the
            // compiler vectorises; no division per pixel).
            match &self.light_map {
                None => lerp_fill(light_buf, w, LIGHT_STEP, |u| scene.illumination(at(u))),
                Some(m) => lerp_fill(light_buf, w, LIGHT_STEP, |u| scene.illumination(at(u)) * m.at(at(u))),
            }
            if textured {
                lerp_fill(tex_buf, w, tstep, |u| scene.texture_at(at(u)) * row.fade);
            }
        }
        // Columns before `probe_from` are known to be clear of every line (see
        // `Scene::floor_color`): the distance to a line shrinks by at most one step per
        // column.
        let step_len = row.dg[0].hypot(row.dg[1]) as f32;
        let mut probe_from = 0usize;
        let mut u = 0usize;
        while u < w {
            if all_floor && u < probe_from {
                // A run of pixels known to be clear of every line: bare floor only (the
                // same arithmetic as `floor_color` without a probe), no positions needed.
                let end = probe_from.min(w);
                let (light, tex) = (&light_buf[u..end], &tex_buf[..]);
                for (j, ((px, &vg), &l)) in out[3 * u..3 * end]
                    .chunks_exact_mut(3)
                    .zip(&vig[u..end])
                    .zip(light)
                    .enumerate()
                {
                    let t = if textured { tex[u + j] } else { 0.0 };
                    let c = scene.plain_floor(l, t);
                    let k = gain * vg;
                    px[0] = (c[0] * k) as u8;
                    px[1] = (c[1] * k) as u8;
                    px[2] = (c[2] * k) as u8;
                }
                u = end;
                continue;
            }
            let (px, vg) = (&mut out[3 * u..3 * u + 3], vig[u]);
            let uf = u as f64;
            let p = [lens[0] + g0[0] + uf * dg[0], lens[1] + g0[1] + uf * dg[1]];
            let c = if all_floor || (row.floor && scene.on_floor(p)) {
                let fp = Footprint {
                    ju,
                    jv: [jv0[0] + uf * djv[0], jv0[1] + uf * djv[1]],
                    size: row.size,
                    fade: row.fade,
                };
                let light = light_buf[u];
                let tex = if textured { tex_buf[u] } else { 0.0 };
                let probe = u >= probe_from;
                let (c, clear) = scene.floor_color(p, &fp, light, tex, probe);
                if probe && clear > row.size {
                    probe_from = u + 1 + ((clear - row.size) / step_len.max(1e-9)).min(w as f32) as usize;
                }
                c
            } else {
                scene.wall_color(o, self.world_ray((sy, cy), uf, v as f64))
            };
            let k = gain * vg;
            // `as u8` saturates (and maps NaN to 0): no clamp needed.
            px[0] = (c[0] * k) as u8;
            px[1] = (c[1] * k) as u8;
            px[2] = (c[2] * k) as u8;
            u += 1;
        }
    }

    /// Step 3 of [`Renderer::render_rows`]: the track's objects over the rows `rows`, far ones
    /// first, each pixel from four rays (±¼ pixel) blended over what step 2 drew.
    fn render_objects(&mut self, pose: &Pose, t_s: f64, view: &View, rows: &Range<usize>, img: &mut RgbImage) {
        let w = self.mount.camera.width as usize;
        let scene = &*self.scene;
        let (o, (sy, cy), gain) = (view.o, view.yaw, view.gain);
        let buf: &mut [u8] = img.as_mut();
        let mut order: Vec<(f64, &Object)> = scene
            .track
            .enabled_objects()
            .map(|ob| ((ob.pos[0] - o[0]).hypot(ob.pos[1] - o[1]), ob))
            .collect();
        order.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (_, ob) in order {
            let Some(rect) = self.screen_rect(pose, ob) else {
                continue;
            };
            self.prims.clear();
            scene.object_prims(ob, t_s, &mut self.prims);
            let [u0, v0, u1, v1] = rect;
            // Each solid's own pixel rectangle (its bounds projected, one pixel of slack for
            // the ±¼-pixel samples): a pixel is cast only against the solids whose rectangle
            // holds it, in their order, and not at all outside every one. A ray outside a
            // solid's rectangle misses it, so the image is the same.
            self.prim_rects.clear();
            for p in &self.prims {
                let mut r = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
                let mut all = true;
                for c in p.bounds() {
                    match self.mount.project_world(pose, c) {
                        Some((u, v)) => r = [r[0].min(u), r[1].min(v), r[2].max(u), r[3].max(v)],
                        None => all = false,
                    }
                }
                let r = if all && r.iter().all(|x| x.is_finite()) {
                    [
                        r[0].floor() - 1.0,
                        r[1].floor() - 1.0,
                        r[2].ceil() + 1.0,
                        r[3].ceil() + 1.0,
                    ]
                } else {
                    [f64::NEG_INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::INFINITY]
                };
                self.prim_rects.push(r);
            }
            let mut mask_of_active = 0u64;
            for v in v0.max(rows.start)..=v1.min(rows.end.saturating_sub(1)) {
                for u in u0..=u1 {
                    let (uf, vf) = (u as f64, v as f64);
                    let mut mask = 0u64;
                    for (k, r) in self.prim_rects.iter().enumerate().take(64) {
                        if uf >= r[0] && uf <= r[2] && vf >= r[1] && vf <= r[3] {
                            mask |= 1 << k;
                        }
                    }
                    if self.prims.len() > 64 {
                        mask = u64::MAX;
                    }
                    if mask == 0 {
                        continue;
                    }
                    if mask != mask_of_active {
                        self.active.clear();
                        for (k, p) in self.prims.iter().enumerate() {
                            if k >= 64 || mask & (1 << k) != 0 {
                                self.active.push(*p);
                            }
                        }
                        mask_of_active = mask;
                    }
                    let mut sum = [0f32; 3];
                    let mut hits = 0;
                    for (du, dv) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                        let d = self.world_ray((sy, cy), u as f64 + du, v as f64 + dv);
                        let t_floor = if d[2] < 0.0 { o[2] / -d[2] } else { f64::INFINITY };
                        if let Some(hit) = scene.intersect(&self.active, o, d, t_floor) {
                            for (acc, c) in sum.iter_mut().zip(hit.rgb) {
                                *acc += c;
                            }
                            hits += 1;
                        }
                    }
                    if hits == 0 {
                        continue;
                    }
                    let k = gain * self.vig[v * w + u];
                    let i = 3 * (v * w + u);
                    for ch in 0..3 {
                        let bg = buf[i + ch] as f32;
                        let c = (sum[ch] * k + bg * (4 - hits) as f32) / 4.0;
                        buf[i + ch] = c.clamp(0.0, 255.0) as u8;
                    }
                }
            }
        }
    }

    /// Step 4 of [`Renderer::render_rows`]: the lens blur, then the frame's sensor noise over
    /// the rows `rows`.
    fn blur_and_noise(&mut self, frame: u64, rows: &Range<usize>, img: &mut RgbImage) {
        let w = self.mount.camera.width as usize;
        if self.opts.blur_px > 0.0 {
            gaussian_blur(img, self.opts.blur_px);
        }
        if !self.noise.is_empty() {
            // The frame's noise: the table read from a random offset (seeded by the frame).
            let off = (mix(self.opts.seed ^ frame.wrapping_mul(0x9E37_79B9_7F4A_7C15)) % NOISE_SLACK as u64) as usize;
            let buf: &mut [u8] = img.as_mut();
            let (a, b) = (3 * w * rows.start, 3 * w * rows.end);
            let noise = &self.noise[off + a..off + b];
            for (val, &n) in buf[a..b].iter_mut().zip(noise) {
                *val = val.saturating_add_signed(n);
            }
        }
    }

    /// A fresh image of the camera's size with the view from `pose` at `t_s`.
    pub fn render_new(&mut self, pose: &Pose, t_s: f64, frame: u64) -> RgbImage {
        let mut img = RgbImage::new(self.mount.camera.width, self.mount.camera.height);
        self.render(pose, t_s, frame, &mut img);
        img
    }

    /// The ray through pixel (u, v), world frame.
    /// `sc` is (sin, cos) of the car's yaw. Not normalised: every user compares ray
    /// parameters along the same ray only.
    #[inline]
    fn world_ray(&self, sc: (f64, f64), u: f64, v: f64) -> [f64; 3] {
        // PinholeCamera::ray, with the tilt's sine and cosine computed once.
        let cam = &self.mount.camera;
        let (a, b) = ((u - cam.u0) / cam.f_px, (v - cam.v0) / cam.f_px);
        let (ts, tc) = self.tilt_sc;
        // forward (tc, 0, −ts), right (0, −1, 0), down (−ts, 0, −tc)
        let r = [tc - b * ts, -a, -ts - b * tc];
        let (s, c) = sc;
        [c * r[0] - s * r[1], s * r[0] + c * r[1], r[2]]
    }

    /// The pixel rectangle [u0, v0, u1, v1] (inclusive, clipped) an object can cover, or
    /// `None` when it is out of view.
    fn screen_rect(&self, pose: &Pose, ob: &Object) -> Option<[usize; 4]> {
        let b = self.object_box(pose, ob)?;
        let bb = b.bbox;
        Some([
            bb[0].floor().max(0.0) as usize,
            bb[1].floor().max(0.0) as usize,
            (bb[2].ceil() as usize).min(self.mount.camera.width as usize - 1),
            (bb[3].ceil() as usize).min(self.mount.camera.height as usize - 1),
        ])
    }

    /// Where an object appears: its bounding box's projection, clipped; `None` when any
    /// corner is behind the camera or the box is outside the image.
    pub fn object_box(&self, pose: &Pose, ob: &Object) -> Option<ObjectBox> {
        let cam = &self.mount.camera;
        let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for p in Scene::object_bounds(ob) {
            let (u, v) = self.mount.project_world(pose, p)?;
            bb = [bb[0].min(u), bb[1].min(v), bb[2].max(u), bb[3].max(v)];
        }
        let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
        if bb[2] < 0.0 || bb[3] < 0.0 || bb[0] > w || bb[1] > h {
            return None;
        }
        let clipped = bb[0] < 0.0 || bb[1] < 0.0 || bb[2] > w || bb[3] > h;
        let o = self.mount.origin(pose);
        Some(ObjectBox {
            index: ob.index,
            kind: ob.kind,
            distance_m: (ob.pos[0] - o[0]).hypot(ob.pos[1] - o[1]),
            bbox: [bb[0].max(0.0), bb[1].max(0.0), bb[2].min(w), bb[3].min(h)],
            clipped,
        })
    }

    /// Image boxes of every drawn object in view from `pose`.
    pub fn object_boxes(&self, pose: &Pose) -> Vec<ObjectBox> {
        self.scene
            .track
            .enabled_objects()
            .filter_map(|ob| self.object_box(pose, ob))
            .collect()
    }
}

/// Fills `out[0..w]` with `f` sampled every `step` columns (and one past the end) and
/// linearly interpolated between.
fn lerp_fill(out: &mut Vec<f32>, w: usize, step: usize, f: impl Fn(usize) -> f32) {
    out.clear();
    out.resize(w + step, 0.0);
    let inv = 1.0 / step as f32;
    let mut a = f(0);
    for k in 0..w.div_ceil(step) {
        let b = f((k + 1) * step);
        let d = (b - a) * inv;
        for (j, o) in out[k * step..(k + 1) * step].iter_mut().enumerate() {
            *o = a + d * j as f32;
        }
        a = b;
    }
}

/// Separable Gaussian blur in place (kernel radius 3σ, edges clamped).
fn gaussian_blur(img: &mut RgbImage, sigma: f64) {
    let r = (3.0 * sigma).ceil().max(1.0) as i64;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = k.iter().sum();
    let k: Vec<f32> = k.iter().map(|v| v / sum).collect();
    let (w, h) = (img.width() as i64, img.height() as i64);
    let src: Vec<f32> = img.as_raw().iter().map(|&v| v as f32).collect();
    let mut tmp = vec![0f32; src.len()];
    for y in 0..h {
        for x in 0..w {
            for ch in 0..3 {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    let xx = (x + j as i64 - r).clamp(0, w - 1);
                    acc += kv * src[((y * w + xx) * 3 + ch) as usize];
                }
                tmp[((y * w + x) * 3 + ch) as usize] = acc;
            }
        }
    }
    let out: &mut [u8] = img.as_mut();
    for y in 0..h {
        for x in 0..w {
            for ch in 0..3 {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    let yy = (y + j as i64 - r).clamp(0, h - 1);
                    acc += kv * tmp[((yy * w + x) * 3 + ch) as usize];
                }
                out[((y * w + x) * 3 + ch) as usize] = (acc + 0.5).clamp(0.0, 255.0) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{CameraConfig, VehicleConfig};
    use crate::sim::track::Track;
    use std::path::Path;

    fn setup() -> (Renderer, Track) {
        let track = Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).unwrap();
        let scene = Arc::new(Scene::new(&track));
        let mount = CameraMount {
            camera: PinholeCamera::from(&CameraConfig::default()),
            x_m: VehicleConfig::default().camera_x_m,
        };
        (Renderer::new(scene, mount, RenderOptions::clean()), track)
    }

    #[test]
    fn world_ray_matches_the_camera_model() {
        let (r, _) = setup();
        let yaw = 0.7f64;
        let cam = r.mount().camera;
        for (u, v) in [(0.0, 0.0), (100.0, 200.0), (319.0, 17.5)] {
            let a = cam.ray(u, v);
            let (s, c) = yaw.sin_cos();
            let want = [c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]];
            let got = r.world_ray((s, c), u, v);
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 1e-12, "{got:?} {want:?}");
            }
        }
    }

    /// The lane lines appear where the camera model puts them: a car centred in its lane on
    /// the first straight sees bright line pixels at the projected line centres.
    #[test]
    fn lines_land_where_the_camera_projects_them() {
        let (mut r, track) = setup();
        let (p, yaw) = track.lane_pose_at(0.5);
        let pose = Pose { x: p[0], y: p[1], yaw };
        let img = r.render_new(&pose, 0.0, 0);
        let cam = r.mount().camera;
        // The solid right-hand line (the left one of this lane is dashed).
        for (x, y) in [(0.5, -0.15), (0.9, -0.15), (0.45, -0.149)] {
            let (u, v) = cam.project([x, y, 0.0]).unwrap();
            let px = img.get_pixel(u.round() as u32, v.round() as u32);
            assert!(px[0] > 180, "line at y={y} -> ({u:.1},{v:.1}) is {px:?}");
            let (u, v) = cam.project([x, y + 0.05, 0.0]).unwrap();
            let px = img.get_pixel(u.round() as u32, v.round() as u32);
            assert!(px[0] < 160, "floor beside the line is {px:?}");
        }
    }

    /// `RCCAR_SIM_SNAPSHOT=dir cargo test snapshot` writes a few views to look at.
    #[test]
    fn snapshot() {
        let Ok(dir) = std::env::var("RCCAR_SIM_SNAPSHOT") else {
            return;
        };
        let (mut r, track) = setup();
        for s in [0.5, 1.5, 3.3, 5.6, 7.0, 12.5, 14.0] {
            let (p, yaw) = track.lane_pose_at(s);
            let pose = Pose { x: p[0], y: p[1], yaw };
            // Put the lens (not the rear axle) at the lane point.
            let pose = Pose {
                x: pose.x - 0.24 * yaw.cos(),
                y: pose.y - 0.24 * yaw.sin(),
                ..pose
            };
            r.render_new(&pose, s, 0)
                .save(format!("{dir}/view_{s:05.1}.png"))
                .unwrap();
        }
        let near_sign = Pose {
            x: 0.85,
            y: -0.15,
            yaw: 0.0,
        };
        r.render_new(&near_sign, 0.0, 0)
            .save(format!("{dir}/sign.png"))
            .unwrap();
        let near_light = Pose {
            x: -1.35,
            y: 3.75,
            yaw: -std::f64::consts::FRAC_PI_2,
        };
        r.render_new(&near_light, 6.0, 0)
            .save(format!("{dir}/light.png"))
            .unwrap();
    }

    /// The ground-truth image box of the stop sign holds every pixel the sign changes, and
    /// not much more.
    #[test]
    fn object_box_is_tight_around_the_drawn_sign() {
        let (mut r, track) = setup();
        let pose = Pose {
            x: 3.2,
            y: -0.15,
            yaw: 0.0,
        };
        let with = r.render_new(&pose, 0.0, 0);
        let mut bare_track = track.clone();
        for o in &mut bare_track.objects {
            if o.0.kind == ObjectClass::StopSign {
                o.1 = false;
            }
        }
        let mut bare = Renderer::new(Arc::new(Scene::new(&bare_track)), *r.mount(), RenderOptions::clean());
        let without = bare.render_new(&pose, 0.0, 0);
        let boxes = r.object_boxes(&pose);
        let sign = boxes
            .iter()
            .find(|b| b.kind == ObjectClass::StopSign)
            .expect("sign in view");
        let mut diff = [u32::MAX, u32::MAX, 0, 0];
        for (x, y, p) in with.enumerate_pixels() {
            if p != without.get_pixel(x, y) {
                diff = [diff[0].min(x), diff[1].min(y), diff[2].max(x), diff[3].max(y)];
            }
        }
        let b = sign.bbox;
        assert!(
            diff[0] as f64 >= b[0] - 1.0
                && diff[1] as f64 >= b[1] - 1.0
                && diff[2] as f64 <= b[2] + 1.0
                && diff[3] as f64 <= b[3] + 1.0,
            "drawn {diff:?} outside box {b:?}"
        );
        let area = |w: f64, h: f64| w * h;
        let drawn = area((diff[2] - diff[0] + 1) as f64, (diff[3] - diff[1] + 1) as f64);
        let boxed = area(b[2] - b[0] + 1.0, b[3] - b[1] + 1.0);
        assert!(boxed < 1.5 * drawn, "box {b:?} much larger than drawn {diff:?}");
    }

    #[test]
    fn same_seed_same_frame() {
        let (_, track) = setup();
        let scene = Arc::new(Scene::new(&track));
        let mount = CameraMount {
            camera: PinholeCamera::from(&CameraConfig::default()),
            x_m: 0.24,
        };
        let opts = RenderOptions {
            noise_sigma: 4.0,
            ..RenderOptions::clean()
        };
        let mut a = Renderer::new(scene.clone(), mount, opts.clone());
        let mut b = Renderer::new(scene, mount, opts);
        let pose = Pose {
            x: 1.0,
            y: -0.15,
            yaw: 0.0,
        };
        assert_eq!(a.render_new(&pose, 1.0, 7), b.render_new(&pose, 1.0, 7));
        assert_ne!(a.render_new(&pose, 1.0, 7), a.render_new(&pose, 1.0, 8));
    }
}
