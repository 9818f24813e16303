//! `tendril train`: cascade-correlation training (`DESIGN.md` §4) → `.tnet`
//! weight file, training-log CSV and learning-curve PNG.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::dataset::{prepare, Dataset};
use crate::learn::cascor::export::{write_tnet, Ranges};
use crate::learn::cascor::{
    self, CascadeNet, CascorOptions, ObjectiveChoice, OutputKind, OutputSolver, TrainReport,
};

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

/// Train a cascade-correlation IK net (pose → tensions) and export it as `.tnet`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Dataset CSV (`tendril generate`): t0..t{T-1},px,py,pz,qw,qx,qy,qz.
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
    /// Training report JSON (choices made, learning curve, test RMSE); default: <out>.train.json.
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
    /// Seed of the split and of every candidate's initial weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Held-out test fraction (never seen by training).
    #[arg(long, default_value_t = 0.03)]
    pub test_fraction: f64,
    /// Validation fraction carved from the training rows (stopping, choices).
    #[arg(long, default_value_t = 0.1)]
    pub valid_fraction: f64,
    /// Hidden-unit cap (≤ 64, the host decoder's capacity; the MCU build holds 16).
    #[arg(long, default_value_t = 64)]
    pub max_hidden: usize,
    /// Candidates trained per installed unit (in parallel).
    #[arg(long, default_value_t = 8)]
    pub pool: usize,
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
    /// Candidates train on a seeded random subset of this many training rows per unit (0 = all).
    #[arg(long, default_value_t = 3000)]
    pub cand_patterns: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

impl TrainArgs {
    /// The trainer options these arguments describe.
    pub fn options(&self) -> CascorOptions {
        let d = CascorOptions::default();
        CascorOptions {
            max_hidden: self.max_hidden,
            pool: self.pool,
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
            candidate_patterns: self.cand_patterns,
            ..d
        }
    }
}

/// How to split the data: seed, held-out test fraction, validation fraction of the rest.
#[derive(Clone, Copy, Debug)]
pub struct SplitSpec {
    /// Split and candidate seed.
    pub seed: u64,
    /// Held-out test fraction (0.03 by default).
    pub test_fraction: f64,
    /// Validation fraction carved from the training rows (0.1 by default).
    pub valid_fraction: f64,
}

/// Where a training run writes.
#[derive(Clone, Debug)]
pub struct TrainPaths {
    /// `.tnet` weight file.
    pub out: PathBuf,
    /// Training-log CSV.
    pub log: PathBuf,
    /// Learning-curve PNG.
    pub plot: PathBuf,
    /// Report JSON.
    pub report: PathBuf,
}

impl TrainPaths {
    /// `model.tnet` → `model.log.csv`, `model.curve.png`, `model.train.json` beside it.
    pub fn beside(out: &Path) -> TrainPaths {
        TrainPaths {
            out: out.to_path_buf(),
            log: sibling(out, ".log.csv"),
            plot: sibling(out, ".curve.png"),
            report: sibling(out, ".train.json"),
        }
    }
}

/// Everything a training run produced.
pub struct Trained {
    /// The kept net (normalised units).
    pub net: CascadeNet,
    /// What training did.
    pub report: TrainReport,
    /// Normalisation ranges baked into the weight file.
    pub ranges: Ranges,
    /// Test tension RMSE, normalised ×100 (f64 net).
    pub test_rmse_norm100: f64,
}

/// Train on `data` with `opts`, write the weight file, log CSV, report JSON and
/// learning curve; the library entry point of `tendril train` (the main job uses it too).
#[allow(clippy::too_many_arguments)] // the main job calls it with every path spelled out
pub fn train_to_files(
    data: &Dataset,
    opts: &CascorOptions,
    seed: u64,
    test_fraction: f64,
    valid_fraction: f64,
    out: &Path,
    log_path: &Path,
    plot_path: &Path,
    report_path: &Path,
) -> anyhow::Result<Trained> {
    if !(0.0..1.0).contains(&test_fraction) || !(0.0..1.0).contains(&valid_fraction) {
        anyhow::bail!("--test-fraction and --valid-fraction must be in [0, 1)");
    }
    if opts.max_hidden > cascor::export::HOST_MAX_HIDDEN {
        anyhow::bail!(
            "--max-hidden {} exceeds the decoder capacity {}",
            opts.max_hidden,
            cascor::export::HOST_MAX_HIDDEN
        );
    }
    let p = prepare(data, test_fraction, valid_fraction, seed);
    log::info!(
        "training on {} rows, validating on {}, testing on {} ({} tendons)",
        p.train_x.nrows(),
        p.valid_x.nrows(),
        p.test_x.nrows(),
        data.n_tendons
    );
    let (net, report) = cascor::train(&p.train_x, &p.train_y, &p.valid_x, &p.valid_y, opts, seed)?;
    let test_pred = net.predict(&p.test_x);
    let test_rmse_norm100 = if p.test_y.is_empty() {
        f64::NAN
    } else {
        100.0 * ((&test_pred - &p.test_y).norm_squared() / p.test_y.len() as f64).sqrt()
    };
    log::info!(
        "kept {} hidden units ({} outputs, {}); test tension RMSE {:.4} (normalised ×100)",
        net.n_hidden(),
        report.output_kind,
        report.output_solver,
        test_rmse_norm100
    );
    let ranges = Ranges {
        input_lo: p.x_range.lo.clone(),
        input_hi: p.x_range.hi.clone(),
        output_lo: p.y_range.lo.clone(),
        output_hi: p.y_range.hi.clone(),
    };
    write_tnet(out, &net, &ranges)?;
    crate::fsutil::write_atomic_with(log_path, |w| {
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
    .with_context(|| format!("writing {}", log_path.display()))?;
    let json = serde_json::json!({
        "data_rows": data.len(),
        "train_rows": p.train_x.nrows(),
        "valid_rows": p.valid_x.nrows(),
        "test_rows": p.test_x.nrows(),
        "seed": seed,
        "options": opts,
        "report": report,
        "hidden_units": net.n_hidden(),
        "parameters": net.parameter_count(),
        "test_tension_rmse_norm100": test_rmse_norm100,
    });
    crate::fsutil::write_atomic(report_path, serde_json::to_string_pretty(&json)?.as_bytes())
        .with_context(|| format!("writing {}", report_path.display()))?;
    crate::plot::learning_curve::draw_learning_curve(
        &report.history,
        report.best_hidden,
        &format!(
            "Cascade correlation learning curve ({} outputs, {})",
            report.output_kind, report.output_solver
        ),
        plot_path,
    )
    .map_err(|e| anyhow::anyhow!("drawing {}: {e}", plot_path.display()))?;
    Ok(Trained {
        net,
        report,
        ranges,
        test_rmse_norm100,
    })
}

fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model".into());
    out.with_file_name(format!("{stem}{suffix}"))
}

/// Run `tendril train`.
pub fn run(a: TrainArgs) -> anyhow::Result<()> {
    let data = Dataset::read_csv(&a.data)?;
    let opts = a.options();
    let mut paths = TrainPaths::beside(&a.out);
    if let Some(p) = &a.log {
        paths.log = p.clone();
    }
    if let Some(p) = &a.plot {
        paths.plot = p.clone();
    }
    if let Some(p) = &a.report {
        paths.report = p.clone();
    }
    let split = SplitSpec {
        seed: a.seed,
        test_fraction: a.test_fraction,
        valid_fraction: a.valid_fraction,
    };
    let go = || {
        train_to_files(
            &data,
            &opts,
            split.seed,
            split.test_fraction,
            split.valid_fraction,
            &paths.out,
            &paths.log,
            &paths.plot,
            &paths.report,
        )
    };
    let t = match a.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build()?
            .install(go)?,
        None => go()?,
    };
    eprintln!(
        "wrote {} ({} hidden units, {:.1} s; test tension RMSE {:.4} normalised ×100), {}, {}, {}",
        a.out.display(),
        t.net.n_hidden(),
        t.report.seconds,
        t.test_rmse_norm100,
        paths.log.display(),
        paths.plot.display(),
        paths.report.display()
    );
    Ok(())
}
