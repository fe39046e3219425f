//! `rccar config check [FILE]` and `rccar config roi`.

use super::common::ConfigArgs;
use anyhow::{bail, Result};
use clap::Subcommand;
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
        ConfigCmd::Check { file, mut args } => {
            if let Some(f) = file {
                args.config = Some(f);
            }
            check(&args)
        }
        ConfigCmd::Roi {
            args,
            near,
            far,
            half_width,
        } => {
            // The rectangle must be a real one in front of the camera: near < far, both ahead,
            // a positive width (a zero width gives collinear corners and an infinite scale).
            for (flag, v) in [("--near", near), ("--far", far), ("--half-width", half_width)] {
                if !v.is_finite() || v <= 0.0 || v > 100.0 {
                    bail!("{flag} {v}: must be a distance in metres, > 0 and <= 100");
                }
            }
            if near >= far {
                bail!("--near {near} must be less than --far {far} (the near edge is closer to the car)");
            }
            let cfg = args.load()?;
            let roi = cfg.roi_of_ground_rect(near, far, half_width)?;
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

/// Loads and prints the configuration, or every error (exit code 1).
fn check(args: &ConfigArgs) -> Result<ExitCode> {
    match args.load_full() {
        Ok(l) => {
            // A named stereo calibration must be one the pipeline would load (file, image
            // size, a pair that can range).
            if !l.cfg.stereo.calibration.is_empty() {
                let path = std::path::Path::new(&l.cfg.stereo.calibration);
                if let Err(e) =
                    rccar::calib::file::CalibrationFile::load_stereo(path, l.cfg.camera.width, l.cfg.camera.height)
                {
                    eprintln!("config error:\nstereo.calibration: {e}");
                    return Ok(ExitCode::from(1));
                }
            }
            // So must the camera's lens (`camera.calibration`'s file, a model that does not
            // fold back inside the ROI).
            if let Err(e) = l.cfg.camera_lens() {
                eprintln!("config error:\n{e}");
                return Ok(ExitCode::from(1));
            }
            print!("{}", l.cfg.to_toml());
            let files: Vec<String> = l.files.iter().map(|p| p.display().to_string()).collect();
            if l.values_in_files == 0 {
                eprintln!(
                    "note: no values are set in {}: every value is a default",
                    files.join(" + ")
                );
            }
            eprintln!("config OK: {}", files.join(" + "));
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("config error:\n{e:#}");
            Ok(ExitCode::from(1))
        }
    }
}
