//! The Pi's button, LED and ultrasonic brake as a part of the drive loop: between frames it
//! shows the car's status on the LED, turns button presses into the one arming state's
//! start/stop, holds the brake, and reports the sensor's and the GPIO threads' health.
//!
//! A dead brake sensor is a fault, and the car stops: the ultrasonic brake is the one safety
//! that does not depend on vision, so a car whose brake cannot see must not drive on vision
//! alone. While the sensor does not answer (`gpio.fault_after` readings without an echo, or its
//! thread died) the car is disarmed and arming is refused with the reason; when it answers
//! again the interlock lifts, and the car stays disarmed until someone arms it. A dead
//! button/LED thread is a fault too (the button would no longer stop the car).

use super::{GpioEvents, LedState};
use crate::drive::{Actor, Arming, Flow, Observer};
use crate::health::{CarStatus, Part, PartState};
use crate::pipeline::Pipeline;
use crate::telemetry::FrameRecord;
use std::sync::Arc;

/// Something that shows an LED state and returns what happened since the last poll: the
/// Pi's pins ([`super::pi::GpioDevices`]), or a test's recorded sequence.
pub trait GpioPoll {
    /// Shows `led` from now on; the events since the last call.
    fn poll(&mut self, led: LedState) -> GpioEvents;
}

/// The GPIO devices as an observer of the loop (see the module notes).
pub struct GpioObserver<D: GpioPoll> {
    dev: D,
    arming: Arc<Arming>,
    distance: Option<f64>,
    events: Vec<String>,
    sensor: bool,
    /// The sensor's reading count at the last poll, and polls since it last grew.
    readings: (u64, u32),
}

/// Polls (frames) without a new ultrasonic reading before the sensor counts as silent: at
/// 30 fps about 1 s, against a reading every `gpio.sonar_period_s` (0.06 s).
pub const STALE_POLLS: u32 = 30;

impl<D: GpioPoll> GpioObserver<D> {
    /// Polls `dev` for the car armed by `arming` (whose health it reports into). `sensor`:
    /// whether an ultrasonic sensor is wired (`gpio.ultrasonic`).
    pub fn new(dev: D, arming: Arc<Arming>, sensor: bool) -> Self {
        let h = arming.health();
        h.set(Part::Gpio, PartState::Ok, "");
        h.set(
            Part::Brake,
            if sensor { PartState::Waiting } else { PartState::Unused },
            "",
        );
        Self {
            dev,
            arming,
            distance: None,
            events: Vec::new(),
            sensor,
            readings: (0, 0),
        }
    }

    /// The car's status now, for the LED.
    fn status(&self) -> CarStatus {
        let h = self.arming.health();
        CarStatus::of(
            &h.snapshot(),
            h.interlock().is_some(),
            self.arming.is_armed(),
            self.arming.is_estopped(),
            self.arming.is_braking(),
        )
    }

    /// One poll: LED out, presses, brake and health in.
    pub fn poll(&mut self) {
        let led = LedState::for_status(self.status());
        let ev = self.dev.poll(led);
        let h = self.arming.health().clone();
        if !ev.gpio_ok && h.state(Part::Gpio) != PartState::Failed {
            h.fail(Part::Gpio, "the button/LED thread stopped (the button cannot stop the car)");
            self.arming.disarm(Actor::Sensor);
            self.events.push("fault: GPIO button/LED thread stopped; disarmed".into());
        }
        // A sensor thread that runs but takes no readings is as silent as one without echoes.
        if ev.readings == self.readings.0 {
            self.readings.1 = self.readings.1.saturating_add(1);
        } else {
            self.readings = (ev.readings, 0);
        }
        let stale = self.readings.1 >= STALE_POLLS;
        if self.sensor {
            if ev.sensor_ok && !stale {
                if ev.readings > 0 && h.set(Part::Brake, PartState::Ok, "") {
                    self.events.push("ultrasonic brake sensor answering".into());
                }
            } else if h.set(
                Part::Brake,
                PartState::Lost,
                "the ultrasonic brake sensor does not answer (wiring? power?); the car stops until it does",
            ) {
                self.arming.disarm(Actor::Sensor);
                self.events.push("fault: ultrasonic brake sensor silent; disarmed, arming refused".into());
            }
        }
        for _ in 0..ev.presses {
            match self.arming.toggle(Actor::Button) {
                Ok(_) => {}
                Err(why) => self.events.push(format!("button: not armed: {why}")),
            }
        }
        self.arming.set_brake(ev.brake && self.sensor);
        self.distance = ev.distance_m;
    }
}

impl<D: GpioPoll> Observer for GpioObserver<D> {
    fn before_frame(&mut self, _p: &mut Pipeline) -> Flow {
        self.poll();
        Flow::Continue
    }
    fn decorate(&mut self, r: &mut FrameRecord) {
        r.ultrasonic_m = self.distance;
        r.events.append(&mut self.events);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpio::{EchoReading, GpioLogic, GpioOptions};
    use crate::health::Health;

    /// The GPIO logic fed by a script instead of pins; records the LED states shown.
    struct Scripted {
        logic: GpioLogic,
        leds: Vec<LedState>,
        thread_dead: bool,
    }
    impl GpioPoll for Scripted {
        fn poll(&mut self, led: LedState) -> GpioEvents {
            self.leds.push(led);
            self.logic.set_led(led);
            let mut ev = self.logic.take_events();
            if self.thread_dead {
                ev.sensor_ok = false;
            }
            ev
        }
    }

    fn setup() -> (GpioObserver<Scripted>, Arc<Arming>) {
        let opts = GpioOptions::default();
        let health = Health::new();
        health.set(Part::Camera, PartState::Ok, "");
        health.set(Part::Link, PartState::Ok, "");
        let arming = Arming::new(health);
        let dev = Scripted {
            logic: GpioLogic::new(&opts, false, 0.0),
            leds: Vec::new(),
            thread_dead: false,
        };
        (GpioObserver::new(dev, arming.clone(), true), arming)
    }

    fn press(o: &mut GpioObserver<Scripted>, t: f64) {
        o.dev.logic.button_level(true, t);
        o.dev.logic.button_level(true, t + 0.05);
        o.dev.logic.button_level(false, t + 0.1);
        o.dev.logic.button_level(false, t + 0.15);
    }

    #[test]
    fn a_silent_brake_sensor_disarms_refuses_arming_and_shows_fault() {
        let (mut o, arming) = setup();
        for _ in 0..3 {
            o.dev.logic.echo(EchoReading::Pulse { width_s: 0.006 }); // ~1 m: clear
        }
        press(&mut o, 1.0);
        o.poll();
        assert!(arming.is_armed(), "the button arms");
        o.poll();
        assert_eq!(*o.dev.leds.last().unwrap(), LedState::Driving);
        // the sensor stops answering (unplugged: no echo edge at all)
        for _ in 0..20 {
            o.dev.logic.echo(EchoReading::NoEcho);
        }
        o.poll();
        assert!(!arming.is_armed(), "a silent brake sensor disarms");
        assert_eq!(arming.health().state(Part::Brake), PartState::Lost);
        press(&mut o, 3.0);
        o.poll();
        assert!(!arming.is_armed(), "the button cannot arm without a brake");
        assert!(o.events.iter().any(|e| e.contains("not armed") && e.contains("ultrasonic")), "{:?}", o.events);
        assert_eq!(*o.dev.leds.last().unwrap(), LedState::Fault);
        // it answers again: the interlock lifts, the car stays disarmed until pressed
        for _ in 0..3 {
            o.dev.logic.echo(EchoReading::Pulse { width_s: 0.006 });
        }
        o.poll();
        assert_eq!(arming.health().state(Part::Brake), PartState::Ok);
        assert!(!arming.is_armed());
        press(&mut o, 5.0);
        o.poll();
        assert!(arming.is_armed());
    }

    #[test]
    fn a_sensor_that_takes_no_readings_is_silent() {
        let (mut o, arming) = setup();
        o.dev.logic.echo(EchoReading::Pulse { width_s: 0.006 });
        o.poll();
        arming.arm(Actor::Flag).unwrap();
        for _ in 0..STALE_POLLS - 1 {
            o.poll();
        }
        assert!(arming.is_armed(), "not yet");
        o.poll();
        assert!(!arming.is_armed(), "no reading for {STALE_POLLS} polls");
        assert_eq!(arming.health().state(Part::Brake), PartState::Lost);
    }

    #[test]
    fn a_dead_sensor_thread_is_a_fault_too() {
        let (mut o, arming) = setup();
        arming.arm(Actor::Flag).unwrap();
        o.dev.thread_dead = true;
        o.poll();
        assert!(!arming.is_armed());
        assert!(arming.arm(Actor::Page).is_err());
    }

    #[test]
    fn the_led_shows_waiting_disarmed_and_braking() {
        let (mut o, arming) = setup();
        arming.health().set(Part::Camera, PartState::Waiting, "");
        o.poll();
        assert_eq!(*o.dev.leds.last().unwrap(), LedState::WaitingCamera);
        arming.health().set(Part::Camera, PartState::Ok, "");
        for _ in 0..3 {
            o.dev.logic.echo(EchoReading::Pulse { width_s: 0.006 });
        }
        o.poll();
        o.poll();
        assert_eq!(*o.dev.leds.last().unwrap(), LedState::Ready, "disarmed is not 'driving'");
        arming.arm(Actor::Flag).unwrap();
        for _ in 0..3 {
            o.dev.logic.echo(EchoReading::Pulse { width_s: 0.001166 }); // 0.2 m: brake
        }
        o.poll();
        assert!(arming.is_braking());
        o.poll();
        assert_eq!(*o.dev.leds.last().unwrap(), LedState::Fault, "braking shows");
    }
}
