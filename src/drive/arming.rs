//! One arming state for every way the car is armed or stopped, and the one gate every command
//! passes on its way to the motors.
//!
//! ```text
//!  --arm flag ─┐                                   ┌─ interlock: link lost, brake sensor dead
//!  button ─────┤                                   │  (Health)
//!  page ───────┼──► Arming (atomics) ◄─────────────┘
//!  pad, broker ┘       │ armed? e-stop? brake?
//!                      ▼
//!  pipeline ──cmd──► Gate ──(arm / disarm the actuators, cmd or neutral)──► Actuators
//!                      │                                                    (link, simulated car,
//!                      └──► Sent (what really went out, for plots)          nothing)
//! ```
//!
//! [`Arming`] is a few atomics behind an `Arc`: any thread (a signal thread, the dashboard's
//! server, the GPIO poller) may arm, disarm or press the emergency stop without waiting for
//! the loop. The e-stop latches until released on purpose; arming is refused while it is
//! pressed or while [`Health::interlock`] names a fault. Every change remembers who made it
//! ([`Actor`]), so telemetry can say "disarmed by the page".
//!
//! [`Gate`] is the only way from the loop to the motors: it compares the arming state with the
//! actuators' own (a firmware that must be sent ARM/DISARM), reports a lost or reconnected
//! link (a reconnect disarms; a link lost for longer than `give_up_s` is a fatal fault), lets
//! a command through only while armed (the ultrasonic brake caps the throttle at 0), and
//! returns what it actually sent.

use crate::health::{Health, Part, PartState};
pub use super::actor::{Actor, AtomicF64};
use super::manual::Controls;
use super::{Clock, StopReason, StopSignal};
use crate::control::Command;
use crate::sink::{Actuators, CommandSink, Connection, SinkError};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;

/// Why arming was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// The emergency stop is pressed.
    #[error("the emergency stop is pressed: release it first")]
    EStopped,
    /// A fault stands in the way (named).
    #[error("{0}")]
    Interlock(String),
}

/// Who wants the car armed, whether the emergency stop is pressed, and whether the ultrasonic
/// brake holds it. Shared by `Arc`; every method is lock-free.
#[derive(Debug)]
pub struct Arming {
    armed: AtomicBool,
    estop: AtomicBool,
    brake: AtomicBool,
    /// Bumped on every change, so a watcher can tell something happened.
    version: AtomicU64,
    /// The last actor of a change.
    actor: AtomicU8,
    health: Arc<Health>,
    /// The driving mode and the human's input, beside the arming (`super::manual`).
    controls: Controls,
}

impl Arming {
    /// Disarmed, e-stop released, guarded by `health`'s interlocks.
    pub fn new(health: Arc<Health>) -> Arc<Self> {
        Arc::new(Self {
            armed: AtomicBool::new(false),
            estop: AtomicBool::new(false),
            brake: AtomicBool::new(false),
            version: AtomicU64::new(0),
            actor: AtomicU8::new(Actor::Program as u8),
            health,
            controls: Controls::new(),
        })
    }

    fn changed(&self, by: Actor) {
        self.actor.store(by as u8, Ordering::SeqCst);
        self.version.fetch_add(1, Ordering::SeqCst);
    }

    /// Arms, unless the e-stop is pressed or a fault interlocks.
    pub fn arm(&self, by: Actor) -> Result<(), Refused> {
        if self.estop.load(Ordering::SeqCst) {
            return Err(Refused::EStopped);
        }
        if let Some(f) = self.health.interlock() {
            return Err(Refused::Interlock(f.to_string()));
        }
        if !self.armed.swap(true, Ordering::SeqCst) {
            self.changed(by);
        }
        Ok(())
    }

    /// Disarms (the car stops and stays stopped until armed again).
    pub fn disarm(&self, by: Actor) {
        if self.armed.swap(false, Ordering::SeqCst) {
            self.changed(by);
        }
    }

    /// The start/stop button: disarms an armed car, arms a disarmed one. Returns whether the
    /// car is armed now, or why arming was refused.
    pub fn toggle(&self, by: Actor) -> Result<bool, Refused> {
        if self.armed.load(Ordering::SeqCst) {
            self.disarm(by);
            Ok(false)
        } else {
            self.arm(by).map(|_| true)
        }
    }

    /// Presses the emergency stop: disarmed, and arming refused until [`Arming::release`].
    /// Only atomics: safe from any thread, never waits.
    pub fn estop(&self, by: Actor) {
        self.estop.store(true, Ordering::SeqCst);
        self.armed.store(false, Ordering::SeqCst);
        self.changed(by);
    }

    /// Releases the emergency stop (the car stays disarmed).
    pub fn release(&self, by: Actor) {
        if self.estop.swap(false, Ordering::SeqCst) {
            self.changed(by);
        }
    }

    /// The ultrasonic brake: while set, no forward throttle passes the gate.
    pub fn set_brake(&self, on: bool) {
        self.brake.store(on, Ordering::SeqCst);
    }

    /// Whether commands may move the car.
    pub fn is_armed(&self) -> bool {
        self.armed.load(Ordering::SeqCst) && !self.estop.load(Ordering::SeqCst)
    }

    /// Whether the emergency stop is pressed.
    pub fn is_estopped(&self) -> bool {
        self.estop.load(Ordering::SeqCst)
    }

    /// Whether the ultrasonic brake holds the car.
    pub fn is_braking(&self) -> bool {
        self.brake.load(Ordering::SeqCst)
    }

    /// Changes so far.
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::SeqCst)
    }

    /// Who made the last change.
    pub fn last_actor(&self) -> Actor {
        Actor::from_u8(self.actor.load(Ordering::SeqCst))
    }

    /// The health this arming is guarded by.
    pub fn health(&self) -> &Arc<Health> {
        &self.health
    }

    /// Who drives (the mode) and the human's newest input: the loop chooses the command by
    /// them before the gate, so everything above still holds for a human.
    pub fn controls(&self) -> &Controls {
        &self.controls
    }
}

/// What the gate really sent, and when (on the run's clock), for the dashboard's plots and the
/// e-stop measurement. Atomics only: the e-stop handler never waits for the loop.
#[derive(Debug, Default)]
pub struct Sent {
    /// Throttle of the last command sent.
    pub throttle: AtomicF64,
    /// Steering of the last command sent.
    pub steer: AtomicF64,
    /// When it was sent, seconds on the run's clock.
    pub clock_s: AtomicF64,
    /// The frame time it was sent for, seconds (simulated time in the simulator).
    pub frame_s: AtomicF64,
    /// When the e-stop was pressed, seconds on the run's clock (NaN: not pressed).
    pub estop_clock_s: AtomicF64,
    /// The frame time of the last command before the e-stop.
    pub estop_frame_s: AtomicF64,
    /// When the first zero-throttle command after the e-stop was sent, clock seconds.
    pub neutral_clock_s: AtomicF64,
    /// … and its frame time.
    pub neutral_frame_s: AtomicF64,
    /// When the throttle sent last became 0 (the first zero after a non-zero throttle),
    /// clock seconds: a released joystick or key is measured here. NaN: never moved.
    pub stopped_clock_s: AtomicF64,
    /// … and its frame time.
    pub stopped_frame_s: AtomicF64,
}

impl Sent {
    /// Nothing sent yet.
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    /// The e-stop was pressed at `clock_s` (the server's e-stop handler, before it presses).
    pub fn mark_estop(&self, clock_s: f64) {
        self.neutral_clock_s.set(f64::NAN);
        self.neutral_frame_s.set(f64::NAN);
        self.estop_frame_s.set(self.frame_s.get());
        self.estop_clock_s.set(clock_s);
    }

    fn record(&self, cmd: Command, clock_s: f64, frame_s: f64) {
        let before = self.throttle.get();
        if cmd.throttle == 0.0 && before != 0.0 && !before.is_nan() {
            self.stopped_clock_s.set(clock_s);
            self.stopped_frame_s.set(frame_s);
        }
        self.throttle.set(cmd.throttle);
        self.steer.set(cmd.steer);
        self.clock_s.set(clock_s);
        self.frame_s.set(frame_s);
        if !self.estop_clock_s.get().is_nan() && self.neutral_clock_s.get().is_nan() && cmd.throttle == 0.0 {
            self.neutral_clock_s.set(clock_s);
            self.neutral_frame_s.set(frame_s);
        }
    }
}

/// What the gate needs besides the actuators.
pub struct GateOptions {
    /// The run's arming state.
    pub arming: Arc<Arming>,
    /// Stopped with [`StopReason::Fault`] when the link is lost for good.
    pub stop: StopSignal,
    /// The run's clock (how long the link has been down; [`Sent`] times).
    pub clock: Arc<dyn Clock + Send + Sync>,
    /// A link down for longer than this, seconds, is a fatal fault (the run ends).
    pub give_up_s: f64,
}

/// The one gate between the loop and the motors (see the module notes).
pub struct Gate<A: Actuators> {
    inner: A,
    arming: Arc<Arming>,
    stop: StopSignal,
    clock: Arc<dyn Clock + Send + Sync>,
    give_up_s: f64,
    /// Whether the actuators are armed (the firmware was sent ARM and did not reset since).
    armed: bool,
    /// The arming state as last seen: (armed, e-stop, version).
    seen: (bool, bool, u64),
    braking: bool,
    down_since: Option<f64>,
    sent: Arc<Sent>,
    events: Vec<String>,
}

impl<A: Actuators> Gate<A> {
    /// Gates `inner` by `opts.arming`.
    pub fn new(inner: A, opts: GateOptions) -> Self {
        Self {
            inner,
            seen: (opts.arming.is_armed(), opts.arming.is_estopped(), opts.arming.version()),
            arming: opts.arming,
            stop: opts.stop,
            clock: opts.clock,
            give_up_s: opts.give_up_s,
            armed: false,
            braking: false,
            down_since: None,
            sent: Sent::new(),
            events: Vec::new(),
        }
    }

    /// What was really sent (shared with a dashboard).
    pub fn sent(&self) -> Arc<Sent> {
        self.sent.clone()
    }

    /// The actuators.
    pub fn inner_mut(&mut self) -> &mut A {
        &mut self.inner
    }

    fn health(&self) -> &Health {
        &self.arming.health
    }

    /// 1. The connection: a lost link disarms and interlocks; for good after `give_up_s`.
    fn check_connection(&mut self) {
        let now = self.clock.now_s();
        match self.inner.connection() {
            Connection::Up => {
                if self.down_since.take().is_some() {
                    self.health().set(Part::Link, PartState::Ok, "");
                    self.events.push("link: up again".into());
                }
            }
            Connection::Reconnected => {
                self.down_since = None;
                self.health().set(Part::Link, PartState::Ok, "");
                self.armed = false;
                if self.arming.is_armed() {
                    self.arming.disarm(Actor::Link);
                }
                self.events.push("link: reconnected (firmware restarted or port back); disarmed until armed again".into());
            }
            Connection::Down(why) => {
                let since = *self.down_since.get_or_insert(now);
                self.armed = false;
                if self.health().state(Part::Link) != PartState::Failed {
                    if self.health().set(Part::Link, PartState::Lost, &why) {
                        self.events.push(format!("link lost: {why}; disarmed"));
                    }
                    self.arming.disarm(Actor::Link);
                    if now - since >= self.give_up_s {
                        self.health()
                            .fail(Part::Link, format!("lost for {:.1} s: {why}", now - since));
                        self.stop.request(StopReason::Fault);
                    }
                }
            }
        }
    }

    /// 2. Arming changes since the last command, as events naming who.
    fn note_changes(&mut self) {
        let (a, e, v) = (self.arming.is_armed(), self.arming.is_estopped(), self.arming.version());
        if v != self.seen.2 {
            let who = self.arming.last_actor().name();
            if e && !self.seen.1 {
                self.events.push(format!("e-stop by {who}"));
            } else if !e && self.seen.1 {
                self.events.push(format!("e-stop released by {who}"));
            }
            if a && !self.seen.0 {
                self.events.push(format!("armed by {who}"));
            } else if !a && self.seen.0 && !e {
                self.events.push(format!("disarmed by {who}"));
            }
        }
        self.seen = (a, e, v);
        let b = self.arming.is_braking();
        if b != self.braking {
            self.events.push(if b { "ultrasonic brake on".into() } else { "ultrasonic brake off".into() });
            self.braking = b;
        }
    }

    /// 3. The actuators follow the arming state (ARM / DISARM to the firmware).
    fn follow_arming(&mut self) -> Result<bool, SinkError> {
        let want = self.arming.is_armed() && self.down_since.is_none();
        if want && !self.armed {
            match self.inner.arm() {
                Ok(()) => self.armed = true,
                Err(e) => {
                    self.arming.disarm(Actor::Link);
                    self.events.push(format!("arming refused by the actuators: {e}"));
                }
            }
        } else if !want && self.armed {
            self.armed = false;
            self.inner.disarm()?;
        }
        Ok(want && self.armed)
    }
}

impl<A: Actuators> CommandSink for Gate<A> {
    fn send(&mut self, cmd: Command, now_s: f64) -> Result<Command, SinkError> {
        self.check_connection();
        self.note_changes();
        let go = self.follow_arming()?;
        // 4. The command, or neutral; the brake allows no forward throttle.
        let c = match (go, self.braking) {
            (false, _) => Command::NEUTRAL,
            (true, true) => Command {
                steer: cmd.steer,
                throttle: cmd.throttle.min(0.0),
            },
            (true, false) => cmd,
        };
        let sent = self.inner.send(c, now_s)?;
        self.sent.record(sent, self.clock.now_s(), now_s);
        Ok(sent)
    }

    fn stop(&mut self) -> Result<(), SinkError> {
        self.armed = false;
        let r = self.inner.disarm();
        self.sent.record(Command::NEUTRAL, self.clock.now_s(), self.sent.frame_s.get());
        r
    }

    fn drain_events(&mut self, out: &mut Vec<String>) {
        out.append(&mut self.events);
        self.inner.drain_events(out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::NoClock;
    use crate::sink::RecordingSink;

    /// Actuators that log arm/disarm and whose connection the test sets.
    #[derive(Default)]
    struct Fake {
        log: RecordingSink,
        calls: Vec<&'static str>,
        conn: Option<Connection>,
    }
    impl CommandSink for Fake {
        fn send(&mut self, c: Command, t: f64) -> Result<Command, SinkError> {
            self.log.send(c, t)
        }
    }
    impl Actuators for Fake {
        fn arm(&mut self) -> Result<(), SinkError> {
            self.calls.push("arm");
            Ok(())
        }
        fn disarm(&mut self) -> Result<(), SinkError> {
            self.calls.push("disarm");
            Ok(())
        }
        fn connection(&mut self) -> Connection {
            self.conn.take().unwrap_or(Connection::Up)
        }
    }

    fn gate(arming: &Arc<Arming>) -> Gate<Fake> {
        Gate::new(
            Fake::default(),
            GateOptions {
                arming: arming.clone(),
                stop: StopSignal::new(),
                clock: Arc::new(NoClock),
                give_up_s: 3.0,
            },
        )
    }

    const GO: Command = Command {
        steer: 0.1,
        throttle: 0.4,
    };

    #[test]
    fn only_armed_commands_pass_and_estop_latches() {
        let st = Arming::new(Health::new());
        let mut g = gate(&st);
        let mut sent = vec![g.send(GO, 0.0).unwrap()];
        st.arm(Actor::Flag).unwrap();
        sent.push(g.send(GO, 0.1).unwrap());
        st.estop(Actor::Page);
        assert_eq!(st.arm(Actor::Button), Err(Refused::EStopped), "arming refused while e-stopped");
        sent.push(g.send(GO, 0.2).unwrap());
        st.release(Actor::Page);
        sent.push(g.send(GO, 0.3).unwrap());
        st.arm(Actor::Page).unwrap();
        sent.push(g.send(GO, 0.4).unwrap());
        assert_eq!(sent, vec![Command::NEUTRAL, GO, Command::NEUTRAL, Command::NEUTRAL, GO]);
        assert_eq!(g.inner.calls, vec!["arm", "disarm", "arm"], "the actuators follow");
        let mut ev = Vec::new();
        g.drain_events(&mut ev);
        assert_eq!(ev, vec!["armed by --arm", "e-stop by page", "e-stop released by page", "armed by page"]);
    }

    #[test]
    fn the_brake_allows_no_forward_throttle() {
        let st = Arming::new(Health::new());
        let mut g = gate(&st);
        st.arm(Actor::Flag).unwrap();
        st.set_brake(true);
        let back = Command {
            steer: -0.2,
            throttle: -0.3,
        };
        assert_eq!(g.send(GO, 0.0).unwrap(), Command { steer: 0.1, throttle: 0.0 });
        assert_eq!(g.send(back, 0.1).unwrap(), back, "reversing away is allowed");
        st.set_brake(false);
        assert_eq!(g.send(GO, 0.2).unwrap(), GO);
    }

    #[test]
    fn a_lost_link_disarms_interlocks_and_a_reconnect_needs_arming_again() {
        let st = Arming::new(Health::new());
        let mut g = gate(&st);
        st.arm(Actor::Button).unwrap();
        assert_eq!(g.send(GO, 0.0).unwrap(), GO);
        g.inner.conn = Some(Connection::Down("read: EIO".into()));
        assert_eq!(g.send(GO, 0.1).unwrap(), Command::NEUTRAL);
        assert!(!st.is_armed());
        let refused = st.arm(Actor::Button).unwrap_err();
        assert!(refused.to_string().contains("EIO"), "{refused}");
        g.inner.conn = Some(Connection::Reconnected);
        assert_eq!(g.send(GO, 0.2).unwrap(), Command::NEUTRAL, "a reconnect does not drive off");
        st.arm(Actor::Button).unwrap();
        assert_eq!(g.send(GO, 0.3).unwrap(), GO);
    }

    #[test]
    fn a_link_down_for_good_is_fatal_and_stops_the_run() {
        struct Ticking(std::sync::Mutex<f64>);
        impl Clock for Ticking {
            fn now_s(&self) -> f64 {
                let mut t = self.0.lock().unwrap();
                *t += 1.0;
                *t
            }
        }
        let st = Arming::new(Health::new());
        let stop = StopSignal::new();
        let mut g = Gate::new(
            Fake::default(),
            GateOptions {
                arming: st.clone(),
                stop: stop.clone(),
                clock: Arc::new(Ticking(std::sync::Mutex::new(0.0))),
                give_up_s: 2.5,
            },
        );
        for k in 0..4 {
            g.inner.conn = Some(Connection::Down("port gone".into()));
            g.send(GO, k as f64).unwrap();
        }
        assert_eq!(stop.reason(), Some(StopReason::Fault));
        let f = st.health().fatal().unwrap();
        assert_eq!(f.part, Part::Link);
        assert!(f.message.contains("port gone"), "{f}");
    }
}
