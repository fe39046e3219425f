//! `--dashboard` for `rccar sim` and `rccar drive`: the flags. The dashboard itself (the
//! loop's side and the HTTP server, feature `dashboard`) is library code in
//! `rccar::dashboard`; without the feature `--dashboard` says how to get it.

use anyhow::Result;
use clap::Args;
use rccar::config::Config;
use rccar::dashboard::Dash;
use rccar::drive::{Clock, StopSignal};
use rccar::session::Session;
use std::path::PathBuf;
use std::sync::Arc;

/// The dashboard flags of `sim` and `drive`.
#[derive(Args, Debug, Clone, Default)]
pub struct DashArgs {
    /// Serve the live dashboard (needs a build with `--features dashboard`).
    #[arg(long)]
    pub dashboard: bool,
    /// Address of the dashboard (default `dashboard.listen`, 127.0.0.1:8080). Any other
    /// address than 127.0.0.1 / ::1 requires the token printed at start-up.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<String>,
    /// The dashboard's set-up page (/setup) shows this image (PNG or JPEG, resized to [camera]
    /// width x height) instead of a frozen camera frame, e.g. a frame saved by `rccar camera
    /// check` or the shipped tests/data/lane_sample/frame_000.png
    #[arg(long, value_name = "FILE", requires = "dashboard")]
    pub setup_frame: Option<PathBuf>,
}

impl DashArgs {
    /// The run's dashboard: off unless `--dashboard` was given.
    pub fn start(
        &self,
        cfg: &Config,
        local: PathBuf,
        session: &Session,
        stop: &StopSignal,
        clock: Arc<dyn Clock + Send + Sync>,
    ) -> Result<Dash> {
        if !self.dashboard {
            return Ok(Dash::off());
        }
        let frame = match &self.setup_frame {
            None => None,
            Some(p) => {
                let img = rccar::imageio::open(p)
                    .map_err(|e| anyhow::anyhow!("--setup-frame {}: {e}", p.display()))?
                    .to_rgb8();
                Some((img, p.display().to_string()))
            }
        };
        Ok(Dash::serve(
            self.listen.clone(),
            cfg,
            local,
            session,
            stop,
            clock,
            frame,
        )?)
    }
}
