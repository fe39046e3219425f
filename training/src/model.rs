//! A cascade being trained, written in OpenCV's current cascade XML format (the one
//! `opencv_traincascade` writes: `<cascade>`, `stageType` BOOST, `featureType` HAAR,
//! `internalNodes` = `left right feature threshold`, `leafValues`), and evaluated with the
//! detector's own arithmetic.
//!
//! The written file is read back with rccar's loader (`rccar::detect::Cascade::from_xml_str`)
//! and that loaded cascade is what the trainer evaluates ([`CompiledCascade`]), so the
//! thresholds and leaves the trainer bootstraps with are bit-for-bit the ones the car (and
//! `cv2.CascadeClassifier`, which rounds text → f64 → f32 the same way) will use.
//! Units: pixels of the training window.

use crate::features::{self, HaarMode};
use rccar::detect::cascade::HaarFeature;
use rccar::detect::{Cascade, CascadeError};
use std::fmt::Write;

/// OpenCV's `-bt` boosting variants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
pub enum BoostType {
    /// Discrete AdaBoost (DAB).
    Discrete,
    /// Real AdaBoost (RAB).
    Real,
    /// LogitBoost (LB).
    Logit,
    /// Gentle AdaBoost (GAB, OpenCV's default).
    Gentle,
}

impl BoostType {
    /// OpenCV's short name in `<boostType>`.
    pub fn code(self) -> &'static str {
        match self {
            BoostType::Discrete => "DAB",
            BoostType::Real => "RAB",
            BoostType::Logit => "LB",
            BoostType::Gentle => "GAB",
        }
    }
}

/// One split of a weak tree: go left when `value < threshold`; children > 0 are node indices,
/// ≤ 0 are leaves `-child` (OpenCV's encoding).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Split {
    /// Index into the trainer's feature pool.
    pub feature: usize,
    /// Threshold on the normalised feature value.
    pub threshold: f32,
    /// Left child.
    pub left: i32,
    /// Right child.
    pub right: i32,
}

/// A weak classifier: a stump (one split, two leaves) or a depth-2 tree.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Weak {
    /// Splits, root first.
    pub splits: Vec<Split>,
    /// Leaf values.
    pub leaves: Vec<f32>,
}

/// A finished (or growing) boosted stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageModel {
    /// Stage threshold as written to the file (the detector subtracts 1e-5).
    pub threshold: f32,
    /// Weak classifiers.
    pub weaks: Vec<Weak>,
}

/// The training parameters written into `<stageParams>` / `<featureParams>`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelParams {
    /// Window width, pixels.
    pub width: i32,
    /// Window height, pixels.
    pub height: i32,
    /// Feature mode.
    pub mode: HaarMode,
    /// Boosting variant.
    pub boost: BoostType,
    /// Minimal hit rate per stage.
    pub min_hit_rate: f64,
    /// Maximal false-alarm rate per stage.
    pub max_false_alarm: f64,
    /// Tree depth (1 = stumps, 2 = depth-2 trees).
    pub max_depth: u32,
    /// Most weak classifiers per stage.
    pub max_weak_count: u32,
    /// Planned number of stages.
    pub num_stages: u32,
}

/// A cascade in training: parameters, finished stages and the feature pool they index.
#[derive(Debug, Clone)]
pub struct Model {
    /// Parameters.
    pub params: ModelParams,
    /// Stages so far.
    pub stages: Vec<StageModel>,
    /// The full feature pool for the window and mode.
    pub pool: Vec<HaarFeature>,
}

fn fmt_f(v: f64) -> String {
    // 17 significant digits, as OpenCV's FileStorage writes doubles: exact round trip.
    format!("{:.16e}", v)
}

impl Model {
    /// An empty cascade.
    pub fn new(params: ModelParams) -> Model {
        let pool = features::generate(params.width, params.height, params.mode);
        Model {
            params,
            stages: Vec::new(),
            pool,
        }
    }

    /// The cascade as OpenCV XML text (features renumbered to the ones used).
    pub fn to_xml(&self) -> String {
        let p = &self.params;
        // 1. The used features, in first-use order.
        let mut index = std::collections::HashMap::new();
        let mut used: Vec<usize> = Vec::new();
        for st in &self.stages {
            for w in &st.weaks {
                for s in &w.splits {
                    index.entry(s.feature).or_insert_with(|| {
                        used.push(s.feature);
                        used.len() - 1
                    });
                }
            }
        }
        let mut x = String::new();
        let _ = writeln!(x, "<?xml version=\"1.0\"?>\n<opencv_storage>\n<cascade>");
        let _ = writeln!(x, "  <stageType>BOOST</stageType>\n  <featureType>HAAR</featureType>");
        let _ = writeln!(x, "  <height>{}</height>\n  <width>{}</width>", p.height, p.width);
        let _ = writeln!(x, "  <stageParams>\n    <boostType>{}</boostType>", p.boost.code());
        let _ = writeln!(x, "    <minHitRate>{}</minHitRate>", fmt_f(p.min_hit_rate));
        let _ = writeln!(x, "    <maxFalseAlarm>{}</maxFalseAlarm>", fmt_f(p.max_false_alarm));
        let _ = writeln!(x, "    <weightTrimRate>{}</weightTrimRate>", fmt_f(1.0));
        let _ = writeln!(x, "    <maxDepth>{}</maxDepth>", p.max_depth);
        let _ = writeln!(x, "    <maxWeakCount>{}</maxWeakCount></stageParams>", p.max_weak_count);
        let mode = match p.mode {
            HaarMode::Basic => "BASIC",
            HaarMode::Core => "CORE",
            HaarMode::All => "ALL",
        };
        let _ = writeln!(
            x,
            "  <featureParams>\n    <maxCatCount>0</maxCatCount>\n    <featSize>1</featSize>\n    <mode>{mode}</mode></featureParams>"
        );
        let _ = writeln!(x, "  <stageNum>{}</stageNum>\n  <stages>", self.stages.len());
        // 2. Stages.
        for (si, st) in self.stages.iter().enumerate() {
            let _ = writeln!(x, "    <!-- stage {si} -->\n    <_>");
            let _ = writeln!(x, "      <maxWeakCount>{}</maxWeakCount>", st.weaks.len());
            let _ = writeln!(
                x,
                "      <stageThreshold>{}</stageThreshold>",
                fmt_f(st.threshold as f64)
            );
            let _ = writeln!(x, "      <weakClassifiers>");
            for w in &st.weaks {
                let nodes: Vec<String> = w
                    .splits
                    .iter()
                    .map(|s| {
                        format!(
                            "{} {} {} {}",
                            s.left,
                            s.right,
                            index[&s.feature],
                            fmt_f(s.threshold as f64)
                        )
                    })
                    .collect();
                let leaves: Vec<String> = w.leaves.iter().map(|v| fmt_f(*v as f64)).collect();
                let _ = writeln!(
                    x,
                    "        <_>\n          <internalNodes>\n            {}</internalNodes>\n          <leafValues>\n            {}</leafValues></_>",
                    nodes.join("\n            "),
                    leaves.join(" ")
                );
            }
            let _ = writeln!(x, "      </weakClassifiers></_>");
        }
        let _ = writeln!(x, "  </stages>\n  <features>");
        // 3. Features.
        for &fi in &used {
            let f = &self.pool[fi];
            let _ = writeln!(x, "    <_>\n      <rects>");
            for r in &f.rects[..f.count] {
                let _ = writeln!(
                    x,
                    "        <_>\n          {} {} {} {} {:.1}</_>",
                    r.x, r.y, r.w, r.h, r.weight
                );
            }
            let _ = writeln!(x, "      </rects>\n      <tilted>{}</tilted></_>", f.tilted as i32);
        }
        let _ = writeln!(x, "  </features>\n</cascade>\n</opencv_storage>");
        x
    }

    /// The cascade as rccar's detector loads it (through the XML text, so the rounding is the
    /// file's).
    pub fn to_cascade(&self) -> Result<Cascade, CascadeError> {
        Cascade::from_xml_str(&self.to_xml(), "<training>")
    }
}

/// A loaded cascade compiled for one integral layout (stride and tilted offset), evaluated as
/// the detector's `eval_trees` does.
#[derive(Debug, Clone)]
pub struct CompiledCascade {
    feats: Vec<features::Compiled>,
    /// (threshold, first tree, tree count) per stage.
    stages: Vec<(f32, usize, usize)>,
    /// (first node, first leaf) per tree.
    trees: Vec<(usize, usize)>,
    nodes: Vec<(i32, i32, usize, f32)>,
    leaves: Vec<f32>,
}

impl CompiledCascade {
    /// Compiles `c` for tables with `stride` elements per row, tilted table at `tofs`.
    pub fn new(c: &Cascade, stride: usize, tofs: usize) -> CompiledCascade {
        CompiledCascade {
            feats: c
                .haar_features
                .iter()
                .map(|f| features::Compiled::new(f, stride, tofs))
                .collect(),
            stages: c
                .stages
                .iter()
                .map(|s| (s.threshold, s.first_tree, s.tree_count))
                .collect(),
            trees: c.trees.iter().map(|t| (t.first_node, t.first_leaf)).collect(),
            nodes: c
                .nodes
                .iter()
                .map(|n| (n.left, n.right, n.feature, n.threshold))
                .collect(),
            leaves: c.leaves.clone(),
        }
    }

    /// Number of stages.
    pub fn len(&self) -> usize {
        self.stages.len()
    }

    /// Whether there are no stages (everything passes).
    pub fn is_empty(&self) -> bool {
        self.stages.is_empty()
    }

    /// 1 if the window (integral data `d`, normalisation `inv`) passes every stage, else
    /// −(failed stage), as the detector's result.
    #[inline]
    pub fn eval(&self, d: &[i32], inv: f32) -> i32 {
        for (si, &(thr, ft, nt)) in self.stages.iter().enumerate() {
            let mut sum = 0.0f64;
            for &(first_node, first_leaf) in &self.trees[ft..ft + nt] {
                let mut idx = 0i32;
                let leaf = loop {
                    let (l, r, f, t) = self.nodes[first_node + idx as usize];
                    let v = self.feats[f].raw(d) * inv;
                    idx = if v < t { l } else { r };
                    if idx <= 0 {
                        break -idx;
                    }
                };
                sum += self.leaves[first_leaf + leaf as usize] as f64;
            }
            if sum < thr as f64 {
                return -(si as i32);
            }
        }
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> ModelParams {
        ModelParams {
            width: 8,
            height: 8,
            mode: HaarMode::Basic,
            boost: BoostType::Gentle,
            min_hit_rate: 0.995,
            max_false_alarm: 0.5,
            max_depth: 1,
            max_weak_count: 100,
            num_stages: 2,
        }
    }

    #[test]
    fn written_xml_loads_with_the_same_numbers() {
        let mut m = Model::new(params());
        m.stages.push(StageModel {
            threshold: -0.123_456_79,
            weaks: vec![
                Weak {
                    splits: vec![Split {
                        feature: 5,
                        threshold: 0.017,
                        left: 0,
                        right: -1,
                    }],
                    leaves: vec![-0.75, 0.5],
                },
                Weak {
                    splits: vec![
                        Split {
                            feature: 300,
                            threshold: -0.2,
                            left: 1,
                            right: 2,
                        },
                        Split {
                            feature: 5,
                            threshold: 0.3,
                            left: 0,
                            right: -1,
                        },
                        Split {
                            feature: 7,
                            threshold: 0.1,
                            left: -2,
                            right: -3,
                        },
                    ],
                    leaves: vec![0.1, 0.2, 0.3, 0.4],
                },
            ],
        });
        let c = m.to_cascade().expect("loads");
        assert_eq!((c.width, c.height), (8, 8));
        assert_eq!(c.stages.len(), 1);
        assert_eq!(c.haar_features.len(), 3, "features deduplicated");
        assert_eq!(c.stages[0].threshold, -0.123_456_79f32 - 1e-5);
        assert_eq!(c.leaves, vec![-0.75, 0.5, 0.1, 0.2, 0.3, 0.4]);
        assert_eq!(c.nodes[0].threshold, 0.017f32);
        assert_eq!(c.haar_features[0], m.pool[5]);
        assert_eq!(c.haar_features[1], m.pool[300]);
    }

    #[test]
    fn every_feature_of_the_all_pool_passes_the_loaders_window_checks() {
        // The loader refuses rectangles (upright or tilted) that leave the window, so a
        // cascade using every feature of the pool, tilted ones included, must load.
        let mut m = Model::new(ModelParams {
            width: 12,
            height: 10,
            mode: HaarMode::All,
            ..params()
        });
        let weaks: Vec<Weak> = (0..m.pool.len())
            .map(|f| Weak {
                splits: vec![Split {
                    feature: f,
                    threshold: 0.0,
                    left: 0,
                    right: -1,
                }],
                leaves: vec![-1.0, 1.0],
            })
            .collect();
        m.stages.push(StageModel { threshold: 0.0, weaks });
        let c = m.to_cascade().expect("every feature inside the window");
        assert!(c.has_tilted);
        assert_eq!(c.haar_features.len(), m.pool.len());
    }
}
