//! The closed-loop simulator: a track ([`track`]), a car ([`vehicle`]), what its camera would
//! see ([`render`]) and the loop that feeds those frames through the same pipeline the car
//! runs ([`run`]), scored against ground truth ([`truth`]). [`scene`] holds what the camera
//! looks at (floor, lines, walls, objects), [`glyphs`] the stroke letters of the signs,
//! [`plot`] the run's plots, [`sweep`] gain sweeps over one or two keys, [`step`]
//! step-response figures, [`rng`] the seeded generator, [`light`] shadows, bright patches and dusk. Usage and the track format:
//! `docs/sim.md`.
//!
//! Units: metres, seconds, radians (degrees only in files). World frame x east, y north,
//! z up; headings counter-clockwise from +x.

pub mod board;
pub mod camera;
pub mod glyphs;
pub mod geometry;
pub mod lens;
pub mod light;
pub mod network;
pub mod plan;
pub mod plot;
pub mod pwm;
pub mod render;
pub mod report;
pub mod rng;
pub mod run;
pub mod world;
pub mod scenario_lab;
pub mod stereo;
pub mod scene;
pub mod step;
pub mod sweep;
pub mod track;
pub mod truth;
pub mod vehicle;
