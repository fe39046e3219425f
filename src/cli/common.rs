//! Flags shared by every subcommand that needs the car's configuration, and where the
//! configuration is found.
//!
//! The base file is `--config FILE` when given, else `$RCCAR_CONFIG`, else `config/car.toml`
//! in the working directory or the nearest folder above it (so `rccar` works from any
//! subfolder of the project), else — outside any project — the `config/car.toml` of the source
//! tree this binary was built from, when it still exists (said on stderr). Overrides: `--local FILE` (must exist when named), else
//! `local.toml` beside the base file when it exists (`--no-local`: none); then
//! `--set key=value`. Relative paths inside a file resolve against that file's folder (see
//! `rccar::config::LoadedConfig`). The lookups themselves are the library's
//! (`rccar::config::{find_config, source_tree_config, find_local}`); here: the flags.

use anyhow::{bail, Result};
use clap::Args;
use rccar::config::{Config, LoadedConfig};
use std::path::{Path, PathBuf};

/// Where the configuration comes from.
#[derive(Args, Debug, Clone, Default)]
pub struct ConfigArgs {
    /// The car's configuration file [default: $RCCAR_CONFIG, else config/car.toml in this
    /// folder or the nearest folder above it, else the one of the source tree rccar was
    /// built from].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Personal overrides layered on top (git-ignored); an error if named and missing
    /// [default: local.toml beside the configuration, when it exists].
    #[arg(long, conflicts_with = "no_local")]
    pub local: Option<PathBuf>,
    /// Use no override file, even if local.toml exists (reproducible runs, tests).
    #[arg(long)]
    pub no_local: bool,
    /// Override one value, e.g. `--set steering.kp=0.8` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

impl ConfigArgs {
    /// The base configuration file this command uses.
    pub fn base_file(&self) -> Result<PathBuf> {
        match &self.config {
            Some(p) => Ok(p.clone()),
            None => match rccar::config::find_config(Path::new("."), std::env::var_os("RCCAR_CONFIG").as_deref()) {
                Ok(p) => Ok(p),
                Err(e) => match rccar::config::source_tree_config() {
                    Some(p) => {
                        static SAID: std::sync::Once = std::sync::Once::new();
                        SAID.call_once(|| {
                            super::signals::say_err(&format!(
                                "rccar: no config/car.toml here or above; using {} (the source tree rccar was built from; --config FILE to choose)",
                                p.display()
                            ))
                        });
                        Ok(p)
                    }
                    None => Err(e.into()),
                },
            },
        }
    }

    /// The override file: `--local` (must exist), else `local.toml` beside `base` if present.
    pub fn local_file(&self, base: &Path) -> Result<Option<PathBuf>> {
        if self.no_local {
            return Ok(None);
        }
        Ok(rccar::config::find_local(base, self.local.as_deref())?)
    }

    /// Where a change saved by this command goes (a dashboard's "save"): `--local` if named,
    /// else `local.toml` beside the configuration (created when missing).
    pub fn local_target(&self) -> Result<PathBuf> {
        match &self.local {
            Some(p) => Ok(p.clone()),
            None => Ok(rccar::config::local_beside(&self.base_file()?)),
        }
    }

    /// Loads, merges and validates the configuration: the values, the base file's folder and
    /// every file read. Path keys in the result are absolute.
    pub fn load_full(&self) -> Result<LoadedConfig> {
        let base = self.base_file()?;
        let locals: Vec<PathBuf> = self.local_file(&base)?.into_iter().collect();
        Ok(LoadedConfig::load(&base, &locals, &self.set)?)
    }

    /// Loads, merges and validates the configuration (path keys absolute).
    pub fn load(&self) -> Result<Config> {
        Ok(self.load_full()?.cfg)
    }
}

/// Loads the classes' cascades (`classes.<name>.model`); a configured one that is missing is an
/// error naming the key, the file and the fix (an empty path switches a class off). The paths
/// in `cfg` are absolute after [`ConfigArgs::load`].
pub fn load_detector(cfg: &Config) -> Result<Option<rccar::detect::DetectStage>> {
    let (stage, missing) = rccar::pipeline::load_detector(cfg, Path::new("."))?;
    if let Some(m) = missing.first() {
        bail!("{m}");
    }
    Ok(stage)
}
