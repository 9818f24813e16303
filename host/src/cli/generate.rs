//! `tendril generate`: the tension ↔ pose dataset (DESIGN §3).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use sha2::{Digest, Sha256};

use super::common::{stop_flag, RobotArg};
use crate::dataset::generate::{column_ranges, generate, GenerateOptions};
use crate::dataset::split::{prepare, SPLIT_SEED, TEST_FRACTION};
use crate::dataset::{Sampler, Sidecar};
use crate::statics::{SolverSettings, Statics};

/// Sample tensions, solve the statics for each, write CSV + JSON sidecar.
#[derive(clap::Args, Debug, Clone)]
pub struct GenerateArgs {
    #[command(flatten)]
    pub robot: RobotArg,
    /// Number of samples.
    #[arg(long, default_value_t = 20_000)]
    pub samples: usize,
    /// Random seed of the sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Tension sampler [default: adjacent for robots with more than two tendons, else uniform].
    #[arg(long, value_enum)]
    pub sampler: Option<Sampler>,
    /// Output CSV; the sidecar goes beside it as <name>.json.
    #[arg(long, value_name = "CSV", default_value = "data.csv")]
    pub out: PathBuf,
    /// Fail (exit non-zero, after writing) if more than this fraction of solves fails.
    #[arg(long, default_value_t = 0.001)]
    pub max_failure_fraction: f64,
    /// Held-out test fraction recorded for the learners (split seed 1).
    #[arg(long, default_value_t = TEST_FRACTION)]
    pub test_fraction: f64,
    /// RK4 steps over the length.
    #[arg(long, default_value_t = SolverSettings::default().steps)]
    pub steps: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Run `tendril generate`.
pub fn run(args: GenerateArgs) -> anyhow::Result<()> {
    let sidecar = generate_dataset(&args)?;
    log::info!(
        "wrote {} rows to {} in {:.2} s ({} re-solved cold, {} dropped)",
        sidecar.count,
        args.out.display(),
        sidecar.seconds,
        sidecar.resolved_cold,
        sidecar.dropped
    );
    let fraction = sidecar.dropped as f64 / sidecar.requested as f64;
    if fraction > args.max_failure_fraction {
        bail!(
            "{} of {} solves failed ({:.2} %, above --max-failure-fraction {}); see {}",
            sidecar.dropped,
            sidecar.requested,
            100.0 * fraction,
            args.max_failure_fraction,
            Sidecar::path_for(&args.out).display()
        );
    }
    Ok(())
}

/// Generate and write the dataset and its sidecar; returns the sidecar.
pub fn generate_dataset(args: &GenerateArgs) -> anyhow::Result<Sidecar> {
    let (robot, source) = args.robot.load()?;
    if !(0.0..1.0).contains(&args.test_fraction) {
        bail!(
            "--test-fraction must be in [0, 1), got {}",
            args.test_fraction
        );
    }
    let settings = SolverSettings {
        steps: args.steps.max(1),
        ..SolverSettings::default()
    };
    let statics = Statics::new(&robot, settings);
    let sampler = args
        .sampler
        .unwrap_or(Sampler::default_for(robot.n_tendons()));
    let opts = GenerateOptions {
        samples: args.samples,
        seed: args.seed,
        sampler,
        progress: !args.quiet,
    };
    let out = generate(&statics, &opts, stop_flag())?;
    for (t, e) in &out.failures {
        log::warn!("dropped sample {t:?}: {e}");
    }
    if out.data.is_empty() {
        bail!(
            "every solve failed: nothing to write (first failure: {:?})",
            out.failures.first()
        );
    }
    let prepared = prepare(&out.data, args.test_fraction, 0.0, SPLIT_SEED);
    let sidecar = Sidecar {
        robot_file: args.robot.robot.display().to_string(),
        robot_sha256: hex(&Sha256::digest(source.as_bytes())),
        robot_name: robot.name.clone(),
        sampler: sampler.name().into(),
        seed: args.seed,
        requested: args.samples,
        count: out.data.len(),
        solver: settings,
        ranges: column_ranges(&out.data),
        resolved_cold: out.resolved_cold,
        dropped: out.dropped,
        failure_policy: "a warm-started solve that misses the tolerance is re-solved cold; \
                         a sample whose cold solve fails too is dropped and counted here"
            .into(),
        test_fraction: args.test_fraction,
        train_ranges: Some(prepared.ranges()),
        seconds: out.seconds,
        tendril_version: env!("CARGO_PKG_VERSION").into(),
    };
    out.data
        .write_csv(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    sidecar.write(&Sidecar::path_for(&args.out))?;
    Ok(sidecar)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether `path` looks like a dataset this command wrote for `args`
/// (same robot bytes, sampler, seed and count) — lets the pipeline reuse it.
pub fn is_up_to_date(args: &GenerateArgs, path: &Path) -> bool {
    let Ok(side) = Sidecar::read(&Sidecar::path_for(path)) else {
        return false;
    };
    let Ok((robot, source)) = args.robot.load() else {
        return false;
    };
    let sampler = args
        .sampler
        .unwrap_or(Sampler::default_for(robot.n_tendons()));
    path.exists()
        && side.robot_sha256 == hex(&Sha256::digest(source.as_bytes()))
        && side.sampler == sampler.name()
        && side.seed == args.seed
        && side.requested == args.samples
        && side.solver.steps == args.steps
}
