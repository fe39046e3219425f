//! `rccar config check [FILE]` and `rccar config roi`.

use super::common::ConfigArgs;
use anyhow::Result;
use clap::Subcommand;
use rccar::camera::PinholeCamera;
use std::process::ExitCode;

/// Configuration subcommands.
#[derive(Subcommand)]
pub enum ConfigCmd {
    /// Load, merge and validate the configuration; print it resolved, or every error.
    Check {
        /// The file to check (default: --config, i.e. config/car.toml).
        file: Option<std::path::PathBuf>,
        #[command(flatten)]
        args: ConfigArgs,
    },
    /// Print the ROI corners (for `[warp] src`) of a floor rectangle seen by the configured camera.
    Roi {
        #[command(flatten)]
        args: ConfigArgs,
        /// Near edge of the rectangle, metres ahead of the lens.
        #[arg(long, default_value_t = 0.40)]
        near: f64,
        /// Far edge, metres ahead of the lens.
        #[arg(long, default_value_t = 1.00)]
        far: f64,
        /// Half width, metres either side of the centre line.
        #[arg(long, default_value_t = 0.25)]
        half_width: f64,
    },
}

/// Runs a config subcommand.
pub fn run(cmd: ConfigCmd) -> Result<ExitCode> {
    match cmd {
        ConfigCmd::Check { file, mut args } => match {
            if let Some(f) = file {
                args.config = f;
            }
            args.load()
        } {
            Ok(cfg) => {
                print!("{}", cfg.to_toml());
                eprintln!("config OK: {}", args.config.display());
                Ok(ExitCode::SUCCESS)
            }
            Err(e) => {
                eprintln!("config error:\n{e:#}");
                Ok(ExitCode::from(1))
            }
        },
        ConfigCmd::Roi {
            args,
            near,
            far,
            half_width,
        } => {
            let cfg = args.load()?;
            let cam = PinholeCamera::from_config(&cfg.camera);
            let roi = cam
                .roi_of_ground_rect(near, far, half_width)
                .ok_or_else(|| anyhow::anyhow!("the rectangle is behind or above the camera"))?;
            let pts: Vec<String> = roi.iter().map(|p| format!("[{:.2}, {:.2}]", p[0], p[1])).collect();
            println!("[warp]\nsrc = [{}]", pts.join(", "));
            let w = cfg.warp.out_width as f64 - 1.0;
            println!(
                "# bird's-eye scale: {:.1} px/m across, {:.1} px/m along",
                w / (2.0 * half_width),
                (cfg.warp.out_height as f64 - 1.0) / (far - near)
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}
