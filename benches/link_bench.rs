//! Link bench on the emulated Uno (simavr, real firmware, real serial transport):
//! 1. 1,000 DRIVEs at 100 Hz: no drops (every one written, accepted by the firmware, none lost)
//!    and the latency DRIVE delivered to the UART → new pulse width on D9, in simulated time;
//! 2. 1,000 PINGs: round trip over the pty (write → TELEMETRY decoded), wall time.
//!
//! Prints median and max. Run: `cargo bench --features serial --bench link_bench`.

#[path = "../tests/support/sim.rs"]
mod sim;

use rccar::link::protocol::{self, id};
use rccar::link::transport::{Link, LinkOptions};
use sim::{Event, Sim};
use std::time::{Duration, Instant};

fn stats(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[v.len() - 1])
}

fn main() {
    const N: usize = 1000;
    let sim = Sim::start("bench");
    let link = Link::open(&sim.tty, LinkOptions::default());
    link.wait_connected(Duration::from_secs(5)).expect("handshake");
    link.arm().expect("arm");
    let before = link.ping().expect("ping").0;
    let rx_before = sim.events().len();

    // 1. 100 Hz, distinct steering values so each can be found on the pin
    let steer = |i: usize| ((i * 389) % 1801) as i16 - 900;
    let t0 = Instant::now();
    for i in 0..N {
        link.drive(steer(i), 0);
        let next = t0 + Duration::from_micros(10_000 * (i as u64 + 1));
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let rate = N as f64 / t0.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(60));
    let after = link.ping().expect("ping").0;
    let st = link.stats();
    let accepted = after.rx_frames - before.rx_frames - 1;
    let lost = after.lost_frames.wrapping_sub(before.lost_frames);
    println!(
        "sustained: {N} DRIVEs at {rate:.1} Hz: {} written, {} superseded on the host, {accepted} accepted by the \
         firmware, {lost} lost, {} crc / {} framing errors, {} overruns",
        st.drives_sent, st.drives_superseded, after.crc_errors, after.framing_errors, after.overruns
    );
    let ok = st.drives_superseded == 0 && accepted as usize == N && lost == 0;
    println!(
        "no drops at >= 100 Hz: {}",
        if ok && rate >= 99.0 { "yes" } else { "NO" }
    );

    // DRIVE at the UART -> first pulse of the new width (PWM runs at 50 Hz, so at 100 Hz about
    // half the commands are replaced by the next one before a period starts: those are skipped)
    let ev = &sim.events()[rx_before..];
    let rx: Vec<f64> = ev
        .iter()
        .filter_map(|e| match e {
            Event::Rx { id: i, t_us, .. } if *i == id::DRIVE => Some(*t_us),
            _ => None,
        })
        .collect();
    let pulses: Vec<(f64, f64)> = ev
        .iter()
        .filter_map(|e| match e {
            Event::Pulse {
                servo: true,
                width_us,
                t_us,
            } => Some((*width_us, *t_us)),
            _ => None,
        })
        .collect();
    let mut lat = Vec::new();
    for (i, &t) in rx.iter().enumerate().take(N) {
        let want = f64::from(protocol::permille_to_us(steer(i), 1000, 1500, 2000)) + 0.5;
        let end = rx.get(i + 1).copied().unwrap_or(f64::INFINITY);
        if let Some(p) = pulses.iter().find(|p| p.1 >= t && (p.0 - want).abs() < 0.3) {
            if p.1 < end + 20_000.0 {
                lat.push((p.1 - t) / 1000.0);
            }
        }
    }
    let (med, max) = stats(lat.clone());
    println!(
        "DRIVE at UART -> pulse width changed (simulated time): median {med:.2} ms, max {max:.2} ms over {} commands \
         that reached the pin ({} DRIVEs seen at the UART)",
        lat.len(),
        rx.len()
    );

    // 2. round trip over the pty
    let mut rtt = Vec::with_capacity(N);
    for _ in 0..N {
        rtt.push(link.ping().expect("ping").1.as_secs_f64() * 1e3);
    }
    let (med, max) = stats(rtt);
    println!("PING -> TELEMETRY round trip over the pty (wall time): median {med:.2} ms, max {max:.2} ms over {N}");
}
