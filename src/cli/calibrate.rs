//! `rccar calibrate ranging PAIRS.csv`: fits the camera tilt α and principal-point row v0 (and
//! a_y with `--fit-ay`) of tilt ranging (src/ranging.rs, Eq. 5) to measured (box-bottom row,
//! true distance[, height]) pairs, prints the residuals and writes the result into a config
//! override (default config/local.toml; other keys in it are kept). `--from-sim N` makes the
//! pairs in the simulator's calibration lab instead (src/sim/scenario_lab.rs).

use super::common::ConfigArgs;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use rccar::camera::PinholeCamera;
use rccar::ranging::{fit, parse_pairs_csv, FitOptions, TiltRanging};
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
    /// CSV of `row_px,distance_m[,height_m]` lines (header and `#` comments allowed).
    pub pairs: Option<PathBuf>,
    /// Also fit a_y (needs pairs spread over many rows).
    #[arg(long)]
    pub fit_ay: bool,
    /// Config override file to write the result into (existing keys are kept).
    #[arg(long, default_value = "config/local.toml")]
    pub write: PathBuf,
    /// Print only; write nothing.
    #[arg(long)]
    pub dry_run: bool,
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
    /// How far v0 may plausibly move from the image centre, pixels (a prior; 0 = free).
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
    let cfg = a.config.load()?;
    // 1. The pairs: measured, or made in the simulator's lab.
    let pairs = match (&a.pairs, a.from_sim) {
        (_, Some(n)) => {
            let mut real = cfg.clone();
            real.camera.tilt_deg += a.sim_tilt_error_deg;
            let p = rccar::sim::scenario_lab::calibration_pairs(&real, n, a.sim_tape_sigma_m, a.sim_seed)?;
            println!(
                "lab: {} pairs from the simulator (true tilt {:.2} deg, tape sigma {} m)",
                p.len(),
                real.camera.tilt_deg,
                a.sim_tape_sigma_m
            );
            if let Some(out) = &a.sim_pairs_out {
                let mut text = String::from("row_px,distance_m,height_m\n");
                for q in &p {
                    text += &format!("{:.1},{:.4},{}\n", q.v, q.d, q.z);
                }
                std::fs::write(out, text).with_context(|| format!("{}: cannot write", out.display()))?;
                println!("lab pairs written to {}", out.display());
            }
            p
        }
        (Some(path), None) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
            parse_pairs_csv(&text, &path.display().to_string()).map_err(anyhow::Error::msg)?
        }
        (None, None) => bail!("give a PAIRS.csv or --from-sim N"),
    };
    // 2. Fit from the configured (nominal) camera.
    let cam = PinholeCamera::from_config(&cfg.camera);
    let mut start = TiltRanging::from_camera(&cam);
    start.v0 += cfg.ranging.v0_offset_px;
    start.a_y *= cfg.ranging.a_y_scale;
    let opts = FitOptions {
        fit_ay: a.fit_ay,
        v0_sigma_px: if a.v0_sigma_px > 0.0 {
            a.v0_sigma_px
        } else {
            f64::INFINITY
        },
        ..Default::default()
    };
    let f = fit(&pairs, start, opts)?;
    // 3. Report.
    println!(
        "{:>8} {:>9} {:>10} {:>10} {:>7}",
        "row px", "true m", "fitted m", "resid m", "resid %"
    );
    for (p, r) in pairs.iter().zip(&f.residuals_m) {
        println!(
            "{:>8.1} {:>9.4} {:>10.4} {:>+10.4} {:>+7.2}",
            p.v,
            p.d,
            p.d + r,
            r,
            100.0 * r / p.d
        );
    }
    let tilt = f.ranging.alpha.to_degrees();
    let v0_off = f.ranging.v0 - cam.v0;
    let ay_scale = f.ranging.a_y / cam.f_px;
    println!(
        "fit: tilt {tilt:.3} deg (was {:.3}), v0 {:.2} px (offset {v0_off:+.2}), a_y {:.1} px (scale {ay_scale:.4}); rms row error {:.2} px",
        cfg.camera.tilt_deg, f.ranging.v0, f.ranging.a_y, f.rms_row_px
    );
    // 4. Merge into the override file.
    if a.dry_run {
        return Ok(ExitCode::SUCCESS);
    }
    let mut table: toml::Table = if a.write.exists() {
        let text = std::fs::read_to_string(&a.write).with_context(|| format!("{}: cannot read", a.write.display()))?;
        text.parse()
            .with_context(|| format!("{}: not valid TOML", a.write.display()))?
    } else {
        toml::Table::new()
    };
    let mut set = |section: &str, key: &str, v: f64| {
        let t = table
            .entry(section)
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let toml::Value::Table(t) = t {
            t.insert(key.into(), toml::Value::Float((v * 1e4).round() / 1e4));
        }
    };
    set("camera", "tilt_deg", tilt);
    set("ranging", "v0_offset_px", v0_off);
    set("ranging", "a_y_scale", ay_scale);
    let text = format!(
        "# Written by `rccar calibrate ranging` over config/car.toml;\n# other keys are kept, comments are not.\n{}",
        toml::to_string(&table)?
    );
    if let Some(dir) = a.write.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    std::fs::write(&a.write, text).with_context(|| format!("{}: cannot write", a.write.display()))?;
    // The merged configuration must still load.
    rccar::config::Config::load(&a.config.config, std::slice::from_ref(&a.write), &[]).with_context(|| {
        format!(
            "{}: written, but the merged configuration is invalid",
            a.write.display()
        )
    })?;
    println!(
        "wrote camera.tilt_deg, ranging.v0_offset_px, ranging.a_y_scale to {}",
        a.write.display()
    );
    Ok(ExitCode::SUCCESS)
}
