//! rccar: the brain of an educational autonomous RC car.
//!
//! One frame's way through (see `docs/lane.md` and the architecture notes):
//!
//! ```text
//! FrameSource (camera | replay dir | simulator)
//!   -> lane:    ROI + bird's-eye warp -> grey threshold + Canny -> column histogram
//!               -> P_left, P_right -> L_c = (P_right - P_left)/2 + P_left -> error = L_c - L_F
//!   -> control: PID on the lane error + throttle policy -> Command { steer, throttle }
//!   -> CommandSink (serial link | simulator vehicle | recorder)
//!   -> telemetry: one JSONL record per frame
//! ```
//!
//! Perception (`lane`) never depends on `control`, `link` or the CLI; `control` produces a
//! [`control::Command`] and never talks to a sink itself. The library reads no clock: time is
//! passed in, so every test is deterministic.

pub mod annotate;
pub mod calib;
pub mod camera;
#[cfg(feature = "camera")]
pub mod camera_source;
pub mod capture;
pub mod classes;
pub mod config;
pub mod control;
pub mod dashboard;
pub mod dataset;
pub mod detect;
pub mod drive;
pub mod fields;
pub mod gpio;
pub mod health;
pub mod imageio;
pub mod lane;
pub mod lens;
pub mod link;
pub mod pad;
pub mod pipeline;
#[cfg(unix)]
pub mod pipecam;
pub mod ranging;
pub mod record;
pub mod report;
pub mod route;
pub mod run_dir;
pub mod session;
pub mod sim;
pub mod sink;
pub mod source;
pub mod stereo;
pub mod telemetry;
pub mod timing;
