//! `rccar calibrate camera` and `rccar calibrate stereo`: checkerboard calibration of one
//! camera or of the stereo pair (src/calib/, Zhang's method with OpenCV's lens model,
//! Bouguet's rectification). Prints the reprojection error of every image, names the images
//! where the board was not found, and writes the results file (JSON) that `[stereo]
//! calibration` points at.

use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::calib::corners::{find_chessboard, orient_like, BoardSize, CornerOptions};
use rccar::calib::file::{CalibrationFile, CameraCalibration, StereoCalibration, MAX_STEREO_RMS_PX};
use rccar::calib::intrinsics::{board_points, calibrate_camera};
use rccar::calib::stereo::{stereo_calibrate, stereo_rectify};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Flags shared by both commands.
#[derive(Args, Debug, Clone)]
pub struct BoardArgs {
    /// Inner corners of the board, COLSxROWS (OpenCV's sample board: 9x6).
    #[arg(long, default_value = "9x6")]
    pub board: BoardSize,
    /// Side of one square, metres (the unit of T and the baseline); 0 < S <= 1.
    #[arg(long, default_value_t = 0.025)]
    pub square: f64,
    /// Half size of the sub-pixel search window, pixels (OpenCV's winSize (11, 11) → 11);
    /// 1..=32.
    #[arg(long, default_value_t = 11)]
    pub subpix_win: usize,
    /// Also write the corners found in every image to this JSON file ({image: [[u, v], ...]}).
    #[arg(long)]
    pub corners_out: Option<PathBuf>,
}

/// `rccar calibrate camera` flags.
#[derive(Args, Debug)]
pub struct CameraArgs {
    /// Photos of the board (PNG or JPEG), at least 3 with the board found, at most 100.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    #[command(flatten)]
    pub board: BoardArgs,
    /// Results file to write.
    #[arg(long, short, default_value = "camera_calib.json")]
    pub out: PathBuf,
}

/// `rccar calibrate stereo` flags.
#[derive(Args, Debug)]
pub struct StereoArgs {
    /// Left-camera photos, in the same order as `--right` (at most 100 pairs).
    #[arg(long, num_args = 1.., required = true)]
    pub left: Vec<PathBuf>,
    /// Right-camera photos, paired one to one with `--left`.
    #[arg(long, num_args = 1.., required = true)]
    pub right: Vec<PathBuf>,
    #[command(flatten)]
    pub board: BoardArgs,
    /// Results file to write (`[stereo] calibration` in config/car.toml reads it).
    #[arg(long, short, default_value = "stereo_calib.json")]
    pub out: PathBuf,
    /// Refuse a stereo fit whose rms reprojection error is above this, pixels (0 < N <= 5;
    /// a good calibration is below 0.5 px).
    #[arg(long, default_value_t = 1.0)]
    pub max_rms_px: f64,
}

fn load_gray(path: &Path) -> Result<image::GrayImage> {
    Ok(open_image(path)?.to_luma8())
}

/// Opens an image with the `image` crate's decoders (the calibration's parity with OpenCV was
/// measured with them), after checking the size in its header against the project's image
/// limits (`rccar::config::limits`), so a header claiming 100000×100000 pixels is refused by
/// name before anything is allocated.
pub(crate) fn open_image(path: &Path) -> Result<image::DynamicImage> {
    use rccar::config::limits::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
    let (w, h) = image::image_dimensions(path).with_context(|| format!("{}: cannot read the image", path.display()))?;
    if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE || w as u64 * h as u64 > MAX_IMAGE_PIXELS {
        bail!(
            "{}: {w}×{h} pixels is outside the image limit (1..={MAX_IMAGE_SIDE} per side, at most {} megapixels)",
            path.display(),
            MAX_IMAGE_PIXELS / 1_000_000
        );
    }
    image::open(path).with_context(|| format!("{}: cannot read the image", path.display()))
}

/// Most photos per camera: the docs ask for 10–20, and the fit's Jacobian grows with the
/// square of the views.
pub const MAX_IMAGES: usize = 100;
/// Most board corners over all photos of one fit (the Jacobian has 2 rows per corner and 6
/// columns per photo: 20,000 corners of 100 photos is 40,000 × 615 values, 200 MB).
pub const MAX_CORNERS: usize = 20_000;
/// Largest `--corners-out` file read back to append to, bytes.
const MAX_CORNERS_FILE: u64 = 64 << 20;
/// `--subpix-win` bounds, pixels.
const SUBPIX_WIN: (usize, usize) = (1, 32);

/// Refuses more than [`MAX_IMAGES`] photos and more than [`MAX_CORNERS`] corners found.
fn check_counts(what: &str, n_images: usize, found: &Found) -> Result<()> {
    if n_images > MAX_IMAGES {
        bail!("{n_images} {what}: at most {MAX_IMAGES} (10–20 photos calibrate a camera)");
    }
    let corners: usize = found.iter().flatten().map(Vec::len).sum();
    if corners > MAX_CORNERS {
        bail!(
            "{corners} board corners found in {n_images} {what}: at most {MAX_CORNERS} in one fit; use fewer photos or a board with fewer squares"
        );
    }
    Ok(())
}

/// Corners of each image (None where the board was not found); all images must share a size.
/// Corners per image (`None`: board not found).
type Found = Vec<Option<Vec<[f64; 2]>>>;

fn find_all(paths: &[PathBuf], b: &BoardArgs) -> Result<(Found, (u32, u32))> {
    if !(b.square > 0.0 && b.square <= 1.0) {
        bail!("--square {} must be a length in metres, > 0 and <= 1", b.square);
    }
    if !(SUBPIX_WIN.0..=SUBPIX_WIN.1).contains(&b.subpix_win) {
        bail!(
            "--subpix-win {}: must be {}..={} pixels",
            b.subpix_win,
            SUBPIX_WIN.0,
            SUBPIX_WIN.1
        );
    }
    if paths.len() > MAX_IMAGES {
        bail!(
            "{} images: at most {MAX_IMAGES} (10–20 photos calibrate a camera)",
            paths.len()
        );
    }
    let opts = CornerOptions {
        subpix_win: b.subpix_win,
        ..CornerOptions::default()
    };
    let mut size = None;
    let mut out = vec![];
    for p in paths {
        let img = load_gray(p)?;
        match size {
            None => size = Some((img.width(), img.height())),
            Some((w, h)) if (w, h) != img.dimensions() => bail!(
                "{}: image is {}x{}, but {} is {w}x{h}: all images must have the same size",
                p.display(),
                img.width(),
                img.height(),
                paths[0].display()
            ),
            _ => {}
        }
        out.push(find_chessboard(&img, b.board, &opts));
    }
    if let Some(path) = &b.corners_out {
        // Appends to what an earlier call (the other camera) wrote.
        let small = std::fs::metadata(path).map_or(true, |m| m.len() <= MAX_CORNERS_FILE);
        if !small {
            bail!(
                "--corners-out {}: an existing file larger than {MAX_CORNERS_FILE} bytes (not one this command wrote); move it away",
                path.display()
            );
        }
        let mut all: std::collections::BTreeMap<String, Option<Vec<[f64; 2]>>> = std::fs::read_to_string(path)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok())
            .unwrap_or_default();
        for (p, c) in paths.iter().zip(&out) {
            all.insert(name(p), c.clone());
        }
        std::fs::write(path, serde_json::to_string(&all)?)
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok((out, size.unwrap_or((0, 0))))
}

fn print_camera(label: &str, c: &CameraCalibration) {
    let k = &c.intrinsics;
    let d = &c.distortion.0;
    println!(
        "{label}: fx {:.3} fy {:.3} cx {:.3} cy {:.3} px; k1 {:.5} k2 {:.5} p1 {:.6} p2 {:.6} k3 {:.5}; RMS {:.4} px",
        k.fx, k.fy, k.cx, k.cy, d[0], d[1], d[2], d[3], d[4], c.rms_px
    );
}

fn name(p: &Path) -> String {
    p.display().to_string()
}

/// Runs `rccar calibrate camera`.
pub fn run_camera(a: CameraArgs) -> Result<ExitCode> {
    let (found, size) = find_all(&a.images, &a.board)?;
    check_counts("images", a.images.len(), &found)?;
    let mut views = vec![];
    let mut names = vec![];
    let mut not_found = vec![];
    for (p, f) in a.images.iter().zip(found) {
        match f {
            Some(v) => {
                views.push(v);
                names.push(name(p));
            }
            None => {
                eprintln!(
                    "{}: board {}x{} not found",
                    p.display(),
                    a.board.board.cols,
                    a.board.board.rows
                );
                not_found.push(name(p));
            }
        }
    }
    let obj = board_points(a.board.board.cols, a.board.board.rows, a.board.square);
    let fit = calibrate_camera(&obj, &views, size.0, size.1).with_context(|| {
        format!(
            "calibrating from {} images ({} without a board)",
            a.images.len(),
            not_found.len()
        )
    })?;
    let cam = CameraCalibration::from_fit(&fit, &names, size, not_found);
    for (n, e) in &cam.per_image_rms_px {
        println!("{n}: reprojection RMS {e:.4} px");
    }
    print_camera("camera", &cam);
    let file = CalibrationFile::Camera {
        board: a.board.board,
        square_m: a.board.square,
        camera: cam,
    };
    std::fs::write(&a.out, file.to_json()).with_context(|| format!("{}: cannot write", a.out.display()))?;
    println!("wrote {}", a.out.display());
    Ok(ExitCode::SUCCESS)
}

/// Runs `rccar calibrate stereo`.
pub fn run_stereo(a: StereoArgs) -> Result<ExitCode> {
    if a.left.len() != a.right.len() {
        bail!(
            "{} left images but {} right images: --left and --right must pair up one to one",
            a.left.len(),
            a.right.len()
        );
    }
    if !(a.max_rms_px.is_finite() && a.max_rms_px > 0.0 && a.max_rms_px <= MAX_STEREO_RMS_PX) {
        bail!(
            "--max-rms-px {}: must be > 0 and <= {MAX_STEREO_RMS_PX} pixels",
            a.max_rms_px
        );
    }
    let (fl, sl) = find_all(&a.left, &a.board)?;
    check_counts("left images", a.left.len(), &fl)?;
    let (fr, sr) = find_all(&a.right, &a.board)?;
    check_counts("right images", a.right.len(), &fr)?;
    if sl != sr {
        bail!(
            "left images are {}x{} but right images are {}x{} ({} vs {}): the pair must have one size",
            sl.0,
            sl.1,
            sr.0,
            sr.1,
            a.left[0].display(),
            a.right[0].display()
        );
    }
    let (mut lv, mut rv, mut names, mut skipped) = (vec![], vec![], vec![], vec![]);
    for i in 0..a.left.len() {
        match (&fl[i], &fr[i]) {
            (Some(l), Some(r)) => {
                rv.push(orient_like(l, r));
                lv.push(l.clone());
                names.push((name(&a.left[i]), name(&a.right[i])));
            }
            (l, r) => {
                let mut why = vec![];
                if l.is_none() {
                    why.push(name(&a.left[i]));
                }
                if r.is_none() {
                    why.push(name(&a.right[i]));
                }
                eprintln!("pair {}: board not found in {}", i + 1, why.join(" and "));
                skipped.push(why.join(" "));
            }
        }
    }
    let obj = board_points(a.board.board.cols, a.board.board.rows, a.board.square);
    let fit_l = calibrate_camera(&obj, &lv, sl.0, sl.1).context("left camera")?;
    let fit_r = calibrate_camera(&obj, &rv, sl.0, sl.1).context("right camera")?;
    let st = stereo_calibrate(&obj, &lv, &rv, &fit_l.k, &fit_l.dist, &fit_r.k, &fit_r.dist).context("stereo fit")?;
    let rect = stereo_rectify(&fit_l.k, &fit_l.dist, &fit_r.k, &fit_r.dist, &st.r, &st.t, sl.0, sl.1);
    let (ln, rn): (Vec<String>, Vec<String>) = names.iter().cloned().unzip();
    let left = CameraCalibration::from_fit(&fit_l, &ln, sl, vec![]);
    let right = CameraCalibration::from_fit(&fit_r, &rn, sl, vec![]);
    print_camera("left", &left);
    print_camera("right", &right);
    let stereo = StereoCalibration::from_fit(left, right, &st, &names, skipped, rect);
    for (l, r, e) in &stereo.per_pair_rms_px {
        println!("{l} + {r}: stereo reprojection RMS {e:.4} px");
    }
    let t = stereo.t;
    println!(
        "stereo: T = [{:.5}, {:.5}, {:.5}] m (baseline {:.4} m), RMS {:.4} px; rectified f {:.2} px, c ({:.2}, {:.2})",
        t[0], t[1], t[2], stereo.baseline_m, st.rms, stereo.rectification.f, stereo.rectification.c[0], stereo.rectification.c[1]
    );
    // Only a pair that can range is written (the loaders refuse the rest too).
    stereo.check(a.max_rms_px).map_err(|e| {
        anyhow::anyhow!(
            "the stereo calibration is not usable, so {} is not written: {e}",
            a.out.display()
        )
    })?;
    let file = CalibrationFile::Stereo {
        board: a.board.board,
        square_m: a.board.square,
        stereo,
    };
    std::fs::write(&a.out, file.to_json()).with_context(|| format!("{}: cannot write", a.out.display()))?;
    println!("wrote {}", a.out.display());
    Ok(ExitCode::SUCCESS)
}
