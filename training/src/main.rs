//! `rccar-train`: cascade training tools (see `training/README.md`).

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use rccar_train::evaluate;
use rccar_train::features::HaarMode;
use rccar_train::model::{BoostType, ModelParams};
use rccar_train::samples;
use rccar_train::simgen;
use rccar_train::train::{self, Progress, StageLog, TrainOptions};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "rccar-train",
    about = "Train and evaluate Haar cascades for rccar (OpenCV XML)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a cascade (opencv_traincascade's job).
    Train(TrainArgs),
    /// Render positives, negatives or held-out frames with the simulator.
    Gen(GenArgs),
    /// Recall, precision, FP per frame and the recall–FP curve on labelled frames.
    Evaluate(EvalArgs),
    /// Positives from template images, distorted over backgrounds (opencv_createsamples -img).
    Distort(DistortArgs),
    /// Boxes from a CSV (file,x,y,w,h per line) to info.dat, with preview pictures.
    Boxes(BoxesArgs),
    /// Photo-like labelled frames: the simulator's stop sign pasted on photographs.
    Photoset(PhotosetArgs),
    /// Train the learned pilot (`steering.method = "learned"`) on simulator drives of the
    /// classical controller and/or recordings; writes its weights file (docs/pilot.md).
    Pilot(PilotArgs),
}

#[derive(clap::Args)]
struct DistortArgs {
    /// Template images: files, folders (every .png/.jpg in them) or globs like `crops/*.jpg`;
    /// repeat or list several. PNG with alpha: transparent pixels show the background; a JPEG
    /// or opaque PNG crop is pasted whole (the rectangle is the object).
    #[arg(long = "template", num_args = 1..)]
    templates: Vec<String>,
    /// Use the boxes of these info.dat files (e.g. from `rccar-train boxes`) as templates: each
    /// box is cut out of its photo.
    #[arg(long = "templates-from-info", num_args = 1..)]
    templates_from_info: Vec<PathBuf>,
    /// Backgrounds to paste onto (bg.txt: one image per line, or a folder). Another set than
    /// training's --bg is better (docs/training.md, "Which backgrounds").
    #[arg(long = "bg", required = true)]
    bg: Vec<PathBuf>,
    /// Samples to write. Train with --num-pos up to about count / 1.04 (each stage drops a few;
    /// `train` works it out).
    #[arg(long, default_value_t = rccar_train::plan::DEFAULT_DISTORT_COUNT)]
    count: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Window WxH the samples are made for: the pasted object is at least this big. Written
    /// into info.dat; `train` then uses it for -W/-H. Default: from the boxes (with
    /// --templates-from-info), else (crops) the crops' median aspect at 20 px on the shorter
    /// side; with crops, give the smallest object in your frames / 1.21.
    #[arg(long)]
    window: Option<String>,
    /// Output folder (PNG crops + info.dat).
    #[arg(long)]
    out: PathBuf,
    /// Largest in-plane rotation, degrees.
    #[arg(long, default_value_t = 10.0)]
    max_angle_deg: f64,
    /// Largest corner displacement (perspective), fraction of the object size.
    #[arg(long, default_value_t = 0.12)]
    max_skew: f64,
    /// Smallest object, multiple of the window.
    #[arg(long, default_value_t = 1.0)]
    min_scale: f64,
    /// Largest object, multiple of the window.
    #[arg(long, default_value_t = 3.0)]
    max_scale: f64,
    /// Largest Gaussian blur sigma, pixels (0 = none).
    #[arg(long, default_value_t = 1.5)]
    max_blur: f64,
    /// Largest camera noise standard deviation, grey levels.
    #[arg(long, default_value_t = 8.0)]
    max_noise: f64,
    /// Largest exposure gamma: each sample gets γ in [1/G, G] (1 = none).
    #[arg(long, default_value_t = 1.35)]
    max_gamma: f64,
    /// Lowest JPEG quality of the half of the samples that are JPEG-compressed (100 = none).
    #[arg(long, default_value_t = 50)]
    min_jpeg_quality: u8,
}

/// Refuses a flag's value outside `lo..=hi` (NaN too), naming the flag and the bound.
fn within<T: PartialOrd + std::fmt::Display + Copy>(flag: &str, v: T, lo: T, hi: T, unit: &str) -> anyhow::Result<()> {
    if !(v >= lo && v <= hi) {
        bail!("{flag} {v}: must be {lo}..={hi}{unit}");
    }
    Ok(())
}

/// Refuses a window side outside 3..=256 pixels (as `train -W/-H`).
fn check_window(flag: &str, (w, h): (u32, u32)) -> anyhow::Result<()> {
    if !(3..=256).contains(&w) || !(3..=256).contains(&h) {
        bail!("{flag} {w}x{h}: each side must be 3..=256 px");
    }
    Ok(())
}

/// Refuses a size (N or WxH) with a side above the largest image side.
fn check_size(flag: &str, (w, h): (u32, u32)) -> anyhow::Result<()> {
    let side = rccar::imageio::limits::MAX_IMAGE_SIDE;
    if w > side || h > side {
        bail!("{flag} {w}x{h}: each side must be 0..={side} px");
    }
    Ok(())
}

/// Most templates `distort` holds (each a decoded image).
const MAX_TEMPLATES: usize = 10_000;
/// Most stages `train` builds (OpenCV's cascades have 20-25).
const MAX_STAGES: u32 = 100;
/// Most samples (`--count`, `--num-pos`, `--num-neg`) a command makes or uses per stage.
const MAX_SAMPLES: usize = 1_000_000;
/// Most weak classifiers per stage.
const MAX_WEAK: u32 = 10_000;
/// Most memory `train --mem-mb` may be given, MiB (64 GiB).
const MAX_MEM_MB: usize = 65_536;
/// Most threads.
const MAX_THREADS: usize = 256;
/// Most frames `photoset` makes of either kind.
const MAX_PHOTOSET_FRAMES: usize = 100_000;

/// The detector's settings a user gives `train` (held-out check) and `evaluate`, as
/// `[detect]` bounds them: scale factor 1.01..=2, minNeighbors 0..=100, a minimum size within
/// the largest image side.
fn check_detector(prefix: &str, scale_factor: f64, min_neighbors: u32, min_size: (u32, u32)) -> anyhow::Result<()> {
    within("--scale-factor", scale_factor, 1.01, 2.0, "")?;
    within(&format!("--{prefix}min-neighbors"), min_neighbors, 0, 100, "")?;
    check_size(&format!("--{prefix}min-size"), min_size)
}

/// `train`'s sizes and counts, each refused by flag and bound before anything is read.
fn check_train_args(a: &TrainArgs) -> anyhow::Result<(u32, u32)> {
    for (flag, side) in [("-W", a.width), ("-H", a.height)] {
        if let Some(v) = side {
            within(flag, v, 3, 256, " px")?;
        }
    }
    within("--num-stages", a.num_stages, 1, MAX_STAGES, "")?;
    if let Some(n) = a.num_pos {
        within("--num-pos", n, 1, MAX_SAMPLES, "")?;
    }
    within("--num-neg", a.num_neg, 1, MAX_SAMPLES, "")?;
    within("--max-weak-count", a.max_weak_count, 1, MAX_WEAK, "")?;
    within("--mem-mb", a.mem_mb, 1, MAX_MEM_MB, " MiB")?;
    if let Some(t) = a.threads {
        within("--threads", t, 1, MAX_THREADS, "")?;
    }
    within("--target-fp-per-frame", a.target_fp_per_frame, 0.0, 1000.0, "")?;
    let min_size = parse_size(&a.holdout_min_size)?;
    check_detector("holdout-", a.scale_factor, a.holdout_min_neighbors, min_size)?;
    Ok(min_size)
}

/// Expands files, folders and simple globs (`*`, `?` in the file name) to image files.
fn expand_images(specs: &[String]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for s in specs {
        let p = PathBuf::from(s);
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        if name.contains('*') || name.contains('?') {
            let dir = p
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new("."));
            let mut m: Vec<PathBuf> = std::fs::read_dir(dir)
                .with_context(|| format!("{s}: cannot list {}", dir.display()))?
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|f| f.file_name().is_some_and(|n| glob_match(&name, &n.to_string_lossy())))
                .collect();
            if m.is_empty() {
                bail!("{s}: matches no file");
            }
            m.sort();
            out.extend(m);
        } else if p.is_dir() {
            let found = rccar_train::photogen::list_photos(std::slice::from_ref(&p));
            if found.is_empty() {
                bail!("{s}: no .png/.jpg files in this folder");
            }
            out.extend(found);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

fn glob_match(pat: &str, s: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pat.chars().collect(), s.chars().collect());
    let (mut pi, mut ti, mut star, mut mark) = (0, 0, None, 0);
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ti;
            pi += 1;
        } else if let Some(sp) = star {
            pi = sp + 1;
            mark += 1;
            ti = mark;
        } else {
            return false;
        }
    }
    while pi < p.len() && p[pi] == '*' {
        pi += 1;
    }
    pi == p.len()
}

/// `distort`'s counts, angles, scales and window, each refused by flag and bound.
fn check_distort_args(a: &DistortArgs) -> anyhow::Result<()> {
    within("--count", a.count, 1, MAX_SAMPLES, "")?;
    within("--max-angle-deg", a.max_angle_deg, 0.0, 180.0, " degrees")?;
    within("--max-skew", a.max_skew, 0.0, 0.5, " (fraction of the object size)")?;
    within(
        "--min-scale",
        a.min_scale,
        1.0,
        20.0,
        " (multiple of the window: the object is at least the window)",
    )?;
    within(
        "--max-scale",
        a.max_scale,
        a.min_scale.max(1.0),
        20.0,
        " (multiple of the window, at least --min-scale)",
    )?;
    if let Some(w) = &a.window {
        check_window("--window", parse_wh(w)?)?;
    }
    Ok(())
}

/// Every box of these info.dat files cut out of its photo as a template (at most
/// [`MAX_TEMPLATES`] in all); boxes outside their photo and unreadable photos are skipped, named.
fn templates_from_info(
    files: &[PathBuf],
    templates: &mut Vec<image::RgbaImage>,
) -> anyhow::Result<Vec<samples::InfoLine>> {
    let mut info_lines = Vec::new();
    for f in files {
        let (lines, skipped) = samples::read_info(f)?;
        for s in &skipped {
            eprintln!("{s}");
        }
        for l in &lines {
            let img = match samples::checked_dimensions(&l.path)
                .map_err(|e| e.to_string())
                .and_then(|_| image::open(&l.path).map_err(|e| e.to_string()))
            {
                Ok(i) => i.to_rgba8(),
                Err(e) => {
                    eprintln!("{}:{}: skipped: {}: {e}", f.display(), l.line, l.path.display());
                    continue;
                }
            };
            for b in &l.boxes {
                if b.x < 0
                    || b.y < 0
                    || b.width <= 0
                    || b.height <= 0
                    || (b.x as i64 + b.width as i64) > img.width() as i64
                    || (b.y as i64 + b.height as i64) > img.height() as i64
                {
                    eprintln!(
                        "{}:{}: skipped: box {:?} is outside {}",
                        f.display(),
                        l.line,
                        b,
                        l.path.display()
                    );
                    continue;
                }
                if templates.len() >= MAX_TEMPLATES {
                    bail!("{}:{}: more than {MAX_TEMPLATES} templates", f.display(), l.line);
                }
                templates.push(
                    image::imageops::crop_imm(&img, b.x as u32, b.y as u32, b.width as u32, b.height as u32).to_image(),
                );
            }
        }
        info_lines.extend(lines);
    }
    Ok(info_lines)
}

fn run_distort(a: DistortArgs) -> anyhow::Result<ExitCode> {
    check_distort_args(&a)?;
    let mut templates = Vec::new();
    let files = expand_images(&a.templates)?;
    if files.len() > MAX_TEMPLATES {
        bail!("{} templates: at most {MAX_TEMPLATES}", files.len());
    }
    for t in files {
        if let Err(e) = samples::checked_dimensions(&t) {
            bail!("{e}");
        }
        templates.push(
            image::open(&t)
                .with_context(|| format!("{}: cannot read template", t.display()))?
                .to_rgba8(),
        );
    }
    let info_lines = templates_from_info(&a.templates_from_info, &mut templates)?;
    if templates.is_empty() {
        bail!("no templates: give --template FILE|FOLDER|GLOB or --templates-from-info info.dat");
    }
    // From the boxes of --templates-from-info; without boxes (crops given with --template)
    // the crops' aspect at 20 px, said so.
    let crop_sizes: Vec<(u32, u32)> = templates.iter().map(|t| t.dimensions()).collect();
    let window = match &a.window {
        Some(w) => parse_wh(w)?,
        None => match rccar_train::plan::choose_window(&info_lines)
            .or_else(|| rccar_train::plan::window_for_crops(&crop_sizes))
        {
            Some(c) => {
                eprintln!("{}", c.why);
                c.size
            }
            None => (20, 20),
        },
    };
    let (bgs, skipped) = samples::load_backgrounds(&a.bg)?;
    for s in &skipped {
        eprintln!("{s}");
    }
    if bgs.is_empty() {
        bail!("no readable background image in {:?}", a.bg);
    }
    if !(a.max_blur >= 0.0 && a.max_blur <= 10.0) {
        bail!("--max-blur {}: expected 0-10 pixels", a.max_blur);
    }
    if !(a.max_noise >= 0.0 && a.max_noise <= 64.0) {
        bail!("--max-noise {}: expected 0-64 grey levels", a.max_noise);
    }
    if !(a.max_gamma >= 1.0 && a.max_gamma <= 4.0) {
        bail!("--max-gamma {}: expected 1-4", a.max_gamma);
    }
    if !(1..=100).contains(&a.min_jpeg_quality) {
        bail!("--min-jpeg-quality {}: expected 1-100", a.min_jpeg_quality);
    }
    let o = rccar_train::distort::DistortOptions {
        count: a.count,
        seed: a.seed,
        window,
        max_angle: a.max_angle_deg.to_radians(),
        max_skew: a.max_skew,
        scale: (a.min_scale, a.max_scale),
        max_blur: a.max_blur,
        max_noise: a.max_noise,
        max_gamma: a.max_gamma,
        min_jpeg_quality: a.min_jpeg_quality,
        ..Default::default()
    };
    let imgs: Vec<image::GrayImage> = bgs.into_iter().map(|b| b.img).collect();
    let list = rccar_train::distort::generate(&templates, &imgs, &o, &a.out).map_err(anyhow::Error::msg)?;
    println!(
        "{}: {} samples from {} templates over {} backgrounds, window {}x{}",
        list.display(),
        a.count,
        templates.len(),
        imgs.len(),
        window.0,
        window.1
    );
    println!(
        "next: rccar-train train --pos {} --bg <backgrounds> --out <dir>   (-W {} -H {} and --num-pos {} are taken from it)",
        list.display(),
        window.0,
        window.1,
        rccar_train::plan::max_num_pos(a.count, 20, rccar_train::plan::DEFAULT_MIN_HIT_RATE)
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct BoxesArgs {
    /// The boxes: one per line `file,x,y,w,h` (pixels, top-left corner; paths relative to the
    /// CSV); `file` alone marks a frame without the object.
    #[arg(long)]
    csv: PathBuf,
    /// info.dat to write (frames with boxes).
    #[arg(long)]
    out: PathBuf,
    /// bg.txt to write for the frames without the object (default: bg.txt beside --out, when
    /// there are such lines).
    #[arg(long)]
    bg_out: Option<PathBuf>,
    /// Folder for previews: every labelled image with its boxes drawn, and crops.png.
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Also write every box cut out as its own PNG into this folder (a folder of crops, as
    /// `distort --template DIR` takes).
    #[arg(long)]
    crops: Option<PathBuf>,
}

fn run_boxes(a: BoxesArgs) -> anyhow::Result<ExitCode> {
    let labels = match rccar_train::annotate::read_csv(&a.csv) {
        Ok(l) => l,
        Err(errors) => {
            for e in &errors {
                eprintln!("{e}");
            }
            bail!("{}: {} bad lines, nothing written", a.csv.display(), errors.len());
        }
    };
    let has_empty = labels.images.iter().any(|(_, b)| b.is_empty());
    let bg = a
        .bg_out
        .clone()
        .or_else(|| has_empty.then(|| a.out.with_file_name("bg.txt")));
    let (imgs, boxes, empty) = rccar_train::annotate::write_lists(&labels, &a.out, bg.as_deref())
        .with_context(|| a.out.display().to_string())?;
    println!("{}: {boxes} boxes in {imgs} images", a.out.display());
    if let Some(bg) = &bg {
        println!("{}: {empty} frames without the object", bg.display());
    }
    if let Some(dir) = &a.preview {
        let files = rccar_train::annotate::previews(&labels, dir, 64).map_err(anyhow::Error::msg)?;
        println!(
            "{}: {} preview pictures (crops.png shows every box)",
            dir.display(),
            files.len()
        );
    }
    if let Some(dir) = &a.crops {
        let n = rccar_train::annotate::write_crops(&labels, dir).map_err(anyhow::Error::msg)?;
        println!("{}: {n} crops, one PNG per box", dir.display());
    }
    println!(
        "next: rccar-train distort --templates-from-info {} --bg <pictures to paste on> --out <dir>   (docs/training.md, step 3)",
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct PhotosetArgs {
    /// Photo folders or files (.jpg/.png). Default: OpenCV's sample pictures
    /// (/usr/share/doc/opencv-doc/examples/data, Debian's opencv-doc), the same on every
    /// machine with that package.
    #[arg(long = "photos", num_args = 1..)]
    photos: Vec<PathBuf>,
    /// Which photos of the sorted list: `0` or `1` (every other photo: train on one half, test
    /// on the other), `0-train` / `0-val` (half 0 split 4:1, so validation frames come from
    /// photos the training never saw), or `all`.
    #[arg(long, default_value = "all")]
    half: String,
    /// Frames with a stop sign.
    #[arg(long, default_value_t = 48)]
    with_sign: usize,
    /// Frames without.
    #[arg(long, default_value_t = 350)]
    without: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Smallest and largest sign face, pixels (MINxMAX).
    #[arg(long, default_value = "16x64")]
    sign_px: String,
    /// Track file whose scene paints the sign.
    #[arg(long, default_value = "config/tracks/default.toml")]
    track: PathBuf,
    /// Signs that look printed rather than rendered: a light frame round the face, colours
    /// jittered and washed towards white, posts of any grey and width
    /// (training/realsets/photolike.sh's stop-sign candidates). Stop signs only: refused with
    /// `--traffic-light`.
    #[arg(long, conflicts_with = "traffic_light")]
    printed: bool,
    /// Traffic lights instead of stop signs: the simulator's three-lamp housing or a toy's
    /// one-lamp block, of varied width, grey and lamp size (`--sign-px` is then the housing's
    /// height).
    #[arg(long)]
    traffic_light: bool,
    /// Output folder (frames/, info.dat, bg.txt, boxes.csv).
    #[arg(long)]
    out: PathBuf,
}

fn run_photoset(a: PhotosetArgs) -> anyhow::Result<ExitCode> {
    use rccar_train::photogen;
    within("--with-sign", a.with_sign, 0, MAX_PHOTOSET_FRAMES, "")?;
    within("--without", a.without, 0, MAX_PHOTOSET_FRAMES, "")?;
    let (lo, hi) = parse_wh(&a.sign_px)?;
    if !(4..=1024).contains(&lo) || !(lo..=1024).contains(&hi) {
        bail!("--sign-px {lo}x{hi}: each must be 4..=1024 px, MIN <= MAX");
    }
    let dirs = if a.photos.is_empty() {
        photogen::system_photo_dirs()
    } else {
        a.photos.clone()
    };
    let all = photogen::list_photos(&dirs);
    let Some(photos) = photogen::part(&all, &a.half) else {
        bail!("--half `{}`: expected 0, 1, 0-train, 0-val or all", a.half)
    };
    if photos.is_empty() {
        bail!("no .jpg/.png photos in {dirs:?} (install Debian's opencv-doc, or give --photos DIR)");
    }

    let track = if a.track.exists() {
        a.track.clone()
    } else {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(&a.track)
    };
    let t = photogen::stop_sign_template(&track, 96).map_err(anyhow::Error::msg)?;
    let o = photogen::PhotoSetOptions {
        with_sign: a.with_sign,
        without: a.without,
        seed: a.seed,
        sign_px: (lo as f64, hi as f64),
        printed: a.printed,
        traffic_light: a.traffic_light,
    };
    let set = photogen::generate(&photos, &t, &o, &a.out).map_err(anyhow::Error::msg)?;
    println!(
        "{}: {} frames with a sign; {}: {} without; {} (the same as a boxes CSV); from {} photos",
        set.info.display(),
        a.with_sign,
        set.bg.display(),
        a.without,
        set.csv.display(),
        photos.len()
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct EvalArgs {
    /// Cascade XML.
    #[arg(long)]
    cascade: PathBuf,
    /// Labelled frames: info.dat files (boxes), bg.txt files or folders (frames without the
    /// object, where every detection is a false positive); several may follow, and each gets a
    /// line of its own in the output.
    #[arg(long, required = true, num_args = 1..)]
    info: Vec<PathBuf>,
    /// Output folder for report.json and curve.png (default: next to the cascade).
    #[arg(long)]
    out: Option<PathBuf>,
    /// minNeighbors whose numbers are printed as the operating point.
    #[arg(long, default_value_t = 3)]
    min_neighbors: u32,
    /// Scale factor (as `[detect] scale_factor`).
    #[arg(long, default_value_t = 1.1)]
    scale_factor: f64,
    /// Smallest search window, pixels: N (square) or WxH; 0 = the cascade's own size (as
    /// `[detect] min_size_px`, so the numbers match `rccar detect`).
    #[arg(long, default_value = "0")]
    min_size: String,
    /// IoU for a match.
    #[arg(long, default_value_t = 0.5)]
    iou: f64,
    /// The false positives per frame without the object the car can live with: the printed
    /// choice is the smallest minNeighbors that stays within it on these frames (the held-out
    /// track recording), to set as `classes.<name>.min_neighbors`.
    #[arg(long, default_value_t = 0.01)]
    target_fp_per_frame: f64,
    /// Title of the curve.
    #[arg(long)]
    title: Option<String>,
}

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

fn run_evaluate(a: EvalArgs) -> anyhow::Result<ExitCode> {
    let min_size = parse_size(&a.min_size)?;
    check_detector("", a.scale_factor, a.min_neighbors, min_size)?;
    within("--iou", a.iou, 0.01, 1.0, "")?;
    within("--target-fp-per-frame", a.target_fp_per_frame, 0.0, 1000.0, "")?;
    let cascade = rccar::detect::Cascade::from_file(&a.cascade)?;
    // Frames list by list, so each list's figures can be named (a track recording's false
    // positives are the estimate for the car's own frames).
    let mut frames = Vec::new();
    let mut lists = Vec::new();
    for f in &a.info {
        let start = frames.len();
        frames.extend(load_frames(std::slice::from_ref(f))?);
        lists.push((f.display().to_string(), start..frames.len()));
    }
    let info_name = a
        .info
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" + ");
    if frames.is_empty() {
        bail!("{info_name}: no readable frames");
    }
    let mns: Vec<u32> = (0..=10).collect();
    let mut rep = evaluate::evaluate(
        cascade,
        &a.cascade.display().to_string(),
        &frames,
        a.scale_factor,
        min_size,
        a.iou,
        &mns,
        a.min_neighbors,
    )?;
    rep.choose(a.target_fp_per_frame);
    let out = a
        .out
        .unwrap_or_else(|| a.cascade.parent().map(|p| p.to_path_buf()).unwrap_or_default());
    std::fs::create_dir_all(&out).with_context(|| out.display().to_string())?;
    let json = out.join("report.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rep)?).with_context(|| json.display().to_string())?;
    if let Ok(bytes) = std::fs::read(FONT) {
        rccar::sim::plot::register_font(Box::leak(bytes.into_boxed_slice()));
        let title = a
            .title
            .clone()
            .unwrap_or_else(|| format!("{} on {}", a.cascade.display(), info_name));
        let img = evaluate::curve_png(&rep, &title).map_err(anyhow::Error::msg)?;
        let png = out.join("curve.png");
        img.save(&png).with_context(|| png.display().to_string())?;
    } else {
        eprintln!("{FONT} not found (Debian fonts-dejavu-core): no curve.png");
    }
    println!(
        "{} frames: {} with the object ({} boxes), {} without; IoU >= {}, scale factor {}, min size {}x{}",
        rep.frames,
        rep.sign_frames,
        rep.boxes,
        rep.negative_frames,
        rep.iou,
        rep.scale_factor,
        rep.min_size.0,
        rep.min_size.1
    );
    // FP/neg: per frame without the object; FP/sign: beside the object on its frames; FP/all:
    // over every frame (the held-out early stop's figure).
    let per = |v: Option<f64>| v.map_or("       -".to_string(), |v| format!("{v:>8.4}"));
    println!("minNeighbors  recall  precision    FP/neg   FP/sign    FP/all   TP   FP  miss");
    for p in &rep.points {
        println!(
            "{:>12}  {}  {:>9.4}  {}  {}  {:>8.4}  {:>3}  {:>3}  {:>4}{}",
            p.min_neighbors,
            // no labelled box: no recall to give
            if rep.boxes > 0 { format!("{:.4}", p.recall) } else { "     -".to_string() },
            p.precision,
            per(p.fp_per_negative_frame),
            per(p.fp_per_sign_frame),
            p.fp_per_frame,
            p.true_positives,
            p.false_positives,
            p.misses,
            if p.min_neighbors == a.min_neighbors { "  <-" } else { "" }
        );
    }
    println!(
        "FP/neg: false positives per frame without the object; FP/sign: per frame with it (boxes beside it); \
         FP/all: over all {} frames",
        rep.frames
    );
    print_choice(&rep);
    // (frames_detail is kept at the printed minNeighbors, one of 0-10)
    if lists.len() > 1 && rep.frames_detail.len() == frames.len() {
        println!("at minNeighbors {}, list by list:", a.min_neighbors);
        for (name, range) in &lists {
            let part = &rep.frames_detail[range.clone()];
            let with = frames[range.clone()].iter().filter(|f| !f.2.is_empty()).count();
            let boxes: usize = frames[range.clone()].iter().map(|f| f.2.len()).sum();
            let (found, fp): (usize, usize) = part.iter().fold((0, 0), |(t, f), d| (t + d.1, f + d.2));
            let n = range.len();
            if with == 0 {
                println!(
                    "  {name}: {n} frames without the object, {fp} false positives = {:.4} per frame",
                    fp as f64 / n.max(1) as f64
                );
            } else {
                println!(
                    "  {name}: {n} frames, {with} with the object: recall {:.4} ({found}/{boxes}), {fp} false positives = {:.4} per frame",
                    found as f64 / boxes.max(1) as f64,
                    fp as f64 / n.max(1) as f64
                );
            }
        }
    }
    println!(
        "time per {}x{} frame: median {:.2} ms, mean {:.2} ms, max {:.2} ms",
        rep.frame_size.0, rep.frame_size.1, rep.ms_median, rep.ms_mean, rep.ms_max
    );
    println!("wrote {} and curve.png", json.display());
    Ok(ExitCode::SUCCESS)
}

/// The `choose:` line of `evaluate`: the minNeighbors [`evaluate::Report::choose`] chose for
/// the car and what it costs, or why there is none.
fn print_choice(rep: &evaluate::Report) {
    let target = rep.target_fp_per_frame.unwrap_or(0.0);
    let chosen = rep
        .chosen_min_neighbors
        .and_then(|m| rep.points.iter().find(|p| p.min_neighbors == m));
    match chosen {
        Some(p) => {
            let recall = if rep.boxes > 0 {
                format!(", recall {:.4} ({}/{})", p.recall, p.true_positives, rep.boxes)
            } else {
                String::new()
            };
            println!(
                "choose: minNeighbors {} — the smallest whose false positives per frame without the object \
                 ({:.4} on {} frames) are at most {target} (--target-fp-per-frame){recall}; \
                 set classes.<name>.min_neighbors = {} for this cascade",
                p.min_neighbors,
                p.fp_per_negative_frame.unwrap_or(0.0),
                rep.negative_frames,
                p.min_neighbors
            );
        }
        None if rep.negative_frames == 0 => println!(
            "choose: nothing to choose on: no frames without the object (give the held-out track \
             recording, e.g. track-b)"
        ),
        None => println!(
            "choose: no minNeighbors up to {} keeps the false positives at most {target} per frame \
             without the object: add backgrounds like the frames with false positives (docs/training.md, step 6)",
            rep.points.last().map_or(0, |p| p.min_neighbors)
        ),
    }
}

#[derive(clap::Args)]
struct GenArgs {
    /// stop_sign | traffic_light | obstacle | yield_sign | turn_sign.
    #[arg(long)]
    kind: String,
    /// What to make.
    #[arg(long, value_enum)]
    split: simgen::Split,
    /// Samples (positives) or frames.
    #[arg(long, default_value_t = 1000)]
    count: usize,
    /// Seed (use different seeds for training and held-out data).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Track file the objects are placed on.
    #[arg(long, default_value = "config/tracks/default.toml")]
    track: PathBuf,
    /// Window WxH (default per kind: stop 16x16, light 8x20, obstacle 20x16, yield 18x16, turn 16x16).
    #[arg(long)]
    window: Option<String>,
    /// Object placements to spread the frames over.
    #[arg(long, default_value_t = 20)]
    scenes: usize,
    /// Nearest object distance, metres.
    #[arg(long, default_value_t = 0.2)]
    min_distance: f64,
    /// Farthest object distance, metres.
    #[arg(long, default_value_t = 1.5)]
    max_distance: f64,
    /// Peak relative change of the lighting, 0..=0.9 (as `[sim] light_variation`), at a
    /// random phase per frame, on top of the random exposure (0 = off).
    #[arg(long, default_value_t = 0.0)]
    light_variation: f64,
    /// Shadows, sun patches and dusk (`[sim] light_level`, docs/light.md): each frame takes
    /// a level from 0 to this at random (0 = none, 3 = the strongest).
    #[arg(long, default_value_t = 0)]
    light_level: u32,
}

fn parse_wh(s: &str) -> anyhow::Result<(u32, u32)> {
    let (a, b) = s.split_once('x').with_context(|| format!("`{s}`: expected WxH"))?;
    Ok((
        a.trim().parse().with_context(|| format!("`{s}`: expected WxH"))?,
        b.trim().parse().with_context(|| format!("`{s}`: expected WxH"))?,
    ))
}

/// `N` (square) or `WxH`.
fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    if s.contains('x') {
        parse_wh(s)
    } else {
        let n: u32 = s
            .trim()
            .parse()
            .with_context(|| format!("`{s}`: expected N or WxH pixels"))?;
        Ok((n, n))
    }
}

fn run_gen(a: GenArgs) -> anyhow::Result<ExitCode> {
    let kind = simgen::parse_kind(&a.kind)
        .with_context(|| format!("--kind `{}`: expected stop_sign, traffic_light or obstacle", a.kind))?;
    let window = match &a.window {
        Some(s) => parse_wh(s)?,
        None => simgen::default_window(kind),
    };
    let g = simgen::SimGen::new(&a.track, rccar::config::Config::default())?;
    let opts = simgen::GenOptions {
        kind,
        split: a.split,
        count: a.count,
        seed: a.seed,
        distance_m: (a.min_distance, a.max_distance),
        window,
        scenes: a.scenes,
        light_variation: a.light_variation,
        light_level: a.light_level,
    };
    let t = std::time::Instant::now();
    let bar = indicatif::ProgressBar::new(a.count as u64);
    let list = g.generate(&opts, &a.out, &mut |n| bar.set_position(n as u64))?;
    bar.finish_and_clear();
    println!(
        "{}: {} items in {:.1} s",
        list.display(),
        a.count,
        t.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct TrainArgs {
    /// Output folder (cascade.xml, stages.json).
    #[arg(long)]
    out: PathBuf,
    /// Positives: info.dat files (`path count x y w h ...`); repeat for several.
    #[arg(long = "pos", required = true, num_args = 1..)]
    pos: Vec<PathBuf>,
    /// Backgrounds: bg.txt / info.dat files (boxes on a line are kept out of the negatives), or
    /// folders (every .png/.jpg in them and their subfolders, e.g. a recording of the track).
    #[arg(long = "bg", required = true, num_args = 1..)]
    bg: Vec<PathBuf>,
    /// Window width, pixels. Default: the window `distort` wrote into the info.dat, else chosen
    /// from the boxes (median aspect; the 5th-percentile size, 12-24 px).
    #[arg(short = 'W', long)]
    width: Option<i32>,
    /// Window height, pixels (default: as -W).
    #[arg(short = 'H', long)]
    height: Option<i32>,
    /// Stages at most.
    #[arg(long, default_value_t = 20)]
    num_stages: u32,
    /// Positives per stage. Default: as many as exist, less what the stages will drop
    /// (available / (1 + (stages-1)(1-min-hit-rate))); a larger number is reduced, with a note.
    #[arg(long)]
    num_pos: Option<usize>,
    /// Negatives per stage (windows the cascade so far wrongly accepts).
    #[arg(long, default_value_t = rccar_train::plan::DEFAULT_NUM_NEG)]
    num_neg: usize,
    /// Per-stage hit rate (0.998; OpenCV's 0.995 lost 19% of the unseen signs over 20 stages on the
    /// photo-like check, docs/training.md).
    #[arg(long, default_value_t = rccar_train::plan::DEFAULT_MIN_HIT_RATE)]
    min_hit_rate: f64,
    /// Per-stage false-alarm rate.
    #[arg(long, default_value_t = 0.5)]
    max_false_alarm: f64,
    /// Haar feature set.
    #[arg(long, value_enum, default_value_t = HaarMode::Basic)]
    mode: HaarMode,
    /// Boosting.
    #[arg(long, value_enum, default_value_t = BoostType::Gentle)]
    boost: BoostType,
    /// Weak tree depth (1 = stumps, 2).
    #[arg(long, default_value_t = 1)]
    max_depth: u32,
    /// Most weak classifiers per stage.
    #[arg(long, default_value_t = 100)]
    max_weak_count: u32,
    /// Memory for the whole run, MiB: backgrounds, held-out frames, samples and 32 MiB for the
    /// program first; the precomputed feature values get the rest (features that do not fit
    /// are sampled).
    #[arg(long, default_value_t = 512)]
    mem_mb: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scale step of the negative pool's pyramid (the detector's scaleFactor).
    #[arg(long, default_value_t = 1.1)]
    scale_factor: f64,
    /// Also draw negatives from mirror images of the backgrounds (twice as many windows).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    mirror_negatives: bool,
    /// Also draw negatives from the backgrounds turned upside down (and their mirror images):
    /// twice as many windows again, so a few hundred backgrounds last 20 stages. Off by
    /// default: on the photo-like check's validation photos it left more false positives after
    /// 20 stages (docs/training.md).
    #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
    upside_down_negatives: bool,
    /// Held-out frames (info.dat with boxes; bg.txt or a folder without), never trained on: after
    /// every stage the cascade is run over them and training stops once the false positives
    /// per frame reach --target-fp-per-frame.
    #[arg(long = "holdout", num_args = 1..)]
    holdout: Vec<PathBuf>,
    /// Early-stop target: false positives per held-out frame.
    #[arg(long, default_value_t = 0.01)]
    target_fp_per_frame: f64,
    /// minNeighbors of the held-out check (as `[detect] min_neighbors`).
    #[arg(long, default_value_t = 3)]
    holdout_min_neighbors: u32,
    /// Smallest window of the held-out check, N or WxH pixels (as `[detect] min_size_px`).
    #[arg(long, default_value = "0")]
    holdout_min_size: String,
    /// Continue from the last finished stage in --out.
    #[arg(long)]
    resume: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

/// Progress on stderr: on a terminal a bar per stage; otherwise (a log file, a pipe) plain
/// lines only. One line per finished stage either way.
struct Bars {
    bar: Option<indicatif::ProgressBar>,
    tty: bool,
}

impl Progress for Bars {
    fn stage_start(&mut self, stage: usize, max_weak: usize) {
        if !self.tty {
            return;
        }
        let b = indicatif::ProgressBar::new(max_weak as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template("stage {prefix:>2} [{bar:30}] {pos:>3} weak  {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_prefix(stage.to_string());
        self.bar = Some(b);
    }
    fn weak(&mut self, count: usize, hit: f64, fa: f64) {
        if let Some(b) = &self.bar {
            b.set_position(count as u64);
            b.set_message(format!("hit {hit:.4}  false alarm {fa:.4}"));
        }
    }
    fn stage_end(&mut self, l: &StageLog) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        let neg = l
            .holdout_fp_per_negative_frame
            .map(|v| format!(" ({v:.4} per frame without the object)"))
            .unwrap_or_default();
        let ho = match (l.holdout_recall, l.holdout_fp_per_frame) {
            (Some(r), Some(f)) => format!(", held-out recall {r:.3} FP/frame {f:.4}{neg}"),
            (None, Some(f)) => format!(", held-out FP/frame {f:.4}{neg}"),
            _ => String::new(),
        };
        eprintln!(
            "stage {:>2}: {:>3} weak, hit {:.4}, false alarm {:.4}, pos {}, neg {}{} (acceptance {:.2e}){}, {:.1}+{:.1}+{:.1} = {:.1} s",
            l.stage,
            l.weak_count,
            l.hit_rate,
            l.false_alarm,
            l.num_pos,
            l.num_neg,
            if l.negatives_exhausted { " (all the backgrounds hold)" } else { "" },
            l.acceptance_ratio,
            ho,
            l.seconds_mining,
            l.seconds_precompute,
            l.seconds_boost,
            l.seconds
        );
    }
    fn note(&mut self, msg: &str) {
        if let Some(b) = &self.bar {
            b.suspend(|| eprintln!("{msg}"));
        } else {
            eprintln!("{msg}");
        }
    }
}

fn load_frames(files: &[PathBuf]) -> anyhow::Result<Vec<(String, image::GrayImage, Vec<rccar::detect::Rect>)>> {
    let mut frames = Vec::new();
    for f in files {
        let (lines, skipped) = samples::read_info(f)?;
        for s in &skipped {
            eprintln!("{s}");
        }
        for l in lines {
            match samples::load_gray(&l.path) {
                Ok(img) => frames.push((l.path.display().to_string(), img, l.boxes)),
                Err(e) => eprintln!("{}:{}: skipped: {e}", f.display(), l.line),
            }
        }
    }
    Ok(frames)
}

/// The training window and why: `-W/-H`, the window `distort` wrote into the --pos files, or
/// one chosen from their boxes; each side 3..=256 px.
fn train_window(a: &TrainArgs) -> anyhow::Result<(i32, i32, String)> {
    use rccar_train::plan;
    let mut lines = Vec::new();
    let mut hint = None;
    for f in &a.pos {
        let text = samples::read_list_text(f)?;
        hint = hint.or(plan::window_hint(&text));
        lines.extend(samples::parse_info(&text, f).0);
    }
    let (width, height, why) = match (a.width, a.height) {
        (Some(w), Some(h)) => (w, h, "given".to_string()),
        (Some(w), None) => (w, w, "given (-H = -W)".to_string()),
        (None, Some(h)) => (h, h, "given (-W = -H)".to_string()),
        (None, None) => match hint {
            Some((w, h)) => (
                w as i32,
                h as i32,
                "the window distort made the positives for".to_string(),
            ),
            None => {
                let c = plan::choose_window(&lines).context("no boxes in the --pos files")?;
                (c.size.0 as i32, c.size.1 as i32, c.why)
            }
        },
    };
    if !(3..=256).contains(&width) || !(3..=256).contains(&height) {
        bail!("-W/-H window {width}x{height} ({why}): each side must be 3..=256 px");
    }
    Ok((width, height, why))
}

/// The held-out frames of `--holdout` and the detector settings they are checked with
/// (`None` without `--holdout`); an error when none of the frames can be read.
fn load_holdout(a: &TrainArgs, min_size: (u32, u32)) -> anyhow::Result<Option<train::Holdout>> {
    if a.holdout.is_empty() {
        return Ok(None);
    }
    let frames = load_frames(&a.holdout)?;
    if frames.is_empty() {
        bail!("no readable held-out frame in {:?}", a.holdout);
    }
    eprintln!(
        "{} held-out frames ({} boxes): training stops at {} false positives per frame",
        frames.len(),
        frames.iter().map(|f| f.2.len()).sum::<usize>(),
        a.target_fp_per_frame
    );
    Ok(Some(train::Holdout {
        frames,
        min_neighbors: a.holdout_min_neighbors,
        min_size,
        scale_factor: a.scale_factor,
        iou: 0.5,
        target_fp_per_frame: a.target_fp_per_frame,
    }))
}

/// What `train` prints at the end besides the outcome.
struct Summary<'a> {
    window: (i32, i32, &'a str),
    num_pos: usize,
    usable: usize,
    /// Positives the stages trained on (fewest, most), from stages.json.
    stage_pos: Option<(usize, usize)>,
    /// What the held-out negatives share with training's backgrounds, when they do.
    holdout_source: Option<String>,
    backgrounds: usize,
    seconds: f64,
    note: Option<String>,
}

/// Whether the held-out frames without the object come from where training's backgrounds
/// come from (the same files, or the same folders), said as a note: then their false
/// positives say how the cascade does on those places, not on a room or track it never saw.
fn same_source(
    bgs: &[samples::Background],
    holdout: &[(String, image::GrayImage, Vec<rccar::detect::Rect>)],
) -> Option<String> {
    use std::collections::BTreeSet;
    let canon = |s: &str| std::fs::canonicalize(s).unwrap_or_else(|_| PathBuf::from(s));
    let files: BTreeSet<PathBuf> = bgs.iter().map(|b| canon(&b.name)).collect();
    let dirs: BTreeSet<PathBuf> = files.iter().filter_map(|f| f.parent().map(|d| d.to_path_buf())).collect();
    let negs: Vec<PathBuf> = holdout.iter().filter(|f| f.2.is_empty()).map(|f| canon(&f.0)).collect();
    let same_file = negs.iter().filter(|f| files.contains(*f)).count();
    let shared: BTreeSet<&std::path::Path> = negs
        .iter()
        .filter_map(|f| f.parent())
        .filter(|d| dirs.contains(*d))
        .collect();
    let same_dir = negs
        .iter()
        .filter(|f| f.parent().is_some_and(|d| dirs.contains(d)))
        .count();
    if same_file > 0 {
        Some(format!(
            "{same_file} of the {} held-out frames without the object are also training backgrounds: they are not held \
             out, and their false positives say nothing about new frames",
            negs.len()
        ))
    } else if same_dir > 0 {
        let names: Vec<String> = shared.iter().take(3).map(|d| d.display().to_string()).collect();
        Some(format!(
            "{same_dir} of the {} held-out frames without the object come from the folders training's backgrounds come \
             from ({}{}): their false positives are for those places and that session; on a room or track training \
             never saw expect more (hold out another recording of the track, docs/training.md step 1)",
            negs.len(),
            names.join(", "),
            if shared.len() > 3 { ", ..." } else { "" }
        ))
    } else {
        None
    }
}

/// The fewest and most positives a stage of `out/stages.json` trained on.
fn stage_positives_used(out: &std::path::Path) -> Option<(usize, usize)> {
    let text = std::fs::read_to_string(out.join("stages.json")).ok()?;
    let file: train::StageFile = serde_json::from_str(&text).ok()?;
    let lo = file.log.iter().map(|l| l.num_pos).min()?;
    let hi = file.log.iter().map(|l| l.num_pos).max()?;
    Some((lo, hi))
}

/// The summary of a finished training, on stdout.
fn print_summary(a: &TrainArgs, out: &train::TrainOutcome, s: &Summary) {
    let (width, height, why) = s.window;
    println!("cascade      {}", out.xml.display());
    println!("stages       {} ({})", out.stages, out.reason);
    println!("window       {width}x{height} ({why})");
    match s.stage_pos {
        Some((lo, hi)) if lo != hi => println!(
            "positives    {} per stage asked, {lo}-{hi} used (a stage takes those the cascade so far accepts), of {} usable",
            s.num_pos, s.usable
        ),
        Some((lo, _)) => println!("positives    {lo} per stage used ({} asked) of {} usable", s.num_pos, s.usable),
        None => println!("positives    {} per stage asked of {} usable", s.num_pos, s.usable),
    }
    println!(
        "negatives    {} per stage from {} backgrounds",
        a.num_neg, s.backgrounds
    );
    if let Some(c) = &out.holdout {
        let (neg, sign) = c.frames;
        let split = |v: Option<f64>, n: usize, what: &str| v.map(|v| format!("; {v:.4} per frame {what} ({n})"));
        println!(
            "held-out     {:.4} false positives per frame over all {} frames (target {}){}{}{} at minNeighbors {}",
            c.fp_per_frame,
            neg + sign,
            a.target_fp_per_frame,
            split(c.fp_per_negative_frame, neg, "without the object").unwrap_or_default(),
            split(c.fp_per_sign_frame, sign, "with it").unwrap_or_default(),
            c.recall.map(|r| format!(", recall {r:.4}")).unwrap_or_default(),
            a.holdout_min_neighbors
        );
    }
    if let Some(n) = &s.holdout_source {
        println!("held-out     {n}");
    }
    println!("time         {:.1} s", s.seconds);
    if let Some(n) = &s.note {
        println!("note         {n}");
    }
}

fn run_train(a: TrainArgs) -> anyhow::Result<ExitCode> {
    use rccar_train::plan;
    use std::io::IsTerminal;
    let holdout_min_size = check_train_args(&a)?;
    if let Some(d) = a.pos.iter().find(|p| p.is_dir()) {
        bail!(
            "--pos {}: a folder; positives are info.dat files with boxes. A folder of cut-out signs (crops) \
             becomes samples with `rccar-train distort --template {} --bg <pictures> --out <dir>` \
             (docs/training.md, step 3); train on its info.dat",
            d.display(),
            d.display()
        );
    }
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().ok();
    }
    let t = std::time::Instant::now();
    // 1. The window: given, written by distort, or chosen from the boxes.
    let (width, height, why) = train_window(&a)?;
    eprintln!("window {width}x{height}: {why}");
    let (w, h) = (width as usize, height as usize);
    // 2. Positives and backgrounds.
    let (pos, skipped) = samples::load_positives(&a.pos, w, h)?;
    for s in skipped.iter().take(20) {
        eprintln!("{s}");
    }
    if skipped.len() > 20 {
        eprintln!("... {} more skipped lines/boxes", skipped.len() - 20);
    }
    // Usable: loaded and not too flat for the detector (training leaves those out), so the
    // per-stage count below and the summary agree with the stage log.
    let usable = train::usable_positives(&pos, w, h);
    eprintln!(
        "{} positives loaded ({} lines/boxes skipped), {usable} usable ({} too flat for the detector)",
        pos.len(),
        skipped.len(),
        pos.len() - usable
    );
    if usable == 0 {
        bail!("no usable positive in {:?}", a.pos);
    }
    let (num_pos, note) = plan::choose_num_pos(a.num_pos, usable, a.num_stages, a.min_hit_rate);
    if let Some(n) = &note {
        eprintln!("note: {n}");
    }
    let (bgs, bskipped) = samples::load_backgrounds(&a.bg)?;
    for s in &bskipped {
        eprintln!("{s}");
    }
    eprintln!("{} background images", bgs.len());
    let holdout = load_holdout(&a, holdout_min_size)?;
    let holdout_source = holdout.as_ref().and_then(|h| same_source(&bgs, &h.frames));
    if let Some(n) = &holdout_source {
        eprintln!("note: {n}");
    }
    let opts = TrainOptions {
        params: ModelParams {
            width,
            height,
            mode: a.mode,
            boost: a.boost,
            min_hit_rate: a.min_hit_rate,
            max_false_alarm: a.max_false_alarm,
            max_depth: a.max_depth,
            max_weak_count: a.max_weak_count,
            num_stages: a.num_stages,
        },
        num_pos,
        num_neg: a.num_neg,
        mem_mb: a.mem_mb,
        seed: a.seed,
        scale_factor: a.scale_factor,
        mirror_negatives: a.mirror_negatives,
        upside_down_negatives: a.upside_down_negatives,
    };
    let mut bars = Bars {
        bar: None,
        tty: std::io::stderr().is_terminal(),
    };
    let out = train::train_with_holdout(&opts, &pos, &bgs, holdout.as_ref(), &a.out, a.resume, &mut bars)
        .with_context(|| format!("training into {}", a.out.display()))?;
    // 3. The summary, on stdout.
    let summary = Summary {
        window: (width, height, &why),
        num_pos,
        usable,
        stage_pos: stage_positives_used(&a.out),
        holdout_source,
        backgrounds: bgs.len(),
        seconds: t.elapsed().as_secs_f64(),
        note,
    };
    print_summary(&a, &out, &summary);
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args)]
struct PilotArgs {
    /// The weights file to write (safetensors; `steering.model` reads it). loss.png and
    /// loss.csv go beside it, named after it.
    #[arg(long)]
    out: PathBuf,
    /// Simulator drives labelled by the classical controller: one drive per value, the value
    /// being the drive's `sim.steer_noise` (steer units; noise makes the car wander so the
    /// data shows recoveries), e.g. `0.05,0.15,0.25`.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    sim_noise: Vec<f64>,
    /// Laps per simulator drive.
    #[arg(long, default_value_t = 1)]
    sim_laps: u32,
    /// Recordings to train on, read as datasets (docs/data.md): a car's `--record` folder,
    /// a Donkey tub v2, or a `rccar sim --record DIR` frames folder with `--telemetry`;
    /// repeat for several.
    #[arg(long)]
    recording: Vec<PathBuf>,
    /// The run's telemetry.jsonl for a `rccar sim --record DIR` frames folder given as the
    /// (one) --recording.
    #[arg(long)]
    telemetry: Option<PathBuf>,
    /// The configuration (camera, controller, track of the simulator drives). Default: the
    /// source tree's config/car.toml.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The later part of each drive held out for validation (split by time), 0.05..0.5.
    #[arg(long, default_value_t = 0.2)]
    val_fraction: f64,
    /// Most epochs.
    #[arg(long, default_value_t = 40)]
    epochs: usize,
    /// Early stopping: epochs without a lower validation loss before stopping.
    #[arg(long, default_value_t = 6)]
    patience: usize,
    /// Examples per Adam step.
    #[arg(long, default_value_t = 32)]
    batch: usize,
    /// Adam's learning rate.
    #[arg(long, default_value_t = 1e-3)]
    lr: f32,
    /// Seed (initial weights, shuffling, augmentation, simulator drives).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// No mirror-and-negate augmentation.
    #[arg(long)]
    no_mirror: bool,
    /// No light augmentation (gain, offset, ramp).
    #[arg(long)]
    no_light: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

fn run_pilot(a: PilotArgs) -> anyhow::Result<ExitCode> {
    use rccar_train::pilot::{self, data};
    if a.sim_noise.is_empty() && a.recording.is_empty() {
        bail!("no data: give --sim-noise (simulator drives) and/or --recording DIR");
    }
    if !(0.05..=0.5).contains(&a.val_fraction) {
        bail!("--val-fraction {}: must be 0.05..=0.5", a.val_fraction);
    }
    if let Some(n) = a.threads {
        rayon::ThreadPoolBuilder::new().num_threads(n).build_global().context("--threads")?;
    }
    let t0 = std::time::Instant::now();
    let mut drives = Vec::new();
    let mut said = Vec::new();
    if !a.sim_noise.is_empty() {
        let path = match &a.config {
            Some(p) => p.clone(),
            None => rccar::config::source_tree_config().context("no config/car.toml in the source tree: give --config")?,
        };
        let cfg = rccar::config::Config::load(&path, &[], &[]).with_context(|| path.display().to_string())?;
        let track = rccar::sim::track::Track::load(std::path::Path::new(&cfg.sim.track))
            .with_context(|| format!("sim.track = {}", cfg.sim.track))?;
        let plan = data::SimPlan {
            cfg,
            track,
            noise: a.sim_noise.clone(),
            laps: a.sim_laps,
            seed: a.seed as i64,
        };
        let bar = indicatif::ProgressBar::new_spinner();
        let d = data::from_sim(&plan, &mut |k, n| bar.set_message(format!("simulator drive {}/{}: {n} frames", k + 1, plan.noise.len())))
            .map_err(anyhow::Error::msg)?;
        bar.finish_and_clear();
        let n: usize = d.iter().map(|d| d.samples.len()).sum();
        println!(
            "simulator: {} drive(s) of {} lap(s), steer noise {:?}: {n} frames in {:.0} s",
            d.len(),
            a.sim_laps,
            a.sim_noise,
            t0.elapsed().as_secs_f64()
        );
        said.push(format!("simulator: {} drive(s) x {} lap(s), steer noise {:?}, {n} frames", d.len(), a.sim_laps, a.sim_noise));
        drives.extend(d);
    }
    if a.telemetry.is_some() && a.recording.len() != 1 {
        bail!("--telemetry goes with exactly one --recording (a frames folder)");
    }
    for r in &a.recording {
        let d = data::from_recording(r, a.telemetry.as_deref()).map_err(anyhow::Error::msg)?;
        println!("{}: {} frames", d.name, d.samples.len());
        said.push(format!("recording {}: {} frames", d.name, d.samples.len()));
        drives.push(d);
    }
    let (train, val) = data::split_by_time(drives, a.val_fraction);
    let h = data::histogram(&train);
    let top = h.iter().max().copied().unwrap_or(0);
    println!("steering labels (training), bins of 0.1 from -1 to 1:");
    for (i, c) in h.iter().enumerate().filter(|(_, c)| **c > 0) {
        let lo = -1.0 + 0.1 * i as f64;
        println!("  {lo:+.1}..{:+.1} {c:>7} {}", lo + 0.1, "#".repeat((40 * c).div_ceil(top.max(1))));
    }
    let o = pilot::TrainOptions {
        max_epochs: a.epochs,
        patience: a.patience,
        batch: a.batch,
        lr: a.lr,
        seed: a.seed,
        mirror: !a.no_mirror,
        light: !a.no_light,
    };
    println!("training on {} examples, validating on {} (later frames of each drive)", train.len(), val.len());
    let bar = indicatif::ProgressBar::new(train.len() as u64);
    let t1 = std::time::Instant::now();
    let mut best = f64::INFINITY;
    let trained = pilot::train(
        &train,
        &val,
        &o,
        &mut |e| {
            let mark = if e.val < best { " (best)" } else { "" };
            best = best.min(e.val);
            bar.suspend(|| {
                println!(
                    "epoch {:>3}/{}: train MSE {:.5}, validation MSE {:.5}{mark}, {:.0} s",
                    e.epoch, o.max_epochs, e.train, e.val, e.seconds
                )
            });
        },
        &mut |done, n| {
            bar.set_length(n as u64);
            bar.set_position(done.min(n) as u64);
        },
    );
    bar.finish_and_clear();
    let meta = pilot::metadata(&trained, train.len(), val.len(), &o, &said.join("; "));
    let weights = trained.params.to_weights(meta);
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    }
    weights.save(&a.out)?;
    let stem = a.out.with_extension("");
    let csv = std::path::PathBuf::from(format!("{}.loss.csv", stem.display()));
    std::fs::write(&csv, pilot::loss_csv(&trained.log)).with_context(|| csv.display().to_string())?;
    let png = std::path::PathBuf::from(format!("{}.loss.png", stem.display()));
    if let Some(f) = rccar::sim::plot::system_font() {
        rccar::sim::plot::register_font(f);
        let img = pilot::loss_plot(&trained.log).map_err(anyhow::Error::msg)?;
        img.save(&png).with_context(|| png.display().to_string())?;
    } else {
        eprintln!("note: no {} (fonts-dejavu-core): no loss plot", rccar::sim::plot::SYSTEM_FONT);
    }
    let b = trained.log.iter().find(|e| e.epoch == trained.best_epoch);
    println!(
        "{}: epoch {} of {} kept (validation MSE {:.5}, RMS {:.4} steer); training {:.0} s, all {:.0} s",
        a.out.display(),
        trained.best_epoch,
        trained.log.len(),
        b.map_or(f64::NAN, |b| b.val),
        b.map_or(f64::NAN, |b| b.val.sqrt()),
        t1.elapsed().as_secs_f64(),
        t0.elapsed().as_secs_f64()
    );
    println!("loss curve: {} {}", png.display(), csv.display());
    let cfg = match a.config.clone().or_else(rccar::config::source_tree_config) {
        Some(p) => rccar::config::Config::load(&p, &[], &[]).with_context(|| p.display().to_string())?,
        None => rccar::config::Config::default(),
    };
    let (rows, classical) = pilot::held_out_report(&trained.params, &train, &val, &cfg);
    let table = pilot::report_table(&rows, &classical);
    print!("{table}");
    let rep = std::path::PathBuf::from(format!("{}.report.txt", stem.display()));
    std::fs::write(&rep, &table).with_context(|| rep.display().to_string())?;
    println!("held-out report: {}", rep.display());
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Train(a) => run_train(a),
        Cmd::Gen(a) => run_gen(a),
        Cmd::Evaluate(a) => run_evaluate(a),
        Cmd::Distort(a) => run_distort(a),
        Cmd::Boxes(a) => run_boxes(a),
        Cmd::Photoset(a) => run_photoset(a),
        Cmd::Pilot(a) => run_pilot(a),
    };
    match r {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
