//! `rccar synth OUT`: renders the lane sample sequence (or a single scene) as PNG frames,
//! with a `truth.jsonl` of the true line columns. This is how tests/data/lane_sample/ was made.

use super::common::ConfigArgs;
use anyhow::{Context, Result};
use clap::Args;
use rccar::camera::PinholeCamera;
use rccar::lane::synth::sample_sequence;
use rccar::lane::warp::Homography;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar synth`.
#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Output folder (created).
    pub out: PathBuf,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Writes the frames and their truth.
pub fn run(a: SynthArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    let cam = PinholeCamera::from(&cfg.camera);
    let h = Homography::from_quad_to_rect(&cfg.warp.src, cfg.warp.out_width, cfg.warp.out_height)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    let mut truth = std::fs::File::create(a.out.join("truth.jsonl"))?;
    let scenes = sample_sequence();
    for (i, scene) in scenes.iter().enumerate() {
        let f = scene.render(&cam, &h, cfg.warp.out_height, cfg.lane.band);
        if !f.truth_center().is_finite() {
            anyhow::bail!("warp.src: the histogram band of this ROI does not look at the floor, so there is no truth");
        }
        let name = format!("frame_{i:03}.png");
        f.image.save(a.out.join(&name))?;
        writeln!(
            truth,
            "{}",
            serde_json::json!({"file": name, "truth_left": f.truth_left, "truth_right": f.truth_right,
                "truth_center": f.truth_center(), "left_visible": scene.left_visible, "right_visible": scene.right_visible})
        )?;
    }
    println!("wrote {} frames and truth.jsonl to {}", scenes.len(), a.out.display());
    Ok(ExitCode::SUCCESS)
}
