//! `rccar stages IMAGE... --out DIR`: writes every intermediate image of the lane pipeline
//! (bird's-eye grey, edges, threshold ∪ edges) and a JSON line per image with the histogram,
//! the lines and the warp matrix. For students to see each stage, and for the OpenCV parity
//! script (tests/parity/lane_parity.py) to compare stage by stage.

use super::common::ConfigArgs;
use anyhow::{Context, Result};
use clap::Args;
use rccar::lane::LaneDetector;
use rccar::timing::{NoTimer, StageTimes};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Flags of `rccar stages`.
#[derive(Args, Debug)]
pub struct StagesArgs {
    /// Camera frames (PNG/JPEG), any size; resized to the configured camera size.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Output folder.
    #[arg(long, short, default_value = "out/stages")]
    pub out: PathBuf,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Dumps the stages of each image.
pub fn run(a: StagesArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    let mut det = LaneDetector::from_config(&cfg)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    let mut index = std::fs::File::create(a.out.join("stages.jsonl"))?;
    let m = det.warp_map().homography().inverse().map(|h| h.0).unwrap_or_default();
    let mut failed = 0;
    for path in &a.images {
        let img = match rccar::imageio::open(path) {
            Ok(i) => i.to_rgb8(),
            Err(e) => {
                eprintln!("skipped {}: {e}", path.display());
                failed += 1;
                continue;
            }
        };
        let img = if img.dimensions() == (cfg.camera.width, cfg.camera.height) {
            img
        } else {
            image::imageops::resize(
                &img,
                cfg.camera.width,
                cfg.camera.height,
                image::imageops::FilterType::Triangle,
            )
        };
        let lane = det.measure(&img, &mut NoTimer, &mut StageTimes::default());
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let im = det.images();
        im.bird.save(a.out.join(format!("{stem}.bird.png")))?;
        im.edges.save(a.out.join(format!("{stem}.edges.png")))?;
        im.binary.save(a.out.join(format!("{stem}.binary.png")))?;
        // The bird's-eye → camera matrix, row-major, so another tool can warp identically.
        let inv: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
        writeln!(
            index,
            "{}",
            serde_json::json!({
                "image": path.display().to_string(), "stem": stem, "level": im.level,
                "band_rows": im.band_rows, "hist": im.hist, "bird_to_camera": inv, "lane": lane,
            })
        )?;
    }
    println!(
        "wrote stages of {} image(s) to {}",
        a.images.len() - failed,
        a.out.display()
    );
    Ok(if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
