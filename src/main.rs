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
    /// Run OpenCV Haar/LBP cascades on images; print boxes as JSON, write annotated images.
    Detect(cli::detect::DetectArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Config(c) => cli::config::run(c),
        Cmd::Detect(a) => cli::detect::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
