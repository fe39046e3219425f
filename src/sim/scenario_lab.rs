//! A ranging calibration lab in the simulator: a flat marker on the floor of a straight road
//! at several distances ahead of the car, its image row read off the rendered ground-truth box
//! (snapped to the pixel grid, as a student reads it off a photo) and its distance "taped"
//! with a chosen error. The pairs feed `rccar calibrate ranging` (docs/ranging.md;
//! [`lab_pairs`] checks its `--from-sim` options and sets the camera's true tilt).
//!
//! The simulated camera is the one `cfg` describes (its tilt is the "true" one); calibrating
//! against another configuration's nominal tilt shows how well the fit recovers it.
//!
//! Units: metres, pixels.

use super::rng::SplitMix64;
use super::run::{SimError, Simulation};
use super::track::Track;
use crate::classes::SimShape;
use crate::config::Config;
use crate::ranging::Pair;

/// The loop both lab roads share: a 6 m straight, a half circle of 3 m radius, the straight
/// back and the half circle home (TOML `[[segments]]`).
const SEGMENTS: &str = r#"[[segments]]
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
"#;

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
{SEGMENTS}[[objects]]
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

/// How `rccar calibrate ranging --from-sim N` sets up the lab.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabOptions {
    /// The simulated camera's true tilt minus the configured one, degrees (-30..=30).
    pub tilt_error_deg: f64,
    /// Standard deviation of the taped distances, metres (0..=0.5).
    pub tape_sigma_m: f64,
    /// Seed of the tape errors.
    pub seed: u64,
}

/// Lab options or a pair count out of bounds (the message names the flag and the bound).
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// Fewer than 3 or more than `max` pairs.
    #[error("--from-sim {n}: must be 3..={max} pairs")]
    Count {
        /// Pairs asked for.
        n: usize,
        /// The most allowed.
        max: usize,
    },
    /// The tilt error is not within ±30 degrees.
    #[error("--sim-tilt-error-deg {0}: must be -30..=30 degrees")]
    TiltError(f64),
    /// The tape sigma is not within 0..=0.5 m.
    #[error("--sim-tape-sigma-m {0}: must be 0..=0.5 m")]
    TapeSigma(f64),
    /// The simulation could not run.
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// `n` pairs (3..=`max`) made in the lab with a camera tilted `o.tilt_error_deg` away from
/// `cfg`'s, and that true tilt, degrees.
pub fn lab_pairs(cfg: &Config, n: usize, max: usize, o: &LabOptions) -> Result<(Vec<Pair>, f64), LabError> {
    if !(3..=max).contains(&n) {
        return Err(LabError::Count { n, max });
    }
    if !(o.tilt_error_deg.is_finite() && o.tilt_error_deg.abs() <= 30.0) {
        return Err(LabError::TiltError(o.tilt_error_deg));
    }
    if !(o.tape_sigma_m.is_finite() && (0.0..=0.5).contains(&o.tape_sigma_m)) {
        return Err(LabError::TapeSigma(o.tape_sigma_m));
    }
    let mut real = cfg.clone();
    real.camera.tilt_deg += o.tilt_error_deg;
    let pairs = calibration_pairs(&real, n, o.tape_sigma_m, o.seed)?;
    Ok((pairs, real.camera.tilt_deg))
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
        let step = sim.step();
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

/// The straight test road of the ranging and stereo tests (tests/ranging_sim.rs,
/// tests/stereo_sim.rs, tests/stereo_track.rs): a 6 m straight (then a loop back), two
/// 0.30 m lanes with a dashed centre line on a textured floor, and one object of `kind`
/// (`"stop_sign"`, `"traffic_light"`, `"obstacle"`) facing the car on the driven lane's
/// centre (y = −0.15 m), 3 m from the start.
pub fn straight_with_object(kind: &str) -> Result<Track, super::track::TrackError> {
    let text = format!(
        r#"
name = "straight with one {kind}"
[start]
x = 0.0
y = 0.0
heading_deg = 0.0
[road]
lanes = 2
lane_width_m = 0.30
line_width_m = 0.02
line_color = [235, 235, 228]
centre_line = "dashed"
centre_line_color = [235, 235, 228]
dash_m = 0.12
gap_m = 0.05
[floor]
color = [112, 104, 96]
texture = 0.18
texture_scale_m = 0.15
seed = 7
margin_m = 1.0
wall_color = [190, 186, 176]
{SEGMENTS}[[objects]]
type = "{kind}"
x = 3.0
y = -0.15
yaw_deg = 180
"#
    );
    Track::from_toml_str(&text, "straight_with_object")
}

/// The car's pose (rear axle, heading +x, on the object's lateral line) with the lens
/// `d_m` metres before the face a camera sees of `track`'s first enabled object (an
/// obstacle's near side, a sign's face), for the roads of [`straight_with_object`].
/// `None` if the track has no object.
pub fn pose_before_object(cfg: &Config, track: &Track, d_m: f64) -> Option<super::vehicle::Pose> {
    let ob = track.enabled_objects().next()?;
    let near = if ob.kind.info().shape == SimShape::Box {
        ob.size[0] / 2.0
    } else {
        0.0
    };
    Some(super::vehicle::Pose {
        x: ob.pos[0] - near - d_m - cfg.vehicle.camera_x_m,
        y: ob.pos[1],
        yaw: 0.0,
    })
}

/// A frontal picture of the simulator's stop sign, cropped to its face: the camera of `cfg`
/// 0.35 m before the sign of [`straight_with_object`], rendered without noise or blur. The
/// template picture of Abdollahi's detector (`detect::colour_sign`) in the tests and benches.
pub fn stop_sign_picture(cfg: &Config) -> image::RgbImage {
    use super::render::{CameraMount, RenderOptions, Renderer};
    let track = straight_with_object("stop_sign").expect("the built-in road is valid");
    let pose = pose_before_object(cfg, &track, 0.35).expect("the road has its sign");
    let scene = std::sync::Arc::new(super::scene::Scene::new(&track));
    let mount = CameraMount {
        camera: crate::camera::PinholeCamera::from(&cfg.camera),
        x_m: cfg.vehicle.camera_x_m,
    };
    let mut r = Renderer::new(scene, mount, RenderOptions::clean());
    let img = r.render_new(&pose, 0.0, 0);
    let b = track
        .enabled_objects()
        .next()
        .and_then(|ob| super::stereo::sign_face_box(&r, &pose, ob))
        .map(|(b, _)| b)
        .unwrap_or([0.0, 0.0, img.width() as f64 - 1.0, img.height() as f64 - 1.0]);
    let (x0, y0) = ((b[0] + 0.5).max(0.0) as u32, (b[1] + 0.5).max(0.0) as u32);
    let (x1, y1) = (
        ((b[2] + 0.5) as u32).min(img.width()),
        ((b[3] + 0.5) as u32).min(img.height()),
    );
    image::imageops::crop_imm(&img, x0, y0, x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1)).to_image()
}

/// Where the line of [`straight_with_stop_line`] lies: its middle's x, metres (its near edge
/// is 0.025 m before, the sign 0.1 m after).
pub const STOP_LINE_X: f64 = 2.9;

/// The road of [`straight_with_object`] with a stop sign on the right verge 3 m from the start
/// (facing the car, as on the default track) when `sign`, and a line across the driven lane
/// 0.1 m before it when `mark` names one (`"stop_line"` or `"yield_line"`; default length and
/// width: the lane plus a line, 0.05 m): the stop-at-the-line scenario of issue 27.
pub fn straight_with_stop_line(sign: bool, mark: Option<&str>) -> Result<Track, super::track::TrackError> {
    // The same road as `straight_with_object` (every other key at its default).
    let mut text =
        format!("name = \"straight with a stop line\"\n[road]\nlanes = 2\nlane_width_m = 0.30\ndash_m = 0.12\ngap_m = 0.05\n{SEGMENTS}");
    if sign {
        text += "[[objects]]\ntype = \"stop_sign\"\nx = 3.0\ny = -0.48\nyaw_deg = 180\n";
    }
    if let Some(kind) = mark {
        text += &format!("[[marks]]\ntype = \"{kind}\"\nx = {STOP_LINE_X}\ny = -0.15\n");
    }
    Track::from_toml_str(&text, "straight_with_stop_line")
}
