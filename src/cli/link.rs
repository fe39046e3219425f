//! `rccar link --port PATH`: the students' bench tool for the Arduino link. Handshake and
//! versions, then one of: live telemetry (default), a servo sweep (`--sweep`), trim editing
//! (`--trim-us`, `--save` to store it in EEPROM), round-trip latency (`--latency N`); the
//! modes themselves are `rccar::link::bench`.
//! Every exit path disarms: the `Link` sends DISARM + neutral when dropped, and Ctrl-C only
//! raises a flag that ends the loops so that drop runs; a second Ctrl-C/SIGTERM disarms from
//! the signal thread and exits.

use clap::Args;
use std::process::ExitCode;

/// Flags of `rccar link`.
#[derive(Args, Debug)]
pub struct LinkArgs {
    /// Serial port of the Arduino (e.g. /dev/ttyACM0) or the emulator's pty.
    #[arg(long)]
    pub port: String,
    /// How long to show live telemetry, seconds (0 < S <= 86400).
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// Arm and sweep the steering servo full left ↔ full right twice (throttle stays 0).
    #[arg(long)]
    pub sweep: bool,
    /// Set the servo centre (trim), µs, e.g. 1480. Shown on the wheels at once.
    #[arg(long)]
    pub trim_us: Option<u16>,
    /// With --trim-us: store the new configuration in the Arduino's EEPROM.
    #[arg(long)]
    pub save: bool,
    /// Measure the PING → TELEMETRY round trip N times (1..=10000) and print median and max.
    #[arg(long)]
    pub latency: Option<usize>,
}

/// Refuses flags out of their bounds before the port is opened.
fn check(args: &LinkArgs) -> anyhow::Result<()> {
    if !(args.seconds > 0.0 && args.seconds <= 86_400.0) {
        anyhow::bail!("--seconds {}: must be > 0 and <= 86400 seconds", args.seconds);
    }
    if let Some(n) = args.latency.filter(|n| !(1..=10_000).contains(n)) {
        anyhow::bail!("--latency {n}: must be 1..=10000 pings");
    }
    Ok(())
}

#[cfg(not(feature = "serial"))]
pub fn run(args: LinkArgs) -> anyhow::Result<ExitCode> {
    check(&args)?;
    anyhow::bail!("this rccar was built without the serial link: cargo build --release --features serial")
}

#[cfg(feature = "serial")]
pub fn run(args: LinkArgs) -> anyhow::Result<ExitCode> {
    use anyhow::Context;
    use super::signals::say;
    use rccar::link::bench;
    use rccar::link::protocol::status;
    use rccar::link::transport::{Link, LinkOptions};
    use std::time::Duration;
    check(&args)?;

    // Ctrl-C / SIGTERM end the loops (the Link disarms when dropped); a second one disarms
    // from the signal thread and exits at once, even if this thread is stuck.
    let stop = super::signals::install();
    let stopped = || stop.is_set();

    let link = std::sync::Arc::new(Link::open(&args.port, LinkOptions::default()));
    let l = link.clone();
    super::signals::on_emergency(move || {
        l.drive(0, 0);
        let _ = l.disarm();
    });
    let hello = link
        .wait_connected(Duration::from_secs(3))
        .with_context(|| format!("no firmware answering on {}", args.port))?;
    say(&format!(
        "connected to {}: protocol {}, firmware {}.{}.{} ({})",
        args.port,
        hello.protocol_version,
        hello.fw_major,
        hello.fw_minor,
        hello.fw_patch,
        status::name(hello.status)
    ));
    let (cfg, from_eeprom) = link.get_config()?;
    say(&format!("config ({}): {cfg:?}", if from_eeprom { "EEPROM" } else { "defaults" }));

    if let Some(us) = args.trim_us {
        bench::set_trim(&link, cfg, us, args.save)?;
        say(&format!("servo centre = {us} µs{}", if args.save { " (saved to EEPROM)" } else { "" }));
    }
    if let Some(n) = args.latency {
        if let Some(line) = bench::latency_line(&bench::round_trips(&link, n, &stopped)?) {
            say(&line);
        }
    }
    if args.sweep {
        bench::sweep(&link, 4.0, &stopped)?;
        say("sweep done");
    }
    if args.trim_us.is_none() && !args.sweep && args.latency.is_none() {
        bench::watch(&link, args.seconds, &stopped, &mut |line| say(line));
    }
    // disarm and a neutral DRIVE now (dropping the last `Link` does the same)
    link.drive(0, 0);
    let _ = link.disarm();
    drop(link);
    Ok(if stopped() {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    })
}
