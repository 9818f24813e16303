//! `tendril run`: the main job on any robot file (`cargo run --release`
//! with no subcommand is `tendril run` on the default robot into `out/`).

use std::path::PathBuf;

use super::common::RobotArg;

/// Run the whole pipeline (dataset → net → comparison → firmware parity →
/// closed loop) on a robot file, writing a report and figures.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    #[command(flatten)]
    pub robot: RobotArg,
    /// Output directory (default: `out/` for the default robot, else
    /// `out/<file stem>/`).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Dataset size (default: `tendril generate`'s for the robot).
    #[arg(long, value_name = "N")]
    pub samples: Option<usize>,
    /// A smoke run to check a new robot file end to end in a minute or two:
    /// 2,000 samples, at most 16 hidden units, 4-second closed-loop runs.
    #[arg(long)]
    pub quick: bool,
    /// Skip the firmware-parity stage (MCU build under QEMU).
    #[arg(long)]
    pub no_parity: bool,
    /// Skip the closed-loop stage (real-time processes).
    #[arg(long)]
    pub no_closed_loop: bool,
}

/// Run `tendril run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    // Validate first, so a bad file is one clear error before any work.
    if let Some(out) = &args.out {
        super::common::refuse_stdout("--out", out, "names a directory")?;
    }
    args.robot.load()?;
    let out = args
        .out
        .unwrap_or_else(|| crate::pipeline::default_out_dir(&args.robot.robot));
    let options = crate::pipeline::RunOptions {
        samples: args.samples,
        quick: args.quick,
        no_parity: args.no_parity,
        no_closed_loop: args.no_closed_loop,
    };
    let command = format!(
        "tendril run --robot {}{}{}{}",
        args.robot.robot.display(),
        if args.quick { " --quick" } else { "" },
        if args.no_parity { " --no-parity" } else { "" },
        if args.no_closed_loop {
            " --no-closed-loop"
        } else {
            ""
        }
    );
    crate::pipeline::run(&args.robot.robot, &out, &options, command)
}
