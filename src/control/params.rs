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

/// Every tunable parameter of every steering method and of the throttle, each key once (a
/// limit that two methods share, such as `steering.max_steer`, appears once): what the
/// configuration checks.
pub fn all() -> Vec<ParamInfo> {
    let mut out: Vec<ParamInfo> = Vec::new();
    let tables = super::steering::SteeringMethod::ALL
        .iter()
        .flat_map(|m| m.params())
        .chain(infos(super::throttle::Throttle::PARAMS));
    for p in tables {
        if !out.iter().any(|q| q.key == p.key) {
            out.push(p);
        }
    }
    out
}

/// The parameters of a run that steers with `method`: the method's table, then the
/// throttle's (what [`super::Controller::params`] returns; what the dashboard may change).
pub fn of_method(method: super::steering::SteeringMethod) -> Vec<ParamInfo> {
    let mut p = method.params();
    p.extend(infos(super::throttle::Throttle::PARAMS));
    p
}

/// The row of `key` among [`all`].
pub fn find(key: &str) -> Option<ParamInfo> {
    all().into_iter().find(|p| p.key == key)
}

/// `"lo ..= hi"` of a range, as the configuration's errors print it.
pub fn show_range(r: [f64; 2]) -> String {
    format!("{} ..= {}", r[0], r[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_is_consistent() {
        for p in all() {
            let [lo, hi] = p.range;
            let [slo, shi, step] = p.slider;
            assert!(lo < hi && lo.is_finite() && hi.is_finite(), "{}: range {lo}..{hi}", p.key);
            assert!(lo <= slo && slo < shi && shi <= hi, "{}: slider {slo}..{shi} outside {lo}..{hi}", p.key);
            assert!(step > 0.0 && step <= (shi - slo) / 4.0, "{}: step {step}", p.key);
            assert!(!p.doc.is_empty() && !p.doc.contains('\n'), "{}: doc", p.key);
            assert!(p.key.starts_with("steering.") || p.key.starts_with("throttle."), "{}", p.key);
        }
    }

    /// A limit two methods share has one description (else the check would depend on which
    /// table came first).
    #[test]
    fn shared_keys_agree_between_tables() {
        let rows: Vec<ParamInfo> = super::super::steering::SteeringMethod::ALL
            .iter()
            .flat_map(|m| m.params())
            .collect();
        for a in &rows {
            for b in rows.iter().filter(|b| b.key == a.key) {
                assert_eq!(a, b, "{} described twice, differently", a.key);
            }
        }
    }
}
