//! The checkerboard photos of a calibration: opened within the project's image limits, the
//! board's inner corners found in each ([`find_all`]), bounded in count (the fit's Jacobian
//! grows with the square of the views), sorted into the views a fit uses ([`camera_views`],
//! [`pair_views`]), and optionally written to a corners file ([`merge_corners_file`]).
//! `rccar calibrate camera|stereo` calls these and prints what they return.

use super::corners::{find_chessboard, orient_like, BoardSize, CornerOptions};
use crate::imageio::limits::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Most photos per camera: the docs ask for 10–20, and the fit's Jacobian grows with the
/// square of the views.
pub const MAX_IMAGES: usize = 100;
/// Most board corners over all photos of one fit (the Jacobian has 2 rows per corner and 6
/// columns per photo: 20,000 corners of 100 photos is 40,000 × 615 values, 200 MB).
pub const MAX_CORNERS: usize = 20_000;
/// Largest corners file read back to append to, bytes.
pub const MAX_CORNERS_FILE: u64 = 64 << 20;

/// Corners per image (`None`: board not found).
pub type Found = Vec<Option<Vec<[f64; 2]>>>;

/// What can go wrong with the photos (each names the file or the bound).
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    /// The image cannot be opened or decoded.
    #[error("{}: cannot read the image", path.display())]
    Read {
        /// The photo.
        path: PathBuf,
        /// Why.
        #[source]
        err: image::ImageError,
    },
    /// The header's size is outside [`crate::imageio::limits`].
    #[error("{}: {w}×{h} pixels is outside the image limit (1..={MAX_IMAGE_SIDE} per side, at most {} megapixels)", path.display(), MAX_IMAGE_PIXELS / 1_000_000)]
    Limit {
        /// The photo.
        path: PathBuf,
        /// Its width, pixels.
        w: u32,
        /// Its height, pixels.
        h: u32,
    },
    /// A photo of another size than the first.
    #[error("{}: image is {}x{}, but {} is {}x{}: all images must have the same size", path.display(), size.0, size.1, first.display(), first_size.0, first_size.1)]
    Size {
        /// The photo that differs.
        path: PathBuf,
        /// Its size, pixels.
        size: (u32, u32),
        /// The first photo.
        first: PathBuf,
        /// The first photo's size.
        first_size: (u32, u32),
    },
    /// More photos than [`MAX_IMAGES`].
    #[error("{n} {what}: at most {MAX_IMAGES} (10–20 photos calibrate a camera)")]
    TooMany {
        /// Photos given.
        n: usize,
        /// What they are ("images", "left images").
        what: String,
    },
    /// More corners found than [`MAX_CORNERS`].
    #[error("{corners} board corners found in {n} {what}: at most {MAX_CORNERS} in one fit; use fewer photos or a board with fewer squares")]
    TooManyCorners {
        /// Corners found.
        corners: usize,
        /// Photos.
        n: usize,
        /// What they are.
        what: String,
    },
    /// An existing corners file too large to be one this command wrote.
    #[error("--corners-out {}: an existing file larger than {MAX_CORNERS_FILE} bytes (not one this command wrote); move it away", path.display())]
    CornersFileSize {
        /// The file.
        path: PathBuf,
    },
    /// `--left` and `--right` of different lengths.
    #[error("{left} left images but {right} right images: --left and --right must pair up one to one")]
    Unpaired {
        /// Left photos.
        left: usize,
        /// Right photos.
        right: usize,
    },
    /// The left photos are of another size than the right ones.
    #[error("left images are {}x{} but right images are {}x{} ({} vs {}): the pair must have one size", left_size.0, left_size.1, right_size.0, right_size.1, left.display(), right.display())]
    PairSize {
        /// The first left photo.
        left: PathBuf,
        /// The left photos' size.
        left_size: (u32, u32),
        /// The first right photo.
        right: PathBuf,
        /// The right photos' size.
        right_size: (u32, u32),
    },
    /// The corners file cannot be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        err: std::io::Error,
    },
}

/// Opens an image with the `image` crate's decoders (the calibration's parity with OpenCV was
/// measured with them), after checking the size in its header against the project's image
/// limits, so a header claiming 100000×100000 pixels is refused by name before anything is
/// allocated.
pub fn open_image(path: &Path) -> Result<image::DynamicImage, PhotoError> {
    let read = |err| PhotoError::Read { path: path.to_path_buf(), err };
    let (w, h) = image::image_dimensions(path).map_err(read)?;
    if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE || w as u64 * h as u64 > MAX_IMAGE_PIXELS {
        return Err(PhotoError::Limit { path: path.to_path_buf(), w, h });
    }
    image::open(path).map_err(read)
}

/// Refuses more than [`MAX_IMAGES`] photos and more than [`MAX_CORNERS`] corners found.
pub fn check_counts(what: &str, n_images: usize, found: &Found) -> Result<(), PhotoError> {
    if n_images > MAX_IMAGES {
        return Err(PhotoError::TooMany { n: n_images, what: what.into() });
    }
    let corners: usize = found.iter().flatten().map(Vec::len).sum();
    if corners > MAX_CORNERS {
        return Err(PhotoError::TooManyCorners { corners, n: n_images, what: what.into() });
    }
    Ok(())
}

/// Refuses `--left` and `--right` photo lists that do not pair up one to one.
pub fn check_paired(left: &[PathBuf], right: &[PathBuf]) -> Result<(), PhotoError> {
    if left.len() != right.len() {
        return Err(PhotoError::Unpaired { left: left.len(), right: right.len() });
    }
    Ok(())
}

/// Refuses a pair whose left photos (of `left_size`) and right photos (of `right_size`) differ
/// in size; the error names the first photo of each side.
pub fn check_pair_size(left: &[PathBuf], left_size: (u32, u32), right: &[PathBuf], right_size: (u32, u32)) -> Result<(), PhotoError> {
    match (left.first(), right.first()) {
        (Some(l), Some(r)) if left_size != right_size => Err(PhotoError::PairSize {
            left: l.clone(),
            left_size,
            right: r.clone(),
            right_size,
        }),
        _ => Ok(()),
    }
}

/// The board's corners in each photo (at most [`MAX_IMAGES`], all of one size) and that size
/// ((0, 0) for no photos).
pub fn find_all(paths: &[PathBuf], board: BoardSize, opts: &CornerOptions) -> Result<(Found, (u32, u32)), PhotoError> {
    if paths.len() > MAX_IMAGES {
        return Err(PhotoError::TooMany { n: paths.len(), what: "images".into() });
    }
    let mut size = None;
    let mut out = vec![];
    for p in paths {
        let img = open_image(p)?.to_luma8();
        match size {
            None => size = Some(img.dimensions()),
            Some(first_size) if first_size != img.dimensions() => {
                return Err(PhotoError::Size {
                    path: p.clone(),
                    size: img.dimensions(),
                    first: paths[0].clone(),
                    first_size,
                })
            }
            _ => {}
        }
        out.push(find_chessboard(&img, board, opts));
    }
    Ok((out, size.unwrap_or((0, 0))))
}

/// Adds the corners of `paths` to the JSON file `path` ({image: [[u, v], ...] or null}),
/// keeping what an earlier call (the other camera) wrote there.
pub fn merge_corners_file(path: &Path, paths: &[PathBuf], found: &Found) -> Result<(), PhotoError> {
    let small = std::fs::metadata(path).map_or(true, |m| m.len() <= MAX_CORNERS_FILE);
    if !small {
        return Err(PhotoError::CornersFileSize { path: path.to_path_buf() });
    }
    let mut all: BTreeMap<String, Option<Vec<[f64; 2]>>> = std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    for (p, c) in paths.iter().zip(found) {
        all.insert(p.display().to_string(), c.clone());
    }
    let text = serde_json::to_string(&all).expect("corners serialise");
    std::fs::write(path, text).map_err(|err| PhotoError::Write { path: path.to_path_buf(), err })
}

/// One camera's views: the photos with the board, and the names of those without.
#[derive(Debug, Default)]
pub struct Views {
    /// Corners of each photo with the board.
    pub views: Vec<Vec<[f64; 2]>>,
    /// Their names (as displayed).
    pub names: Vec<String>,
    /// Photos where the board was not found.
    pub not_found: Vec<String>,
}

/// Sorts one camera's photos into views and the photos without a board.
pub fn camera_views(paths: &[PathBuf], found: Found) -> Views {
    let mut v = Views::default();
    for (p, f) in paths.iter().zip(found) {
        match f {
            Some(c) => {
                v.views.push(c);
                v.names.push(p.display().to_string());
            }
            None => v.not_found.push(p.display().to_string()),
        }
    }
    v
}

/// A stereo pair's views: the pairs with the board in both photos (the right corners ordered
/// like the left ones), and the pairs skipped.
#[derive(Debug, Default)]
pub struct PairViews {
    /// Left corners of each usable pair.
    pub left: Vec<Vec<[f64; 2]>>,
    /// Right corners, in the left's order.
    pub right: Vec<Vec<[f64; 2]>>,
    /// (left, right) names of each usable pair.
    pub names: Vec<(String, String)>,
    /// Skipped pairs: their index (0-based) and the photos without the board.
    pub skipped: Vec<(usize, Vec<String>)>,
}

/// Pairs the left and right photos one to one (the lists have one length).
pub fn pair_views(left: &[PathBuf], right: &[PathBuf], fl: &Found, fr: &Found) -> PairViews {
    let mut v = PairViews::default();
    for i in 0..left.len().min(right.len()) {
        match (&fl[i], &fr[i]) {
            (Some(l), Some(r)) => {
                v.right.push(orient_like(l, r));
                v.left.push(l.clone());
                v.names.push((left[i].display().to_string(), right[i].display().to_string()));
            }
            (l, r) => {
                let mut why = vec![];
                if l.is_none() {
                    why.push(left[i].display().to_string());
                }
                if r.is_none() {
                    why.push(right[i].display().to_string());
                }
                v.skipped.push((i, why));
            }
        }
    }
    v
}

/// Which fit of a stereo calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum PairFitError {
    /// The left camera's intrinsics.
    #[error("left camera")]
    Left(#[source] super::CalibError),
    /// The right camera's intrinsics.
    #[error("right camera")]
    Right(#[source] super::CalibError),
    /// The pair's R and T.
    #[error("stereo fit")]
    Stereo(#[source] super::CalibError),
}

/// Both cameras' intrinsics, then the pair's R, T and rectification from the views `v` of a
/// board with `square_m` squares in photos of `size`; `skipped`: the pairs left out, as the
/// results file names them. Returns the calibration and the stereo fit's rms, pixels.
pub fn fit_pair(
    board: BoardSize,
    square_m: f64,
    v: &PairViews,
    skipped: Vec<String>,
    size: (u32, u32),
) -> Result<(super::StereoCalibration, f64), PairFitError> {
    use super::{calibrate_camera, stereo_calibrate, stereo_rectify, CameraCalibration, StereoCalibration};
    let obj = super::intrinsics::board_points(board.cols, board.rows, square_m);
    let fit_l = calibrate_camera(&obj, &v.left, size.0, size.1).map_err(PairFitError::Left)?;
    let fit_r = calibrate_camera(&obj, &v.right, size.0, size.1).map_err(PairFitError::Right)?;
    let st = stereo_calibrate(&obj, &v.left, &v.right, &fit_l.k, &fit_l.dist, &fit_r.k, &fit_r.dist)
        .map_err(PairFitError::Stereo)?;
    let rect = stereo_rectify(&fit_l.k, &fit_l.dist, &fit_r.k, &fit_r.dist, &st.r, &st.t, size.0, size.1);
    let (ln, rn): (Vec<String>, Vec<String>) = v.names.iter().cloned().unzip();
    let left = CameraCalibration::from_fit(&fit_l, &ln, size, vec![]);
    let right = CameraCalibration::from_fit(&fit_r, &rn, size, vec![]);
    Ok((StereoCalibration::from_fit(left, right, &st, &v.names, skipped, rect), st.rms))
}
