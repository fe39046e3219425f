//! The simulated camera: renders what a pinhole camera on the car sees of a [`Scene`].
//!
//! 1. Once per camera: for every pixel, the floor point its centre ray meets (in the car's
//!    frame) and the Jacobian of that point with respect to the pixel coordinates, i.e. the
//!    pixel's footprint on the floor. The camera is fixed to the car, so a frame only has to
//!    move these points into the world (one rotation and translation each).
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

use super::rng::mix;
use super::scene::{Footprint, Prim, Scene};
use super::track::{Object, ObjectKind};
use super::vehicle::Pose;
use crate::camera::PinholeCamera;
use crate::config::SimConfig;
use image::RgbImage;
use std::sync::Arc;

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
        }
    }
}

/// Per-pixel geometry of one camera, in the camera model's car frame.
#[derive(Debug, Clone, Copy, Default)]
struct PixelGeom {
    /// Floor point (x forward, y left); NaN when the ray does not come down.
    g: [f32; 2],
    /// d(floor point)/du and d/dv.
    ju: [f32; 2],
    jv: [f32; 2],
    /// Vignetting gain.
    vig: f32,
    /// |ju| + |jv| (rotation does not change it), metres.
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
    pub kind: ObjectKind,
    /// Horizontal distance from the lens to the object's base, metres.
    pub distance_m: f64,
    /// Image box [left, top, right, bottom], pixels, clipped to the image.
    pub bbox: [f64; 4],
    /// Whether the box was cut by the image border.
    pub clipped: bool,
}

/// Renders a scene through one camera.
#[derive(Debug, Clone)]
pub struct Renderer {
    scene: Arc<Scene>,
    mount: CameraMount,
    opts: RenderOptions,
    geom: Vec<PixelGeom>,
    prims: Vec<Prim>,
}

impl Renderer {
    /// Precomputes the per-pixel tables for `mount` (a few ms).
    pub fn new(scene: Arc<Scene>, mount: CameraMount, opts: RenderOptions) -> Renderer {
        let cam = mount.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut geom = vec![PixelGeom::default(); w * h];
        for v in 0..h {
            for u in 0..w {
                let (uf, vf) = (u as f64, v as f64);
                let g = cam.ground_of_pixel(uf, vf);
                let gu0 = cam.ground_of_pixel(uf - 0.5, vf);
                let gu1 = cam.ground_of_pixel(uf + 0.5, vf);
                let gv0 = cam.ground_of_pixel(uf, vf - 0.5);
                let gv1 = cam.ground_of_pixel(uf, vf + 0.5);
                let px = &mut geom[v * w + u];
                // cos⁴ of the angle off axis, gently (a real lens, not a pinhole).
                let r2 = ((uf - cam.u0).powi(2) + (vf - cam.v0).powi(2)) / (cam.f_px * cam.f_px);
                let cos2 = 1.0 / (1.0 + r2);
                px.vig = (1.0 - 0.25 * (1.0 - cos2 * cos2)) as f32;
                match (g, gu0, gu1, gv0, gv1) {
                    (Some(g), Some(a), Some(b), Some(c), Some(d)) => {
                        px.g = [g.0 as f32, g.1 as f32];
                        // Clamp footprints near the horizon: they only decide filtering.
                        let cl = |x: f64| x.clamp(-2.0, 2.0) as f32;
                        px.ju = [cl(b.0 - a.0), cl(b.1 - a.1)];
                        px.jv = [cl(d.0 - c.0), cl(d.1 - c.1)];
                        let size = (px.ju[0].hypot(px.ju[1]) + px.jv[0].hypot(px.jv[1])) as f64;
                        px.size = size as f32;
                        px.fade = Footprint::fade_for(size);
                    }
                    _ => px.g = [f32::NAN, f32::NAN],
                }
            }
        }
        Renderer {
            scene,
            mount,
            opts,
            geom,
            prims: Vec::new(),
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
        let cam = self.mount.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        if img.dimensions() != (cam.width, cam.height) {
            *img = RgbImage::new(cam.width, cam.height);
        }
        let scene = &*self.scene;
        let o = self.mount.origin(pose);
        let (sy, cy) = pose.yaw.sin_cos();
        let lens = pose.to_world([self.mount.x_m, 0.0]);
        let rot = |v: [f32; 2]| -> [f64; 2] {
            let (x, y) = (v[0] as f64, v[1] as f64);
            [cy * x - sy * y, sy * x + cy * y]
        };
        // 1. Global gain: exposure and the slow lighting change.
        let gain = (self.opts.exposure
            * (1.0
                + self.opts.light_variation * (std::f64::consts::TAU * t_s / self.opts.light_period_s.max(1e-3)).sin()))
            as f32;
        let buf: &mut [u8] = img.as_mut();
        // 2. Floor, walls, ceiling.
        for v in 0..h {
            for u in 0..w {
                let px = &self.geom[v * w + u];
                let c = if px.g[0].is_nan() {
                    scene.wall_color(o, self.world_ray(pose, u as f64, v as f64))
                } else {
                    let gw = rot(px.g);
                    let p = [lens[0] + gw[0], lens[1] + gw[1]];
                    if scene.on_floor(p) {
                        let fp = Footprint {
                            ju: rot(px.ju),
                            jv: rot(px.jv),
                            size: px.size,
                            fade: px.fade,
                        };
                        scene.floor_color(p, &fp)
                    } else {
                        scene.wall_color(o, self.world_ray(pose, u as f64, v as f64))
                    }
                };
                let k = gain * px.vig;
                let i = 3 * (v * w + u);
                buf[i] = (c[0] * k).clamp(0.0, 255.0) as u8;
                buf[i + 1] = (c[1] * k).clamp(0.0, 255.0) as u8;
                buf[i + 2] = (c[2] * k).clamp(0.0, 255.0) as u8;
            }
        }
        // 3. Objects, far ones first.
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
            for v in v0..=v1 {
                for u in u0..=u1 {
                    let mut sum = [0f32; 3];
                    let mut hits = 0;
                    for (du, dv) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                        let d = self.world_ray(pose, u as f64 + du, v as f64 + dv);
                        let t_floor = if d[2] < 0.0 { o[2] / -d[2] } else { f64::INFINITY };
                        if let Some(hit) = scene.intersect(&self.prims, o, d, t_floor) {
                            for ch in 0..3 {
                                sum[ch] += hit.rgb[ch];
                            }
                            hits += 1;
                        }
                    }
                    if hits == 0 {
                        continue;
                    }
                    let k = gain * self.geom[v * w + u].vig;
                    let i = 3 * (v * w + u);
                    for ch in 0..3 {
                        let bg = buf[i + ch] as f32;
                        let c = (sum[ch] * k + bg * (4 - hits) as f32) / 4.0;
                        buf[i + ch] = c.clamp(0.0, 255.0) as u8;
                    }
                }
            }
        }
        // 4. Blur and noise.
        if self.opts.blur_px > 0.0 {
            gaussian_blur(img, self.opts.blur_px);
        }
        if self.opts.noise_sigma > 0.0 {
            // Triangular noise from two bytes per channel: variance 1/6 of its half-width².
            let a = (self.opts.noise_sigma * 6f64.sqrt()) as f32 / 255.0;
            let seed = mix(self.opts.seed ^ frame.wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let buf: &mut [u8] = img.as_mut();
            for (p, px) in buf.chunks_exact_mut(3).enumerate() {
                let r = mix(seed.wrapping_add(p as u64));
                for (ch, val) in px.iter_mut().enumerate() {
                    let b1 = ((r >> (16 * ch)) & 0xFF) as f32;
                    let b2 = ((r >> (16 * ch + 8)) & 0xFF) as f32;
                    let n = (b1 + b2 - 255.0) * a;
                    *val = (*val as f32 + n + 0.5).clamp(0.0, 255.0) as u8;
                }
            }
        }
    }

    /// A fresh image of the camera's size with the view from `pose` at `t_s`.
    pub fn render_new(&mut self, pose: &Pose, t_s: f64, frame: u64) -> RgbImage {
        let mut img = RgbImage::new(self.mount.camera.width, self.mount.camera.height);
        self.render(pose, t_s, frame, &mut img);
        img
    }

    /// The unit ray through pixel (u, v), world frame.
    fn world_ray(&self, pose: &Pose, u: f64, v: f64) -> [f64; 3] {
        let r = self.mount.camera.ray(u, v);
        let (s, c) = pose.yaw.sin_cos();
        let d = [c * r[0] - s * r[1], s * r[0] + c * r[1], r[2]];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        [d[0] / n, d[1] / n, d[2] / n]
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
            camera: PinholeCamera::from_config(&CameraConfig::default()),
            x_m: VehicleConfig::default().camera_x_m,
        };
        (Renderer::new(scene, mount, RenderOptions::clean()), track)
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
            assert!(px[0] > 200, "line at y={y} -> ({u:.1},{v:.1}) is {px:?}");
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

    #[test]
    fn same_seed_same_frame() {
        let (_, track) = setup();
        let scene = Arc::new(Scene::new(&track));
        let mount = CameraMount {
            camera: PinholeCamera::from_config(&CameraConfig::default()),
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
