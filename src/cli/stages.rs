//! `rccar stages IMAGE... --out DIR`: writes every intermediate image of the lane pipeline
//! (bird's-eye grey, edges, threshold ∪ edges) and a JSON line per image with the histogram,
//! the lines and the warp matrix. For students to see each stage, and for the OpenCV parity
//! script (tests/parity/lane_parity.py) to compare stage by stage.

use super::common::ConfigArgs;
use anyhow::{Context, Result};
use clap::Args;
use rccar::source::{escape_name, load_frame, min_frame_size, unique_name};
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

/// Dumps the stages of each image. A damaged, unreadable or too small image is named,
/// counted and skipped (exit 1 at the end); outputs are named `<file name>.bird.png` etc.
/// (extension kept, so `a.jpg` and `a.png` do not collide).
pub fn run(a: StagesArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    let mut det = cfg.lane_detector()?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    let index_path = a.out.join("stages.jsonl");
    let mut index = std::io::BufWriter::new(
        std::fs::File::create(&index_path).with_context(|| format!("{}: cannot create", index_path.display()))?,
    );
    let bird_to_camera = det.bird_to_camera();
    let min_size = min_frame_size(&cfg.warp.src, cfg.camera.width, cfg.camera.height);
    let mut failed = 0;
    let mut used = std::collections::HashSet::new();
    for path in &a.images {
        let shown = escape_name(path.as_os_str());
        let img = match load_frame(path, cfg.camera.width, cfg.camera.height, min_size) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("skipped {shown}: {e}");
                failed += 1;
                continue;
            }
        };
        let lane = det.measure(&img, &mut NoTimer, &mut StageTimes::default());
        let stem = unique_name(path.file_name().map(escape_name).unwrap_or_default(), &mut used);
        for (what, pic) in det.images().stages() {
            let p = a.out.join(format!("{stem}.{what}.png"));
            pic.save(&p).with_context(|| format!("{}: cannot write", p.display()))?;
        }
        let mut record = det.images().stage_record(&bird_to_camera, &lane);
        record["image"] = shown.into();
        record["stem"] = stem.into();
        writeln!(index, "{record}")
            .and_then(|_| index.flush())
            .with_context(|| format!("{}: cannot write", index_path.display()))?;
    }
    index
        .flush()
        .with_context(|| format!("{}: cannot write", index_path.display()))?;
    println!(
        "wrote stages of {} image(s) to {}",
        a.images.len() - failed,
        a.out.display()
    );
    if failed > 0 {
        eprintln!("{failed} of {} image(s) skipped", a.images.len());
    }
    Ok(if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
