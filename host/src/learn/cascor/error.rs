//! Why a training job failed ([`TrainError`]): its own module, below the
//! job and the robot lookup that both return it.

use std::path::PathBuf;

use crate::fsutil::PathCollision;
use crate::learn::cascor::export::ExportError;
use crate::learn::LearnError;

/// Why a training run failed; nothing was written.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The request is invalid (too few rows, a fraction out of range, a cap too large).
    #[error("{0}")]
    BadInput(String),
    /// Two of the job's files are the same file.
    #[error(transparent)]
    Paths(#[from] PathCollision),
    /// Training failed or was interrupted.
    // The cause is part of the message and deliberately not a `source`
    // (hence no `#[from]`): `{:#}` would print it twice (issue 31).
    #[error("training: {0}")]
    Learn(LearnError),
    /// The worker pool could not be built.
    #[error("worker threads: {0}")]
    Threads(String),
    /// The weight file could not be written.
    #[error("writing the weight file: {0}")]
    Export(#[from] ExportError),
    /// Another output could not be written.
    #[error("writing {}: {why}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

impl From<LearnError> for TrainError {
    fn from(e: LearnError) -> Self {
        TrainError::Learn(e)
    }
}

impl TrainError {
    /// Whether the run ended because a stop was requested (Ctrl-C).
    pub fn is_interrupted(&self) -> bool {
        matches!(self, TrainError::Learn(LearnError::Interrupted))
    }
}
