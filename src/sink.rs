//! Where commands go: the serial link to the Arduino, the simulator's vehicle, or a recorder.
//!
//! Safety rule: anything that can move a motor ends by sending [`Command::NEUTRAL`].
//! [`NeutralOnDrop`] wraps a sink and does so when it goes out of scope, on every exit path
//! (return, `?`, panic unwinding).

use crate::control::Command;

/// Error from a command sink (a closed port, a full buffer...).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SinkError(pub String);

/// Something that executes commands.
pub trait CommandSink {
    /// Delivers one command and returns what was really sent (a gate sends neutral while the
    /// car is disarmed). `now_s` is the time of the frame it answers, seconds.
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError>;

    /// Brings the car to the safe state (steer straight, motor stopped). Must not fail
    /// silently: implementations try their best and report.
    fn stop(&mut self) -> Result<(), SinkError> {
        self.send(Command::NEUTRAL, f64::NAN).map(|_| ())
    }

    /// Moves what happened at the actuators since the last call (armed by the button, link
    /// lost…) into `out`, for the frame's telemetry record. Default: nothing happens.
    fn drain_events(&mut self, _out: &mut Vec<String>) {}
}

/// A borrowed sink is a sink (so the loop can wrap `&mut dyn CommandSink` in
/// [`NeutralOnDrop`]).
impl<S: CommandSink + ?Sized> CommandSink for &mut S {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError> {
        (**self).send(cmd, now_s)
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        (**self).stop()
    }
    fn drain_events(&mut self, out: &mut Vec<String>) {
        (**self).drain_events(out)
    }
}

/// A boxed sink is a sink.
impl<S: CommandSink + ?Sized> CommandSink for Box<S> {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError> {
        (**self).send(cmd, now_s)
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        (**self).stop()
    }
    fn drain_events(&mut self, out: &mut Vec<String>) {
        (**self).drain_events(out)
    }
}

/// A sink that forgets everything (replay without a car).
#[derive(Debug, Default)]
pub struct NullSink;

impl CommandSink for NullSink {
    fn send(&mut self, cmd: Command, _now_s: f64) -> Result<Command, SinkError> {
        Ok(cmd)
    }
}

/// A sink that keeps every command it was given, with its time (for tests and reports).
#[derive(Debug, Default)]
pub struct RecordingSink {
    /// (time, command) in the order received; `stop()` records a NaN time.
    pub log: Vec<(f64, Command)>,
}

impl CommandSink for RecordingSink {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError> {
        self.log.push((now_s, cmd));
        Ok(cmd)
    }
}

/// Sends neutral when dropped, whatever the reason the scope ends.
pub struct NeutralOnDrop<S: CommandSink> {
    inner: Option<S>,
}

impl<S: CommandSink> NeutralOnDrop<S> {
    /// Wraps `sink`.
    pub fn new(sink: S) -> Self {
        Self { inner: Some(sink) }
    }

    /// The wrapped sink.
    pub fn get_mut(&mut self) -> &mut S {
        self.inner.as_mut().expect("present until drop")
    }

    /// Sends neutral now and returns the sink (no second neutral on drop).
    pub fn into_inner(mut self) -> S {
        let mut s = self.inner.take().expect("present until drop");
        let _ = s.stop();
        s
    }
}

impl<S: CommandSink> CommandSink for NeutralOnDrop<S> {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError> {
        self.get_mut().send(cmd, now_s)
    }
    fn stop(&mut self) -> Result<(), SinkError> {
        self.get_mut().stop()
    }
    fn drain_events(&mut self, out: &mut Vec<String>) {
        self.get_mut().drain_events(out)
    }
}

impl<S: CommandSink> Drop for NeutralOnDrop<S> {
    fn drop(&mut self) {
        if let Some(s) = self.inner.as_mut() {
            // Nothing more can be done from a destructor than trying; the firmware's own
            // watchdog is the second line of defence.
            let _ = s.stop();
        }
    }
}

/// The state of the connection to the actuators, as the gate sees it before each command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Connection {
    /// Up (or nothing to connect: the simulator, a dry run).
    Up,
    /// Down, with the reason (port gone, silent firmware); may come back.
    Down(String),
    /// Up again after being down, or the firmware restarted: it forgot that it was armed.
    Reconnected,
}

/// Something that moves the car: the serial link, the simulated car, or nothing. The gate arms
/// and disarms it as the [`crate::drive::Arming`] state says; on its own it never arms.
pub trait Actuators: CommandSink {
    /// Arms the actuators (the firmware's ARM). Default: nothing to arm.
    fn arm(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    /// Disarms them (the firmware's DISARM, neutral). Default: neutral.
    fn disarm(&mut self) -> Result<(), SinkError> {
        self.stop()
    }
    /// How the connection is now. Default: always up.
    fn connection(&mut self) -> Connection {
        Connection::Up
    }
}

impl<A: Actuators + ?Sized> Actuators for Box<A> {
    fn arm(&mut self) -> Result<(), SinkError> {
        (**self).arm()
    }
    fn disarm(&mut self) -> Result<(), SinkError> {
        (**self).disarm()
    }
    fn connection(&mut self) -> Connection {
        (**self).connection()
    }
}

impl Actuators for NullSink {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records into a shared log, so the test can look after the guard is gone.
    struct Shared(std::rc::Rc<std::cell::RefCell<Vec<Command>>>);
    impl CommandSink for Shared {
        fn send(&mut self, cmd: Command, _now_s: f64) -> Result<Command, SinkError> {
            self.0.borrow_mut().push(cmd);
            Ok(cmd)
        }
    }

    #[test]
    fn drop_sends_neutral_even_on_early_exit() {
        let log = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
        let drive = |log| -> Result<(), SinkError> {
            let mut sink = NeutralOnDrop::new(Shared(log));
            sink.send(
                Command {
                    steer: 0.3,
                    throttle: 0.5,
                },
                0.0,
            )?;
            Err::<(), _>(SinkError("simulated failure".into()))?;
            sink.send(
                Command {
                    steer: 0.0,
                    throttle: 0.9,
                },
                0.1,
            )
            .map(|_| ())
        };
        assert!(drive(log.clone()).is_err());
        assert_eq!(
            *log.borrow(),
            vec![
                Command {
                    steer: 0.3,
                    throttle: 0.5
                },
                Command::NEUTRAL
            ]
        );
    }

    #[test]
    fn into_inner_sends_exactly_one_neutral() {
        let mut g = NeutralOnDrop::new(RecordingSink::default());
        g.send(
            Command {
                steer: 0.2,
                throttle: 0.3,
            },
            0.0,
        )
        .unwrap();
        let s = g.into_inner();
        assert_eq!(s.log.len(), 2);
        assert_eq!(s.log[1].1, Command::NEUTRAL);
    }
}
