//! Calibrating tilt ranging from measured pairs (`rccar calibrate ranging`): which pairs can
//! determine the camera ([`check_pairs`]), where the fit starts ([`from_image_centre`]; the
//! check start [`nominal`], [`same_fit`]), and writing the
//! result into the student's override file in place ([`edit_override`], [`backup_name`],
//! [`write_file`], the dry run's [`line_diff`]). The fit itself is
//! [`crate::ranging::fit`].

use crate::camera::PinholeCamera;
use crate::ranging::{Pair, TiltRanging};
use std::path::{Path, PathBuf};

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
