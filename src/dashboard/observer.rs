//! The loop's side of the dashboard ([`DashObserver`]): publishes a [`Snapshot`] at most
//! `stream_fps` times per second of frame time into a newest-only slot, drains the bounded
//! inbox between frames without blocking (except while the operator has paused the
//! simulator), and puts every change into the record of the first frame it acts on.
//! [`channel`] makes the slot, the inbox and the observer.

use super::messages::{Control, ControlSender, Live, PlotPoint, Snapshot, INBOX_CAPACITY};
use crate::config::Config;
use crate::control::behaviour::Transition;
use crate::drive::{Arming, Flow, FrameContext, Latest, LoopError, Observer, StopSignal};
use crate::pipeline::Pipeline;
use crate::sim::world::{lock, SharedWorld};
use crate::telemetry::FrameRecord;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A plot value to 4 decimals: a page draws no finer, and the pushed samples are a third as
/// long (a 0 stays exactly 0).
fn r4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// Applies a settable key to the running pipeline (acts on the next frame).
pub fn apply_value(p: &mut Pipeline, key: &str, value: f64) -> bool {
    p.controller_mut().set_param(key, value)
}

/// The loop's side of the dashboard: publishes snapshots, applies control messages between
/// frames, and puts its events into the record of the first frame they act on.
pub struct DashObserver {
    rx: Receiver<Control>,
    out: Arc<Latest<Arc<Snapshot>>>,
    live: Arc<Live>,
    world: Option<SharedWorld>,
    stop: Option<StopSignal>,
    /// The car's arming state: each plot sample says what the gate let through.
    arming: Option<Arc<Arming>>,
    pending: Arc<Mutex<Vec<String>>>,
    every_s: f64,
    last_pub: Option<f64>,
    points: Vec<PlotPoint>,
    roi: [[f64; 2]; 4],
    last_transition: Option<(f64, Transition)>,
    paused: bool,
    /// A `Step` was taken: pause again after this frame.
    stepping: bool,
}

/// The loop's end and the server's end of a dashboard.
pub struct Channel {
    /// Snapshots, newest only.
    pub slot: Arc<Latest<Arc<Snapshot>>>,
    /// Per-frame counters.
    pub live: Arc<Live>,
    /// The inbox, for the server.
    pub tx: ControlSender,
    /// The observer, for the loop.
    pub observer: DashObserver,
}

/// The slot the loop publishes into, the inbox sender for the server, and the observer.
pub fn channel(cfg: &Config, world: Option<SharedWorld>, stop: Option<StopSignal>, arming: Option<Arc<Arming>>) -> Channel {
    let (tx, rx) = std::sync::mpsc::sync_channel(INBOX_CAPACITY);
    let out = Arc::new(Latest::new());
    let live = Arc::new(Live::default());
    let obs = DashObserver {
        rx,
        out: out.clone(),
        live: live.clone(),
        world,
        stop,
        arming,
        pending: Arc::new(Mutex::new(Vec::new())),
        every_s: 1.0 / cfg.dashboard.stream_fps.clamp(1.0, 60.0),
        last_pub: None,
        points: Vec::new(),
        roi: cfg.warp.src,
        last_transition: None,
        paused: false,
        stepping: false,
    };
    Channel {
        slot: out,
        live,
        tx: ControlSender::new(tx),
        observer: obs,
    }
}

impl DashObserver {
    /// Whether the simulator is paused.
    pub fn paused(&self) -> bool {
        self.paused
    }

    fn event(&self, s: String) {
        self.pending.lock().unwrap_or_else(|e| e.into_inner()).push(s);
    }

    /// Applies one message; returns whether the loop should go on to the next frame now
    /// (only meaningful while paused).
    fn apply(&mut self, c: Control, p: &mut Pipeline) -> bool {
        match c {
            Control::Set { key, value, note } => {
                let was = p.controller().get_param(&key);
                if apply_value(p, &key, value) {
                    self.event(format!(
                        "{key}={value} (was {}) from {note}",
                        was.map_or("?".into(), |w| w.to_string())
                    ));
                }
                false
            }
            Control::Pause => {
                self.paused = true;
                self.event("paused from dashboard".into());
                false
            }
            Control::Resume => {
                let was = self.paused;
                self.paused = false;
                self.stepping = false;
                if was {
                    self.event("resumed from dashboard".into());
                }
                true
            }
            Control::Step => {
                self.stepping = true;
                true
            }
            Control::Reset | Control::PlaceAt(_) => {
                let s = if let Control::PlaceAt(s) = c { s } else { 0.0 };
                if let Some(w) = &self.world {
                    lock(w).place_at(s);
                    p.controller_mut().steering_mut().reset();
                    self.event(format!("car placed at s={s:.2} m from dashboard"));
                }
                false
            }
            Control::Lane { cfg, note } => {
                match p.set_lane_config(&cfg) {
                    Ok(()) => {
                        self.roi = cfg.warp.src;
                        self.event(note);
                    }
                    // Checked by the server with the same configuration checks: not expected.
                    Err(e) => self.event(format!("set-up refused by the pipeline: {e} ({note})")),
                }
                false
            }
            Control::Note(n) => {
                self.event(n);
                false
            }
        }
    }
}

impl Observer for DashObserver {
    fn before_frame(&mut self, p: &mut Pipeline) -> Flow {
        if self.stepping {
            // The stepped frame has been processed: pause again.
            self.stepping = false;
            self.paused = true;
        }
        // Every command sent since the last frame (empty or disconnected: none left).
        while let Ok(c) = self.rx.try_recv() {
            self.apply(c, p);
        }
        // Paused (simulator only): wait for the operator, a stop request ends the wait.
        self.live.paused.store(self.paused, Ordering::SeqCst);
        while self.paused {
            if self.stop.as_ref().is_some_and(|s| s.reason().is_some()) {
                break;
            }
            match self.rx.recv_timeout(Duration::from_millis(50)) {
                Ok(c) => {
                    if self.apply(c, p) {
                        break;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    self.paused = false;
                }
            }
        }
        self.live.paused.store(false, Ordering::SeqCst);
        Flow::Continue
    }

    /// The operator's changes acted on from this frame on, in its record.
    fn decorate(&mut self, r: &mut FrameRecord) {
        r.events
            .append(&mut self.pending.lock().unwrap_or_else(|e| e.into_inner()));
    }

    fn on_frame(&mut self, ctx: &FrameContext<'_>) -> Result<Flow, LoopError> {
        let r = ctx.record;
        self.live.time_bits.store(r.time_s.to_bits(), Ordering::SeqCst);
        self.live.frame.store(r.frame, Ordering::SeqCst);
        self.live.frames.fetch_add(1, Ordering::SeqCst);
        let sent = r.sent.unwrap_or(crate::control::Command { steer: r.steer, throttle: r.throttle });
        let truth = |k: &str| r.truth.as_ref().and_then(|t| t.get(k)).and_then(serde_json::Value::as_f64);
        let true_speed = truth("speed_mps");
        let gate = match &self.arming {
            Some(a) if a.is_estopped() => "estop",
            Some(a) if !a.is_armed() => "disarmed",
            Some(a) if a.is_braking() => "brake",
            _ => "armed",
        };
        self.points.push(PlotPoint {
            t: r4(r.time_s),
            error_px: r.error_px.map(r4),
            steer: r4(r.steer),
            throttle: r4(r.throttle),
            sent_steer: r4(sent.steer),
            sent_throttle: r4(sent.throttle),
            speed: true_speed.or(r.speed_est_mps).map(r4),
            speed_true: true_speed.is_some(),
            cte_m: truth("offset_m").map(r4),
            gate,
            paused: self.paused || self.stepping,
            mode: r.drive_mode.map(|m| m.name()),
            events: r.events.clone(),
        });
        if let Some(tr) = &r.transition {
            if self.last_transition.as_ref().map(|(_, t)| t) != Some(tr) {
                self.last_transition = Some((r.time_s, tr.clone()));
            }
        }
        let due = self
            .last_pub
            .is_none_or(|t| r.time_s - t >= self.every_s - 1e-6 || r.time_s < t)
            || self.paused
            || self.stepping;
        if !due {
            return Ok(Flow::Continue);
        }
        self.last_pub = Some(r.time_s);
        let p = ctx.pipeline;
        let c = p.controller();
        let values = c
            .params()
            .iter()
            .filter_map(|i| Some((i.key.to_string(), c.get_param(i.key)?)))
            .collect();
        let snap = Snapshot {
            record: r.clone(),
            image: ctx.frame.image.clone(),
            lane_images: p.lane().images().clone(),
            lane: ctx.output.lane,
            command: ctx.output.command,
            homography: *p.lane().warp_map().homography(),
            roi: self.roi,
            points: std::mem::take(&mut self.points),
            values,
            last_transition: self.last_transition.clone(),
            objects: p.objects().to_vec(),
            paused: self.paused || self.stepping,
            dropped: self.out.dropped(),
        };
        self.out.put(Arc::new(snap));
        Ok(Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dashboard::messages::{validate_setup, SetupRequest};

    /// Set-up by clicking: a new ROI and threshold reach the pipeline between two frames (its
    /// next frame measures with them, bit for bit as a pipeline built with them), the stream's
    /// ROI outline follows, and the change is an event of that frame. Under pure pursuit the
    /// steering method is rebuilt with the new bird's-eye → floor map.
    #[test]
    fn a_set_up_acts_on_the_next_frame() {
        let frame = image::open(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/lane_sample/frame_000.png"
        ))
        .unwrap()
        .to_rgb8();
        for method in ["pid", "pure_pursuit"] {
            let cfg = Config::default()
                .with_override(&format!("steering.method={method}"))
                .unwrap();
            let req = SetupRequest {
                src: [[90.0, 82.0], [230.0, 82.0], [312.0, 155.0], [6.0, 155.0]],
                threshold: Some(140.0),
                threshold_mode: Some("fixed".into()),
                adaptive_c: None,
            };
            let new = validate_setup(&cfg, &req).unwrap();
            let mut p = Pipeline::new(&cfg).unwrap();
            let mut ch = channel(&cfg, None, None, None);
            assert!(ch.tx.send(Control::Lane {
                cfg: Box::new(new.clone()),
                note: "set-up: test".into()
            }));
            assert_eq!(ch.observer.before_frame(&mut p), Flow::Continue);
            assert_eq!(ch.observer.roi, req.src);
            let mut timer = crate::timing::NoTimer;
            let got = p.step(&frame, 1.0 / 30.0, &mut timer);
            let mut r = FrameRecord::new(1, "f", 0.0, &got.lane, &got.command, got.stage_us);
            ch.observer.decorate(&mut r);
            assert_eq!(r.events, vec!["set-up: test".to_string()]);
            let mut want = Pipeline::new(&new).unwrap();
            let expect = want.step(&frame, 1.0 / 30.0, &mut timer);
            assert_eq!(p.lane().images().binary, want.lane().images().binary, "{method}");
            assert_eq!(p.lane().images().level, 140);
            assert_eq!((got.lane, got.command), (expect.lane, expect.command), "{method}");
            assert_eq!(p.controller().steering().method().name(), method);
        }
    }
}
