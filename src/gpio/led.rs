//! The status LED: one light, five blink codes, so a student can tell from across the room
//! what the car is waiting for.
//!
//! | state            | pattern (repeats)                               | period |
//! |------------------|-------------------------------------------------|--------|
//! | waiting for camera  | 1 flash: 0.15 s on, then off                 | 2 s    |
//! | waiting for Arduino | 2 flashes: 0.15 s on, 0.25 s off, 0.15 s on  | 2 s    |
//! | ready (armed on a press) | steady on                               | –      |
//! | driving          | even blink, 0.25 s on / 0.25 s off (2 Hz)       | 0.5 s  |
//! | fault            | fast flicker, 0.0625 s on / off (8 Hz)          | 0.125 s|
//!
//! [`led_level`] is a pure function of the state and the time in seconds (any origin; the
//! patterns start at t = 0 and repeat), so the LED thread and the tests agree exactly.
//! [`LedState::from_status`] picks the state from the car's condition, the most urgent first.

/// What the car is doing, as shown by the LED.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LedState {
    /// No frame from the camera yet (or the camera was lost).
    WaitingCamera,
    /// The link to the Arduino is not up (no handshake yet, or reconnecting).
    WaitingArduino,
    /// Camera and Arduino are up; a press of the button starts driving.
    Ready,
    /// Driving.
    Driving,
    /// Something is wrong and the car stopped (e.g. the ultrasonic sensor does not answer,
    /// a thread died): look at the log.
    Fault,
}

/// One segment of a blink pattern: the level and how long it lasts, seconds.
type Segment = (bool, f64);

const WAITING_CAMERA: &[Segment] = &[(true, 0.15), (false, 1.85)];
const WAITING_ARDUINO: &[Segment] = &[(true, 0.15), (false, 0.25), (true, 0.15), (false, 1.45)];
const DRIVING: &[Segment] = &[(true, 0.25), (false, 0.25)];
const FAULT: &[Segment] = &[(true, 0.0625), (false, 0.0625)];

impl LedState {
    /// The state to show: fault first, then what the car waits for, then driving or ready.
    pub fn from_status(fault: bool, camera_ok: bool, link_ok: bool, driving: bool) -> Self {
        if fault {
            LedState::Fault
        } else if !camera_ok {
            LedState::WaitingCamera
        } else if !link_ok {
            LedState::WaitingArduino
        } else if driving {
            LedState::Driving
        } else {
            LedState::Ready
        }
    }

    /// The blink code of the car's status (docs/pi.md): e-stopped and braking show as fault.
    pub fn for_status(s: crate::health::CarStatus) -> Self {
        use crate::health::CarStatus;
        match s {
            CarStatus::Fault | CarStatus::EStopped | CarStatus::Braking => LedState::Fault,
            CarStatus::WaitingCamera => LedState::WaitingCamera,
            CarStatus::WaitingLink => LedState::WaitingArduino,
            CarStatus::Disarmed => LedState::Ready,
            CarStatus::Driving => LedState::Driving,
        }
    }

    /// The repeating pattern, or `None` for steady on.
    fn pattern(self) -> Option<&'static [Segment]> {
        match self {
            LedState::WaitingCamera => Some(WAITING_CAMERA),
            LedState::WaitingArduino => Some(WAITING_ARDUINO),
            LedState::Ready => None,
            LedState::Driving => Some(DRIVING),
            LedState::Fault => Some(FAULT),
        }
    }

    /// Length of one repetition of the pattern, seconds (0 for steady on).
    pub fn period_s(self) -> f64 {
        self.pattern().map_or(0.0, |p| p.iter().map(|s| s.1).sum())
    }
}

/// Whether the LED is lit in `state` at time `t`, seconds. A non-finite time gives "off".
pub fn led_level(state: LedState, t: f64) -> bool {
    let Some(pattern) = state.pattern() else {
        return true;
    };
    if !t.is_finite() {
        return false;
    }
    let period: f64 = pattern.iter().map(|s| s.1).sum();
    let mut phase = t.rem_euclid(period);
    for &(level, len) in pattern {
        if phase < len {
            return level;
        }
        phase -= len;
    }
    // Rounding at the very end of the period: the last segment.
    pattern[pattern.len() - 1].0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_car_status_has_its_blink_code() {
        use crate::health::CarStatus;
        assert_eq!(LedState::for_status(CarStatus::Driving), LedState::Driving);
        assert_eq!(LedState::for_status(CarStatus::Disarmed), LedState::Ready);
        assert_eq!(LedState::for_status(CarStatus::Fault), LedState::Fault);
        assert_eq!(LedState::for_status(CarStatus::EStopped), LedState::Fault);
        assert_eq!(LedState::for_status(CarStatus::WaitingCamera), LedState::WaitingCamera);
        assert_eq!(LedState::for_status(CarStatus::WaitingLink), LedState::WaitingArduino);
    }

    /// Rising edges and lit time over `secs` seconds, sampled every 1 ms.
    fn measure(state: LedState, secs: f64) -> (usize, f64) {
        let n = (secs * 1000.0).round() as usize;
        let mut rises = 0;
        let mut lit = 0usize;
        let mut prev = led_level(state, -0.0005);
        for k in 0..n {
            let l = led_level(state, (k as f64 + 0.5) / 1000.0);
            if l && !prev {
                rises += 1;
            }
            lit += usize::from(l);
            prev = l;
        }
        (rises, lit as f64 / 1000.0)
    }

    #[test]
    fn each_state_has_its_blink_count_and_duty() {
        // Over 10 s: flashes and total lit time (1 ms sampling, so ±2 ms per flash).
        let (r, lit) = measure(LedState::WaitingCamera, 10.0);
        assert_eq!(r, 5);
        assert!((lit - 0.75).abs() < 0.011, "{lit}");
        let (r, lit) = measure(LedState::WaitingArduino, 10.0);
        assert_eq!(r, 10, "two flashes per 2 s");
        assert!((lit - 1.5).abs() < 0.021, "{lit}");
        let (r, lit) = measure(LedState::Ready, 10.0);
        assert_eq!(r, 0);
        assert!((lit - 10.0).abs() < 1e-9);
        let (r, lit) = measure(LedState::Driving, 10.0);
        assert_eq!(r, 20);
        assert!((lit - 5.0).abs() < 0.041, "{lit}");
        let (r, lit) = measure(LedState::Fault, 10.0);
        assert_eq!(r, 80);
        assert!((lit - 5.0).abs() < 0.161, "{lit}");
    }

    #[test]
    fn documented_edges() {
        use LedState::*;
        assert!(led_level(WaitingCamera, 0.0));
        assert!(led_level(WaitingCamera, 0.149));
        assert!(!led_level(WaitingCamera, 0.151));
        assert!(led_level(WaitingCamera, 2.01), "repeats every 2 s");
        assert!(!led_level(WaitingArduino, 0.2));
        assert!(led_level(WaitingArduino, 0.45));
        assert!(!led_level(WaitingArduino, 0.56));
        assert!(led_level(Driving, 0.6) && !led_level(Driving, 0.8));
        assert!(led_level(Fault, 0.03) && !led_level(Fault, 0.09));
        assert!(led_level(Driving, -0.4), "negative times repeat the pattern too");
        assert!(!led_level(Driving, f64::NAN));
        assert!((WaitingArduino.period_s() - 2.0).abs() < 1e-12);
        assert!((WaitingCamera.period_s() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn status_priorities() {
        use LedState::*;
        assert_eq!(LedState::from_status(true, false, false, true), Fault);
        assert_eq!(LedState::from_status(false, false, false, false), WaitingCamera);
        assert_eq!(LedState::from_status(false, true, false, true), WaitingArduino);
        assert_eq!(LedState::from_status(false, true, true, true), Driving);
        assert_eq!(LedState::from_status(false, true, true, false), Ready);
    }
}
