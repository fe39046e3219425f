//! `rccar calibrate ranging PAIRS.csv`: fits the camera tilt α and principal-point row v0 (and
//! a_y with `--fit-ay`) of tilt ranging (src/ranging.rs, Eq. 5) to measured (box-bottom row,
//! true distance[, height]) pairs, prints the residuals and writes the result into a config
//! override (default: local.toml beside the configuration), edited in place so the student's
//! comments and other keys stay, with a backup of the old file. `--from-sim N` makes the
//! pairs in the simulator's calibration lab instead (src/sim/scenario_lab.rs).
//!
//! It never writes a value it cannot stand behind: degenerate pairs (too few distinct rows,
//! rows outside the image, heights at or above the camera, NaN/inf anywhere) are refused
//! before the fit; a fit with an undefined residual or an rms row error above `--max-rms-px`
//! is refused after it; so is a fit decided by where it started (the prior on v0 sits at the
//! image centre, never at the last calibration's v0, and the fit started from the configured
//! values must land on the same answer); the merged configuration is validated before
//! anything is written;
//! `--dry-run` prints the diff of the override file instead of writing it.

use super::common::ConfigArgs;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use rccar::calib::tilt::{self, check_pairs, edit_override, line_diff, MAX_PAIRS};
use rccar::camera::PinholeCamera;
use rccar::config::{Config, LoadedConfig};
use rccar::ranging::{fit, Pair};
use rccar::sim::scenario_lab::{lab_pairs, LabOptions};
use std::path::Path;
use std::path::PathBuf;
use std::process::ExitCode;

/// `rccar calibrate ...`
#[derive(Subcommand, Debug)]
pub enum CalibrateCmd {
    /// Fit tilt and v0 (and a_y) of monocular ranging to measured pairs.
    Ranging(RangingArgs),
    /// Intrinsics and lens distortion of one camera from checkerboard photos (JSON results).
    Camera(super::calib_board::CameraArgs),
    /// A stereo pair from checkerboard photo pairs: both cameras, R, T, rectification.
    Stereo(super::calib_board::StereoArgs),
}

/// `rccar calibrate ranging` flags.
#[derive(Args, Debug)]
pub struct RangingArgs {
    /// CSV of `row_px,distance_m[,height_m]` lines (header and `#` comments allowed; at most
    /// 10,000 pairs, 1 MiB).
    pub pairs: Option<PathBuf>,
    /// Also fit a_y (needs pairs spread over many rows).
    #[arg(long)]
    pub fit_ay: bool,
    /// Config override file to write the result into (comments and other keys are kept; the
    /// old file is kept as FILE.bak) [default: local.toml beside the configuration].
    #[arg(long)]
    pub write: Option<PathBuf>,
    /// Print the fit and the change to the override file as a diff; write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Refuse a fit whose rms row error is above this, pixels (a good tape-measure
    /// calibration is below 1 px); 0 < N <= 100.
    #[arg(long, default_value_t = 2.0)]
    pub max_rms_px: f64,
    /// Make N pairs in the simulator's lab instead of reading a CSV.
    #[arg(long, value_name = "N")]
    pub from_sim: Option<usize>,
    /// Lab: the simulated camera's true tilt differs from the configured one by this, degrees.
    #[arg(long, default_value_t = 0.0)]
    pub sim_tilt_error_deg: f64,
    /// Lab: standard deviation of the taped distances, metres.
    #[arg(long, default_value_t = 0.005)]
    pub sim_tape_sigma_m: f64,
    /// Lab: random seed of the tape errors.
    #[arg(long, default_value_t = 1)]
    pub sim_seed: u64,
    /// Lab: also write the pairs to this CSV (a lab hand-out).
    #[arg(long)]
    pub sim_pairs_out: Option<PathBuf>,
    /// How far v0 may plausibly move from the image centre, pixels (a prior centred on the
    /// image's middle row, never on the configured v0_offset_px; 0 = free); 0..=1000.
    #[arg(long, default_value_t = 3.0)]
    pub v0_sigma_px: f64,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Dispatches `rccar calibrate`.
pub fn run(c: CalibrateCmd) -> Result<ExitCode> {
    match c {
        CalibrateCmd::Ranging(a) => ranging(a),
        CalibrateCmd::Camera(a) => super::calib_board::run_camera(a),
        CalibrateCmd::Stereo(a) => super::calib_board::run_stereo(a),
    }
}

fn ranging(a: RangingArgs) -> Result<ExitCode> {
    let loaded = a.config.load_full()?;
    let cfg = loaded.cfg.clone();
    tilt::check_options(a.max_rms_px, a.v0_sigma_px)?;
    // 1. The pairs: measured, or made in the simulator's lab.
    let pairs = match (&a.pairs, a.from_sim) {
        (_, Some(n)) => from_lab(&a, &cfg, n)?,
        (Some(path), None) => tilt::read_pairs_csv(path)?,
        (None, None) => bail!("give a PAIRS.csv or --from-sim N"),
    };
    let origin = match (&a.pairs, a.from_sim) {
        (Some(p), None) => p.display().to_string(),
        _ => "lab pairs".into(),
    };
    // 2. Refuse data that cannot determine the unknowns.
    check_pairs(&pairs, cfg.camera.height, cfg.camera.height_m, a.fit_ay)
        .map_err(|e| anyhow::anyhow!("{origin}: {e}; nothing written"))?;
    // 3. Fit. The prior on v0 sits at the image centre (a property of the image, not of the
    // last calibration: tilt and v0 trade off, so a prior at an earlier fit's v0 returns that
    // fit whatever the pairs say). Without --fit-ay, a_y is held at the configured scale.
    let cam = PinholeCamera::from(&cfg.camera);
    let from_image = tilt::from_image_centre(&cam, cfg.ranging.a_y_scale, a.fit_ay);
    let opts = tilt::centre_prior(&cam, a.fit_ay, a.v0_sigma_px);
    let f = fit(&pairs, from_image, opts).map_err(|e| anyhow::anyhow!("{origin}: {e}; nothing written"))?;
    // 4. Report.
    for line in tilt::residual_lines(&pairs, &f) {
        println!("{line}");
    }
    let fitted = tilt::fitted_values(&f.ranging, &cam);
    let [(_, tilt), (_, v0_off), (_, ay_scale)] = fitted;
    println!(
        "fit: tilt {tilt:.3} deg (was {:.3}), v0 {:.2} px (offset {v0_off:+.2}), a_y {:.1} px (scale {ay_scale:.4}); rms row error {:.2} px",
        cfg.camera.tilt_deg, f.ranging.v0, f.ranging.a_y, f.rms_row_px
    );
    // 5. Refuse a fit that does not explain the data.
    tilt::check_fit(&pairs, &f, a.max_rms_px, fitted, cfg.camera.height)
        .and_then(|()| tilt::check_start(&pairs, &f, opts, &cam, cfg.ranging.v0_offset_px, cfg.ranging.a_y_scale))
        .map_err(|e| anyhow::anyhow!("{origin}: {e}; nothing written"))?;
    // 6.-7. The override file.
    let values = tilt::override_values(fitted);
    write_result(&a, &loaded, &values)
}

/// `n` pairs made in the simulator's calibration lab (and written to `--sim-pairs-out`).
fn from_lab(a: &RangingArgs, cfg: &Config, n: usize) -> Result<Vec<Pair>> {
    let o = LabOptions {
        tilt_error_deg: a.sim_tilt_error_deg,
        tape_sigma_m: a.sim_tape_sigma_m,
        seed: a.sim_seed,
    };
    let (p, true_tilt) = lab_pairs(cfg, n, MAX_PAIRS, &o)?;
    println!(
        "lab: {} pairs from the simulator (true tilt {true_tilt:.2} deg, tape sigma {} m)",
        p.len(),
        a.sim_tape_sigma_m
    );
    if let Some(out) = &a.sim_pairs_out {
        write_file(out, &tilt::pairs_csv(&p))?;
        println!("lab pairs written to {}", out.display());
    }
    Ok(p)
}

/// The new override file, validated merged with the configuration, then printed as a diff
/// (`--dry-run`) or written (the old one backed up first, the new one replacing it atomically).
fn write_result(a: &RangingArgs, loaded: &LoadedConfig, values: &[(&str, &str, f64)]) -> Result<ExitCode> {
    let target = a.write.clone().unwrap_or_else(|| loaded.dir.join("local.toml"));
    let old = tilt::read_override(&target)?;
    let new = edit_override(old.as_deref(), values).with_context(|| format!("{}: cannot update", target.display()))?;
    let base = &loaded.files[0];
    let others: Vec<PathBuf> = loaded.files[1..].to_vec();
    LoadedConfig::check_with_text(base, &others, &target, &new).map_err(|e| {
        anyhow::anyhow!(
            "the fit gives a configuration that does not validate, so {} is left as it was:\n{e}",
            target.display()
        )
    })?;
    if a.dry_run {
        println!(
            "--- {} (now)\n+++ {} (after calibration)",
            target.display(),
            target.display()
        );
        print!("{}", line_diff(old.as_deref().unwrap_or(""), &new));
        println!("dry run: nothing written");
        return Ok(ExitCode::SUCCESS);
    }
    // Back up, then replace atomically (a full disk leaves the old file in place).
    if let Some(backup) = tilt::backup_override(&target, old.is_some())? {
        println!("old {} kept as {}", target.display(), backup.display());
    }
    write_file(&target, &new)?;
    println!(
        "wrote camera.tilt_deg, ranging.v0_offset_px, ranging.a_y_scale to {}",
        target.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// [`tilt::write_file`]; errors name `path`.
fn write_file(path: &Path, text: &str) -> Result<()> {
    tilt::write_file(path, text).map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))
}
