//! Command-line interface: one file per subcommand, each an argument struct
//! plus a call into the library. The contract is `DESIGN.md` §7.

use clap::{Parser, Subcommand};

/// Learn and run inverse kinematics of tendon-driven continuum robots.
///
/// With no subcommand, runs the whole pipeline on the default robot and
/// writes a report and figures under `out/`.
#[derive(Parser, Debug)]
#[command(name = "tendril", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {}

/// Parse `std::env::args` and run the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        None => crate::pipeline::run_default(),
    }
}
