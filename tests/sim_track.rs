//! Bad track files give a clear error naming the problem, never a panic (issue 5).

use rccar::sim::track::{Track, TrackError};

const GOOD: &str = r#"
name = "oval"
[road]
lane_width_m = 0.3
lanes = 1
[[segments]]
type = "straight"
length_m = 2.0
[[segments]]
type = "arc"
radius_m = 1.0
angle_deg = 180
[[segments]]
type = "straight"
length_m = 2.0
[[segments]]
type = "arc"
radius_m = 1.0
angle_deg = 180
[[objects]]
type = "stop_sign"
x = 1.0
y = -0.4
"#;

fn err(text: &str) -> String {
    match Track::from_toml_str(text, "bad.toml") {
        Ok(_) => panic!("accepted a bad track:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_good_one_loads() {
    let t = Track::from_toml_str(GOOD, "good.toml").unwrap();
    assert_eq!(t.pieces.len(), 4);
}

#[test]
fn unknown_key_is_named_with_its_place() {
    let e = err(&GOOD.replace("length_m = 2.0", "lenght_m = 2.0"));
    assert!(
        e.contains("lenght_m") && e.contains("segments[0]") && e.contains("bad.toml"),
        "{e}"
    );
    let e = err(&GOOD.replace("lanes = 1", "lanes = 1\nlane_colour = 3"));
    assert!(e.contains("lane_colour") && e.contains("road"), "{e}");
    let e = err(&GOOD.replace("name = \"oval\"", "name = \"oval\"\nspeed = 3"));
    assert!(e.contains("speed"), "{e}");
    let e = err(&GOOD.replace("type = \"arc\"", "type = \"spiral\""));
    assert!(e.contains("spiral"), "{e}");
}

#[test]
fn zero_length_segment_is_named() {
    let e = err(&GOOD.replacen("length_m = 2.0", "length_m = 0.0", 1));
    assert!(
        e.contains("segments[0].length_m") && e.contains("longer than zero"),
        "{e}"
    );
    let e = err(&GOOD.replacen("radius_m = 1.0", "radius_m = 0", 1));
    assert!(e.contains("segments[1].radius_m"), "{e}");
    let e = err(&GOOD.replacen("angle_deg = 180", "angle_deg = 0", 1));
    assert!(e.contains("segments[1].angle_deg"), "{e}");
}

#[test]
fn arcs_that_do_not_join_are_reported_with_the_gap() {
    let e = err(&GOOD.replacen("angle_deg = 180", "angle_deg = 170", 1));
    assert!(e.contains("do not join up") && e.contains("segments[3]"), "{e}");
    let e = err(&GOOD.replacen("length_m = 2.0", "length_m = 2.1", 1));
    assert!(e.contains("do not join up") && e.contains("0.100 m"), "{e}");
    // An arc tighter than the road is wide.
    let e = err(&GOOD.replace("radius_m = 1.0", "radius_m = 0.1"));
    assert!(e.contains("radius_m") && e.contains("outer lines"), "{e}");
}

#[test]
fn objects_off_the_map_are_named() {
    let e = err(&GOOD.replace("x = 1.0\ny = -0.4", "x = 40.0\ny = -0.4"));
    assert!(
        e.contains("objects[0]") && e.contains("stop_sign") && e.contains("off the map"),
        "{e}"
    );
    let e = err(&GOOD.replace("type = \"stop_sign\"", "type = \"obstacle\"\nsize_m = [0.1, 0.1]"));
    assert!(e.contains("objects[0].size_m"), "{e}");
}

#[test]
fn syntax_errors_name_the_line() {
    let e = err(&GOOD.replace("lanes = 1", "lanes = = 1"));
    assert!(e.contains("line"), "{e}");
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    match Track::load(std::path::Path::new("no/such/track.toml")) {
        Err(TrackError::Io { path, .. }) => assert!(path.ends_with("track.toml")),
        other => panic!("{other:?}"),
    }
}

/// Random damage to a good file never panics: it loads or it errors.
#[test]
fn mangled_files_never_panic() {
    let mut seed = 12345u64;
    for _ in 0..300 {
        let mut bytes = GOOD.as_bytes().to_vec();
        for _ in 0..3 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let i = (seed >> 33) as usize % bytes.len();
            bytes[i] = b"0123456789-.=[]\"x \n"[(seed >> 20) as usize % 19];
        }
        let text = String::from_utf8_lossy(&bytes);
        let _ = Track::from_toml_str(&text, "mangled.toml");
    }
}
