//! `tendril compare`: every learner on one split — Table II and Figure 3.

use std::path::PathBuf;
use std::time::Instant;

use super::common::RobotArg;
use crate::compare::job::{self, CompareJob};
use crate::compare::CompareOptions;

/// Train cascade correlation and the six baselines on the same split and
/// compare them (tension RMSE, task-space error, time, size). The dataset
/// needs at least 50 rows.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Dataset CSV (from `tendril generate`).
    #[arg(long, value_name = "CSV")]
    pub data: PathBuf,
    #[command(flatten)]
    pub robot: RobotArg,
    /// Directory for compare.md, compare.csv and compare.png.
    #[arg(long, value_name = "DIR", default_value = "out")]
    pub out: PathBuf,
    /// Seed of the split and of every learner.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Fraction of rows held out for testing, in (0, 0.5].
    #[arg(long, default_value_t = 0.03)]
    pub test_fraction: f64,
    /// Fraction of the training rows used for validation (hyper-parameter choice), in (0, 0.5].
    #[arg(long, default_value_t = 0.1)]
    pub valid_fraction: f64,
    /// Training rows pushed through the statics for the train-split task-space error (0 = all).
    #[arg(long, default_value_t = 1000)]
    pub train_task_rows: usize,
    /// Also write the normalised splits here (input of scripts/python/baselines_reference.py).
    #[arg(long, value_name = "DIR")]
    pub dump_splits: Option<PathBuf>,
    /// Outliers of the tip in the training rows [default: reject for a dataset without a
    /// sidecar (measured rows, docs/design.md §3.1), else keep].
    #[arg(long, value_enum)]
    pub outliers: Option<super::train::OutliersArg>,
    /// Synthetic measured rows: the noiseless rows behind --data (same tensions, same order);
    /// the test split is judged against them on --true-robot. Needs --true-robot.
    #[arg(long, value_name = "CSV", requires = "true_robot")]
    pub true_data: Option<PathBuf>,
    /// The robot that made --true-data. Needs --true-data.
    #[arg(long, value_name = "FILE", requires = "true_data")]
    pub true_robot: Option<PathBuf>,
}

impl CompareArgs {
    /// The comparison these arguments describe.
    pub fn job(&self) -> CompareJob {
        CompareJob {
            data: self.data.clone(),
            robot: self.robot.robot.clone(),
            out_dir: self.out.clone(),
            options: CompareOptions {
                test_fraction: self.test_fraction,
                valid_fraction: self.valid_fraction,
                seed: self.seed,
                train_task_rows: self.train_task_rows,
                dump_splits: self.dump_splits.clone(),
                ..CompareOptions::default()
            },
            reject_outliers: self
                .outliers
                .map(|o| o == super::train::OutliersArg::Reject),
            truth: self.true_data.clone().zip(self.true_robot.clone()),
        }
    }
}

/// Run `tendril compare`.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout("--out", &args.out, "names a directory")?;
    if let Some(d) = &args.dump_splits {
        super::common::refuse_stdout("--dump-splits", d, "names a directory")?;
    }
    let t = Instant::now();
    let r = job::run(&args.job())?;
    for f in &r.files {
        log::info!("wrote {}", f.display());
    }
    for b in r.comparison.beats() {
        log::info!("{b}");
    }
    log::info!("comparison took {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
