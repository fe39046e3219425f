//! The HC-SR04 ultrasonic sensor as an emergency brake that does not depend on vision.
//!
//! How the sensor works (HC-SR04 datasheet): a 10 µs high pulse on TRIG makes it send a burst
//! of 40 kHz sound; ECHO then goes high and stays high until the echo comes back, so the
//! pulse width `w` is the sound's round trip. With no echo the module gives up after about
//! 38 ms and drops ECHO anyway. Its range is 2 cm to 4 m.
//!
//! 1. Speed of sound in air at `T` °C: `c = 331.3 · sqrt(1 + T / 273.15)` m/s
//!    (343.2 m/s at 20 °C; 1 °C changes it by about 0.18 %).
//! 2. Distance: `d = c · w / 2` metres (out and back).
//! 3. Plausibility: no ECHO rise at all ([`EchoReading::NoEcho`]: the sensor does not answer,
//!    e.g. unplugged), ECHO still high after the timeout ([`EchoReading::Timeout`]), or `d`
//!    outside `min_range_m ..= max_range_m`: no distance (`None`).
//! 4. A median over the last `median_n` readings removes single wrong readings (a sound
//!    burst reflected by the floor, a missed echo). A reading without a distance counts as
//!    "farther than anything" in the median, so one missing echo among near readings does not
//!    hide an obstacle, and a majority of missing echoes means "nothing ahead".
//! 5. Brake decision with hysteresis: brake when the filtered distance is nearer than
//!    `brake_m`, release only beyond `release_m` (or when nothing is in range), so a reading
//!    that wavers around the threshold does not make the car jerk.
//!
//! Everything here is pure: the hardware layer (`gpio::pi`) measures edge timestamps and
//! passes them in (seconds, f64), this module decides. A sensor that stops answering
//! ([`EchoReading::NoEcho`] `fault_after` times in a row) is reported by
//! [`UltrasonicOutput::sensor_ok`]: the caller decides whether that stops the car.

use std::collections::VecDeque;

/// Speed of sound in dry air at `temp_c` degrees Celsius, m/s (step 1).
pub fn speed_of_sound(temp_c: f64) -> f64 {
    331.3 * (1.0 + temp_c / 273.15).max(0.0).sqrt()
}

/// The sensor's options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UltrasonicOptions {
    /// Air temperature at the sensor, °C (sets the speed of sound).
    pub temp_c: f64,
    /// Nearest distance the sensor measures, metres (HC-SR04: 0.02).
    pub min_range_m: f64,
    /// Farthest distance that counts, metres (HC-SR04: 4.0); farther = nothing ahead.
    pub max_range_m: f64,
    /// Readings in the median (1 = no filter). At one reading per 60 ms the median of n
    /// lags a steady approach by (n - 1) / 2 readings: 60 ms for 3, 120 ms for 5.
    pub median_n: usize,
    /// Brake when the filtered distance is nearer than this, metres.
    pub brake_m: f64,
    /// Release the brake when the filtered distance is beyond this (or nothing is in range),
    /// metres; more than `brake_m`.
    pub release_m: f64,
    /// The sensor counts as failed after this many readings in a row without an echo rise.
    pub fault_after: u32,
}

impl Default for UltrasonicOptions {
    fn default() -> Self {
        Self {
            temp_c: 20.0,
            min_range_m: 0.02,
            max_range_m: 4.0,
            median_n: 3,
            brake_m: 0.35,
            release_m: 0.50,
            fault_after: 5,
        }
    }
}

/// One measurement as the hardware saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EchoReading {
    /// ECHO was high for this long, seconds.
    Pulse {
        /// Width of the echo pulse, seconds.
        width_s: f64,
    },
    /// ECHO never rose after the trigger: the sensor did not answer.
    NoEcho,
    /// ECHO rose but had not fallen when we stopped waiting.
    Timeout,
}

/// Timeouts for turning recorded edge times into a reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EchoTimeouts {
    /// ECHO must rise within this time after the trigger pulse ends, seconds
    /// (the HC-SR04 rises after its 8-cycle burst, about 0.5 ms).
    pub rise_s: f64,
    /// ECHO must fall within this time after it rose, seconds (the module's own no-echo
    /// timeout is about 38 ms; 30 ms = 5 m at 20 °C covers its 4 m range).
    pub width_s: f64,
}

impl Default for EchoTimeouts {
    fn default() -> Self {
        Self {
            rise_s: 0.005,
            width_s: 0.030,
        }
    }
}

/// Turns the timestamps of one measurement (seconds, one clock) into a reading: `trigger_end`
/// is when the trigger pulse ended, `rise` and `fall` the first ECHO edges seen after it
/// (`None` = not seen before the caller stopped waiting).
pub fn reading_from_edges(trigger_end: f64, rise: Option<f64>, fall: Option<f64>, to: EchoTimeouts) -> EchoReading {
    let Some(rise) = rise.filter(|r| r.is_finite() && *r >= trigger_end && *r - trigger_end <= to.rise_s) else {
        return EchoReading::NoEcho;
    };
    match fall.filter(|f| f.is_finite()) {
        Some(fall) if fall >= rise && fall - rise <= to.width_s => EchoReading::Pulse { width_s: fall - rise },
        _ => EchoReading::Timeout,
    }
}

/// The reading an ideal sensor gives for an obstacle `distance_m` metres away (`None`:
/// nothing in front), at `temp_c` °C: a pulse of `2 d / c`, or a timeout beyond `timeout_s`.
/// For the simulator, which knows the true distance, and for tests.
pub fn ideal_reading(distance_m: Option<f64>, temp_c: f64, timeout_s: f64) -> EchoReading {
    match distance_m.filter(|d| d.is_finite() && *d >= 0.0) {
        Some(d) if 2.0 * d / speed_of_sound(temp_c) <= timeout_s => EchoReading::Pulse {
            width_s: 2.0 * d / speed_of_sound(temp_c),
        },
        _ => EchoReading::Timeout,
    }
}

/// Distance of one echo pulse of `width_s` seconds, metres, or `None` when it is outside
/// the plausible range (steps 2-3).
pub fn echo_distance(width_s: f64, opts: &UltrasonicOptions) -> Option<f64> {
    if !(width_s.is_finite() && width_s > 0.0) {
        return None;
    }
    let d = speed_of_sound(opts.temp_c) * width_s / 2.0;
    (d >= opts.min_range_m && d <= opts.max_range_m).then_some(d)
}

/// The distance of a reading, if it has a plausible one.
pub fn reading_distance(r: EchoReading, opts: &UltrasonicOptions) -> Option<f64> {
    match r {
        EchoReading::Pulse { width_s } => echo_distance(width_s, opts),
        EchoReading::NoEcho | EchoReading::Timeout => None,
    }
}

/// Median of the last N distances, with "no distance" counted as farther than anything
/// (step 4).
#[derive(Debug, Clone)]
pub struct MedianFilter {
    n: usize,
    window: VecDeque<Option<f64>>,
    scratch: Vec<f64>,
}

impl MedianFilter {
    /// A filter over the last `n` readings (at least 1).
    pub fn new(n: usize) -> Self {
        let n = n.max(1);
        Self {
            n,
            window: VecDeque::with_capacity(n),
            scratch: Vec::with_capacity(n),
        }
    }

    /// Adds a reading and returns the median of the window: the middle value (the upper of
    /// the two middle ones for an even count, i.e. the farther: a brake needs a majority),
    /// `None` when that middle value is "no distance".
    pub fn push(&mut self, d: Option<f64>) -> Option<f64> {
        if self.window.len() == self.n {
            self.window.pop_front();
        }
        self.window.push_back(d.filter(|v| v.is_finite()));
        self.scratch.clear();
        self.scratch
            .extend(self.window.iter().map(|v| v.unwrap_or(f64::INFINITY)));
        self.scratch.sort_by(f64::total_cmp);
        let m = self.scratch[self.scratch.len() / 2];
        m.is_finite().then_some(m)
    }

    /// Forgets every reading.
    pub fn clear(&mut self) {
        self.window.clear();
    }
}

/// The brake decision with hysteresis (step 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeDecision {
    brake_m: f64,
    release_m: f64,
    braking: bool,
}

impl BrakeDecision {
    /// Not braking; brake nearer than `brake_m`, release beyond `release_m` (≥ `brake_m`).
    pub fn new(brake_m: f64, release_m: f64) -> Self {
        Self {
            brake_m,
            release_m: release_m.max(brake_m),
            braking: false,
        }
    }

    /// The decision after one filtered distance (`None` = nothing in range).
    pub fn update(&mut self, distance_m: Option<f64>) -> bool {
        self.braking = match distance_m {
            Some(d) if d < self.brake_m => true,
            Some(d) if d > self.release_m => false,
            Some(_) => self.braking,
            None => false,
        };
        self.braking
    }

    /// Whether the brake is on.
    pub fn braking(&self) -> bool {
        self.braking
    }
}

/// What the sensor says after one reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UltrasonicOutput {
    /// This reading's distance, metres (`None`: no plausible echo).
    pub raw_m: Option<f64>,
    /// The median-filtered distance, metres (`None`: nothing in range).
    pub distance_m: Option<f64>,
    /// Stop the car: an obstacle is nearer than `brake_m` (until beyond `release_m`).
    pub brake: bool,
    /// False once the sensor has not answered `fault_after` times in a row.
    pub sensor_ok: bool,
}

/// The whole chain: reading → distance → median → brake. See the module documentation.
#[derive(Debug, Clone)]
pub struct Ultrasonic {
    opts: UltrasonicOptions,
    median: MedianFilter,
    brake: BrakeDecision,
    no_echo_run: u32,
    last: UltrasonicOutput,
}

impl Ultrasonic {
    /// A sensor with no readings yet (nothing in range, no brake, sensor ok).
    pub fn new(opts: UltrasonicOptions) -> Self {
        Self {
            median: MedianFilter::new(opts.median_n),
            brake: BrakeDecision::new(opts.brake_m, opts.release_m),
            no_echo_run: 0,
            last: UltrasonicOutput {
                raw_m: None,
                distance_m: None,
                brake: false,
                sensor_ok: true,
            },
            opts,
        }
    }

    /// Takes one reading and returns the new state.
    pub fn push(&mut self, r: EchoReading) -> UltrasonicOutput {
        let raw = reading_distance(r, &self.opts);
        self.no_echo_run = if r == EchoReading::NoEcho {
            self.no_echo_run.saturating_add(1)
        } else {
            0
        };
        let distance_m = self.median.push(raw);
        let brake = self.brake.update(distance_m);
        self.last = UltrasonicOutput {
            raw_m: raw,
            distance_m,
            brake,
            sensor_ok: self.no_echo_run < self.opts.fault_after.max(1),
        };
        self.last
    }

    /// The state after the last reading.
    pub fn last(&self) -> UltrasonicOutput {
        self.last
    }

    /// The options in use.
    pub fn options(&self) -> &UltrasonicOptions {
        &self.opts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: f64 = 1e-6;

    #[test]
    fn speed_of_sound_matches_tables() {
        // Tabulated values for dry air: 331.3 m/s at 0 °C, 343.2 at 20 °C, 349.0 at 30 °C.
        assert!((speed_of_sound(0.0) - 331.3).abs() < 1e-9);
        assert!((speed_of_sound(20.0) - 343.2).abs() < 0.1);
        assert!((speed_of_sound(30.0) - 349.0).abs() < 0.1);
        assert!((speed_of_sound(-10.0) - 325.2).abs() < 0.1);
    }

    #[test]
    fn pulse_width_to_distance() {
        let o = UltrasonicOptions::default();
        // 1 m at 20 °C: 2 m of travel at 343.2 m/s = 5828 µs.
        let d = echo_distance(5828.0 * US, &o).unwrap();
        assert!((d - 1.0).abs() < 0.001, "{d}");
        // The same pulse on a 0 °C day reads 3.5 % shorter.
        let cold = UltrasonicOptions { temp_c: 0.0, ..o };
        let dc = echo_distance(5828.0 * US, &cold).unwrap();
        assert!((dc - 0.9654).abs() < 0.001, "{dc}");
        // The datasheet's rule of thumb, 58 µs per cm, at 20 °C: within 0.5 %.
        let d = echo_distance(58.0 * 50.0 * US, &o).unwrap();
        assert!((d - 0.50).abs() < 0.0025, "{d}");
        // Out of range and nonsense.
        assert_eq!(echo_distance(100.0 * US, &o), None, "1.7 cm < 2 cm");
        assert_eq!(echo_distance(25_000.0 * US, &o), None, "4.29 m > 4 m");
        assert_eq!(echo_distance(0.0, &o), None);
        assert_eq!(echo_distance(-1.0, &o), None);
        assert_eq!(echo_distance(f64::NAN, &o), None);
    }

    #[test]
    fn ideal_readings_round_trip() {
        let o = UltrasonicOptions {
            temp_c: 31.0,
            ..Default::default()
        };
        for d in [0.05, 0.35, 1.0, 3.9] {
            let r = ideal_reading(Some(d), o.temp_c, 0.030);
            let back = reading_distance(r, &o).unwrap();
            assert!((back - d).abs() < 1e-12, "{d} -> {r:?} -> {back}");
        }
        assert_eq!(ideal_reading(None, 20.0, 0.030), EchoReading::Timeout);
        assert_eq!(
            ideal_reading(Some(6.0), 20.0, 0.030),
            EchoReading::Timeout,
            "35 ms > 30 ms"
        );
        assert_eq!(
            reading_distance(ideal_reading(Some(4.5), 20.0, 0.030), &o),
            None,
            "beyond 4 m"
        );
    }

    #[test]
    fn edges_to_readings_with_timeouts() {
        let to = EchoTimeouts::default();
        // Recorded: trigger ended at 1.000000 s, echo rose 460 µs later, fell 2914 µs after.
        let r = reading_from_edges(1.0, Some(1.000460), Some(1.003374), to);
        match r {
            EchoReading::Pulse { width_s } => assert!((width_s - 2914.0 * US).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert_eq!(reading_from_edges(1.0, None, None, to), EchoReading::NoEcho);
        // A rise 8 ms late belongs to something else: no echo.
        assert_eq!(
            reading_from_edges(1.0, Some(1.008), Some(1.009), to),
            EchoReading::NoEcho
        );
        // A rise before the trigger ended (a stale edge): no echo.
        assert_eq!(
            reading_from_edges(1.0, Some(0.999), Some(1.001), to),
            EchoReading::NoEcho
        );
        // The module's own 38 ms "nothing there" pulse, or no fall at all: timeout.
        assert_eq!(
            reading_from_edges(1.0, Some(1.0005), Some(1.0385), to),
            EchoReading::Timeout
        );
        assert_eq!(reading_from_edges(1.0, Some(1.0005), None, to), EchoReading::Timeout);
    }

    #[test]
    fn median_rejects_single_outliers_and_counts_missing_as_far() {
        let mut m = MedianFilter::new(5);
        for d in [1.0, 1.01, 0.99, 1.0] {
            m.push(Some(d));
        }
        // A floor reflection at 0.2 m: the median stays at 1 m.
        let v = m.push(Some(0.2)).unwrap();
        assert!((v - 1.0).abs() < 0.011, "{v}");
        // Two missing echoes: still 1 m (3 of 5 near).
        m.push(None);
        let v = m.push(None).unwrap();
        assert!((v - 0.2).abs() > 0.5 && (v - 1.0).abs() < 0.011, "{v}");
        // A third: the majority sees nothing.
        assert_eq!(m.push(None), None);
        let mut one = MedianFilter::new(1);
        assert_eq!(one.push(Some(0.5)), Some(0.5));
        assert_eq!(one.push(None), None);
    }

    #[test]
    fn hysteresis() {
        let mut b = BrakeDecision::new(0.30, 0.45);
        let seq = [
            (Some(1.0), false),
            (Some(0.31), false),
            (Some(0.29), true),
            (Some(0.35), true), // wavering between: keep braking
            (Some(0.44), true),
            (Some(0.46), false),
            (Some(0.40), false), // coming back, between: stay released
            (Some(0.10), true),
            (None, false), // nothing in range
        ];
        for (i, (d, want)) in seq.iter().enumerate() {
            assert_eq!(b.update(*d), *want, "step {i}: {d:?}");
        }
    }

    /// A wall approached at 1 m/s from 2 m, one reading every 60 ms (the HC-SR04's
    /// measurement cycle): the echo widths a real sensor gives at 20 °C, with one floor
    /// reflection, two missed echoes and ±3 mm jitter recorded in.
    fn approach() -> Vec<(f64, f64, EchoReading)> {
        let c = speed_of_sound(20.0);
        let mut out = vec![];
        for k in 0..40 {
            let t = k as f64 * 0.060;
            let truth: f64 = 2.0 - 1.0 * t;
            if truth < 0.05 {
                break;
            }
            let jitter = [0.003, -0.002, 0.0, 0.001, -0.003][k % 5];
            let r = match k {
                12 => EchoReading::Pulse {
                    width_s: 2.0 * 0.15 / c,
                }, // floor reflection at 0.15 m
                17 => EchoReading::Timeout, // missed echo
                21 => EchoReading::NoEcho,  // sensor did not answer once
                _ => EchoReading::Pulse {
                    width_s: 2.0 * (truth + jitter) / c,
                },
            };
            out.push((t, truth, r));
        }
        out
    }

    #[test]
    fn wall_approaching_brakes_near_brake_m() {
        // A steady approach: the median of n lags (n - 1) / 2 readings (one more while a
        // missed echo is in the window), each 0.06 m at 1 m/s; jitter adds up to 6 mm.
        const STEP: f64 = 0.06;
        for n in [1usize, 3, 5] {
            let opts = UltrasonicOptions {
                median_n: n,
                brake_m: 0.30,
                release_m: 0.45,
                ..Default::default()
            };
            let lag = ((n - 1) / 2) as f64 * STEP;
            let mut u = Ultrasonic::new(opts);
            let mut first_brake = None;
            for (t, truth, r) in approach() {
                let o = u.push(r);
                assert!(o.sensor_ok);
                if o.brake && first_brake.is_none() {
                    first_brake = Some((t, truth));
                }
                // The floor reflection (0.15 m at 1.28 m) is voted out by any median; without
                // a filter (n = 1) it brakes for one reading, which is why the filter exists.
                if truth > 0.45 && n > 1 {
                    assert!(!o.brake, "n={n}: braked at {truth:.2} m (t = {t:.2} s)");
                }
                if let (Some(d), true) = (o.distance_m, truth > 0.3 && n > 1) {
                    assert!(
                        d - truth <= lag + STEP + 0.006 && d - truth >= -0.006,
                        "n={n}: {d} vs {truth}"
                    );
                }
            }
            let (t, truth) = first_brake.expect("must brake before the wall");
            if n == 1 {
                assert!(
                    (truth - 1.28).abs() < 1e-9,
                    "n=1 brakes on the floor reflection: {truth}"
                );
            } else {
                // The median passes 0.30 m `lag` late, within one reading's step.
                assert!(
                    truth <= 0.30 - lag + 0.006 && truth >= 0.30 - lag - STEP - 0.006,
                    "n={n}: braked at {truth:.3} m, t = {t:.2} s"
                );
            }
        }
    }

    #[test]
    fn silent_sensor_is_a_fault_not_a_brake() {
        let mut u = Ultrasonic::new(UltrasonicOptions::default());
        for _ in 0..3 {
            u.push(EchoReading::Pulse { width_s: 0.002 }); // 0.34 m
        }
        for i in 0..5 {
            let o = u.push(EchoReading::NoEcho);
            assert_eq!(o.sensor_ok, i < 4, "after {} silent readings", i + 1);
            assert_eq!(o.raw_m, None);
        }
        assert!(!u.last().brake);
        assert_eq!(u.last().distance_m, None);
        // One answer makes it ok again.
        assert!(u.push(EchoReading::Pulse { width_s: 0.002 }).sensor_ok);
    }

    #[test]
    fn timeouts_mean_nothing_ahead_and_release() {
        let mut u = Ultrasonic::new(UltrasonicOptions {
            median_n: 3,
            ..Default::default()
        });
        for _ in 0..3 {
            u.push(EchoReading::Pulse { width_s: 0.001 }); // 0.17 m
        }
        assert!(u.last().brake);
        u.push(EchoReading::Timeout);
        assert!(u.last().brake, "one timeout among near readings keeps the brake");
        u.push(EchoReading::Timeout);
        assert!(!u.last().brake, "a majority of timeouts: the obstacle has gone");
        assert!(u.last().sensor_ok, "timeouts are answers");
    }
}
