//! Loading a configuration in layers: the base file, override files (e.g. `config/local.toml`)
//! and `key=value` assignments from the command line, merged table by table over the defaults
//! (so a section, e.g. one `[classes.<name>]`, needs only the keys it changes); unknown keys are
//! refused with a hint, relative paths resolved against the file that names them, and the
//! result deserialised and checked ([`Config::validate`]). Also where the configuration is
//! found ([`find_config`], [`source_tree_config`]) and its personal override file
//! ([`find_local`], [`local_beside`]).

use super::value::{lookup, number_at, to_table};
use super::{Config, ConfigError};
use std::path::{Path, PathBuf};

/// The keys whose values are file paths: `sim.track`, `stereo.calibration`,
/// `camera.calibration`, `steering.model` and each class's
/// model (`classes.<name>.model`, from the registry). A relative path written in a file is
/// resolved against that file's folder; one given on the command line (`--set`) against the
/// working directory; a default (a key set nowhere) against the base configuration's folder.
/// Add a new path key here and to [`Config::resolve_paths`] and it is resolved like the others.
pub fn path_keys() -> impl Iterator<Item = &'static str> {
    ["sim.track", "stereo.calibration", "camera.calibration", "steering.model"]
        .into_iter()
        .chain(crate::classes::CLASSES.iter().map(|c| c.model_key))
}

impl Config {
    /// Loads `base`, then each override file, then `key=value` overrides; checks everything.
    /// Relative path keys ([`path_keys`]) come back absolute, as [`LoadedConfig::load`].
    pub fn load(base: &Path, override_files: &[PathBuf], overrides: &[String]) -> Result<Config, ConfigError> {
        LoadedConfig::load(base, override_files, overrides).map(|l| l.cfg)
    }

    /// Parses one TOML text (e.g. a test's inline config) on top of the defaults. Paths are
    /// kept as written.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Config, ConfigError> {
        let table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: origin.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let layer = Layer {
            origin: origin.to_string(),
            table,
        };
        layer.check_numbers()?;
        Self::from_layers(&[layer])
    }

    /// This config with one dotted numeric or boolean key set, e.g. `steering.kp=0.8`;
    /// used by gain sweeps. Validated like a file. A path value is kept as typed.
    pub fn with_override(&self, assignment: &str) -> Result<Config, ConfigError> {
        let base = Layer {
            origin: "config".into(),
            table: to_table(self),
        };
        Self::from_layers(&[base, Layer::from_assignment(assignment, None)?])
    }

    /// The number at a dotted key, e.g. `steering.kp` (`None`: no such key, or not a number).
    pub fn number(&self, key: &str) -> Option<f64> {
        number_at(&to_table(self), key)
    }

    fn from_layers(layers: &[Layer]) -> Result<Config, ConfigError> {
        let known = to_table(&Config::default());
        // Every layer merges over the defaults' tree (the one unknown keys are checked
        // against), so a partial `[classes.<name>]` keeps that class's other defaults.
        let mut merged = known.clone();
        for layer in layers {
            check_known(&layer.table, &known, "", &layer.origin)?;
            merge(&mut merged, &layer.table);
        }
        let origin = layers.iter().map(|l| l.origin.as_str()).collect::<Vec<_>>().join(" + ");
        // serde_path_to_error remembers which key was being read when a type is wrong.
        let cfg: Config = serde_path_to_error::deserialize(toml::Value::Table(merged.clone())).map_err(|e| {
            let key = e.path().to_string();
            let typed = lookup(&merged, &key).map(show_value).unwrap_or_default();
            ConfigError::Type {
                origin: origin.clone(),
                message: if typed.is_empty() {
                    format!("`{key}`: {}", e.inner().message().trim())
                } else {
                    format!("`{key}` = {typed}: {}", e.inner().message().trim())
                },
            }
        })?;
        cfg.validate().map_err(|e| match e {
            ConfigError::Invalid { errors, .. } => ConfigError::Invalid { origin, errors },
            other => other,
        })?;
        Ok(cfg)
    }

    /// Makes every relative path key ([`path_keys`]) absolute against `dir` (e.g. the folder of
    /// the file the defaults stand for). Empty values are left alone.
    pub fn resolve_paths(&mut self, dir: &Path) {
        let models = self.classes.iter_mut().map(|c| &mut c.model);
        for p in [
            &mut self.sim.track,
            &mut self.stereo.calibration,
            &mut self.camera.calibration,
            &mut self.steering.model,
        ]
            .into_iter()
            .chain(models)
        {
            if !p.is_empty() && Path::new(p.as_str()).is_relative() {
                *p = absolute(&dir.join(p.as_str())).display().to_string();
            }
        }
    }
}

/// A configuration as loaded for a command: the values (path keys absolute), the folder of
/// the base file and every file that was read.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedConfig {
    /// The merged, validated configuration; every [`path_keys`] value is an absolute path.
    pub cfg: Config,
    /// The folder of the base configuration file, absolute.
    pub dir: PathBuf,
    /// Every file read, base first, then the override files in order.
    pub files: Vec<PathBuf>,
    /// How many values the files set (0: every value is a default).
    pub values_in_files: usize,
}

impl LoadedConfig {
    /// Loads `base`, then each override file (each must exist), then `key=value` overrides,
    /// and checks everything. Relative paths in a file resolve against that file's folder,
    /// those in `overrides` against the working directory, defaults against `base`'s folder.
    pub fn load(base: &Path, override_files: &[PathBuf], overrides: &[String]) -> Result<LoadedConfig, ConfigError> {
        let base_layer = Layer::from_file(base).map_err(|e| match e {
            ConfigError::Io { path, error } if error.kind() == std::io::ErrorKind::NotFound => {
                ConfigError::Missing { path, error }
            }
            other => other,
        })?;
        let mut layers = vec![base_layer];
        for f in override_files {
            layers.push(Layer::from_file(f)?);
        }
        let values_in_files = layers.iter().map(|l| count_values(&l.table)).sum();
        let cwd = absolute(Path::new("."));
        for o in overrides {
            layers.push(Layer::from_assignment(o, Some(&cwd))?);
        }
        let mut cfg = Config::from_layers(&layers)?;
        let dir = absolute(
            base.parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        );
        cfg.resolve_paths(&dir);
        let mut files = vec![base.to_path_buf()];
        files.extend(override_files.iter().cloned());
        Ok(LoadedConfig {
            cfg,
            dir,
            files,
            values_in_files,
        })
    }
}

impl LoadedConfig {
    /// Checks what the configuration would be if the override file `path` held `text`
    /// (before writing it): `base`, then `override_files` without `path`, then `text` as
    /// `path`. Nothing is written.
    pub fn check_with_text(
        base: &Path,
        override_files: &[PathBuf],
        path: &Path,
        text: &str,
    ) -> Result<Config, ConfigError> {
        let mut layers = vec![Layer::from_file(base)?];
        for f in override_files.iter().filter(|f| !same_file(f, path)) {
            layers.push(Layer::from_file(f)?);
        }
        layers.push(Layer::from_text(path, text)?);
        Config::from_layers(&layers)
    }
}

/// The same path, compared after making both absolute (the files need not exist).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => absolute(a) == absolute(b),
    }
}

/// Finds the configuration: `env` (the value of `RCCAR_CONFIG`, relative to `start`) when
/// given and non-empty, else `config/car.toml` in `start` or the nearest folder above it.
pub fn find_config(start: &Path, env: Option<&std::ffi::OsStr>) -> Result<PathBuf, ConfigError> {
    if let Some(e) = env.filter(|e| !e.is_empty()) {
        // Loading it reports a missing file, with the OS error and how to point elsewhere.
        return Ok(start.join(e));
    }
    let start = absolute(start);
    for dir in start.ancestors() {
        let p = dir.join("config").join("car.toml");
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(ConfigError::NotFound { start })
}

/// `config/car.toml` of the source tree this crate was compiled from, if it is still there: a
/// student who built rccar with cargo can run it from any folder. A binary copied to the car
/// has no such tree (`None`).
pub fn source_tree_config() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config").join("car.toml");
    p.is_file().then_some(p)
}

/// The personal override file that goes with the configuration `base`: `local.toml` in its
/// folder (git-ignored; it need not exist).
pub fn local_beside(base: &Path) -> PathBuf {
    base.parent().unwrap_or(Path::new("")).join("local.toml")
}

/// An override file named with `--local` that does not exist.
#[derive(Debug, thiserror::Error)]
#[error(
    "--local {}: no such file (leave --local out to use local.toml beside the configuration when it exists)",
    .0.display()
)]
pub struct MissingLocal(pub PathBuf);

/// The override file layered on `base`: `named` (`--local`), which must exist, else
/// [`local_beside`] `base` when it exists, else none.
pub fn find_local(base: &Path, named: Option<&Path>) -> Result<Option<PathBuf>, MissingLocal> {
    match named {
        Some(p) if p.is_file() => Ok(Some(p.to_path_buf())),
        Some(p) => Err(MissingLocal(p.to_path_buf())),
        None => {
            let p = local_beside(base);
            Ok(p.is_file().then_some(p))
        }
    }
}

/// `p` made absolute against the working directory (no symlinks resolved; unchanged if the
/// working directory cannot be read).
fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

fn count_values(t: &toml::Table) -> usize {
    t.values()
        .map(|v| match v {
            toml::Value::Table(s) => count_values(s),
            _ => 1,
        })
        .sum()
}

fn show_value(v: &toml::Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 60 {
        format!("{}…", s.chars().take(60).collect::<String>())
    } else {
        s
    }
}

/// One source of settings: a file or a command-line assignment.
struct Layer {
    origin: String,
    table: toml::Table,
}

impl Layer {
    fn from_file(path: &Path) -> Result<Layer, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io {
            path: path.into(),
            error,
        })?;
        Self::from_text(path, &text)
    }

    /// The text of a file at `path` (relative paths in it resolve against its folder).
    fn from_text(path: &Path, text: &str) -> Result<Layer, ConfigError> {
        let mut table = text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
            path: path.into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let dir = absolute(
            path.parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        );
        resolve_table_paths(&mut table, &dir);
        let layer = Layer {
            origin: path.display().to_string(),
            table,
        };
        layer.check_numbers()?;
        Ok(layer)
    }

    /// `key=value`; a relative path value resolves against `cwd` when given.
    fn from_assignment(text: &str, cwd: Option<&Path>) -> Result<Layer, ConfigError> {
        let (key, value) = text
            .split_once('=')
            .ok_or_else(|| ConfigError::BadOverride(text.into()))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(ConfigError::BadOverride(text.into()));
        }
        let typed = value.trim();
        // Parse the value as TOML so numbers, booleans, arrays and quoted strings all work;
        // an unquoted word is taken as a string (`lane.threshold_mode=otsu`), unless it reads
        // as a number that is not finite (`1e309`, `NaN`, `inf`): that is refused here.
        let parsed = format!("v = {typed}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"));
        let not_finite = match &parsed {
            Some(toml::Value::Float(f)) => !f.is_finite(),
            Some(_) => false,
            None => typed.parse::<f64>().is_ok_and(|f| !f.is_finite()),
        };
        if not_finite {
            return Err(ConfigError::NotFinite {
                origin: "command line".into(),
                key: key.into(),
                typed: typed.into(),
            });
        }
        let value = parsed.unwrap_or_else(|| toml::Value::String(typed.to_string()));
        let mut table = toml::Table::new();
        let parts: Vec<&str> = key.split('.').collect();
        let mut cur = &mut table;
        for p in &parts[..parts.len() - 1] {
            cur = cur
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .ok_or_else(|| ConfigError::BadOverride(text.into()))?;
        }
        cur.insert(parts[parts.len() - 1].to_string(), value);
        if let Some(cwd) = cwd {
            resolve_table_paths(&mut table, cwd);
        }
        Ok(Layer {
            origin: "command line".into(),
            table,
        })
    }

    /// Refuses inf and NaN anywhere (TOML allows `inf` and `nan` literals).
    fn check_numbers(&self) -> Result<(), ConfigError> {
        fn walk(v: &toml::Value, key: &str, origin: &str) -> Result<(), ConfigError> {
            match v {
                toml::Value::Float(f) if !f.is_finite() => Err(ConfigError::NotFinite {
                    origin: origin.into(),
                    key: key.into(),
                    typed: f.to_string(),
                }),
                toml::Value::Table(t) => {
                    for (k, v) in t {
                        let full = if key.is_empty() {
                            k.clone()
                        } else {
                            format!("{key}.{k}")
                        };
                        walk(v, &full, origin)?;
                    }
                    Ok(())
                }
                toml::Value::Array(a) => {
                    for (i, v) in a.iter().enumerate() {
                        walk(v, &format!("{key}[{i}]"), origin)?;
                    }
                    Ok(())
                }
                _ => Ok(()),
            }
        }
        walk(&toml::Value::Table(self.table.clone()), "", &self.origin)
    }
}

/// Makes the relative string values of [`path_keys`] in one layer absolute against `dir`.
fn resolve_table_paths(table: &mut toml::Table, dir: &Path) {
    for key in path_keys() {
        let mut parts = key.split('.');
        let mut cur = parts.next().and_then(|p| table.get_mut(p));
        for p in parts {
            cur = cur.and_then(toml::Value::as_table_mut).and_then(|t| t.get_mut(p));
        }
        if let Some(toml::Value::String(s)) = cur {
            if !s.is_empty() && Path::new(s.as_str()).is_relative() {
                *s = absolute(&dir.join(s.as_str())).display().to_string();
            }
        }
    }
}

/// Every key of `layer` must exist in `known` (the default config's tree).
fn check_known(layer: &toml::Table, known: &toml::Table, prefix: &str, origin: &str) -> Result<(), ConfigError> {
    for (k, v) in layer {
        let full = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match known.get(k) {
            None => {
                let hint = unknown_key_hint(k, &full, prefix, known);
                return Err(ConfigError::UnknownKey {
                    origin: origin.into(),
                    key: full,
                    hint,
                });
            }
            Some(toml::Value::Table(sub)) => {
                if let toml::Value::Table(vt) = v {
                    check_known(vt, sub, &full, origin)?;
                } else {
                    return Err(ConfigError::Type {
                        origin: origin.into(),
                        message: format!("`{full}` is a section ([{full}]), not a value"),
                    });
                }
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The hint after an unknown key `k` (`full` with its section): a close spelling among its
/// siblings; for a key of the former flat layout (`detect.stop_sign`) the key it is now
/// (`classes.stop_sign.model`); for an unknown class, the class an alias names or the known
/// ones.
fn unknown_key_hint(k: &str, full: &str, prefix: &str, known: &toml::Table) -> String {
    if let Some(c) = closest(k, known.keys()) {
        return format!(", did you mean `{c}`?");
    }
    if let Some(new) = super::classes::moved_key(full) {
        return format!(", each class has its own section now: `{new}`");
    }
    if prefix == "classes" {
        return match crate::classes::ObjectClass::from_label(k) {
            Some(c) => format!(", did you mean `{c}`?"),
            None => format!(
                ", the classes are {} (a new one needs its entry in src/classes.rs)",
                super::classes::class_names()
            ),
        };
    }
    String::new()
}

fn merge(into: &mut toml::Table, from: &toml::Table) {
    for (k, v) in from {
        match (into.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge(a, b),
            _ => {
                into.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The known key closest to a misspelt one (edit distance ≤ 2).
fn closest<'a>(word: &str, candidates: impl Iterator<Item = &'a String>) -> Option<&'a String> {
    candidates
        .map(|c| (edit_distance(word, c), c))
        .filter(|(d, _)| *d <= 2)
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur.push(sub.min(prev[j + 1] + 1).min(cur[j] + 1));
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ThresholdMode;

    /// Outside any project (and without RCCAR_CONFIG) the search names the folder it started
    /// from and says how to point at a file; the CLI may then fall back to its source tree.
    #[test]
    fn no_config_anywhere_above_is_a_named_error() {
        let t = tempfile::tempdir().unwrap();
        let e = find_config(t.path(), None).unwrap_err();
        let m = e.to_string();
        assert!(
            m.starts_with("no config/car.toml in ") && m.contains("--config FILE or RCCAR_CONFIG=FILE"),
            "{m}"
        );
        assert!(matches!(e, ConfigError::NotFound { .. }));
        std::fs::create_dir_all(t.path().join("config/sub")).unwrap();
        std::fs::write(t.path().join("config/car.toml"), "").unwrap();
        assert_eq!(
            find_config(&t.path().join("config/sub"), None).unwrap(),
            t.path().join("config/car.toml")
        );
        assert_eq!(
            find_config(t.path(), Some(std::ffi::OsStr::new("x.toml"))).unwrap(),
            t.path().join("x.toml")
        );
    }

    #[test]
    fn unknown_key_is_named_with_a_hint() {
        let e = Config::from_toml_str("[steering]\nkpp = 1.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("steering.kpp") && e.contains("did you mean `kp`"), "{e}");
        let e = Config::from_toml_str("[steer]\nkp = 1.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown key `steer`"), "{e}");
    }

    #[test]
    fn wrong_type_names_key() {
        let e = Config::from_toml_str("[steering]\nkp = \"high\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("kp"), "{e}");
    }

    #[test]
    fn overrides_layer_in_order() {
        let cfg = Config::default().with_override("steering.kp=2.5").unwrap();
        assert_eq!(cfg.steering.kp, 2.5);
        let cfg = cfg.with_override("lane.threshold_mode=otsu").unwrap();
        assert_eq!(cfg.lane.threshold_mode, ThresholdMode::Otsu);
        assert!(Config::default().with_override("steering.kq=1").is_err());
        assert!(Config::default().with_override("nonsense").is_err());
    }

    /// `--local` must exist; without it, local.toml beside the configuration counts only when
    /// it is there.
    #[test]
    fn the_override_file_is_named_or_beside_the_configuration() {
        let t = tempfile::tempdir().unwrap();
        let base = t.path().join("car.toml");
        assert_eq!(local_beside(&base), t.path().join("local.toml"));
        assert_eq!(find_local(&base, None).unwrap(), None);
        std::fs::write(t.path().join("local.toml"), "").unwrap();
        assert_eq!(find_local(&base, None).unwrap(), Some(t.path().join("local.toml")));
        let named = t.path().join("mine.toml");
        let e = find_local(&base, Some(&named)).unwrap_err().to_string();
        assert!(e.starts_with(&format!("--local {}: no such file", named.display())), "{e}");
        std::fs::write(&named, "").unwrap();
        assert_eq!(find_local(&base, Some(&named)).unwrap(), Some(named));
    }
}
