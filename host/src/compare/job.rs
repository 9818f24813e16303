//! `tendril compare` as a typed job: read the dataset and robot, check the
//! request and every output path, compare every learner, write the table,
//! the CSV and the figure.

use std::path::{Path, PathBuf};

use super::{all_learners_for, compare, CompareError, CompareOptions, Comparison};
use crate::dataset::Dataset;
use crate::fsutil::check_distinct;
use crate::learn::cascor::job::MAX_HELD_OUT_FRACTION;
use crate::learn::targets::Targets;
use crate::robot::Robot;

/// A comparison run: which data and robot, how, and into which directory.
#[derive(Clone, Debug)]
pub struct CompareJob {
    /// Dataset CSV.
    pub data: PathBuf,
    /// Robot description (TOML).
    pub robot: PathBuf,
    /// Directory for `compare.md`, `compare.csv` and `compare.png`.
    pub out_dir: PathBuf,
    /// Split, seed and evaluation settings.
    pub options: CompareOptions,
}

/// What a comparison run produced.
#[derive(Clone, Debug)]
pub struct CompareResult {
    /// The comparison.
    pub comparison: Comparison,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Check `job`, compare every learner and write the results.
pub fn run(job: &CompareJob) -> Result<CompareResult, CompareError> {
    let o = &job.options;
    for (name, v) in [
        ("--test-fraction", o.test_fraction),
        ("--valid-fraction", o.valid_fraction),
    ] {
        if !(v > 0.0 && v <= MAX_HELD_OUT_FRACTION) {
            return Err(CompareError::BadInput(format!(
                "{name} must be in (0, {MAX_HELD_OUT_FRACTION}], got {v}"
            )));
        }
    }
    let files = output_files(&job.out_dir, o.dump_splits.as_deref());
    let outputs: Vec<(&str, &Path)> = files.iter().map(|(r, p)| (*r, p.as_path())).collect();
    check_distinct(&[("--data", &job.data), ("--robot", &job.robot)], &outputs)?;
    let data = Dataset::read_csv(&job.data).map_err(|e| CompareError::BadInput(e.to_string()))?;
    let robot = Robot::load(&job.robot).map_err(|e| CompareError::BadInput(e.to_string()))?;
    let sidecar = crate::dataset::Sidecar::read(&crate::dataset::Sidecar::path_for(&job.data)).ok();
    let options = CompareOptions {
        targets: Some(Targets::for_dataset(&robot, sidecar.as_ref())),
        ..o.clone()
    };
    let comparison = compare(&data, &robot, all_learners_for(&robot), &options)?;
    let files = comparison.write(&job.out_dir)?;
    Ok(CompareResult { comparison, files })
}

/// Every file the job writes, named by the option that places it.
fn output_files(out_dir: &Path, dump_splits: Option<&Path>) -> Vec<(&'static str, PathBuf)> {
    let mut v: Vec<(&'static str, PathBuf)> = ["compare.md", "compare.csv", "compare.png"]
        .into_iter()
        .map(|f| ("--out", out_dir.join(f)))
        .collect();
    if let Some(dir) = dump_splits {
        v.extend(
            ["fit.csv", "valid.csv", "test.csv"]
                .into_iter()
                .map(|f| ("--dump-splits", dir.join(f))),
        );
    }
    v
}
