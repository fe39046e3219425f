//! The catalogue of tunable parameters: which steering method publishes which of them, and
//! every key of every method and of the throttle, each once.
//!
//! Each part publishes its own table ([`super::params::Params`]); this file only gathers them,
//! so it stands above the parts ([`super::pid`], [`super::pure_pursuit`], [`super::throttle`])
//! and the parts never look at each other's tables. What reads the catalogue: the
//! configuration's range checks ([`all`]), the dashboard and `local.toml` saving ([`of_method`],
//! [`find`]), `sim --sweep` and the dashboard's refusal of another method's key ([`unused_by`]).
//! A new steering method adds its table in [`SteeringMethod::params`] here (docs/control.md,
//! "Adding a steering method").

use super::params::{infos, ParamInfo, Params};
use super::learned::Learned;
use super::pid::Pid;
use super::pure_pursuit::PurePursuit;
use super::steering::SteeringMethod;
use super::throttle::Throttle;

impl SteeringMethod {
    /// The method's parameter table.
    pub fn params(self) -> Vec<ParamInfo> {
        match self {
            SteeringMethod::Pid => infos(Pid::PARAMS),
            SteeringMethod::PurePursuit => infos(PurePursuit::PARAMS),
            SteeringMethod::Learned => infos(Learned::PARAMS),
        }
    }

    /// Whether `key` is one of this method's parameters.
    pub fn uses(self, key: &str) -> bool {
        self.params().iter().any(|p| p.key == key)
    }
}

/// Why `key` does nothing in a run that steers with `method`: `Some(reason)` when it is a
/// parameter of other steering methods only, `None` otherwise (one of `method`'s, the
/// throttle's, or not a steering parameter at all).
pub fn unused_by(method: SteeringMethod, key: &str) -> Option<String> {
    if method.uses(key) {
        return None;
    }
    let owners: Vec<&str> = SteeringMethod::ALL
        .iter()
        .filter(|m| m.uses(key))
        .map(|m| m.name())
        .collect();
    (!owners.is_empty()).then(|| {
        format!(
            "`{key}` is a parameter of steering.method = {}, and this run steers with {} (add --set steering.method={})",
            owners.join(" or "),
            method.name(),
            owners[0]
        )
    })
}

/// Every tunable parameter of every steering method and of the throttle, each key once (a
/// limit that two methods share, such as `steering.max_steer`, appears once): what the
/// configuration checks.
pub fn all() -> Vec<ParamInfo> {
    let mut out: Vec<ParamInfo> = Vec::new();
    let tables = SteeringMethod::ALL
        .iter()
        .flat_map(|m| m.params())
        .chain(infos(Throttle::PARAMS));
    for p in tables {
        if !out.iter().any(|q| q.key == p.key) {
            out.push(p);
        }
    }
    out
}

/// The parameters of a run that steers with `method`: the method's table, then the
/// throttle's (what [`super::Controller::params`] returns; what the dashboard may change).
pub fn of_method(method: SteeringMethod) -> Vec<ParamInfo> {
    let mut p = method.params();
    p.extend(infos(Throttle::PARAMS));
    p
}

/// The row of `key` among [`all`].
pub fn find(key: &str) -> Option<ParamInfo> {
    all().into_iter().find(|p| p.key == key)
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
        let rows: Vec<ParamInfo> = SteeringMethod::ALL
            .iter()
            .flat_map(|m| m.params())
            .collect();
        for a in &rows {
            for b in rows.iter().filter(|b| b.key == a.key) {
                assert_eq!(a, b, "{} described twice, differently", a.key);
            }
        }
    }

    #[test]
    fn a_key_of_another_method_is_named_with_its_owner() {
        assert_eq!(unused_by(SteeringMethod::Pid, "steering.kp"), None);
        assert_eq!(unused_by(SteeringMethod::Pid, "throttle.base"), None);
        assert_eq!(unused_by(SteeringMethod::PurePursuit, "steering.max_steer"), None);
        let why = unused_by(SteeringMethod::Pid, "steering.lookahead_m").unwrap();
        assert!(why.contains("pure_pursuit") && why.contains("steers with pid"), "{why}");
        let why = unused_by(SteeringMethod::PurePursuit, "steering.kd").unwrap();
        assert!(why.contains("steering.method = pid"), "{why}");
    }
}
