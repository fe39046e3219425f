//! rccar's cascade trainer: what OpenCV's removed `opencv_createsamples` and
//! `opencv_traincascade` did, in Rust, writing OpenCV's current cascade XML (read by rccar's
//! detector and by `cv2.CascadeClassifier`). Never part of the car's runtime.
//!
//! ```text
//! simgen    render positives / negatives / held-out frames with the simulator  (simgen.rs)
//! distort   template images distorted over backgrounds                       (distort.rs)
//! samples   info.dat positives, bg.txt negatives                                 (samples.rs)
//! train     stage loop: mine hard negatives, precompute, boost, save            (train.rs)
//!           features.rs (Haar pool), boost.rs (Gentle/Real/Discrete/Logit), model.rs (XML)
//! evaluate  recall, precision, FP per frame, curve over minNeighbors            (evaluate.rs)
//! boxes     a boxes CSV to info.dat, with previews                              (annotate.rs)
//! plan      window and sample counts chosen from the data                       (plan.rs)
//! photoset  photo-like labelled frames: the sim's sign on system photos         (photogen.rs)
//! pilot     the learned pilot: data from the simulator or recordings, training  (pilot/)
//! ```
//!
//! Usage: `training/README.md`, `docs/training.md`.

pub mod annotate;
pub mod boost;
pub mod distort;
pub mod evaluate;
pub mod features;
pub mod model;
pub mod photogen;
pub mod pilot;
pub mod plan;
pub mod samples;
pub mod scan;
pub mod simgen;
pub mod train;
