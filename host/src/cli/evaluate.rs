//! `tendril evaluate`: the `DESIGN.md` §4 metrics of a `.tnet` net on a
//! dataset — tension RMSE, task-space error through the statics, inference time.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;

use crate::dataset::{split_indices, Dataset, Sidecar};
use crate::evaluate::SplitMetrics;
use crate::learn::cascor::export::{infer_batch, read_tnet, HostNet};
use crate::statics::{SolverSettings, Statics};

/// Which rows of `--data` to evaluate.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// Every row (e.g. a separate test file).
    All,
    /// Only the held-out test split `tendril train` left out (same --seed, --test-fraction).
    Test,
}

/// Evaluate a trained net: tension RMSE, task-space tip error, inference time.
#[derive(clap::Args, Debug)]
pub struct EvaluateArgs {
    /// Weight file written by `tendril train`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// Dataset CSV (t0..,px,py,pz,qw,qx,qy,qz) with the true tensions and poses.
    #[arg(long, value_name = "CSV")]
    pub data: PathBuf,
    #[command(flatten)]
    pub robot: super::common::RobotArg,
    /// Rows to evaluate.
    #[arg(long, value_enum, default_value_t = Rows::All)]
    pub rows: Rows,
    /// Split seed (with --rows test; must match `tendril train --seed`).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Test fraction (with --rows test; must match `tendril train`).
    #[arg(long, default_value_t = 0.03)]
    pub test_fraction: f64,
    /// Metrics JSON to write; default: <model>.eval.json.
    #[arg(long, value_name = "JSON")]
    pub json_out: Option<PathBuf>,
}

/// Mean wall time of one f32 inference (ns), timing batches on one thread for ≥ 50 ms.
pub fn inference_ns(net: &HostNet, poses: &nalgebra::DMatrix<f64>) -> f64 {
    if poses.nrows() == 0 {
        return f64::NAN;
    }
    let mut n = 0usize;
    let t = Instant::now();
    while t.elapsed().as_millis() < 50 {
        std::hint::black_box(infer_batch(net, std::hint::black_box(poses)));
        n += poses.nrows();
    }
    t.elapsed().as_nanos() as f64 / n as f64
}

/// Metrics of `net` on `data` (all rows), with the statics of `statics`.
pub fn evaluate_net(
    statics: &Statics,
    net: &HostNet,
    data: &Dataset,
) -> anyhow::Result<SplitMetrics> {
    if net.shape().outputs != data.n_tendons {
        anyhow::bail!(
            "the model predicts {} tensions but the data has {} tendons",
            net.shape().outputs,
            data.n_tendons
        );
    }
    if statics.robot().n_tendons() != data.n_tendons {
        anyhow::bail!(
            "the robot has {} tendons but the data has {}",
            statics.robot().n_tendons(),
            data.n_tendons
        );
    }
    let pred = infer_batch(net, &data.poses);
    let lo: Vec<f64> = net.output_lo().iter().map(|&x| f64::from(x)).collect();
    let hi: Vec<f64> = net.output_hi().iter().map(|&x| f64::from(x)).collect();
    let ns = inference_ns(net, &data.poses);
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

/// Run `tendril evaluate`.
pub fn run(a: EvaluateArgs) -> anyhow::Result<()> {
    let net = read_tnet(&a.model)?;
    let (robot, _) = a.robot.load()?;
    let mut data = Dataset::read_csv(&a.data)?;
    if a.rows == Rows::Test {
        let (_, test) = split_indices(data.len(), a.test_fraction, a.seed);
        data = data.rows(&test);
    }
    let statics = Statics::new(&robot, settings_for(&a.data));
    let m = evaluate_net(&statics, &net, &data)?;
    print!(
        "{}",
        m.table(&format!(
            "{} on {} ({} hidden units)",
            a.model.display(),
            a.data.display(),
            net.shape().hidden
        ))
    );
    let out = a
        .json_out
        .clone()
        .unwrap_or_else(|| a.model.with_extension("eval.json"));
    let json = serde_json::json!({
        "model": a.model.display().to_string(),
        "data": a.data.display().to_string(),
        "rows": format!("{:?}", a.rows).to_lowercase(),
        "hidden_units": net.shape().hidden,
        "metrics": m,
    });
    crate::fsutil::write_atomic(&out, serde_json::to_string_pretty(&json)?.as_bytes())
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
