//! Calibrating tilt ranging from measured pairs (`rccar calibrate ranging`): the pairs file
//! ([`read_pairs_csv`]), which pairs can determine the camera ([`check_pairs`]), where the fit
//! starts ([`from_image_centre`]; the check start [`nominal`], [`same_fit`]), the residuals'
//! table ([`residual_lines`]), and writing the result into the student's override file in
//! place ([`read_override`], [`edit_override`], [`backup_name`], [`write_file`], the dry
//! run's [`line_diff`]). The fit itself is [`crate::ranging::fit`].

use crate::camera::PinholeCamera;
use crate::ranging::{parse_pairs_csv, Fit, Pair, TiltRanging};
use std::path::{Path, PathBuf};

/// Most pairs a calibration takes: a CSV's, and `--from-sim N` (one rendered frame per pair).
pub const MAX_PAIRS: usize = 10_000;
/// Largest pairs CSV, bytes (10,000 pairs of ~25 bytes fit 25 times over).
pub const MAX_CSV_BYTES: u64 = 1 << 20;
/// Largest override file edited in place, bytes.
pub const MAX_OVERRIDE_BYTES: u64 = 1 << 20;
/// Largest `--max-rms-px`, pixels.
pub const MAX_RMS_PX: f64 = 100.0;
/// Largest `--v0-sigma-px`, pixels (4× the largest image side is no prior at all).
pub const MAX_V0_SIGMA_PX: f64 = 1000.0;

/// A fit option out of its bounds (the message names the flag and the bound).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitOptionsError {
    /// `--max-rms-px` not in (0, [`MAX_RMS_PX`]].
    #[error("--max-rms-px {0}: must be > 0 and <= {MAX_RMS_PX} pixels")]
    MaxRms(f64),
    /// `--v0-sigma-px` not in [0, [`MAX_V0_SIGMA_PX`]].
    #[error("--v0-sigma-px {0}: must be 0..={MAX_V0_SIGMA_PX} pixels (0 = free)")]
    V0Sigma(f64),
}

/// Checks the fit's refusal bound `max_rms_px` and the width `v0_sigma_px` of the prior on v0
/// (0 = free; see [`centre_prior`]).
pub fn check_options(max_rms_px: f64, v0_sigma_px: f64) -> Result<(), FitOptionsError> {
    if !(max_rms_px > 0.0 && max_rms_px <= MAX_RMS_PX) {
        return Err(FitOptionsError::MaxRms(max_rms_px));
    }
    if !(0.0..=MAX_V0_SIGMA_PX).contains(&v0_sigma_px) {
        return Err(FitOptionsError::V0Sigma(v0_sigma_px));
    }
    Ok(())
}

/// Why the override file cannot be updated.
#[derive(Debug, thiserror::Error)]
pub enum OverrideError {
    /// The file is not TOML.
    #[error("not valid TOML (fix it or move it away first)")]
    Toml(#[source] toml_edit::TomlError),
    /// The section exists but is not a table.
    #[error("`{0}` is not a table")]
    NotTable(String),
    /// The key exists but is not a value.
    #[error("`{0}` is not a value")]
    NotValue(String),
}

/// Where the fit starts: the configured camera with v0 at the image centre (the prior on v0
/// sits there too: the centre is a property of the image, not of the last calibration; tilt
/// and v0 trade off, so a prior at an earlier fit's v0 returns that fit whatever the pairs
/// say). Without `fit_ay`, a_y is held at the configured `a_y_scale`.
pub fn from_image_centre(cam: &PinholeCamera, a_y_scale: f64, fit_ay: bool) -> TiltRanging {
    let mut start = TiltRanging::from_camera(cam);
    if !fit_ay {
        start.a_y *= a_y_scale;
    }
    start
}

/// The configured (nominal) camera's tilt ranging, with the configured v0 offset and a_y
/// scale applied (the last calibration): where the second fit starts, which must land on the
/// same answer as the first ([`same_fit`]).
pub fn nominal(cam: &PinholeCamera, v0_offset_px: f64, a_y_scale: f64) -> TiltRanging {
    let mut start = TiltRanging::from_camera(cam);
    start.v0 += v0_offset_px;
    start.a_y *= a_y_scale;
    start
}

/// Two fits of the same pairs, one started from the image centre and one from the configured
/// values, must agree within this tilt, degrees, ...
pub const START_TOL_DEG: f64 = 0.01;
/// ... this v0, pixels ...
pub const START_TOL_PX: f64 = 0.05;
/// ... and this fraction of a_y; otherwise the start decided the answer and it is refused.
pub const START_TOL_AY: f64 = 1e-3;

/// Whether the fit `g` (started from the configured values) lands on `f` (started from the
/// image centre) within [`START_TOL_DEG`], [`START_TOL_PX`] and [`START_TOL_AY`].
pub fn same_fit(f: &TiltRanging, g: &TiltRanging) -> bool {
    !((g.alpha - f.alpha).abs().to_degrees() > START_TOL_DEG
        || (g.v0 - f.v0).abs() > START_TOL_PX
        || (g.a_y - f.a_y).abs() > START_TOL_AY * f.a_y)
}

/// The pairs as the CSV `calibrate ranging` reads (`row_px,distance_m,height_m`).
pub fn pairs_csv(pairs: &[Pair]) -> String {
    let mut text = String::from("row_px,distance_m,height_m\n");
    for q in pairs {
        text += &format!("{:.1},{:.4},{}\n", q.v, q.d, q.z);
    }
    text
}

/// Why these pairs cannot calibrate the camera, if they cannot. `pairs` are 1-based in
/// messages, as a student counts the rows of the CSV. `image_height`: the camera's rows;
/// `h_cam`: its height above the floor, metres.
pub fn check_pairs(pairs: &[Pair], image_height: u32, h_cam: f64, fit_ay: bool) -> Result<(), String> {
    let h_img = image_height as f64;
    for (i, p) in pairs.iter().enumerate() {
        let n = i + 1;
        if !(p.v.is_finite() && p.d.is_finite() && p.z.is_finite()) {
            return Err(format!(
                "pair {n} ({}, {}, {}): every value must be a finite number (NaN and inf are not allowed)",
                p.v, p.d, p.z
            ));
        }
        if !(0.0..h_img).contains(&p.v) {
            return Err(format!(
                "pair {n}: row {} px is outside the image (rows 0..{} of camera.height = {})",
                p.v,
                h_img - 1.0,
                image_height
            ));
        }
        if !(p.d > 0.0 && p.d <= 100.0) {
            return Err(format!("pair {n}: distance {} m must be > 0 and <= 100 m", p.d));
        }
        if !(p.z >= 0.0 && p.z < h_cam) {
            return Err(format!(
                "pair {n}: height {} m must be >= 0 and below the camera (camera.height_m = {h_cam} m): a ray from the lens only reaches lower points",
                p.z
            ));
        }
    }
    let need = if fit_ay { 4 } else { 3 };
    let mut rows: Vec<f64> = pairs.iter().map(|p| p.v).collect();
    rows.sort_by(f64::total_cmp);
    rows.dedup_by(|a, b| (*a - *b).abs() < 0.5);
    if rows.len() < need {
        return Err(format!(
            "{} pair(s) on only {} distinct row(s) (rows closer than 0.5 px count as one); fitting {} needs at least {need} distinct rows: measure at more distances",
            pairs.len(),
            rows.len(),
            if fit_ay { "tilt, v0 and a_y" } else { "tilt and v0" }
        ));
    }
    Ok(())
}

/// The override file's text with `values` set (section, key, value): existing comments,
/// formatting and other keys are kept; a missing section or key is added.
pub fn edit_override(old: Option<&str>, values: &[(&str, &str, f64)]) -> Result<String, OverrideError> {
    let mut doc: toml_edit::DocumentMut = match old {
        Some(t) => t.parse().map_err(OverrideError::Toml)?,
        None => "# Personal overrides of the car's configuration (git-ignored).\n# `rccar calibrate ranging` updates its keys here in place.\n"
            .parse()
            .map_err(OverrideError::Toml)?,
    };
    for &(section, key, v) in values {
        let item = doc
            .as_table_mut()
            .entry(section)
            .or_insert_with(|| toml_edit::Item::Table(toml_edit::Table::new()));
        let table = item
            .as_table_like_mut()
            .ok_or_else(|| OverrideError::NotTable(section.to_string()))?;
        match table.get_mut(key) {
            Some(it) => {
                let decor = it
                    .as_value()
                    .ok_or_else(|| OverrideError::NotValue(format!("{section}.{key}")))?
                    .decor()
                    .clone();
                let mut nv = toml_edit::Value::from(v);
                *nv.decor_mut() = decor;
                *it = toml_edit::Item::Value(nv);
            }
            None => {
                table.insert(key, toml_edit::value(v));
            }
        }
    }
    Ok(doc.to_string())
}

/// `FILE.bak`, or `FILE.bak2`, `FILE.bak3`... when that exists (no backup is overwritten).
pub fn backup_name(target: &Path) -> PathBuf {
    let base = target.as_os_str().to_owned();
    for n in 1..10_000 {
        let mut name = base.clone();
        name.push(if n == 1 { ".bak".to_string() } else { format!(".bak{n}") });
        let p = PathBuf::from(name);
        if !p.exists() {
            return p;
        }
    }
    let mut name = base;
    name.push(".bak");
    PathBuf::from(name)
}

/// Writes `text` to `path`. A regular file (or a symlink to one) is
/// replaced atomically: the text goes to a temporary file beside the real file, which is then
/// renamed over it, so a full disk leaves the old file untouched and a symlink stays a
/// symlink. Anything else (a new file, a device such as /dev/null) is written directly.
pub fn write_file(path: &Path, text: &str) -> std::io::Result<()> {
    use std::io::Write;
    let real = std::fs::canonicalize(path).ok().filter(|p| p.is_file());
    let Some(real) = real else {
        return std::fs::write(path, text);
    };
    let mut tmp = real.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let res = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, &real)
    })();
    if let Err(e) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    Ok(())
}

/// A line diff (`-` old, `+` new, two spaces unchanged) by longest common subsequence; the
/// files are a few dozen lines.
pub fn line_diff(old: &str, new: &str) -> String {
    let a: Vec<&str> = old.lines().collect();
    let b: Vec<&str> = new.lines().collect();
    let (n, m) = (a.len(), b.len());
    let mut l = vec![vec![0u32; m + 1]; n + 1];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            l[i][j] = if a[i] == b[j] {
                l[i + 1][j + 1] + 1
            } else {
                l[i + 1][j].max(l[i][j + 1])
            };
        }
    }
    let (mut i, mut j) = (0, 0);
    let mut out = String::new();
    while i < n || j < m {
        if i < n && j < m && a[i] == b[j] {
            out += &format!("  {}\n", a[i]);
            i += 1;
            j += 1;
        } else if i < n && (j == m || l[i + 1][j] >= l[i][j + 1]) {
            out += &format!("- {}\n", a[i]);
            i += 1;
        } else {
            out += &format!("+ {}\n", b[j]);
            j += 1;
        }
    }
    out
}

/// Why a fit is refused before anything is written (the caller names the pairs' origin).
#[derive(Debug, thiserror::Error)]
pub enum FitRefused {
    /// A pair's row is above the fitted camera's horizon.
    #[error("pair {n} (row {v} px, {d} m): the fitted camera does not see that row on the floor (above its horizon); the pairs do not belong together")]
    AboveHorizon {
        /// The pair, 1-based.
        n: usize,
        /// Its row, pixels.
        v: f64,
        /// Its distance, metres.
        d: f64,
    },
    /// The rms row error is above the bound.
    #[error("rms row error {rms:.2} px is above the bound {max} px (--max-rms-px): the rows and distances do not fit one camera; check the measurements")]
    Rms {
        /// The fit's rms row error, pixels.
        rms: f64,
        /// The bound, pixels.
        max: f64,
    },
    /// A fitted value is not finite.
    #[error("the fitted {what} is {value}")]
    NotFinite {
        /// Which value.
        what: String,
        /// It.
        value: f64,
    },
    /// v0 outside the image.
    #[error("the fitted principal point row v0 = {v0:.1} px is outside the image (rows 0..{last_row}): the pairs do not pin tilt and v0 apart; measure at more distances spread over the image, or keep v0 near the centre (--v0-sigma-px 3)")]
    V0Outside {
        /// The fitted v0, pixels.
        v0: f64,
        /// The image's last row.
        last_row: i64,
    },
    /// Started from the configured values, the fit lands elsewhere.
    #[error("the fit depends on where it starts: from the image centre it gives tilt {:.3} deg, v0 {:.2} px, a_y {:.1} px; from the configured values (ranging.v0_offset_px = {v0_offset_px}, ranging.a_y_scale = {a_y_scale}) {other}; the pairs do not pin the camera down: measure at more distances spread over the image{}", fit.alpha.to_degrees(), fit.v0, fit.a_y, if *v0_free { ", or keep v0 near the image centre (--v0-sigma-px 3)" } else { "" })]
    StartDependent {
        /// The fit from the image centre.
        fit: TiltRanging,
        /// The configured v0 offset, pixels.
        v0_offset_px: f64,
        /// The configured a_y scale.
        a_y_scale: f64,
        /// What the fit from the configured values gave.
        other: String,
        /// v0 was fitted without a prior.
        v0_free: bool,
    },
}

/// Refuses a fit with an undefined residual, an rms row error above `max_rms_px`, a value
/// that is not finite or a v0 outside the image's `image_height` rows.
pub fn check_fit(
    pairs: &[Pair],
    f: &crate::ranging::Fit,
    max_rms_px: f64,
    values: [(&str, f64); 3],
    image_height: u32,
) -> Result<(), FitRefused> {
    if let Some(i) = f.residuals_m.iter().position(|r| !r.is_finite()) {
        return Err(FitRefused::AboveHorizon { n: i + 1, v: pairs[i].v, d: pairs[i].d });
    }
    if !(f.rms_row_px.is_finite() && f.rms_row_px <= max_rms_px) {
        return Err(FitRefused::Rms { rms: f.rms_row_px, max: max_rms_px });
    }
    if let Some((what, value)) = values.into_iter().find(|(_, v)| !v.is_finite()) {
        return Err(FitRefused::NotFinite { what: what.into(), value });
    }
    if !(0.0..image_height as f64).contains(&f.ranging.v0) {
        return Err(FitRefused::V0Outside { v0: f.ranging.v0, last_row: image_height as i64 - 1 });
    }
    Ok(())
}

/// Refuses a fit `f` that lands elsewhere when started from the configured values (the last
/// calibration, [`nominal`]): it was decided by its start, not by the pairs.
pub fn check_start(
    pairs: &[Pair],
    f: &crate::ranging::Fit,
    opts: crate::ranging::FitOptions,
    cam: &PinholeCamera,
    v0_offset_px: f64,
    a_y_scale: f64,
) -> Result<(), FitRefused> {
    let g = crate::ranging::fit(pairs, nominal(cam, v0_offset_px, a_y_scale), opts);
    let other = match &g {
        Ok(g) if same_fit(&f.ranging, &g.ranging) => return Ok(()),
        Ok(g) => format!(
            "tilt {:.3} deg, v0 {:.2} px, a_y {:.1} px",
            g.ranging.alpha.to_degrees(),
            g.ranging.v0,
            g.ranging.a_y
        ),
        Err(e) => format!("no fit ({e})"),
    };
    Err(FitRefused::StartDependent {
        fit: f.ranging,
        v0_offset_px,
        a_y_scale,
        other,
        v0_free: !(opts.v0_sigma_px.is_finite()),
    })
}

/// Why a small text file cannot be read, or the override file not backed up.
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    /// Reading failed.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        err: std::io::Error,
    },
    /// Larger than the bound.
    #[error("{}: larger than {max} bytes; not a file this command reads", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The bound, bytes.
        max: u64,
    },
    /// Its folder cannot be created.
    #[error("{}: cannot create", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        err: std::io::Error,
    },
    /// The backup copy failed.
    #[error("{}: cannot back up to {}", path.display(), backup.display())]
    Backup {
        /// The file.
        path: PathBuf,
        /// The backup's name.
        backup: PathBuf,
        /// Why.
        #[source]
        err: std::io::Error,
    },
}

/// Why a pairs CSV cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PairsFileError {
    /// Not readable, or larger than [`MAX_CSV_BYTES`].
    #[error(transparent)]
    Read(#[from] TextFileError),
    /// A line that is not `row_px,distance_m[,height_m]` (the message names it).
    #[error("{0}")]
    Parse(String),
    /// More than [`MAX_PAIRS`] pairs.
    #[error("{}: {count} pairs; at most {MAX_PAIRS}", path.display())]
    TooMany {
        /// The file.
        path: PathBuf,
        /// Its pairs.
        count: usize,
    },
}

/// The pairs of a CSV of `row_px,distance_m[,height_m]` lines (header and `#` comments
/// allowed; at most [`MAX_CSV_BYTES`] and [`MAX_PAIRS`] pairs).
pub fn read_pairs_csv(path: &Path) -> Result<Vec<Pair>, PairsFileError> {
    let text = read_small(path, MAX_CSV_BYTES)?;
    let pairs = parse_pairs_csv(&text, &path.display().to_string()).map_err(PairsFileError::Parse)?;
    if pairs.len() > MAX_PAIRS {
        return Err(PairsFileError::TooMany { path: path.to_path_buf(), count: pairs.len() });
    }
    Ok(pairs)
}

/// The residuals of fit `f` to `pairs` as a table: a header, then per pair its row, true and
/// fitted distance and the residual in metres and per cent.
pub fn residual_lines(pairs: &[Pair], f: &Fit) -> Vec<String> {
    let mut lines = vec![format!(
        "{:>8} {:>9} {:>10} {:>10} {:>7}",
        "row px", "true m", "fitted m", "resid m", "resid %"
    )];
    for (p, r) in pairs.iter().zip(&f.residuals_m) {
        lines.push(format!(
            "{:>8.1} {:>9.4} {:>10.4} {:>+10.4} {:>+7.2}",
            p.v,
            p.d,
            p.d + r,
            r,
            100.0 * r / p.d
        ));
    }
    lines
}

/// The override file's text as it is now (at most [`MAX_OVERRIDE_BYTES`]); `None` when it does
/// not exist yet.
pub fn read_override(path: &Path) -> Result<Option<String>, TextFileError> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        _ => read_small(path, MAX_OVERRIDE_BYTES).map(Some),
    }
}

/// Reads a text file of at most `max` bytes; the error names the file and the bound.
pub fn read_small(path: &Path, max: u64) -> Result<String, TextFileError> {
    use std::io::Read;
    let read = |err| TextFileError::Read { path: path.to_path_buf(), err };
    let f = std::fs::File::open(path).map_err(read)?;
    let mut text = String::new();
    f.take(max + 1).read_to_string(&mut text).map_err(read)?;
    if text.len() as u64 > max {
        return Err(TextFileError::TooLarge { path: path.to_path_buf(), max });
    }
    Ok(text)
}

/// Before `target` is replaced: creates its folder, and copies the existing file (when
/// `exists`) to [`backup_name`]; returns the backup's path.
pub fn backup_override(target: &Path, exists: bool) -> Result<Option<PathBuf>, TextFileError> {
    if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|err| TextFileError::CreateDir { path: dir.to_path_buf(), err })?;
    }
    if !exists {
        return Ok(None);
    }
    let backup = backup_name(target);
    std::fs::copy(target, &backup).map_err(|err| TextFileError::Backup {
        path: target.to_path_buf(),
        backup: backup.clone(),
        err,
    })?;
    Ok(Some(backup))
}

/// The fit's options: a_y fitted or held, and the prior on v0 centred on the image's middle
/// row (a property of the image, not of the last calibration: tilt and v0 trade off, so a
/// prior at an earlier fit's v0 returns that fit whatever the pairs say); `v0_sigma_px` 0 =
/// free.
pub fn centre_prior(cam: &PinholeCamera, fit_ay: bool, v0_sigma_px: f64) -> crate::ranging::FitOptions {
    crate::ranging::FitOptions {
        fit_ay,
        v0_sigma_px: if v0_sigma_px > 0.0 { v0_sigma_px } else { f64::INFINITY },
        v0_prior_px: Some(cam.v0),
        ..Default::default()
    }
}

/// What a fit gives in the configuration's terms: `[camera] tilt_deg`, `[ranging]
/// v0_offset_px` (from the image centre) and `a_y_scale` (of the focal length).
pub fn fitted_values(f: &TiltRanging, cam: &PinholeCamera) -> [(&'static str, f64); 3] {
    [
        ("tilt", f.alpha.to_degrees()),
        ("v0 offset", f.v0 - cam.v0),
        ("a_y scale", f.a_y / cam.f_px),
    ]
}

/// [`fitted_values`] as the override file's keys, rounded to 4 decimals.
pub fn override_values(values: [(&str, f64); 3]) -> [(&'static str, &'static str, f64); 3] {
    let round = |v: f64| (v * 1e4).round() / 1e4;
    [
        ("camera", "tilt_deg", round(values[0].1)),
        ("ranging", "v0_offset_px", round(values[1].1)),
        ("ranging", "a_y_scale", round(values[2].1)),
    ]
}
