//! Tunable parameters, published once by the part they tune.
//!
//! Each control part (a steering method, the throttle policy) declares a table of its
//! parameters ([`Params::PARAMS`]): the config key, its unit, the range the configuration
//! allows, a slider's span for the dashboard, a one-line doc, and how to read and set the
//! value on the running part. Everything that names a tunable key reads that table instead of
//! listing the keys again:
//! - the configuration's range checks of `[steering]` and `[throttle]` (so `--set`,
//!   `config/local.toml` and the dashboard refuse the same values);
//! - the dashboard (which keys it may change live, their sliders, units and docs, the values in
//!   force; src/dashboard/, its server src/dashboard/server/);
//! - `sim --sweep` (axis units, and a key of a steering method the run does not use is refused);
//! - saving to `config/local.toml` (only table keys; a new key gets its unit and range as a
//!   comment).
//!
//! [`ParamInfo`] is the table row without the accessors (what a UI shows); [`Tunable`] is the
//! object-safe access every [`Params`] type gets for free, so a `Box<dyn Steering>` can be
//! read and tuned by key.

/// What a UI shows of one parameter: the table row without its accessors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamInfo {
    /// Dotted config key, e.g. `steering.kp`.
    pub key: &'static str,
    /// Unit, e.g. `steer per unit error`, `m`, `s` (empty: none).
    pub unit: &'static str,
    /// Allowed values, inclusive: the configuration refuses others, and so do the dashboard
    /// and `--set`.
    pub range: [f64; 2],
    /// The dashboard slider's `[low, high, step]` (within `range`; the useful span).
    pub slider: [f64; 3],
    /// One line: what the parameter does.
    pub doc: &'static str,
}

/// One row of a part's parameter table: what it is and how to read and set it on a running
/// `T` (a change acts from the next step on).
pub struct Param<T> {
    /// The row's description.
    pub info: ParamInfo,
    /// Reads the value in force.
    pub get: fn(&T) -> f64,
    /// Sets it (the caller has checked it against `info.range`).
    pub set: fn(&mut T, f64),
}

/// A part with a parameter table. Implement this (one `const`); [`Tunable`] follows.
pub trait Params: Sized + 'static {
    /// The part's tunable parameters, each once.
    const PARAMS: &'static [Param<Self>];
}

/// Reading and setting a part's parameters by key, through a trait object.
pub trait Tunable {
    /// The parameters, in table order.
    fn params(&self) -> Vec<ParamInfo>;
    /// The value in force of `key` (`None`: not a parameter of this part).
    fn get_param(&self, key: &str) -> Option<f64>;
    /// Sets `key` to `value` from the next step on; `false` when `key` is not a parameter of
    /// this part. The value is not checked here: the configuration's range is the check.
    fn set_param(&mut self, key: &str, value: f64) -> bool;
}

impl<T: Params> Tunable for T {
    fn params(&self) -> Vec<ParamInfo> {
        infos(T::PARAMS)
    }

    fn get_param(&self, key: &str) -> Option<f64> {
        T::PARAMS.iter().find(|p| p.info.key == key).map(|p| (p.get)(self))
    }

    fn set_param(&mut self, key: &str, value: f64) -> bool {
        match T::PARAMS.iter().find(|p| p.info.key == key) {
            Some(p) => {
                (p.set)(self, value);
                true
            }
            None => false,
        }
    }
}

/// The descriptions of a table's rows.
pub fn infos<T>(table: &[Param<T>]) -> Vec<ParamInfo> {
    table.iter().map(|p| p.info).collect()
}

/// `"lo ..= hi"` of a range, as the configuration's errors print it.
pub fn show_range(r: [f64; 2]) -> String {
    format!("{} ..= {}", r[0], r[1])
}
