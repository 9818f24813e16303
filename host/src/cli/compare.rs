//! `tendril compare`: every learner on one split — Table II and Figure 3.

use std::path::PathBuf;
use std::time::Instant;

use super::common::RobotArg;
use crate::compare::{all_learners, compare, CompareOptions};
use crate::dataset::Dataset;

/// Train cascade correlation and the six baselines on the same split and
/// compare them (tension RMSE, task-space error, time, size).
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
    /// Fraction of rows held out for testing.
    #[arg(long, default_value_t = 0.03)]
    pub test_fraction: f64,
    /// Fraction of the training rows used for validation (hyper-parameter choice).
    #[arg(long, default_value_t = 0.1)]
    pub valid_fraction: f64,
    /// Training rows pushed through the statics for the train-split task-space error (0 = all).
    #[arg(long, default_value_t = 1000)]
    pub train_task_rows: usize,
    /// Also write the normalised splits here (input of scripts/python/baselines_reference.py).
    #[arg(long, value_name = "DIR")]
    pub dump_splits: Option<PathBuf>,
}

/// Run `tendril compare`.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    for (name, v) in [
        ("--test-fraction", args.test_fraction),
        ("--valid-fraction", args.valid_fraction),
    ] {
        if !(v > 0.0 && v < 1.0) {
            anyhow::bail!("{name} must be strictly between 0 and 1, got {v}");
        }
    }
    let t = Instant::now();
    let data = Dataset::read_csv(&args.data)?;
    let (robot, _) = args.robot.load()?;
    let opts = CompareOptions {
        test_fraction: args.test_fraction,
        valid_fraction: args.valid_fraction,
        seed: args.seed,
        train_task_rows: args.train_task_rows,
        dump_splits: args.dump_splits,
        ..CompareOptions::default()
    };
    let cmp = compare(&data, &robot, all_learners(), &opts)?;
    let files = cmp.write(&args.out)?;
    for f in &files {
        log::info!("wrote {}", f.display());
    }
    for b in cmp.beats() {
        log::info!("{b}");
    }
    log::info!("comparison took {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
