//! `tendril evaluate`: the `docs/design.md` §4 metrics of a `.tnet` net on a
//! dataset — tension RMSE, task-space error through the statics, inference time.

use std::path::PathBuf;

use crate::jobs::evaluate::{self as job, EvaluateJob, RowSelection};

/// Which rows of `--data` to evaluate.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// Every row (e.g. a separate test file).
    All,
    /// Only the held-out test split `tendril train` left out (the split the net records).
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
    /// Split seed (with --rows test) [default: the seed the net records, else 1]; a seed
    /// other than the one the net records is refused (its "test" rows would be training rows).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Test fraction in (0, 0.5] (with --rows test) [default: the one the net records, else
    /// 0.03]; another than the net's is refused.
    #[arg(long)]
    pub test_fraction: Option<f64>,
    /// Evaluate a net trained for another robot than --robot (with a warning) instead of refusing it.
    #[arg(long)]
    pub allow_robot_mismatch: bool,
    /// Metrics JSON to write; default: <model>.eval.json.
    #[arg(long, value_name = "JSON")]
    pub json_out: Option<PathBuf>,
}

impl EvaluateArgs {
    /// The evaluation these arguments describe.
    pub fn job(&self) -> EvaluateJob {
        EvaluateJob {
            model: self.model.clone(),
            data: self.data.clone(),
            robot: self.robot.robot.clone(),
            rows: match self.rows {
                Rows::All => RowSelection::All,
                Rows::Test => RowSelection::Test {
                    seed: self.seed,
                    test_fraction: self.test_fraction,
                },
            },
            allow_robot_mismatch: self.allow_robot_mismatch,
            json_out: self
                .json_out
                .clone()
                .unwrap_or_else(|| self.model.with_extension("eval.json")),
        }
    }
}

/// Run `tendril evaluate`: the table to stdout, the JSON to `--json-out`
/// (the table to stderr when the JSON goes to stdout, `--json-out -`).
pub fn run(a: EvaluateArgs) -> anyhow::Result<()> {
    let job = a.job();
    let e = job::run(&job)?;
    let to_stderr = crate::fsutil::is_stdout(&job.json_out);
    let say = |text: String| {
        if to_stderr {
            eprint!("{text}");
        } else {
            print!("{text}");
        }
    };
    say(e.metrics.table(&format!(
        "{} on {} ({} hidden units)",
        job.model.display(),
        job.data.display(),
        e.hidden_units
    )));
    let r = &e.refinement;
    let (net, refined) = (&r.net_tip_error_mm, &r.refined_tip_error_mm);
    let mm = crate::units::length_mm;
    say(format!(
        "net alone vs net + exact IK ({} rows, pose targets): tip error mean / p95 / max \
         {} / {} / {} in {} µs vs {} / {} / {} in {} µs per query \
         ({} out of reach, {} not converged)\n",
        r.rows,
        mm(net.mean),
        mm(net.p95),
        mm(net.max),
        crate::units::number(r.net_us_per_query, 1),
        mm(refined.mean),
        mm(refined.p95),
        mm(refined.max),
        crate::units::number(r.refined_us_per_query, 0),
        r.unreachable,
        r.failed
    ));
    log::info!("wrote {}", job.json_out.display());
    Ok(())
}
