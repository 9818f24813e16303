//! The paper's comparison (Table II, Figure 3), done fairly: every learner is
//! trained on the same split with the same normalisation, tunes its
//! hyper-parameters on the same validation split (never the test split) with
//! a comparable budget, and is judged by the same metrics (`docs/design.md` §4) —
//! tension RMSE and, what a user of the robot cares about, the task-space tip
//! error after pushing the predicted tensions through the Cosserat model.

//!
//! - [`registry`]: which learners take part, with their tuning grids;
//! - [`runner`]: fitting, timing and evaluating each on one split;
//! - [`report`]: the table (Markdown, CSV), the figure and the files;
//! - [`job`]: a whole `tendril compare` run.

use std::path::PathBuf;

use crate::dataset::split::{SPLIT_SEED, TEST_FRACTION, VALID_FRACTION};
use crate::evaluate::{EvalError, SplitMetrics};
use crate::learn::targets::Targets;
use crate::learn::LearnError;

pub mod job;
pub mod registry;
pub mod report;
pub mod runner;

pub use registry::{all_learners, all_learners_for, baselines, REFERENCE};
pub use runner::{compare, dump_splits, time_inference, InferenceTime};

/// Why the comparison failed.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The dataset does not fit the robot or is too small to split.
    #[error("{0}")]
    BadInput(String),
    /// A learner failed to fit.
    #[error("{name}: {source}")]
    Learn {
        /// The learner.
        name: String,
        /// Its error.
        source: LearnError,
    },
    /// A metric could not be computed.
    #[error("evaluating {name}: {source}")]
    Eval {
        /// The learner.
        name: String,
        /// Why.
        source: EvalError,
    },
    /// Two of the job's files are the same file.
    #[error(transparent)]
    Paths(#[from] crate::fsutil::PathCollision),
    /// A stop was requested (Ctrl-C, SIGTERM, SIGHUP) between learners.
    #[error("interrupted; nothing was written")]
    Interrupted,
    /// Writing an output failed.
    #[error("writing {path}: {why}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

/// Settings of one comparison run.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// Fraction of rows held out for testing (the paper's 3 %).
    pub test_fraction: f64,
    /// Fraction of the training rows carved off for validation (hyper-parameter choice).
    pub valid_fraction: f64,
    /// Seed of the split and of every learner.
    pub seed: u64,
    /// Training rows pushed through the statics for the train-split task-space
    /// error (a seeded subsample: the full split would cost one Cosserat solve
    /// per row per learner; 0 = all).
    pub train_task_rows: usize,
    /// Test rows timed for the inference times (single and batched,
    /// [`runner::time_inference`]).
    pub timing_queries: usize,
    /// Show a progress bar over learners on stderr.
    pub progress: bool,
    /// Also write the normalised fit / valid / test splits as CSV into this
    /// directory (for the scikit-learn reference in `scripts/python/`).
    pub dump_splits: Option<PathBuf>,
    /// What every learner learns; `None`: [`Targets::for_robot`] the robot.
    pub targets: Option<Targets>,
    /// Leave the training rows whose tip is an outlier out of every
    /// learner's fit and validation (measured rows, `docs/design.md` §3.1).
    pub reject_outliers: bool,
    /// Judge the test split against these true rows instead of the
    /// dataset's own poses (a synthetic benchmark of measured rows).
    pub true_rows: Option<TrueRows>,
}

/// The truth behind synthetic measured rows: the noiseless pose of every
/// row of the dataset (same order) and the robot that produced them. With
/// it, every learner is asked for the true pose of each test row, its
/// tensions are solved on the true robot, and the tip is measured against
/// the true tip.
#[derive(Clone, Debug)]
pub struct TrueRows {
    /// `n × 7` true poses, row `i` the truth of the dataset's row `i`.
    pub poses: nalgebra::DMatrix<f64>,
    /// The robot that made them.
    pub robot: crate::robot::Robot,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            test_fraction: TEST_FRACTION,
            valid_fraction: VALID_FRACTION,
            seed: SPLIT_SEED,
            train_task_rows: 1000,
            timing_queries: 300,
            progress: true,
            dump_splits: None,
            targets: None,
            reject_outliers: false,
            true_rows: None,
        }
    }
}

/// One learner's row of the table.
#[derive(Clone, Debug)]
pub struct Entry {
    /// Learner name.
    pub name: String,
    /// Hyper-parameters chosen on the validation split.
    pub hyper: String,
    /// Stored numbers needed at inference.
    pub parameters: usize,
    /// Wall time of `fit` (tuning included), seconds.
    pub train_seconds: f64,
    /// Mean wall time of one single-row prediction, microseconds.
    pub infer_us: f64,
    /// Mean wall time per row of a batched prediction, microseconds.
    pub infer_batched_us: f64,
    /// Mean wall time of one single-row prediction by the learner's fast
    /// path, not the deployed arithmetic (cascade correlation's relaxed
    /// kernel), microseconds; `None`: no such path (or not on this CPU).
    pub infer_fast_us: Option<f64>,
    /// Metrics on the training split (validation rows excluded); the
    /// task-space part on a seeded subsample of `train_task_rows` rows.
    pub train: SplitMetrics,
    /// Rows of the training split that went through the statics.
    pub train_task_rows: usize,
    /// Metrics on the held-out test split (task space on every row).
    pub test: SplitMetrics,
}

/// The whole comparison.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// Robot name.
    pub robot: String,
    /// Rows used for fitting, validation and testing.
    pub sizes: (usize, usize, usize),
    /// Options it ran with.
    pub options: CompareOptions,
    /// One entry per learner, in the order they ran.
    pub entries: Vec<Entry>,
    /// Sentences on how the rows were treated (outliers left out, the
    /// truth judged against), printed under the table.
    pub notes: Vec<String>,
}
