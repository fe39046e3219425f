//! Step-response figures of the lane keeper, from a time series of the true cross-track
//! error after the car was put off the lane centre (`rccar sim --start-offset M`) or kicked
//! sideways (`rccar sim --kick T:DY`): rise time, overshoot and settling time, the textbook
//! measures of a second-order loop (Ogata, *Modern Control Engineering*, Sec. 5-3), applied
//! to the PID of Rivera & Andaluz 2021 Eq. 2 closing the loop round the car.
//!
//! The set-point is the lane centre (cross-track error 0) and the step is the initial offset
//! `x0` (the first sample at or after the step time). With `r(t) = 1 − x(t)/x0` the part of
//! the way back to the centre:
//! 1. **rise time** = first time `r ≥ 0.9` minus first time `r ≥ 0.1` (10 → 90 %);
//! 2. **overshoot** = largest excursion past the centre, `max(−x·sign(x0))`, as % of `|x0|`
//!    (0 when the car never crosses);
//! 3. **settling time** = from the step to the last sample outside the band
//!    `|x| ≤ max(band_fraction·|x0|, band_min_m)` (5 % of the offset, at least 2 mm: the
//!    straight-road noise floor of the simulated camera is about 1.5 mm); `None` when the
//!    last sample is still outside.
//!
//! Pure functions of `(t, x)` slices; times in seconds, offsets in metres.

use serde::Serialize;

/// How the figures are taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOptions {
    /// Settling band as a fraction of the initial offset (0..1).
    pub band_fraction: f64,
    /// Smallest settling band, metres.
    pub band_min_m: f64,
    /// Only samples up to this long after the step are used, seconds (a later curve is not
    /// part of the step response).
    pub window_s: f64,
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            band_fraction: 0.05,
            band_min_m: 0.002,
            window_s: 10.0,
        }
    }
}

/// The step-response figures (`summary.json` → `"step"`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepMetrics {
    /// Time of the step, seconds.
    pub t0_s: f64,
    /// Cross-track error at the step, metres (+ = left of the lane centre).
    pub initial_offset_m: f64,
    /// Time from 10 % to 90 % of the way back, seconds (`None`: never got 90 % back).
    pub rise_time_s: Option<f64>,
    /// When the response first got 10 % of the way back, seconds after the step.
    pub rise_start_s: Option<f64>,
    /// When the response first got 90 % of the way back, seconds after the step.
    pub rise_end_s: Option<f64>,
    /// Largest excursion past the lane centre, % of |initial offset|.
    pub overshoot_pct: f64,
    /// When that excursion peaked, seconds after the step (`None`: no crossing).
    pub peak_s: Option<f64>,
    /// From the step to entering the settling band for good, seconds (`None`: not settled).
    pub settling_time_s: Option<f64>,
    /// Half-width of the settling band, metres.
    pub band_m: f64,
    /// Length of the analysed window, seconds.
    pub window_s: f64,
}

/// Why no figures could be taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// `t` and `x` differ in length.
    #[error("step response: {t} times but {x} values")]
    Length {
        /// Number of times.
        t: usize,
        /// Number of values.
        x: usize,
    },
    /// No sample at or after the step time.
    #[error("step response: no sample at or after t = {0} s")]
    NoSamples(f64),
    /// The offset at the step is too small to measure a response against.
    #[error("step response: the offset at the step is {0} m; it must be at least 1 mm")]
    TooSmall(f64),
}

/// A step-response request of `rccar sim`: a start offset (`kick` false, at t = 0) or a
/// kick sideways by `dy` metres at `t` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRequest {
    /// A kick during the run (else an offset at the start).
    pub kick: bool,
    /// When, seconds.
    pub t: f64,
    /// How far sideways, metres.
    pub dy: f64,
}

/// A `--start-offset` or `--kick` that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepRequestError {
    /// Both given.
    #[error("--start-offset and --kick: give one of them")]
    Both,
    /// Further than a lane width, or not a number.
    #[error("{what}: {dy} m is off the lane; give at most ±{lane_width} m (the lane width)")]
    OffLane {
        /// The flag.
        what: &'static str,
        /// The offset, metres.
        dy: f64,
        /// The lane width, metres.
        lane_width: f64,
    },
    /// `--kick` not of the form T:DY.
    #[error("--kick `{0}`: expected T:DY (seconds 0..=36000 : metres), e.g. 5:0.05")]
    Form(String),
}

impl StepRequest {
    /// Checks `--start-offset` and `--kick T:DY` (at most a lane width either way).
    pub fn parse(offset: Option<f64>, kick: Option<&str>, lane_width: f64) -> Result<Option<StepRequest>, StepRequestError> {
        let check = |what: &'static str, dy: f64| {
            if !dy.is_finite() || dy.abs() > lane_width {
                return Err(StepRequestError::OffLane { what, dy, lane_width });
            }
            Ok(())
        };
        match (offset, kick) {
            (Some(_), Some(_)) => Err(StepRequestError::Both),
            (Some(m), None) => {
                check("--start-offset", m)?;
                Ok(Some(StepRequest { kick: false, t: 0.0, dy: m }))
            }
            (None, Some(k)) => {
                let form = || StepRequestError::Form(k.to_string());
                let (t, dy) = k.split_once(':').ok_or_else(form)?;
                let t: f64 = t.trim().parse().ok().filter(|t: &f64| (0.0..=36_000.0).contains(t)).ok_or_else(form)?;
                let dy: f64 = dy.trim().parse().ok().filter(|d: &f64| d.is_finite()).ok_or_else(form)?;
                check("--kick", dy)?;
                Ok(Some(StepRequest { kick: true, t, dy }))
            }
            (None, None) => Ok(None),
        }
    }
}

impl StepMetrics {
    /// The figures as the terminal shows them, a line each.
    pub fn lines(&self) -> Vec<String> {
        let s = |v: Option<f64>| v.map_or("not reached".to_string(), |v| format!("{v:.2} s"));
        vec![
            format!(
                "  step response from {:+.4} m at t = {:.2} s (window {:.1} s):",
                self.initial_offset_m, self.t0_s, self.window_s
            ),
            format!("    rise time 10→90 %:  {}", s(self.rise_time_s)),
            format!("    overshoot:          {:.1} % of the offset", self.overshoot_pct),
            format!(
                "    settling time:      {} (band ±{:.1} mm = 5 % of the offset, at least 2 mm)",
                s(self.settling_time_s),
                self.band_m * 1000.0
            ),
        ]
    }
}

/// The step-response figures of `x` (metres) over `t` (seconds, increasing) for a step at
/// `t0` seconds.
pub fn step_metrics(t: &[f64], x: &[f64], t0: f64, opt: &StepOptions) -> Result<StepMetrics, StepError> {
    if t.len() != x.len() {
        return Err(StepError::Length { t: t.len(), x: x.len() });
    }
    let first = t
        .iter()
        .position(|&ti| ti >= t0 - 1e-9)
        .ok_or(StepError::NoSamples(t0))?;
    let end = t
        .iter()
        .position(|&ti| ti > t0 + opt.window_s + 1e-9)
        .unwrap_or(t.len());
    let (t, x) = (&t[first..end], &x[first..end]);
    let ts = t[0];
    let x0 = x[0];
    if !x0.is_finite() || x0.abs() < 1e-3 {
        return Err(StepError::TooSmall(x0));
    }
    let sign = x0.signum();
    // 1. Rise: the part of the way back, first crossings of 10 % and 90 %.
    let back = |xi: f64| 1.0 - xi / x0;
    let cross = |level: f64| t.iter().zip(x).find(|(_, &xi)| back(xi) >= level).map(|(&ti, _)| ti - ts);
    let (r10, r90) = (cross(0.1), cross(0.9));
    let rise = match (r10, r90) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    // 2. Overshoot: the largest excursion past the centre.
    let (mut peak, mut peak_t) = (0.0f64, None);
    for (&ti, &xi) in t.iter().zip(x) {
        let past = -xi * sign;
        if past > peak {
            peak = past;
            peak_t = Some(ti - ts);
        }
    }
    // 3. Settling: after the last sample outside the band.
    let band = (opt.band_fraction * x0.abs()).max(opt.band_min_m);
    let settling = match x.iter().rposition(|xi| xi.abs() > band) {
        None => Some(0.0),
        Some(i) if i + 1 < x.len() => Some(t[i + 1] - ts),
        Some(_) => None,
    };
    Ok(StepMetrics {
        t0_s: ts,
        initial_offset_m: x0,
        rise_time_s: rise,
        rise_start_s: r10,
        rise_end_s: r90,
        overshoot_pct: 100.0 * peak / x0.abs(),
        peak_s: peak_t,
        settling_time_s: settling,
        band_m: band,
        window_s: t.last().map_or(0.0, |l| l - ts),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x(t) = x0·(1 − s(t)) where s is the unit-step response of ωn²/(s² + 2ζωn s + ωn²).
    fn second_order(x0: f64, zeta: f64, wn: f64, dt: f64, t_end: f64) -> (Vec<f64>, Vec<f64>) {
        let wd = wn * (1.0 - zeta * zeta).sqrt();
        let phi = (1.0 - zeta * zeta).sqrt().atan2(zeta);
        let n = (t_end / dt).round() as usize;
        let t: Vec<f64> = (0..=n).map(|i| i as f64 * dt).collect();
        let x = t
            .iter()
            .map(|&ti| {
                let s = 1.0 - (-zeta * wn * ti).exp() / (1.0 - zeta * zeta).sqrt() * (wd * ti + phi).sin();
                x0 * (1.0 - s)
            })
            .collect();
        (t, x)
    }

    #[test]
    fn underdamped_second_order_matches_the_analytic_figures() {
        let (zeta, wn, x0) = (0.4, 3.0, 0.05);
        let (t, x) = second_order(x0, zeta, wn, 1e-4, 12.0);
        let opt = StepOptions {
            band_fraction: 0.05,
            band_min_m: 0.0,
            window_s: 100.0,
        };
        let m = step_metrics(&t, &x, 0.0, &opt).unwrap();
        // Overshoot exp(−ζπ/√(1−ζ²)), peak at π/ωd.
        let wd = wn * (1.0f64 - zeta * zeta).sqrt();
        let mp = 100.0 * (-zeta * std::f64::consts::PI / (1.0f64 - zeta * zeta).sqrt()).exp();
        assert!((m.overshoot_pct - mp).abs() < 0.01, "{} vs {mp}", m.overshoot_pct);
        assert!((m.peak_s.unwrap() - std::f64::consts::PI / wd).abs() < 1e-3);
        // 10-90 % rise time: solve s(t) = 0.1 and 0.9 by bisection on the closed form.
        let s = |ti: f64| {
            let phi = (1.0 - zeta * zeta).sqrt().atan2(zeta);
            1.0 - (-zeta * wn * ti).exp() / (1.0 - zeta * zeta).sqrt() * (wd * ti + phi).sin()
        };
        let solve = |lvl: f64| {
            let (mut a, mut b) = (0.0, std::f64::consts::PI / wd);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if s(m) < lvl {
                    a = m
                } else {
                    b = m
                }
            }
            a
        };
        let tr = solve(0.9) - solve(0.1);
        assert!((m.rise_time_s.unwrap() - tr).abs() < 2e-4, "{:?} vs {tr}", m.rise_time_s);
        // Settling into 5 %: the envelope exp(−ζωn t)/√(1−ζ²) reaches 5 % at
        // ln(20/√(1−ζ²))/(ζωn) = 2.57 s, an upper bound; the last exit is within half a
        // period (π/ωd = 1.14 s) before it.
        let ts = m.settling_time_s.unwrap();
        let bound = (20.0 / (1.0f64 - zeta * zeta).sqrt()).ln() / (zeta * wn);
        assert!(ts <= bound && ts > bound - std::f64::consts::PI / wd, "{ts} vs {bound}");
        // Check it directly: after ts inside the band, just before it outside.
        let k = t.iter().position(|&ti| ti >= ts).unwrap();
        assert!(x[k..].iter().all(|v| v.abs() <= 0.05 * x0 + 1e-12));
        assert!(x[k - 1].abs() > 0.05 * x0);
        assert!((m.band_m - 0.05 * x0).abs() < 1e-12);
    }

    #[test]
    fn overdamped_negative_step_has_no_overshoot() {
        // First order: x = x0·exp(−t/τ): rise 10→90 % = τ·ln 9, settling 5 % = τ·ln 20.
        let (x0, tau) = (-0.04, 0.5);
        let t: Vec<f64> = (0..=40000).map(|i| i as f64 * 1e-4).collect();
        let x: Vec<f64> = t.iter().map(|ti| x0 * (-ti / tau).exp()).collect();
        let opt = StepOptions {
            band_min_m: 0.0,
            ..Default::default()
        };
        let m = step_metrics(&t, &x, 0.0, &opt).unwrap();
        assert_eq!(m.overshoot_pct, 0.0);
        assert_eq!(m.peak_s, None);
        assert!((m.rise_time_s.unwrap() - tau * 9f64.ln()).abs() < 3e-4);
        assert!((m.settling_time_s.unwrap() - tau * 20f64.ln()).abs() < 3e-4);
    }

    #[test]
    fn step_later_in_the_series_and_window() {
        // Zero until 2 s, then a kick of 3 cm decaying; a disturbance at 9 s outside the window.
        let t: Vec<f64> = (0..=1000).map(|i| i as f64 * 0.01).collect();
        let x: Vec<f64> = t
            .iter()
            .map(|&ti| {
                if ti >= 9.0 {
                    0.05
                } else if ti >= 2.0 {
                    0.03 * (-(ti - 2.0) / 0.3).exp()
                } else {
                    0.0
                }
            })
            .collect();
        let opt = StepOptions {
            window_s: 5.0,
            ..Default::default()
        };
        let m = step_metrics(&t, &x, 2.0, &opt).unwrap();
        assert!((m.t0_s - 2.0).abs() < 1e-9);
        assert!((m.initial_offset_m - 0.03).abs() < 1e-12);
        // Band: max(5 % of 3 cm, 2 mm) = 2 mm → 0.3·ln(15) s.
        assert!((m.band_m - 0.002).abs() < 1e-12);
        assert!((m.settling_time_s.unwrap() - 0.3 * 15f64.ln()).abs() < 0.011);
        assert!((m.window_s - 5.0).abs() < 1e-9);
        // With a window reaching 9 s the disturbance makes it "not settled".
        let long = StepOptions { window_s: 20.0, ..opt };
        assert_eq!(step_metrics(&t, &x, 2.0, &long).unwrap().settling_time_s, None);
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        assert!(matches!(step_metrics(&[0.0], &[], 0.0, &StepOptions::default()), Err(StepError::Length { .. })));
        assert_eq!(step_metrics(&[0.0, 1.0], &[0.1, 0.0], 5.0, &StepOptions::default()), Err(StepError::NoSamples(5.0)));
        assert!(matches!(step_metrics(&[0.0, 1.0], &[0.0, 0.0], 0.0, &StepOptions::default()), Err(StepError::TooSmall(_))));
        assert!(matches!(step_metrics(&[], &[], 0.0, &StepOptions::default()), Err(StepError::NoSamples(_))));
    }
}
