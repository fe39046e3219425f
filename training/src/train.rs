//! The cascade training loop, as OpenCV's `CvCascadeClassifier::train` runs it (Viola & Jones
//! 2001, Sec. 4; Lienhart, Kuranov & Pisarevsky 2003):
//!
//! For each stage i:
//! 1. positives: up to `num_pos` samples the cascade so far accepts (OpenCV's
//!    `updateTrainingSet`); too few is an error;
//! 2. negatives: `num_neg` windows of the backgrounds the cascade so far wrongly accepts
//!    ([`crate::scan`]); none left means the cascade is done, not failed;
//! 3. feature values of all samples, precomputed and binned ([`crate::boost::FeatureMatrix`])
//!    within the `--mem-mb` budget (a seeded random part of the pool when the whole pool does
//!    not fit);
//! 4. weak learners are added ([`crate::boost::Booster`]) until, with the stage threshold set
//!    so that `min_hit_rate` of the positives pass (threshold = the score at index
//!    `⌊(1 − minHitRate)·numPos⌋` of the sorted positive scores), at most `max_false_alarm` of
//!    the negatives pass;
//! 5. the stage is appended, `cascade.xml` and `stages.json` (parameters, stages, per-stage
//!    log) rewritten atomically, so an interrupted run resumes from its last finished stage.
//!
//! The clock is read only for the per-stage times in the log.

use crate::boost::{Booster, FeatureMatrix};
use crate::features::{self, SampleIntegral};
use crate::model::{Model, ModelParams, StageModel};
use crate::samples::Background;
use crate::scan;
use rccar::detect::integral::Integrals;
use rccar::detect::Cascade;
use rccar::sim::rng::{mix, SplitMix64};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Why training stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// Reading or writing the output folder failed.
    #[error("{path}: {err}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause (in the message, not a `source`: printed once).
        err: std::io::Error,
    },
    /// A bad parameter or data set.
    #[error("{0}")]
    Invalid(String),
    /// The resume file does not fit this run.
    #[error("{path}: cannot resume: {message}")]
    Resume {
        /// The stages.json.
        path: PathBuf,
        /// What differs.
        message: String,
    },
    /// The written cascade did not load (a bug).
    #[error("the trained cascade does not load: {0}")]
    Cascade(rccar::detect::CascadeError),
}

// By hand, not `#[from]`: a `source` would print the cascade's error a second time.
impl From<rccar::detect::CascadeError> for TrainError {
    fn from(e: rccar::detect::CascadeError) -> Self {
        TrainError::Cascade(e)
    }
}

/// Training options beyond the model's parameters.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrainOptions {
    /// Cascade parameters.
    pub params: ModelParams,
    /// Positives per stage.
    pub num_pos: usize,
    /// Negatives per stage.
    pub num_neg: usize,
    /// Budget for the precomputed feature values, MiB.
    pub mem_mb: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Scale step of the negative pool's pyramid (the detector's `scaleFactor`).
    pub scale_factor: f64,
    /// Also draw negatives from the backgrounds' mirror images (twice the pool).
    #[serde(default)]
    pub mirror_negatives: bool,
    /// Also draw negatives from the backgrounds turned upside down (and their mirror images):
    /// twice the pool again.
    #[serde(default)]
    pub upside_down_negatives: bool,
}

/// One finished stage's record in `stages.json`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StageLog {
    /// Stage index.
    pub stage: usize,
    /// Weak classifiers in it.
    pub weak_count: usize,
    /// Hit rate on this stage's positives.
    pub hit_rate: f64,
    /// False-alarm rate on this stage's negatives.
    pub false_alarm: f64,
    /// Positives used.
    pub num_pos: usize,
    /// Negatives used.
    pub num_neg: usize,
    /// Background windows scanned while mining the negatives.
    pub windows_scanned: u64,
    /// Of those, accepted by the cascade before this stage.
    pub windows_accepted: u64,
    /// `windows_accepted / windows_scanned`: the cascade's false-alarm rate per window so far
    /// (OpenCV's "acceptanceRatio").
    pub acceptance_ratio: f64,
    /// Features in the precomputed matrix (all of the pool unless the budget cut it).
    pub features_used: usize,
    /// Bytes of the matrix.
    pub matrix_bytes: usize,
    /// Seconds: mining, precomputing, boosting, total.
    pub seconds_mining: f64,
    /// Seconds precomputing.
    pub seconds_precompute: f64,
    /// Seconds boosting.
    pub seconds_boost: f64,
    /// Seconds for the whole stage.
    pub seconds: f64,
    /// Window positions in the negative pool (all backgrounds, scales, offsets).
    #[serde(default)]
    pub pool_windows: u64,
    /// Whether every window of the pool had to be checked to find this stage's negatives
    /// (they are all the backgrounds hold).
    #[serde(default)]
    pub negatives_exhausted: bool,
    /// Recall on the held-out frames after this stage (when they have boxes).
    #[serde(default)]
    pub holdout_recall: Option<f64>,
    /// False positives per held-out frame after this stage (all frames, those with the object
    /// too: the early stop's figure).
    #[serde(default)]
    pub holdout_fp_per_frame: Option<f64>,
    /// False positives per held-out frame without the object after this stage.
    #[serde(default)]
    pub holdout_fp_per_negative_frame: Option<f64>,
}

/// Frames kept out of training, checked after every stage: training stops once their false
/// positives per frame are at most `target_fp_per_frame`.
#[derive(Debug, Clone)]
pub struct Holdout {
    /// (name, grey frame, object boxes); frames without boxes count false positives only.
    pub frames: Vec<(String, image::GrayImage, Vec<rccar::detect::Rect>)>,
    /// Detector settings the check uses (as `rccar detect` would run).
    pub min_neighbors: u32,
    /// Smallest window, pixels ((0, 0) = the cascade's size).
    pub min_size: (u32, u32),
    /// Scale step.
    pub scale_factor: f64,
    /// IoU for a detection to count as finding a box.
    pub iou: f64,
    /// Stop when false positives per frame ≤ this.
    pub target_fp_per_frame: f64,
}

/// The held-out check runs once the cascade is estimated to accept at most this fraction of
/// windows (acceptance before the stage × the stage's false-alarm rate): about 200 raw hits
/// per 320 × 240 frame.
pub const HOLDOUT_FROM: f64 = 2e-3;

/// Held-out figures after a stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldoutCheck {
    /// Recall (None when the frames have no boxes).
    pub recall: Option<f64>,
    /// False positives per frame, over all held-out frames (the early stop's figure).
    pub fp_per_frame: f64,
    /// False positives per held-out frame without the object (None when there are none).
    pub fp_per_negative_frame: Option<f64>,
    /// False positives per held-out frame with the object (None when there are none).
    pub fp_per_sign_frame: Option<f64>,
    /// Held-out frames without the object, and with it.
    pub frames: (usize, usize),
}

/// Runs `cascade` over the held-out frames.
pub fn check_holdout(cascade: &Cascade, h: &Holdout) -> Result<HoldoutCheck, TrainError> {
    let rep = crate::evaluate::evaluate(
        cascade.clone(),
        "holdout",
        &h.frames,
        h.scale_factor,
        h.min_size,
        h.iou,
        &[h.min_neighbors],
        h.min_neighbors,
    )
    .map_err(|e| TrainError::Invalid(format!("held-out check: {e}")))?;
    let p = &rep.points[0];
    Ok(HoldoutCheck {
        recall: (rep.boxes > 0).then_some(p.recall),
        fp_per_frame: p.fp_per_frame,
        fp_per_negative_frame: p.fp_per_negative_frame,
        fp_per_sign_frame: p.fp_per_sign_frame,
        frames: (rep.negative_frames, rep.sign_frames),
    })
}

/// `stages.json`: everything needed to resume, plus the log.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StageFile {
    /// The options the run started with.
    pub options: TrainOptions,
    /// Finished stages.
    pub stages: Vec<StageModel>,
    /// Their logs.
    pub log: Vec<StageLog>,
    /// Why training ended (`null` while it runs).
    pub finished: Option<String>,
    /// Positives available (scannable) at the start.
    pub positives_total: usize,
    /// Backgrounds available.
    pub backgrounds_total: usize,
}

/// Progress callbacks (the binary draws bars; tests pass [`NoProgress`]).
pub trait Progress {
    /// A stage starts.
    fn stage_start(&mut self, stage: usize, max_weak: usize);
    /// A weak learner was added.
    fn weak(&mut self, count: usize, hit: f64, fa: f64);
    /// A stage ended.
    fn stage_end(&mut self, log: &StageLog);
    /// A note (skipped input, stop reason).
    fn note(&mut self, msg: &str);
}

/// Silent progress.
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage_start(&mut self, _: usize, _: usize) {}
    fn weak(&mut self, _: usize, _: f64, _: f64) {}
    fn stage_end(&mut self, _: &StageLog) {}
    fn note(&mut self, _: &str) {}
}

fn write_atomic(path: &Path, text: &str) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    let io = |err| TrainError::Io {
        path: path.into(),
        err,
    };
    std::fs::write(&tmp, text).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// How a run ended.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// The cascade file.
    pub xml: PathBuf,
    /// Stages in it.
    pub stages: usize,
    /// Why it stopped.
    pub reason: String,
    /// Held-out figures of the final cascade (when a held-out set was given).
    pub holdout: Option<HoldoutCheck>,
    /// Whether training ended because the negatives ran out before the targets.
    pub negatives_ran_out: bool,
}

/// Trains (or resumes) a cascade into `out_dir` (`cascade.xml`, `stages.json`).
pub fn train(
    opts: &TrainOptions,
    positives: &[Vec<u8>],
    backgrounds: &[Background],
    out_dir: &Path,
    resume: bool,
    progress: &mut dyn Progress,
) -> Result<TrainOutcome, TrainError> {
    train_with_holdout(opts, positives, backgrounds, None, out_dir, resume, progress)
}

/// Memory `--mem-mb` sets aside for the program itself (code, allocator, threads' buffers,
/// decoding), bytes. Measured: with 32 MiB the peak resident memory stayed under the budget
/// (issue 28: 24 MiB, without the held-out frames counted, peaked at 544 MiB of 512).
pub const PROGRAM_BYTES: usize = 32 << 20;

/// Memory for the detector's pyramid and tables while it checks the held-out frames, bytes.
pub const HOLDOUT_DETECTOR_BYTES: usize = 4 << 20;

/// Bytes the training data takes besides the feature matrix: backgrounds, positives' and
/// negatives' integral tables (two `i32` tables of `(w+1)·(h+1)` each) and raw windows.
pub fn data_bytes(backgrounds: &[Background], positives: usize, num_neg: usize, w: usize, h: usize) -> usize {
    let bg: usize = backgrounds.iter().map(|b| b.img.as_raw().len()).sum();
    let per = 2 * (w + 1) * (h + 1) * 4 + 64;
    bg + (positives + num_neg) * per + 2 * num_neg * (w * h + 24) + positives * (w * h + 24)
}

/// [`train`] with an optional held-out set checked after every stage (early stop at its
/// false-positive target).
#[allow(clippy::too_many_arguments)]
pub fn train_with_holdout(
    opts: &TrainOptions,
    positives: &[Vec<u8>],
    backgrounds: &[Background],
    holdout: Option<&Holdout>,
    out_dir: &Path,
    resume: bool,
    progress: &mut dyn Progress,
) -> Result<TrainOutcome, TrainError> {
    let p = &opts.params;
    let (w, h) = (p.width as usize, p.height as usize);
    // 0. Checks.
    check_inputs(opts, positives, backgrounds)?;
    let (xml_path, log_path) = output_paths(out_dir)?;
    // 1. Positives' integrals; windows the detector would never look at are left out.
    let mut ii = Integrals::new();
    let pos_pool = positive_pool(positives, w, h, opts.seed, &mut ii, progress);
    // 2. Resume.
    let mut model = Model::new(p.clone());
    let mut file = StageFile::new(opts, pos_pool.len(), backgrounds.len());
    if resume && log_path.exists() {
        if let Some(done) = resume_from(&log_path, &xml_path, &mut model, &mut file, progress)? {
            return Ok(done);
        }
    }
    // The feature matrix gets what the data leaves of --mem-mb; 2b. the negative pool. Besides
    // the samples and backgrounds, the data holds the held-out frames (and the detector's
    // pyramid for them) and the Haar pool twice (as features and compiled for the samples).
    let holdout_bytes = holdout.map_or(0, |h| {
        h.frames.iter().map(|f| f.1.as_raw().len() + f.0.len() + 64).sum::<usize>() + HOLDOUT_DETECTOR_BYTES
    });
    let pool_bytes = model.pool.len()
        * (std::mem::size_of::<rccar::detect::cascade::HaarFeature>() + std::mem::size_of::<features::Compiled>());
    let (budget, pool) = negative_pool(opts, positives.len(), backgrounds, holdout_bytes + pool_bytes, progress)?;
    let mut last_check: Option<HoldoutCheck> = None;
    let mut ran_out = false;
    let reason;
    loop {
        let si = model.stages.len();
        if si >= p.num_stages as usize {
            reason = format!("all {} stages trained", p.num_stages);
            break;
        }
        let t0 = Instant::now();
        let cascade: Option<Cascade> = if si == 0 { None } else { Some(model.to_cascade()?) };
        // 2c. The held-out check of the cascade so far (its early stop).
        let est = file.log.last().map_or(1.0, |l| l.acceptance_ratio * l.false_alarm);
        if let Some(r) = early_stop(holdout, cascade.as_ref(), est, &mut last_check, si)? {
            reason = r;
            break;
        }
        // 3. Positives the cascade so far accepts.
        let pos = stage_positives(&pos_pool, cascade.as_ref(), (w, h), opts.num_pos, si)?;
        // 4. Negatives: windows of the pool the cascade so far wrongly accepts.
        let seed = mix(opts.seed ^ (si as u64 + 1).wrapping_mul(0x9E37));
        let mined = pool.mine(backgrounds, cascade.as_ref(), opts.num_neg, seed);
        let t_mine = t0.elapsed().as_secs_f64();
        if let Some((r, out)) = negatives_stop(opts, &mined, si, backgrounds, &pool, holdout, last_check, progress)? {
            (reason, ran_out) = (r, out);
            break;
        }
        let (np, nn) = (pos.len(), mined.windows.len());
        // 5. Feature matrix within the budget.
        let t1 = Instant::now();
        let matrix = feature_matrix(&model, opts, si, budget, &pos, &mined.windows, &mut ii);
        let t_pre = t1.elapsed().as_secs_f64();
        // 6. Boosting until the stage's false-alarm target.
        let t2 = Instant::now();
        let (stage, hit, fa) = boost_stage(p, &matrix, np, nn, si, progress);
        if stage.weaks.is_empty() {
            reason = format!("done after {si} stages: no feature separates the remaining samples");
            break;
        }
        let t_boost = t2.elapsed().as_secs_f64();
        // 7. Save.
        model.stages.push(stage.clone());
        let times = [t_mine, t_pre, t_boost];
        let mut log = stage_log(si, &stage, (hit, fa), (np, nn), &mined, &matrix, times, pool.windows());
        // 8. The held-out check of the new cascade, once it rejects most windows.
        if let Some(chk) = log_holdout(&model, holdout, &mined, fa, &mut log)? {
            last_check = Some(chk);
        }
        log.seconds = t0.elapsed().as_secs_f64();
        progress.stage_end(&log);
        file.stages.push(stage);
        file.log.push(log);
        save(&xml_path, &log_path, &model, &file)?;
    }
    progress.note(&reason);
    above_target_note(holdout, last_check, ran_out, progress);
    file.finished = Some(reason.clone());
    if model.stages.is_empty() {
        return Err(TrainError::Invalid(format!("no stage could be trained: {reason}")));
    }
    save(&xml_path, &log_path, &model, &file)?;
    Ok(TrainOutcome {
        xml: xml_path,
        stages: model.stages.len(),
        reason,
        holdout: last_check,
        negatives_ran_out: ran_out,
    })
}

/// Creates `out_dir`; the paths of its cascade.xml and stages.json.
fn output_paths(out_dir: &Path) -> Result<(PathBuf, PathBuf), TrainError> {
    std::fs::create_dir_all(out_dir).map_err(|err| TrainError::Io {
        path: out_dir.into(),
        err,
    })?;
    Ok((out_dir.join("cascade.xml"), out_dir.join("stages.json")))
}

/// Writes the cascade and the stage log (each atomically).
fn save(xml_path: &Path, log_path: &Path, model: &Model, file: &StageFile) -> Result<(), TrainError> {
    write_atomic(xml_path, &model.to_xml())?;
    write_atomic(log_path, &serde_json::to_string_pretty(file).unwrap_or_default())
}

impl StageFile {
    /// A run with no stage yet.
    fn new(opts: &TrainOptions, positives_total: usize, backgrounds_total: usize) -> StageFile {
        StageFile {
            options: opts.clone(),
            stages: vec![],
            log: vec![],
            finished: None,
            positives_total,
            backgrounds_total,
        }
    }
}

/// Step 3: the first `num_pos` positives of the seeded pool that the cascade so far accepts;
/// an error when fewer than 10 do.
fn stage_positives<'a>(
    pos_pool: &'a [SampleIntegral],
    cascade: Option<&Cascade>,
    (w, h): (usize, usize),
    num_pos: usize,
    si: usize,
) -> Result<Vec<&'a SampleIntegral>, TrainError> {
    let compiled = cascade.map(|c| scan::compile_for_samples(c, w, h));
    let pos: Vec<&SampleIntegral> = pos_pool
        .iter()
        .filter(|s| scan::passes(s, compiled.as_ref()))
        .take(num_pos)
        .collect();
    if pos.len() < 10 {
        return Err(TrainError::Invalid(format!(
            "stage {si}: only {} positives pass the cascade so far (of {}); need at least 10",
            pos.len(),
            pos_pool.len()
        )));
    }
    Ok(pos)
}

/// Step 8: the held-out check of the model so far, once it rejects most windows (before, the
/// raw hits are too many to group quickly and the check could not stop anything), written
/// into the stage's log.
fn log_holdout(
    model: &Model,
    holdout: Option<&Holdout>,
    mined: &scan::Mined,
    fa: f64,
    log: &mut StageLog,
) -> Result<Option<HoldoutCheck>, TrainError> {
    let (scanned, accepted) = (mined.evaluated, mined.accepted);
    let acc_now = if scanned > 0 {
        accepted as f64 / scanned as f64
    } else {
        1.0
    };
    let Some(hd) = holdout.filter(|_| acc_now * fa <= HOLDOUT_FROM) else {
        return Ok(None);
    };
    let c = model.to_cascade()?;
    let chk = check_holdout(&c, hd)?;
    log.holdout_recall = chk.recall;
    log.holdout_fp_per_frame = Some(chk.fp_per_frame);
    log.holdout_fp_per_negative_frame = chk.fp_per_negative_frame;
    Ok(Some(chk))
}

/// Step 2c: the held-out check of the cascade so far, first run once it should reject most
/// windows (`est` ≤ [`HOLDOUT_FROM`]); the reason to stop when it meets the target.
fn early_stop(
    holdout: Option<&Holdout>,
    cascade: Option<&Cascade>,
    est: f64,
    last_check: &mut Option<HoldoutCheck>,
    si: usize,
) -> Result<Option<String>, TrainError> {
    if let (Some(hd), Some(c)) = (holdout, cascade) {
        if last_check.is_none() && est <= HOLDOUT_FROM {
            let chk = check_holdout(c, hd)?;
            *last_check = Some(chk);
        }
        if let Some(chk) = *last_check {
            if chk.fp_per_frame <= hd.target_fp_per_frame {
                return Ok(Some(format!(
                    "held-out target reached after {si} stages: {:.4} false positives per frame <= {}{}",
                    chk.fp_per_frame,
                    hd.target_fp_per_frame,
                    chk.recall.map(|r| format!(", recall {r:.4}")).unwrap_or_default()
                )));
            }
        }
    }
    Ok(None)
}

/// Step 4's outcome: `Some((reason, negatives ran out))` when training stops for want of
/// negatives (an error at stage 0), with a note when it goes on with fewer than asked.
#[allow(clippy::too_many_arguments)]
fn negatives_stop(
    opts: &TrainOptions,
    mined: &scan::Mined,
    si: usize,
    backgrounds: &[Background],
    pool: &scan::NegativePool,
    holdout: Option<&Holdout>,
    last_check: Option<HoldoutCheck>,
    progress: &mut dyn Progress,
) -> Result<Option<(String, bool)>, TrainError> {
    let (w, h) = (opts.params.width as usize, opts.params.height as usize);
    let negs = &mined.windows;
    let (scanned, accepted) = (mined.evaluated, mined.accepted);
    if negs.is_empty() {
        if si == 0 {
            return Err(TrainError::Invalid(format!(
                "no negative windows in the {} background images (each must be at least {w}x{h} and not flat)",
                backgrounds.len()
            )));
        }
        let reason = format!(
            "done after {si} stages: the cascade accepts none of the {scanned} background windows{}",
            if holdout.is_some()
                && last_check.is_some_and(|c| c.fp_per_frame > holdout.map_or(0.0, |h| h.target_fp_per_frame))
            {
                format!(
                    "; {}",
                    more_backgrounds_advice(backgrounds.len(), 0.0, opts.num_neg, pool.windows())
                )
            } else {
                String::new()
            }
        );
        return Ok(Some((reason, holdout.is_some())));
    }
    let min_neg = (opts.num_neg / 10).max(10);
    if mined.exhausted && negs.len() < min_neg {
        let reason = format!(
            "negatives ran out after {si} stages: only {} windows of the {} in the backgrounds \
             (every offset and scale) still pass the cascade, fewer than {min_neg} (num_neg/10). {}",
            negs.len(),
            pool.windows(),
            more_backgrounds_advice(
                backgrounds.len(),
                accepted as f64 / scanned.max(1) as f64,
                opts.num_neg,
                pool.windows()
            )
        );
        return Ok(Some((reason, true)));
    }
    if mined.exhausted {
        progress.note(&format!(
            "stage {si}: only {} negatives left in all {} background windows (asked {}): training on them",
            negs.len(),
            pool.windows(),
            opts.num_neg
        ));
    }
    Ok(None)
}

/// Step 7: the log of a finished stage (its held-out figures and total time come later).
#[allow(clippy::too_many_arguments)]
fn stage_log(
    si: usize,
    stage: &StageModel,
    (hit, fa): (f64, f64),
    (np, nn): (usize, usize),
    mined: &scan::Mined,
    matrix: &FeatureMatrix,
    times: [f64; 3],
    pool_windows: u64,
) -> StageLog {
    let (scanned, accepted) = (mined.evaluated, mined.accepted);
    StageLog {
        stage: si,
        weak_count: stage.weaks.len(),
        hit_rate: hit,
        false_alarm: fa,
        num_pos: np,
        num_neg: nn,
        windows_scanned: scanned,
        windows_accepted: accepted,
        acceptance_ratio: if scanned > 0 {
            accepted as f64 / scanned as f64
        } else {
            0.0
        },
        features_used: matrix.features.len(),
        matrix_bytes: matrix.bytes(),
        seconds_mining: times[0],
        seconds_precompute: times[1],
        seconds_boost: times[2],
        seconds: 0.0,
        pool_windows,
        negatives_exhausted: mined.exhausted,
        holdout_recall: None,
        holdout_fp_per_frame: None,
        holdout_fp_per_negative_frame: None,
    }
}

/// The advice when training ended above the held-out target for another reason than the
/// negatives running out.
fn above_target_note(
    holdout: Option<&Holdout>,
    last_check: Option<HoldoutCheck>,
    ran_out: bool,
    progress: &mut dyn Progress,
) {
    if let (Some(hd), Some(chk)) = (holdout, last_check) {
        if chk.fp_per_frame > hd.target_fp_per_frame && !ran_out {
            progress.note(&format!(
                "held-out false positives {:.4} per frame are above the target {}: more stages (--num-stages), \
                 more backgrounds like the frames with false positives, or a higher --holdout-min-neighbors",
                chk.fp_per_frame, hd.target_fp_per_frame
            ));
        }
    }
}

/// Step 0 of [`train_with_holdout`]: the window, rates, depth, counts and samples, each
/// refused with what is allowed.
fn check_inputs(opts: &TrainOptions, positives: &[Vec<u8>], backgrounds: &[Background]) -> Result<(), TrainError> {
    let p = &opts.params;
    let (w, h) = (p.width as usize, p.height as usize);
    if !(3..=256).contains(&w) || !(3..=256).contains(&h) {
        return Err(TrainError::Invalid(format!(
            "window {w}x{h}: each side must be 3..=256 px"
        )));
    }
    // Written so that NaN fails too.
    let rates_ok = p.min_hit_rate > 0.0 && p.min_hit_rate <= 1.0 && p.max_false_alarm > 0.0 && p.max_false_alarm < 1.0;
    if !rates_ok {
        return Err(TrainError::Invalid(format!(
            "min hit rate {} must be in (0, 1] and max false alarm {} in (0, 1)",
            p.min_hit_rate, p.max_false_alarm
        )));
    }
    if !(1..=2).contains(&p.max_depth) {
        return Err(TrainError::Invalid(format!("max depth {} must be 1 or 2", p.max_depth)));
    }
    if opts.num_pos == 0 || opts.num_neg == 0 {
        return Err(TrainError::Invalid("num_pos and num_neg must be > 0".into()));
    }
    if backgrounds.is_empty() {
        return Err(TrainError::Invalid(
            "no background images: negatives are mined from them (--bg)".into(),
        ));
    }
    if let Some(b) = positives.iter().find(|s| s.len() != w * h) {
        return Err(TrainError::Invalid(format!(
            "a positive has {} pixels, the window {w}x{h} needs {}",
            b.len(),
            w * h
        )));
    }
    Ok(())
}

/// Step 1: the positives' integrals in a seeded order (each stage takes the first accepted
/// ones); windows the detector would never look at (too flat) are left out, with a note.
/// How many of `positives` (`w` × `h` windows) the detector would look at (not too flat):
/// the positives training can use, before any stage drops some.
pub fn usable_positives(positives: &[Vec<u8>], w: usize, h: usize) -> usize {
    let mut ii = Integrals::new();
    positives
        .iter()
        .filter(|s| SampleIntegral::new(s, w, h, &mut ii).scannable)
        .count()
}

fn positive_pool(
    positives: &[Vec<u8>],
    w: usize,
    h: usize,
    seed: u64,
    ii: &mut Integrals,
    progress: &mut dyn Progress,
) -> Vec<SampleIntegral> {
    let pos_all: Vec<SampleIntegral> = positives.iter().map(|s| SampleIntegral::new(s, w, h, ii)).collect();
    let flat = pos_all.iter().filter(|s| !s.scannable).count();
    if flat > 0 {
        progress.note(&format!(
            "{flat} of {} positives are too flat for the detector (grey std dev ≤ 10): left out",
            pos_all.len()
        ));
    }
    let mut pos_pool: Vec<SampleIntegral> = pos_all.into_iter().filter(|s| s.scannable).collect();
    // Seeded order, so each stage takes the first accepted ones.
    let mut rng = SplitMix64::new(seed);
    for i in (1..pos_pool.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        pos_pool.swap(i, j);
    }
    pos_pool
}

/// Step 2, `--resume`: the finished stages of `log_path` into `model` and `file` (the window
/// and mode must match, every feature must be in the pool). `Some` when all stages are done.
fn resume_from(
    log_path: &Path,
    xml_path: &Path,
    model: &mut Model,
    file: &mut StageFile,
    progress: &mut dyn Progress,
) -> Result<Option<TrainOutcome>, TrainError> {
    let p = &file.options.params.clone();
    let text = std::fs::read_to_string(log_path).map_err(|err| TrainError::Io {
        path: log_path.into(),
        err,
    })?;
    let old: StageFile = serde_json::from_str(&text).map_err(|e| TrainError::Resume {
        path: log_path.into(),
        message: format!("not a stages.json: {e}"),
    })?;
    if old.options.params.width != p.width || old.options.params.height != p.height || old.options.params.mode != p.mode
    {
        return Err(TrainError::Resume {
            path: log_path.into(),
            message: format!(
                "it was trained with window {}x{} mode {:?}, this run asks for {}x{} {:?}",
                old.options.params.width, old.options.params.height, old.options.params.mode, p.width, p.height, p.mode
            ),
        });
    }
    if let Some(bad) = old
        .stages
        .iter()
        .flat_map(|s| s.weaks.iter().flat_map(|w| w.splits.iter()))
        .find(|s| s.feature >= model.pool.len())
    {
        return Err(TrainError::Resume {
            path: log_path.into(),
            message: format!("feature {} is outside the pool", bad.feature),
        });
    }
    model.stages = old.stages.clone();
    file.stages = old.stages;
    file.log = old.log;
    progress.note(&format!("resuming after stage {}", model.stages.len()));
    if model.stages.len() >= p.num_stages as usize {
        let reason = old.finished.unwrap_or_else(|| "all stages trained".into());
        return Ok(Some(TrainOutcome {
            xml: xml_path.into(),
            stages: model.stages.len(),
            reason,
            holdout: None,
            negatives_ran_out: false,
        }));
    }
    Ok(None)
}

/// The feature matrix's share of `--mem-mb` (what the data leaves; an error when the data
/// alone does not fit) and step 2b, the negative pool: every window of every background at
/// every scale (noted with its size).
fn negative_pool(
    opts: &TrainOptions,
    positives: usize,
    backgrounds: &[Background],
    other_bytes: usize,
    progress: &mut dyn Progress,
) -> Result<(usize, scan::NegativePool), TrainError> {
    let (w, h) = (opts.params.width as usize, opts.params.height as usize);
    let budget_total = opts.mem_mb.saturating_mul(1 << 20);
    let data = data_bytes(backgrounds, positives, opts.num_neg, w, h) + other_bytes + PROGRAM_BYTES;
    if data >= budget_total {
        return Err(TrainError::Invalid(format!(
            "--mem-mb {}: the backgrounds, held-out frames and samples alone take about {} MiB (plus {} for the \
             program); give at least {} MiB, or fewer/smaller backgrounds",
            opts.mem_mb,
            (data - PROGRAM_BYTES) >> 20,
            PROGRAM_BYTES >> 20,
            (data >> 20) + 32
        )));
    }
    let budget = budget_total - data;
    // 2b. The negative pool: every window of every background at every scale.
    let pool = scan::NegativePool::with_flips(
        backgrounds,
        w,
        h,
        opts.scale_factor,
        opts.mirror_negatives,
        opts.upside_down_negatives,
    );
    progress.note(&format!(
        "negative pool: {} windows of {w}x{h} in {} backgrounds (every offset and scale{}); \
         feature values get {} MiB of --mem-mb {}",
        pool.windows(),
        backgrounds.len(),
        match (opts.mirror_negatives, opts.upside_down_negatives) {
            (true, true) => ", mirrored and upside down too",
            (true, false) => ", mirrored too",
            (false, true) => ", upside down too",
            (false, false) => "",
        },
        budget >> 20,
        opts.mem_mb
    ));
    Ok((budget, pool))
}

/// Step 5: the feature matrix of stage `si` over `pos` then the negative windows `negs`,
/// within `budget` bytes (a seeded part of the pool when all features do not fit).
fn feature_matrix(
    model: &Model,
    opts: &TrainOptions,
    si: usize,
    budget: usize,
    pos: &[&SampleIntegral],
    negs: &[Vec<u8>],
    ii: &mut Integrals,
) -> FeatureMatrix {
    let (w, h) = (opts.params.width as usize, opts.params.height as usize);
    let neg: Vec<SampleIntegral> = negs.iter().map(|s| SampleIntegral::new(s, w, h, ii)).collect();
    let (np, n) = (pos.len(), pos.len() + neg.len());
    // Per feature: one bin byte per sample, up to 255 f32 edges and their Vec (header and the
    // allocator's own bytes).
    let fit = (budget / (n + 1024 + 48)).max(1);
    let mut feats: Vec<usize> = (0..model.pool.len()).collect();
    if feats.len() > fit {
        let mut frng = SplitMix64::new(mix(opts.seed ^ 0xFEA7 ^ si as u64));
        for i in 0..fit {
            let j = i + (frng.next_u64() % (feats.len() - i) as u64) as usize;
            feats.swap(i, j);
        }
        feats.truncate(fit);
        feats.sort_unstable();
    }
    let tofs = features::tilted_offset(w, h);
    let compiled_feats: Vec<features::Compiled> = model
        .pool
        .iter()
        .map(|f| features::Compiled::new(f, w + 1, tofs))
        .collect();
    let sample = |i: usize| if i < np { pos[i] } else { &neg[i - np] };
    FeatureMatrix::build(feats, n, 1024, |f, i| sample(i).value(&compiled_feats[f]))
}

/// Step 6: boosting until the stage's false-alarm target (or `max_weak_count`); the stage
/// and its hit and false-alarm rates as the detector tests them.
fn boost_stage(
    p: &ModelParams,
    matrix: &FeatureMatrix,
    np: usize,
    nn: usize,
    si: usize,
    progress: &mut dyn Progress,
) -> (StageModel, f64, f64) {
    progress.stage_start(si, p.max_weak_count as usize);
    let mut booster = Booster::new(p.boost, np, nn);
    let mut stage = StageModel {
        threshold: 0.0,
        weaks: vec![],
    };
    let (mut hit, mut fa) = (0.0, 1.0);
    while stage.weaks.len() < p.max_weak_count as usize {
        let Some(weak) = booster.add_weak(matrix, p.max_depth) else {
            break;
        };
        stage.weaks.push(weak);
        let mut ps: Vec<f64> = booster.score[..np].to_vec();
        ps.sort_by(|a, b| a.total_cmp(b));
        let idx = (((1.0 - p.min_hit_rate) * np as f64) as usize).min(np - 1);
        stage.threshold = ps[idx] as f32;
        // The detector's test: reject when sum < threshold − 1e-5 (in f32, then widened).
        let eff = (stage.threshold - rccar::detect::cascade::THRESHOLD_EPS) as f64;
        hit = booster.score[..np].iter().filter(|&&s| s >= eff).count() as f64 / np as f64;
        fa = booster.score[np..].iter().filter(|&&s| s >= eff).count() as f64 / nn as f64;
        progress.weak(stage.weaks.len(), hit, fa);
        if fa <= p.max_false_alarm {
            break;
        }
    }
    (stage, hit, fa)
}

/// What to add when the negatives run out: at acceptance ratio `acc` per window, `num_neg`
/// negatives need `num_neg / acc` windows; the pool has `pool` in `n_bg` backgrounds.
pub fn more_backgrounds_advice(n_bg: usize, acc: f64, num_neg: usize, pool: u64) -> String {
    let per_bg = pool as f64 / n_bg.max(1) as f64;
    if acc > 0.0 {
        let need = (num_neg as f64 / acc / per_bg).ceil() as u64;
        format!(
            "To train further add background images without the object — frames like the ones the car \
             will see (the track, the room, the floor), and above all frames where it gives false positives: \
             about {} more of this size ({} in all) would hold {num_neg} false alarms. Or stop here: \
             check the held-out result (rccar-train evaluate).",
            need.saturating_sub(n_bg as u64).max(1),
            need.max(n_bg as u64 + 1)
        )
    } else {
        "To train further add background images without the object, above all frames where the cascade \
         gives false positives (rccar-train evaluate lists them in report.json)."
            .to_string()
    }
}
