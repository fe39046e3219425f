//! The integration tests of the car's hardware path (`cargo test --release --features
//! serial,camera,gpio,dashboard --test car`): the serial link to the real firmware in simavr,
//! the firmware in the loop, `rccar drive`, camera programs on a pipe (pipe_camera: ffmpeg as
//! the camera), the dashboard and the labs that drive them. The files whose tests need a
//! feature say so in their first lines (`#![cfg(feature = ..)]`); without the features this
//! binary still runs what needs none (drive_cli, labs, pipe_camera).

/// The firmware in simavr on a pty (tests/support/sim.rs), for drive_fil and link_hil.
#[cfg(feature = "serial")]
#[path = "support/sim.rs"]
mod sim;

mod dashboard_security;
mod drive_cli;
mod drive_fil;
mod labs;
mod link_hil;
mod pipe_camera;
mod session_fil;
