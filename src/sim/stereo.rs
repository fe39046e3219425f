//! A stereo camera in the simulator (issue 12): two [`Renderer`]s on the same scene, the
//! configured camera mounted `base` metres apart across the car (left lens at +base/2, right
//! at −base/2, both at the configured height, tilt and `vehicle.camera_x_m`), so the pair is
//! ideal and already rectified (same intrinsics, parallel axes, base along the image rows).
//! Ground truth: each object's image box in the reference camera and its forward distance
//! from the lenses' line. Units: metres, pixels.

use super::render::{CameraMount, ObjectBox, RenderOptions, Renderer};
use super::scene::Scene;
use super::vehicle::Pose;
use crate::camera::PinholeCamera;
use crate::classes::SimShape;
use crate::config::Config;
pub use super::lens::LensWarp;
use image::RgbImage;
use std::sync::Arc;

/// Two cameras on the simulated car.
#[derive(Debug, Clone)]
pub struct StereoRig {
    /// The left camera.
    pub left: Renderer,
    /// The right camera.
    pub right: Renderer,
    /// Distance between the lenses, metres.
    pub base_m: f64,
}

/// One object as the reference camera sees it, with its true forward distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoTruth {
    /// Its box in the reference image.
    pub bbox: ObjectBox,
    /// Forward distance (along the car's heading) from the lenses to the object's face that
    /// a camera sees (an obstacle's near side, a sign's face), metres.
    pub forward_m: f64,
    /// Lateral offset from the reference lens, left positive, metres.
    pub lateral_m: f64,
}

impl StereoRig {
    /// A rig of `cfg`'s camera with base `base_m` on `scene`, with `opts` camera effects;
    /// each camera's noise is seeded differently.
    pub fn new(cfg: &Config, scene: Arc<Scene>, base_m: f64, opts: RenderOptions) -> StereoRig {
        let mount = |lat: f64| {
            let mut cam = PinholeCamera::from(&cfg.camera);
            cam.lateral_m = lat;
            CameraMount {
                camera: cam,
                x_m: cfg.vehicle.camera_x_m,
            }
        };
        let mut ropts = opts.clone();
        ropts.seed = opts.seed.wrapping_add(0x5EED);
        StereoRig {
            left: Renderer::new(scene.clone(), mount(base_m / 2.0), opts),
            right: Renderer::new(scene, mount(-base_m / 2.0), ropts),
            base_m,
        }
    }

    /// Renders both views from the car at `pose` (time `t_s`, frame number `frame`).
    pub fn render(&mut self, pose: &Pose, t_s: f64, frame: u64) -> (RgbImage, RgbImage) {
        (
            self.left.render_new(pose, t_s, frame),
            self.right.render_new(pose, t_s, frame),
        )
    }

    /// Truth for every object in view of the reference camera (`left` or not).
    pub fn truth(&self, pose: &Pose, reference_left: bool) -> Vec<StereoTruth> {
        let r = if reference_left { &self.left } else { &self.right };
        let o = r.mount().origin(pose);
        let (s, c) = pose.yaw.sin_cos();
        r.object_boxes(pose)
            .into_iter()
            .filter_map(|b| {
                let ob = r
                    .scene()
                    .track
                    .objects
                    .iter()
                    .map(|o| &o.0)
                    .find(|o| o.index == b.index)?;
                // a box standing on the floor is ranged to its near face, a post to its pole
                let near = if ob.kind.info().shape == SimShape::Box {
                    ob.size[0] / 2.0
                } else {
                    0.0
                };
                let (dx, dy) = (ob.pos[0] - o[0], ob.pos[1] - o[1]);
                Some(StereoTruth {
                    bbox: b,
                    forward_m: c * dx + s * dy - near,
                    lateral_m: -s * dx + c * dy,
                })
            })
            .collect()
    }
}

/// The image box [left, top, right, bottom] (pixels, pixel centres at integers) of a stop
/// sign's octagonal face (white rim included) as `r` sees it from `pose`, and whether it is
/// cut by the image border; `None` for other objects, a corner behind the camera or a face
/// wholly outside the image. [`Renderer::object_box`] boxes the whole object, pole and all;
/// a detector boxes the face.
pub fn sign_face_box(r: &Renderer, pose: &Pose, ob: &super::track::Object) -> Option<([f64; 4], bool)> {
    if ob.kind.info().shape != SimShape::Octagon {
        return None;
    }
    let half = ob.size[0] / 2.0;
    let (s, c) = ob.yaw.sin_cos();
    // The face panel stands 7 mm in front of the pole (src/sim/scene.rs).
    let (x, y) = (ob.pos[0] + 0.007 * c, ob.pos[1] + 0.007 * s);
    let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for (ly, z) in [(-half, -half), (half, -half), (-half, half), (half, half)] {
        let p = [x - s * ly, y + c * ly, ob.height + z];
        let (u, v) = r.mount().project_world(pose, p)?;
        bb = [bb[0].min(u), bb[1].min(v), bb[2].max(u), bb[3].max(v)];
    }
    let cam = &r.mount().camera;
    let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
    if bb[2] < 0.0 || bb[3] < 0.0 || bb[0] > w || bb[1] > h {
        return None;
    }
    // Pixel edges are at ±0.5 around the centres.
    let clipped = bb[0] < -0.5 || bb[1] < -0.5 || bb[2] > w + 0.5 || bb[3] > h + 0.5;
    Some((bb, clipped))
}

/// The drive loop's second camera in the simulator (`rccar sim` with `ranging.method =
/// "stereo"`, src/drive/stereo.rs): the car's own camera of `[camera]` is the reference (on
/// the centre line, where the lane keeping and the truth model expect it) and this one is
/// mounted `stereo.base_m` beside it, to its right when `stereo.reference = "left"` (to its
/// left otherwise), with the reference's height, tilt and `vehicle.camera_x_m`; its noise is
/// seeded apart from the reference's. The pair is ideal and rectified unless
/// `sim.stereo_error_deg` / `sim.stereo_error_k1` turn and bend this camera ([`LensWarp`]),
/// as two real webcams are.
pub fn other_camera(cfg: &Config, scene: Arc<Scene>, opts: RenderOptions) -> OtherCamera {
    let mut cam = PinholeCamera::from(&cfg.camera);
    let base = cfg.stereo.base_m;
    cam.lateral_m = if cfg.stereo.reference.is_left() { -base } else { base };
    let mut o = opts;
    o.seed = o.seed.wrapping_add(0x5EED);
    let lens = LensWarp::from_config(cfg).map(|l| (l, RgbImage::new(0, 0)));
    OtherCamera {
        renderer: Renderer::new(
            scene,
            CameraMount {
                camera: cam,
                x_m: cfg.vehicle.camera_x_m,
            },
            o,
        ),
        lens,
    }
}

/// A stereo pair's second camera: the renderer of an ideal camera, and the error of the real
/// one ([`LensWarp`]) applied to its image, if any.
#[derive(Debug, Clone)]
pub struct OtherCamera {
    /// The ideal camera's renderer.
    pub renderer: Renderer,
    /// The camera's error and the ideal image it is applied to.
    lens: Option<(LensWarp, RgbImage)>,
}

/// Renders the rows `spans` (sorted, disjoint) of `r`'s view from `pose` into `img`, each
/// widened by the blur's reach (`3·blur_px`; with blur, one range from the first span to the
/// last), as `World::render_spans` does for the reference camera; through the camera's error
/// ([`LensWarp`]) when it has one (the ideal rows those rows read are rendered, then bent).
pub fn render_spans(
    r: &mut OtherCamera,
    pose: &Pose,
    t_s: f64,
    frame: u64,
    img: &mut RgbImage,
    spans: &[std::ops::Range<usize>],
    blur_px: f64,
) {
    super::lens::render_through(&mut r.renderer, r.lens.as_mut(), pose, t_s, frame, img, spans, blur_px);
}
