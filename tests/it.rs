//! The integration tests that need no hardware feature, as ONE test binary (`cargo test
//! --release --test it`). Each file in tests/ stays a module of its own, so its tests are
//! named after it: `cargo test --release --test it stereo_sim` runs tests/stereo_sim.rs.
//!
//! Why one binary: every test binary links the whole library again (30 of them cost ~75 s of
//! CPU to build), and tests from different files share the two test threads instead of
//! waiting for each other's slowest test. Cargo.toml has `autotests = false`; a new file in
//! tests/ must be listed here (or in tests/car.rs), which `every_test_file_is_compiled` checks.

mod behaviour_scenarios;
mod broken_pipe;
mod calib_sim;
mod cli_robustness;
mod data_cmd;
mod detect_bad_input;
mod detect_band;
mod detect_cascades;
mod detect_pyramid;
mod errors_once;
mod fuzz_inputs;
mod interrupt;
mod labs_tools;
mod lane_accuracy;
mod lane_peak;
mod lane_replay;
mod lens_sim;
mod light_sim;
mod pad;
mod pilot;
mod pilot_round_trip;
mod ranging_calibrate_cli;
mod ranging_sim;
mod record_replay;
mod runs;
mod session;
mod sim_loop;
mod sim_replay;
mod sign_classes;
mod sim_track;
mod stereo_cli;
mod stereo_loop;
mod stereo_photos;
mod stereo_pipeline;
mod stereo_signs;
mod stereo_sim;
mod town_sim;
mod stereo_track;
mod stop_line;
mod real_photos;

/// Every tests/*.rs file is compiled: a module here or in tests/car.rs, or its own `[[test]]`
/// in Cargo.toml (`autotests = false` means cargo no longer finds them by itself).
#[test]
fn every_test_file_is_compiled() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let listed = |f: &str| std::fs::read_to_string(root.join(f)).unwrap();
    let (it, car, manifest) = (listed("tests/it.rs"), listed("tests/car.rs"), listed("Cargo.toml"));
    let mut missing = Vec::new();
    for e in std::fs::read_dir(root.join("tests")).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        let Some(stem) = name.strip_suffix(".rs") else { continue };
        let module = format!("\nmod {stem};");
        let target = format!("path = \"tests/{name}\"");
        if !(it.contains(&module) || car.contains(&module) || manifest.contains(&target)) {
            missing.push(name);
        }
    }
    assert!(missing.is_empty(), "not compiled: tests/{}; add `mod NAME;` to tests/it.rs", missing.join(", tests/"));
}
