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

/// The Ctrl-C stop flag: the first Ctrl-C asks long commands to stop
/// between work units, writing nothing (see [`crate::interrupt`]).
pub use crate::interrupt::stop_flag;
