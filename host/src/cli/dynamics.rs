//! `tendril dynamics`: a tension step response of the dynamic rod
//! (`docs/design.md` §4.2), tip trajectory CSV and figure.

use std::path::PathBuf;

use super::common::{stop_flag, RobotArg};
use crate::dynamics::{Damping, DynamicsSettings};
use crate::jobs::dynamics::{run as run_offline, OfflineRun, TensionStep};

/// Step the tendon tensions and record how the robot's tip moves and rings.
#[derive(clap::Args, Debug)]
pub struct DynamicsArgs {
    #[command(flatten)]
    robot: RobotArg,
    /// Tensions (N) before and after the step, and its time (s): `0,0,0,0:2,0,0,0@0.1`.
    #[arg(long, value_name = "BEFORE:AFTER@SECONDS")]
    tensions_step: String,
    /// Simulated time, s.
    #[arg(long, value_name = "SECONDS", default_value_t = 3.0)]
    duration: f64,
    /// Time step, s.
    #[arg(long, value_name = "SECONDS", default_value_t = DynamicsSettings::default().dt_s)]
    dt: f64,
    /// BDF-alpha parameter in [-0.5, 0] (0 = BDF2, -0.5 = trapezoidal).
    #[arg(long, allow_hyphen_values = true, default_value_t = DynamicsSettings::default().alpha)]
    alpha: f64,
    /// RK4 steps over the backbone (spatial grid).
    #[arg(long, default_value_t = DynamicsSettings::default().steps)]
    steps: usize,
    /// Output directory: tip.csv (t,px,py,pz,vx,vy,vz; s, m, m/s), tip.png
    /// and run.mcap (the swinging rod for Foxglove).
    #[arg(long, value_name = "DIR", default_value = "out/dynamics")]
    out: PathBuf,
    /// Do not write run.mcap.
    #[arg(long)]
    no_mcap: bool,
}

/// Run `tendril dynamics`.
pub fn run(args: DynamicsArgs) -> anyhow::Result<()> {
    super::common::refuse_stdout("--out", &args.out, "names a directory")?;
    let (robot, _) = args.robot.load()?;
    let job = OfflineRun {
        damping: Damping::of_robot(&robot),
        robot,
        step: TensionStep::parse(&args.tensions_step)?,
        duration_s: args.duration,
        settings: DynamicsSettings {
            dt_s: args.dt,
            alpha: args.alpha,
            steps: args.steps,
            ..DynamicsSettings::default()
        },
        out: args.out,
        progress: log::log_enabled!(log::Level::Info),
        mcap: !args.no_mcap,
    };
    let csv = run_offline(&job, stop_flag())?;
    println!("{}", csv.display());
    Ok(())
}
