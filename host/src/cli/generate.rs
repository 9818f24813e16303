//! `tendril generate`: the tension ↔ pose dataset (docs/design.md §3).

use std::path::PathBuf;

use super::common::{stop_flag, RobotArg};
use crate::dataset::job::{self, GenerateRequest, DEFAULT_MAX_FAILURE_FRACTION, DEFAULT_SAMPLES};
use crate::dataset::split::TEST_FRACTION;
use crate::dataset::Sampler;
use crate::statics::SolverSettings;

/// Sample tensions, solve the statics for each, write CSV + JSON sidecar.
#[derive(clap::Args, Debug, Clone)]
pub struct GenerateArgs {
    #[command(flatten)]
    pub robot: RobotArg,
    /// Number of samples (1 to 20,000,000).
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// Random seed of the sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Tension sampler [default: adjacent for robots with more than two tendons, else uniform].
    #[arg(long, value_enum)]
    pub sampler: Option<Sampler>,
    /// Output CSV, a regular file (not a device or FIFO); the sidecar goes beside it as <name>.json.
    #[arg(long, value_name = "CSV", default_value = "data.csv")]
    pub out: PathBuf,
    /// Fail (exit non-zero, after writing) if more than this fraction of solves fails.
    #[arg(long, default_value_t = DEFAULT_MAX_FAILURE_FRACTION)]
    pub max_failure_fraction: f64,
    /// Held-out test fraction recorded for the learners (split seed 1).
    #[arg(long, default_value_t = TEST_FRACTION)]
    pub test_fraction: f64,
    /// RK4 steps over the length (1 to 100,000).
    #[arg(long, default_value_t = SolverSettings::default().steps)]
    pub steps: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

impl GenerateArgs {
    /// The library request these arguments ask for.
    pub fn request(&self) -> GenerateRequest {
        GenerateRequest {
            robot_path: self.robot.robot.clone(),
            samples: self.samples,
            seed: self.seed,
            sampler: self.sampler,
            out: self.out.clone(),
            max_failure_fraction: self.max_failure_fraction,
            test_fraction: self.test_fraction,
            steps: self.steps,
        }
    }
}

/// Run `tendril generate`.
pub fn run(args: GenerateArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout(
        "--out",
        &args.out,
        "a dataset is a CSV with its sidecar (.json) beside it",
    )?;
    let sidecar = job::generate(&args.request(), !args.quiet, stop_flag())?;
    log::info!(
        "wrote {} to {} in {:.2} s ({} re-solved cold, {} dropped)",
        rows(sidecar.count),
        args.out.display(),
        sidecar.seconds,
        sidecar.resolved_cold,
        sidecar.dropped
    );
    Ok(())
}

fn rows(n: usize) -> String {
    if n == 1 {
        "1 row".into()
    } else {
        format!("{n} rows")
    }
}
