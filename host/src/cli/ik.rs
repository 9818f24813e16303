//! `tendril ik`: tensions for tip poses through a `.tnet` net, checked and
//! through the firmware's command stage by [`crate::net`]; with `--exact`, the
//! model-based IK of [`crate::inverse`] (the net's guess as its start).

use std::path::PathBuf;

use anyhow::bail;

use super::common::{parse_list, RobotArg};
use crate::inverse::{ExactIk, IkSettings};
use crate::jobs;
use crate::net::{solve_csv, GuardedNet};
use crate::robot::count;

/// Inverse kinematics: tip pose → tendon tensions (N) with a trained net,
/// or exactly through the statics (`--exact`).
#[derive(clap::Args, Debug)]
pub struct IkArgs {
    /// Weight file written by `tendril train` (with --exact: the start guess).
    #[arg(long, value_name = "FILE", required_unless_present = "exact")]
    pub model: Option<PathBuf>,
    /// Exact model-based IK: tensions whose statics reach the target to 1e-7 m.
    #[arg(long)]
    pub exact: bool,
    /// With --exact: reach the tip position only (the quaternion is checked, not targeted).
    #[arg(long, requires = "exact")]
    pub position_only: bool,
    /// The robot the net drives: the command stage keeps tensions in its limits.
    #[command(flatten)]
    pub robot: RobotArg,
    /// One pose: px,py,pz,qw,qx,qy,qz (m, unit quaternion w first).
    #[arg(
        long,
        value_name = "POSE",
        allow_hyphen_values = true,
        conflicts_with = "input"
    )]
    pub pose: Option<String>,
    /// Print `{"tensions":[...],"raw":[...]}` (staged, net output) instead of plain numbers.
    #[arg(long)]
    pub json: bool,
    /// Answer poses outside the net's training ranges (with a warning) instead of refusing them.
    #[arg(long)]
    pub allow_extrapolation: bool,
    /// Use a net trained for another robot than --robot (with a warning) instead of refusing it.
    #[arg(long)]
    pub allow_robot_mismatch: bool,
    /// Take (and with --exact give) poses in the robot's base frame, not the
    /// tracker's frame of the robot file's `[base]` (the same without one).
    #[arg(long)]
    pub base_frame: bool,
    /// Batch input CSV with columns px,py,pz,qw,qx,qy,qz (others ignored).
    #[arg(long, value_name = "CSV", requires = "output")]
    pub input: Option<PathBuf>,
    /// Batch output CSV: t0.. (command stage) and raw_t0.. (net output), N; with --exact t0..,
    /// the reached pose, its errors, `reachable` and `status` (exact, closest or failed), every
    /// row answered, exit non-zero when any row was not reached. Written atomically.
    #[arg(long, value_name = "CSV", requires = "input")]
    pub output: Option<PathBuf>,
}

/// The `--pose` argument as 7 numbers.
fn parse_pose(text: &str) -> anyhow::Result<[f64; 7]> {
    let values = parse_list(text, "--pose")?;
    let Ok(pose) = <[f64; 7]>::try_from(values.as_slice()) else {
        bail!(
            "--pose needs 7 numbers px,py,pz,qw,qx,qy,qz, got {}",
            values.len()
        );
    };
    Ok(pose)
}

/// `tendril ik --exact`.
fn run_exact(a: &IkArgs, robot: &crate::robot::Robot) -> anyhow::Result<()> {
    let net = match &a.model {
        Some(m) => Some(GuardedNet::load(m, robot, true, a.allow_robot_mismatch)?),
        None => None,
    };
    let ik = ExactIk::new(robot, IkSettings::default());
    if let Some(text) = &a.pose {
        let answer =
            jobs::ik_batch::answer(&ik, net.as_ref(), &parse_pose(text)?, a.position_only)?;
        if a.json {
            println!("{}", answer.to_json());
        } else {
            let s: Vec<String> = answer
                .solution
                .tensions
                .iter()
                .map(f64::to_string)
                .collect();
            println!("{}", s.join(","));
        }
        if !answer.reachable {
            bail!(
                "target out of reach: printed the closest reachable pose, {:.6} m away ({})",
                answer.solution.position_error,
                answer.solution.active_limits()
            );
        }
        return Ok(());
    }
    let (Some(input), Some(output)) = (&a.input, &a.output) else {
        bail!("give --pose px,py,pz,qw,qx,qy,qz or --input poses.csv --output tensions.csv");
    };
    let s = jobs::ik_batch::solve_csv(&ik, net.as_ref(), a.position_only, input, output)?;
    eprintln!(
        "wrote {} ({}: {} reached, {} out of reach, {} failed; worst reached error {:.2e} m)",
        output.display(),
        count(s.rows, "row"),
        s.rows - s.unreachable - s.failed,
        s.unreachable,
        s.failed,
        s.worst_reached
    );
    // As `fk --input`: every row is written, and the exit status is 0 only
    // when every target was reached; as a single `--pose`, a target out of
    // reach is not reached (its closest pose is written all the same).
    let out = output.display();
    match (s.unreachable, s.failed) {
        (0, 0) => Ok(()),
        (u, 0) => bail!(
            "{u} of {} out of reach (closest pose written, status=closest in {out})",
            count(s.rows, "row")
        ),
        (0, f) => bail!(
            "{f} of {} failed: the exact IK did not converge (status=failed in {out})",
            count(s.rows, "row")
        ),
        (u, f) => bail!(
            "{} of {} not reached: {u} out of reach (closest pose written, status=closest), \
             {f} failed (status=failed) in {out}",
            u + f,
            count(s.rows, "row")
        ),
    }
}

/// Run `tendril ik`.
pub fn run(a: IkArgs) -> anyhow::Result<()> {
    let (mut robot, _) = a.robot.load()?;
    if a.base_frame {
        robot.base = crate::robot::BasePose::IDENTITY;
    }
    // The net answers in the base frame: a target in the tracker's frame
    // (`docs/design.md` §2.4) is mapped to it first.
    let to_base = robot.base.to_base();
    if a.exact {
        return run_exact(&a, &robot);
    }
    let Some(model) = &a.model else {
        bail!("give --model model.tnet (or --exact)");
    };
    let ik = GuardedNet::load(model, &robot, a.allow_extrapolation, a.allow_robot_mismatch)?;
    if let Some(text) = &a.pose {
        let pose = to_base.pose(parse_pose(text)?);
        let answer = ik.solve(&pose)?;
        if !answer.extrapolated.is_empty() {
            log::warn!(
                "pose outside the net's training range in {}: the net extrapolates",
                answer.extrapolated.join(", ")
            );
        }
        if !answer.beyond_limits.is_empty() {
            log::warn!(
                "net output {:?} N is beyond the robot's limits even after the co-contraction shift: clipped",
                answer.raw
            );
        }
        if a.json {
            println!(
                "{}",
                serde_json::json!({ "tensions": answer.tensions, "raw": answer.raw })
            );
        } else {
            let s: Vec<String> = answer.tensions.iter().map(f64::to_string).collect();
            println!("{}", s.join(","));
        }
        return Ok(());
    }
    let (Some(input), Some(output)) = (&a.input, &a.output) else {
        bail!("give --pose px,py,pz,qw,qx,qy,qz or --input poses.csv --output tensions.csv");
    };
    let s = solve_csv(&ik, input, output, &to_base)?;
    eprintln!(
        "wrote {} ({} {}, {} beyond the limits and clipped, {} extrapolated)",
        output.display(),
        s.rows,
        if s.rows == 1 { "row" } else { "rows" },
        s.beyond_limits,
        s.extrapolated
    );
    Ok(())
}
