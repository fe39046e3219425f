//! The town track's road network (issue 27's first "must show"): a route through six fork
//! passages driven by the real pipeline with its detectors, every fork taken the way the route
//! says (the simulator's truth of which road the car ended up on, against the plan the track
//! predicts), no lane departure, the crossing crossed; and a route whose step names no way of
//! its fork refused by the CLI before anything runs.

use rccar::config::Config;
use rccar::route::Step;
use rccar::sim::network::JunctionKind;
use rccar::sim::plan::{configure_route, fork_ways_of};
use rccar::sim::run::{EndReason, Simulation};
use rccar::sim::track::Track;
use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn town() -> Track {
    Track::load(&Path::new(ROOT).join("config/tracks/town.toml")).unwrap()
}

/// What the test keeps of each frame: time, the front axle's position, behaviour, speed.
#[derive(Debug, Clone, Copy)]
struct Frame {
    t: f64,
    front: [f64; 2],
    mode: rccar::control::behaviour::Mode,
    speed: f64,
}

/// Drives `laps` of the town with `route` (None: the track's own), detectors on.
fn drive(route: Option<Vec<Step>>, laps: u32) -> (rccar::sim::run::Summary, Vec<rccar::sim::plan::Passage>, u32, Vec<Frame>) {
    drive_on(town(), route, laps, None)
}

/// Drives `track` for `laps` (or `seconds` of simulated time), detectors on.
fn drive_on(
    track: Track,
    route: Option<Vec<Step>>,
    laps: u32,
    seconds: Option<f64>,
) -> (rccar::sim::run::Summary, Vec<rccar::sim::plan::Passage>, u32, Vec<Frame>) {
    drive_with(track, route, laps, seconds, &[])
}

/// As [`drive_on`], the shipped configuration with `sets` (`key=value`) on top.
fn drive_with(
    track: Track,
    route: Option<Vec<Step>>,
    laps: u32,
    seconds: Option<f64>,
    sets: &[&str],
) -> (rccar::sim::run::Summary, Vec<rccar::sim::plan::Passage>, u32, Vec<Frame>) {
    let mut cfg = Config::default().with_override(&format!("sim.laps={laps}")).unwrap();
    for set in sets {
        cfg = cfg.with_override(set).unwrap();
    }
    if let Some(s) = seconds {
        cfg.sim.max_seconds = s;
    }
    let steps = configure_route(&mut cfg, &track, route);
    let plan = track.plan(&steps, laps.max(1)).unwrap();
    let mut sim = Simulation::new(&cfg, &track).unwrap();
    let (det, missing) = rccar::pipeline::load_detector(&cfg, &Path::new(ROOT).join("config")).unwrap();
    assert!(missing.is_empty(), "{missing:?}");
    sim.set_detector(det);
    let mut forks_met = 0;
    let mut frames = Vec::new();
    let wheelbase = cfg.vehicle.wheelbase_m;
    let summary = sim
        .run(|_, s| {
            let [x, y, yaw] = s.truth.pose;
            frames.push(Frame {
                t: s.time_s,
                front: [x + wheelbase * yaw.cos(), y + wheelbase * yaw.sin()],
                mode: s.out.mode,
                speed: s.truth.speed_mps,
            });
            if s.out.junction.is_some_and(|j| j.new && j.kind == rccar::lane::junction::JunctionKind::Fork) {
                forks_met += 1;
            }
            Ok::<(), ()>(())
        })
        .unwrap();
    (summary, plan, forks_met, frames)
}

/// The stretches of standing still in `mode` (true speed below the behaviour's standstill speed,
/// `behaviour.standstill_mps` = 1 cm/s): (first frame, last frame).
fn stands(frames: &[Frame], mode: rccar::control::behaviour::Mode) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        if f.mode == mode && f.speed.abs() < 0.01 {
            match out.last_mut() {
                Some(l) if l.1 + 1 == i => l.1 = i,
                _ => out.push((i, i)),
            }
        }
    }
    out
}

#[test]
fn the_town_route_takes_every_fork_the_way_it_says() {
    let (s, plan, met, frames) = drive(None, 3);
    check_the_route(&s, &plan, met, &frames);
}

/// Issue 27's "must show" 3: the same route, the same checks, at the strongest light
/// (`sim.light_level = 3`: shadows across the road, sun patches, dusk, sensor noise) in the
/// shipped configuration (the adaptive threshold, opened; obstacle boxes the floor's colour
/// dropped as shadows), and not one stop for an obstacle: the town has none on this route, so
/// any would be a shadow or a sun patch taken for one.
#[test]
fn the_town_route_at_the_strongest_light() {
    let (s, plan, met, frames) = drive_with(town(), None, 3, None, &["sim.light_level=3"]);
    check_the_route(&s, &plan, met, &frames);
    let phantoms = frames.iter().filter(|f| f.mode == rccar::control::behaviour::Mode::Obstacle).count();
    assert_eq!(phantoms, 0, "{phantoms} frames stopped for an obstacle");
}

/// Three laps of the shipped route: every fork as planned, no departure, each road driven, the
/// crossing crossed twice, the stop held at its line, the yield passed without a stop.
fn check_the_route(s: &rccar::sim::run::Summary, plan: &[rccar::sim::plan::Passage], met: u32, frames: &[Frame]) {
    for l in s.lines() {
        eprintln!("{l}");
    }
    assert_eq!(s.end, EndReason::LapsDone, "{:?}", s.end);
    assert_eq!(s.laps, 3);
    assert_eq!(s.lane_departures, 0, "departures at {:?}", s.departures_at_m);
    let (want, got) = (fork_ways_of(plan), fork_ways_of(&s.junctions));
    assert!(want.len() >= 6, "the shipped route passes {} forks", want.len());
    assert_eq!(got, want, "forks driven (junction, way) vs planned");
    // The pipeline met exactly the forks the car passed (no merge taken for a fork).
    assert_eq!(met as usize, got.len());
    // Each way of the network is driven: main, A, B, C, and the crossing is crossed both ways.
    for road in ["A", "B", "C"] {
        assert!(s.junctions.iter().any(|p| p.road == road), "never on {road}");
    }
    let crossings = s.junctions.iter().filter(|p| p.kind == JunctionKind::Crossing).count();
    assert_eq!(crossings, 2);
    assert!(s.xte_rms_m < 0.03, "cross-track RMS {:.4} m", s.xte_rms_m);
    // The stop sign on B, with its stop line: the car's front axle stands at the line's near
    // edge (x = 4.805 m, B heads west) within 3 cm, for the 5 s hold, then drives on.
    let track = town();
    let line = track.marks.iter().find(|m| m.kind == rccar::sim::track::MarkKind::StopLine).unwrap();
    let near_edge = line.pos[0] + line.width / 2.0;
    let at_b = stands(frames, rccar::control::behaviour::Mode::StopSign);
    let slowest = frames
        .iter()
        .filter(|f| f.mode == rccar::control::behaviour::Mode::StopSign)
        .map(|f| f.speed)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(at_b.len(), 1, "one stop at the stop sign on the route: {at_b:?} (slowest in stop_sign {slowest} m/s)");
    let (a, b) = at_b[0];
    let miss = frames[a].front[0] - near_edge;
    let held = frames[b].t - frames[a].t;
    eprintln!("stop line: front {:+.1} mm from its near edge, held {held:.2} s", miss * 1000.0);
    assert!(miss.abs() <= 0.03, "front {miss:+.4} m from the stop line");
    assert!(held >= 4.9, "held {held:.2} s");
    assert!((frames[a].front[1] - line.pos[1]).abs() < 0.05, "stopped elsewhere: {:?}", frames[a].front);
    // The yield sign on A with nothing crossing: the car creeps past it, never stops.
    use rccar::control::behaviour::Mode;
    assert!(frames.iter().any(|f| f.mode == Mode::Yield), "never yielded on A");
    assert!(frames.iter().all(|f| f.mode != Mode::YieldStop), "stopped at the yield sign with nothing crossing");
    assert!(stands(frames, Mode::Yield).is_empty());
}

/// The town with an edit of its text (a sign switched on, an obstacle added).
fn town_with(edit: impl Fn(&str) -> String) -> Track {
    let text = std::fs::read_to_string(Path::new(ROOT).join("config/tracks/town.toml")).unwrap();
    Track::from_toml_str(&edit(&text), "town.toml").unwrap()
}

#[test]
fn turn_signs_decide_their_fork_against_the_route() {
    // Fork B: the route says straight, the "turn left" sign before B says left.
    let route = vec![Step::Straight, Step::Left, Step::Straight];
    let (s, plan, _, _) = drive(Some(route), 1);
    let b = plan.iter().find(|p| p.kind == JunctionKind::Fork && p.road == "B").expect("the plan takes B");
    assert_eq!((b.way, b.why, b.step), (Some(Step::Left), Some(rccar::route::Why::Sign), Some(2)));
    assert_eq!(fork_ways_of(&s.junctions), fork_ways_of(&plan), "driven vs planned (with the sign)");
    assert_eq!(s.lane_departures, 0);
    // Fork C with its "turn right" sign switched on: the route says left (stay on main).
    let track = town_with(|t| t.replace("yaw_deg = 180\nenabled = false", "yaw_deg = 180\nenabled = true"));
    assert!(track.enabled_objects().filter(|o| o.arrow.is_some()).count() == 2, "the right-turn sign is on");
    let (s, plan, _, _) = drive_on(track, Some(vec![Step::Straight, Step::Left]), 1, None);
    let c = &plan.iter().filter(|p| p.kind == JunctionKind::Fork).collect::<Vec<_>>()[1];
    assert_eq!((c.way, c.why, c.road.as_str()), (Some(Step::Right), Some(rccar::route::Why::Sign), "C"));
    assert_eq!(fork_ways_of(&s.junctions), fork_ways_of(&plan));
    assert_eq!(s.lane_departures, 0);
}

#[test]
fn a_yield_stops_at_its_line_while_an_obstacle_is_in_the_crossing() {
    // An obstacle in the crossing of A and B; the route takes A (left at the first fork).
    let track = town_with(|t| {
        format!("{t}\n[[objects]]\ntype = \"obstacle\"\nx = 4.5\ny = 6.5\nsize_m = [0.15, 0.12, 0.10]\ncolor = [170, 70, 40]\n")
    });
    let line = track.marks.iter().find(|m| m.kind == rccar::sim::track::MarkKind::YieldLine).unwrap();
    let near_edge = line.pos[1] - line.width / 2.0;
    let (_, _, _, frames) = drive_on(track, Some(vec![Step::Left]), 0, Some(35.0));
    use rccar::control::behaviour::Mode;
    let st = stands(&frames, Mode::YieldStop);
    assert!(!st.is_empty(), "never stood yielding");
    let (a, b) = (st[0].0, st.last().unwrap().1);
    let miss = frames[a].front[1] - near_edge;
    eprintln!("yield line: front {:+.1} mm from its near edge, stood {:.1} s", miss * 1000.0, frames[b].t - frames[a].t);
    assert!(miss.abs() <= 0.03, "front {miss:+.4} m from the give-way line");
    // It stays while the obstacle stays, and never reaches the crossing.
    assert!(frames[b].t - frames[a].t > 3.0);
    assert!(frames.iter().all(|f| f.front[1] < near_edge + 0.03));
}

#[test]
fn a_route_step_no_fork_offers_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(dir.path())
        .args(["sim", "--config", &format!("{ROOT}/config/car.toml"), "--track", "town", "--route", "right", "--laps", "1", "--no-timing", "-o"])
        .arg(dir.path().join("run"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "a bad input exits 2: {err}");
    assert!(err.contains("route step 1 is `right`") && err.contains("town.toml"), "{err}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rccar"))
        .current_dir(dir.path())
        .args(["sim", "--config", &format!("{ROOT}/config/car.toml"), "--track", "town", "--route", "left,up", "--no-timing"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("step 2 is `up`"), "{err}");
}

#[test]
fn without_the_junction_rule_the_car_does_not_follow_the_route() {
    // The same pipeline with `route.junctions = "off"`: Eq. 3 on the two peaks at the fork.
    let track = town();
    let mut cfg = Config::default()
        .with_override("sim.laps=1")
        .unwrap()
        .with_override("route.junctions=\"off\"")
        .unwrap();
    let steps = configure_route(&mut cfg, &track, Some(vec![Step::Left]));
    let plan = track.plan(&steps, 1).unwrap();
    let mut sim = Simulation::new(&cfg, &track).unwrap();
    sim.set_full_frames(false);
    let s = sim.run(|_, _| Ok::<(), ()>(())).unwrap();
    assert_ne!(fork_ways_of(&s.junctions), fork_ways_of(&plan), "the rule is what takes the branch");
    assert_eq!(fork_ways_of(&s.junctions)[0], (0, Step::Straight));
}

/// The phantom obstacle of light level 2, before `detect.shadow_tolerance`: on the main road's
/// top edge (x −2.79 m, y 8.10 m) a shadow blotch lies across the lane; the obstacle cascade
/// boxed it 0.37 m ahead, the car stopped, and standing still it saw the same picture every
/// frame and stood there for the rest of its run (441 s). Rendered at that pose at light
/// level 2, frames with the camera noise of eight frame numbers: with the check off the
/// pipeline reports an obstacle in 3 of the 8; with the shipped tolerance it finds the box
/// the floor's colour (only darker) and drops it, in every one.
#[test]
fn a_shadow_across_the_lane_is_not_an_obstacle() {
    use rccar::pipeline::{load_detector, Pipeline};
    use rccar::sim::vehicle::Pose;
    let count = |tolerance: &str| -> usize {
        let cfg = Config::default()
            .with_override("sim.light_level=2")
            .unwrap()
            .with_override(&format!("detect.shadow_tolerance={tolerance}"))
            .unwrap();
        let sim = Simulation::new(&cfg, &town()).unwrap();
        let mut renderer = sim.renderer();
        let pose = Pose {
            x: -2.7895,
            y: 8.1004,
            yaw: 10.62126,
        };
        // One pipeline with its cascades loaded once; each frame runs on a fresh copy of it.
        let mut fresh = Pipeline::new(&cfg).unwrap();
        let (det, missing) = load_detector(&cfg, &Path::new(ROOT).join("config")).unwrap();
        assert!(missing.is_empty(), "{missing:?}");
        fresh.set_detector(det);
        (4760..4768)
            .filter(|&frame| {
                let img = renderer.render_new(&pose, frame as f64 / 30.0, frame);
                let mut pipe = fresh.clone();
                pipe.step(&img, 1.0 / 30.0, &mut rccar::timing::NoTimer);
                pipe.objects()
                    .iter()
                    .any(|o| o.class == rccar::ranging::ObjectClass::Obstacle)
            })
            .count()
    };
    let (off, on) = (count("0"), count("0.02"));
    eprintln!("frames with an obstacle box: check off {off} of 8, on {on} of 8");
    assert!(
        off >= 2,
        "the shadow is no longer boxed ({off} of 8): the test no longer shows the fault"
    );
    assert_eq!(on, 0, "the shadow is taken for an obstacle in {on} of 8 frames");
}
