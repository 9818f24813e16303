//! One training run as a typed job — what `tendril train` and the main job
//! both do: split a dataset, train a cascade-correlation net, and write the
//! `.tnet` weight file, the training log, the learning curve and a report
//! (`docs/design.md` §4, §5).
//!
//! Nothing is written until training has finished and every output path has
//! been checked: an invalid request, a collision between paths or a Ctrl-C
//! leaves every existing file as it was.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;
use tendril_shared::{max_hidden_for, MAX_HIDDEN};

use crate::dataset::split::{SPLIT_SEED, TEST_FRACTION, VALID_FRACTION};
use crate::dataset::{prepare_excluding, Dataset};
use crate::fsutil::{check_distinct, write_atomic, write_atomic_with};
use crate::learn::cascor::export::{write_tnet_with, Ranges};
use crate::learn::cascor::fine_tune::fine_tune_with_stop;
use crate::learn::cascor::polish::{PolishLoss, RowMetrics};
use crate::learn::cascor::tip_metric::tip_metrics;
pub use crate::learn::cascor::{robot_for_data, DataRobot, TrainError};
use crate::learn::cascor::{train_with_stop, CascorOptions, GrowingNet, Metrics, TrainReport};
use crate::learn::targets::{Targets, TargetsSummary};
use crate::learn::LearnError;

/// Fewest dataset rows a training run accepts: enough that the default
/// fractions leave a test split of at least 2 rows and a validation split of
/// at least 5 (the comparison asks for the same).
pub const MIN_TRAIN_ROWS: usize = 50;

/// Largest held-out test (or validation) fraction: beyond half, the net
/// would be fitted on fewer rows than it is judged on.
pub const MAX_HELD_OUT_FRACTION: f64 = crate::dataset::split::MAX_TEST_FRACTION;

/// How to split the data.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SplitSpec {
    /// Seed of the split and of every candidate's initial weights.
    pub seed: u64,
    /// Held-out test fraction, in (0, [`MAX_HELD_OUT_FRACTION`]].
    pub test_fraction: f64,
    /// Validation fraction carved from the training rows, in [0, [`MAX_HELD_OUT_FRACTION`]].
    pub valid_fraction: f64,
    /// The rows are measurements (`docs/design.md` §3.1): `None` for the
    /// exact rows of `tendril generate`.
    pub measured: Option<MeasuredSpec>,
}

/// How measured rows are trained on (`docs/design.md` §3.1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MeasuredSpec {
    /// Leave training rows whose tip is an outlier
    /// ([`crate::dataset::measured::flag_outliers`]) out of the fit and
    /// the validation; the test split keeps every row.
    pub reject_outliers: bool,
    /// The tracker's jitter per position axis, mm, when the user knows it;
    /// else estimated (repeated rows, else the local fit's residuals).
    pub noise_mm: Option<f64>,
}

impl Default for SplitSpec {
    fn default() -> Self {
        SplitSpec {
            seed: SPLIT_SEED,
            test_fraction: TEST_FRACTION,
            valid_fraction: VALID_FRACTION,
            measured: None,
        }
    }
}

impl SplitSpec {
    /// Check the fractions; the error names the option and its range.
    pub fn validate(&self) -> Result<(), TrainError> {
        crate::dataset::split::check_test_fraction(self.test_fraction)
            .map_err(TrainError::BadInput)?;
        if let Some(n) = self.measured.and_then(|m| m.noise_mm) {
            if !(n.is_finite() && n > 0.0) {
                return Err(TrainError::BadInput(format!(
                    "--noise-mm must be a finite number > 0, got {n}"
                )));
            }
        }
        crate::dataset::split::check_valid_fraction(self.valid_fraction)
            .map_err(TrainError::BadInput)
    }
}

/// Where a training run writes.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOutputs {
    /// `.tnet` weight file.
    pub model: PathBuf,
    /// Training-log CSV (one row per installed unit).
    pub log: PathBuf,
    /// Learning-curve PNG.
    pub curve: PathBuf,
    /// Report JSON (choices made, learning curve, test RMSE).
    pub report: PathBuf,
}

impl TrainOutputs {
    /// `model.tnet` → `model.log.csv`, `model.curve.png`, `model.train.json` beside it.
    pub fn beside(model: &Path) -> TrainOutputs {
        TrainOutputs {
            model: model.to_path_buf(),
            log: sibling(model, ".log.csv"),
            curve: sibling(model, ".curve.png"),
            report: sibling(model, ".train.json"),
        }
    }
}

fn sibling(model: &Path, suffix: &str) -> PathBuf {
    let stem = model
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model".into());
    model.with_file_name(format!("{stem}{suffix}"))
}

/// A training run: the data, how to train and split, where to write.
#[derive(Clone, Debug)]
pub struct TrainJob<'a> {
    /// The dataset (physical units).
    pub data: &'a Dataset,
    /// The file `data` was read from, if any: no output may overwrite it.
    pub data_file: Option<PathBuf>,
    /// Trainer hyper-parameters.
    pub options: CascorOptions,
    /// What the net learns from the tensions (centred on the robot's
    /// co-contraction sets, [`Targets::for_robot`]).
    pub targets: Targets,
    /// The split.
    pub split: SplitSpec,
    /// Output files.
    pub outputs: TrainOutputs,
    /// Worker threads (`None`: rayon's default, all cores).
    pub threads: Option<usize>,
    /// The robot the net is for: its fingerprint and name, and the split,
    /// go into the `.tnet` (version 2, `docs/design.md` §5.1) so that every
    /// consumer can check the robot it is given. `None` writes version 1.
    pub robot: Option<crate::robot::Robot>,
    /// Fine-tune this net instead of growing one
    /// ([`crate::learn::cascor::fine_tune`]): its ranges normalise the rows
    /// and go into the written file.
    pub init: Option<InitNet>,
}

/// The net a fine-tuning run starts from (`tendril train --init`).
#[derive(Clone, Debug)]
pub struct InitNet {
    /// Its weights (normalised, inputs in [0, 1]).
    pub net: GrowingNet,
    /// Its normalisation ranges.
    pub ranges: Ranges,
}

/// Rows in each split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SplitSizes {
    /// Rows the net was fitted on.
    pub train: usize,
    /// Validation rows (stopping and choices).
    pub valid: usize,
    /// Held-out test rows.
    pub test: usize,
}

/// What a training run produced (everything it wrote is also in memory here).
#[derive(Clone, Debug)]
pub struct TrainResult {
    /// The kept net (normalised units).
    pub net: GrowingNet,
    /// What training did.
    pub report: TrainReport,
    /// Normalisation ranges baked into the weight file.
    pub ranges: Ranges,
    /// Rows per split.
    pub sizes: SplitSizes,
    /// Test RMSE of the targets ([`TrainJob::targets`]), normalised ×100 (f64 net).
    pub test_rmse_norm100: f64,
    /// For measured rows: the outliers found and the held-out error against
    /// the noise floor.
    pub measured: Option<MeasuredReport>,
}

/// What training on measured rows found (in the report JSON as `measured`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeasuredReport {
    /// Whether the outliers were left out of the fit.
    pub outliers_rejected: bool,
    /// Outliers among the training rows (validation rows included).
    pub outliers: crate::dataset::measured::OutlierReport,
    /// Lines of the data file (header = 1) of the rows flagged.
    pub outlier_lines: Vec<usize>,
    /// The net's held-out error against the noise floor.
    pub noise_floor: crate::dataset::measured::NoiseFloorReport,
}

/// The report JSON written beside the weight file.
#[derive(Serialize)]
struct ReportFile<'a> {
    data_rows: usize,
    train_rows: usize,
    valid_rows: usize,
    test_rows: usize,
    seed: u64,
    options: &'a CascorOptions,
    targets: TargetsSummary,
    report: &'a TrainReport,
    hidden_units: usize,
    parameters: usize,
    test_tension_rmse_norm100: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    measured: Option<&'a MeasuredReport>,
}

/// Check `job`, train, and write the weight file, log, learning curve and
/// report. `stop` is checked before every unit and once more before anything
/// is written: once set, the run returns [`LearnError::Interrupted`] and
/// every existing output is left as it was.
pub fn run(job: &TrainJob<'_>, stop: &AtomicBool) -> Result<TrainResult, TrainError> {
    check(job)?;
    let train = || train_and_write(job, stop);
    match job.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build()
            .map_err(|e| TrainError::Threads(e.to_string()))?
            .install(train),
        None => train(),
    }
}

/// Everything that can be refused before training starts.
fn check(job: &TrainJob<'_>) -> Result<(), TrainError> {
    let o = &job.outputs;
    let inputs: Vec<(&str, &Path)> = job
        .data_file
        .iter()
        .map(|p| ("--data", p.as_path()))
        .collect();
    check_distinct(
        &inputs,
        &[
            ("--out", &o.model),
            ("--log", &o.log),
            ("--plot", &o.curve),
            ("--report", &o.report),
        ],
    )?;
    job.split.validate()?;
    if job.data.len() < MIN_TRAIN_ROWS {
        return Err(TrainError::BadInput(format!(
            "the dataset has {} row{}; training needs at least {MIN_TRAIN_ROWS}",
            job.data.len(),
            if job.data.len() == 1 { "" } else { "s" }
        )));
    }
    check_tensions_vary(job.data)?;
    if job.options.max_hidden > MAX_HIDDEN {
        return Err(TrainError::BadInput(format!(
            "--max-hidden {} exceeds the decoder capacity {MAX_HIDDEN}",
            job.options.max_hidden
        )));
    }
    let robust = job.options.polish.robust;
    if !(robust.is_finite() && robust >= 0.0) {
        return Err(TrainError::BadInput(format!(
            "--polish-robust {robust}: must be a finite number ≥ 0 (0 = squared loss)"
        )));
    }
    Ok(())
}

/// Refuse a dataset whose tension column(s) hold one value in every row
/// (all zero, say): the net would learn a constant for that tendon, not
/// inverse kinematics, and the file's output range would be empty.
fn check_tensions_vary(data: &crate::dataset::Dataset) -> Result<(), TrainError> {
    let constant: Vec<String> = (0..data.n_tendons)
        .filter(|&c| {
            let col = data.tensions.column(c);
            col.iter().all(|&v| v == col[0])
        })
        .map(|c| match data.tensions.column(c).iter().next() {
            Some(v) => format!("t{c} (always {v} N)"),
            None => format!("t{c}"),
        })
        .collect();
    if constant.is_empty() {
        return Ok(());
    }
    Err(TrainError::BadInput(format!(
        "tension column{} {} of the dataset never change{}: a net cannot learn inverse \
         kinematics from {}; generate data in which every tendon pulls",
        if constant.len() == 1 { "" } else { "s" },
        constant.join(", "),
        if constant.len() == 1 { "s" } else { "" },
        if constant.len() == 1 { "it" } else { "them" }
    )))
}

fn train_and_write(job: &TrainJob<'_>, stop: &AtomicBool) -> Result<TrainResult, TrainError> {
    let data = job.data;
    let s = job.split;
    let mut learned = job.targets.learning_data(data);
    // Measured tips are in the tracker's frame; the net takes the base's
    // (`docs/design.md` §2.4): a robot file with a `[base]` maps them.
    if let (Some(_), Some(robot)) = (s.measured, job.robot.as_ref()) {
        if !robot.base.is_identity() {
            learned.map_poses(&robot.base.to_base());
        }
    }
    let outliers = s
        .measured
        .map(|_| crate::dataset::measured::training_outliers(data, s.test_fraction, s.seed));
    let exclude = match (&outliers, s.measured) {
        (Some((exclude, r)), Some(m)) if m.reject_outliers => {
            log::info!(
                "left out {} of {} training rows as outliers (tip off its neighbours' fit by more than {})",
                r.count,
                r.rows,
                crate::units::length_mm(r.threshold_mm)
            );
            exclude.clone()
        }
        _ => Vec::new(),
    };
    let p = prepare_excluding(
        &learned,
        s.test_fraction,
        s.valid_fraction,
        s.seed,
        &exclude,
    );
    // A fine-tuned net keeps the normalisation it was trained with.
    let p = match &job.init {
        Some(InitNet { ranges: r, .. }) => {
            p.in_ranges(&r.input_lo, &r.input_hi, &r.output_lo, &r.output_hi)
        }
        None => p,
    };
    let sizes = SplitSizes {
        train: p.train_x.nrows(),
        valid: p.valid_x.nrows(),
        test: p.test_x.nrows(),
    };
    log::debug!(
        "training on {} rows, validating on {}, testing on {} ({} tendons)",
        sizes.train,
        sizes.valid,
        sizes.test,
        data.n_tendons
    );
    // The controllers' weight store bounds the net by its weights: with
    // nine tendons it holds one unit fewer than the dimension cap.
    let cap = max_hidden_for(data.n_tendons);
    let mut options = job.options.clone();
    if options.max_hidden > cap {
        log::info!(
            "{} tendons: the controllers' weight store holds {cap} hidden units, not {}",
            data.n_tendons,
            options.max_hidden
        );
        options.max_hidden = cap;
    }
    let metrics = polish_metrics(job, &options, data, &p, stop)?;
    let metrics = Metrics {
        train: metrics.as_ref().map(|m| &m.0),
        valid: metrics.as_ref().map(|m| &m.1),
    };
    let (x, y, vx, vy) = (&p.train_x, &p.train_y, &p.valid_x, &p.valid_y);
    let (net, report) = match &job.init {
        Some(init) => fine_tune_with_stop(&init.net, x, y, vx, vy, &options, stop, metrics)?,
        None => train_with_stop(x, y, vx, vy, &options, s.seed, stop, metrics)?,
    };
    // The last unit may have finished after Ctrl-C: still write nothing.
    if stop.load(Ordering::SeqCst) {
        return Err(LearnError::Interrupted.into());
    }
    let test_pred = net.predict(&p.test_x);
    let test_rmse_norm100 =
        100.0 * ((&test_pred - &p.test_y).norm_squared() / p.test_y.len() as f64).sqrt();
    let measured = match (s.measured, outliers) {
        (Some(m), Some((marks, report))) => Some(measured_report(
            job, m, &marks, report, &p.y_range, &net, &p.test_x,
        )),
        _ => None,
    };
    let ranges = Ranges {
        input_lo: p.x_range.lo.clone(),
        input_hi: p.x_range.hi.clone(),
        output_lo: p.y_range.lo.clone(),
        output_hi: p.y_range.hi.clone(),
    };
    let o = &job.outputs;
    // The plot first: it is the output most likely to fail, and a failure
    // then leaves the other files as they were.
    use crate::plot::learning_curve::CurvePoint;
    let curve: Vec<CurvePoint> = report
        .history
        .iter()
        .map(|u| CurvePoint {
            hidden: u.hidden,
            train_rmse: u.train_rmse,
            valid_rmse: u.valid_rmse,
        })
        .collect();
    crate::plot::learning_curve::draw_learning_curve(
        &curve,
        report.best_hidden,
        &format!(
            "Cascade correlation learning curve ({} outputs, {})",
            report.output_kind, report.output_solver
        ),
        &o.curve,
    )
    .map_err(|e| TrainError::Write {
        path: o.curve.clone(),
        why: e.to_string(),
    })?;
    let provenance = job.robot.as_ref().map(|r| {
        let split = tendril_shared::SplitRecord {
            seed: s.seed,
            test_fraction: s.test_fraction,
        };
        tendril_shared::Provenance::new(r.fingerprint(), &r.name, Some(split))
    });
    write_tnet_with(&o.model, &net, &ranges, provenance.as_ref())?;
    write_log(&o.log, &report)?;
    let file = ReportFile {
        data_rows: data.len(),
        train_rows: sizes.train,
        valid_rows: sizes.valid,
        test_rows: sizes.test,
        seed: s.seed,
        options: &job.options,
        targets: job.targets.summary(),
        report: &report,
        hidden_units: net.n_hidden(),
        parameters: net.parameter_count(),
        test_tension_rmse_norm100: test_rmse_norm100,
        measured: measured.as_ref(),
    };
    let werr = |why: String| TrainError::Write {
        path: o.report.clone(),
        why,
    };
    // Through a `Value`, so keys come out sorted as in every earlier report.
    let json = serde_json::to_value(&file)
        .and_then(|v| serde_json::to_string_pretty(&v))
        .map_err(|e| werr(e.to_string()))?;
    write_atomic(&o.report, json.as_bytes()).map_err(|e| werr(e.to_string()))?;
    log::debug!(
        "kept {} hidden units ({} outputs, {}); test tension RMSE {:.4} (normalised ×100)",
        net.n_hidden(),
        report.output_kind,
        report.output_solver,
        test_rmse_norm100
    );
    Ok(TrainResult {
        net,
        report,
        ranges,
        sizes,
        test_rmse_norm100,
        measured,
    })
}

/// The tip metrics (`tip_metric`) of the fitted and validation rows, when
/// the polish runs with the tip loss and the robot is known.
fn polish_metrics(
    job: &TrainJob<'_>,
    options: &CascorOptions,
    data: &Dataset,
    p: &crate::dataset::Prepared,
    stop: &AtomicBool,
) -> Result<Option<(RowMetrics, RowMetrics)>, TrainError> {
    let polish = &options.polish;
    if polish.max_iterations == 0 || polish.loss != PolishLoss::Tip {
        return Ok(None);
    }
    let Some(robot) = job.robot.as_ref() else {
        log::info!("no robot: the polish minimises the plain output error");
        return Ok(None);
    };
    let span: Vec<f64> = p
        .y_range
        .hi
        .iter()
        .zip(&p.y_range.lo)
        .map(|(h, l)| h - l)
        .collect();
    let rows: Vec<usize> = p.fit_rows.iter().chain(&p.valid_rows).copied().collect();
    let tensions = data.tensions.select_rows(&rows);
    let bar = crate::dataset::generate::solve_bar(
        rows.len(),
        options.progress && log::log_enabled!(log::Level::Info),
    );
    let all = tip_metrics(robot, &tensions, &span, stop, &|k| bar.inc(k as u64))?;
    bar.finish_and_clear();
    let Some(all) = all else {
        return Err(LearnError::Interrupted.into());
    };
    let o2 = all.outputs * all.outputs;
    let cut = p.fit_rows.len() * o2;
    let fit = RowMetrics {
        outputs: all.outputs,
        m: all.m[..cut].to_vec(),
    };
    let valid = RowMetrics {
        outputs: all.outputs,
        m: all.m[cut..].to_vec(),
    };
    Ok(Some((fit, valid)))
}

/// The held-out error of `net` on measured rows against the noise floor
/// (`docs/design.md` §3.1): the test rows' predicted tensions, staged as the
/// MCU would command them, pushed through the local fit of the kept
/// training rows, against the measured tips.
#[allow(clippy::too_many_arguments)]
fn measured_report(
    job: &TrainJob<'_>,
    m: MeasuredSpec,
    marks: &[bool],
    report: crate::dataset::measured::OutlierReport,
    y_range: &crate::dataset::MinMax,
    net: &GrowingNet,
    test_x: &nalgebra::DMatrix<f64>,
) -> MeasuredReport {
    use crate::dataset::measured::{held_out_vs_noise, noise_from_repeats, NoiseSource};
    let s = job.split;
    let (mut train_idx, test_idx) =
        crate::dataset::split_indices(job.data.len(), s.test_fraction, s.seed);
    // The judge's forward fit leaves the outliers out whether or not the
    // net was fitted without them: both are judged by the same yardstick.
    train_idx.retain(|&i| !marks[i]);
    let (train, test) = (job.data.rows(&train_idx), job.data.rows(&test_idx));
    let mut pred = y_range.denormalise(&net.predict(test_x));
    if let Some(limits) = job
        .robot
        .as_ref()
        .and_then(|r| crate::command_stage::limits_for(r, 1.0).ok())
    {
        pred = crate::command_stage::command_rows(&limits, &pred);
    }
    let noise = match (m.noise_mm, noise_from_repeats(&train)) {
        (Some(n), _) => (Some(n), NoiseSource::Given),
        (None, Some((sigma, _))) => (Some(sigma * 1e3), NoiseSource::RepeatedRows),
        (None, None) => (report.noise_sigma_mm, NoiseSource::LocalFit),
    };
    let noise_floor = held_out_vs_noise(&train, &report, &test, &pred, noise);
    MeasuredReport {
        outliers_rejected: m.reject_outliers,
        outlier_lines: (0..marks.len())
            .filter(|&i| marks[i])
            .map(|i| i + 2)
            .collect(),
        outliers: report,
        noise_floor,
    }
}

/// The training log: one CSV row per installed unit.
fn write_log(path: &Path, report: &TrainReport) -> Result<(), TrainError> {
    write_atomic_with(path, |w| {
        writeln!(w, "hidden_units,train_rmse_norm100,valid_rmse_norm100,objective,score,error_removed,candidate_epochs,output_epochs,seconds")?;
        for r in &report.history {
            writeln!(
                w,
                "{},{},{},{},{},{},{},{},{:.3}",
                r.hidden,
                100.0 * r.train_rmse,
                100.0 * r.valid_rmse,
                r.objective.map_or(String::new(), |o| o.to_string()),
                r.score,
                r.reduction,
                r.candidate_epochs,
                r.output_epochs,
                r.seconds
            )?;
        }
        Ok(())
    })
    .map_err(|e| TrainError::Write {
        path: path.to_path_buf(),
        why: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn rows(n: usize) -> Dataset {
        Dataset {
            n_tendons: 2,
            tensions: DMatrix::from_fn(n, 2, |i, j| (i + j) as f64 / n as f64),
            poses: DMatrix::from_fn(n, 7, |i, j| ((i * (j + 3)) % 11) as f64 / 11.0),
        }
    }

    fn job<'a>(data: &'a Dataset, dir: &Path) -> TrainJob<'a> {
        TrainJob {
            data,
            data_file: None,
            targets: Targets::Tensions,
            options: CascorOptions {
                max_hidden: 2,
                progress: false,
                ..CascorOptions::default()
            },
            split: SplitSpec::default(),
            outputs: TrainOutputs::beside(&dir.join("m.tnet")),
            threads: Some(1),
            robot: None,
            init: None,
        }
    }

    fn nothing_written(dir: &Path) -> bool {
        std::fs::read_dir(dir).unwrap().next().is_none()
    }

    #[test]
    fn fewer_rows_than_the_minimum_are_refused_before_writing() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(MIN_TRAIN_ROWS - 1);
        let err = run(&job(&data, dir.path()), &AtomicBool::new(false)).unwrap_err();
        assert!(matches!(err, TrainError::BadInput(_)), "{err}");
        assert!(err.to_string().contains("at least 50"), "{err}");
        assert!(nothing_written(dir.path()));
    }

    #[test]
    fn test_fraction_outside_its_range_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(200);
        for bad in [0.0, 0.51, 0.99, 1.5, -0.1, f64::NAN] {
            let mut j = job(&data, dir.path());
            j.split.test_fraction = bad;
            let err = run(&j, &AtomicBool::new(false)).unwrap_err();
            assert!(err.to_string().contains("--test-fraction"), "{bad}: {err}");
        }
        let mut j = job(&data, dir.path());
        j.split.valid_fraction = 0.7;
        assert!(run(&j, &AtomicBool::new(false))
            .unwrap_err()
            .to_string()
            .contains("--valid-fraction"));
        assert!(nothing_written(dir.path()));
    }

    #[test]
    fn a_log_path_equal_to_the_model_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(200);
        let mut j = job(&data, dir.path());
        j.outputs.log = j.outputs.model.clone();
        let err = run(&j, &AtomicBool::new(false)).unwrap_err();
        assert!(matches!(err, TrainError::Paths(_)), "{err}");
        assert!(nothing_written(dir.path()));
    }

    #[test]
    fn a_negative_or_nan_robust_scale_is_refused_before_writing() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(200);
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            let mut j = job(&data, dir.path());
            j.options.polish.robust = bad;
            let err = run(&j, &AtomicBool::new(false)).unwrap_err();
            assert!(err.to_string().contains("--polish-robust"), "{bad}: {err}");
        }
        assert!(nothing_written(dir.path()));
    }

    #[test]
    fn a_stop_before_training_writes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(200);
        let err = run(&job(&data, dir.path()), &AtomicBool::new(true)).unwrap_err();
        assert!(err.is_interrupted(), "{err}");
        assert!(nothing_written(dir.path()));
    }
}
