//! The tension ↔ tip-pose dataset (docs/design.md §3): sampling tensions,
//! solving the statics for each, CSV + JSON sidecar, the train/test split and
//! min–max normalisation.
//!
//! Learners see poses (px, py, pz, qw, qx, qy, qz) as inputs and tensions as
//! outputs. With four antagonistic tendons, the `uniform` sampler makes the
//! inverse map non-unique (co-contracting opposite tendons hardly moves the
//! tip), so no learner's tension-space error means much on such data; the
//! `adjacent` sampler (two neighbouring tendons pulling) keeps it a function.

pub mod disk;
pub mod generate;
pub mod io;
pub mod measured;
pub mod resolve;
pub mod sample;
pub mod split;

pub use io::{Dataset, DatasetError, ResidualRecord, Sidecar};
pub use resolve::Resolve;
pub use sample::Sampler;
pub use split::{prepare, prepare_excluding, split_indices, MinMax, Prepared};

/// Names of the pose columns, in order.
pub const POSE_COLUMNS: [&str; 7] = ["px", "py", "pz", "qw", "qx", "qy", "qz"];
