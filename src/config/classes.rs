//! `[classes.<name>]`: one section per object class of the registry (src/classes.rs), all with
//! the same keys: its model file (a path), where it is searched (fractions of the frame), the
//! width of its detector box (metres), and what that box frames for ranging (sizes and heights,
//! metres; a margin). Each class's defaults are in its registry entry
//! ([`crate::classes::ClassDefaults`]); a file sets only the keys it changes. An unknown class
//! name is refused like any unknown key (the loader checks against the serialised defaults).

use super::check::Checker;
use crate::classes::{ObjectClass, CLASSES};
use crate::ranging::ClassBox;
use serde::de::{self, MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::ops::{Index, IndexMut};

/// How a class is found in the frames (`classes.<name>.detect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DetectMethod {
    /// Its cascade, the `model` file.
    #[default]
    Cascade,
    /// Abdollahi's (2011) HSV threshold + template matching (src/detect/colour_sign.rs), with
    /// templates drawn from the octagon's geometry; `model` is not read. Only for classes whose
    /// registry entry allows it (`ClassInfo::colour_template`: the stop sign).
    ColourTemplate,
}

/// `[classes.<name>]`: the tunables of one object class (docs/detect.md, docs/ranging.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassConfig {
    /// How it is found: `cascade` (its `model`) or `colour_template` (Abdollahi's colour +
    /// template detector, red octagons only).
    pub detect: DetectMethod,
    /// Its cascade (OpenCV XML); a relative path is relative to the folder of the config file
    /// that names it; "" = the class is not detected. A named file that is missing is an error.
    pub model: String,
    /// Where it is searched: [left, top, right, bottom], fractions of the frame (0..1); a box
    /// must lie inside.
    pub region: [f64; 4],
    /// Width of what its cascade's box frames, [min, max] metres (the box, not the object:
    /// trained boxes carry a margin); with `detect.range_m` it bounds the cascade's window size.
    pub box_m: [f64; 2],
    /// [width, height] of the face its box frames, metres (0 = unknown: not used for ranging).
    pub size_m: [f64; 2],
    /// Height above the floor of its box's bottom edge (the face's lower edge), metres (0: it
    /// stands on the floor).
    pub bottom_m: f64,
    /// Its detector box's size over the face's outline (the training crops' margin plus the
    /// detector's own bias; 1 = tight).
    pub box_margin: f64,
    /// Its cascade's grouping threshold (`minNeighbors`: a box needs more than this many raw
    /// hits), for this class only; 0 = `detect.min_neighbors`. A cascade trained by a class is
    /// given the value `rccar-train evaluate` chooses on its held-out frames (docs/training.md,
    /// step 5): cascades differ in how many hits a true object gets.
    pub min_neighbors: u32,
}

impl ClassConfig {
    /// The defaults of `class` (its registry entry).
    pub fn default_for(class: ObjectClass) -> Self {
        let d = class.info().defaults;
        ClassConfig {
            detect: DetectMethod::Cascade,
            model: d.model.into(),
            region: d.region,
            box_m: d.box_m,
            size_m: d.size_m,
            bottom_m: d.bottom_m,
            box_margin: d.box_margin,
            min_neighbors: 0,
        }
    }

    /// What a detector box of this class frames, for ranging (`size_m`, `bottom_m`,
    /// `box_margin`).
    pub fn class_box(&self) -> ClassBox {
        ClassBox {
            width_m: self.size_m[0],
            height_m: self.size_m[1],
            bottom_m: self.bottom_m,
            margin: self.box_margin,
        }
    }

    /// Checks of one section, keys named `classes.<name>.<key>`: the region inside the frame,
    /// an ordered box width, sizes, height and margin in range.
    fn check(&self, class: ObjectClass, c: &mut Checker) {
        let key = |k: &str| format!("classes.{class}.{k}");
        if self.detect == DetectMethod::ColourTemplate && !class.info().colour_template {
            c.fail(
                &key("detect"),
                "\"colour_template\"".to_string(),
                "\"cascade\" (the colour + template detector finds red octagons: stop_sign only)",
            );
        }
        let r = self.region;
        if !(r.iter().all(|v| (0.0..=1.0).contains(v)) && r[0] < r[2] && r[1] < r[3]) {
            c.fail(
                &key("region"),
                format!("{r:?}"),
                "[left, top, right, bottom] in 0..=1 with left < right, top < bottom",
            );
        }
        let b = self.box_m;
        if !(b[0] > 0.0 && b[0] <= b[1] && b[1] <= 5.0) {
            c.fail(
                &key("box_m"),
                format!("{b:?}"),
                "[min, max] metres, 0 < min <= max <= 5",
            );
        }
        c.range(&key("size_m[0]"), self.size_m[0], 0.0, 3.0);
        c.range(&key("size_m[1]"), self.size_m[1], 0.0, 3.0);
        c.range(&key("bottom_m"), self.bottom_m, 0.0, 3.0);
        c.range(&key("box_margin"), self.box_margin, 0.5, 3.0);
        c.range(&key("min_neighbors"), self.min_neighbors, 0, 100);
    }
}

/// `[classes]`: one [`ClassConfig`] per class, indexed by [`ObjectClass`]; in TOML a table
/// keyed by the class names (`[classes.stop_sign]`, …), in registry order.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassesConfig([ClassConfig; ObjectClass::COUNT]);

impl Default for ClassesConfig {
    fn default() -> Self {
        ClassesConfig(ObjectClass::ALL.map(ClassConfig::default_for))
    }
}

impl Index<ObjectClass> for ClassesConfig {
    type Output = ClassConfig;
    fn index(&self, class: ObjectClass) -> &ClassConfig {
        &self.0[class.index()]
    }
}

impl IndexMut<ObjectClass> for ClassesConfig {
    fn index_mut(&mut self, class: ObjectClass) -> &mut ClassConfig {
        &mut self.0[class.index()]
    }
}

impl ClassesConfig {
    /// Every class with its section, in registry order.
    pub fn iter(&self) -> impl Iterator<Item = (ObjectClass, &ClassConfig)> {
        ObjectClass::ALL.into_iter().zip(self.0.iter())
    }

    /// Every class's section, mutable, in registry order.
    pub fn iter_mut(&mut self) -> impl Iterator<Item = &mut ClassConfig> {
        self.0.iter_mut()
    }

    /// Every section's checks.
    pub(super) fn check(&self, c: &mut Checker) {
        for (class, k) in self.iter() {
            k.check(class, c);
        }
    }
}

impl Serialize for ClassesConfig {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(ObjectClass::COUNT))?;
        for (class, k) in self.iter() {
            m.serialize_entry(class.name(), k)?;
        }
        m.end()
    }
}

impl<'de> Deserialize<'de> for ClassesConfig {
    /// A table keyed by class names; a class not named keeps its defaults (the loader merges
    /// every file over the defaults, so each section read here is complete).
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct ByName;
        impl<'de> Visitor<'de> for ByName {
            type Value = ClassesConfig;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a table of object classes ([classes.<name>])")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<ClassesConfig, A::Error> {
                let mut out = ClassesConfig::default();
                while let Some(name) = m.next_key::<String>()? {
                    let Some(class) = ObjectClass::ALL.into_iter().find(|c| c.name() == name) else {
                        return Err(de::Error::custom(format!(
                            "unknown class `{name}`, expected one of {}",
                            class_names()
                        )));
                    };
                    out.0[class.index()] = m.next_value()?;
                }
                Ok(out)
            }
        }
        d.deserialize_map(ByName)
    }
}

/// The class names, quoted and comma-separated (for messages).
pub(super) fn class_names() -> String {
    CLASSES
        .iter()
        .map(|c| format!("`{}`", c.name))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Where a key of the former flat layout lives now: `detect.<name>` is
/// `classes.<name>.model`, `detect.<name>_region` `classes.<name>.region`,
/// `ranging.<name>_bottom_m` `classes.<name>.bottom_m`, and so on (`None`: no such key).
pub(super) fn moved_key(key: &str) -> Option<String> {
    let (section, rest) = key.split_once('.')?;
    if !matches!(section, "detect" | "ranging") {
        return None;
    }
    let fields = super::value::to_table(&ClassConfig::default_for(ObjectClass::ALL[0]));
    CLASSES.iter().find_map(|c| {
        let tail = rest.strip_prefix(c.name)?;
        let field = if tail.is_empty() {
            "model"
        } else {
            tail.strip_prefix('_')?
        };
        fields
            .contains_key(field)
            .then(|| format!("classes.{}.{field}", c.name))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{path_keys, Config, LoadedConfig};

    /// A section that sets one key keeps the class's other defaults, and the other classes
    /// keep theirs; a model path given in a file or with `--set` is resolved like before.
    #[test]
    fn a_partial_class_section_merges_over_the_defaults() {
        let c = Config::from_toml_str("[classes.stop_sign]\nregion = [0.5, 0.1, 0.9, 0.5]\n", "t.toml").unwrap();
        let mut want = ClassesConfig::default();
        want[ObjectClass::StopSign].region = [0.5, 0.1, 0.9, 0.5];
        assert_eq!(c.classes, want);
        assert_eq!(c.classes[ObjectClass::StopSign].box_m, [0.11, 0.16]);
        assert_eq!(c.classes[ObjectClass::StopSign].model, "cascades/stop_sign.xml");
        let c = Config::default()
            .with_override("classes.obstacle.bottom_m=0.02")
            .unwrap();
        assert_eq!(c.classes[ObjectClass::Obstacle].bottom_m, 0.02);
        assert_eq!(c.classes[ObjectClass::Obstacle].box_margin, 1.36);
        assert_eq!(c.number("classes.obstacle.bottom_m"), Some(0.02));

        // A relative model path in an override file is read from that file's folder; a default
        // from the base file's.
        let t = tempfile::tempdir().unwrap();
        let dir = std::path::absolute(t.path()).unwrap();
        std::fs::create_dir(dir.join("sub")).unwrap();
        std::fs::write(dir.join("car.toml"), "").unwrap();
        std::fs::write(
            dir.join("sub/local.toml"),
            "[classes.traffic_light]\nmodel = \"mine/light.xml\"\n",
        )
        .unwrap();
        let set = ["classes.stop_sign.model=/x.xml".to_string()];
        let l = LoadedConfig::load(&dir.join("car.toml"), &[dir.join("sub/local.toml")], &set).unwrap();
        let model = |c: ObjectClass| std::path::PathBuf::from(&l.cfg.classes[c].model);
        assert_eq!(model(ObjectClass::StopSign), std::path::Path::new("/x.xml"));
        assert_eq!(model(ObjectClass::TrafficLight), dir.join("sub/mine/light.xml"));
        assert_eq!(model(ObjectClass::Obstacle), dir.join("cascades/obstacle.xml"));
        assert_eq!(l.cfg.classes[ObjectClass::TrafficLight].box_m, [0.065, 0.10]);
        // Every path key names a string of the defaults (each class's model among them).
        let defaults = crate::config::value::to_table(&Config::default());
        let keys: Vec<&str> = path_keys().collect();
        assert!(keys.contains(&"classes.obstacle.model"), "{keys:?}");
        for k in keys {
            let (section, rest) = k.split_once('.').unwrap();
            let mut v = &defaults[section];
            for p in rest.split('.') {
                v = &v[p];
            }
            assert!(v.is_str(), "{k}");
        }
    }

    /// A class the registry does not have is an unknown key, named, with the classes there are
    /// (or the one an alias means); so is a key no class has.
    #[test]
    fn an_unknown_class_or_class_key_is_refused_naming_it() {
        let e = Config::from_toml_str("[classes.bicycle]\nregion = [0.0, 0.0, 1.0, 1.0]\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: unknown key `classes.bicycle`, the classes are `stop_sign`, `traffic_light`, \
             `obstacle`, `yield_sign`, `turn_sign` (a new one needs its entry in src/classes.rs)"
        );
        let e = Config::from_toml_str("[classes.stop_signs]\nbottom_m = 0.1\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: unknown key `classes.stop_signs`, did you mean `stop_sign`?");
        let e = Config::default()
            .with_override("classes.light.bottom_m=0.1")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "command line: unknown key `classes.light`, did you mean `traffic_light`?"
        );
        let e = Config::from_toml_str("[classes.obstacle]\nmargin = 1.2\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: unknown key `classes.obstacle.margin`");
    }

    /// A key of the former flat layout names the key it is now.
    #[test]
    fn an_old_flat_key_names_its_new_key() {
        for (text, old, new) in [
            (
                "[detect]\nstop_sign = \"x.xml\"\n",
                "detect.stop_sign",
                "classes.stop_sign.model",
            ),
            (
                "[detect]\ntraffic_light_region = [0.0, 0.0, 1.0, 1.0]\n",
                "detect.traffic_light_region",
                "classes.traffic_light.region",
            ),
            (
                "[detect]\nobstacle_box_m = [0.1, 0.2]\n",
                "detect.obstacle_box_m",
                "classes.obstacle.box_m",
            ),
            (
                "[ranging]\nobstacle_bottom_m = 0.0\n",
                "ranging.obstacle_bottom_m",
                "classes.obstacle.bottom_m",
            ),
            (
                "[ranging]\nstop_sign_size_m = [0.1, 0.1]\n",
                "ranging.stop_sign_size_m",
                "classes.stop_sign.size_m",
            ),
            (
                "[ranging]\ntraffic_light_box_margin = 1.2\n",
                "ranging.traffic_light_box_margin",
                "classes.traffic_light.box_margin",
            ),
        ] {
            let e = Config::from_toml_str(text, "t.toml").unwrap_err().to_string();
            assert_eq!(
                e,
                format!("t.toml: unknown key `{old}`, each class has its own section now: `{new}`")
            );
        }
        let e = Config::default()
            .with_override("detect.obstacle=o.xml")
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("`classes.obstacle.model`"), "{e}");
        // Not every unknown key of those sections is an old class key.
        let e = Config::from_toml_str("[detect]\nstop_sign_colour = 1\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "t.toml: unknown key `detect.stop_sign_colour`");
    }

    /// The checks name the class's key: a region outside the frame or reversed, an unordered
    /// box width, a box bottom above the lens, a value of the wrong type.
    #[test]
    fn a_bad_class_value_names_its_key() {
        let e = Config::from_toml_str("[classes.traffic_light]\nregion = [0.6, 0.0, 0.4, 0.5]\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "t.toml: classes.traffic_light.region = [0.6, 0.0, 0.4, 0.5] is out of range \
             (allowed: [left, top, right, bottom] in 0..=1 with left < right, top < bottom)"
        );
        let e = Config::default()
            .with_override("classes.obstacle.region=[0.0, 0.0, 1.0, 1.5]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("classes.obstacle.region = [0.0, 0.0, 1.0, 1.5]"), "{e}");
        let e = Config::from_toml_str("[classes.stop_sign]\nbox_m = [0.2, 0.1]\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.toml: classes.stop_sign.box_m = [0.2, 0.1]"), "{e}");
        let e = Config::from_toml_str(
            "[camera]\nheight_m = 0.1\n[classes.stop_sign]\nbottom_m = 0.15\n",
            "t.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("t.toml: classes.stop_sign.bottom_m = 0.15 is out of range (allowed: below camera.height_m"),
            "{e}"
        );
        let e = Config::from_toml_str("[classes.stop_sign]\nregion = \"right\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.toml: `classes.stop_sign.region` = \"right\""), "{e}");
    }

    /// `detect` picks the colour + template detector for the stop sign; a class it cannot find
    /// is refused naming the key; an unknown method is refused.
    #[test]
    fn detect_method_per_class() {
        assert_eq!(
            Config::default().classes[ObjectClass::StopSign].detect,
            DetectMethod::Cascade
        );
        let c = Config::from_toml_str("[classes.stop_sign]\ndetect = \"colour_template\"\n", "t.toml").unwrap();
        assert_eq!(c.classes[ObjectClass::StopSign].detect, DetectMethod::ColourTemplate);
        assert_eq!(c.classes[ObjectClass::TrafficLight].detect, DetectMethod::Cascade);
        let c = Config::default()
            .with_override("classes.stop_sign.detect=colour_template")
            .unwrap();
        assert_eq!(c.classes[ObjectClass::StopSign].detect, DetectMethod::ColourTemplate);
        let e = Config::from_toml_str("[classes.traffic_light]\ndetect = \"colour_template\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.toml: classes.traffic_light.detect = \"colour_template\" is out of range"),
            "{e}"
        );
        let e = Config::from_toml_str("[classes.stop_sign]\ndetect = \"hog\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("classes.stop_sign.detect"), "{e}");
    }
}
