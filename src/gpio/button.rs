//! A debounced push button: the car's start/stop button.
//!
//! A mechanical contact does not close once: for a few milliseconds it chatters (bounces)
//! between open and closed, and a long cable picks up short glitches. [`Button`] sees the raw
//! level as a list of edges, each with its time in seconds, and accepts a new level only once
//! it has held, unchanged, for `debounce_s`; any pulse shorter than that is a bounce and is
//! ignored. The accepted level changes produce [`ButtonEvent`]s:
//!
//! * [`ButtonEventKind::Press`] when a press has held for `debounce_s` (so a press acts
//!   `debounce_s` after the contact first settles closed: 30 ms with the default);
//! * [`ButtonEventKind::LongPress`] once per press that stays down `long_press_s` (optional);
//! * [`ButtonEventKind::Release`] when the release has held for `debounce_s`.
//!
//! A button that is already held when the car starts is taken as the starting level: it
//! produces no press until it is released and pressed again, so a stuck button never starts
//! the car. [`StartStop`] turns presses into the car's run state: press = arm and go, press
//! again = stop.
//!
//! Time is passed in (seconds, any origin, non-decreasing); the button reads no clock, so the
//! tests replay recorded edge timings. The same type works on sampled levels: feeding the
//! same level again is not an edge and changes nothing.

use std::collections::VecDeque;

/// How the button is debounced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ButtonOptions {
    /// A level must hold this long to count, seconds (> 0). Contact bounce of common tact
    /// switches lasts 1-10 ms.
    pub debounce_s: f64,
    /// A press held this long also gives one [`ButtonEventKind::LongPress`], seconds;
    /// `None` = no long presses.
    pub long_press_s: Option<f64>,
}

impl Default for ButtonOptions {
    fn default() -> Self {
        Self {
            debounce_s: 0.030,
            long_press_s: None,
        }
    }
}

/// What the debounced button did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ButtonEventKind {
    /// The button went down (and stayed down for the debounce time).
    Press,
    /// The button went up (and stayed up for the debounce time).
    Release,
    /// The button has been held down for `long_press_s`.
    LongPress,
}

/// One debounced event and the time at which it became certain, seconds (the edge that
/// started it plus `debounce_s`, or the press plus `long_press_s`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ButtonEvent {
    /// What happened.
    pub kind: ButtonEventKind,
    /// When it was decided, seconds (same time base as the edges).
    pub t: f64,
}

/// The debouncer. See the module documentation.
#[derive(Debug, Clone)]
pub struct Button {
    opts: ButtonOptions,
    /// Raw level (true = pressed) since the last edge, and when that edge came.
    raw: bool,
    raw_since: f64,
    /// The accepted (debounced) level.
    stable: bool,
    /// When the accepted press began (its raw edge time), for the long press.
    pressed_at: f64,
    long_sent: bool,
    last_t: f64,
    events: VecDeque<ButtonEvent>,
    presses: u64,
}

impl Button {
    /// A button whose raw level is `pressed` at time `t0` (the level it has at start-up,
    /// accepted as it is: no event).
    pub fn new(opts: ButtonOptions, pressed: bool, t0: f64) -> Self {
        Self {
            opts,
            raw: pressed,
            raw_since: t0,
            stable: pressed,
            pressed_at: t0,
            // A button held at start-up never gives a long press for that hold either.
            long_sent: true,
            last_t: t0,
            events: VecDeque::with_capacity(4),
            presses: 0,
        }
    }

    /// The raw level seen at time `t` (true = pressed). A level equal to the current raw
    /// level is not an edge and only lets time pass.
    pub fn input(&mut self, pressed: bool, t: f64) {
        let t = self.clamp_time(t);
        // 1. Let the time up to this edge pass: the old level may have become stable.
        self.update(t);
        // 2. A real edge restarts the hold time.
        if pressed != self.raw {
            self.raw = pressed;
            self.raw_since = t;
        }
    }

    /// Lets time pass until `t` with no new edge.
    pub fn update(&mut self, t: f64) {
        let t = self.clamp_time(t);
        self.last_t = t;
        // 1. Accept the raw level once it has held for the debounce time.
        let settled_at = self.raw_since + self.opts.debounce_s;
        if self.raw != self.stable && t >= settled_at {
            self.stable = self.raw;
            if self.stable {
                self.pressed_at = self.raw_since;
                self.long_sent = false;
                self.presses += 1;
                self.push(ButtonEventKind::Press, settled_at);
            } else {
                self.push(ButtonEventKind::Release, settled_at);
            }
        }
        // 2. A press that lasts gives one long press. Bounces while held (raw briefly up)
        //    do not end the press: only an accepted release does.
        if let Some(long) = self.opts.long_press_s {
            let long_at = self.pressed_at + long;
            if self.stable && !self.long_sent && t >= long_at {
                self.long_sent = true;
                self.push(ButtonEventKind::LongPress, long_at);
            }
        }
    }

    /// The oldest event not yet taken, if any.
    pub fn pop_event(&mut self) -> Option<ButtonEvent> {
        self.events.pop_front()
    }

    /// The debounced level: true while the button counts as pressed.
    pub fn is_pressed(&self) -> bool {
        self.stable
    }

    /// Presses accepted since the start.
    pub fn presses(&self) -> u64 {
        self.presses
    }

    fn push(&mut self, kind: ButtonEventKind, t: f64) {
        // Nobody taking events must not grow memory without bound.
        if self.events.len() >= 64 {
            self.events.pop_front();
        }
        self.events.push_back(ButtonEvent { kind, t });
    }

    /// Time never runs backwards (a NaN or an older time is taken as the last time).
    fn clamp_time(&self, t: f64) -> f64 {
        if t >= self.last_t {
            t
        } else {
            self.last_t
        }
    }
}

/// What a press asks the car to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartStopAction {
    /// Arm the firmware and start driving.
    Start,
    /// Stop: neutral, disarm.
    Stop,
}

/// The start/stop toggle: the first press starts, the next stops, and so on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StartStop {
    running: bool,
}

impl StartStop {
    /// Stopped.
    pub fn new() -> Self {
        Self::default()
    }

    /// One accepted press: what to do now.
    pub fn press(&mut self) -> StartStopAction {
        self.running = !self.running;
        if self.running {
            StartStopAction::Start
        } else {
            StartStopAction::Stop
        }
    }

    /// The car stopped for another reason (Ctrl-C, fault, lost camera): the next press
    /// starts it again.
    pub fn force_stop(&mut self) {
        self.running = false;
    }

    /// Whether the button last asked to run.
    pub fn running(&self) -> bool {
        self.running
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: f64 = 1e-3;

    /// Feeds (time in ms, raw level) edges, then lets time run to `end_ms`; returns events
    /// with their times in ms.
    fn run(opts: ButtonOptions, start: bool, edges: &[(f64, bool)], end_ms: f64) -> Vec<(ButtonEventKind, f64)> {
        let mut b = Button::new(opts, start, 0.0);
        let mut out = vec![];
        for &(t, level) in edges {
            b.input(level, t * MS);
            while let Some(e) = b.pop_event() {
                out.push((e.kind, e.t / MS));
            }
        }
        b.update(end_ms * MS);
        while let Some(e) = b.pop_event() {
            out.push((e.kind, e.t / MS));
        }
        out
    }

    fn kinds(ev: &[(ButtonEventKind, f64)]) -> Vec<ButtonEventKind> {
        ev.iter().map(|e| e.0).collect()
    }

    /// A press recorded from a tact switch: 4 ms of chatter when closing, held 180 ms,
    /// 3 ms of chatter when opening.
    const BOUNCY_PRESS: [(f64, bool); 12] = [
        (100.0, true),
        (100.4, false),
        (101.1, true),
        (101.5, false),
        (102.9, true),
        (103.2, false),
        (104.0, true), // settles closed
        (284.0, false),
        (284.6, true),
        (285.3, false),
        (285.9, true),
        (287.0, false), // settles open
    ];

    #[test]
    fn bouncy_press_gives_one_press_and_one_release() {
        let opts = ButtonOptions {
            debounce_s: 0.020,
            long_press_s: None,
        };
        let ev = run(opts, false, &BOUNCY_PRESS, 1000.0);
        assert_eq!(kinds(&ev), vec![ButtonEventKind::Press, ButtonEventKind::Release]);
        // Press decided 20 ms after the last closing edge, release 20 ms after the last opening.
        assert!((ev[0].1 - 124.0).abs() < 1e-6, "{ev:?}");
        assert!((ev[1].1 - 307.0).abs() < 1e-6, "{ev:?}");
    }

    #[test]
    fn glitches_shorter_than_debounce_are_rejected() {
        let opts = ButtonOptions {
            debounce_s: 0.020,
            long_press_s: None,
        };
        // Three spikes of 1, 5 and 19.9 ms on an idle line: no event.
        let edges = [
            (50.0, true),
            (51.0, false),
            (200.0, true),
            (205.0, false),
            (400.0, true),
            (419.9, false),
        ];
        assert!(run(opts, false, &edges, 1000.0).is_empty());
        // A pulse of 20.1 ms is a (very short) press.
        let ev = run(opts, false, &[(400.0, true), (420.1, false)], 1000.0);
        assert_eq!(kinds(&ev), vec![ButtonEventKind::Press, ButtonEventKind::Release]);
        assert!((ev[0].1 - 420.0).abs() < 1e-6);
    }

    #[test]
    fn press_is_decided_by_update_without_a_further_edge() {
        let mut b = Button::new(ButtonOptions::default(), false, 0.0);
        b.input(true, 1.000);
        b.update(1.029);
        assert!(b.pop_event().is_none(), "29 ms < 30 ms debounce");
        b.update(1.031);
        let e = b.pop_event().expect("press after 30 ms");
        assert_eq!(e.kind, ButtonEventKind::Press);
        assert!((e.t - 1.030).abs() < 1e-9);
        assert!(b.is_pressed());
    }

    #[test]
    fn held_at_start_needs_release_and_new_press() {
        let opts = ButtonOptions {
            debounce_s: 0.020,
            long_press_s: Some(1.0),
        };
        // Held from power-on for 3 s: no press, no long press; released, then pressed again.
        let ev = run(opts, true, &[(3000.0, false), (3500.0, true)], 3600.0);
        assert_eq!(kinds(&ev), vec![ButtonEventKind::Release, ButtonEventKind::Press]);
    }

    #[test]
    fn long_press_once_and_survives_bounces_while_held() {
        let opts = ButtonOptions {
            debounce_s: 0.020,
            long_press_s: Some(1.5),
        };
        // Pressed at 0.1 s, a 2 ms drop-out at 0.9 s (shaky thumb), released at 2.5 s.
        let edges = [(100.0, true), (900.0, false), (902.0, true), (2500.0, false)];
        let ev = run(opts, false, &edges, 4000.0);
        assert_eq!(
            kinds(&ev),
            vec![
                ButtonEventKind::Press,
                ButtonEventKind::LongPress,
                ButtonEventKind::Release
            ]
        );
        assert!(
            (ev[1].1 - 1600.0).abs() < 1e-6,
            "long press 1.5 s after the press edge: {ev:?}"
        );
        // A short press never gives a long press.
        let ev = run(opts, false, &[(100.0, true), (600.0, false)], 4000.0);
        assert_eq!(kinds(&ev), vec![ButtonEventKind::Press, ButtonEventKind::Release]);
    }

    #[test]
    fn sampled_levels_work_like_edges() {
        // The same bouncy press sampled every 1 ms (a polling thread): the press is decided
        // within one sample of the edge-exact time.
        let opts = ButtonOptions {
            debounce_s: 0.020,
            long_press_s: None,
        };
        let level_at = |t: f64| {
            let mut l = false;
            for &(te, lv) in &BOUNCY_PRESS {
                if te <= t {
                    l = lv;
                }
            }
            l
        };
        let mut b = Button::new(opts, false, 0.0);
        let mut ev = vec![];
        for k in 0..1000 {
            let t = k as f64;
            b.input(level_at(t), t * MS);
            while let Some(e) = b.pop_event() {
                ev.push((e.kind, e.t / MS));
            }
        }
        assert_eq!(kinds(&ev), vec![ButtonEventKind::Press, ButtonEventKind::Release]);
        assert!((ev[0].1 - 124.0).abs() <= 1.0 + 1e-9, "{ev:?}");
        assert!((ev[1].1 - 307.0).abs() <= 1.0 + 1e-9, "{ev:?}");
    }

    #[test]
    fn time_going_backwards_or_nan_is_harmless() {
        let mut b = Button::new(ButtonOptions::default(), false, 10.0);
        b.input(true, 5.0); // older than start: taken as 10.0
        b.update(f64::NAN);
        b.update(10.05);
        assert_eq!(b.pop_event().map(|e| e.kind), Some(ButtonEventKind::Press));
        assert_eq!(b.presses(), 1);
    }

    #[test]
    fn start_stop_toggles() {
        let mut s = StartStop::new();
        assert_eq!(s.press(), StartStopAction::Start);
        assert!(s.running());
        assert_eq!(s.press(), StartStopAction::Stop);
        assert_eq!(s.press(), StartStopAction::Start);
        s.force_stop();
        assert_eq!(s.press(), StartStopAction::Start);
    }
}
