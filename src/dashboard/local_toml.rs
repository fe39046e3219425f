//! Writes the dashboard's changed keys into `config/local.toml` in place: only those keys are
//! added or replaced; every other line, comment and table of the student's file is kept
//! (toml_edit keeps the document's formatting). Only keys of the parameter tables
//! ([`crate::control::catalog::all`]) are written; a key new to the file gets its unit and
//! allowed range as a comment on its line.

use std::path::Path;
use toml_edit::{value, DocumentMut, Item, Table};

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

/// `text` with each dotted `section.key` (a tunable parameter) set to its value (other content
/// kept as it was).
pub fn set_keys(text: &str, keys: &[(String, f64)], path: &str) -> Result<String, SaveError> {
    let mut doc: DocumentMut = text.parse().map_err(|e: toml_edit::TomlError| SaveError::Parse {
        path: path.into(),
        message: e.to_string().trim().replace('\n', " "),
    })?;
    for (key, v) in keys {
        let (Some((section, name)), Some(info)) = (key.split_once('.'), crate::control::catalog::find(key)) else {
            return Err(SaveError::Key {
                path: path.into(),
                key: key.clone(),
                why: "not a tunable parameter (src/control/params.rs)".into(),
            });
        };
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
                *old = toml_edit::Value::from(*v);
                *old.decor_mut() = decor;
            }
            None => {
                let mut item = value(*v);
                if let Some(new) = item.as_value_mut() {
                    let range = crate::control::params::show_range(info.range);
                    new.decor_mut().set_suffix(format!(" # {}, allowed {range}", info.unit));
                }
                tab.insert(name, item);
            }
        }
    }
    Ok(doc.to_string())
}

/// Updates the file at `path` (created when missing) atomically: a temporary file beside it,
/// then a rename, so a crash never leaves half a file.
pub fn save(path: &Path, keys: &[(String, f64)]) -> Result<(), SaveError> {
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
        let out = set_keys(text, &[("steering.kp".into(), 0.9), ("throttle.base".into(), 0.3)], "local.toml").unwrap();
        assert!(out.starts_with("# my overrides\n[steering]\n# tuned on the hall floor\nkp = 0.9 # keep\nkd = 0.1\n"), "{out}");
        assert!(out.contains("[sim]\nlaps = 2\n"), "{out}");
        assert!(out.contains("[throttle]\nbase = 0.3 # throttle 0..1, allowed 0 ..= 1\n"), "{out}");
        let back: toml::Table = out.parse().unwrap();
        assert_eq!(back["steering"]["kp"].as_float(), Some(0.9));
    }

    #[test]
    fn a_comment_only_file_keeps_its_comment_on_top() {
        let out = set_keys("# mine\n", &[("steering.kp".into(), 1.05)], "l.toml").unwrap();
        assert_eq!(out, "# mine\n[steering]\nkp = 1.05 # steer per unit error, allowed 0 ..= 20\n");
        let out = set_keys("", &[("steering.lookahead_m".into(), 0.95)], "l.toml").unwrap();
        assert_eq!(out, "[steering]\nlookahead_m = 0.95 # m, allowed 0.1 ..= 5\n");
    }

    #[test]
    fn a_broken_file_is_left_alone_with_its_line() {
        let e = set_keys("[steering\nkp = 1", &[("steering.kp".into(), 0.9)], "local.toml").unwrap_err();
        assert!(e.to_string().contains("local.toml") && e.to_string().contains("line 1"), "{e}");
        let e = set_keys("steering = 3\n", &[("steering.kp".into(), 0.9)], "l.toml").unwrap_err();
        assert!(e.to_string().contains("not a table"), "{e}");
    }

    /// Only the tables' keys are written (the page can set nothing else either).
    #[test]
    fn a_key_outside_the_parameter_tables_is_refused() {
        for key in ["camera.fps", "steering.method", "kp"] {
            let e = set_keys("", &[(key.into(), 1.0)], "l.toml").unwrap_err().to_string();
            assert!(e.contains(&format!("`{key}`")) && e.contains("not a tunable parameter"), "{e}");
        }
    }
}
