//! `rccar detect [--cascade FILE…] IMAGE…`: runs OpenCV cascades (Haar or LBP, current or old
//! XML format; without `--cascade` the configured classes' own, what the car runs) on images;
//! prints one JSON line per image with the boxes and writes an annotated copy of each image
//! (`<file name>.detect.png`, extension kept). A damaged or unreadable image is named, counted
//! and skipped; the run goes on with the next one and exits 1 at the end if any failed.
//!
//! `rccar detect --method colour-template IMAGE…` runs Abdollahi's stop-sign detector (HSV
//! threshold + template matching, src/detect/colour_sign.rs, with the octagon-model templates the
//! pipeline uses for `classes.stop_sign.detect = "colour_template"`) instead; its boxes are
//! printed the same way, with `"cascade": "colour_template"`; its options are the
//! configuration's `[colour_template]` (`--config`, `--set colour_template.KEY=VALUE`).

use anyhow::{Context, Result};
use clap::Args;
use rccar::detect::{annotate, Cascade, DetectParams, Detector};
use rccar::source::escape_name;
use rccar::detect::colour_sign::{HsvSignDetector, HsvSignOptions, Verdict};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// What finds the objects.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// The `--cascade` files.
    Cascade,
    /// Abdollahi's colour + template stop-sign detector (no `--cascade`; the scan flags do not
    /// apply).
    ColourTemplate,
}

/// Flags of `rccar detect`.
#[derive(Args, Debug)]
pub struct DetectArgs {
    /// Cascade XML file (repeatable, at most 16; each runs on every image). Without it, the
    /// configuration's: every class's `classes.<name>.model` whose `detect` is `cascade`.
    /// The scan options are this command's flags (`--scale-factor` …), not `[detect]`'s.
    #[arg(long = "cascade")]
    pub cascades: Vec<PathBuf>,
    /// What finds the objects: the cascades, or Abdollahi's colour + template stop-sign
    /// detector (as `classes.stop_sign.detect = "colour_template"`).
    #[arg(long, value_enum, default_value_t = Method::Cascade)]
    pub method: Method,
    /// The configuration whose `[colour_template]` options `--method colour-template` uses,
    /// and whose classes' cascades run when no `--cascade` is given.
    #[command(flatten)]
    pub config: super::common::ConfigArgs,
    /// Images (PNG or JPEG; colour is converted to grey as OpenCV's cvtColor does).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Ratio between pyramid levels (1.01..=4; below 1.01 the pyramid needs hundreds of levels).
    #[arg(long, default_value_t = 1.1)]
    pub scale_factor: f64,
    /// Raw hits a box needs beyond itself; 0 prints raw hits (0..=100). Default: 3 with
    /// `--cascade`; without it, each class's as the car uses it (`classes.<name>.min_neighbors`,
    /// or `detect.min_neighbors` when that is 0).
    #[arg(long)]
    pub min_neighbors: Option<u32>,
    /// Smallest box, WxH pixels (each side 0..=16384).
    #[arg(long, value_parser = parse_size, default_value = "0x0")]
    pub min_size: (u32, u32),
    /// Largest box, WxH pixels (0x0 = image size; each side 0..=16384).
    #[arg(long, value_parser = parse_size, default_value = "0x0")]
    pub max_size: (u32, u32),
    /// Spread the pyramid levels over all cores.
    #[arg(long)]
    pub parallel: bool,
    /// Also read the traffic-light state inside every box.
    #[arg(long)]
    pub light: bool,
    /// With `--method colour-template`: also print every red candidate and the step that kept
    /// or rejected it (`too_small`, `not_square`, `dark_rim`, `low_score`, `sign`) with its
    /// template score, under `"candidates"`.
    #[arg(long)]
    pub explain: bool,
    /// Directory for annotated images.
    #[arg(long, default_value = "out/detect")]
    pub out: PathBuf,
    /// Don't write annotated images.
    #[arg(long)]
    pub no_annotate: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WxH, e.g. 24x24"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("`{s}`: `{v}` is not a size in pixels"))
    };
    Ok((p(w)?, p(h)?))
}

/// OpenCV's `detectMultiScale` default, used with `--cascade` files when `--min-neighbors` is
/// not given.
const DEFAULT_MIN_NEIGHBORS: u32 = 3;

/// Without `--cascade`: the cascade of every class of the configuration that is found by one
/// (`classes.<name>.model`, `detect = "cascade"`), what the car runs, each with the class's
/// grouping threshold as the car uses it; a configured file that is missing is an error naming
/// its key.
fn configured_cascades(config: &super::common::ConfigArgs) -> Result<Vec<(PathBuf, u32)>> {
    let cfg = config.load()?;
    let (found, missing) = rccar::pipeline::cascade_files(&cfg, Path::new("."));
    if let Some(m) = missing.first() {
        anyhow::bail!("{m}; or give --cascade FILE");
    }
    if found.is_empty() {
        anyhow::bail!(
            "no class of the configuration is found by a cascade: give --cascade FILE (or --method colour-template)"
        );
    }
    let files: Vec<(PathBuf, u32)> = found
        .into_iter()
        .map(|(class, path)| (path, rccar::pipeline::class_min_neighbors(&cfg, class)))
        .collect();
    let shown: Vec<String> = files
        .iter()
        .map(|(p, mn)| format!("{} (min_neighbors {mn})", escape_name(p.as_os_str())))
        .collect();
    eprintln!("detect: the configuration's cascades: {}", shown.join(", "));
    Ok(files)
}

/// Runs the detectors and reports.
pub fn run(args: DetectArgs) -> Result<ExitCode> {
    let params = DetectParams {
        scale_factor: args.scale_factor,
        min_neighbors: args.min_neighbors.unwrap_or(DEFAULT_MIN_NEIGHBORS),
        min_size: args.min_size,
        max_size: args.max_size,
        parallel: args.parallel,
    };
    let mut detectors = Vec::new();
    let names: Vec<String> = match args.method {
        Method::Cascade => {
            let files: Vec<(PathBuf, u32)> = if args.cascades.is_empty() {
                configured_cascades(&args.config)?
            } else {
                args.cascades.iter().map(|p| (p.clone(), params.min_neighbors)).collect()
            };
            annotate::check_options(&params, files.len(), rccar::imageio::limits::MAX_IMAGE_SIDE)?;
            for (path, class_mn) in &files {
                let own = DetectParams {
                    min_neighbors: args.min_neighbors.unwrap_or(*class_mn),
                    ..params
                };
                detectors.push(Finder::Cascade(Box::new(Detector::new(Cascade::from_file(path)?)), own));
            }
            files.iter().map(|(p, _)| escape_name(p.as_os_str())).collect()
        }
        Method::ColourTemplate => {
            if !args.cascades.is_empty() {
                anyhow::bail!("--cascade is not read with --method colour-template: leave it out");
            }
            let cfg = args.config.load()?;
            let det = HsvSignDetector::with_octagon_model(HsvSignOptions::from(&cfg.colour_template))?;
            detectors.push(Finder::Colour(Box::new(det)));
            vec!["colour_template".to_string()]
        }
    };
    if !args.no_annotate {
        std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create", args.out.display()))?;
    }
    let mut failed = 0usize;
    let mut used = std::collections::HashSet::new();
    for path in &args.images {
        let shown = escape_name(path.as_os_str());
        match detect_one(&args, (&names, &mut detectors), path, &shown, &mut used) {
            Ok(()) => {}
            Err(DetectFailure::Skip(why)) => {
                eprintln!("skipped {shown}: {why}");
                failed += 1;
            }
            Err(DetectFailure::Fatal(e)) => return Err(e),
        }
    }
    if failed > 0 {
        eprintln!("{failed} of {} image(s) failed", args.images.len());
        return Ok(ExitCode::from(1));
    }
    Ok(ExitCode::SUCCESS)
}

/// One detector of the run (a cascade with its own scan parameters: the grouping threshold can
/// differ per class).
enum Finder {
    Cascade(Box<Detector>, DetectParams),
    Colour(Box<HsvSignDetector>),
}

/// A problem with one image (skip it) or with the run (stop: e.g. the output disk is full).
enum DetectFailure {
    Skip(String),
    Fatal(anyhow::Error),
}

fn detect_one(
    args: &DetectArgs,
    (names, detectors): (&[String], &mut [Finder]),
    path: &std::path::Path,
    shown: &str,
    used: &mut std::collections::HashSet<String>,
) -> Result<(), DetectFailure> {
    let img = rccar::source::read_image(path).map_err(DetectFailure::Skip)?;
    let (rgb, gray) = annotate::rgb_and_gray(&img);
    let mut candidates = None;
    let found = match detectors {
        [Finder::Colour(det)] => {
            let all = det.candidates(&rgb);
            let found = all
                .iter()
                .filter(|c| c.verdict == Verdict::Sign)
                .map(|c| annotate::FoundBox {
                    cascade: 0,
                    detection: rccar::detect::Detection {
                        rect: c.face,
                        neighbors: 0,
                    },
                    light: None,
                })
                .collect();
            if args.explain {
                candidates = Some(all);
            }
            found
        }
        _ => {
            let cascades = detectors.iter_mut().filter_map(|f| match f {
                Finder::Cascade(d, p) => Some((d.as_mut(), &*p)),
                Finder::Colour(_) => None,
            });
            annotate::detect_all(cascades, &gray, &rgb, args.light)
                .map_err(|(ci, e)| DetectFailure::Skip(format!("{}: {e}", names[ci])))?
        }
    };
    let mut record = annotate::image_record(shown, gray.dimensions(), &found, names);
    if let Some(all) = candidates {
        record["candidates"] = all
            .iter()
            .map(|c| {
                serde_json::json!({
                    "x": c.red.x, "y": c.red.y, "width": c.red.width, "height": c.red.height,
                    "verdict": c.verdict,
                    "score": if c.score.is_finite() { serde_json::json!((c.score * 1000.0).round() / 1000.0) } else { serde_json::Value::Null },
                })
            })
            .collect();
    }
    println!("{record}");
    if !args.no_annotate {
        let name = rccar::source::unique_name(path.file_name().map(escape_name).unwrap_or_default(), used);
        let out = args.out.join(format!("{name}.detect.png"));
        annotate::annotated(&rgb, &found)
            .save(&out)
            .with_context(|| format!("{}: cannot write", out.display()))
            .map_err(DetectFailure::Fatal)?;
    }
    Ok(())
}
