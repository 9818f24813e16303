//! Arguments and helpers several subcommands share.

use std::path::PathBuf;

use anyhow::Context;

use crate::robot::{Robot, DEFAULT_ROBOT};

/// `--robot FILE`, defaulting to the seed robot.
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArg {
    /// Robot description (TOML, docs/design.md §2 schema).
    #[arg(long, value_name = "FILE", default_value = DEFAULT_ROBOT)]
    pub robot: PathBuf,
}

impl RobotArg {
    /// Load and validate the robot; the error names file, field and problem.
    pub fn load(&self) -> anyhow::Result<(Robot, String)> {
        Ok(Robot::load_with_source(&self.robot)?)
    }
}

/// Parse a comma-separated list of numbers (`2,0,0,0`).
pub fn parse_list(text: &str, what: &str) -> anyhow::Result<Vec<f64>> {
    text.split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .with_context(|| format!("{what}: {s:?} is not a number"))
        })
        .collect()
}

/// Refuse `-` (stdout) for an output that is not one stream of bytes: a
/// directory, or a file that other files are written beside. `why` says
/// what the option names. Single-file outputs take `-` through
/// [`crate::fsutil::write_atomic_with`].
pub fn refuse_stdout(option: &str, path: &std::path::Path, why: &str) -> anyhow::Result<()> {
    if crate::fsutil::is_stdout(path) {
        anyhow::bail!(
            "{option} -: {why}, not a single stream; give a path (`./-` for a file named -)"
        );
    }
    Ok(())
}

/// The Ctrl-C stop flag: the first Ctrl-C asks long commands to stop
/// between work units, writing nothing (see [`crate::interrupt`]).
pub use crate::interrupt::stop_flag;
