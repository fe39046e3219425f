//! Throttle policy: drive at a base speed, slower as the lane error grows (curves), and stop
//! once the lane has been lost for a while. Time is passed in. Its tunable parameters are a
//! table ([`Params`]) like the steering methods'.

use super::params::{Param, ParamInfo, Params};

/// The policy's settings (`[throttle]` of car.toml converts into them). Throttle 0..=1.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrottleOptions {
    /// Throttle on a straight with zero error.
    pub base: f64,
    /// Lowest throttle while the lane is seen (at most `base`).
    pub min: f64,
    /// Throttle drop per unit of |normalised error|.
    pub error_slowdown: f64,
    /// Once the lane has been lost this long, seconds, the throttle is zero.
    pub lost_timeout_s: f64,
}

/// The throttle policy and how long the lane has been lost.
#[derive(Debug, Clone, PartialEq)]
pub struct Throttle {
    cfg: ThrottleOptions,
    lost_for_s: f64,
}

impl Throttle {
    /// A policy with these settings.
    pub fn new(cfg: ThrottleOptions) -> Self {
        Self { cfg, lost_for_s: 0.0 }
    }

    /// Throttle (0..=base) for this frame. `error` is the normalised lane error, `None` when
    /// the lane is lost; `dt` seconds since the previous frame.
    pub fn update(&mut self, error: Option<f64>, dt: f64) -> f64 {
        let c = &self.cfg;
        match error {
            Some(e) if e.is_finite() => {
                self.lost_for_s = 0.0;
                (c.base - c.error_slowdown * e.abs()).clamp(c.min.min(c.base), c.base)
            }
            _ => {
                if dt.is_finite() && dt > 0.0 {
                    self.lost_for_s += dt;
                }
                // Creep at the minimum while hoping to see the lane again, then stop.
                if self.lost_for_s >= c.lost_timeout_s {
                    0.0
                } else {
                    c.min.min(c.base)
                }
            }
        }
    }

    /// The policy's settings.
    pub fn options(&self) -> &ThrottleOptions {
        &self.cfg
    }

    /// The policy's settings, to change between frames (a dashboard does it by key through
    /// [`Params`]).
    pub fn options_mut(&mut self) -> &mut ThrottleOptions {
        &mut self.cfg
    }

    /// Seconds since the lane was last seen (0 while it is seen).
    pub fn lost_for_s(&self) -> f64 {
        self.lost_for_s
    }
}

impl Params for Throttle {
    const PARAMS: &'static [Param<Throttle>] = &[
        Param {
            info: ParamInfo {
                key: "throttle.base",
                unit: "throttle 0..1",
                range: [0.0, 1.0],
                slider: [0.0, 1.0, 0.01],
                doc: "throttle on a straight with zero error",
            },
            get: |t| t.cfg.base,
            set: |t, v| t.cfg.base = v,
        },
        Param {
            info: ParamInfo {
                key: "throttle.min",
                unit: "throttle 0..1",
                range: [0.0, 1.0],
                slider: [0.0, 1.0, 0.01],
                doc: "lowest throttle while the lane is seen (at most throttle.base)",
            },
            get: |t| t.cfg.min,
            set: |t, v| t.cfg.min = v,
        },
        Param {
            info: ParamInfo {
                key: "throttle.error_slowdown",
                unit: "throttle per unit error",
                range: [0.0, 5.0],
                slider: [0.0, 2.0, 0.05],
                doc: "throttle taken off per unit of |lane error|: slows down in curves",
            },
            get: |t| t.cfg.error_slowdown,
            set: |t, v| t.cfg.error_slowdown = v,
        },
        Param {
            info: ParamInfo {
                key: "throttle.lost_timeout_s",
                unit: "s",
                range: [0.0, 60.0],
                slider: [0.0, 5.0, 0.1],
                doc: "after the lane has been lost this long the throttle is zero",
            },
            get: |t| t.cfg.lost_timeout_s,
            set: |t, v| t.cfg.lost_timeout_s = v,
        },
    ];
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> ThrottleOptions {
        ThrottleOptions {
            base: 0.5,
            min: 0.2,
            error_slowdown: 0.6,
            lost_timeout_s: 0.5,
        }
    }

    #[test]
    fn slows_down_with_error_but_not_below_min() {
        let mut t = Throttle::new(cfg());
        assert!((t.update(Some(0.0), 0.1) - 0.5).abs() < 1e-12);
        assert!((t.update(Some(-0.25), 0.1) - 0.35).abs() < 1e-12);
        assert!((t.update(Some(1.0), 0.1) - 0.2).abs() < 1e-12);
    }

    #[test]
    fn stops_after_the_lane_is_lost_for_the_timeout() {
        let mut t = Throttle::new(cfg());
        let dt = 1.0 / 30.0;
        let mut stopped_at = None;
        for k in 1..=30 {
            if t.update(None, dt) == 0.0 && stopped_at.is_none() {
                stopped_at = Some(k);
            }
        }
        // 0.5 s at 30 fps: the 15th lost frame reaches the timeout (within float rounding).
        assert!(matches!(stopped_at, Some(15) | Some(16)), "{stopped_at:?}");
        // Seeing the lane again resets the timer.
        assert!(t.update(Some(0.0), dt) > 0.0);
        assert_eq!(t.lost_for_s(), 0.0);
    }
}
