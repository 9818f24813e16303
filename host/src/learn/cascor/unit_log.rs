//! One row of the training log ([`UnitLog`]): what the output phase, the
//! training loop and the growth all record, below each of them.

use serde::{Deserialize, Serialize};

use super::candidates::Objective;

/// One row of the training log: the net after installing `hidden` units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitLog {
    /// Hidden units installed.
    pub hidden: usize,
    /// Training RMSE (normalised units).
    pub train_rmse: f64,
    /// Validation RMSE (normalised units).
    pub valid_rmse: f64,
    /// Objective score of the installed candidate (NaN for the first row).
    pub score: f64,
    /// Fraction of the residual SSE the installed candidate was predicted to remove.
    pub reduction: f64,
    /// Objective of the installed candidate, if any.
    pub objective: Option<Objective>,
    /// Candidate-phase epochs of the installed candidate.
    pub candidate_epochs: usize,
    /// Output-phase epochs (0 for the ridge solve).
    pub output_epochs: usize,
    /// Wall time since training started, seconds.
    pub seconds: f64,
}
