//! Evaluation of a `.tnet` net as a typed job — what `tendril evaluate` and
//! the main job do: the `docs/design.md` §4 metrics (tension RMSE, task-space
//! tip error through the statics, inference time) through the exported f32
//! weights, i.e. the firmware's arithmetic.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::{EvalError, SplitMetrics};
use crate::dataset::{split_indices, Dataset, DatasetError, Sidecar};
use crate::fsutil::{check_distinct, write_atomic, PathCollision};
use crate::learn::cascor::export::{infer_batch, read_tnet, ExportError, HostNet};
use crate::learn::cascor::job::MAX_HELD_OUT_FRACTION;
use crate::robot::{Robot, RobotError};
use crate::statics::{SolverSettings, Statics};

/// Which rows of the dataset to evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RowSelection {
    /// Every row (e.g. a separate test file).
    All,
    /// Only the held-out test split a training run with this seed and test
    /// fraction left out.
    Test {
        /// Split seed (`tendril train --seed`).
        seed: u64,
        /// Test fraction (`tendril train --test-fraction`), in (0, 0.5].
        test_fraction: f64,
    },
}

/// An evaluation: which net, on which data and robot, where the JSON goes.
#[derive(Clone, Debug)]
pub struct EvaluateJob {
    /// Weight file written by `tendril train`.
    pub model: PathBuf,
    /// Dataset CSV with the true tensions and poses.
    pub data: PathBuf,
    /// Robot description (TOML) the task-space error is computed with.
    pub robot: PathBuf,
    /// Rows to evaluate.
    pub rows: RowSelection,
    /// Metrics JSON to write.
    pub json_out: PathBuf,
}

/// What an evaluation measured.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The metrics.
    pub metrics: SplitMetrics,
    /// Hidden units of the evaluated net.
    pub hidden_units: usize,
}

/// Why an evaluation failed; nothing was written.
#[derive(Debug, thiserror::Error)]
pub enum EvaluateError {
    /// The request or the data cannot give a meaningful number.
    #[error("{0}")]
    BadInput(String),
    /// Two of the job's files are the same file.
    #[error(transparent)]
    Paths(#[from] PathCollision),
    /// The weight file could not be read.
    #[error(transparent)]
    Model(#[from] ExportError),
    /// The dataset could not be read.
    #[error(transparent)]
    Data(#[from] DatasetError),
    /// The robot file could not be loaded.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// A metric could not be computed.
    #[error(transparent)]
    Metric(#[from] EvalError),
    /// The metrics JSON could not be written.
    #[error("writing {}: {why}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

/// The metrics JSON.
#[derive(Serialize)]
struct EvaluationFile<'a> {
    model: String,
    data: String,
    rows: &'static str,
    hidden_units: usize,
    metrics: &'a SplitMetrics,
}

/// Run the evaluation and write its JSON (atomically, after every check).
pub fn run(job: &EvaluateJob) -> Result<Evaluation, EvaluateError> {
    check_distinct(
        &[
            ("--model", &job.model),
            ("--data", &job.data),
            ("--robot", &job.robot),
        ],
        &[("--json-out", &job.json_out)],
    )?;
    if let RowSelection::Test { test_fraction, .. } = job.rows {
        if !(test_fraction > 0.0 && test_fraction <= MAX_HELD_OUT_FRACTION) {
            return Err(EvaluateError::BadInput(format!(
                "--test-fraction must be in (0, {MAX_HELD_OUT_FRACTION}], got {test_fraction}"
            )));
        }
    }
    let net = read_tnet(&job.model)?;
    let robot = Robot::load(&job.robot)?;
    let mut data = Dataset::read_csv(&job.data)?;
    if let RowSelection::Test {
        seed,
        test_fraction,
    } = job.rows
    {
        let (_, test) = split_indices(data.len(), test_fraction, seed);
        data = data.rows(&test);
    }
    if data.is_empty() {
        return Err(EvaluateError::BadInput(format!(
            "no rows to evaluate: {} selects none of the rows of {}",
            match job.rows {
                RowSelection::All => "--rows all",
                RowSelection::Test { .. } => "--rows test",
            },
            job.data.display()
        )));
    }
    let statics = Statics::new(&robot, settings_for(&job.data));
    let metrics = evaluate_net(&statics, &net, &data)?;
    let file = EvaluationFile {
        model: job.model.display().to_string(),
        data: job.data.display().to_string(),
        rows: match job.rows {
            RowSelection::All => "all",
            RowSelection::Test { .. } => "test",
        },
        hidden_units: net.shape().hidden,
        metrics: &metrics,
    };
    let werr = |why: String| EvaluateError::Write {
        path: job.json_out.clone(),
        why,
    };
    // Through a `Value`, so keys come out sorted as in every earlier file.
    let json = serde_json::to_value(&file)
        .and_then(|v| serde_json::to_string_pretty(&v))
        .map_err(|e| werr(e.to_string()))?;
    write_atomic(&job.json_out, json.as_bytes()).map_err(|e| werr(e.to_string()))?;
    Ok(Evaluation {
        metrics,
        hidden_units: net.shape().hidden,
    })
}

/// Mean wall time of one f32 inference (ns), timing batches on one thread
/// for ≥ 50 ms; `None` without a pose to time.
pub fn inference_ns(net: &HostNet, poses: &nalgebra::DMatrix<f64>) -> Option<f64> {
    if poses.nrows() == 0 {
        return None;
    }
    let mut n = 0usize;
    let t = Instant::now();
    while t.elapsed().as_millis() < 50 {
        std::hint::black_box(infer_batch(net, std::hint::black_box(poses)));
        n += poses.nrows();
    }
    Some(t.elapsed().as_nanos() as f64 / n as f64)
}

/// Metrics of `net` on every row of `data` (at least one), with the statics
/// of `statics`.
pub fn evaluate_net(
    statics: &Statics,
    net: &HostNet,
    data: &Dataset,
) -> Result<SplitMetrics, EvaluateError> {
    if net.shape().outputs != data.n_tendons {
        return Err(EvaluateError::BadInput(format!(
            "the model predicts {} tensions but the data has {} tendons",
            net.shape().outputs,
            data.n_tendons
        )));
    }
    if statics.robot().n_tendons() != data.n_tendons {
        return Err(EvaluateError::BadInput(format!(
            "the robot has {} tendons but the data has {}",
            statics.robot().n_tendons(),
            data.n_tendons
        )));
    }
    let Some(ns) = inference_ns(net, &data.poses) else {
        return Err(EvaluateError::BadInput("no rows to evaluate".into()));
    };
    let pred = infer_batch(net, &data.poses);
    let lo: Vec<f64> = net.output_lo().iter().map(|&x| f64::from(x)).collect();
    let hi: Vec<f64> = net.output_hi().iter().map(|&x| f64::from(x)).collect();
    Ok(SplitMetrics::compute(
        statics,
        &pred,
        &data.tensions,
        &data.poses,
        &lo,
        &hi,
        ns,
    )?)
}

/// Solver settings of the dataset's sidecar if it has one (so predicted and
/// true poses come from the same discretisation), else the defaults.
pub fn settings_for(data: &Path) -> SolverSettings {
    Sidecar::read(&Sidecar::path_for(data))
        .map(|s| s.solver)
        .unwrap_or_default()
}
