//! The dashboard of one run (issue 11): an observer that does nothing when the dashboard is
//! off, or the loop's side of [`channel`](super::observer::channel) with the HTTP server
//! ([`super::server`], feature `dashboard`) serving it. The page arms, disarms and e-stops
//! through the session's one arming state and gate; in the simulator it may also pause, step
//! and place the car. The loop only publishes into the bounded slot: it never waits on the
//! server (the arrow runs from the network side to the loop's slot, never back).

use crate::config::Config;
use crate::drive::{Clock, Flow, FrameContext, LoopError, Observer, StopSignal};
use crate::pipeline::Pipeline;
use crate::session::Session;
use crate::source::FrameError;
use crate::telemetry::FrameRecord;
use std::path::PathBuf;
use std::sync::Arc;

use super::observer::DashObserver;
use super::shared::DashboardError;

/// The dashboard of one run: off (an observer that does nothing) or serving.
pub struct Dash {
    obs: Option<DashObserver>,
    max_s: Option<f64>,
    #[cfg(feature = "dashboard")]
    _server: Option<super::server::Server>,
}

impl Dash {
    /// No dashboard: an observer that does nothing.
    pub fn off() -> Dash {
        Dash {
            obs: None,
            max_s: None,
            #[cfg(feature = "dashboard")]
            _server: None,
        }
    }

    /// Starts the server on `listen` (default `dashboard.listen`) for `session`'s car; "save"
    /// writes `local`; the set-up page shows `setup_frame` (an image and its name) when given,
    /// else a frozen camera frame. Under the simulator the run then ends at `sim.max_seconds`
    /// only. Without the `dashboard` feature: [`DashboardError::NotBuilt`].
    #[allow(unused_variables, clippy::too_many_arguments)]
    pub fn serve(
        listen: Option<String>,
        cfg: &Config,
        local: PathBuf,
        session: &Session,
        stop: &StopSignal,
        clock: Arc<dyn Clock + Send + Sync>,
        setup_frame: Option<(image::RgbImage, String)>,
    ) -> Result<Dash, DashboardError> {
        #[cfg(not(feature = "dashboard"))]
        {
            Err(DashboardError::NotBuilt)
        }
        #[cfg(feature = "dashboard")]
        {
            use super::server;
            let listen = listen.unwrap_or_else(|| cfg.dashboard.listen.clone());
            let world = session.world().cloned();
            let world_given = world.is_some();
            let ch = super::observer::channel(cfg, world.clone(), Some(stop.clone()), Some(session.arming().clone()));
            let srv = server::Server::start(server::Options {
                listen,
                cfg: cfg.clone(),
                local,
                slot: ch.slot,
                live: ch.live,
                tx: ch.tx,
                arm: session.arming().clone(),
                sent: Arc::new(super::shared::Sent::new(session.sent(), clock)),
                world,
                stop: stop.clone(),
                setup_frame,
            })?;
            Ok(Dash {
                obs: Some(ch.observer),
                max_s: world_given.then_some(cfg.sim.max_seconds),
                _server: Some(srv),
            })
        }
    }
}

impl Observer for Dash {
    fn before_frame(&mut self, p: &mut Pipeline) -> Flow {
        self.obs.as_mut().map_or(Flow::Continue, |o| o.before_frame(p))
    }
    fn decorate(&mut self, r: &mut FrameRecord) {
        if let Some(o) = &mut self.obs {
            o.decorate(r)
        }
    }
    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let f = match &mut self.obs {
            Some(o) => o.on_frame(ctx)?,
            None => Flow::Continue,
        };
        // The simulator under a dashboard ends at `sim.max_seconds` (`--seconds`) only.
        Ok(match self.max_s {
            Some(m) if ctx.frame.time_s >= m => Flow::Stop,
            _ => f,
        })
    }
    fn on_skip(&mut self, e: &FrameError) {
        if let Some(o) = &mut self.obs {
            o.on_skip(e)
        }
    }
    fn on_stall(&mut self, e: &FrameError) {
        if let Some(o) = &mut self.obs {
            o.on_stall(e)
        }
    }
}
