//! `rccar calibrate camera` and `rccar calibrate stereo`: checkerboard calibration of one
//! camera or of the stereo pair (src/calib/, Zhang's method with OpenCV's lens model,
//! Bouguet's rectification). Prints the reprojection error of every image, names the images
//! where the board was not found, and writes the results file (JSON) that `[stereo]
//! calibration` points at.

use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::calib::corners::{find_chessboard, orient_like, BoardSize, CornerOptions};
use rccar::calib::file::{CalibrationFile, CameraCalibration, StereoCalibration};
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
    /// Side of one square, metres (the unit of T and the baseline).
    #[arg(long, default_value_t = 0.025)]
    pub square: f64,
    /// Half size of the sub-pixel search window, pixels (OpenCV's winSize (11, 11) → 11).
    #[arg(long, default_value_t = 11)]
    pub subpix_win: usize,
    /// Also write the corners found in every image to this JSON file ({image: [[u, v], ...]}).
    #[arg(long)]
    pub corners_out: Option<PathBuf>,
}

/// `rccar calibrate camera` flags.
#[derive(Args, Debug)]
pub struct CameraArgs {
    /// Photos of the board (PNG or JPEG), at least 3 with the board found.
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
    /// Left-camera photos, in the same order as `--right`.
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
}

fn load_gray(path: &Path) -> Result<image::GrayImage> {
    let img = image::open(path).with_context(|| format!("{}: cannot read the image", path.display()))?;
    Ok(img.to_luma8())
}

/// Corners of each image (None where the board was not found); all images must share a size.
/// Corners per image (`None`: board not found).
type Found = Vec<Option<Vec<[f64; 2]>>>;

fn find_all(paths: &[PathBuf], b: &BoardArgs) -> Result<(Found, (u32, u32))> {
    if b.square <= 0.0 || !b.square.is_finite() {
        bail!("--square {} must be a positive length in metres", b.square);
    }
    let opts = CornerOptions {
        subpix_win: b.subpix_win.max(1),
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
    let (fl, sl) = find_all(&a.left, &a.board)?;
    let (fr, sr) = find_all(&a.right, &a.board)?;
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
    let file = CalibrationFile::Stereo {
        board: a.board.board,
        square_m: a.board.square,
        stereo,
    };
    std::fs::write(&a.out, file.to_json()).with_context(|| format!("{}: cannot write", a.out.display()))?;
    println!("wrote {}", a.out.display());
    Ok(ExitCode::SUCCESS)
}
