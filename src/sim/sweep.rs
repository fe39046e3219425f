//! Gain sweeps over one or two configuration keys (`rccar sim --sweep KEY=LO:HI:N`, given
//! once for a line, twice for a grid): parsing an axis, the grid of runs, the chatter
//! measure of a run's steering, the runs themselves ([`run_all`]: [`super::run::Simulation`]s
//! on a few threads) and the CSV table.
//!
//! A sweep can be stopped (Ctrl-C): a run that had not started is [`RunOutcome::NotRun`] and
//! gets no row (its figures would be zeros, the best-looking row of the table); a run cut
//! short keeps its row with end `interrupted`, its figures covering what it drove.
//!
//! Units: whatever the swept key's unit is ([`key_unit`]); metres and seconds for the scores.

use super::run::{EndReason, Simulation, Summary};
use super::scene::Scene;
use crate::config::Config;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// A `--sweep` that cannot be understood.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SweepError {
    /// Not of the form `KEY=LO:HI:N`.
    #[error("--sweep `{0}`: expected KEY=LO:HI:N, e.g. steering.kp=0.2:2.0:10")]
    Form(String),
    /// LO or HI is not a finite number.
    #[error("--sweep `{arg}`: {what} `{text}` is not a finite number")]
    Number {
        /// The whole argument.
        arg: String,
        /// "LO" or "HI".
        what: &'static str,
        /// What was typed.
        text: String,
    },
    /// N is not a count in 1..=1000.
    #[error("--sweep `{arg}`: N must be 1..=1000 (got `{text}`)")]
    Count {
        /// The whole argument.
        arg: String,
        /// What was typed.
        text: String,
    },
    /// More than two axes, or the same key twice.
    #[error("--sweep: {0}")]
    Axes(String),
    /// The grid would be too large.
    #[error("--sweep: {0} runs; a sweep may have at most 1000")]
    TooMany(usize),
    /// A parameter of another steering method than the run's: it would change nothing (every
    /// row the same).
    #[error("--sweep {key}: {why}")]
    OtherMethod {
        /// The key.
        key: String,
        /// Which method it belongs to and how to steer with it
        /// ([`crate::control::catalog::unused_by`]).
        why: String,
    },
    /// A value of the grid the configuration refuses (its message, with its causes).
    #[error("--sweep {key}={value}: {message}")]
    Value {
        /// The key.
        key: String,
        /// The value.
        value: f64,
        /// Why the configuration refuses it.
        message: String,
    },
}

/// One swept key and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Dotted config key, e.g. `steering.kp`.
    pub key: String,
    /// The values, LO to HI evenly spaced (N of them; N = 1 gives LO).
    pub values: Vec<f64>,
}

/// Parses `KEY=LO:HI:N`.
pub fn parse_axis(s: &str) -> Result<Axis, SweepError> {
    let form = || SweepError::Form(s.to_string());
    let (key, range) = s.split_once('=').ok_or_else(form)?;
    let key = key.trim();
    if key.is_empty() {
        return Err(form());
    }
    let parts: Vec<&str> = range.split(':').collect();
    let [lo, hi, n] = parts[..] else {
        return Err(form());
    };
    let num = |text: &str, what| {
        text.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| SweepError::Number {
                arg: s.to_string(),
                what,
                text: text.to_string(),
            })
    };
    let (lo, hi) = (num(lo, "LO")?, num(hi, "HI")?);
    let n: usize = n
        .trim()
        .parse()
        .ok()
        .filter(|n| (1..=1000).contains(n))
        .ok_or_else(|| SweepError::Count {
            arg: s.to_string(),
            text: n.to_string(),
        })?;
    let values = (0..n)
        .map(|i| if n == 1 { lo } else { lo + (hi - lo) * i as f64 / (n - 1) as f64 })
        .collect();
    Ok(Axis {
        key: key.to_string(),
        values,
    })
}

/// Parses one or two `--sweep` arguments and checks the grid's size (at most 1000 runs).
pub fn parse_axes(args: &[String]) -> Result<Vec<Axis>, SweepError> {
    if args.is_empty() || args.len() > 2 {
        return Err(SweepError::Axes(format!(
            "give it once (a line) or twice (a grid), not {} times",
            args.len()
        )));
    }
    let axes: Vec<Axis> = args.iter().map(|a| parse_axis(a)).collect::<Result<_, _>>()?;
    if axes.len() == 2 && axes[0].key == axes[1].key {
        return Err(SweepError::Axes(format!("`{}` is swept twice", axes[0].key)));
    }
    let runs: usize = axes.iter().map(|a| a.values.len()).product();
    if runs > 1000 {
        return Err(SweepError::TooMany(runs));
    }
    Ok(axes)
}

/// The runs of a sweep: every combination of the axes' values, the last axis varying fastest
/// (row-major: for a grid, all of the second key's values for the first key's first value,
/// and so on).
pub fn grid(axes: &[Axis]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new()];
    for a in axes {
        out = out
            .iter()
            .flat_map(|p| {
                a.values.iter().map(move |&v| {
                    let mut q = p.clone();
                    q.push(v);
                    q
                })
            })
            .collect();
    }
    out
}

/// The unit of a config key for axis labels: a tunable parameter's from its table
/// ([`crate::control::params`]), else from its name's suffix (`_m`, `_s`, `_deg`, …). Empty
/// when unitless or unknown.
pub fn key_unit(key: &str) -> &'static str {
    if let Some(p) = crate::control::catalog::find(key) {
        return p.unit;
    }
    let last = key.rsplit('.').next().unwrap_or(key);
    for (suffix, unit) in [
        ("_mps", "m/s"),
        ("_dps", "deg/s"),
        ("_deg", "deg"),
        ("_px", "px"),
        ("_ms", "ms"),
        ("_m", "m"),
        ("_s", "s"),
    ] {
        if last.ends_with(suffix) {
            return unit;
        }
    }
    ""
}

/// An axis label: `steering.kd (steer per error/s)`, or the key alone.
pub fn axis_label(key: &str) -> String {
    match key_unit(key) {
        "" => key.to_string(),
        u => format!("{key} ({u})"),
    }
}

/// Running chatter measure of a steering command: RMS of its frame-to-frame change
/// (steer units per frame). Frame-rate chatter raises it; a smooth command that follows the
/// road keeps it small.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Chatter {
    last: Option<f64>,
    sq: f64,
    n: u64,
}

impl Chatter {
    /// Adds the next frame's steering command.
    pub fn push(&mut self, steer: f64) {
        if let Some(l) = self.last {
            let d = steer - l;
            self.sq += d * d;
            self.n += 1;
        }
        self.last = Some(steer);
    }

    /// RMS of the first difference so far (0 with fewer than two frames).
    pub fn rms(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            (self.sq / self.n as f64).sqrt()
        }
    }
}

/// One finished run of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRun {
    /// The swept keys' values, in axis order.
    pub values: Vec<f64>,
    /// The run's score.
    pub summary: Summary,
    /// RMS of the steering command's frame-to-frame change ([`Chatter`]).
    pub steer_diff_rms: f64,
}

impl SweepRun {
    /// The run left its lane (a departure) or ended off the road or stalled.
    pub fn left_lane(&self) -> bool {
        self.summary.lane_departures > 0 || matches!(self.summary.end, EndReason::LeftTheRoad | EndReason::Stalled)
    }

    /// Mean lap time, seconds (`None` without a completed lap).
    pub fn lap_time_s(&self) -> Option<f64> {
        let l = &self.summary.lap_times_s;
        (!l.is_empty()).then(|| l.iter().sum::<f64>() / l.len() as f64)
    }
}

/// How one run of a sweep went.
#[derive(Debug, Clone, PartialEq)]
pub enum RunOutcome {
    /// Ran to its end.
    Finished(SweepRun),
    /// Stopped part-way by the stop request: its summary ends `interrupted` and covers what
    /// ran.
    Interrupted(SweepRun),
    /// Never started: the stop request came first.
    NotRun,
    /// Could not run: the simulation could not be built, or it panicked (the message).
    Failed(String),
}

impl RunOutcome {
    /// The run's figures, when it ran at all.
    pub fn run(&self) -> Option<&SweepRun> {
        match self {
            RunOutcome::Finished(r) | RunOutcome::Interrupted(r) => Some(r),
            _ => None,
        }
    }
}

/// Runs `cfgs` (one per point of the sweep, `points[i]` its swept values) on `jobs` threads
/// over one shared scene. `stop` is asked before each run starts and after every frame: once
/// it says yes, running runs end at their next frame (interrupted) and no new run starts.
/// `done(i, outcome)` is called from the worker as each run ends, in the order they end
/// (progress lines). Returns the outcomes in the order of `cfgs`.
pub fn run_all(
    cfgs: &[Config],
    points: &[Vec<f64>],
    scene: Arc<Scene>,
    jobs: usize,
    stop: &(dyn Fn() -> bool + Sync),
    done: &(dyn Fn(usize, &RunOutcome) + Sync),
) -> Vec<RunOutcome> {
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<RunOutcome>> = cfgs.iter().map(|_| Mutex::new(RunOutcome::NotRun)).collect();
    let one = |i: usize| -> RunOutcome {
        let mut sim = match Simulation::with_scene(&cfgs[i], scene.clone()) {
            Ok(s) => s,
            Err(e) => return RunOutcome::Failed(e.to_string()),
        };
        sim.set_full_frames(false);
        let mut chatter = Chatter::default();
        let r = sim.run(|_, st| {
            chatter.push(st.out.command.steer);
            if stop() {
                Err(())
            } else {
                Ok(())
            }
        });
        let values = points.get(i).cloned().unwrap_or_default();
        match r {
            Ok(summary) => RunOutcome::Finished(SweepRun {
                values,
                summary,
                steer_diff_rms: chatter.rms(),
            }),
            Err(()) => {
                super::world::lock(sim.world()).interrupt();
                RunOutcome::Interrupted(SweepRun {
                    values,
                    summary: sim.summary(),
                    steer_diff_rms: chatter.rms(),
                })
            }
        }
    };
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, cfgs.len().max(1)) {
            s.spawn(|| loop {
                if stop() {
                    break;
                }
                let i = next.fetch_add(1, Ordering::SeqCst);
                if i >= cfgs.len() {
                    break;
                }
                let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| one(i))).unwrap_or_else(|p| {
                    let msg = p
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| p.downcast_ref::<String>().cloned())
                        .unwrap_or_default();
                    RunOutcome::Failed(format!("the run panicked: {msg}"))
                });
                done(i, &out);
                *results[i].lock().unwrap_or_else(|e| e.into_inner()) = out;
            });
        }
    });
    results
        .into_iter()
        .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()))
        .collect()
}

/// The configuration of every point of the grid (`keys` set to the point's values), each
/// checked before any run starts; a key of another steering method than `cfg`'s is refused.
pub fn configs(cfg: &Config, keys: &[&str], points: &[Vec<f64>]) -> Result<Vec<Config>, SweepError> {
    // A parameter of another steering method would change nothing: every row the same.
    for k in keys {
        if let Some(why) = crate::control::catalog::unused_by(cfg.steering.method, k) {
            return Err(SweepError::OtherMethod {
                key: k.to_string(),
                why,
            });
        }
    }
    points
        .iter()
        .map(|p| {
            let mut c = cfg.clone();
            for (k, v) in keys.iter().zip(p) {
                c = c.with_override(&format!("{k}={v}")).map_err(|e| {
                    let mut message = e.to_string();
                    let mut src = std::error::Error::source(&e);
                    while let Some(s) = src {
                        message += &format!(": {s}");
                        src = s.source();
                    }
                    SweepError::Value {
                        key: k.to_string(),
                        value: *v,
                        message,
                    }
                })?;
            }
            Ok(c)
        })
        .collect()
}

/// A point of the grid as `key=value` words.
pub fn label(keys: &[&str], p: &[f64]) -> String {
    keys.iter()
        .zip(p)
        .map(|(k, v)| format!("{k}={v:.4}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// After a stop request: how many of the runs at `points` finished, were cut short (their
/// rows end `interrupted`) and never started (no row; named by their points), as one line.
pub fn interrupted_line(keys: &[&str], points: &[Vec<f64>], outcomes: &[RunOutcome]) -> String {
    let count = |f: fn(&RunOutcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    let finished = count(|o| matches!(o, RunOutcome::Finished(_)));
    let cut = count(|o| matches!(o, RunOutcome::Interrupted(_)));
    let not_run: Vec<String> = points
        .iter()
        .zip(outcomes)
        .filter(|(_, o)| **o == RunOutcome::NotRun)
        .map(|(p, _)| label(keys, p))
        .collect();
    format!(
        "sweep: interrupted; {finished} of {} run(s) finished, {cut} cut short (rows ending `interrupted`), {} not run (no row): {}",
        points.len(),
        not_run.len(),
        if not_run.is_empty() { "-".to_string() } else { not_run.join(", ") }
    )
}

/// The end reason as in sweep.csv (`time_up`, `interrupted`, …).
pub fn end_name(s: &Summary) -> String {
    serde_json::to_value(s.end)
        .ok()
        .and_then(|v| v.as_str().map(String::from))
        .unwrap_or_default()
}

/// How a run ended, in a few words (the progress line).
pub fn outcome_words(o: &RunOutcome) -> String {
    match o {
        RunOutcome::Finished(r) => format!(
            "laps {}, RMS {:.4} m, max {:.4} m, departures {}, {}",
            r.summary.laps,
            r.summary.xte_rms_m,
            r.summary.xte_max_m,
            r.summary.lane_departures,
            end_name(&r.summary)
        ),
        RunOutcome::Interrupted(r) => format!("interrupted after {:.1} s simulated", r.summary.seconds),
        RunOutcome::Failed(e) => format!("error: {e}"),
        RunOutcome::NotRun => "not run".into(),
    }
}

/// The printed table's head: the swept keys, then the figures.
pub fn table_head(keys: &[&str]) -> String {
    let head: Vec<String> = keys.iter().map(|k| format!("{k:>12}")).collect();
    format!(
        "{} {:>5} {:>10} {:>10} {:>6} {:>10} {:>9} {:>8}  end",
        head.join(" "),
        "laps",
        "rms_m",
        "max_m",
        "dep",
        "rev/s",
        "dsteer",
        "lost"
    )
}

/// The printed table's row of the run at point `p`.
pub fn table_row(p: &[f64], o: &RunOutcome) -> String {
    let vals: Vec<String> = p.iter().map(|v| format!("{v:>12.4}")).collect();
    let vals = vals.join(" ");
    match o {
        RunOutcome::Finished(r) | RunOutcome::Interrupted(r) => {
            let s = &r.summary;
            format!(
                "{vals} {:>5} {:>10.4} {:>10.4} {:>6} {:>10.2} {:>9.4} {:>8}  {:?}",
                s.laps,
                s.xte_rms_m,
                s.xte_max_m,
                s.lane_departures,
                s.steer_reversals_per_s,
                r.steer_diff_rms,
                s.lane_lost_frames,
                s.end
            )
        }
        RunOutcome::Failed(e) => format!("{vals} error: {e}"),
        RunOutcome::NotRun => format!("{vals} not run"),
    }
}

/// The sweep's table: a header naming the swept keys, then one row per run that ran (a run
/// cut short ends `interrupted`; a run that never started has no row).
pub fn csv_outcomes(keys: &[&str], outcomes: &[RunOutcome]) -> String {
    let runs: Vec<SweepRun> = outcomes.iter().filter_map(|o| o.run().cloned()).collect();
    csv(keys, &runs)
}

/// The sweep's table: a header naming the swept keys, then one row per run.
pub fn csv(keys: &[&str], runs: &[SweepRun]) -> String {
    let mut s = keys.join(",");
    s += ",laps,lap_time_s,xte_rms_m,xte_max_m,departures,reversals_per_s,steer_diff_rms,lost_frames,end\n";
    for r in runs {
        let m = &r.summary;
        let vals: Vec<String> = r.values.iter().map(|v| format!("{v}")).collect();
        s += &format!(
            "{},{},{},{},{},{},{},{},{},{}\n",
            vals.join(","),
            m.laps,
            r.lap_time_s().map_or(String::new(), |t| format!("{t}")),
            m.xte_rms_m,
            m.xte_max_m,
            m.lane_departures,
            m.steer_reversals_per_s,
            r.steer_diff_rms,
            m.lane_lost_frames,
            serde_json::to_value(m.end).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_values_are_evenly_spaced() {
        let a = parse_axis("steering.kp=0.2:2.0:10").unwrap();
        assert_eq!(a.key, "steering.kp");
        assert_eq!(a.values.len(), 10);
        assert!((a.values[0] - 0.2).abs() < 1e-12 && (a.values[9] - 2.0).abs() < 1e-12);
        assert!((a.values[1] - 0.4).abs() < 1e-12);
        assert_eq!(parse_axis(" steering.kd = 0.5:1:1").unwrap().values, vec![0.5]);
        // Descending ranges are allowed.
        assert_eq!(parse_axis("a=1:0:3").unwrap().values, vec![1.0, 0.5, 0.0]);
    }

    #[test]
    fn bad_axes_name_what_is_wrong() {
        assert_eq!(parse_axis("steering.kp"), Err(SweepError::Form("steering.kp".into())));
        assert_eq!(parse_axis("k=1:2"), Err(SweepError::Form("k=1:2".into())));
        assert_eq!(parse_axis("=1:2:3"), Err(SweepError::Form("=1:2:3".into())));
        let e = parse_axis("k=x:2:3").unwrap_err().to_string();
        assert!(e.contains("LO `x`"), "{e}");
        let e = parse_axis("k=1:inf:3").unwrap_err().to_string();
        assert!(e.contains("HI `inf`"), "{e}");
        assert!(matches!(parse_axis("k=1:2:0"), Err(SweepError::Count { .. })));
        assert!(matches!(parse_axis("k=1:2:1001"), Err(SweepError::Count { .. })));
        assert!(matches!(parse_axis("k=1:2:-1"), Err(SweepError::Count { .. })));
    }

    #[test]
    fn a_grid_is_every_pair_last_axis_fastest() {
        let axes = parse_axes(&["a=1:2:2".into(), "b=10:30:3".into()]).unwrap();
        let g = grid(&axes);
        assert_eq!(g.len(), 6);
        assert_eq!(g[0], vec![1.0, 10.0]);
        assert_eq!(g[1], vec![1.0, 20.0]);
        assert_eq!(g[3], vec![2.0, 10.0]);
        assert_eq!(g[5], vec![2.0, 30.0]);
        assert_eq!(grid(&axes[..1]), vec![vec![1.0], vec![2.0]]);
        assert!(matches!(parse_axes(&["a=1:2:2".into(), "a=1:2:2".into()]), Err(SweepError::Axes(_))));
        assert!(matches!(parse_axes(&["a=1:2:100".into(), "b=1:2:11".into()]), Err(SweepError::TooMany(1100))));
        assert!(matches!(parse_axes(&[]), Err(SweepError::Axes(_))));
        let three: Vec<String> = vec!["a=1:2:2".into(), "b=1:2:2".into(), "c=1:2:2".into()];
        assert!(matches!(parse_axes(&three), Err(SweepError::Axes(_))));
    }

    #[test]
    fn units_from_names() {
        assert_eq!(axis_label("steering.kd"), "steering.kd (steer per error/s)");
        assert_eq!(axis_label("vehicle.servo_delay_s"), "vehicle.servo_delay_s (s)");
        assert_eq!(axis_label("vehicle.max_speed_mps"), "vehicle.max_speed_mps (m/s)");
        assert_eq!(axis_label("vehicle.wheelbase_m"), "vehicle.wheelbase_m (m)");
        assert_eq!(axis_label("lane.min_peak"), "lane.min_peak");
    }

    #[test]
    fn a_stopped_sweep_has_no_rows_for_runs_that_never_started() {
        use crate::sim::track::Track;
        let track = Track::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/tracks/default.toml"
        )))
        .unwrap();
        let scene = Arc::new(Scene::new(&track));
        let mut base = Config::default();
        base.detect.enabled = false;
        base.sim.laps = 0;
        base.sim.max_seconds = 2.0;
        let axes = parse_axes(&["steering.kp=0.5:2:6".into()]).unwrap();
        let points = grid(&axes);
        let cfgs: Vec<Config> = points
            .iter()
            .map(|p| base.with_override(&format!("steering.kp={}", p[0])).unwrap())
            .collect();
        // One thread: stop() is asked once before each run and once per frame, so answering
        // yes from its 67th call on lets run 0 finish (calls 1..61) and cuts run 1 after 5
        // frames (calls 62..66); runs 2.. never start.
        let calls = AtomicUsize::new(0);
        let order = Mutex::new(Vec::new());
        let out = run_all(
            &cfgs,
            &points,
            scene.clone(),
            1,
            &|| calls.fetch_add(1, Ordering::SeqCst) >= 66,
            &|i, o| order.lock().unwrap().push((i, matches!(o, RunOutcome::Finished(_)))),
        );
        assert_eq!(
            *order.lock().unwrap(),
            [(0, true), (1, false)],
            "progress as the runs ended"
        );
        let RunOutcome::Finished(first) = &out[0] else {
            panic!("{:?}", out[0])
        };
        assert_eq!(first.summary.frames, 60);
        assert_eq!(first.summary.end, EndReason::TimeUp);
        let RunOutcome::Interrupted(cut) = &out[1] else {
            panic!("{:?}", out[1])
        };
        assert_eq!(cut.summary.end, EndReason::Interrupted);
        assert_eq!(cut.summary.frames, 5);
        assert!(out[2..].iter().all(|o| *o == RunOutcome::NotRun), "{out:?}");
        let table = csv_outcomes(&["steering.kp"], &out);
        let rows: Vec<&str> = table.lines().skip(1).collect();
        assert_eq!(rows.len(), 2, "{table}");
        assert!(
            rows[0].starts_with("0.5,0,,") && rows[0].ends_with(",time_up"),
            "{table}"
        );
        assert!(rows[1].ends_with(",interrupted"), "{table}");
        // Not stopped: every run, in order, the same figures as run alone.
        let all = run_all(&cfgs[..2], &points[..2], scene, 2, &|| false, &|_, _| {});
        assert_eq!(all[0], out[0]);
        assert!(matches!(&all[1], RunOutcome::Finished(r) if r.values == [0.8]));
    }

    #[test]
    fn chatter_is_the_rms_of_the_first_difference() {
        let mut c = Chatter::default();
        assert_eq!(c.rms(), 0.0);
        for s in [0.0, 0.1, 0.0, 0.1, 0.0] {
            c.push(s);
        }
        assert!((c.rms() - 0.1).abs() < 1e-12);
        let mut c = Chatter::default();
        for i in 0..10 {
            c.push(0.01 * i as f64);
        }
        assert!((c.rms() - 0.01).abs() < 1e-12);
    }
}
