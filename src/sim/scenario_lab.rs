//! A ranging calibration lab in the simulator: a flat marker on the floor of a straight road
//! at several distances ahead of the car, its image row read off the rendered ground-truth box
//! (snapped to the pixel grid, as a student reads it off a photo) and its distance "taped"
//! with a chosen error. The pairs feed `rccar calibrate ranging` (docs/ranging.md).
//!
//! The simulated camera is the one `cfg` describes (its tilt is the "true" one); calibrating
//! against another configuration's nominal tilt shows how well the fit recovers it.
//!
//! Units: metres, pixels.

use super::rng::SplitMix64;
use super::run::{SimError, Simulation};
use super::track::Track;
use crate::config::Config;
use crate::ranging::Pair;
use crate::timing::NoTimer;

/// Marker size on the floor: length along the road, width, height, metres.
const MARKER: [f64; 3] = [0.04, 0.10, 0.01];

/// A straight road with one marker on the driven lane's centre, 3 m from the start.
fn lab_track() -> Track {
    let text = format!(
        r#"
name = "ranging lab"
[start]
x = 0.0
y = 0.0
heading_deg = 0.0
[road]
lanes = 2
lane_width_m = 0.30
[[segments]]
type = "straight"
length_m = 6.0
[[segments]]
type = "arc"
radius_m = 3.0
angle_deg = 180
[[segments]]
type = "straight"
length_m = 6.0
[[segments]]
type = "arc"
radius_m = 3.0
angle_deg = 180
[[objects]]
type = "obstacle"
x = 3.0
y = -0.15
size_m = [{}, {}, {}]
color = [240, 240, 240]
"#,
        MARKER[0], MARKER[1], MARKER[2]
    );
    Track::from_toml_str(&text, "ranging lab").expect("the built-in lab track is valid")
}

/// `n` pairs (box-bottom row, taped distance to the marker's near edge, height 0) with the
/// marker between 0.25 and 1.5 m from the lens; tape error Gaussian with `tape_sigma_m`.
pub fn calibration_pairs(cfg: &Config, n: usize, tape_sigma_m: f64, seed: u64) -> Result<Vec<Pair>, SimError> {
    let track = lab_track();
    let marker = track
        .enabled_objects()
        .next()
        .expect("the lab track has its marker")
        .clone();
    let mut rng = SplitMix64::new(seed);
    let mut gauss = move || {
        // Box–Muller.
        let (u1, u2) = (rng.next_f64().max(1e-12), rng.next_f64());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let lens_ahead = cfg.vehicle.camera_x_m - cfg.vehicle.wheelbase_m / 2.0;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        // 1. Place the car so the marker's near edge is about d ahead of the lens.
        let d = 0.25 + 1.25 * k as f64 / (n.max(2) - 1) as f64;
        let mut sim = Simulation::new(cfg, &track)?;
        sim.set_full_frames(false);
        sim.place_at(marker.pos[0] - MARKER[0] / 2.0 - d - lens_ahead);
        let step = sim.step(&mut NoTimer);
        // 2. The marker's box bottom, snapped to a pixel edge.
        let Some(b) = step.truth.objects.first() else {
            continue;
        };
        let v = (b.bbox[3] + 0.5).round() - 0.5;
        // 3. The true forward distance, taped.
        let [x, y, yaw] = step.truth.pose;
        let (s, c) = yaw.sin_cos();
        let lens = [x + c * cfg.vehicle.camera_x_m, y + s * cfg.vehicle.camera_x_m];
        let fwd = c * (marker.pos[0] - lens[0]) + s * (marker.pos[1] - lens[1]) - MARKER[0] / 2.0;
        out.push(Pair {
            v,
            d: fwd + tape_sigma_m * gauss(),
            z: 0.0,
        });
    }
    Ok(out)
}
