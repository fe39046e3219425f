//! `--pad [DEVICE]` for `rccar drive` and `rccar sim`: a gamepad read on this computer
//! (feature `gamepad`, Linux; docs/gamepad.md). The mapping and what it does to the car are
//! library code (`rccar::pad`); without the feature `--pad` says how to get it.

use anyhow::{bail, Result};
use clap::Args;
use rccar::config::Config;
use rccar::drive::{Clock, Observer};
use rccar::pad::PadEvents;
use rccar::session::Session;
use rccar::telemetry::FrameRecord;
use std::sync::Arc;

/// The gamepad flag of `sim` and `drive`.
#[derive(Args, Debug, Clone, Default)]
pub struct PadArgs {
    /// Drive with a gamepad on this computer (a build with `--features gamepad`): `--pad`
    /// alone reads `gamepad.device` (default `auto`, the first gamepad), `--pad
    /// /dev/input/eventN` names one. Hold LB or RB to drive; B is the e-stop; Start held 1 s
    /// arms (docs/gamepad.md). `rccar drive` also reads one with `gamepad.enabled = true`.
    #[arg(long, value_name = "DEVICE", num_args = 0..=1, default_missing_value = "")]
    pub pad: Option<String>,
}

/// The run's pad: its events go into the telemetry; its thread stops when this is dropped.
pub struct Pad {
    events: PadEvents,
    #[cfg(all(feature = "gamepad", target_os = "linux"))]
    _thread: rccar::pad::device::PadThread,
}

impl Observer for Pad {
    fn decorate(&mut self, record: &mut FrameRecord) {
        self.events.decorate(record);
    }
}

impl PadArgs {
    /// The device asked for, and the key or flag that named it; `None`: no pad (`config`:
    /// whether `gamepad.enabled` counts, as for `rccar drive`).
    pub fn wanted(&self, cfg: &Config, config: bool) -> Option<(String, &'static str)> {
        match self.pad.as_deref() {
            Some("") => Some((cfg.gamepad.device.clone(), "gamepad.device")),
            Some(d) => Some((d.to_string(), "--pad")),
            None if config && cfg.gamepad.enabled => Some((cfg.gamepad.device.clone(), "gamepad.device")),
            None => None,
        }
    }

    /// Starts the pad's thread on `session`'s car (`None`: no pad wanted).
    pub fn start(
        &self,
        cfg: &Config,
        session: &Session,
        clock: Arc<dyn Clock + Send + Sync>,
        config: bool,
    ) -> Result<Option<Pad>> {
        let Some((device, key)) = self.wanted(cfg, config) else {
            return Ok(None);
        };
        start(cfg, session, clock, device, key).map(Some)
    }
}

#[cfg(all(feature = "gamepad", target_os = "linux"))]
fn start(
    cfg: &Config,
    session: &Session,
    clock: Arc<dyn Clock + Send + Sync>,
    device: String,
    key: &'static str,
) -> Result<Pad> {
    use rccar::pad::device::{Source, Which};
    use rccar::pad::{PadLink, PadMachine};
    let opts = cfg.gamepad.options();
    let which = if device == "auto" {
        Which::Auto
    } else {
        Which::Path(device.into())
    };
    let arming = session.arming().clone();
    let link = PadLink::new(arming.clone(), clock, cfg.gamepad.disarm_on_disconnect).with_say(super::signals::sayer());
    let events = link.events();
    let src = Source {
        which,
        key: key.to_string(),
        axes: [
            ("gamepad.steer_axis", opts.steer_axis),
            ("gamepad.throttle_axis", opts.throttle_axis),
        ],
    };
    // Waiting for a pad is part of the run: its health shows it until one is there.
    arming.health().set(
        rccar::health::Part::Pad,
        rccar::health::PartState::Waiting,
        "no gamepad yet",
    );
    let (thread, line) = rccar::pad::device::start(src, PadMachine::new(opts), link)?;
    // A human may drive from now on: every record says the mode and who drove.
    arming.controls().attach();
    super::signals::say(&line);
    Ok(Pad {
        events,
        _thread: thread,
    })
}

#[cfg(not(all(feature = "gamepad", target_os = "linux")))]
fn start(_: &Config, _: &Session, _: Arc<dyn Clock + Send + Sync>, _: String, key: &'static str) -> Result<Pad> {
    let what = if key == "--pad" {
        "--pad"
    } else {
        "--pad / gamepad.enabled"
    };
    bail!("{what}: this rccar was built without the gamepad: cargo build --release --features gamepad (Linux only)")
}

/// `rccar sim --pad` needs the simulator at real time (a human drives on the wall clock).
pub fn check_sim(a: &PadArgs, sweeping: bool) -> Result<()> {
    if a.pad.is_some() && sweeping {
        bail!("--pad: not with --sweep (nobody can drive a sweep)");
    }
    Ok(())
}
