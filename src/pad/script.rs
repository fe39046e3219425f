//! Recorded pad event sequences as text (tests/data/pad/*.txt): one event per line,
//! `TIME_MS KIND ...`, times never going back; `#` starts a comment.
//!
//! ```text
//! 0     connect  Xbox Wireless Controller     the pad is found (its name)
//! 0     range    ABS_RY -32768 32767          an axis's range (default: this one)
//! 100   key      BTN_TL 1                     a button: 1 down, 0 up, 2 repeat
//! 140   abs      ABS_RY -16384                an axis's raw value
//! 400   tick                                  time passes (the device thread ticks)
//! 900   disconnect  ENODEV                    the pad is gone (why)
//! ```
//!
//! Keys and axes are named as `evtest` prints them (`BTN_SOUTH`, `BTN_TL`, `ABS_X`, …, see
//! [`super::machine::code::NAMES`]) or given as numbers (`0x136`, `310`).

use super::machine::{code, AxisRange, PadEvent};

/// A line that cannot be read: which, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {why}")]
pub struct ScriptError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub why: String,
}

fn parse_code(s: &str) -> Option<u16> {
    code::by_name(s).or_else(|| match s.strip_prefix("0x") {
        Some(hex) => u16::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    })
}

/// Reads a recorded sequence: `(time ms, event)` in order.
pub fn parse(text: &str) -> Result<Vec<(u64, PadEvent)>, ScriptError> {
    let mut out = Vec::new();
    let mut last = 0u64;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let err = |why: String| ScriptError { line: i + 1, why };
        let mut words = line.split_whitespace();
        let (Some(t), Some(kind)) = (words.next(), words.next()) else {
            return Err(err(format!("`{line}`: expected TIME_MS KIND ...")));
        };
        let t: u64 = t
            .parse()
            .map_err(|_| err(format!("`{t}`: not a time in whole milliseconds")))?;
        if t < last {
            return Err(err(format!("time {t} ms goes back (the line before says {last} ms)")));
        }
        last = t;
        let rest: Vec<&str> = words.collect();
        let code_of =
            |w: &str| parse_code(w).ok_or_else(|| err(format!("`{w}`: not a key or axis name, nor a number")));
        let int = |w: &str| w.parse::<i32>().map_err(|_| err(format!("`{w}`: not a whole number")));
        let ev = match (kind, rest.as_slice()) {
            ("connect", name) => PadEvent::Connected(name.join(" ")),
            ("disconnect", why) => PadEvent::Disconnected(why.join(" ")),
            ("tick", []) => PadEvent::Tick,
            ("key", [c, v]) => PadEvent::Key { code: code_of(c)?, value: int(v)? },
            ("abs", [c, v]) => PadEvent::Abs { code: code_of(c)?, value: int(v)? },
            ("range", [c, lo, hi]) => PadEvent::Range {
                code: code_of(c)?,
                range: AxisRange { min: int(lo)?, max: int(hi)? },
            },
            _ => {
                return Err(err(format!(
                    "`{line}`: expected `connect NAME`, `range AXIS MIN MAX`, `key KEY 0|1|2`, `abs AXIS VALUE`, `tick` or `disconnect WHY`"
                )))
            }
        };
        out.push((t, ev));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_every_kind_and_names_a_bad_line() {
        let s = parse("# a pad\n0 connect Pad 1\n0 range ABS_X -10 10\n5 key BTN_TL 1\n6 abs 0x04 -3\n7 tick\n8 disconnect ENODEV\n").unwrap();
        assert_eq!(s.len(), 6);
        assert_eq!(s[0], (0, PadEvent::Connected("Pad 1".into())));
        assert_eq!(
            s[2],
            (
                5,
                PadEvent::Key {
                    code: code::BTN_TL,
                    value: 1
                }
            )
        );
        assert_eq!(
            s[3],
            (
                6,
                PadEvent::Abs {
                    code: code::ABS_RY,
                    value: -3
                }
            )
        );
        assert_eq!(parse("0 tick\n\n3 key BTN_NOPE 1").unwrap_err().line, 3);
        assert!(parse("5 tick\n4 tick").unwrap_err().why.contains("goes back"));
        assert!(parse("1 wiggle").is_err());
    }
}
