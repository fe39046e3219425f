//! `rccar stereo LEFT RIGHT`: ranges objects in one stereo pair (Zaarane et al. 2020): the
//! boxes given with `--box`, else the configured detector's boxes in the reference image,
//! are matched along the rows of the other image (NCC) and ranged by Eq. 16, exact angles and
//! b·f/d. With `[stereo] calibration` set, both images are first rectified with the maps of
//! that file (which must be for this image size); without it the pair is taken as an ideal
//! rectified pair of `[camera]` with `[stereo] base_m`. Prints one JSON line per box.

use super::common::{load_detector, ConfigArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::stereo::matching::Matcher;
use rccar::stereo::still::StillPair;
use std::path::PathBuf;
use std::process::ExitCode;

/// `rccar stereo` flags.
#[derive(Args, Debug)]
pub struct StereoRangeArgs {
    /// Left image (PNG or JPEG).
    pub left: PathBuf,
    /// Right image, the same size.
    pub right: PathBuf,
    /// A box in the reference image, `X,Y,W,H` pixels (repeatable, at most 1000; X, Y
    /// 0..=16384, W, H 1..=16384); default: run the detector.
    #[arg(long = "box", value_name = "X,Y,W,H")]
    pub boxes: Vec<String>,
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Most `--box` flags.
const MAX_BOXES: usize = 1000;

fn parse_box(s: &str) -> Result<[i64; 4]> {
    let v: Vec<i64> = s
        .split(',')
        .map(|t| t.trim().parse::<i64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--box {s}: not four integers X,Y,W,H"))?;
    let [x, y, w, h] = v[..] else {
        bail!("--box {s}: needs exactly four integers X,Y,W,H");
    };
    let side = rccar::imageio::limits::MAX_IMAGE_SIDE as i64;
    if !((0..=side).contains(&x) && (0..=side).contains(&y) && (1..=side).contains(&w) && (1..=side).contains(&h)) {
        bail!("--box {s}: X and Y must be 0..={side}, W and H 1..={side} pixels (the largest image side)");
    }
    Ok([x, y, w, h])
}

/// Runs `rccar stereo`.
pub fn run(a: StereoRangeArgs) -> Result<ExitCode> {
    let cfg = a.config.load()?;
    if a.boxes.len() > MAX_BOXES {
        bail!("{} --box flags: at most {MAX_BOXES}", a.boxes.len());
    }
    let boxes: Vec<[i64; 4]> = a.boxes.iter().map(|s| parse_box(s)).collect::<Result<_>>()?;
    let load = |p: &PathBuf| -> Result<image::RgbImage> { Ok(rccar::calib::photos::open_image(p)?.to_rgb8()) };
    let (l, r) = (load(&a.left)?, load(&a.right)?);
    if l.dimensions() != r.dimensions() {
        bail!(
            "{} is {}x{} but {} is {}x{}: a stereo pair must have one size",
            a.left.display(),
            l.width(),
            l.height(),
            a.right.display(),
            r.width(),
            r.height()
        );
    }
    // 1. Rectify with the calibration file, or take the pair as ideal.
    let (w, h) = l.dimensions();
    let pair = StillPair::new(&cfg.still_pair_setup(w, h), &l, &r).context("[stereo] calibration")?;
    let reference_left = pair.matching.reference_left;
    // 2. The boxes: given, or detected in the (rectified) reference image.
    let labelled: Vec<(String, [i64; 4])> = if boxes.is_empty() {
        let Some(mut stage) = load_detector(&cfg)? else {
            bail!("no --box given and no detector configured ([detect] cascades missing or off)");
        };
        stage
            .run(pair.reference(), None)?
            .into_iter()
            .map(|d| (d.label, [d.rect.x, d.rect.y, d.rect.width, d.rect.height].map(i64::from)))
            .collect()
    } else {
        boxes.into_iter().map(|b| ("box".to_string(), b)).collect()
    };
    if labelled.is_empty() {
        bail!(
            "no boxes: the detector found nothing in the {} image {}; give the object's box with --box X,Y,W,H",
            cfg.stereo.reference,
            if reference_left {
                a.left.display()
            } else {
                a.right.display()
            }
        );
    }
    // 3. Match and range each box.
    let mut m = Matcher::new();
    for (label, b) in labelled {
        println!("{}", pair.range_record(&mut m, &label, b));
    }
    Ok(ExitCode::SUCCESS)
}
