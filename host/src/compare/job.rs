//! `tendril compare` as a typed job: read the dataset and robot, check the
//! request and every output path, compare every learner, write the table,
//! the CSV and the figure.

use std::path::{Path, PathBuf};

use super::{all_learners_for, compare, CompareError, CompareOptions, Comparison};
use crate::dataset::Dataset;
use crate::fsutil::check_distinct;
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
    /// Leave outliers out of the fits (`Some(true)`), keep them
    /// (`Some(false)`); `None`: leave them out when the dataset has no
    /// sidecar (measured rows, `docs/design.md` §3.1).
    pub reject_outliers: Option<bool>,
    /// The noiseless rows behind synthetic measured rows, and the robot
    /// that made them ([`super::TrueRows`]): both or neither.
    pub truth: Option<(PathBuf, PathBuf)>,
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
    crate::dataset::split::check_test_fraction(o.test_fraction).map_err(CompareError::BadInput)?;
    // Every baseline stops early on its validation rows: none is refused too.
    if o.valid_fraction == 0.0 {
        return Err(CompareError::BadInput(
            "--valid-fraction must be > 0: the baselines stop early on their validation rows"
                .into(),
        ));
    }
    crate::dataset::split::check_valid_fraction(o.valid_fraction)
        .map_err(CompareError::BadInput)?;
    let files = output_files(&job.out_dir, o.dump_splits.as_deref());
    let outputs: Vec<(&str, &Path)> = files.iter().map(|(r, p)| (*r, p.as_path())).collect();
    let mut inputs: Vec<(&str, &Path)> = vec![("--data", &job.data), ("--robot", &job.robot)];
    if let Some((d, r)) = &job.truth {
        inputs.push(("--true-data", d));
        inputs.push(("--true-robot", r));
    }
    check_distinct(&inputs, &outputs)?;
    let bad = |e: &dyn std::fmt::Display| CompareError::BadInput(e.to_string());
    let mut data = Dataset::read_csv(&job.data).map_err(|e| bad(&e))?;
    let robot = Robot::load(&job.robot).map_err(|e| bad(&e))?;
    crate::dataset::measured::check_rows(&data, &robot, &job.data).map_err(|e| bad(&e))?;
    let side_path = crate::dataset::Sidecar::path_for(&job.data);
    let measured = !side_path.exists() || job.reject_outliers.is_some();
    if measured {
        crate::dataset::measured::canonical_quaternions(&mut data);
    }
    let sidecar = crate::dataset::Sidecar::read(&side_path).ok();
    let true_rows = match &job.truth {
        None => None,
        Some((d, r)) => {
            let t = Dataset::read_csv(d).map_err(|e| bad(&e))?;
            let robot = Robot::load(r).map_err(|e| bad(&e))?;
            if t.len() != data.len() || t.tensions != data.tensions {
                return Err(CompareError::BadInput(format!(
                    "--true-data {} is not the truth of --data {}: its tensions are not the \
                     same rows",
                    d.display(),
                    job.data.display()
                )));
            }
            Some(super::TrueRows {
                poses: t.poses,
                robot,
            })
        }
    };
    let options = CompareOptions {
        targets: Some(Targets::for_dataset(&robot, sidecar.as_ref())),
        reject_outliers: job.reject_outliers.unwrap_or(measured),
        true_rows,
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
