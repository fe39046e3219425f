//! Training data for the pilot: (input, steering label) pairs in time order, from the
//! simulator driven by the classical controller with noise on the steering the car obeys
//! ([`from_sim`]), or from recordings on disk ([`from_recording`]); the split by time and the
//! augmentations (mirror and negate, light).
//!
//! Labels are the controller's own command for the frame, not what the car obeyed: with
//! `sim.steer_noise` the car drifts off the lane centre and the label says how the classical
//! controller brings it back (the recoveries a net never sees in clean driving; Bojarski et
//! al. 2016 shifted and rotated camera views for the same reason).

use super::net::INPUT_LEN;
use rccar::config::Config;
use rccar::control::behaviour::Mode;
use rccar::control::learned::{input_from_frame, IN_W};
use rccar::sim::rng::SplitMix64;
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use std::path::{Path, PathBuf};

/// One training example.
#[derive(Debug, Clone)]
pub struct Sample {
    /// The network's input ([`input_from_frame`]).
    pub input: Vec<f32>,
    /// The steering label, −1..=1.
    pub steer: f32,
    /// The frame's file and time (s) when it came from disk (the held-out report runs the
    /// classical pipeline on it); `None` for simulator drives.
    pub image: Option<(PathBuf, f64)>,
}

/// Examples of one drive, in time order (the unit of the split by time).
#[derive(Debug, Clone, Default)]
pub struct Drive {
    /// Where it came from (for messages).
    pub name: String,
    /// The examples, in time order.
    pub samples: Vec<Sample>,
}

/// What the simulator drives for [`from_sim`].
#[derive(Debug, Clone)]
pub struct SimPlan {
    /// The configuration (its `[sim]` track, camera and controller).
    pub cfg: Config,
    /// The track.
    pub track: Track,
    /// One drive per entry: the `sim.steer_noise` of that drive.
    pub noise: Vec<f64>,
    /// Laps per drive.
    pub laps: u32,
    /// Seed of the first drive (camera noise and steering noise; +1 per drive).
    pub seed: i64,
}

/// Drives the simulator as [`SimPlan`] says, labelling each frame with the classical
/// controller's command. `progress(drive, frames)` is called now and then.
pub fn from_sim(plan: &SimPlan, progress: &mut dyn FnMut(usize, usize)) -> Result<Vec<Drive>, String> {
    let mut drives = Vec::new();
    for (k, &noise) in plan.noise.iter().enumerate() {
        let cfg = plan
            .cfg
            .with_override(&format!("sim.steer_noise={noise}"))
            .and_then(|c| c.with_override(&format!("sim.laps={}", plan.laps)))
            .and_then(|c| c.with_override(&format!("sim.seed={}", plan.seed + k as i64)))
            .and_then(|c| c.with_override("steering.method=pid"))
            .map_err(|e| e.to_string())?;
        let mut sim = Simulation::new(&cfg, &plan.track).map_err(|e| e.to_string())?;
        let mut d = Drive {
            name: format!("simulator drive {} (steer noise {noise})", k + 1),
            samples: Vec::new(),
        };
        let mut input = vec![0.0f32; INPUT_LEN];
        sim.run(|sim, step| {
            // A frame whose lane the pipeline lost has no meaningful label (the controller
            // holds the wheel); one after the car left the road neither.
            // A lane change is the behaviour machine's steering, not the controller's.
            let measured = step.out.lane.lane_center.is_some();
            let changing = matches!(step.out.mode, Mode::PassOut | Mode::PassBack);
            if measured && !changing && sim.ended().is_none() && input_from_frame(sim.image(), &mut input) {
                d.samples.push(Sample {
                    input: input.clone(),
                    steer: step.out.command.steer as f32,
                    image: None,
                });
            }
            if d.samples.len().is_multiple_of(500) {
                progress(k, d.samples.len());
            }
            Ok::<(), String>(())
        })?;
        drives.push(d);
    }
    Ok(drives)
}

/// A recording read through [`rccar::dataset::Dataset`]: a car's `--record` folder
/// (telemetry.jsonl + seg_*/frame_*.jpg), a Donkey tub v2 (manifest.json), or, with
/// `telemetry`, a `rccar sim --record DIR` frames folder and its run's telemetry.jsonl.
/// The label is the dataset's (`sent` when the gate changed the command, else the command:
/// with `sim.steer_noise` that is the classical controller's clean command, as in
/// [`from_sim`]). Like [`from_sim`], frames whose telemetry says the lane was lost
/// (`lane_center` null) or the behaviour machine was changing lanes are left out (a tub has
/// no such fields: all its records are kept). Frames must be the pilot's 320×240.
pub fn from_recording(dir: &Path, telemetry: Option<&Path>) -> Result<Drive, String> {
    use rccar::dataset::Dataset;
    let ds = match telemetry {
        Some(t) => Dataset::open_frames(dir, t),
        None => Dataset::open(dir),
    }
    .map_err(|e| e.to_string())?;
    let mut d = Drive {
        name: format!("{} ({})", dir.display(), ds.kind.name()),
        samples: Vec::new(),
    };
    let mut input = vec![0.0f32; INPUT_LEN];
    for s in &ds.samples {
        if let Some(v) = s.telemetry.as_deref().and_then(|l| serde_json::from_str::<serde_json::Value>(l).ok()) {
            let lost = v.get("lane_center").is_some_and(|c| c.is_null());
            let changing = matches!(v.get("behaviour").and_then(|b| b.as_str()), Some("pass_out" | "pass_back"));
            if lost || changing {
                continue;
            }
        }
        let img = s.load_image().map_err(|e| e.to_string())?;
        if !input_from_frame(&img, &mut input) {
            return Err(format!(
                "{}: {}x{} frames; the pilot reads {}x{} (`rccar data import --size {}x{}` makes a tub's frames that size)",
                s.image.display(),
                img.width(),
                img.height(),
                rccar::control::learned::FRAME_W,
                rccar::control::learned::FRAME_H,
                rccar::control::learned::FRAME_W,
                rccar::control::learned::FRAME_H
            ));
        }
        d.samples.push(Sample {
            input: input.clone(),
            steer: s.steer as f32,
            image: Some((s.image.clone(), s.time_s)),
        });
    }
    if d.samples.is_empty() {
        return Err(format!("{}: no frame with a steering label", dir.display()));
    }
    Ok(d)
}

/// Splits every drive by time: its first `1 − val_fraction` for training, the rest for
/// validation (neighbouring frames are near-duplicates: a random split would validate on
/// copies of training frames).
pub fn split_by_time(drives: Vec<Drive>, val_fraction: f64) -> (Vec<Sample>, Vec<Sample>) {
    let (mut train, mut val) = (Vec::new(), Vec::new());
    for d in drives {
        let cut = ((d.samples.len() as f64) * (1.0 - val_fraction)).round() as usize;
        let mut s = d.samples;
        val.extend(s.split_off(cut.min(s.len())));
        train.extend(s);
    }
    (train, val)
}

/// The input mirrored left–right (its label is then negated: the track mirrored).
pub fn mirror(input: &[f32]) -> Vec<f32> {
    let mut out = input.to_vec();
    out.chunks_exact_mut(IN_W).for_each(|r| r.reverse());
    out
}

/// Light augmentation in place: a random gain (0.75..1.25), offset (±0.08) and a left–right
/// brightness ramp (±0.05), clamped to 0..1.
pub fn jitter_light(input: &mut [f32], rng: &mut SplitMix64) {
    let gain = 0.75 + 0.5 * rng.next_f64() as f32;
    let off = (rng.next_f64() as f32 - 0.5) * 0.16;
    let ramp = (rng.next_f64() as f32 - 0.5) * 0.1;
    for row in input.chunks_exact_mut(IN_W) {
        for (x, v) in row.iter_mut().enumerate() {
            let r = ramp * (x as f32 / (IN_W - 1) as f32 - 0.5) * 2.0;
            *v = (*v * gain + off + r).clamp(0.0, 1.0);
        }
    }
}

/// Steering labels counted in bins of 0.1 from −1 to 1 (a balance check for the log).
pub fn histogram(samples: &[Sample]) -> [usize; 20] {
    let mut h = [0usize; 20];
    for s in samples {
        let b = ((s.steer.clamp(-1.0, 0.9999) + 1.0) * 10.0) as usize;
        h[b.min(19)] += 1;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_keeps_time_order_per_drive() {
        let d = |n: usize, base: f32| Drive {
            name: String::new(),
            samples: (0..n)
                .map(|i| Sample {
                    input: vec![],
                    steer: base + i as f32,
                    image: None,
                })
                .collect(),
        };
        let (t, v) = split_by_time(vec![d(10, 0.0), d(5, 100.0)], 0.2);
        let ts: Vec<f32> = t.iter().map(|s| s.steer).collect();
        let vs: Vec<f32> = v.iter().map(|s| s.steer).collect();
        assert_eq!(ts, [0., 1., 2., 3., 4., 5., 6., 7., 100., 101., 102., 103.]);
        assert_eq!(vs, [8., 9., 104.]);
    }

    #[test]
    fn mirror_reverses_rows_and_light_stays_in_range() {
        let x: Vec<f32> = (0..INPUT_LEN).map(|i| (i % IN_W) as f32 / IN_W as f32).collect();
        let m = mirror(&x);
        assert_eq!(m[0], x[IN_W - 1]);
        assert_eq!(mirror(&m), x);
        let mut y = x.clone();
        jitter_light(&mut y, &mut SplitMix64::new(1));
        assert!(y.iter().all(|v| (0.0..=1.0).contains(v)) && y != x);
    }
}
