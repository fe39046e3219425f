//! `--dashboard` for `rccar sim` and `rccar drive`: the wiring between the session and the web
//! server (issue 11). The loop side (snapshot slot, inbox, events) is library code in
//! `rccar::dashboard`; arming, the e-stop and what was really sent are the session's one
//! arming state and gate (`rccar::drive::{Arming, Sent}`). The HTTP server lives here because
//! it reads the wall clock.
//!
//! Without the `dashboard` cargo feature everything here still builds; `--dashboard` then
//! says how to get it.

#[cfg(feature = "dashboard")]
pub mod server;

use anyhow::Result;
use clap::Args;
use rccar::config::Config;
use rccar::dashboard::DashObserver;
use rccar::drive::{Clock, Flow, FrameContext, LoopError, Observer, StopSignal};
use rccar::pipeline::Pipeline;
use rccar::session::Session;
use rccar::source::FrameError;
use rccar::telemetry::FrameRecord;
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
}

/// What the gate really sent, on the run's clock (the e-stop's effect is measured here).
pub struct Sent {
    /// The gate's record.
    pub sent: Arc<rccar::drive::Sent>,
    clock: Arc<dyn Clock + Send + Sync>,
}

impl Sent {
    /// Seconds on the run's clock.
    pub fn now(&self) -> f64 {
        self.clock.now_s()
    }
    /// The e-stop arrived now (the server's e-stop handler, before it presses).
    #[cfg_attr(not(feature = "dashboard"), allow(dead_code))]
    pub fn mark_estop(&self) {
        self.sent.mark_estop(self.now());
    }
}

impl std::ops::Deref for Sent {
    type Target = rccar::drive::Sent;
    fn deref(&self) -> &Self::Target {
        &self.sent
    }
}

/// The dashboard of one run: off (an observer that does nothing) or serving.
pub struct Dash {
    obs: Option<DashObserver>,
    max_s: Option<f64>,
    #[cfg(feature = "dashboard")]
    _server: Option<server::Server>,
}

impl Dash {
    /// Starts the server when `--dashboard` was given, for `session`'s car: the page arms,
    /// disarms and e-stops through the session's one arming state; in the simulator it may
    /// pause, step and place the car (the run then ends at `sim.max_seconds` only).
    #[allow(unused_variables)]
    pub fn start(a: &DashArgs, cfg: &Config, local: PathBuf, session: &Session, stop: &StopSignal, clock: Arc<dyn Clock + Send + Sync>) -> Result<Dash> {
        if !a.dashboard {
            return Ok(Dash {
                obs: None,
                max_s: None,
                #[cfg(feature = "dashboard")]
                _server: None,
            });
        }
        #[cfg(not(feature = "dashboard"))]
        {
            anyhow::bail!("--dashboard: this rccar was built without it; rebuild with `cargo build --release --features dashboard`");
        }
        #[cfg(feature = "dashboard")]
        {
            let listen = a.listen.clone().unwrap_or_else(|| cfg.dashboard.listen.clone());
            let world = session.world().cloned();
            let world_given = world.is_some();
            let ch = rccar::dashboard::channel(cfg, world.clone(), Some(stop.clone()));
            let srv = server::Server::start(server::Options {
                listen,
                cfg: cfg.clone(),
                local,
                slot: ch.slot,
                live: ch.live,
                tx: ch.tx,
                arm: session.arming().clone(),
                sent: Arc::new(Sent {
                    sent: session.sent(),
                    clock,
                }),
                world,
                stop: stop.clone(),
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
