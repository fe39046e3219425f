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
    /// (`ranging.method = "stereo"`; src/sim/stereo.rs `LensWarp`).
    pub stereo_error_deg: [f64; 3],
    /// Radial distortion k₁ of the stereo pair's second camera (0 = none).
    pub stereo_error_k1: f64,
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
        c.range("sim.exposure", m.exposure, 0.1, 4.0);
        c.range("sim.light_variation", m.light_variation, 0.0, 0.9);
        c.range("sim.light_period_s", m.light_period_s, 0.1, 3600.0);
        for (i, v) in m.stereo_error_deg.iter().enumerate() {
            c.range(&format!("sim.stereo_error_deg[{i}]"), *v, -5.0, 5.0);
        }
        c.range("sim.stereo_error_k1", m.stereo_error_k1, -0.5, 0.5);
    }
}
