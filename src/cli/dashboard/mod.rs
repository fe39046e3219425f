//! `--dashboard` for `rccar sim` and `rccar drive`: the wiring between the loop and the web
//! server (issue 11). The loop side (snapshot slot, inbox, events) is library code in
//! `rccar::dashboard`; the HTTP server, the real-time pacing of the simulator and the probe
//! that timestamps what the sink really sent live here, because they read the wall clock.
//!
//! Without the `dashboard` cargo feature everything here still builds; `--dashboard` then
//! says how to get it.

#[cfg(feature = "dashboard")]
pub mod server;

use anyhow::Result;
use clap::Args;
use rccar::config::Config;
use rccar::control::Command;
use rccar::dashboard::{DashObserver, WithEvents};
use rccar::drive::{ArmState, Flow, FrameContext, Gate, LoopError, Observer, StopSignal};
use rccar::pipeline::Pipeline;
use rccar::sim::world::SharedWorld;
use rccar::sink::{CommandSink, SinkError};
use rccar::source::FrameError;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

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

/// A float in an atomic (bits), NaN = unset.
#[derive(Debug)]
pub struct AtomicF64(AtomicU64);

impl AtomicF64 {
    /// Unset (NaN).
    pub fn nan() -> Self {
        Self(AtomicU64::new(f64::NAN.to_bits()))
    }
    /// The value.
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::SeqCst))
    }
    /// Sets it.
    pub fn set(&self, v: f64) {
        self.0.store(v.to_bits(), Ordering::SeqCst)
    }
}

/// What the sink really sent (after the arming gate), and when, on the dashboard's clock:
/// the e-stop's effect is measured here. Atomics only: the e-stop handler never waits.
#[derive(Debug)]
pub struct Sent {
    /// Wall clock origin of all `*_wall_s`.
    pub start: Instant,
    /// Last command's throttle and steering as sent to the car.
    pub throttle: AtomicF64,
    /// Steering sent.
    pub steer: AtomicF64,
    /// When it was sent, wall seconds.
    pub wall_s: AtomicF64,
    /// The frame time it was sent for, seconds (simulated time in the simulator).
    pub sim_s: AtomicF64,
    /// When the e-stop request arrived, wall seconds (NaN: not pressed).
    pub estop_wall_s: AtomicF64,
    /// The frame time of the last command before the e-stop arrived.
    #[cfg_attr(not(feature = "dashboard"), allow(dead_code))]
    pub estop_sim_s: AtomicF64,
    /// First zero-throttle command sent after the e-stop, wall seconds.
    pub neutral_wall_s: AtomicF64,
    /// … and its frame time.
    pub neutral_sim_s: AtomicF64,
}

impl Sent {
    fn new() -> Arc<Self> {
        Arc::new(Self {
            start: Instant::now(),
            throttle: AtomicF64::nan(),
            steer: AtomicF64::nan(),
            wall_s: AtomicF64::nan(),
            sim_s: AtomicF64::nan(),
            estop_wall_s: AtomicF64::nan(),
            estop_sim_s: AtomicF64::nan(),
            neutral_wall_s: AtomicF64::nan(),
            neutral_sim_s: AtomicF64::nan(),
        })
    }
    /// Wall seconds since `start`.
    pub fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
    /// The e-stop arrived now (the server's e-stop handler).
    #[cfg_attr(not(feature = "dashboard"), allow(dead_code))]
    pub fn mark_estop(&self) {
        self.neutral_wall_s.set(f64::NAN);
        self.neutral_sim_s.set(f64::NAN);
        self.estop_sim_s.set(self.sim_s.get());
        self.estop_wall_s.set(self.now());
    }
}

/// A sink that records what passes through it into [`Sent`].
pub struct Probe<S> {
    inner: S,
    sent: Arc<Sent>,
}

impl<S: CommandSink> CommandSink for Probe<S> {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<(), SinkError> {
        let r = self.inner.send(cmd, now_s);
        let s = &self.sent;
        let w = s.now();
        s.throttle.set(cmd.throttle);
        s.steer.set(cmd.steer);
        s.wall_s.set(w);
        s.sim_s.set(now_s);
        if !s.estop_wall_s.get().is_nan() && s.neutral_wall_s.get().is_nan() && cmd.throttle == 0.0 {
            s.neutral_wall_s.set(w);
            s.neutral_sim_s.set(now_s);
        }
        r
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        self.inner.stop()
    }
}

/// Sleeps between frames so that a simulated run goes at real time (watchable).
struct Pacer {
    period: Duration,
    next: Option<Instant>,
}

impl Pacer {
    fn before(&mut self) {
        let now = Instant::now();
        if let Some(t) = self.next {
            if t > now {
                std::thread::sleep(t - now);
            }
        }
        // After a pause the schedule restarts from now (no catching up).
        let base = self.next.map_or(now, |t| t.max(now));
        self.next = Some(base + self.period);
    }
}

/// The dashboard of one run: off (everything passes through) or serving.
pub struct Dash {
    obs: Option<DashObserver>,
    pacer: Option<Pacer>,
    max_s: Option<f64>,
    /// Arming and e-stop shared by the page, the gate and the heartbeat watchdog.
    pub arm: Arc<ArmState>,
    sent: Arc<Sent>,
    #[cfg(feature = "dashboard")]
    _server: Option<server::Server>,
}

impl Dash {
    /// No dashboard: the sink is not gated (armed), nothing is served.
    pub fn off() -> Dash {
        let arm = ArmState::new();
        arm.arm();
        Dash {
            obs: None,
            pacer: None,
            max_s: None,
            arm,
            sent: Sent::new(),
            #[cfg(feature = "dashboard")]
            _server: None,
        }
    }

    /// Starts the server when `--dashboard` was given. `world`: the simulator's (pause, step,
    /// place; the run then ends at `sim.max_seconds` only); `pace_fps`: pace the loop at this
    /// frame rate (the simulator); `on_arm`: called when the page arms. The car starts
    /// disarmed: the page arms it.
    #[allow(unused_variables)]
    pub fn start(
        a: &DashArgs,
        cfg: &Config,
        local: PathBuf,
        world: Option<SharedWorld>,
        stop: &StopSignal,
        pace_fps: Option<f64>,
        on_arm: Option<std::sync::Arc<dyn Fn() + Send + Sync>>,
    ) -> Result<Dash> {
        if !a.dashboard {
            return Ok(Dash::off());
        }
        #[cfg(not(feature = "dashboard"))]
        {
            anyhow::bail!("--dashboard: this rccar was built without it; rebuild with `cargo build --release --features dashboard`");
        }
        #[cfg(feature = "dashboard")]
        {
            let listen = a.listen.clone().unwrap_or_else(|| cfg.dashboard.listen.clone());
            let arm = ArmState::new();
            let sent = Sent::new();
            let world_given = world.is_some();
            let ch = rccar::dashboard::channel(cfg, world.clone(), Some(stop.clone()));
            let obs = ch.observer;
            let srv = server::Server::start(server::Options {
                listen,
                cfg: cfg.clone(),
                local,
                slot: ch.slot,
                live: ch.live,
                tx: ch.tx,
                arm: arm.clone(),
                sent: sent.clone(),
                world,
                stop: stop.clone(),
                on_arm,
            })?;
            Ok(Dash {
                obs: Some(obs),
                max_s: world_given.then_some(cfg.sim.max_seconds),
                pacer: pace_fps.map(|f| Pacer {
                    period: Duration::from_secs_f64(1.0 / f.max(1.0)),
                    next: None,
                }),
                arm,
                sent,
                _server: Some(srv),
            })
        }
    }

    /// Whether a page is being served.
    pub fn enabled(&self) -> bool {
        self.obs.is_some()
    }

    /// The loop's sink: gated by the dashboard's arming and probed; unchanged when off.
    pub fn sink<'a, S: CommandSink + 'a>(&self, s: S) -> Box<dyn CommandSink + 'a> {
        if self.enabled() {
            Box::new(Gate::new(
                Probe {
                    inner: s,
                    sent: self.sent.clone(),
                },
                self.arm.clone(),
            ))
        } else {
            Box::new(s)
        }
    }

    /// The telemetry writer, with the dashboard's events added to its records.
    pub fn tag<'a>(&self, telemetry: &'a mut dyn Observer) -> WithEvents<'a> {
        match &self.obs {
            Some(o) => o.tag(telemetry),
            None => WithEvents::plain(telemetry),
        }
    }
}

impl Observer for Dash {
    fn before_frame(&mut self, p: &mut Pipeline) -> Flow {
        let f = self.obs.as_mut().map_or(Flow::Continue, |o| o.before_frame(p));
        if let Some(pc) = &mut self.pacer {
            pc.before();
        }
        f
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
