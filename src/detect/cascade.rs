//! Cascade classifiers read from OpenCV's XML files, the model behind `cv::CascadeClassifier`.
//!
//! Two formats are read into one in-memory [`Cascade`]:
//!
//! * the current `<cascade>` format written by `opencv_traincascade` (OpenCV ≥ 2.4):
//!   `stageType` BOOST, `featureType` HAAR (stumps or trees, `internalNodes`/`leafValues`,
//!   weighted rectangles, tilted features) or LBP (8 × 32-bit category subsets per node);
//! * the old `opencv-haar-classifier` format written by `haartraining`: nested
//!   `stages/trees/nodes` with `feature/rects`, `threshold`, `left_val`/`left_node`. It is
//!   converted on load into the same node/leaf layout as the current format (as OpenCV's
//!   `cascadedetect_convert.cpp` does), so one evaluator serves both.
//!
//! Numbers are rounded the way `CascadeClassifierImpl::Data::read` rounds them (text → f64 →
//! f32), and every stage threshold is lowered by OpenCV's `THRESHOLD_EPS = 1e-5` at load time:
//! both matter for box-for-box parity. Units: rectangles in pixels of the cascade's training
//! window (`width` × `height`).
//!
//! Every malformed file is an error naming the origin (file), the element, its line and
//! column and what was wrong; the loader never panics and never indexes out of range later,
//! because every feature index, child index and rectangle is checked here once.

use roxmltree::{Document, Node};
use std::path::Path;

/// OpenCV lowers every stage threshold by this much when it reads a cascade.
pub const THRESHOLD_EPS: f32 = 1e-5;
/// Largest training window side accepted (OpenCV's stock cascades are 14–64 px).
pub const MAX_WINDOW: i32 = 4096;

/// Largest cascade file read, bytes (OpenCV's largest stock cascade,
/// haarcascade_frontalface_alt_tree.xml, is 2.7 MB).
pub const MAX_CASCADE_BYTES: u64 = 32 << 20;

/// Why a cascade could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum CascadeError {
    /// The file is larger than [`MAX_CASCADE_BYTES`].
    #[error("{path}: larger than a cascade file may be ({MAX_CASCADE_BYTES} bytes)")]
    TooLarge {
        /// File that failed.
        path: String,
    },
    /// The file could not be read.
    #[error("{path}: cannot read: {err}")]
    Io {
        /// File that failed.
        path: String,
        /// Underlying error (in the message, not a `source`: said once).
        err: std::io::Error,
    },
    /// Not well-formed XML (truncated, bad characters, ...).
    #[error("{origin}: XML syntax error: {message}")]
    Xml {
        /// File (or `<memory>`) being read.
        origin: String,
        /// roxmltree's message, with line and column.
        message: String,
    },
    /// Well-formed XML that is not a usable cascade.
    #[error("{origin}:{line}:{column}: <{element}>: {message}")]
    Invalid {
        /// File (or `<memory>`) being read.
        origin: String,
        /// Line of the offending element (1-based).
        line: u32,
        /// Column of the offending element (1-based).
        column: u32,
        /// Name of the offending element.
        element: String,
        /// What was wrong with it.
        message: String,
    },
    /// A class detected by colour + template (`classes.<name>.detect = "colour_template"`)
    /// cannot make its templates with the `[colour_template]` options (e.g. thresholds that
    /// leave the model sign without a red pixel). Loaded beside the cascades, so reported here.
    #[error("classes.{class}.detect = \"colour_template\" with these [colour_template] options: {err}")]
    ColourTemplate {
        /// The class.
        class: String,
        /// Why the templates could not be made.
        err: crate::detect::colour_sign::TemplateError,
    },
}

/// What a cascade's weak classifiers look at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeatureType {
    /// Haar-like features: weighted sums of 2–3 rectangles, optionally tilted by 45°.
    Haar,
    /// Multi-block local binary patterns: a 3 × 3 grid of equal cells, an 8-bit code.
    Lbp,
}

/// One weighted rectangle of a Haar feature, in window pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WeightedRect {
    /// Left (upright) or apex column (tilted).
    pub x: i32,
    /// Top row.
    pub y: i32,
    /// Width (tilted: length along the down-right diagonal).
    pub w: i32,
    /// Height (tilted: length along the down-left diagonal).
    pub h: i32,
    /// Weight of the rectangle's pixel sum (unitless; OpenCV uses it as stored).
    pub weight: f32,
}

/// A Haar-like feature: up to three weighted rectangles.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HaarFeature {
    /// The rectangles; unused ones have weight 0.
    pub rects: [WeightedRect; 3],
    /// How many of `rects` the file gave (2 or 3).
    pub count: usize,
    /// Rectangles are rotated by 45° (summed on the tilted integral image).
    pub tilted: bool,
}

/// An MB-LBP feature: a 3 × 3 grid of `w` × `h` cells whose top-left cell is at (x, y).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LbpFeature {
    /// Left column of the grid.
    pub x: i32,
    /// Top row of the grid.
    pub y: i32,
    /// Cell width.
    pub w: i32,
    /// Cell height.
    pub h: i32,
}

/// One split of a weak classifier's decision tree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TreeNode {
    /// Next node if the test goes left: > 0 an internal node index within the tree, ≤ 0 the
    /// leaf `-left` (OpenCV's encoding).
    pub left: i32,
    /// Same for the right branch.
    pub right: i32,
    /// Index into the cascade's feature list.
    pub feature: usize,
    /// Haar: go left when `feature value < threshold`. LBP: unused (0).
    pub threshold: f32,
}

/// A weak classifier: a tree of nodes and its leaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WeakTree {
    /// First node in [`Cascade::nodes`].
    pub first_node: usize,
    /// Number of nodes.
    pub node_count: usize,
    /// First leaf in [`Cascade::leaves`].
    pub first_leaf: usize,
}

/// A boosted stage: the sum of its trees' leaves must reach the threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stage {
    /// Threshold as OpenCV uses it (file value − [`THRESHOLD_EPS`]).
    pub threshold: f32,
    /// First tree in [`Cascade::trees`].
    pub first_tree: usize,
    /// Number of trees.
    pub tree_count: usize,
}

/// A loaded cascade classifier, format-independent.
#[derive(Debug, Clone, PartialEq)]
pub struct Cascade {
    /// Training window width in pixels.
    pub width: i32,
    /// Training window height in pixels.
    pub height: i32,
    /// Haar or LBP.
    pub feature_type: FeatureType,
    /// Stages in evaluation order.
    pub stages: Vec<Stage>,
    /// All weak trees, stage by stage.
    pub trees: Vec<WeakTree>,
    /// All tree nodes, tree by tree.
    pub nodes: Vec<TreeNode>,
    /// All leaf values, tree by tree.
    pub leaves: Vec<f32>,
    /// LBP category subsets: `subset_size` words per node, node by node (empty for Haar).
    pub subsets: Vec<i32>,
    /// 32-bit words per LBP subset (`(maxCatCount + 31) / 32`; 0 for Haar).
    pub subset_size: usize,
    /// Haar features (empty for LBP).
    pub haar_features: Vec<HaarFeature>,
    /// LBP features (empty for Haar).
    pub lbp_features: Vec<LbpFeature>,
    /// Largest number of nodes in one tree (1 = stumps).
    pub max_nodes_per_tree: usize,
    /// Whether any Haar feature is tilted (the tilted integral is then needed).
    pub has_tilted: bool,
    /// The file was in the old `opencv-haar-classifier` format.
    pub old_format: bool,
}

/// Where we are in the document, for error messages.
struct Ctx<'a> {
    origin: &'a str,
    doc: &'a Document<'a>,
}

impl Ctx<'_> {
    fn err(&self, node: Node, message: impl Into<String>) -> CascadeError {
        let pos = self.doc.text_pos_at(node.range().start);
        CascadeError::Invalid {
            origin: self.origin.to_string(),
            line: pos.row,
            column: pos.col,
            element: element_name(node),
            message: message.into(),
        }
    }

    /// The child element called `name`, or an error naming the parent.
    fn child<'a, 'i>(&self, node: Node<'a, 'i>, name: &str) -> Result<Node<'a, 'i>, CascadeError> {
        child(node, name).ok_or_else(|| self.err(node, format!("missing <{name}>")))
    }

    /// The whitespace-separated numbers in an element's text.
    fn numbers<'n>(&self, node: Node<'n, 'n>) -> impl Iterator<Item = Result<f64, CascadeError>> + use<'n, '_> {
        let text = node.text().unwrap_or("");
        text.split_ascii_whitespace().map(move |t| {
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| self.err(node, format!("`{t}` is not a finite number")))
        })
    }

    fn number(&self, node: Node) -> Result<f64, CascadeError> {
        let mut it = self.numbers(node);
        let v = it
            .next()
            .ok_or_else(|| self.err(node, "expected a number, found nothing"))??;
        if it.next().is_some() {
            return Err(self.err(node, "expected one number, found several"));
        }
        Ok(v)
    }

    fn int(&self, node: Node, min: i64, max: i64) -> Result<i32, CascadeError> {
        as_int(self.number(node)?, min, max).ok_or_else(|| {
            self.err(
                node,
                format!("expected an integer in [{min}, {max}], found `{}`", text_of(node)),
            )
        })
    }

    fn float_child(&self, node: Node, name: &str) -> Result<f32, CascadeError> {
        Ok(self.number(self.child(node, name)?)? as f32)
    }
}

fn element_name(node: Node) -> String {
    if node.is_element() {
        node.tag_name().name().to_string()
    } else {
        "?".to_string()
    }
}

fn text_of<'a>(node: Node<'a, '_>) -> &'a str {
    node.text().unwrap_or("").trim()
}

fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.is_element() && c.tag_name().name() == name)
}

/// The element children (OpenCV's sequence items `<_>`).
fn items<'a, 'i>(node: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(|c| c.is_element())
}

fn as_int(v: f64, min: i64, max: i64) -> Option<i32> {
    (v.fract() == 0.0 && v >= min as f64 && v <= max as f64).then_some(v as i32)
}

impl Cascade {
    /// Loads a cascade from an XML file (either format).
    pub fn from_file(path: impl AsRef<Path>) -> Result<Cascade, CascadeError> {
        use std::io::Read;
        let path = path.as_ref();
        let io = |err| CascadeError::Io {
            path: path.display().to_string(),
            err,
        };
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .map_err(io)?
            .take(MAX_CASCADE_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() as u64 > MAX_CASCADE_BYTES {
            return Err(CascadeError::TooLarge {
                path: path.display().to_string(),
            });
        }
        let origin = path.display().to_string();
        let text = String::from_utf8(bytes).map_err(|e| CascadeError::Xml {
            origin: origin.clone(),
            message: format!("not UTF-8 at byte {}", e.utf8_error().valid_up_to()),
        })?;
        Self::from_xml_str(&text, &origin)
    }

    /// Parses a cascade from XML text; `origin` names it in errors (a path or `<memory>`).
    pub fn from_xml_str(text: &str, origin: &str) -> Result<Cascade, CascadeError> {
        let opts = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: 50_000_000,
            ..Default::default()
        };
        let doc = Document::parse_with_options(text, opts).map_err(|e| CascadeError::Xml {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        let ctx = Ctx { origin, doc: &doc };
        let root = doc.root_element();
        // 1. OpenCV reads the first top-level node of <opencv_storage>.
        let top = if root.tag_name().name() == "opencv_storage" {
            items(root)
                .next()
                .ok_or_else(|| ctx.err(root, "no cascade inside <opencv_storage>"))?
        } else {
            root
        };
        let cascade = if top.attribute("type_id") == Some("opencv-haar-classifier") || child(top, "size").is_some() {
            read_old(&ctx, top)?
        } else {
            read_new(&ctx, top)?
        };
        if cascade.stages.is_empty() {
            return Err(ctx.err(top, "the cascade has no stages"));
        }
        Ok(cascade)
    }

    /// Number of stages.
    pub fn stage_count(&self) -> usize {
        self.stages.len()
    }

    /// Number of features (Haar or LBP).
    pub fn feature_count(&self) -> usize {
        match self.feature_type {
            FeatureType::Haar => self.haar_features.len(),
            FeatureType::Lbp => self.lbp_features.len(),
        }
    }

    /// Checks every index and rectangle once, so evaluation can trust them.
    fn check(&self, ctx: &Ctx, at: Node) -> Result<(), CascadeError> {
        let nfeat = self.feature_count();
        for (ti, t) in self.trees.iter().enumerate() {
            let leaves = if ti + 1 < self.trees.len() {
                self.trees[ti + 1].first_leaf
            } else {
                self.leaves.len()
            } - t.first_leaf;
            if leaves != t.node_count + 1 {
                return Err(ctx.err(at, format!("tree {ti} has {} nodes but {leaves} leaves", t.node_count)));
            }
            for (ni, n) in self.nodes[t.first_node..t.first_node + t.node_count].iter().enumerate() {
                if n.feature >= nfeat {
                    return Err(ctx.err(at, format!("tree {ti} node {ni} uses feature {} of {nfeat}", n.feature)));
                }
                for c in [n.left, n.right] {
                    let ok = if c > 0 {
                        (c as usize) < t.node_count && c as usize > ni
                    } else {
                        ((-(c as i64)) as usize) < leaves
                    };
                    if !ok {
                        return Err(ctx.err(at, format!("tree {ti} node {ni} points to missing child {c}")));
                    }
                }
            }
        }
        let (w, h) = (self.width, self.height);
        for (fi, f) in self.haar_features.iter().enumerate() {
            for r in &f.rects[..f.count] {
                let inside = if f.tilted {
                    r.w >= 0 && r.h >= 0 && r.x - r.h >= 0 && r.x + r.w <= w && r.y >= 0 && r.y + r.w + r.h <= h
                } else {
                    r.w >= 0 && r.h >= 0 && r.x >= 0 && r.y >= 0 && r.x + r.w <= w && r.y + r.h <= h
                };
                if !inside {
                    return Err(ctx.err(
                        at,
                        format!(
                            "feature {fi}: rectangle {} {} {} {} leaves the {w}x{h} window",
                            r.x, r.y, r.w, r.h
                        ),
                    ));
                }
            }
        }
        for (fi, f) in self.lbp_features.iter().enumerate() {
            if f.w <= 0 || f.h <= 0 || f.x < 0 || f.y < 0 || f.x + 3 * f.w > w || f.y + 3 * f.h > h {
                return Err(ctx.err(
                    at,
                    format!(
                        "LBP feature {fi}: grid {} {} {} {} leaves the {w}x{h} window",
                        f.x, f.y, f.w, f.h
                    ),
                ));
            }
        }
        Ok(())
    }
}

fn read_window(ctx: &Ctx, w: i32, h: i32, at: Node) -> Result<(), CascadeError> {
    if w < 3 || h < 3 {
        return Err(ctx.err(at, format!("window {w}x{h} is smaller than 3x3")));
    }
    Ok(())
}

/// Reads a Haar feature's `<rects>` (and `<tilted>`), shared by both formats.
fn read_haar_feature(ctx: &Ctx, feat: Node) -> Result<HaarFeature, CascadeError> {
    let rects = ctx.child(feat, "rects")?;
    let mut f = HaarFeature::default();
    for (i, r) in items(rects).enumerate() {
        if i >= 3 {
            return Err(ctx.err(rects, "more than 3 rectangles"));
        }
        let v: Vec<f64> = ctx.numbers(r).collect::<Result<_, _>>()?;
        if v.len() != 5 {
            return Err(ctx.err(
                r,
                format!("a rectangle needs 5 numbers (x y w h weight), found {}", v.len()),
            ));
        }
        let mut xywh = [0i32; 4];
        for k in 0..4 {
            xywh[k] = as_int(v[k], -(MAX_WINDOW as i64), MAX_WINDOW as i64)
                .ok_or_else(|| ctx.err(r, format!("`{}` is not a rectangle coordinate", v[k])))?;
        }
        f.rects[i] = WeightedRect {
            x: xywh[0],
            y: xywh[1],
            w: xywh[2],
            h: xywh[3],
            weight: v[4] as f32,
        };
        f.count = i + 1;
    }
    if f.count < 1 {
        return Err(ctx.err(rects, "a feature needs at least one rectangle"));
    }
    if let Some(t) = child(feat, "tilted") {
        f.tilted = ctx.int(t, i32::MIN as i64, i32::MAX as i64)? != 0;
    }
    Ok(f)
}

/// One weak tree of a stage (`<_>` of `weakClassifiers`): its nodes (`node_step` numbers
/// each; with `ncat` > 0 categorical, their subsets), then its leaves, appended to `c`.
fn read_tree(ctx: &Ctx, w: Node, node_step: usize, ncat: i32, c: &mut Cascade) -> Result<(), CascadeError> {
    let inodes = ctx.child(w, "internalNodes")?;
    let lv = ctx.child(w, "leafValues")?;
    let vals: Vec<f64> = ctx.numbers(inodes).collect::<Result<_, _>>()?;
    if vals.is_empty() || !vals.len().is_multiple_of(node_step) {
        return Err(ctx.err(
            inodes,
            format!("{} numbers is not a multiple of {node_step} per node", vals.len()),
        ));
    }
    let tree = WeakTree {
        first_node: c.nodes.len(),
        node_count: vals.len() / node_step,
        first_leaf: c.leaves.len(),
    };
    for n in vals.chunks(node_step) {
        let int = |v: f64| {
            as_int(v, i32::MIN as i64, i32::MAX as i64)
                .ok_or_else(|| ctx.err(inodes, format!("`{v}` is not an integer")))
        };
        let feature = int(n[2])?;
        if feature < 0 {
            return Err(ctx.err(inodes, format!("negative feature index {feature}")));
        }
        let threshold = if ncat > 0 {
            for &s in &n[3..] {
                c.subsets.push(int(s)?);
            }
            0.0
        } else {
            n[3] as f32
        };
        c.nodes.push(TreeNode {
            left: int(n[0])?,
            right: int(n[1])?,
            feature: feature as usize,
            threshold,
        });
    }
    for v in ctx.numbers(lv) {
        c.leaves.push(v? as f32);
    }
    c.max_nodes_per_tree = c.max_nodes_per_tree.max(tree.node_count);
    c.trees.push(tree);
    Ok(())
}

/// The current `<cascade>` format.
fn read_new(ctx: &Ctx, top: Node) -> Result<Cascade, CascadeError> {
    // 1. Header: stage type, feature type, window, category count.
    let stage_type = ctx.child(top, "stageType")?;
    if text_of(stage_type) != "BOOST" {
        return Err(ctx.err(stage_type, format!("stage type `{}` is not BOOST", text_of(stage_type))));
    }
    let ft = ctx.child(top, "featureType")?;
    let feature_type = match text_of(ft) {
        "HAAR" => FeatureType::Haar,
        "LBP" => FeatureType::Lbp,
        other => return Err(ctx.err(ft, format!("feature type `{other}` is not supported (HAAR or LBP)"))),
    };
    let width = ctx.int(ctx.child(top, "width")?, 1, MAX_WINDOW as i64)?;
    let height = ctx.int(ctx.child(top, "height")?, 1, MAX_WINDOW as i64)?;
    read_window(ctx, width, height, top)?;
    let fp = ctx.child(top, "featureParams")?;
    let ncat = match child(fp, "maxCatCount") {
        Some(n) => ctx.int(n, 0, 1 << 16)?,
        None => 0,
    };
    let subset_size = (ncat as usize).div_ceil(32);
    if feature_type == FeatureType::Lbp && subset_size == 0 {
        return Err(ctx.err(fp, "an LBP cascade needs maxCatCount > 0"));
    }
    let node_step = 3 + if ncat > 0 { subset_size } else { 1 };

    // 2. Stages and their weak trees.
    let mut c = Cascade {
        width,
        height,
        feature_type,
        stages: vec![],
        trees: vec![],
        nodes: vec![],
        leaves: vec![],
        subsets: vec![],
        subset_size,
        haar_features: vec![],
        lbp_features: vec![],
        max_nodes_per_tree: 0,
        has_tilted: false,
        old_format: false,
    };
    let stages = ctx.child(top, "stages")?;
    for st in items(stages) {
        let threshold = ctx.float_child(st, "stageThreshold")? - THRESHOLD_EPS;
        let weak = ctx.child(st, "weakClassifiers")?;
        let first_tree = c.trees.len();
        for w in items(weak) {
            read_tree(ctx, w, node_step, ncat, &mut c)?;
        }
        if c.trees.len() == first_tree {
            return Err(ctx.err(weak, "a stage without weak classifiers"));
        }
        c.stages.push(Stage {
            threshold,
            first_tree,
            tree_count: c.trees.len() - first_tree,
        });
    }

    // 3. Features.
    let features = ctx.child(top, "features")?;
    for f in items(features) {
        match feature_type {
            FeatureType::Haar => {
                let hf = read_haar_feature(ctx, f)?;
                c.has_tilted |= hf.tilted;
                c.haar_features.push(hf);
            }
            FeatureType::Lbp => {
                let r = ctx.child(f, "rect")?;
                let v: Vec<f64> = ctx.numbers(r).collect::<Result<_, _>>()?;
                let xywh: Option<Vec<i32>> = v
                    .iter()
                    .map(|&x| as_int(x, -(MAX_WINDOW as i64), MAX_WINDOW as i64))
                    .collect();
                match xywh.as_deref() {
                    Some(&[x, y, w, h]) => c.lbp_features.push(LbpFeature { x, y, w, h }),
                    _ => return Err(ctx.err(r, "an LBP rect needs 4 integers (x y w h)")),
                }
            }
        }
    }
    c.check(ctx, features)?;
    Ok(c)
}

/// The old `opencv-haar-classifier` format, converted to the node/leaf layout.
fn read_old(ctx: &Ctx, top: Node) -> Result<Cascade, CascadeError> {
    // 1. Window size "W H".
    let size = ctx.child(top, "size")?;
    let wh: Vec<f64> = ctx.numbers(size).collect::<Result<_, _>>()?;
    let (width, height) = match wh.as_slice() {
        &[w, h] => (
            as_int(w, 1, MAX_WINDOW as i64).ok_or_else(|| ctx.err(size, format!("bad width `{w}`")))?,
            as_int(h, 1, MAX_WINDOW as i64).ok_or_else(|| ctx.err(size, format!("bad height `{h}`")))?,
        ),
        _ => return Err(ctx.err(size, "expected two numbers, width and height")),
    };
    read_window(ctx, width, height, size)?;
    let mut c = Cascade {
        width,
        height,
        feature_type: FeatureType::Haar,
        stages: vec![],
        trees: vec![],
        nodes: vec![],
        leaves: vec![],
        subsets: vec![],
        subset_size: 0,
        haar_features: vec![],
        lbp_features: vec![],
        max_nodes_per_tree: 0,
        has_tilted: false,
        old_format: true,
    };
    // 2. Stages; each tree's nodes carry their own feature, which becomes a feature entry.
    let stages = ctx.child(top, "stages")?;
    for (si, st) in items(stages).enumerate() {
        if let Some(p) = child(st, "parent") {
            let parent = ctx.int(p, -1, i32::MAX as i64)?;
            if parent != si as i32 - 1 {
                return Err(ctx.err(
                    p,
                    "tree-structured cascades (parent other than the previous stage) are not supported",
                ));
            }
        }
        let threshold = ctx.float_child(st, "stage_threshold")? - THRESHOLD_EPS;
        let trees = ctx.child(st, "trees")?;
        let first_tree = c.trees.len();
        for t in items(trees) {
            let tree = WeakTree {
                first_node: c.nodes.len(),
                node_count: 0,
                first_leaf: c.leaves.len(),
            };
            let tnodes: Vec<Node> = items(t).collect();
            if tnodes.is_empty() {
                return Err(ctx.err(t, "a tree without nodes"));
            }
            for n in &tnodes {
                let f = read_haar_feature(ctx, ctx.child(*n, "feature")?)?;
                c.has_tilted |= f.tilted;
                let feature = c.haar_features.len();
                c.haar_features.push(f);
                let threshold = ctx.float_child(*n, "threshold")?;
                // Leaves are numbered in the order met; a child node keeps its index.
                let mut branch = |val: &str, node: &str| -> Result<i32, CascadeError> {
                    if let Some(v) = child(*n, val) {
                        let leaf = (c.leaves.len() - tree.first_leaf) as i32;
                        c.leaves.push(ctx.number(v)? as f32);
                        Ok(-leaf)
                    } else if let Some(k) = child(*n, node) {
                        ctx.int(k, 1, tnodes.len() as i64 - 1)
                    } else {
                        Err(ctx.err(*n, format!("missing <{val}> or <{node}>")))
                    }
                };
                let left = branch("left_val", "left_node")?;
                let right = branch("right_val", "right_node")?;
                c.nodes.push(TreeNode {
                    left,
                    right,
                    feature,
                    threshold,
                });
            }
            let tree = WeakTree {
                node_count: tnodes.len(),
                ..tree
            };
            c.max_nodes_per_tree = c.max_nodes_per_tree.max(tree.node_count);
            c.trees.push(tree);
        }
        if c.trees.len() == first_tree {
            return Err(ctx.err(trees, "a stage without trees"));
        }
        c.stages.push(Stage {
            threshold,
            first_tree,
            tree_count: c.trees.len() - first_tree,
        });
    }
    c.check(ctx, stages)?;
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    const STUMP: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<cascade type_id="opencv-cascade-classifier"><stageType>BOOST</stageType>
  <featureType>HAAR</featureType><height>4</height><width>4</width>
  <featureParams><maxCatCount>0</maxCatCount></featureParams>
  <stageNum>1</stageNum>
  <stages><_><maxWeakCount>1</maxWeakCount><stageThreshold>-0.5</stageThreshold>
    <weakClassifiers><_><internalNodes>0 -1 0 0.25</internalNodes><leafValues>-1. 1.</leafValues></_></weakClassifiers></_></stages>
  <features><_><rects><_>0 0 4 2 -1.</_><_>0 2 4 2 2.</_></rects><tilted>0</tilted></_></features>
</cascade></opencv_storage>"#;

    #[test]
    fn reads_a_stump_and_lowers_the_threshold() {
        let c = Cascade::from_xml_str(STUMP, "t").unwrap();
        assert_eq!((c.width, c.height, c.stages.len(), c.max_nodes_per_tree), (4, 4, 1, 1));
        assert_eq!(c.stages[0].threshold, -0.5f32 - 1e-5f32);
        assert_eq!(c.haar_features[0].rects[1].weight, 2.0);
        assert_eq!(c.leaves, vec![-1.0, 1.0]);
    }

    #[test]
    fn errors_name_the_element_and_line() {
        let bad = STUMP.replace("0 2 4 2 2.", "0 2 4 2");
        let e = Cascade::from_xml_str(&bad, "t.xml").unwrap_err().to_string();
        assert!(
            e.starts_with("t.xml:9:") && e.contains("<_>") && e.contains("5 numbers"),
            "{e}"
        );
        let e = Cascade::from_xml_str(&STUMP[..300], "t.xml").unwrap_err().to_string();
        assert!(e.contains("XML syntax error"), "{e}");
        let bad = STUMP.replace("0 -1 0 0.25", "0 -1 7 0.25");
        let e = Cascade::from_xml_str(&bad, "t.xml").unwrap_err().to_string();
        assert!(e.contains("feature 7 of 1"), "{e}");
        let bad = STUMP.replace("0 2 4 2 2.", "0 2 5 2 2.");
        let e = Cascade::from_xml_str(&bad, "t.xml").unwrap_err().to_string();
        assert!(e.contains("leaves the 4x4 window"), "{e}");
    }
}
