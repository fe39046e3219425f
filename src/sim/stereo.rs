//! A stereo camera in the simulator (issue 12): two [`Renderer`]s on the same scene, the
//! configured camera mounted `base` metres apart across the car (left lens at +base/2, right
//! at −base/2, both at the configured height, tilt and `vehicle.camera_x_m`), so the pair is
//! ideal and already rectified (same intrinsics, parallel axes, base along the image rows).
//! Ground truth: each object's image box in the reference camera and its forward distance
//! from the lenses' line. Units: metres, pixels.

use super::render::{CameraMount, ObjectBox, RenderOptions, Renderer};
use super::scene::Scene;
use super::track::ObjectKind;
use super::vehicle::Pose;
use crate::camera::PinholeCamera;
use crate::config::Config;
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
            let mut cam = PinholeCamera::from_config(&cfg.camera);
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
                let near = if ob.kind == ObjectKind::Obstacle {
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
