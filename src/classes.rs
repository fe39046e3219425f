//! The one registry of object classes: every kind of object the car detects, ranges, reacts
//! to, the simulator draws and the trainer generates is declared here once, in [`CLASSES`].
//! Everything else iterates over [`ObjectClass::ALL`] or reads [`ObjectClass::info`]; label
//! strings are turned into a class only when parsing ([`ObjectClass::from_label`]).
//!
//! Adding a class: a variant of [`ObjectClass`] and its [`ClassInfo`] entry here (with the
//! defaults of its `[classes.<name>]` section, [`ClassDefaults`]), that section in
//! `config/car.toml` and a model file (docs/architecture.md). A class that reuses an existing
//! [`Reaction`], [`ColourCue`] and [`SimShape`] needs no other code. Depends on nothing in the
//! crate (every stage may import it). Units: metres, pixels where said.

use serde::{Deserialize, Serialize};

/// An object class (the index into [`CLASSES`]). Serialized as its [`ClassInfo::name`]
/// (`stop_sign`, …) in telemetry and track files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectClass {
    /// A stop sign (box = the face).
    StopSign,
    /// A traffic light (box = the housing).
    TrafficLight,
    /// An obstacle standing on the floor.
    Obstacle,
    /// A yield sign: a red-bordered white inverted triangle on a post (box = the face).
    YieldSign,
    /// A turn sign: a blue disc with a white arrow pointing left or right (box = the disc).
    TurnSign,
}

/// The direction a turn sign's arrow points (read inside its box, src/detect/arrow.rs; a
/// track file's `arrow` key). Serialized `left` / `right`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TurnArrow {
    /// Turn left.
    Left,
    /// Turn right.
    Right,
}

impl TurnArrow {
    /// `left` or `right`.
    pub fn name(self) -> &'static str {
        match self {
            TurnArrow::Left => "left",
            TurnArrow::Right => "right",
        }
    }
}

/// Which behaviour of `control::behaviour` reacts to a class.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Stop before it, hold, then go on (a stop sign).
    StopThenGo,
    /// Wait while its lamp is red or amber (a traffic light).
    WaitForGreen,
    /// Stop (or pass through the other lane) while it blocks the lane (an obstacle).
    StopOrPass,
    /// Creep past it, stopping while an obstacle is in the lane ahead (a yield sign).
    Yield,
    /// Take the branch its arrow shows (a turn sign; the route's, no throttle behaviour).
    TakeTurn,
}

/// The colour cue ranging refines a detector box with (src/ranging/refine.rs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColourCue {
    /// A red face (a stop sign): the red pixels' outline.
    RedFace,
    /// A dark housing with one lit lamp (a traffic light).
    LitHousing,
    /// A blue disc inside a thin white rim (a turn sign): the blue pixels' outline.
    BlueFace,
    /// A red-bordered inverted triangle (a yield sign): the top edge and its width from the
    /// red rows, the lower vertex where the red rows' width runs out (extrapolated).
    RedTriangle,
    /// No colour cue (obstacles differ): the box is ranged as it is.
    None,
}

/// How the simulator draws a class (src/sim/scene.rs) and places it (src/sim/track.rs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimShape {
    /// A red octagon with STOP on a post; `size_m` = one number, the face's width.
    Octagon,
    /// A housing with red, amber and green lamps on a post; `size_m` = the housing's height.
    LightHousing,
    /// A box standing on the floor; `size_m` = [length, width, height].
    Box,
    /// A red-bordered white inverted triangle on a post; `size_m` = the top edge's length.
    Triangle,
    /// A blue disc with a white arrow on a post; `size_m` = the disc's diameter.
    ArrowDisc,
}

impl SimShape {
    /// How many numbers a track file's `size_m` takes for this shape.
    pub fn size_numbers(self) -> usize {
        match self {
            SimShape::Box => 3,
            SimShape::Octagon | SimShape::LightHousing | SimShape::Triangle | SimShape::ArrowDisc => 1,
        }
    }
}

/// The defaults of a class's `[classes.<name>]` section of `car.toml` (the section's keys,
/// units and checks: `config::ClassConfig`, src/config/classes.rs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassDefaults {
    /// Its model file (a cascade), relative to the config's folder.
    pub model: &'static str,
    /// Where it is searched: [left, top, right, bottom], fractions of the frame.
    pub region: [f64; 4],
    /// Width of what its detector box frames, [min, max] metres.
    pub box_m: [f64; 2],
    /// [width, height] of the face its box frames, metres (0 = unknown).
    pub size_m: [f64; 2],
    /// Height above the floor of its box's bottom edge, metres.
    pub bottom_m: f64,
    /// Its detector box's size over the face's outline.
    pub box_margin: f64,
}

/// Everything about one class: what it is and does, and the defaults of its tunables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassInfo {
    /// The class.
    pub class: ObjectClass,
    /// Its name: telemetry, track files, the cascade's label, its config section
    /// (`[classes.<name>]`).
    pub name: &'static str,
    /// Other spellings accepted when parsing a label (`stop`, `light`).
    pub aliases: &'static [&'static str],
    /// The config key naming its model file (`classes.<name>.model`): messages, and the path
    /// keys the loader resolves (`config::path_keys`).
    pub model_key: &'static str,
    /// The defaults of its `[classes.<name>]` section.
    pub defaults: ClassDefaults,
    /// The detect stage reads the lamp colour inside its boxes.
    pub reads_light: bool,
    /// The detect stage reads an arrow's direction inside its boxes (a turn sign).
    pub reads_arrow: bool,
    /// The colour cue that refines its boxes before ranging.
    pub colour_cue: ColourCue,
    /// Abdollahi's colour + template detector can find it instead of a cascade
    /// (`classes.<name>.detect = "colour_template"`): a red octagon with white letters.
    pub colour_template: bool,
    /// It stands on the floor in a colour of its own: a box whose middle has the colour of the
    /// floor in front of it, only darker or brighter, is a shadow or a sun patch and is dropped
    /// (`detect.shadow_tolerance`, src/ranging/refine.rs `floor_coloured`).
    pub not_floor_colour: bool,
    /// The behaviour that reacts to it.
    pub reaction: Reaction,
    /// How the simulator draws it.
    pub shape: SimShape,
    /// The simulator's size when a track file gives none (`size_m`; unused numbers 0), metres.
    pub sim_size_m: [f64; 3],
    /// The simulator's face-centre height when a track file gives none, metres (`None`: half
    /// the box's height, it stands on the floor).
    pub sim_height_m: Option<f64>,
    /// The trainer's detection window (width, height) in pixels (training/src/simgen.rs).
    pub train_window: (u32, u32),
}

/// The registry: one entry per class, in [`ObjectClass`] order.
pub const CLASSES: [ClassInfo; ObjectClass::COUNT] = [
    ClassInfo {
        class: ObjectClass::StopSign,
        name: "stop_sign",
        aliases: &["stop"],
        model_key: "classes.stop_sign.model",
        defaults: ClassDefaults {
            model: "cascades/stop_sign.xml",
            region: [0.45, 0.0, 1.0, 0.6],
            box_m: [0.11, 0.16],
            size_m: [0.10, 0.10],
            bottom_m: 0.12,
            box_margin: 1.085,
        },
        reads_light: false,
        reads_arrow: false,
        colour_cue: ColourCue::RedFace,
        colour_template: true,
        not_floor_colour: false,
        reaction: Reaction::StopThenGo,
        shape: SimShape::Octagon,
        sim_size_m: [0.10, 0.0, 0.0],
        sim_height_m: Some(0.17),
        train_window: (16, 16),
    },
    ClassInfo {
        class: ObjectClass::TrafficLight,
        name: "traffic_light",
        aliases: &["light"],
        model_key: "classes.traffic_light.model",
        defaults: ClassDefaults {
            model: "cascades/traffic_light.xml",
            region: [0.45, 0.0, 1.0, 0.6],
            box_m: [0.065, 0.10],
            size_m: [0.0, 0.12],
            bottom_m: 0.10,
            box_margin: 1.21,
        },
        reads_light: true,
        reads_arrow: false,
        colour_cue: ColourCue::LitHousing,
        colour_template: false,
        not_floor_colour: false,
        reaction: Reaction::WaitForGreen,
        shape: SimShape::LightHousing,
        sim_size_m: [0.12, 0.0, 0.0],
        sim_height_m: Some(0.16),
        train_window: (8, 20),
    },
    ClassInfo {
        class: ObjectClass::Obstacle,
        name: "obstacle",
        aliases: &[],
        model_key: "classes.obstacle.model",
        defaults: ClassDefaults {
            model: "cascades/obstacle.xml",
            region: [0.0, 0.08, 1.0, 1.0],
            box_m: [0.18, 0.45],
            size_m: [0.0, 0.0],
            bottom_m: 0.0,
            box_margin: 1.36,
        },
        reads_light: false,
        reads_arrow: false,
        colour_cue: ColourCue::None,
        colour_template: false,
        not_floor_colour: true,
        reaction: Reaction::StopOrPass,
        shape: SimShape::Box,
        sim_size_m: [0.15, 0.12, 0.10],
        sim_height_m: None,
        train_window: (20, 16),
    },
    ClassInfo {
        class: ObjectClass::YieldSign,
        name: "yield_sign",
        aliases: &["yield"],
        model_key: "classes.yield_sign.model",
        defaults: ClassDefaults {
            model: "cascades/yield_sign.xml",
            region: [0.45, 0.0, 1.0, 0.6],
            box_m: [0.11, 0.17],
            size_m: [0.12, 0.104],
            bottom_m: 0.118,
            box_margin: 1.165,
        },
        reads_light: false,
        reads_arrow: false,
        colour_cue: ColourCue::RedTriangle,
        colour_template: false,
        not_floor_colour: false,
        reaction: Reaction::Yield,
        shape: SimShape::Triangle,
        sim_size_m: [0.12, 0.0, 0.0],
        sim_height_m: Some(0.17),
        train_window: (18, 16),
    },
    ClassInfo {
        class: ObjectClass::TurnSign,
        name: "turn_sign",
        aliases: &["turn"],
        model_key: "classes.turn_sign.model",
        defaults: ClassDefaults {
            model: "cascades/turn_sign.xml",
            region: [0.45, 0.0, 1.0, 0.6],
            box_m: [0.09, 0.14],
            size_m: [0.10, 0.10],
            bottom_m: 0.12,
            box_margin: 1.093,
        },
        reads_light: false,
        reads_arrow: true,
        colour_cue: ColourCue::BlueFace,
        colour_template: false,
        not_floor_colour: false,
        reaction: Reaction::TakeTurn,
        shape: SimShape::ArrowDisc,
        sim_size_m: [0.10, 0.0, 0.0],
        sim_height_m: Some(0.17),
        train_window: (16, 16),
    },
];

impl ObjectClass {
    /// How many classes there are (the length of per-class arrays).
    pub const COUNT: usize = 5;
    /// Every class, in registry order.
    pub const ALL: [ObjectClass; ObjectClass::COUNT] = [
        ObjectClass::StopSign,
        ObjectClass::TrafficLight,
        ObjectClass::Obstacle,
        ObjectClass::YieldSign,
        ObjectClass::TurnSign,
    ];

    /// Its registry entry.
    pub fn info(self) -> &'static ClassInfo {
        &CLASSES[self.index()]
    }

    /// Its index in [`CLASSES`] and in per-class arrays.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its name (`stop_sign`, `traffic_light`, `obstacle`, `yield_sign`, `turn_sign`).
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The class of a label (its name or an alias); `None` for a label of no class.
    pub fn from_label(label: &str) -> Option<ObjectClass> {
        CLASSES
            .iter()
            .find(|c| c.name == label || c.aliases.contains(&label))
            .map(|c| c.class)
    }
}

impl std::fmt::Display for ObjectClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_is_in_enum_order_and_names_round_trip() {
        for (i, c) in ObjectClass::ALL.iter().enumerate() {
            assert_eq!(CLASSES[i].class, *c);
            assert_eq!(c.index(), i);
            assert_eq!(ObjectClass::from_label(c.name()), Some(*c));
            assert_eq!(c.info().model_key, format!("classes.{}.model", c.name()));
            let json = serde_json::to_string(c).unwrap();
            assert_eq!(json, format!("\"{}\"", c.name()));
        }
        assert_eq!(ObjectClass::from_label("stop"), Some(ObjectClass::StopSign));
        assert_eq!(ObjectClass::from_label("light"), Some(ObjectClass::TrafficLight));
        assert_eq!(ObjectClass::from_label("face"), None);
    }

    #[test]
    fn the_yield_and_turn_signs_are_registered() {
        let y = ObjectClass::YieldSign.info();
        assert_eq!(
            (y.name, y.reaction, y.shape),
            ("yield_sign", Reaction::Yield, SimShape::Triangle)
        );
        assert_eq!(y.defaults.model, "cascades/yield_sign.xml");
        assert_eq!(y.train_window, (18, 16));
        let t = ObjectClass::TurnSign.info();
        assert_eq!(
            (t.name, t.reaction, t.shape),
            ("turn_sign", Reaction::TakeTurn, SimShape::ArrowDisc)
        );
        assert_eq!(t.defaults.model, "cascades/turn_sign.xml");
        assert_eq!(t.train_window, (16, 16));
        // Only the turn sign reads an arrow, only the light a lamp.
        for c in ObjectClass::ALL {
            assert_eq!(c.info().reads_arrow, c == ObjectClass::TurnSign, "{c}");
            assert_eq!(c.info().reads_light, c == ObjectClass::TrafficLight, "{c}");
        }
        // A triangle's box: the face's height is √3/2 of its width.
        assert!((y.defaults.size_m[1] - y.defaults.size_m[0] * 0.75f64.sqrt()).abs() < 1e-3);
        assert_eq!(ObjectClass::from_label("yield"), Some(ObjectClass::YieldSign));
        assert_eq!(ObjectClass::from_label("turn"), Some(ObjectClass::TurnSign));
        assert_eq!(serde_json::to_string(&TurnArrow::Left).unwrap(), "\"left\"");
        assert_eq!(
            serde_json::from_str::<TurnArrow>("\"right\"").unwrap(),
            TurnArrow::Right
        );
        assert_eq!(TurnArrow::Left.name(), "left");
    }
}
