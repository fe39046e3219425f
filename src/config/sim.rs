//! `[sim]`: the closed-loop simulator (`rccar sim`): the track file, how long a run lasts (laps,
//! seconds), the physics step, the seed, and the camera's imperfections (noise in grey levels,
//! blur in pixels, exposure, lighting; a stereo pair's second camera in degrees).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[sim]`: the closed-loop simulator (`rccar sim`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Track file; a relative path is relative to the folder of the config file that names it
    /// (the default, `tracks/default.toml`, to the base config's folder).
    pub track: String,
    /// Laps to drive before the run ends; 0 = no lap target, drive until `max_seconds`.
    pub laps: u32,
    /// The run ends after this much simulated time even if the laps are not done, seconds.
    pub max_seconds: f64,
    /// Vehicle-model steps per camera frame (the physics step is 1 / (fps × substeps)).
    pub substeps: u32,
    /// Seed of every random choice (camera noise); the same seed gives the same run.
    pub seed: i64,
    /// Standard deviation of the camera's pixel noise, grey levels (0 = none).
    pub noise_sigma: f64,
    /// Gaussian blur of the rendered frame, sigma in pixels (0 = sharp).
    pub blur_px: f64,
    /// Exposure gain on the rendered frame (1 = as lit).
    pub exposure: f64,
    /// Peak relative change of the scene's brightness over time (0 = steady lighting).
    pub light_variation: f64,
    /// Period of the brightness change, seconds.
    pub light_period_s: f64,
    /// How a stereo pair's second camera is turned from ideal: yaw, pitch, roll, degrees
    /// (`ranging.method = "stereo"`; src/sim/lens.rs `LensWarp`).
    pub stereo_error_deg: [f64; 3],
    /// Radial distortion k₁ of the stereo pair's second camera (0 = none).
    pub stereo_error_k1: f64,
    /// The car's own camera seen through a lens with this distortion, OpenCV's order [k1, k2,
    /// p1, p2, k3] on `[camera]`'s pinhole (src/sim/lens.rs `LensWarp`); all zero = an ideal
    /// lens. The truth stays the ideal camera's.
    pub lens_distortion: [f64; 5],
    /// Changing light along the route (src/sim/light.rs, docs/light.md): 0 = none, 1..3 =
    /// preset shadows, bright patches, dusk and low-light noise, strongest at 3.
    pub light_level: u32,
    /// Darkening in a shadow's core, fraction 0..0.9; −1 = the level's.
    pub light_shadows: f64,
    /// Extra light in a bright patch's core, fraction 0..3; −1 = the level's.
    pub light_glare: f64,
    /// Dusk: global dimming (and a warmer colour), fraction 0..0.9; −1 = the level's.
    pub light_dusk: f64,
    /// Extra sensor noise, grey levels 0..32; −1 = the level's.
    pub light_noise: f64,
    /// Noise added to the steering command the simulated car obeys (not to the command the
    /// controller wrote in telemetry), standard deviation in steer units 0..1 (0 = none, the
    /// default). A smooth random drift (time constant [`crate::sim::world::STEER_NOISE_TAU_S`]):
    /// the car wanders off the lane centre and the controller brings it back, the recoveries
    /// a learned pilot must see in its training data (docs/pilot.md).
    pub steer_noise: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            track: "tracks/default.toml".into(),
            laps: 3,
            max_seconds: 600.0,
            substeps: 4,
            seed: 1,
            noise_sigma: 2.0,
            blur_px: 0.0,
            exposure: 1.0,
            light_variation: 0.0,
            light_period_s: 10.0,
            stereo_error_deg: [0.0; 3],
            stereo_error_k1: 0.0,
            lens_distortion: [0.0; 5],
            light_level: 0,
            light_shadows: -1.0,
            light_glare: -1.0,
            light_dusk: -1.0,
            light_noise: -1.0,
            steer_noise: 0.0,
        }
    }
}

impl SimConfig {
    /// Range checks of `[sim]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let m = self;
        if m.track.trim().is_empty() {
            c.fail("sim.track", format!("{:?}", m.track), "a path to a track file");
        }
        c.range("sim.laps", m.laps, 0, 1000);
        c.range("sim.max_seconds", m.max_seconds, 0.1, 36000.0);
        c.range("sim.substeps", m.substeps, 1, 100);
        c.range("sim.seed", m.seed, 0, i64::MAX);
        c.range("sim.noise_sigma", m.noise_sigma, 0.0, 64.0);
        c.range("sim.blur_px", m.blur_px, 0.0, 3.0);
        c.range("sim.steer_noise", m.steer_noise, 0.0, 1.0);
        c.range("sim.exposure", m.exposure, 0.1, 4.0);
        c.range("sim.light_variation", m.light_variation, 0.0, 0.9);
        c.range("sim.light_period_s", m.light_period_s, 0.1, 3600.0);
        for (i, v) in m.stereo_error_deg.iter().enumerate() {
            c.range(&format!("sim.stereo_error_deg[{i}]"), *v, -5.0, 5.0);
        }
        c.range("sim.stereo_error_k1", m.stereo_error_k1, -0.5, 0.5);
        for (i, (v, bound)) in m.lens_distortion.iter().zip([1.0, 1.0, 0.1, 0.1, 1.0]).enumerate() {
            c.range(&format!("sim.lens_distortion[{i}]"), *v, -bound, bound);
            // (the same bounds gate the fold check in `check_sim_lens`)
        }
        c.range("sim.light_level", m.light_level, 0, 3);
        for (key, v, hi) in [
            ("sim.light_shadows", m.light_shadows, 0.9),
            ("sim.light_glare", m.light_glare, 3.0),
            ("sim.light_dusk", m.light_dusk, 0.9),
            ("sim.light_noise", m.light_noise, 32.0),
        ] {
            if v != -1.0 && !(0.0..=hi).contains(&v) {
                c.fail(key, v.to_string(), &format!("-1 (the level's) or 0 ..= {hi}"));
            }
        }
    }

    /// The light variation of `light_level` and the `light_*` overrides.
    pub fn light(&self) -> crate::sim::light::LightOptions {
        let o = [self.light_shadows, self.light_glare, self.light_dusk, self.light_noise];
        crate::sim::light::LightOptions::from_level(self.light_level, o, self.seed as u64)
    }
}

impl super::Config {
    /// `sim.lens_distortion` against `[camera]`: the simulated lens must bend every pixel of
    /// the image from one ray (the model may not fold back before the image's corners).
    pub(super) fn check_sim_lens(&self, c: &mut Checker) {
        let d = crate::lens::Distortion(self.sim.lens_distortion);
        let in_range = d.0.iter().zip([1.0, 1.0, 0.1, 0.1, 1.0]).all(|(v, b)| v.abs() <= b);
        if d.is_zero() || !in_range {
            return;
        }
        let cam = crate::camera::PinholeCamera::from(&self.camera);
        let corner = (cam.u0.hypot(cam.v0) / cam.f_px).max(1e-6);
        // Walk out along the radius until the bent radius reaches the corner's.
        let mut r: f64 = 0.0;
        let radial = |r: f64| r * (1.0 + r * r * (d.0[0] + r * r * (d.0[1] + r * r * d.0[4])));
        while radial(r) < corner {
            if d.radial_slope(r * r) <= 0.0 || r > 10.0 * corner {
                c.fail(
                    "sim.lens_distortion",
                    format!("{:?}", self.sim.lens_distortion),
                    &format!(
                        "a lens that bends every pixel from one ray: this model folds back (1 + 3k1 r² + 5k2 r⁴ + 7k3 r⁶ ≤ 0) at r = {r:.3} before the image corners (r_d = {corner:.3}); make k1 less negative or k2 larger"
                    ),
                );
                return;
            }
            r += corner / 256.0;
        }
    }
}
