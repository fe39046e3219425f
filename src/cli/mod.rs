//! Subcommands of the `rccar` binary. Each file parses its flags with clap, wires library
//! parts together and reports; the work itself is library code.

pub mod calib_board;
pub mod calibrate;
pub mod camera;
pub mod common;
pub mod config;
pub mod dashboard;
pub mod data;
pub mod detect;
pub mod drive;
pub mod link;
pub mod outdir;
pub mod pad;
pub mod plot;
pub mod replay;
pub mod report;
pub mod signals;
pub mod sim;
pub mod stages;
pub mod stereo;
pub mod sweep;
pub mod synth;
pub mod timer;
