//! The `rccar` command: a thin layer over the library. `main` parses flags and turns errors
//! into exit codes; each subcommand's work lives in `cli/<name>.rs`.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Controller for educational autonomous RC cars.
#[derive(Parser)]
#[command(name = "rccar", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Check and print the configuration (config/car.toml plus overrides).
    #[command(subcommand)]
    Config(cli::config::ConfigCmd),
    /// Run the pipeline over a folder of recorded frames; write telemetry and annotated frames.
    Replay(cli::replay::ReplayArgs),
    /// Write each lane-pipeline stage of some images (bird's-eye, edges, binary, histogram).
    Stages(cli::stages::StagesArgs),
    /// Write synthetic lane frames with known line positions (the project's own test data).
    Synth(cli::synth::SynthArgs),
    /// Talk to the Arduino: handshake, live telemetry, servo sweep, trim, latency (needs the
    /// `serial` feature).
    Link(cli::link::LinkArgs),
    /// Run OpenCV Haar/LBP cascades on images; print boxes as JSON, write annotated images.
    Detect(cli::detect::DetectArgs),
    /// The car's main loop: camera (or the simulator, or a folder) → pipeline → serial link,
    /// on the wall clock (needs the `serial` feature for a port, `camera` for V4L2).
    Drive(cli::drive::DriveArgs),
    /// Drive the simulated car round a track with the pipeline in the loop; report and plot.
    Sim(cli::sim::SimArgs),
    /// Calibrate the car: `calibrate ranging PAIRS.csv` fits the camera tilt for ranging;
    /// `calibrate camera|stereo` calibrates cameras from checkerboard photos.
    #[command(subcommand)]
    Calibrate(cli::calibrate::CalibrateCmd),
    /// Range objects in a stereo pair: NCC along the rows, Eq. 16 / exact angles / b·f/d.
    Stereo(cli::stereo::StereoRangeArgs),
    /// Check a camera: list what is there, open one, report size, fps and latency, save a
    /// frame (`camera check`).
    #[command(subcommand)]
    Camera(cli::camera::CameraCmd),
    /// Plot telemetry fields of one or more runs against time (`--y error,steer`).
    Plot(cli::plot::PlotArgs),
    /// Write DIR/report.md and a self-contained DIR/report.html for a run's output folder.
    Report(cli::report::ReportArgs),
    /// Recordings as datasets: list label histograms, cut frame ranges, merge, and move data to
    /// and from Donkey Car's tub v2 (`data ls|cut|merge|export|import`, docs/data.md).
    #[command(subcommand)]
    Data(cli::data::DataCmd),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A vanished reader ends a filter quietly; the car's commands and a served dashboard
    // ignore it and go on to their own end (cli/signals.rs).
    match &cli.cmd {
        Cmd::Drive(_) | Cmd::Link(_) => {}
        Cmd::Sim(a) if a.dash.dashboard && a.sweep.is_empty() => {}
        _ => cli::signals::let_sigpipe_end_the_process(),
    }
    let result = match cli.cmd {
        Cmd::Config(c) => cli::config::run(c),
        Cmd::Replay(a) => cli::replay::run(a),
        Cmd::Synth(a) => cli::synth::run(a),
        Cmd::Stages(a) => cli::stages::run(a),
        Cmd::Link(a) => cli::link::run(a),
        Cmd::Detect(a) => cli::detect::run(a),
        Cmd::Sim(a) => cli::sim::run(a),
        Cmd::Drive(a) => cli::drive::run(a),
        Cmd::Calibrate(c) => cli::calibrate::run(c),
        Cmd::Stereo(a) => cli::stereo::run(a),
        Cmd::Camera(c) => cli::camera::run(c),
        Cmd::Plot(a) => cli::plot::run(a),
        Cmd::Report(a) => cli::report::run(a),
        Cmd::Data(c) => cli::data::run(c),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            cli::signals::say_err(&format!("error: {e:#}"));
            ExitCode::from(2)
        }
    }
}
