//! Flags shared by every subcommand that needs the car's configuration.

use anyhow::Result;
use clap::Args;
use rccar::config::Config;
use std::path::PathBuf;

/// Where the configuration comes from.
#[derive(Args, Debug, Clone)]
pub struct ConfigArgs {
    /// The car's configuration file.
    #[arg(long, default_value = "config/car.toml")]
    pub config: PathBuf,
    /// Personal overrides layered on top (git-ignored). Used when it exists.
    #[arg(long, default_value = "config/local.toml")]
    pub local: PathBuf,
    /// Override one value, e.g. `--set steering.kp=0.8` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

impl ConfigArgs {
    /// Loads, merges and validates the configuration.
    pub fn load(&self) -> Result<Config> {
        let locals: Vec<PathBuf> = if self.local.exists() {
            vec![self.local.clone()]
        } else {
            vec![]
        };
        Ok(Config::load(&self.config, &locals, &self.set)?)
    }
}

/// Loads the `[detect]` cascades that exist and says once, on stderr, which are missing (the
/// pipeline then runs without them: lane keeping only when none exists).
pub fn load_detector(cfg: &Config) -> Result<Option<rccar::detect::DetectStage>> {
    let (stage, missing) = rccar::pipeline::load_detector(&cfg.detect, std::path::Path::new("."))?;
    if !missing.is_empty() {
        let names: Vec<String> = missing.iter().map(|p| p.display().to_string()).collect();
        eprintln!(
            "detect: missing {}; {}",
            names.join(", "),
            if stage.is_some() {
                "running without them"
            } else {
                "running lane-only"
            }
        );
    }
    Ok(stage)
}
