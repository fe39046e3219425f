//! `rccar sim --sweep KEY=LO:HI:N` (given twice: a grid): every value checked first, the runs
//! on `--jobs` threads ([`rccar::sim::sweep::run_all`]), one progress line as each run ends,
//! then the table, sweep.csv and the plot in the run folder. Ctrl-C ends the running runs at
//! their next frame (rows marked `interrupted`), starts no new one, writes no row for a run
//! that never started, and says which ran.

use super::outdir;
use anyhow::Result;
use rccar::config::Config;
use rccar::run_dir::{RunDir, RunState};
use rccar::sim::plot;
use rccar::sim::run::Summary;
use rccar::sim::scene::Scene;
use rccar::sim::sweep;
use rccar::sim::track::Track;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

/// Runs the sweep `args` (the `--sweep` values) over `cfg` on `track` into `run`.
pub fn run_sweep(
    args: &[String],
    jobs: Option<usize>,
    cfg: &Config,
    track: &Track,
    font: Option<&'static [u8]>,
    mut run: RunDir,
) -> Result<ExitCode> {
    let axes = sweep::parse_axes(args)?;
    let keys: Vec<&str> = axes.iter().map(|x| x.key.as_str()).collect();
    let points = sweep::grid(&axes);
    // Check every value before spending minutes.
    let cfgs = sweep::configs(cfg, &keys, &points)?;
    let scene = Arc::new(Scene::new(track));
    let jobs = jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, 256);
    let n = cfgs.len();
    println!(
        "sweep {} over {} run(s) on {} thread(s), track {}",
        keys.join(" × "),
        n,
        jobs,
        track.name
    );
    let stop = super::signals::install();
    outdir::started(&mut run);
    let t0 = Instant::now();
    let ended = std::sync::atomic::AtomicUsize::new(0);
    let outcomes = sweep::run_all(&cfgs, &points, scene, jobs, &|| stop.is_set(), &|i, o| {
        let k = ended.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        println!(
            "  [{k}/{n}] {}  {}  ({:.1} s)",
            sweep::label(&keys, &points[i]),
            sweep::outcome_words(o),
            t0.elapsed().as_secs_f64()
        );
    });
    println!("{}", sweep::table_head(&keys));
    for (p, o) in points.iter().zip(&outcomes) {
        println!("{}", sweep::table_row(p, o));
    }
    let csv_path = run.write("sweep.csv", sweep::csv_outcomes(&keys, &outcomes).as_bytes())?;
    if let Some(why) = stop.reason() {
        println!("{}", sweep::interrupted_line(&keys, &points, &outcomes));
        println!("  table: {}", csv_path.display());
        outdir::finish(&mut run, RunState::from_stop(Some(why)), None)?;
        return Ok(ExitCode::from(why.exit_code()));
    }
    println!("  table: {}", csv_path.display());
    let runs: Vec<sweep::SweepRun> = outcomes.iter().filter_map(|o| o.run().cloned()).collect();
    if let Some(font) = font {
        plot::register_font(font);
        if axes.len() == 1 {
            let rows: Vec<(f64, Summary)> = runs.iter().map(|r| (r.values[0], r.summary.clone())).collect();
            let p = run.write_png("sweep.png", &plot::sweep_plot(keys[0], &rows)?)?;
            println!("  plot:  {}", p.display());
        } else {
            let img = plot::grid_plot(keys[0], keys[1], &axes[0].values, &axes[1].values, &runs)?;
            let p = run.write_png("sweep_grid.png", &img)?;
            println!("  heat map: {}", p.display());
        }
    }
    outdir::finish(&mut run, RunState::Finished, None)?;
    Ok(ExitCode::SUCCESS)
}
