//! The simulated car's camera: a [`FrameSource`] rendering what the car's camera sees of the
//! shared [`World`], in one of two timings:
//!
//! - **lock-step** (`rccar sim`, tests, sweeps): frame k at `t_k = k / fps`; the world moves
//!   only when the loop's command arrives ([`super::world::SimVehicle`] steps it one frame
//!   period), so a run is reproducible to the bit and faster than real time;
//! - **on the wall clock** (`rccar drive --camera sim`, the firmware in the loop): at each tick
//!   (1/fps on the clock handed in) the world is first advanced to now under whatever the
//!   actuators do (the firmware's PWM pulses, or the commands in a dry run; see
//!   [`super::pwm`]), then rendered. A late tick is never queued: the next frame is the one due
//!   now, and the ticks missed count as dropped. A scripted stall (`--sim-stall T:D`) delivers
//!   nothing for D seconds, as an unplugged camera would.
//!
//! Both render the same way (only the rows the pipeline reads when nobody looks at the frames,
//! see [`SimCamera::set_row_plan`]) and may carry a stereo pair's other view and the objects'
//! true boxes.
//!
//! Units: seconds, pixels.

use super::stereo::OtherCamera;
use super::world::{lock, SharedWorld};
use crate::control::Command;
use crate::drive::Clock;
use crate::pipeline::RowPlan;
use crate::source::{Frame, FrameError, FrameSource, OtherView};
use image::RgbImage;
use std::ops::Range;
use std::sync::{Arc, Mutex};

/// What the simulated car's actuators do right now on the wall clock: the firmware's pulse
/// widths turned into a command ([`super::pwm::PwmWatcher`]) or, in a dry run, the gate's
/// commands themselves ([`super::pwm::SimActuators`]).
pub type ActuatorState = Arc<Mutex<Command>>;

/// The wall-clock timing of a [`SimCamera`].
struct WallClock {
    clock: Arc<dyn Clock + Send + Sync>,
    actuators: ActuatorState,
    t0: f64,
    last_advance: f64,
    carry: f64,
    stall: Option<(f64, f64)>,
}

/// The simulated car's camera (see the module notes).
pub struct SimCamera {
    world: SharedWorld,
    image: RgbImage,
    frame: u64,
    fps: f64,
    /// Rows to render: `None` = all (recording, viewing, detection).
    rows: Option<Range<usize>>,
    /// Rows to render per frame, from the pipeline (overrides `rows`), and the camera frame
    /// at which the plan was made.
    plan: Option<(RowPlan, u64)>,
    truth_boxes: bool,
    end_with_world: bool,
    /// A stereo pair's other camera and its image (src/sim/stereo.rs `other_camera`).
    other: Option<(OtherCamera, RgbImage)>,
    wall: Option<WallClock>,
}

impl SimCamera {
    /// The lock-step camera of `world`.
    pub fn new(world: SharedWorld) -> SimCamera {
        let (w, h, fps) = {
            let g = lock(&world);
            (g.config().camera.width, g.config().camera.height, g.config().camera.fps)
        };
        SimCamera {
            world,
            image: RgbImage::new(w, h),
            frame: 0,
            fps,
            rows: None,
            plan: None,
            truth_boxes: false,
            end_with_world: true,
            other: None,
            wall: None,
        }
    }

    /// The camera on the wall clock: `clock` paces the ticks, `actuators` is what moves the
    /// car between them; `stall`: `(T, D)` seconds of a scripted camera stall.
    pub fn on_wall_clock(
        mut self,
        clock: Arc<dyn Clock + Send + Sync>,
        actuators: ActuatorState,
        stall: Option<(f64, f64)>,
    ) -> SimCamera {
        let now = clock.now_s();
        self.wall = Some(WallClock {
            clock,
            actuators,
            t0: now,
            last_advance: now,
            carry: 0.0,
            stall,
        });
        self
    }

    /// A second camera (`sim::stereo::other_camera`): each frame then carries its view of
    /// the same moment in [`Frame::other`] (rendered over the same rows as the reference),
    /// for stereo ranging in the drive loop. `None`: one camera (the default).
    pub fn set_other(&mut self, other: Option<OtherCamera>) {
        self.other = other.map(|r| {
            let (w, h) = (self.image.width(), self.image.height());
            (r, RgbImage::new(w, h))
        });
    }

    /// `false`: keep rendering after the world's run has ended (a caller stepping frame by
    /// frame decides when to stop). Default `true`: the source ends with the run.
    pub fn ending_with_world(mut self, on: bool) -> Self {
        self.end_with_world = on;
        self
    }

    /// Renders only `rows` (the rows the pipeline reads, see [`super::world::roi_rows`]) or
    /// every row (`None`, the default). The pipeline decides exactly as on full frames when it
    /// reads nothing else.
    pub fn set_rows(&mut self, rows: Option<Range<usize>>) {
        self.rows = rows;
        self.plan = None;
    }

    /// Renders, frame by frame, only the rows the pipeline reads on that frame
    /// ([`crate::pipeline::Pipeline::row_plan`], made just before the pipeline's next step,
    /// which gets this camera's next frame): the lane's rows, plus the detection rows on
    /// frames where detection runs. The pipeline decides exactly as on full frames. `None`:
    /// back to [`SimCamera::set_rows`]'s all rows.
    pub fn set_row_plan(&mut self, plan: Option<RowPlan>) {
        self.rows = None;
        self.plan = plan.map(|p| (p, self.frame));
    }

    /// `true`: each frame carries the objects' true image boxes (a sign's face, a light's
    /// housing, an obstacle's box; bottom-clipped boxes left out) with the true light colour,
    /// for the pipeline to use instead of its detector's.
    pub fn set_truth_boxes(&mut self, on: bool) {
        self.truth_boxes = on;
    }

    /// The last rendered image.
    pub fn image(&self) -> &RgbImage {
        &self.image
    }

    /// The spans to render for the current frame.
    fn spans(&self) -> Vec<Range<usize>> {
        match &self.plan {
            Some((plan, base)) => plan.rows(self.frame.saturating_sub(*base)).to_vec(),
            None => vec![self.rows.clone().unwrap_or(0..self.image.height() as usize)],
        }
    }

    /// Renders frame `self.frame` at time `t` into a [`Frame`].
    fn render(&mut self, t: f64) -> Frame {
        let spans = self.spans();
        let mut w = lock(&self.world);
        let truth = w.render_spans(self.frame, t, &mut self.image, &spans);
        let given = self.truth_boxes.then(|| w.given_boxes(&truth, t));
        let blur = w.config().sim.blur_px;
        let pose = w.vehicle().pose;
        let other = self.other.as_mut().map(|(r, img)| {
            super::stereo::render_spans(r, &pose, t, self.frame, img, &spans, blur);
            img.clone()
        });
        drop(w);
        let mut f = Frame::new(self.frame, t, format!("frame_{:06}.png", self.frame), self.image.clone());
        f.truth = serde_json::to_value(&truth).ok();
        f.given = given;
        f.other = other.map(|image| OtherView {
            image,
            name: f.name.clone(),
            skew_s: 0.0,
            pairs_dropped: 0,
        });
        f
    }

    /// The world under the actuators' command from the last advance until now.
    fn advance_to_now(world: &SharedWorld, wall: &mut WallClock) -> f64 {
        let now = wall.clock.now_s();
        let cmd = *wall.actuators.lock().unwrap_or_else(|e| e.into_inner());
        lock(world).advance(now - wall.last_advance, cmd, &mut wall.carry);
        wall.last_advance = now;
        now
    }

    /// On the wall clock: waits for the next tick (physics keeps running), delivers nothing
    /// during a scripted stall (a stall error every 0.5 s), then renders the newest tick.
    fn next_on_wall_clock(&mut self) -> Result<Frame, FrameError> {
        let fps = self.fps;
        let wall = self.wall.as_mut().expect("wall-clock camera");
        // 1. Wait for the next tick.
        let due = wall.t0 + (self.frame + 1) as f64 / fps;
        loop {
            let now = Self::advance_to_now(&self.world, wall);
            if now >= due {
                break;
            }
            wall.clock.sleep_s((due - now).min(0.002));
        }
        // 2. A scripted camera stall: nothing for D seconds; tell the loop every 0.5 s.
        let t = wall.clock.now_s() - wall.t0;
        if let Some((at, dur)) = wall.stall {
            if t >= at && t < at + dur {
                let until = (t + 0.5).min(at + dur);
                while wall.clock.now_s() - wall.t0 < until {
                    Self::advance_to_now(&self.world, wall);
                    wall.clock.sleep_s(0.002);
                }
                if wall.clock.now_s() - wall.t0 < at + dur {
                    return Err(FrameError::stalled(
                        self.frame,
                        "sim camera",
                        "no frame for 500 ms (stalled or unplugged)",
                    ));
                }
            }
        }
        // 3. The newest tick (ticks we were too late for are dropped, never queued).
        let now = Self::advance_to_now(&self.world, wall);
        let t0 = wall.t0;
        self.frame = ((now - t0) * fps).floor() as u64;
        let mut f = self.render(now - t0);
        f.captured_s = Some(now);
        Ok(f)
    }
}

impl FrameSource for SimCamera {
    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        if self.end_with_world && lock(&self.world).ended().is_some() {
            return None;
        }
        if self.wall.is_some() {
            return Some(self.next_on_wall_clock());
        }
        let t = self.frame as f64 / self.fps;
        let f = self.render(t);
        self.frame += 1;
        Some(Ok(f))
    }
}
