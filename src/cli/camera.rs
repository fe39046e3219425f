//! `rccar camera check`: what cameras the machine has, then one opened as `drive` would, with
//! its real size, fps and latency over a few seconds, and one frame saved (the library's
//! `rccar::session::camera_check`).

use super::common::ConfigArgs;
use super::signals::{say, say_err};
use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use rccar::session::{CameraSpec, SessionEnv};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

/// `rccar camera …`.
#[derive(Subcommand, Debug)]
pub enum CameraCmd {
    /// List the cameras, open one (as `drive --dry-run` would, never armed), report its size,
    /// fps and capture -> command latency over a few seconds, and save its last frame.
    Check(CheckArgs),
}

/// Flags of `rccar camera check`.
#[derive(Args, Debug)]
pub struct CheckArgs {
    /// The camera, as `drive --camera` takes it: `picam:N[:mjpeg]`, `v4l:N`,
    /// `'pipe:FORMAT:COMMAND'` [default: picam:0 when rpicam-vid is installed, else v4l:0].
    #[arg(long)]
    pub camera: Option<String>,
    /// Seconds to measure (0.5..=600).
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Where the last frame goes (PNG).
    #[arg(long, default_value = "camera_check.png")]
    pub save: PathBuf,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Runs `rccar camera`.
pub fn run(c: CameraCmd) -> Result<ExitCode> {
    let CameraCmd::Check(a) = c;
    let cfg = a.config.load()?;
    if !(0.5..=600.0).contains(&a.seconds) {
        bail!("--seconds {}: give 0.5 ..= 600 seconds", a.seconds);
    }
    for line in rccar::session::camera_check::found() {
        say(&format!("found: {line}"));
    }
    let camera = match &a.camera {
        Some(s) => CameraSpec::parse(s).map_err(anyhow::Error::msg)?,
        None => rccar::session::camera_check::default_camera(),
    };
    say(&format!(
        "checking {} for {} s ({}×{} at {} fps configured)...",
        camera.label(),
        a.seconds,
        cfg.camera.width,
        cfg.camera.height,
        cfg.camera.fps
    ));
    let stop = super::signals::install();
    super::signals::on_emergency(rccar::pipecam::child::kill_all);
    let env = SessionEnv {
        clock: Arc::new(super::timer::WallClock::new()),
        stop,
        timer: Box::new(super::timer::WallTimer::new()),
        say: Arc::new(|_, line: &str| say_err(line)),
    };
    let (report, frame) = rccar::session::camera_check::run(&cfg, camera, a.seconds, env)?;
    for line in report.lines((cfg.camera.width, cfg.camera.height, cfg.camera.fps)) {
        say(&line);
    }
    match frame {
        Some(img) => {
            img.save(&a.save)
                .map_err(|e| anyhow::anyhow!("{}: cannot save: {e}", a.save.display()))?;
            say(&format!("  last frame: {}", a.save.display()));
        }
        None => say_err("  no frame to save"),
    }
    Ok(if report.frames > 0 && report.fault.is_none() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
