//! The bench modes of `rccar link` on an open [`Link`] (the students' tool for the Arduino on
//! the desk): the servo's trim ([`set_trim`]), PING round trips ([`round_trips`],
//! [`latency_line`]), a servo sweep ([`sweep`]) and the firmware's live telemetry
//! ([`watch`], [`telemetry_line`]). Every loop ends early when `stopped()` says so; the
//! caller disarms on the way out (dropping the last `Link` does it too).

use super::protocol::{LinkConfig, Telemetry};
use super::transport::{Link, LinkError};
use std::time::{Duration, Instant};

/// Why the trim was not set.
#[derive(Debug, thiserror::Error)]
pub enum TrimError {
    /// The centre does not lie between the servo's ends.
    #[error("--trim-us {us}: must lie strictly between servo_min_us {min} and servo_max_us {max}")]
    OutOfRange {
        /// The centre asked for, µs.
        us: u16,
        /// The servo's left end, µs.
        min: u16,
        /// The servo's right end, µs.
        max: u16,
    },
    /// The firmware did not take it.
    #[error(transparent)]
    Link(#[from] LinkError),
}

/// Sets the servo's centre (trim) to `us` in `cfg`, the firmware's configuration now, and
/// sends it (`save`: into the EEPROM too); the wheels show it at once.
pub fn set_trim(link: &Link, mut cfg: LinkConfig, us: u16, save: bool) -> Result<(), TrimError> {
    cfg.servo_center_us = us;
    if !cfg.is_valid() {
        return Err(TrimError::OutOfRange {
            us,
            min: cfg.servo_min_us,
            max: cfg.servo_max_us,
        });
    }
    link.set_config(cfg, save)?;
    Ok(())
}

/// PING → TELEMETRY round trips: the answered ones, ms in the order measured, and how many got
/// no answer within the link's reply timeout.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoundTrips {
    /// Round trips of the answered pings, milliseconds.
    pub ms: Vec<f64>,
    /// Pings without an answer in time (counted, not fatal: a measurement goes on).
    pub unanswered: usize,
}

/// Up to `n` PING → TELEMETRY round trips (fewer when stopped). A ping that gets no answer in
/// time while the link is up (a frame lost to a bad checksum, a busy machine) is counted in
/// [`RoundTrips::unanswered`] and the next one is sent; any other error ends the run.
pub fn round_trips(link: &Link, n: usize, stopped: &dyn Fn() -> bool) -> Result<RoundTrips, LinkError> {
    let mut r = RoundTrips {
        ms: Vec::with_capacity(n),
        unanswered: 0,
    };
    for _ in 0..n {
        if stopped() {
            break;
        }
        match link.ping() {
            Ok((_, rtt)) => r.ms.push(rtt.as_secs_f64() * 1e3),
            Err(LinkError::Timeout { .. }) if link.is_connected() => r.unanswered += 1,
            Err(e) => return Err(e),
        }
    }
    Ok(r)
}

/// The median and the maximum of the answered round trips as one line, and the unanswered
/// pings when there were any; `None` without any ping.
pub fn latency_line(r: &RoundTrips) -> Option<String> {
    let lost = match r.unanswered {
        0 => String::new(),
        n => format!("; {n} unanswered in time"),
    };
    let mut ms = r.ms.to_vec();
    ms.sort_by(f64::total_cmp);
    let (Some(median), Some(max)) = (ms.get(ms.len() / 2), ms.last()) else {
        return (r.unanswered > 0).then(|| format!("round trip PING -> TELEMETRY: no answer to {} pings", r.unanswered));
    };
    Some(format!(
        "round trip PING -> TELEMETRY over {} pings: median {median:.2} ms, max {max:.2} ms{lost}",
        ms.len()
    ))
}

/// Steering of the sweep `t` seconds in: a triangle wave from full left to full right and
/// back every 2 s, per-mille.
pub fn sweep_steer(t: f64) -> i16 {
    let ph = (t / 2.0).fract();
    let steer = if ph < 0.5 { -1.0 + 4.0 * ph } else { 3.0 - 4.0 * ph };
    (steer * 1000.0) as i16
}

/// Arms, sweeps the steering servo ([`sweep_steer`], a DRIVE every 20 ms, throttle 0) for
/// `seconds`, then disarms.
pub fn sweep(link: &Link, seconds: f64, stopped: &dyn Fn() -> bool) -> Result<(), LinkError> {
    link.arm()?;
    let t0 = Instant::now();
    while !stopped() && t0.elapsed().as_secs_f64() < seconds {
        link.drive(sweep_steer(t0.elapsed().as_secs_f64()), 0);
        std::thread::sleep(Duration::from_millis(20));
    }
    link.disarm()
}

/// One line of the live telemetry: the `n`-th report `t`.
pub fn telemetry_line(t: &Telemetry, n: u64) -> String {
    format!(
        "#{n:<5} {:?} servo {} µs esc {} µs | crc {} framing {} overrun {} lost {} failsafe {} | up {:.1} s",
        t.state,
        t.servo_us,
        t.esc_us,
        t.crc_errors,
        t.framing_errors,
        t.overruns,
        t.lost_frames,
        t.failsafe_trips,
        f64::from(t.uptime_ms) / 1e3
    )
}

/// The firmware's telemetry for `seconds`: the newest report's [`telemetry_line`] to `each`
/// every 200 ms.
pub fn watch(link: &Link, seconds: f64, stopped: &dyn Fn() -> bool, each: &mut dyn FnMut(&str)) {
    let t0 = Instant::now();
    while !stopped() && t0.elapsed().as_secs_f64() < seconds {
        if let Some((t, n)) = link.telemetry() {
            each(&telemetry_line(&t, n));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_goes_from_full_left_to_full_right_and_back_every_2_s() {
        assert_eq!(sweep_steer(0.0), -1000);
        assert_eq!(sweep_steer(0.5), 0);
        assert_eq!(sweep_steer(1.0), 1000);
        assert_eq!(sweep_steer(1.5), 0);
        assert_eq!(sweep_steer(2.0), -1000);
    }

    #[test]
    fn the_latency_line_gives_the_median_the_maximum_and_the_unanswered() {
        let rt = |ms: &[f64], unanswered| RoundTrips { ms: ms.to_vec(), unanswered };
        assert_eq!(latency_line(&rt(&[], 0)), None);
        assert_eq!(
            latency_line(&rt(&[3.0, 1.0, 2.0], 0)).unwrap(),
            "round trip PING -> TELEMETRY over 3 pings: median 2.00 ms, max 3.00 ms"
        );
        assert_eq!(
            latency_line(&rt(&[3.0, 1.0, 2.0], 2)).unwrap(),
            "round trip PING -> TELEMETRY over 3 pings: median 2.00 ms, max 3.00 ms; 2 unanswered in time"
        );
        assert_eq!(latency_line(&rt(&[], 4)).unwrap(), "round trip PING -> TELEMETRY: no answer to 4 pings");
    }
}
