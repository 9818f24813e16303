//! Evaluation of a `.tnet` net as a typed job — what `tendril evaluate` and
//! the main job do: the `docs/design.md` §4 metrics (tension RMSE, task-space
//! tip error through the statics, inference time) through the exported f32
//! weights, i.e. the firmware's arithmetic.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use tendril_shared::McuNet;

use crate::dataset::{split_indices, Dataset, DatasetError, Sidecar};
use crate::evaluate::{ErrorStats, EvalError, SplitMetrics};
use crate::fsutil::{check_distinct, write_atomic, PathCollision};
use crate::inverse::{ExactIk, IkSettings, InverseError, Target};
use crate::net::{
    check_model_robot, infer_batch, pose_rows, read_model, HostNet, ReadError, RobotMismatch,
    CLI_OVERRIDE,
};
use crate::robot::{Robot, RobotError};
use crate::statics::{SolverSettings, Statics};

/// Which rows of the dataset to evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RowSelection {
    /// Every row (e.g. a separate test file).
    All,
    /// Only the held-out test split the training run left out: the seed
    /// and test fraction the net records (`docs/design.md` §5.1); one
    /// given here must agree with them. A net that records none (version
    /// 1) takes these, or the trainer's defaults.
    Test {
        /// Split seed (`tendril train --seed`).
        seed: Option<u64>,
        /// Test fraction (`tendril train --test-fraction`), in (0, 0.5].
        test_fraction: Option<f64>,
    },
}

/// The split `rows` selects for a net that records `recorded`: the
/// recorded split, unless a given value disagrees (an error: the rows it
/// would select include training rows).
fn test_split(
    model: &Path,
    seed: Option<u64>,
    test_fraction: Option<f64>,
    recorded: Option<tendril_shared::SplitRecord>,
) -> Result<(u64, f64), EvaluateError> {
    use crate::dataset::split::{SPLIT_SEED, TEST_FRACTION};
    let Some(r) = recorded else {
        log::warn!(
            "{}: the net does not record its training split; --rows test uses --seed {} and \
             --test-fraction {}, which must be the ones `tendril train` was given",
            model.display(),
            seed.unwrap_or(SPLIT_SEED),
            test_fraction.unwrap_or(TEST_FRACTION)
        );
        return Ok((
            seed.unwrap_or(SPLIT_SEED),
            test_fraction.unwrap_or(TEST_FRACTION),
        ));
    };
    let disagree = |what: &str, given: String, net: String| {
        EvaluateError::BadInput(format!(
            "{what} {given} is not the one the net {} was trained with ({net}): --rows test \
             would score rows the net was fitted on; leave {what} out (the net records its split)",
            model.display()
        ))
    };
    if let Some(s) = seed.filter(|&s| s != r.seed) {
        return Err(disagree("--seed", s.to_string(), r.seed.to_string()));
    }
    if let Some(f) = test_fraction.filter(|&f| f != r.test_fraction) {
        return Err(disagree(
            "--test-fraction",
            f.to_string(),
            r.test_fraction.to_string(),
        ));
    }
    Ok((r.seed, r.test_fraction))
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
    /// Evaluate a net that records another robot than `robot` (a warning)
    /// instead of refusing it ([`crate::net::check_model_robot`]).
    pub allow_robot_mismatch: bool,
    /// Metrics JSON to write.
    pub json_out: PathBuf,
}

/// Rows the exact refinement runs on (the first ones of the selection):
/// each costs milliseconds where the net alone costs microseconds.
pub const REFINE_ROWS: usize = 200;

/// The net alone against the net's guess refined by the exact IK
/// (`docs/design.md` §4.1), on the same rows, full pose targets.
#[derive(Clone, Debug, Serialize)]
pub struct Refinement {
    /// Rows compared.
    pub rows: usize,
    /// Tip position error of the net alone (through the command stage), mm.
    pub net_tip_error_mm: ErrorStats,
    /// Tip position error after exact refinement, mm (closest pose where
    /// the target is out of reach).
    pub refined_tip_error_mm: ErrorStats,
    /// Targets the exact IK found out of reach.
    pub unreachable: usize,
    /// Targets where the exact IK gave up (not converged).
    pub failed: usize,
    /// The net's inference alone, µs per query, one thread.
    pub net_us_per_query: f64,
    /// Net inference plus exact refinement, µs per query, one thread.
    pub refined_us_per_query: f64,
}

/// What an evaluation measured.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The metrics.
    pub metrics: SplitMetrics,
    /// Net alone vs net + exact refinement.
    pub refinement: Refinement,
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
    Model(#[from] ReadError),
    /// The dataset could not be read.
    #[error(transparent)]
    Data(#[from] DatasetError),
    /// The robot file could not be loaded.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The net was trained for another robot.
    #[error(transparent)]
    Mismatch(#[from] RobotMismatch),
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
    refinement: &'a Refinement,
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
    if let RowSelection::Test {
        test_fraction: Some(test_fraction),
        ..
    } = job.rows
    {
        crate::dataset::split::check_test_fraction(test_fraction)
            .map_err(EvaluateError::BadInput)?;
    }
    let (net, provenance) = read_model(&job.model)?;
    let robot = Robot::load(&job.robot)?;
    check_model_robot(
        &job.model,
        provenance.as_ref(),
        &robot,
        job.allow_robot_mismatch,
        CLI_OVERRIDE,
    )?;
    let mut data = Dataset::read_csv(&job.data)?;
    if let RowSelection::Test {
        seed,
        test_fraction,
    } = job.rows
    {
        let recorded = provenance.and_then(|p| p.split);
        let (seed, test_fraction) = test_split(&job.model, seed, test_fraction, recorded)?;
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
    let refinement = refine(&statics, &net, &data)?;
    let file = EvaluationFile {
        model: job.model.display().to_string(),
        data: job.data.display().to_string(),
        rows: match job.rows {
            RowSelection::All => "all",
            RowSelection::Test { .. } => "test",
        },
        hidden_units: net.shape().hidden,
        metrics: &metrics,
        refinement: &refinement,
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
        refinement,
        hidden_units: net.shape().hidden,
    })
}

/// Net alone vs net + exact refinement on the first [`REFINE_ROWS`] rows of
/// `data` (the tendon counts already checked by [`evaluate_net`]).
pub fn refine(
    statics: &Statics,
    net: &McuNet,
    data: &Dataset,
) -> Result<Refinement, EvaluateError> {
    let robot = statics.robot();
    // The net's tensions through the firmware's command stage: what the MCU
    // would command (co-contraction shift, then the clip).
    let limits = crate::command_stage::limits_for(robot, 1.0)
        .map_err(|e| EvaluateError::BadInput(format!("tension limits: {e}")))?;
    let ik = ExactIk::new(
        robot,
        IkSettings {
            statics: *statics.settings(),
            ..IkSettings::default()
        },
    );
    let rows = data.len().min(REFINE_ROWS);
    let pose_of = |r: usize| -> [f64; 7] { std::array::from_fn(|k| data.poses[(r, k)]) };
    let guess_of = |pose: &[f64; 7]| crate::net::steady_command(net, &limits, pose);
    let started = Instant::now();
    for r in 0..rows {
        std::hint::black_box(guess_of(&pose_of(r)));
    }
    let net_time = started.elapsed().as_secs_f64();
    let mut net_errors = Vec::with_capacity(rows);
    for r in 0..rows {
        let pose = pose_of(r);
        let tip = statics.solve(&guess_of(&pose), None).map_err(|e| {
            EvaluateError::BadInput(format!("row {r}: statics of the net's tensions: {e}"))
        })?;
        net_errors.push(1e3 * distance(&tip.pose(), &pose));
    }
    let (mut refined_errors, mut unreachable, mut failed) = (Vec::with_capacity(rows), 0, 0);
    let started = Instant::now();
    for r in 0..rows {
        let pose = pose_of(r);
        let target = Target::from_pose(&pose, false)
            .map_err(|e| EvaluateError::BadInput(format!("row {r}: {e}")))?;
        match ik.solve(&target, Some(&guess_of(&pose)), None) {
            Ok(s) => refined_errors.push(1e3 * s.position_error),
            Err(InverseError::Unreachable { closest }) => {
                unreachable += 1;
                refined_errors.push(1e3 * closest.position_error);
            }
            Err(e) => {
                log::warn!("row {r}: {e}");
                failed += 1;
            }
        }
    }
    let refined_time = started.elapsed().as_secs_f64();
    let per_query = |t: f64| 1e6 * t / rows.max(1) as f64;
    Ok(Refinement {
        rows,
        net_tip_error_mm: ErrorStats::of(&net_errors),
        refined_tip_error_mm: ErrorStats::of(&refined_errors),
        unreachable,
        failed,
        net_us_per_query: per_query(net_time),
        refined_us_per_query: per_query(refined_time + net_time),
    })
}

fn distance(a: &[f64; 7], b: &[f64; 7]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Mean wall time of one f32 inference (ns) per row, batched: the rows go
/// through one [`HostNet`] (built, and the poses converted to f32, before
/// the clock starts) into one reused buffer, repeated on one thread for
/// ≥ 50 ms. The same method as the comparison's batched column
/// (`compare::runner`); `None` without a pose to time.
pub fn inference_ns(net: &McuNet, poses: &nalgebra::DMatrix<f64>) -> Option<f64> {
    if poses.nrows() == 0 {
        return None;
    }
    let fast = HostNet::new(net);
    let x = pose_rows(poses);
    let mut y = vec![0.0f32; x.len() * fast.outputs()];
    let mut n = 0usize;
    let t = Instant::now();
    while t.elapsed().as_millis() < 50 {
        fast.infer_rows(std::hint::black_box(&x), &mut y);
        std::hint::black_box(&mut y);
        n += x.len();
    }
    Some(t.elapsed().as_nanos() as f64 / n as f64)
}

/// Metrics of `net` on every row of `data` (at least one), with the statics
/// of `statics`.
pub fn evaluate_net(
    statics: &Statics,
    net: &McuNet,
    data: &Dataset,
) -> Result<SplitMetrics, EvaluateError> {
    if net.shape().outputs != data.n_tendons {
        return Err(EvaluateError::BadInput(format!(
            "the model predicts {} but the data has {}",
            crate::robot::count(net.shape().outputs, "tension"),
            crate::robot::count(data.n_tendons, "tendon")
        )));
    }
    if statics.robot().n_tendons() != data.n_tendons {
        return Err(EvaluateError::BadInput(format!(
            "the robot has {} but the data has {}",
            crate::robot::count(statics.robot().n_tendons(), "tendon"),
            data.n_tendons
        )));
    }
    let Some(ns) = inference_ns(net, &data.poses) else {
        return Err(EvaluateError::BadInput("no rows to evaluate".into()));
    };
    let pred = infer_batch(net, &data.poses);
    // Normalised by each tendon's range [min, max], not by the net's output
    // ranges: those are the ranges of its targets, centred on the
    // co-contraction sets (docs/design.md §4), not of the tensions.
    let (lo, hi) = (
        statics.robot().min_tensions(),
        statics.robot().max_tensions(),
    );
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
