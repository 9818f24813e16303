//! Arguments and helpers several subcommands share.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use anyhow::Context;

use crate::robot::{Robot, DEFAULT_ROBOT};

/// `--robot FILE`, defaulting to the seed robot.
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArg {
    /// Robot description (TOML, DESIGN §2 schema).
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

/// A flag set by Ctrl-C, so long commands stop between work units and
/// write nothing half-done. Installs the handler on first use.
pub fn stop_flag() -> &'static AtomicBool {
    static STOP: OnceLock<&'static AtomicBool> = OnceLock::new();
    STOP.get_or_init(|| {
        let flag: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
        // If a handler is already installed (a library user's), keep theirs.
        let _ = ctrlc::set_handler(move || {
            if flag.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupted: finishing the current step, writing nothing partial (Ctrl-C again to abort)");
        });
        flag
    })
}
