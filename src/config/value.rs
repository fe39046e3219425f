//! Configuration values as TOML: a section (or the whole configuration) as a table, and the
//! value or number at a dotted key such as `steering.kp` or `warp.src[1][0]`. Shared by the
//! loader ([`super::layers`]), the range checks ([`super::check`]) and the class map
//! ([`super::classes`]); it imports none of them.

use serde::Serialize;

/// `v` (a configuration type) as a TOML table.
pub(super) fn to_table<T: Serialize>(v: &T) -> toml::Table {
    toml::Table::try_from(v).expect("config types always serialise")
}

/// The value at a serde path such as `steering.kp` or `warp.src[1][0]`.
pub(super) fn lookup<'a>(t: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut cur: Option<&toml::Value> = None;
    for part in path.split('.') {
        let (name, idx) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        cur = match cur {
            None => t.get(name),
            Some(toml::Value::Table(s)) => s.get(name),
            _ => None,
        };
        for i in idx.split(['[', ']']).filter(|s| !s.is_empty()) {
            cur = match (cur, i.parse::<usize>()) {
                (Some(toml::Value::Array(a)), Ok(i)) => a.get(i),
                _ => None,
            };
        }
    }
    cur
}

/// The number at a dotted key of a serialised section or configuration.
pub(super) fn number_at(t: &toml::Table, key: &str) -> Option<f64> {
    match lookup(t, key)? {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}
