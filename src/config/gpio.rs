//! `[gpio]`: the Raspberry Pi's GPIO: BCM pin numbers, the button's debounce and long press
//! (milliseconds), the ultrasonic brake's distances (metres), air temperature (degrees Celsius),
//! median filter length and measurement period (milliseconds).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[gpio]`: the Raspberry Pi's GPIO (feature `gpio`, src/gpio/): a start/stop push button, a
/// status LED and an HC-SR04 ultrasonic sensor as an emergency brake. Pins are BCM numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpioConfig {
    /// Use the GPIO at all (false on a desk computer).
    pub enabled: bool,
    /// Push button to ground, BCM pin (internal pull-up).
    pub button_pin: u8,
    /// Status LED with its resistor, BCM pin.
    pub led_pin: u8,
    /// An HC-SR04 is wired (false: no ultrasonic brake; its pins are not used).
    pub ultrasonic: bool,
    /// HC-SR04 TRIG, BCM pin.
    pub trig_pin: u8,
    /// HC-SR04 ECHO through a 5 V -> 3.3 V divider, BCM pin.
    pub echo_pin: u8,
    /// A button level must hold this long to count, milliseconds.
    pub debounce_ms: f64,
    /// Holding the button this long is a long press, milliseconds (0 = off).
    pub long_press_ms: f64,
    /// Brake when the ultrasonic distance is nearer than this, metres.
    pub brake_m: f64,
    /// Release the brake beyond this distance, metres (> brake_m).
    pub release_m: f64,
    /// Air temperature at the sensor, degrees Celsius (speed of sound).
    pub sensor_temp_c: f64,
    /// Ultrasonic readings in the median filter.
    pub median_n: u32,
    /// Time between two ultrasonic measurements, milliseconds.
    pub period_ms: f64,
}

impl Default for GpioConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            button_pin: 17,
            led_pin: 27,
            ultrasonic: true,
            trig_pin: 23,
            echo_pin: 24,
            debounce_ms: 30.0,
            long_press_ms: 0.0,
            brake_m: 0.35,
            release_m: 0.50,
            sensor_temp_c: 20.0,
            median_n: 3,
            period_ms: 60.0,
        }
    }
}

impl GpioConfig {
    /// The GPIO layer's options (ms -> s; the sensor's fixed limits from its datasheet).
    pub fn options(&self) -> crate::gpio::GpioOptions {
        use crate::gpio::{ButtonOptions, EchoTimeouts, GpioOptions, UltrasonicOptions};
        GpioOptions {
            button_pin: self.button_pin,
            led_pin: self.led_pin,
            ultrasonic: self.ultrasonic,
            trig_pin: self.trig_pin,
            echo_pin: self.echo_pin,
            button: ButtonOptions {
                debounce_s: self.debounce_ms / 1000.0,
                long_press_s: (self.long_press_ms > 0.0).then_some(self.long_press_ms / 1000.0),
            },
            sonar: UltrasonicOptions {
                temp_c: self.sensor_temp_c,
                median_n: self.median_n as usize,
                brake_m: self.brake_m,
                release_m: self.release_m,
                ..UltrasonicOptions::default()
            },
            sonar_period_s: self.period_ms / 1000.0,
            timeouts: EchoTimeouts::default(),
        }
    }
}

impl GpioConfig {
    /// Checks of `[gpio]`: pins on the header and not shared, the ranges.
    pub(super) fn check(&self, c: &mut Checker) {
        let g = self;
        // BCM GPIO 2..27 are on the 40-pin header; 0 and 1 are reserved for HAT EEPROMs.
        let mut pins = vec![("gpio.button_pin", g.button_pin), ("gpio.led_pin", g.led_pin)];
        if g.ultrasonic {
            pins.push(("gpio.trig_pin", g.trig_pin));
            pins.push(("gpio.echo_pin", g.echo_pin));
        }
        for (i, &(key, pin)) in pins.iter().enumerate() {
            c.range(key, pin, 2, 27);
            if let Some(&(first, _)) = pins[..i].iter().find(|(_, p)| *p == pin) {
                c.fail(key, pin.to_string(), &format!("a pin not already used by {first}"));
            }
        }
        c.range("gpio.debounce_ms", g.debounce_ms, 1.0, 500.0);
        if g.long_press_ms != 0.0 {
            c.range("gpio.long_press_ms", g.long_press_ms, 200.0, 10000.0);
        }
        c.range("gpio.brake_m", g.brake_m, 0.03, 3.9);
        c.range("gpio.release_m", g.release_m, g.brake_m.clamp(0.03, 3.9), 4.0);
        c.range("gpio.sensor_temp_c", g.sensor_temp_c, -20.0, 60.0);
        c.range("gpio.median_n", g.median_n, 1, 15);
        c.range("gpio.period_ms", g.period_ms, 60.0, 1000.0);
    }
}
