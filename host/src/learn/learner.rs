//! The one interface every learner implements.

use nalgebra::DMatrix;

/// A view of normalised data: one row per sample.
#[derive(Clone, Copy, Debug)]
pub struct Split<'a> {
    /// Inputs, `n × inputs`, each column in [0, 1] on the training split.
    pub x: &'a DMatrix<f64>,
    /// Targets, `n × outputs`, each column in [0, 1] on the training split.
    pub y: &'a DMatrix<f64>,
}

impl Split<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.x.nrows()
    }

    /// Whether the split holds no sample.
    pub fn is_empty(&self) -> bool {
        self.x.nrows() == 0
    }
}

/// Why fitting a learner failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// The data cannot be learnt from (empty, mismatched shapes, non-finite values).
    #[error("bad training data: {0}")]
    BadData(String),
    /// A hyper-parameter is out of its valid range.
    #[error("bad hyper-parameter {name}: {why}")]
    BadParameter {
        /// The option's name.
        name: &'static str,
        /// What is wrong with it.
        why: String,
    },
    /// A numerical step failed (singular system, divergence).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// A regression learner trained on normalised data.
///
/// `fit` may tune its own hyper-parameters, but only on `valid` — a split
/// carved from the training data, never the test split.
pub trait Learner: Send {
    /// Short display name for tables and plots ("KNN", "Cascade correlation", …).
    fn name(&self) -> &str;

    /// Fit on `train`, choosing hyper-parameters on `valid`. Deterministic for a `seed`.
    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError>;

    /// Predict normalised outputs for normalised inputs (`n × inputs` → `n × outputs`).
    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64>;

    /// Number of stored numbers the model needs at inference (weights, centres, tree nodes…).
    fn parameter_count(&self) -> usize;

    /// The hyper-parameters chosen by `fit`, for the comparison table.
    fn describe(&self) -> String;
}
