//! `rccar calibrate camera` and `rccar calibrate stereo`: checkerboard calibration of one
//! camera or of the stereo pair (src/calib/, Zhang's method with OpenCV's lens model,
//! Bouguet's rectification). Prints the reprojection error of every image, names the images
//! where the board was not found, and writes the results file (JSON) that `[stereo]
//! calibration` (a pair) or `[camera] calibration` (one camera's lens, for the bird's-eye
//! map) points at.

use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::calib::corners::{BoardSize, CornerOptions};
use rccar::calib::photos::{self, check_counts, Found, Views};
use rccar::calib::file::{CalibrationFile, CameraCalibration, MAX_STEREO_RMS_PX};
use rccar::calib::intrinsics::{board_points, calibrate_camera};
use std::path::PathBuf;
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

/// `--subpix-win` bounds, pixels.
const SUBPIX_WIN: (usize, usize) = (1, 32);

/// The board's corners in each photo (after the flags' bounds), written to `--corners-out`.
fn find_all(paths: &[PathBuf], b: &BoardArgs) -> Result<(Found, (u32, u32))> {
    if !(b.square > 0.0 && b.square <= 1.0) {
        bail!("--square {} must be a length in metres, > 0 and <= 1", b.square);
    }
    if !(SUBPIX_WIN.0..=SUBPIX_WIN.1).contains(&b.subpix_win) {
        bail!("--subpix-win {}: must be {}..={} pixels", b.subpix_win, SUBPIX_WIN.0, SUBPIX_WIN.1);
    }
    let opts = CornerOptions {
        subpix_win: b.subpix_win,
        ..CornerOptions::default()
    };
    let (found, size) = photos::find_all(paths, b.board, &opts)?;
    if let Some(path) = &b.corners_out {
        photos::merge_corners_file(path, paths, &found)?;
    }
    Ok((found, size))
}

/// Runs `rccar calibrate camera`.
pub fn run_camera(a: CameraArgs) -> Result<ExitCode> {
    let (found, size) = find_all(&a.images, &a.board)?;
    check_counts("images", a.images.len(), &found)?;
    let Views { views, names, not_found } = photos::camera_views(&a.images, found);
    for n in &not_found {
        eprintln!("{n}: board {}x{} not found", a.board.board.cols, a.board.board.rows);
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
    println!("{}", cam.summary_line("camera"));
    let hint = lane_hint(&cam, &a.out);
    let file = CalibrationFile::Camera {
        board: a.board.board,
        square_m: a.board.square,
        camera: cam,
    };
    std::fs::write(&a.out, file.to_json()).with_context(|| format!("{}: cannot write", a.out.display()))?;
    println!("wrote {}", a.out.display());
    println!("{hint}");
    Ok(ExitCode::SUCCESS)
}

/// How the lane pipeline uses a camera's results file: the `[camera]` keys to set (the file
/// folds the lens into the bird's-eye map; `hfov_deg` from fx keeps `rccar config roi` and the
/// ranging on the same pinhole).
fn lane_hint(cam: &CameraCalibration, out: &std::path::Path) -> String {
    let w = cam.image_size[0] as f64;
    let hfov = 2.0 * (w / (2.0 * cam.intrinsics.fx)).atan().to_degrees();
    format!(
        "lane keeping through this lens: in car.toml [camera] set calibration = \"{}\" and hfov_deg = {hfov:.1} (from fx), then recompute [warp] src with `rccar config roi` (docs/lane.md, \"Wide-angle lenses\")",
        out.display()
    )
}

/// Runs `rccar calibrate stereo`.
pub fn run_stereo(a: StereoArgs) -> Result<ExitCode> {
    photos::check_paired(&a.left, &a.right)?;
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
    photos::check_pair_size(&a.left, sl, &a.right, sr)?;
    let mut pairs = photos::pair_views(&a.left, &a.right, &fl, &fr);
    let skipped: Vec<String> = std::mem::take(&mut pairs.skipped)
        .into_iter()
        .map(|(i, why)| {
            eprintln!("pair {}: board not found in {}", i + 1, why.join(" and "));
            why.join(" ")
        })
        .collect();
    let (stereo, rms) = photos::fit_pair(a.board.board, a.board.square, &pairs, skipped, sl)?;
    println!("{}", stereo.left.summary_line("left"));
    println!("{}", stereo.right.summary_line("right"));
    for (l, r, e) in &stereo.per_pair_rms_px {
        println!("{l} + {r}: stereo reprojection RMS {e:.4} px");
    }
    let t = stereo.t;
    println!(
        "stereo: T = [{:.5}, {:.5}, {:.5}] m (baseline {:.4} m), RMS {:.4} px; rectified f {:.2} px, c ({:.2}, {:.2})",
        t[0], t[1], t[2], stereo.baseline_m, rms, stereo.rectification.f, stereo.rectification.c[0], stereo.rectification.c[1]
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
