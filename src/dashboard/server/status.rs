//! What the page is told ([`state_json`]): the arming state, what the gate sent, the plot
//! samples after a frame time, the newest snapshot's values, and the parameter table once. Used
//! by `GET /api/state` and by the pushed stream (`GET /api/events`, [`super::push`]).

use super::state::Shared;
use crate::dashboard::messages::PlotPoint;
use serde_json::{json, Value};
use std::sync::atomic::Ordering;

/// A finite number, or `null`.
pub fn opt(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// The rows of the parameter table of a run steering with `method`, for the page's sliders.
fn param_rows(method: crate::control::steering::SteeringMethod) -> Vec<Value> {
    crate::control::catalog::of_method(method)
        .iter()
        .map(|p| json!({"key": p.key, "unit": p.unit, "range": p.range, "slider": p.slider, "doc": p.doc}))
        .collect()
}

/// The record switch: whether the run can record, whether it does, frames kept, budget left.
fn record_json(sh: &Shared) -> Value {
    let r = sh.arm.controls().record();
    let left = r.bytes_left();
    json!({
        "available": r.available(),
        "on": r.is_on(),
        "frames": r.frames(),
        "mb_left": if left == u64::MAX { Value::Null } else { json!((left as f64 / 1e6 * 10.0).round() / 10.0) },
    })
}

/// Driving by hand: the human's input as the loop would take it now, the deadline and the
/// ceiling.
fn manual_json(sh: &Shared) -> Value {
    let c = sh.arm.controls();
    let input = c.input(c.now_s());
    json!({
        "input": input.map(|(steer, throttle, age_ms)| json!({"steer": steer, "throttle": throttle, "age_ms": age_ms})),
        // the newest input's arrival, stale or not, on the dashboard's clock (`wall_s`): the
        // input is timed on the human's clock, moved here by its age
        "last_input_wall_s": opt(sh.sent.now() - (c.now_s() - c.input_at_s())),
        "input_timeout_ms": c.deadline_s() * 1e3,
        "max_throttle": c.ceiling(),
    })
}

/// The page's state: the plot samples after frame time `since`; `session`: the caller may
/// control the car; `full`: also the parameter table (the sliders; sent once per viewer).
pub fn state_json(sh: &Shared, since: f64, session: bool, full: bool) -> Value {
    let (snap, points) = {
        let v = sh.view.lock().unwrap_or_else(|e| e.into_inner());
        let pts: Vec<PlotPoint> = v.history.iter().filter(|p| p.t > since).cloned().collect();
        (v.snap.clone(), pts)
    };
    // The settable parameters, from the steering method's and the throttle's tables.
    let method = sh.cfg.lock().unwrap_or_else(|e| e.into_inner()).steering.method;
    let s = &sh.sent;
    let lim = sh.conns.limits();
    let a = &sh.access;
    let mut o = json!({
        "read_only": !session,
        "sim": sh.track_length.is_some(),
        "track_length": sh.track_length,
        "armed": sh.arm.is_armed(),
        "estop": sh.arm.is_estopped(),
        // who last armed, disarmed or stopped the car (flag, button, page, heartbeat, link, …)
        "arm_actor": sh.arm.last_actor().name(),
        "viewers": sh.viewers.load(Ordering::SeqCst),
        "subscribers": sh.subscribers.load(Ordering::SeqCst),
        "events_sent": sh.events_sent.load(Ordering::Relaxed),
        "event_bytes": sh.event_bytes.load(Ordering::Relaxed),
        "stream_frames": sh.frames_sent.load(Ordering::SeqCst),
        "wall_s": s.now(),
        "epoch_ms": std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64() * 1e3),
        "sent": {"throttle": opt(s.throttle.get()), "steer": opt(s.steer.get()), "wall_s": opt(s.clock_s.get()), "sim_s": opt(s.frame_s.get()),
                 "stopped_wall_s": opt(s.stopped_clock_s.get()), "stopped_sim_s": opt(s.stopped_frame_s.get())},
        "estop_timing": {
            "pressed_wall_s": opt(s.estop_clock_s.get()), "pressed_sim_s": opt(s.estop_frame_s.get()),
            "neutral_wall_s": opt(s.neutral_clock_s.get()), "neutral_sim_s": opt(s.neutral_frame_s.get()),
        },
        "connections": {
            "open": sh.conns.open(), "max": lim.max, "reserve": lim.reserve,
            "peak": sh.conns.peak.load(Ordering::Relaxed),
            "evicted": sh.conns.evicted.load(Ordering::Relaxed),
            "reserve_used": sh.conns.reserve_used.load(Ordering::Relaxed),
            "refused": sh.conns.refused.load(Ordering::Relaxed),
            "timed_out": sh.conns.timed_out.load(Ordering::Relaxed),
        },
        "refused": {
            "count": a.refused.load(Ordering::SeqCst),
            "last": a.last.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        },
        "log_lines_dropped": sh.log.dropped.load(Ordering::Relaxed),
        "points": points,
        "changed": *sh.changed.lock().unwrap_or_else(|e| e.into_inner()),
        "steering_method": method.name(),
        "mode": sh.arm.controls().mode().name(),
        "manual": manual_json(sh),
        "record": record_json(sh),
    });
    if full {
        o["params"] = json!(param_rows(method));
    }
    if let Some(sn) = snap {
        let r = &sn.record;
        // Exact between snapshots: the loop's own counters.
        o["frame"] = json!(sh.live.frame.load(Ordering::SeqCst));
        o["t"] = json!(sh.live.time_s());
        o["snapshot_frame"] = json!(r.frame);
        o["error"] = json!(r.error);
        o["error_px"] = json!(r.error_px);
        o["input_age_ms"] = json!(r.input_age_ms);
        o["steer"] = json!(r.steer);
        o["throttle"] = json!(r.throttle);
        o["speed"] = json!(r.speed_est_mps);
        o["status"] = json!(r.status);
        o["behaviour"] = json!(r.behaviour);
        o["junction"] = json!(r.junction);
        o["latency_ms"] = json!(r.latency_ms);
        o["period_ms"] = json!(r.period_ms);
        o["paused"] = json!(sh.live.paused.load(Ordering::SeqCst));
        o["dropped_snapshots"] = json!(sn.dropped);
        o["objects"] = json!(sn.objects);
        o["transition"] = match &sn.last_transition {
            Some((t, tr)) => json!({"t": t, "from": tr.from, "to": tr.to, "reason": tr.reason}),
            None => Value::Null,
        };
        o["values"] = Value::Object(sn.values.iter().map(|(k, v)| (k.clone(), json!(v))).collect());
    }
    o
}
