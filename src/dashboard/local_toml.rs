//! Writes the dashboard's changed keys into `config/local.toml` in place: only those keys are
//! added or replaced; every other line, comment and table of the student's file is kept
//! (toml_edit keeps the document's formatting). Only keys of the parameter tables
//! ([`crate::control::catalog::all`]) and the set-up page's keys ([`SETUP_KEYS`]: the ROI's
//! four corners, the lane threshold, its mode and the adaptive threshold's C) are written; a
//! key new to the file gets its unit and allowed range as a comment on its line.

use serde::Serialize;
use std::path::Path;
use toml_edit::{value, Array, DocumentMut, Item, Table};

/// A value the dashboard writes: a tuning number, or one of the set-up page's values.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Saved {
    /// A number (the tuning tables' keys).
    Number(f64),
    /// A whole number (`lane.threshold`, `lane.adaptive_c`: grey levels the loader reads as
    /// integers).
    Int(i64),
    /// Four corners, pixels (`warp.src`).
    Points([[f64; 2]; 4]),
    /// A word (`lane.threshold_mode`).
    Text(String),
}

impl From<f64> for Saved {
    fn from(v: f64) -> Saved {
        Saved::Number(v)
    }
}

impl std::fmt::Display for Saved {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Saved::Number(v) => write!(f, "{v}"),
            Saved::Int(v) => write!(f, "{v}"),
            Saved::Points(p) => write!(f, "{p:?}"),
            Saved::Text(t) => write!(f, "\"{t}\""),
        }
    }
}

/// The set-up page's keys (issue 26, "set-up by clicking"), with the comment a key new to the
/// file gets.
pub const SETUP_KEYS: [(&str, &str); 4] = [
    (
        "warp.src",
        "ROI corners, camera pixels: top-left, top-right, bottom-right, bottom-left (clicked on the dashboard's /setup page)",
    ),
    ("lane.threshold", "grey level, allowed 0 ..= 255"),
    ("lane.threshold_mode", "\"adaptive\", \"fixed\" or \"otsu\""),
    (
        "lane.adaptive_c",
        "grey levels, allowed -255 ..= 255: line = brighter than the local mean minus this",
    ),
];

/// The TOML value of `v`, or why `key` cannot take it.
fn toml_value(key: &str, v: &Saved) -> Result<(toml_edit::Value, String), String> {
    if let Some(info) = crate::control::catalog::find(key) {
        let Saved::Number(n) = v else {
            return Err(format!("a tunable parameter takes a number, not {v}"));
        };
        let range = crate::control::params::show_range(info.range);
        return Ok((toml_edit::Value::from(*n), format!("{}, allowed {range}", info.unit)));
    }
    let Some((_, comment)) = SETUP_KEYS.iter().find(|(k, _)| *k == key) else {
        return Err("not a tunable parameter (src/control/params.rs) nor a set-up key (warp.src, lane.threshold, lane.threshold_mode, lane.adaptive_c)".into());
    };
    let value = match (key, v) {
        ("warp.src", Saved::Points(p)) => {
            let mut a = Array::new();
            for c in p {
                a.push(Array::from_iter([c[0], c[1]]));
            }
            toml_edit::Value::Array(a)
        }
        ("lane.threshold" | "lane.adaptive_c", Saved::Int(n)) => toml_edit::Value::from(*n),
        ("lane.threshold_mode", Saved::Text(t)) => toml_edit::Value::from(t.as_str()),
        _ => return Err(format!("the value {v} is not of this key's kind")),
    };
    Ok((value, comment.to_string()))
}

/// Why the file could not be updated.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// The existing file is not TOML.
    #[error("{path}: not valid TOML, left untouched: {message}")]
    Parse {
        /// The file.
        path: String,
        /// toml_edit's message (names line and column).
        message: String,
    },
    /// A key without a `section.` prefix, or one whose section is not a table.
    #[error("{path}: cannot set `{key}`: {why}")]
    Key {
        /// The file.
        path: String,
        /// The dotted key.
        key: String,
        /// Why.
        why: String,
    },
    /// Reading or writing failed.
    #[error("{path}: {err}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        err: std::io::Error,
    },
}

/// `text` with each dotted `section.key` (a tunable parameter or a set-up key) set to its
/// value (other content kept as it was).
pub fn set_keys(text: &str, keys: &[(String, Saved)], path: &str) -> Result<String, SaveError> {
    let mut doc: DocumentMut = text.parse().map_err(|e: toml_edit::TomlError| SaveError::Parse {
        path: path.into(),
        message: e.to_string().trim().replace('\n', " "),
    })?;
    for (key, v) in keys {
        let bad = |why: String| SaveError::Key {
            path: path.into(),
            key: key.clone(),
            why,
        };
        let Some((section, name)) = key.split_once('.') else {
            return Err(bad("not a tunable parameter (src/control/params.rs)".into()));
        };
        let (new_value, comment) = toml_value(key, v).map_err(bad)?;
        if !doc.as_table().contains_key(section) {
            let mut t = Table::new();
            // A file of comments only keeps them on top (toml_edit holds them as the
            // document's trailing text, which would otherwise end up below the new table).
            if doc.as_table().is_empty() {
                let lead = doc.trailing().as_str().unwrap_or("").to_string();
                if !lead.trim().is_empty() {
                    t.decor_mut().set_prefix(lead);
                    doc.set_trailing("");
                }
            }
            doc.as_table_mut().insert(section, Item::Table(t));
        }
        let root = doc.as_table_mut();
        let Some(tab) = root.get_mut(section).and_then(Item::as_table_like_mut) else {
            return Err(SaveError::Key {
                path: path.into(),
                key: key.clone(),
                why: format!("`{section}` is not a table"),
            });
        };
        // Keep a comment that sits on an existing key's line: replace only the value.
        match tab.get_mut(name).and_then(Item::as_value_mut) {
            Some(old) => {
                let decor = old.decor().clone();
                *old = new_value;
                *old.decor_mut() = decor;
            }
            None => {
                let mut item = value(new_value);
                if let Some(new) = item.as_value_mut() {
                    new.decor_mut().set_suffix(format!(" # {comment}"));
                }
                tab.insert(name, item);
            }
        }
    }
    Ok(doc.to_string())
}

/// Updates the file at `path` (created when missing) atomically: a temporary file beside it,
/// then a rename, so a crash never leaves half a file.
pub fn save(path: &Path, keys: &[(String, Saved)]) -> Result<(), SaveError> {
    let p = path.display().to_string();
    let io = |err| SaveError::Io { path: p.clone(), err };
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(io(e)),
    };
    let new = set_keys(&text, keys, &p)?;
    let tmp = path.with_extension("toml.tmp");
    std::fs::write(&tmp, new).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_given_keys_change_and_comments_stay() {
        let text = "# my overrides\n[steering]\n# tuned on the hall floor\nkp = 0.7 # keep\nkd = 0.1\n\n[sim]\nlaps = 2\n";
        let out = set_keys(text, &[("steering.kp".into(), 0.9.into()), ("throttle.base".into(), 0.3.into())], "local.toml").unwrap();
        assert!(out.starts_with("# my overrides\n[steering]\n# tuned on the hall floor\nkp = 0.9 # keep\nkd = 0.1\n"), "{out}");
        assert!(out.contains("[sim]\nlaps = 2\n"), "{out}");
        assert!(out.contains("[throttle]\nbase = 0.3 # throttle 0..1, allowed 0 ..= 1\n"), "{out}");
        let back: toml::Table = out.parse().unwrap();
        assert_eq!(back["steering"]["kp"].as_float(), Some(0.9));
    }

    #[test]
    fn a_comment_only_file_keeps_its_comment_on_top() {
        let out = set_keys("# mine\n", &[("steering.kp".into(), 1.05.into())], "l.toml").unwrap();
        assert_eq!(out, "# mine\n[steering]\nkp = 1.05 # steer per unit error, allowed 0 ..= 20\n");
        let out = set_keys("", &[("steering.lookahead_m".into(), 0.95.into())], "l.toml").unwrap();
        assert_eq!(out, "[steering]\nlookahead_m = 0.95 # m, allowed 0.1 ..= 5\n");
    }

    #[test]
    fn a_broken_file_is_left_alone_with_its_line() {
        let e = set_keys("[steering\nkp = 1", &[("steering.kp".into(), 0.9.into())], "local.toml").unwrap_err();
        assert!(e.to_string().contains("local.toml") && e.to_string().contains("line 1"), "{e}");
        let e = set_keys("steering = 3\n", &[("steering.kp".into(), 0.9.into())], "l.toml").unwrap_err();
        assert!(e.to_string().contains("not a table"), "{e}");
    }

    /// Only the tables' keys are written (the page can set nothing else either).
    #[test]
    fn a_key_outside_the_parameter_tables_is_refused() {
        for key in ["camera.fps", "steering.method", "kp"] {
            let e = set_keys("", &[(key.into(), 1.0.into())], "l.toml").unwrap_err().to_string();
            assert!(e.contains(&format!("`{key}`")) && e.contains("not a tunable parameter"), "{e}");
        }
    }

    /// The set-up page's keys: the ROI as an array of four [x, y] pairs, the threshold and
    /// the adaptive C as whole numbers, the mode as a string; the loader reads the file back
    /// to the same values, and a comment on an existing line stays.
    #[test]
    fn the_setup_keys_are_written_so_that_the_loader_reads_them_back() {
        let src = [[93.5, 79.25], [225.0, 78.96], [308.75, 150.02], [10.25, 150.0]];
        let keys = [
            ("warp.src".to_string(), Saved::Points(src)),
            ("lane.threshold".to_string(), Saved::Int(150)),
            ("lane.threshold_mode".to_string(), Saved::Text("otsu".into())),
            ("lane.adaptive_c".to_string(), Saved::Int(-8)),
            ("steering.kp".to_string(), 1.2.into()),
        ];
        let text = "# mine\n[lane]\nthreshold = 170 # my tape\n";
        let out = set_keys(text, &keys, "l.toml").unwrap();
        assert!(
            out.starts_with("# mine\n[lane]\nthreshold = 150 # my tape\nthreshold_mode = \"otsu\" # "),
            "{out}"
        );
        assert!(
            out.contains(
                "[warp]\nsrc = [[93.5, 79.25], [225.0, 78.96], [308.75, 150.02], [10.25, 150.0]] # ROI corners"
            ),
            "{out}"
        );
        let cfg = crate::config::Config::from_toml_str(&out, "l.toml").unwrap();
        assert_eq!(cfg.warp.src, src);
        assert_eq!(cfg.lane.threshold, 150);
        assert_eq!(cfg.lane.threshold_mode, crate::config::ThresholdMode::Otsu);
        assert_eq!(cfg.lane.adaptive_c, -8);
        assert_eq!(cfg.steering.kp, 1.2);
        // Written again (a second save), the line is replaced, not doubled.
        let again = set_keys(&out, &keys[..1], "l.toml").unwrap();
        assert_eq!(again, out);
        // A value of the wrong kind is refused with the key.
        let e = set_keys("", &[("warp.src".into(), 1.0.into())], "l.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("`warp.src`") && e.contains("not of this key's kind"), "{e}");
        let e = set_keys("", &[("steering.kp".into(), Saved::Int(1))], "l.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("takes a number"), "{e}");
    }
}
