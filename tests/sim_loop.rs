//! The closed loop on the default track (issue 5's "must show"): clean laps, gains that
//! matter, and the lane measurement scored against ground truth.
//!
//! These runs use the shipped configuration. (It ships `steering.ki = 0`: with `ki = 0.1` the
//! integral of the look-ahead error winds up in every long curve and pulls the car ~5 cm to
//! the inside, RMS 15% of the lane with 8 departures in 3 laps; see docs/sim.md.)

use rccar::config::Config;
use rccar::sim::run::{EndReason, Simulation, StepOutput, Summary};
use rccar::sim::track::{Piece, Track};
use std::path::Path;

fn track() -> Track {
    Track::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tracks/default.toml")).unwrap()
}

fn cfg() -> Config {
    Config::default()
}

/// Runs `cfg` (optionally from `start` metres along the track) and keeps every step.
fn run(cfg: &Config, start: Option<f64>) -> (Summary, Vec<StepOutput>) {
    let mut sim = Simulation::new(cfg, &track()).unwrap();
    sim.set_full_frames(false);
    if let Some(s) = start {
        sim.place_at(s);
    }
    let mut steps = Vec::new();
    let summary = sim
        .run(|_, s| {
            steps.push(s.clone());
            Ok::<(), ()>(())
        })
        .unwrap();
    (summary, steps)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

#[test]
fn three_clean_laps_within_five_percent_of_the_lane() {
    let cfg = cfg().with_override("sim.laps=3").unwrap();
    let (s, _) = run(&cfg, None);
    eprintln!("{s:?}");
    assert_eq!(s.end, EndReason::LapsDone, "{s:?}");
    assert!(s.laps >= 3 && s.lane_departures == 0, "{s:?}");
    assert!(s.xte_rms_m <= 0.05 * s.lane_width_m, "RMS {} m", s.xte_rms_m);
    assert_eq!(s.lane_lost_frames, 0);
}

/// Issue 25, must-show 3: the second steering method (pure pursuit of a look-ahead point on
/// the lane, src/control/pure_pursuit.rs) drives the same 3 laps cleanly. Measured with the
/// shipped look-ahead (0.9 m): cross-track RMS 0.0138 m (PID: 0.0081 m; pure pursuit cuts
/// the curves by design) and steering chatter 0.0060 steer units per frame (PID: 0.0124);
/// docs/labs/13-pure-pursuit.md. Bounds: RMS ≤ 0.018 m (6% of the lane), chatter ≤ 0.009.
#[test]
fn pure_pursuit_drives_three_clean_laps() {
    let cfg = cfg()
        .with_override("sim.laps=3")
        .unwrap()
        .with_override("steering.method=pure_pursuit")
        .unwrap();
    let (s, steps) = run(&cfg, None);
    let mut chatter = rccar::sim::sweep::Chatter::default();
    steps.iter().for_each(|st| chatter.push(st.out.command.steer));
    eprintln!("pure pursuit: {s:?}, chatter {:.5}", chatter.rms());
    assert_eq!(s.end, EndReason::LapsDone, "{s:?}");
    assert!(s.laps >= 3 && s.lane_departures == 0, "{s:?}");
    assert_eq!(s.lane_lost_frames, 0);
    assert!(s.xte_rms_m <= 0.018, "RMS {} m", s.xte_rms_m);
    assert!(chatter.rms() <= 0.009, "chatter {}", chatter.rms());
}

#[test]
fn lane_centre_matches_ground_truth_over_a_lap() {
    let cfg = cfg().with_override("sim.laps=1").unwrap();
    let (s, steps) = run(&cfg, None);
    assert_eq!(s.laps, 1);
    // L_c against the ideal detector's L_c (histogram peaks of the painted lines).
    let d: Vec<f64> = steps
        .iter()
        .filter_map(|st| Some((st.out.lane.lane_center? - st.truth.center_col_hist?).abs()))
        .collect();
    assert!(
        d.len() as f64 >= 0.95 * steps.len() as f64,
        "{} of {}",
        d.len(),
        steps.len()
    );
    let m = median(d.clone());
    eprintln!(
        "median |L_c - truth| = {m:.3} px over {} frames, max {:.2}",
        d.len(),
        d.iter().fold(0.0f64, |a, b| a.max(*b))
    );
    assert!(m <= 1.0, "median {m} px");
    // On straights the geometric truth (mean column over the band) agrees as closely.
    let straight: Vec<f64> = steps
        .iter()
        .filter(|st| {
            let p = track().project([st.truth.pose[0], st.truth.pose[1]]);
            p.curvature == 0.0 && st.truth.heading_error_rad.abs() < 0.01
        })
        .filter_map(|st| Some((st.out.lane.lane_center? - st.truth.center_col?).abs()))
        .collect();
    assert!(straight.len() > 300, "{}", straight.len());
    assert!(median(straight) <= 0.5);
}

/// Much too high a gain: the car weaves (more steering reversals) and the error grows.
#[test]
fn much_too_high_kp_oscillates() {
    let base = cfg().with_override("sim.max_seconds=60").unwrap();
    let (good, _) = run(&base, None);
    let (high, _) = run(&base.with_override("steering.kp=6").unwrap(), None);
    eprintln!("kp 1: {good:?}\nkp 6: {high:?}");
    assert!(
        high.xte_rms_m > 2.0 * good.xte_rms_m,
        "{} vs {}",
        high.xte_rms_m,
        good.xte_rms_m
    );
    // With the derivative low-pass (steering.derivative_tau 0.2 s) the weave is slow and wide
    // rather than fast: at kp 6 it swings out of the lane every ~5.5 m (4 departures in 60 s,
    // 0.033 reversals/s against 0.017 at kp 1 with the shipped adaptive threshold, 0.067 with
    // the fixed level); with tau 0.05 it was faster and narrower.
    assert!(high.lane_departures >= 2, "kp 6 departures: {}", high.lane_departures);
    assert_eq!(good.lane_departures, 0);
    assert!(
        high.steer_reversals_per_s >= 2.0 * good.steer_reversals_per_s && high.steer_reversals_per_s > 0.02,
        "{} vs {}",
        high.steer_reversals_per_s,
        good.steer_reversals_per_s
    );
}

/// Much too low a gain: starting on the straight before the tightest curve, the car runs
/// wide and leaves the lane in that curve; the shipped gain takes it cleanly.
#[test]
fn much_too_low_kp_departs_on_the_tightest_curve() {
    let t = track();
    // The tightest arc of the driven lane, and the straight before it.
    let (k, _) = t
        .pieces
        .iter()
        .enumerate()
        .filter_map(|(i, p)| match *p {
            Piece::Arc { radius, sweep, .. } => Some((i, radius - sweep.signum() * t.drive_offset)),
            _ => None,
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    let (s0, s1) = (t.piece_s0[k], t.piece_s0[k] + t.pieces[k].length());
    let start = t.piece_s0[k - 1] + 0.1;
    let base = cfg().with_override("sim.max_seconds=30").unwrap();
    let (low, _) = run(&base.with_override("steering.kp=0.3").unwrap(), Some(start));
    eprintln!("kp 0.3: {low:?}, tightest curve {s0:.2}..{s1:.2} m");
    let first = *low.departures_at_m.first().expect("kp 0.3 should leave the lane");
    assert!(
        first > s0 && first < s1,
        "departed at {first} m, not in the curve {s0}..{s1}"
    );
    let (ok, _) = run(&base, Some(start));
    assert_eq!(ok.lane_departures, 0, "{ok:?}");
}

#[test]
fn same_seed_same_run_other_seed_other_noise() {
    let c = cfg().with_override("sim.max_seconds=3").unwrap();
    let (_, a) = run(&c, None);
    let (_, b) = run(&c, None);
    let ra: Vec<String> = a.iter().map(|s| s.record("f").to_json_line()).collect();
    let rb: Vec<String> = b.iter().map(|s| s.record("f").to_json_line()).collect();
    assert_eq!(ra, rb);
    let (_, d) = run(&c.with_override("sim.seed=2").unwrap(), None);
    let rd: Vec<String> = d.iter().map(|s| s.record("f").to_json_line()).collect();
    assert_ne!(ra, rd);
}
