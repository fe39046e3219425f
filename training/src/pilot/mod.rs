//! `rccar-train pilot`: trains the learned pilot ([`rccar::control::learned`]) on examples
//! of the classical controller, in Rust on the CPU, and writes its weights file.
//!
//! 1. **Data**: simulator drives with noise on the steering ([`data::from_sim`]) and/or
//!    recordings ([`data::from_recording`]), split by time ([`data::split_by_time`]).
//! 2. **Epochs**: the training examples shuffled, in mini-batches; each example mirrored
//!    (label negated) with probability ½ and its light jittered; the batch's gradient summed
//!    over threads (rayon) and one Adam step ([`net::Adam`]) on the mean.
//! 3. **Validation** after each epoch on the later part of each drive, unaugmented; the
//!    weights of the best epoch are kept, and training stops after `patience` epochs
//!    without a better one (early stopping).
//! 4. The weights file, and `loss.png` (training and validation loss per epoch) and
//!    `loss.csv` beside it.

pub mod data;
pub mod net;

use data::Sample;
use net::{Adam, Params, INPUT_LEN};
use rayon::prelude::*;
use rccar::sim::rng::SplitMix64;
use std::collections::BTreeMap;

/// Settings of a training run.
#[derive(Debug, Clone)]
pub struct TrainOptions {
    /// Most passes over the training examples.
    pub max_epochs: usize,
    /// Stop after this many epochs without a lower validation loss.
    pub patience: usize,
    /// Examples per Adam step.
    pub batch: usize,
    /// Adam's learning rate.
    pub lr: f32,
    /// Seed of the initial weights, the shuffling and the augmentations.
    pub seed: u64,
    /// Mirror-and-negate augmentation.
    pub mirror: bool,
    /// Light augmentation.
    pub light: bool,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            max_epochs: 40,
            patience: 6,
            batch: 32,
            lr: 1e-3,
            seed: 1,
            mirror: true,
            light: true,
        }
    }
}

/// One epoch's losses (mean squared steering error, steer units²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochLog {
    /// Epoch, from 1.
    pub epoch: usize,
    /// Mean loss over the epoch's training batches (augmented).
    pub train: f64,
    /// Mean loss on the validation examples.
    pub val: f64,
    /// Seconds since training started.
    pub seconds: f64,
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct Trained {
    /// The weights of the best epoch.
    pub params: Params,
    /// Every epoch's losses.
    pub log: Vec<EpochLog>,
    /// The epoch whose weights were kept.
    pub best_epoch: usize,
}

/// Mean squared error of `p` on `samples` (no augmentation).
pub fn mse(p: &Params, samples: &[Sample]) -> f64 {
    if samples.is_empty() {
        return f64::NAN;
    }
    let s: f64 = samples
        .par_iter()
        .map(|s| {
            let (y, _) = net::forward(p, &s.input);
            ((y - s.steer) as f64).powi(2)
        })
        .sum();
    s / samples.len() as f64
}

/// Trains on `train`, validating on `val`; `each_epoch` sees every epoch's log, `each_batch`
/// (examples done, examples in the epoch) the progress inside one.
pub fn train(
    train: &[Sample],
    val: &[Sample],
    o: &TrainOptions,
    each_epoch: &mut dyn FnMut(&EpochLog),
    each_batch: &mut dyn FnMut(usize, usize),
) -> Trained {
    let t0 = std::time::Instant::now();
    let mut p = Params::init(o.seed);
    let mut adam = Adam::new(o.lr, 1e-4);
    let mut rng = SplitMix64::new(rccar::sim::rng::mix(o.seed ^ 0xDA7A));
    let mut order: Vec<usize> = (0..train.len()).collect();
    let mut best = (f64::INFINITY, p.clone(), 0usize);
    let mut log = Vec::new();
    for epoch in 1..=o.max_epochs {
        // Fisher–Yates
        for i in (1..order.len()).rev() {
            order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        let mut sum = 0.0f64;
        for (b, chunk) in order.chunks(o.batch.max(1)).enumerate() {
            // each example's own seed: the result does not depend on how threads split the batch
            let seeds: Vec<u64> = chunk.iter().map(|_| rng.next_u64()).collect();
            let (g, loss) = chunk
                .par_iter()
                .zip(&seeds)
                .fold(
                    || (Params::zeros(), 0.0f64),
                    |(mut g, loss), (&i, &seed)| {
                        let s = &train[i];
                        let mut r = SplitMix64::new(seed);
                        let flip = o.mirror && r.next_f64() < 0.5;
                        let mut x = if flip { data::mirror(&s.input) } else { s.input.clone() };
                        if o.light {
                            data::jitter_light(&mut x, &mut r);
                        }
                        let t = if flip { -s.steer } else { s.steer };
                        let (y, tr) = net::forward(&p, &x);
                        net::backward(&p, &tr, y, t, &mut g);
                        (g, loss + ((y - t) as f64).powi(2))
                    },
                )
                .reduce(
                    || (Params::zeros(), 0.0),
                    |(mut a, la), (b, lb)| {
                        a.add(&b);
                        (a, la + lb)
                    },
                );
            let mut g = g;
            let scale = 1.0 / chunk.len() as f32;
            g.t.iter_mut().flatten().for_each(|v| *v *= scale);
            adam.update(&mut p, &g);
            sum += loss;
            each_batch((b + 1) * o.batch.max(1), train.len());
        }
        let val_loss = mse(&p, val);
        let entry = EpochLog {
            epoch,
            train: sum / train.len().max(1) as f64,
            val: val_loss,
            seconds: t0.elapsed().as_secs_f64(),
        };
        each_epoch(&entry);
        log.push(entry);
        if val_loss < best.0 || (val.is_empty() && epoch == o.max_epochs) {
            best = (val_loss, p.clone(), epoch);
        } else if epoch - best.2 >= o.patience {
            break;
        }
    }
    if best.2 == 0 {
        best = (f64::NAN, p, log.len());
    }
    Trained {
        params: best.1,
        log,
        best_epoch: best.2,
    }
}

/// The weights file's metadata for a run: the data, the settings and the losses.
pub fn metadata(t: &Trained, n_train: usize, n_val: usize, o: &TrainOptions, data: &str) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let best = t.log.iter().find(|e| e.epoch == t.best_epoch);
    m.insert("trained_by".into(), format!("rccar-train pilot {}", env!("CARGO_PKG_VERSION")));
    m.insert("data".into(), data.into());
    m.insert("examples".into(), format!("{n_train} training, {n_val} validation (split by time)"));
    m.insert(
        "settings".into(),
        format!(
            "batch {}, Adam lr {}, seed {}, mirror {}, light {}, patience {}",
            o.batch, o.lr, o.seed, o.mirror, o.light, o.patience
        ),
    );
    if let Some(b) = best {
        m.insert(
            "best_epoch".into(),
            format!("{} of {}: train MSE {:.5}, validation MSE {:.5}, {:.0} s", b.epoch, t.log.len(), b.train, b.val, b.seconds),
        );
    }
    m
}

/// `loss.csv`: epoch, train, val, seconds.
pub fn loss_csv(log: &[EpochLog]) -> String {
    let mut s = String::from("epoch,train_mse,val_mse,seconds\n");
    for e in log {
        s += &format!("{},{:.6},{:.6},{:.1}\n", e.epoch, e.train, e.val, e.seconds);
    }
    s
}

/// `loss.png`: training and validation loss per epoch (the simulator's plot style).
pub fn loss_plot(log: &[EpochLog]) -> Result<image::RgbImage, String> {
    use rccar::sim::plot::{fields_plot, Trace};
    let pts = |f: fn(&EpochLog) -> f64| vec![log.iter().map(|e| (e.epoch as f64, f(e))).collect::<Vec<_>>()];
    fields_plot(
        "epoch",
        &["steering MSE".to_string()],
        &[
            Trace {
                label: "training (augmented)".into(),
                panels: pts(|e| e.train),
            },
            Trace {
                label: "validation (later frames)".into(),
                panels: pts(|e| e.val),
            },
        ],
    )
    .map_err(|e| e.to_string())
}

/// One row of the held-out report: a predictor's steering error against the labels.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutRow {
    /// What predicted.
    pub name: String,
    /// Frames it was scored on.
    pub frames: usize,
    /// Root mean squared error, steer units.
    pub rmse: f64,
    /// Mean absolute error, steer units.
    pub mae: f64,
}

fn row(name: &str, pairs: impl Iterator<Item = (f64, f64)>) -> HeldOutRow {
    let (mut n, mut se, mut ae) = (0usize, 0.0f64, 0.0f64);
    for (y, t) in pairs {
        n += 1;
        se += (y - t).powi(2);
        ae += (y - t).abs();
    }
    HeldOutRow {
        name: name.into(),
        frames: n,
        rmse: (se / n as f64).sqrt(),
        mae: ae / n as f64,
    }
}

/// The held-out (later) frames scored three ways: the learned pilot, the training labels'
/// mean (a net that learned nothing from the image), and the classical pipeline (`cfg`,
/// run in time order over the held-out frames read from disk, so its filters and PID see
/// a sequence). The classical row is `Err(why)` when it cannot be run (simulator drives
/// keep no frames on disk).
pub fn held_out_report(
    p: &Params,
    train: &[Sample],
    val: &[Sample],
    cfg: &rccar::config::Config,
) -> (Vec<HeldOutRow>, Result<HeldOutRow, String>) {
    let mean = train.iter().map(|s| s.steer as f64).sum::<f64>() / train.len().max(1) as f64;
    let learned = row(
        "learned pilot",
        val.iter().map(|s| (net::forward(p, &s.input).0 as f64, s.steer as f64)),
    );
    let base = row(
        &format!("training mean ({mean:+.3})"),
        val.iter().map(|s| (mean, s.steer as f64)),
    );
    let classical = (|| {
        if val.is_empty() {
            return Err("no held-out frames".to_string());
        }
        if val.iter().any(|s| s.image.is_none()) {
            return Err("simulator drives keep no frames on disk (train from a recording to compare)".into());
        }
        let mut pipe = rccar::pipeline::Pipeline::new(cfg).map_err(|e| e.to_string())?;
        let mut pairs = Vec::with_capacity(val.len());
        let mut prev: Option<f64> = None;
        let mut lost = 0usize;
        for s in val {
            let (path, t) = s.image.as_ref().expect("checked");
            let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?.to_rgb8();
            let dt = prev.map_or(1.0 / cfg.camera.fps, |p| (t - p).clamp(1e-3, 1.0));
            prev = Some(*t);
            let out = pipe.step(&img, dt, &mut rccar::timing::NoTimer);
            lost += usize::from(out.lane.lane_center.is_none());
            pairs.push((out.command.steer, s.steer as f64));
        }
        let mut r = row("classical pipeline (default config)", pairs.into_iter());
        if lost > 0 {
            r.name = format!("{} [lane lost on {lost}]", r.name);
        }
        Ok(r)
    })();
    (vec![learned, base], classical)
}

/// The held-out report as a text table (also written to NAME.report.txt).
pub fn report_table(rows: &[HeldOutRow], classical: &Result<HeldOutRow, String>) -> String {
    let mut s = format!("{:<52} {:>7} {:>8} {:>8}\n", "held-out (later) frames, steering vs label", "frames", "RMSE", "MAE");
    let mut line = |r: &HeldOutRow| s += &format!("{:<52} {:>7} {:>8.4} {:>8.4}\n", r.name, r.frames, r.rmse, r.mae);
    rows.iter().for_each(&mut line);
    match classical {
        Ok(r) => line(r),
        Err(why) => s += &format!("{:<52} not run: {why}\n", "classical pipeline (default config)"),
    }
    s
}

/// Input length (re-exported for the binary).
pub const INPUT: usize = INPUT_LEN;

#[cfg(test)]
mod tests {
    use super::*;

    /// A short run on a synthetic task the network can learn (the label is the brightness
    /// difference between the image's halves, as a line left or right of centre would be)
    /// lowers the validation loss to under a quarter of the start's within 8 epochs.
    #[test]
    fn a_short_training_run_lowers_the_loss() {
        let mut r = SplitMix64::new(5);
        let make = |r: &mut SplitMix64| {
            let pos = r.next_f64() as f32; // where a bright stripe is, 0..1 across
            let col = (pos * (rccar::control::learned::IN_W - 4) as f32) as usize;
            let mut x = vec![0.2f32; INPUT_LEN];
            for row in x.chunks_exact_mut(rccar::control::learned::IN_W) {
                row[col..col + 3].fill(0.9);
            }
            Sample {
                input: x,
                steer: (pos - 0.5) * 1.2,
                image: None,
            }
        };
        let tr: Vec<Sample> = (0..600).map(|_| make(&mut r)).collect();
        let va: Vec<Sample> = (0..100).map(|_| make(&mut r)).collect();
        let o = TrainOptions {
            max_epochs: 8,
            patience: 8,
            light: false,
            ..Default::default()
        };
        let start = mse(&Params::init(o.seed), &va);
        let t = train(&tr, &va, &o, &mut |_| {}, &mut |_, _| {});
        let end = mse(&t.params, &va);
        eprintln!("validation MSE {start:.4} -> {end:.4}; {:?}", t.log);
        assert!(end < 0.25 * start, "{start} -> {end}");
        assert!(end < 0.01, "{end}");
    }
}
