//! The car's own inputs and outputs on the Raspberry Pi's GPIO header: a start/stop push
//! button, a status LED and an HC-SR04 ultrasonic sensor used as an emergency brake that does
//! not depend on vision.
//!
//! The logic is pure and tested here with recorded edge timings (time is passed in, seconds):
//! * [`button`]: debouncing (a level must hold `debounce_s`), presses, long presses, and the
//!   start/stop toggle (press = arm and go, press again = stop);
//! * [`led`]: the blink code of each car state, `led_level(state, t)`;
//! * [`ultrasonic`]: echo pulse width → distance with the speed of sound at the configured
//!   temperature, plausibility, a median filter and the brake decision with hysteresis.
//!
//! [`GpioLogic`] joins them into what the drive loop needs, [`GpioEvents`], fed by raw button
//! levels and echo readings; [`observer::GpioObserver`] feeds those events to the car's one
//! arming state and health between frames. The rppal layer (`pi`, feature `gpio`) only moves levels and
//! timestamps between the pins and a `GpioLogic`, in two threads:
//!
//! ```text
//! button/LED thread, every 1 ms: read button pin -> GpioLogic::button_level(pressed, t)
//!                                led_level(state, t) -> LED pin
//! sonar thread, every period:    10 µs TRIG pulse, ECHO edges (kernel timestamps)
//!                                -> EchoReading -> GpioLogic::echo(reading)
//! drive loop, every frame:       GpioDevices::poll(led_state) -> GpioEvents
//! ```
//!
//! Pins are BCM numbers (the `GPIOnn` names, not the header's physical pin numbers).

pub mod button;
pub mod led;
pub mod observer;
#[cfg(feature = "gpio")]
pub mod pi;
pub mod ultrasonic;

pub use button::{Button, ButtonEvent, ButtonEventKind, ButtonOptions, StartStop, StartStopAction};
pub use led::{led_level, LedState};
pub use ultrasonic::{ideal_reading, EchoReading, EchoTimeouts, Ultrasonic, UltrasonicOptions, UltrasonicOutput};

/// Everything the GPIO layer needs: pins and the logic's options (from `[gpio]` in
/// config/car.toml, see `config::GpioConfig::options`).
#[derive(Debug, Clone, PartialEq)]
pub struct GpioOptions {
    /// Push button to ground, BCM pin (internal pull-up: pressed reads low).
    pub button_pin: u8,
    /// Status LED (through a resistor to ground), BCM pin.
    pub led_pin: u8,
    /// Whether an HC-SR04 is wired; false = no brake readings (`distance_m` stays `None`).
    pub ultrasonic: bool,
    /// HC-SR04 TRIG, BCM pin.
    pub trig_pin: u8,
    /// HC-SR04 ECHO (through a 5 V → 3.3 V divider), BCM pin.
    pub echo_pin: u8,
    /// Button debouncing.
    pub button: ButtonOptions,
    /// Distance, filter and brake.
    pub sonar: UltrasonicOptions,
    /// Time between two measurements, seconds (HC-SR04: at least 0.06).
    pub sonar_period_s: f64,
    /// How long to wait for the echo edges.
    pub timeouts: EchoTimeouts,
}

impl Default for GpioOptions {
    fn default() -> Self {
        Self {
            button_pin: 17,
            led_pin: 27,
            ultrasonic: true,
            trig_pin: 23,
            echo_pin: 24,
            button: ButtonOptions::default(),
            sonar: UltrasonicOptions::default(),
            sonar_period_s: 0.06,
            timeouts: EchoTimeouts::default(),
        }
    }
}

/// What happened on the GPIO since the last poll.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GpioEvents {
    /// Debounced presses of the start/stop button since the last poll (normally 0 or 1;
    /// feed each to [`StartStop::press`]).
    pub presses: u32,
    /// Long presses since the last poll (0 unless `long_press_s` is set).
    pub long_presses: u32,
    /// The latest median-filtered ultrasonic distance, metres; `None` = nothing in range,
    /// no sensor, or no reading yet. Goes into telemetry.
    pub distance_m: Option<f64>,
    /// Emergency brake: something is nearer than `brake_m` (held until beyond `release_m`).
    /// The loop sends neutral throttle while it is set, whatever the pipeline says.
    pub brake: bool,
    /// False when the ultrasonic sensor has stopped answering (see
    /// [`UltrasonicOptions::fault_after`]); always true with no sensor configured.
    pub sensor_ok: bool,
    /// Ultrasonic readings taken since the start (to see that the sensor thread runs).
    pub readings: u64,
    /// False when the button/LED thread has died (the button no longer stops the car).
    pub gpio_ok: bool,
}

/// The GPIO logic with no hardware: raw inputs in, [`GpioEvents`] out.
#[derive(Debug, Clone)]
pub struct GpioLogic {
    button: Button,
    sonar: Option<Ultrasonic>,
    presses: u32,
    long_presses: u32,
    readings: u64,
    led: LedState,
}

impl GpioLogic {
    /// Starts with the button's level at `t0` taken as it is (a button held at start-up
    /// gives no press) and the LED waiting for the camera.
    pub fn new(opts: &GpioOptions, button_pressed: bool, t0: f64) -> Self {
        Self {
            button: Button::new(opts.button, button_pressed, t0),
            sonar: opts.ultrasonic.then(|| Ultrasonic::new(opts.sonar)),
            presses: 0,
            long_presses: 0,
            readings: 0,
            led: LedState::WaitingCamera,
        }
    }

    /// The button's raw level at time `t`, seconds (an edge or a sample).
    pub fn button_level(&mut self, pressed: bool, t: f64) {
        self.button.input(pressed, t);
        while let Some(e) = self.button.pop_event() {
            match e.kind {
                ButtonEventKind::Press => self.presses = self.presses.saturating_add(1),
                ButtonEventKind::LongPress => self.long_presses = self.long_presses.saturating_add(1),
                ButtonEventKind::Release => {}
            }
        }
    }

    /// One ultrasonic reading (ignored when no sensor is configured).
    pub fn echo(&mut self, r: EchoReading) -> Option<UltrasonicOutput> {
        let s = self.sonar.as_mut()?;
        self.readings += 1;
        Some(s.push(r))
    }

    /// The LED state to show from now on.
    pub fn set_led(&mut self, state: LedState) {
        self.led = state;
    }

    /// The LED state last set.
    pub fn led(&self) -> LedState {
        self.led
    }

    /// Presses since the last call, and the sensor's latest state.
    pub fn take_events(&mut self) -> GpioEvents {
        let s = self.sonar.as_ref().map(Ultrasonic::last);
        let ev = GpioEvents {
            presses: self.presses,
            long_presses: self.long_presses,
            distance_m: s.and_then(|s| s.distance_m),
            brake: s.is_some_and(|s| s.brake),
            sensor_ok: s.is_none_or(|s| s.sensor_ok),
            readings: self.readings,
            gpio_ok: true,
        };
        self.presses = 0;
        self.long_presses = 0;
        ev
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logic_joins_button_and_sonar() {
        let opts = GpioOptions {
            button: ButtonOptions {
                debounce_s: 0.02,
                long_press_s: Some(2.0),
            },
            ..Default::default()
        };
        let mut g = GpioLogic::new(&opts, false, 0.0);
        let mut toggle = StartStop::new();
        // 1 ms samples of a bouncy press at 0.5 s, released at 0.7 s.
        for k in 0..1000 {
            let t = k as f64 * 1e-3;
            let pressed = (0.5..0.7).contains(&t) && !(0.5015..0.5025).contains(&t);
            g.button_level(pressed, t);
        }
        let ev = g.take_events();
        assert_eq!(ev.presses, 1);
        assert_eq!(ev.long_presses, 0);
        assert_eq!(toggle.press(), StartStopAction::Start);
        assert_eq!(g.take_events().presses, 0, "a press is reported once");
        // A wall at 0.2 m (1166 µs at 20 °C) on three readings: brake.
        for _ in 0..3 {
            g.echo(EchoReading::Pulse { width_s: 0.001166 });
        }
        let ev = g.take_events();
        assert!(ev.brake && ev.sensor_ok);
        assert!((ev.distance_m.unwrap() - 0.2).abs() < 0.001);
        assert_eq!(ev.readings, 3);
    }

    #[test]
    fn no_sensor_means_no_brake_and_ok() {
        let opts = GpioOptions {
            ultrasonic: false,
            ..Default::default()
        };
        let mut g = GpioLogic::new(&opts, false, 0.0);
        assert!(g.echo(EchoReading::NoEcho).is_none());
        let ev = g.take_events();
        assert!(!ev.brake && ev.sensor_ok && ev.distance_m.is_none() && ev.readings == 0);
    }
}
