//! `tendril train`: cascade-correlation training (`docs/design.md` §4) → `.tnet`
//! weight file, training-log CSV and learning-curve PNG.

use std::path::PathBuf;

use super::common::stop_flag;
use crate::dataset::Dataset;
use crate::jobs::train::{self as job, SplitSpec, TrainJob, TrainOutputs};
use crate::learn::cascor::{self, CascorOptions, ObjectiveChoice, OutputKind, OutputSolver};
use crate::learn::targets::Targets;
use crate::robot::Robot;

/// Candidate objective on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ObjectiveArg {
    /// Fahlman's covariance with the residual error.
    Covariance,
    /// Cascade 2's error reduction (Prechelt 1997).
    Cascade2,
    /// Half the pool each; validation picks the installed unit.
    Mixed,
}

/// Output activation on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum OutputArg {
    /// Try linear and sigmoid, keep the better on validation.
    Auto,
    /// Linear outputs.
    Linear,
    /// Logistic sigmoid outputs (always trained by Quickprop).
    Sigmoid,
}

/// Output solver on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum SolverArg {
    /// Try both for linear outputs, keep the better on validation.
    Auto,
    /// Exact ridge least squares (linear outputs).
    Ridge,
    /// Quickprop descent.
    Quickprop,
}

/// What the polish minimises, on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolishLossArg {
    /// The tip displacement the tension error causes (the robot's tip Jacobian per row).
    Tip,
    /// The plain tension error.
    Plain,
}

/// Outlier handling for measured rows on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutliersArg {
    /// Leave training rows whose tip disagrees with its neighbours' out of the fit.
    Reject,
    /// Fit every row.
    Keep,
}

/// Train a cascade-correlation IK net (pose → tensions) and export it as `.tnet`.
/// The dataset needs at least 50 rows; every output must be a distinct file.
/// A dataset without a sidecar is taken as measured rows (docs/design.md §3.1):
/// it needs --robot, its outliers are left out of the fit, and the report
/// gives the held-out error against the noise floor.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Dataset CSV (`tendril generate`, or measured rows):
    /// t0..t{T-1},px,py,pz,qw,qx,qy,qz.
    #[arg(long, value_name = "CSV")]
    pub data: PathBuf,
    /// Weight file to write (`.tnet`, written atomically).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Training-log CSV (hidden units vs train/validation RMSE); default: <out>.log.csv.
    #[arg(long, value_name = "CSV")]
    pub log: Option<PathBuf>,
    /// Learning-curve PNG; default: <out>.curve.png.
    #[arg(long, value_name = "PNG")]
    pub plot: Option<PathBuf>,
    /// Robot the dataset is for: its co-contraction sets centre the targets
    /// (docs/design.md §4). Default: the robot file the dataset's sidecar
    /// records (as recorded, or relative to the sidecar; its SHA-256 checked),
    /// else robots/seed-4t.toml. Must be the sidecar's robot.
    #[arg(long, value_name = "FILE")]
    pub robot: Option<PathBuf>,
    /// Train for --robot although the dataset's sidecar records another
    /// robot file (SHA-256), or for a recorded robot file that has changed
    /// since (a warning instead of an error).
    #[arg(long)]
    pub allow_robot_mismatch: bool,
    /// Training report JSON (choices made, targets, learning curve, test RMSE); default: <out>.train.json.
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
    /// Seed of the split and of every candidate's initial weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Held-out test fraction (never seen by training), in (0, 0.5].
    #[arg(long, default_value_t = 0.03)]
    pub test_fraction: f64,
    /// Validation fraction carved from the training rows (stopping, choices), in [0, 0.5].
    #[arg(long, default_value_t = 0.1)]
    pub valid_fraction: f64,
    /// Hidden-unit cap (at most the controllers' capacity, tendril_shared::MAX_HIDDEN = 64).
    #[arg(long, default_value_t = tendril_shared::MAX_HIDDEN)]
    pub max_hidden: usize,
    /// Candidates trained per installed unit (in parallel) [default: 8; 16 for a robot with
    /// more than four bending degrees of freedom].
    #[arg(long)]
    pub pool: Option<usize>,
    /// Candidate objective.
    #[arg(long, value_enum, default_value_t = ObjectiveArg::Cascade2)]
    pub objective: ObjectiveArg,
    /// Output activation.
    #[arg(long, value_enum, default_value_t = OutputArg::Auto)]
    pub output: OutputArg,
    /// Output solver for linear outputs.
    #[arg(long, value_enum, default_value_t = SolverArg::Auto)]
    pub solver: SolverArg,
    /// Output Quickprop: maximum growth factor μ.
    #[arg(long, default_value_t = 2.0)]
    pub out_mu: f64,
    /// Output Quickprop: ε (divided by the number of patterns).
    #[arg(long, default_value_t = 0.35)]
    pub out_epsilon: f64,
    /// Output Quickprop: weight decay.
    #[arg(long, default_value_t = 1e-4)]
    pub out_decay: f64,
    /// Output Quickprop: patience (epochs).
    #[arg(long, default_value_t = 8)]
    pub out_patience: usize,
    /// Output Quickprop: relative change threshold.
    #[arg(long, default_value_t = 0.01)]
    pub out_threshold: f64,
    /// Output Quickprop: epoch cap per phase.
    #[arg(long, default_value_t = 1000)]
    pub out_max_epochs: usize,
    /// Candidate Quickprop: maximum growth factor μ.
    #[arg(long, default_value_t = 2.0)]
    pub cand_mu: f64,
    /// Candidate Quickprop: ε (divided by patterns × candidate fan-in). Fahlman's
    /// 1.0 leaves candidates nearly untrained here (objectives are normalised); 1000 measured best.
    #[arg(long, default_value_t = 1000.0)]
    pub cand_epsilon: f64,
    /// Candidate Quickprop: patience (epochs).
    #[arg(long, default_value_t = 25)]
    pub cand_patience: usize,
    /// Candidate Quickprop: relative change threshold.
    #[arg(long, default_value_t = 0.01)]
    pub cand_threshold: f64,
    /// Candidate Quickprop: epoch cap per candidate.
    #[arg(long, default_value_t = 1000)]
    pub cand_max_epochs: usize,
    /// Sigmoid-prime offset for sigmoid outputs' error (Fahlman).
    #[arg(long, default_value_t = 0.1)]
    pub prime_offset: f64,
    /// Sigmoid-prime offset in the candidate gradient.
    #[arg(long, default_value_t = 0.1)]
    pub cand_prime_offset: f64,
    /// Stop after this many units without a better validation RMSE (the best net is kept).
    #[arg(long, default_value_t = 8)]
    pub valid_patience: usize,
    /// Stop once the validation RMSE (normalised, not ×100) reaches this.
    #[arg(long, default_value_t = 0.0)]
    pub target_rmse: f64,
    /// Units each output configuration grows before validation picks one (auto modes).
    #[arg(long, default_value_t = 3)]
    pub pilot_units: usize,
    /// Candidates train on a seeded random subset of this many training rows per unit (0 = all)
    /// [default: 3000; 10000 for a robot with more than four bending degrees of freedom].
    #[arg(long)]
    pub cand_patterns: Option<usize>,
    /// Polish: after growth, train every weight together by L-BFGS for at
    /// most this many steps, keeping the best validation net (0 = off)
    /// [default: 0; 4,000 for a robot with more than two bending degrees of freedom].
    #[arg(long, value_name = "STEPS")]
    pub polish: Option<usize>,
    /// Polish: what it minimises — the tip displacement the tension error causes
    /// (needs the robot), or the plain tension error.
    #[arg(long, value_enum, default_value_t = PolishLossArg::Tip)]
    pub polish_loss: PolishLossArg,
    /// Polish: a robust loss, pseudo-Huber with δ = K × the median row error at the start
    /// (0 = squared) [default: 0; 3 for a robot with more than four bending degrees of freedom].
    #[arg(long, value_name = "K", allow_hyphen_values = true)]
    pub polish_robust: Option<f64>,
    /// Polish: stop after this many steps without a better validation RMSE.
    #[arg(long, default_value_t = 200)]
    pub polish_patience: usize,
    /// Polish: curvature pairs L-BFGS keeps [default: the library's].
    #[arg(long, value_name = "PAIRS")]
    pub polish_memory: Option<usize>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Measured rows: the tracker's jitter per position axis, mm, for the
    /// noise floor [default: estimated from repeated rows, else from the
    /// local fit]. Makes the rows measured even with a sidecar.
    #[arg(long, value_name = "SIGMA")]
    pub noise_mm: Option<f64>,
    /// Fine-tune this net on --data instead of growing a new one: its
    /// weights are polished on the rows (--polish steps, default 10,000, the
    /// best validation step kept) and its normalisation kept. The measured
    /// workflow: a net trained on rows generated from a calibrated robot
    /// file, fine-tuned on the robot's own measured rows (docs/design.md §4).
    /// It must be a net for --robot.
    #[arg(long, value_name = "TNET")]
    pub init: Option<PathBuf>,
    /// Measured rows: what to do with outliers of the tip [default: reject].
    /// Makes the rows measured even with a sidecar.
    #[arg(long, value_enum)]
    pub outliers: Option<OutliersArg>,
}

impl TrainArgs {
    /// The trainer options these arguments describe, for `robot`.
    pub fn options(&self, robot: &Robot) -> CascorOptions {
        let d = CascorOptions::for_robot(robot);
        CascorOptions {
            max_hidden: self.max_hidden,
            pool: self.pool.unwrap_or(d.pool),
            objective: match self.objective {
                ObjectiveArg::Covariance => ObjectiveChoice::Covariance,
                ObjectiveArg::Cascade2 => ObjectiveChoice::Cascade2,
                ObjectiveArg::Mixed => ObjectiveChoice::Mixed,
            },
            output_kinds: match self.output {
                OutputArg::Auto => vec![OutputKind::Linear, OutputKind::Sigmoid],
                OutputArg::Linear => vec![OutputKind::Linear],
                OutputArg::Sigmoid => vec![OutputKind::Sigmoid],
            },
            output_solvers: match self.solver {
                SolverArg::Auto => vec![OutputSolver::Ridge, OutputSolver::Quickprop],
                SolverArg::Ridge => vec![OutputSolver::Ridge],
                SolverArg::Quickprop => vec![OutputSolver::Quickprop],
            },
            output: cascor::QuickpropParams {
                mu: self.out_mu,
                epsilon: self.out_epsilon,
                decay: self.out_decay,
                patience: self.out_patience,
                threshold: self.out_threshold,
                max_epochs: self.out_max_epochs,
            },
            candidate: cascor::QuickpropParams {
                mu: self.cand_mu,
                epsilon: self.cand_epsilon,
                decay: 0.0,
                patience: self.cand_patience,
                threshold: self.cand_threshold,
                max_epochs: self.cand_max_epochs,
            },
            output_prime_offset: self.prime_offset,
            candidate_prime_offset: self.cand_prime_offset,
            valid_patience: self.valid_patience,
            target_rmse: self.target_rmse,
            pilot_units: self.pilot_units,
            candidate_patterns: self.cand_patterns.unwrap_or(d.candidate_patterns),
            polish: cascor::PolishOptions {
                max_iterations: self.polish.unwrap_or(d.polish.max_iterations),
                patience: self.polish_patience,
                robust: self.polish_robust.unwrap_or(d.polish.robust),
                memory: self.polish_memory.unwrap_or(d.polish.memory),
                loss: match self.polish_loss {
                    PolishLossArg::Tip => cascor::PolishLoss::Tip,
                    PolishLossArg::Plain => cascor::PolishLoss::Plain,
                },
            },
            ..d
        }
    }
}

impl TrainArgs {
    /// Whether `--data` holds measured rows: it has no sidecar, a sidecar
    /// that does not describe `data` (said once, as a warning), or a
    /// measured-rows option is given.
    pub fn measured(&self, data: &Dataset) -> bool {
        if self.noise_mm.is_some() || self.outliers.is_some() {
            return true;
        }
        let path = crate::dataset::Sidecar::path_for(&self.data);
        if !path.exists() {
            return true;
        }
        match crate::dataset::Sidecar::read(&path).map_err(|e| e.to_string()) {
            Ok(sidecar) => match sidecar.describes(data) {
                Ok(()) => false,
                Err(why) => {
                    log::warn!(
                        "{} does not describe {} ({why}): a stale sidecar; the rows are taken \
                         as measured",
                        path.display(),
                        self.data.display()
                    );
                    true
                }
            },
            Err(e) => {
                log::warn!("{e}: the rows are taken as measured");
                true
            }
        }
    }

    /// The training job these arguments describe, on `data` read from
    /// `--data` (`measured`: [`Self::measured`]).
    pub fn job<'a>(&self, data: &'a Dataset, measured: bool) -> anyhow::Result<TrainJob<'a>> {
        // The log, curve and report go beside the net unless named: beside a
        // device, FIFO or stdout there is no place for them (they would land
        // in /dev).
        let beside = self.log.is_none() || self.plot.is_none() || self.report.is_none();
        if beside && !crate::fsutil::is_regular_output(&self.out).unwrap_or(true) {
            anyhow::bail!(
                "--out {} is not a regular file, so the training log, learning curve and \
                 report have no place beside it: name them with --log, --plot and --report",
                self.out.display()
            );
        }
        let r = job::robot_for_data(
            data,
            &self.data,
            self.robot.as_deref(),
            self.allow_robot_mismatch,
        )?;
        log::info!(
            "targets: {} (robot {})",
            if r.targets == Targets::Tensions {
                "the tensions"
            } else {
                "centred on the co-contraction sets"
            },
            r.path.display()
        );
        let mut outputs = TrainOutputs::beside(&self.out);
        if let Some(p) = &self.log {
            outputs.log = p.clone();
        }
        if let Some(p) = &self.plot {
            outputs.curve = p.clone();
        }
        if let Some(p) = &self.report {
            outputs.report = p.clone();
        }
        let init = match &self.init {
            Some(path) => {
                let (net, _) =
                    crate::net::load_for_robot(path, &r.robot, self.allow_robot_mismatch)?;
                let (net, ranges) = cascor::fine_tune::from_tnet(&net)
                    .map_err(|e| anyhow::anyhow!("--init {}: {e}", path.display()))?;
                Some(job::InitNet { net, ranges })
            }
            None => None,
        };
        let mut options = self.options(&r.robot);
        if init.is_some() && self.polish.is_none() {
            options.polish.max_iterations = FINE_TUNE_STEPS;
        }
        Ok(TrainJob {
            data,
            data_file: Some(self.data.clone()),
            options,
            targets: r.targets,
            split: SplitSpec {
                seed: self.seed,
                test_fraction: self.test_fraction,
                valid_fraction: self.valid_fraction,
                measured: measured.then_some(job::MeasuredSpec {
                    reject_outliers: self.outliers != Some(OutliersArg::Keep),
                    noise_mm: self.noise_mm,
                }),
            },
            outputs,
            threads: self.threads,
            robot: Some(r.robot),
            init,
        })
    }
}

/// `--init`'s polish steps when `--polish` is not given: the polish is all a
/// fine-tune does, and its patience ends it where the rows stop agreeing.
const FINE_TUNE_STEPS: usize = 10_000;

/// Run `tendril train`.
pub fn run(a: TrainArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout(
        "--out",
        &a.out,
        "the model's log, curve and report are written beside it",
    )?;
    if let Some(plot) = &a.plot {
        super::common::refuse_stdout("--plot", plot, "a PNG is drawn into a file")?;
    }
    if a.polish_memory == Some(0) {
        anyhow::bail!("--polish-memory must be at least 1 (L-BFGS curvature pairs), got 0");
    }
    if let Some(k) = a.polish_robust.filter(|k| !(k.is_finite() && *k >= 0.0)) {
        anyhow::bail!(
            "--polish-robust must be a finite number ≥ 0 (0: squared loss), got {}",
            crate::units::given(k)
        );
    }
    if !(a.target_rmse.is_finite() && a.target_rmse >= 0.0) {
        anyhow::bail!(
            "--target-rmse must be a finite number ≥ 0 (normalised ×100), got {}",
            crate::units::given(a.target_rmse)
        );
    }
    let mut data = Dataset::read_csv(&a.data)?;
    let r = job::robot_for_data(&data, &a.data, a.robot.as_deref(), a.allow_robot_mismatch)?;
    crate::dataset::measured::check_rows(&data, &r.robot, &a.data)?;
    let measured = a.measured(&data);
    if measured {
        crate::dataset::measured::canonical_quaternions(&mut data);
        let (kept, copies) = crate::dataset::measured::drop_copies(&data);
        if !copies.is_empty() {
            log::warn!(
                "{}: {} rows copy an earlier row to the last bit (lines {}{}): a tracker never \
                 measures one pose twice exactly, so they are copies, dropped (not repeats)",
                a.data.display(),
                copies.len(),
                copies
                    .iter()
                    .take(5)
                    .map(|l| l.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                if copies.len() > 5 { ", …" } else { "" }
            );
            data = kept;
        }
    }
    let job = a.job(&data, measured)?;
    let t = job::run(&job, stop_flag())?;
    let o = &job.outputs;
    log::info!(
        "wrote {} ({} hidden units, {:.1} s; test tension RMSE {:.4} normalised ×100), {}, {}, {}",
        o.model.display(),
        t.net.n_hidden(),
        t.report.seconds,
        t.test_rmse_norm100,
        o.log.display(),
        o.curve.display(),
        o.report.display()
    );
    if let Some(m) = &t.measured {
        log::info!("{}", measured_summary(m));
    }
    Ok(())
}

/// What training on measured rows found, in one line.
fn measured_summary(m: &job::MeasuredReport) -> String {
    use crate::dataset::measured::NoiseSource;
    let f = &m.noise_floor;
    let mm = crate::units::length_mm;
    let outliers = format!(
        "measured rows: {} of {} training rows are outliers ({}, tip off by > {})",
        m.outliers.count,
        m.outliers.rows,
        if m.outliers_rejected {
            "left out"
        } else {
            "kept"
        },
        mm(m.outliers.threshold_mm)
    );
    let held_out = format!(
        "held-out tip error (predicted tensions through the local fit of the training rows, {} \
         rows, {} outliers left out) RMS {} / mean {}",
        f.rows,
        f.outlier_rows,
        mm(f.held_out_rms_mm),
        mm(f.held_out_mean_mm)
    );
    match (f.noise_sigma_mm, f.floor_rms_mm, f.excess_rms_mm) {
        (Some(sigma), Some(floor), Some(excess)) => format!(
            "{outliers}; {held_out} against a noise floor of RMS {} (σ {} per axis, {}): the \
             net's own share ≈ {}",
            mm(floor),
            mm(sigma),
            match f.noise_source {
                NoiseSource::Given => "given",
                NoiseSource::RepeatedRows => "from repeated rows",
                NoiseSource::LocalFit => "estimated from the local fit",
            },
            mm(excess)
        ),
        _ => {
            let [narrow, wide] = m.outliers.noise_check;
            format!(
                "{outliers}; {held_out}. The noise floor cannot be estimated from these rows: \
                 the local fit's own error is in its residuals (σ {} per axis from the nearest \
                 rows, {} from twice as many; jitter alone gives the same), so the floor, the \
                 net's share and the outlier threshold are upper bounds. Give the tracker's \
                 jitter with --noise-mm, or measure some tension sets more than once",
                mm(narrow),
                mm(wide)
            )
        }
    }
}
