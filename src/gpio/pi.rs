//! The thin rppal layer (feature `gpio`): moves levels and timestamps between the Raspberry
//! Pi's pins and a [`GpioLogic`]; all decisions are made there (see the parent module).
//!
//! [`GpioDevices::open`] claims the pins and starts two threads:
//! * **button/LED**, every 1 ms: reads the button (internal pull-up, pressed = low) and feeds
//!   its level with the time since `open` to the debouncer; sets the LED to
//!   `led_level(state, t)` for the state last given to [`GpioDevices::poll`];
//! * **sonar**, every `sonar_period_s`: a 10 µs TRIG pulse, then the ECHO pin's rising and
//!   falling edges as kernel interrupt events. Their kernel timestamps give the pulse width,
//!   so a thread that is scheduled late still measures the right width; the waits are
//!   bounded by [`EchoTimeouts`] (plus 10 ms of scheduling slack) so a missing echo never
//!   blocks. Each reading goes to the median filter and brake decision.
//!
//! The drive loop calls [`GpioDevices::poll`] once per frame; it never blocks for more than a
//! mutex hand-over. This is the one place of the GPIO code that reads a clock (for the
//! button's sample times and the measurement period), as a camera driver must.
//!
//! Off a Raspberry Pi, `open` fails with a clear error (rppal: unknown model). Dropping the
//! devices stops the threads, switches the LED off and releases the pins.

use super::{led_level, ultrasonic::reading_from_edges, EchoReading, GpioEvents, GpioLogic, GpioOptions, LedState};
use rppal::gpio::{Gpio, InputPin, Level, OutputPin, Trigger};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The GPIO cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum GpioError {
    /// The GPIO peripheral cannot be opened (not a Raspberry Pi, no permission).
    #[error("GPIO: cannot open ({0}); on a desk computer set gpio.enabled = false")]
    Open(String),
    /// One pin cannot be claimed.
    #[error("{key} = {pin}: cannot use this GPIO pin ({reason})")]
    Pin {
        /// The config key that chose the pin.
        key: &'static str,
        /// BCM number.
        pin: u8,
        /// rppal's reason.
        reason: String,
    },
    /// A thread could not be started or the interrupt could not be set.
    #[error("GPIO: {0}")]
    Setup(String),
}

/// The button, LED and ultrasonic sensor, running. See the module documentation.
pub struct GpioDevices {
    logic: Arc<Mutex<GpioLogic>>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

fn lock(m: &Mutex<GpioLogic>) -> MutexGuard<'_, GpioLogic> {
    // A thread that panicked while holding the lock left consistent plain data: go on.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl GpioDevices {
    /// Claims the pins of `opts` and starts the threads.
    pub fn open(opts: &GpioOptions) -> Result<Self, GpioError> {
        let gpio = Gpio::new().map_err(|e| GpioError::Open(e.to_string()))?;
        let pin = |key: &'static str, n: u8| {
            gpio.get(n).map_err(|e| GpioError::Pin {
                key,
                pin: n,
                reason: e.to_string(),
            })
        };
        let button = pin("gpio.button_pin", opts.button_pin)?.into_input_pullup();
        let led = pin("gpio.led_pin", opts.led_pin)?.into_output_low();
        let sonar_pins = if opts.ultrasonic {
            let trig = pin("gpio.trig_pin", opts.trig_pin)?.into_output_low();
            let mut echo = pin("gpio.echo_pin", opts.echo_pin)?.into_input_pulldown();
            echo.set_interrupt(Trigger::Both, None).map_err(|e| GpioError::Pin {
                key: "gpio.echo_pin",
                pin: opts.echo_pin,
                reason: format!("cannot watch its edges: {e}"),
            })?;
            Some((trig, echo))
        } else {
            None
        };

        let start = Instant::now();
        let logic = Arc::new(Mutex::new(GpioLogic::new(opts, button.is_low(), 0.0)));
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        {
            let (logic, stop) = (logic.clone(), stop.clone());
            threads.push(
                std::thread::Builder::new()
                    .name("gpio-button-led".into())
                    .spawn(move || button_led_thread(button, led, logic, stop, start))
                    .map_err(|e| GpioError::Setup(format!("cannot start the button thread: {e}")))?,
            );
        }
        if let Some((trig, echo)) = sonar_pins {
            let (l, st, o) = (logic.clone(), stop.clone(), opts.clone());
            let spawned = std::thread::Builder::new()
                .name("gpio-sonar".into())
                .spawn(move || sonar_thread(trig, echo, &o, l, st));
            match spawned {
                Ok(h) => threads.push(h),
                Err(e) => {
                    let mut d = Self { logic, stop, threads };
                    d.shutdown();
                    return Err(GpioError::Setup(format!("cannot start the sonar thread: {e}")));
                }
            }
        }
        Ok(Self { logic, stop, threads })
    }

    /// Shows `led` from now on and returns what happened since the last poll: button presses
    /// and the ultrasonic distance and brake. If a device thread has died, `sensor_ok` is
    /// false (the loop should treat it as a fault).
    pub fn poll(&mut self, led: LedState) -> GpioEvents {
        let mut ev = {
            let mut l = lock(&self.logic);
            l.set_led(led);
            l.take_events()
        };
        // Thread 0 runs the button and LED, thread 1 (when wired) the ultrasonic sensor.
        if self.threads.first().is_some_and(JoinHandle::is_finished) {
            ev.gpio_ok = false;
        }
        if self.threads.get(1).is_some_and(JoinHandle::is_finished) {
            ev.sensor_ok = false;
        }
        ev
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

impl super::observer::GpioPoll for GpioDevices {
    fn poll(&mut self, led: LedState) -> GpioEvents {
        GpioDevices::poll(self, led)
    }
}

impl Drop for GpioDevices {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn button_led_thread(
    button: InputPin,
    mut led: OutputPin,
    logic: Arc<Mutex<GpioLogic>>,
    stop: Arc<AtomicBool>,
    start: Instant,
) {
    let mut lit = false;
    while !stop.load(Ordering::Relaxed) {
        let t = start.elapsed().as_secs_f64();
        let pressed = button.is_low();
        let state = {
            let mut l = lock(&logic);
            l.button_level(pressed, t);
            l.led()
        };
        let want = led_level(state, t);
        if want != lit {
            led.write(if want { Level::High } else { Level::Low });
            lit = want;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    led.set_low();
}

fn sonar_thread(
    mut trig: OutputPin,
    mut echo: InputPin,
    opts: &GpioOptions,
    logic: Arc<Mutex<GpioLogic>>,
    stop: Arc<AtomicBool>,
) {
    let period = Duration::from_secs_f64(opts.sonar_period_s.max(0.02));
    let slack = Duration::from_millis(10);
    let rise_wait = Duration::from_secs_f64(opts.timeouts.rise_s.max(0.0)) + slack;
    let width_wait = Duration::from_secs_f64(opts.timeouts.width_s.max(0.0)) + slack;
    while !stop.load(Ordering::Relaxed) {
        let cycle = Instant::now();
        let reading = measure(&mut trig, &mut echo, rise_wait, width_wait, opts);
        lock(&logic).echo(reading);
        if let Some(rest) = period.checked_sub(cycle.elapsed()) {
            std::thread::sleep(rest);
        }
    }
    trig.set_low();
}

/// One measurement: TRIG pulse, then wait for the ECHO edges.
fn measure(
    trig: &mut OutputPin,
    echo: &mut InputPin,
    rise_wait: Duration,
    width_wait: Duration,
    opts: &GpioOptions,
) -> EchoReading {
    // 1. Forget edges left over from an earlier cycle.
    while let Ok(Some(_)) = echo.poll_interrupt(false, Some(Duration::ZERO)) {}
    // 2. The 10 µs trigger pulse (busy wait: sleeping would take far longer).
    trig.set_high();
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_micros(10) {
        std::hint::spin_loop();
    }
    trig.set_low();
    // 3. The rising edge, then the falling edge, each with its kernel timestamp.
    let next = |echo: &mut InputPin, want: Trigger, wait: Duration| -> Option<f64> {
        let until = Instant::now() + wait;
        loop {
            let left = until.checked_duration_since(Instant::now())?;
            match echo.poll_interrupt(false, Some(left)) {
                Ok(Some(e)) if e.trigger == want => return Some(e.timestamp.as_secs_f64()),
                Ok(Some(_)) => continue,
                Ok(None) | Err(_) => return None,
            }
        }
    };
    let Some(rise) = next(echo, Trigger::RisingEdge, rise_wait) else {
        return EchoReading::NoEcho;
    };
    let fall = next(echo, Trigger::FallingEdge, width_wait);
    // The rise arrived within `rise_wait` of the trigger (the wait enforced it), so it is
    // its own reference for the rise timeout.
    reading_from_edges(rise, Some(rise), fall, opts.timeouts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_a_pi_open_is_a_clear_error() {
        // This machine is not a Raspberry Pi: rppal cannot identify it.
        if std::fs::read_to_string("/proc/device-tree/model").is_ok_and(|m| m.contains("Raspberry Pi")) {
            eprintln!("running on a Raspberry Pi: open() may succeed, nothing to check");
            return;
        }
        let e = GpioDevices::open(&GpioOptions::default()).err().expect("no GPIO here");
        let msg = e.to_string();
        eprintln!("{msg}");
        assert!(
            msg.starts_with("GPIO: cannot open") && msg.contains("gpio.enabled = false"),
            "{msg}"
        );
    }
}
