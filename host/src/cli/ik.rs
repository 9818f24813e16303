//! `tendril ik`: tensions for tip poses through a `.tnet` net, checked and
//! clamped to the robot's limits by [`crate::ik_net`].

use std::path::PathBuf;

use anyhow::bail;

use super::common::{parse_list, RobotArg};
use crate::ik_net::{solve_csv, IkNet};

/// Inverse kinematics: tip pose → tendon tensions (N) with a trained net.
#[derive(clap::Args, Debug)]
pub struct IkArgs {
    /// Weight file written by `tendril train`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// The robot the net drives: tensions are clamped to its limits.
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
    /// Print `{"tensions":[...],"raw":[...]}` (clamped, unclamped) instead of plain numbers.
    #[arg(long)]
    pub json: bool,
    /// Answer poses outside the net's training ranges (with a warning) instead of refusing them.
    #[arg(long)]
    pub allow_extrapolation: bool,
    /// Batch input CSV with columns px,py,pz,qw,qx,qy,qz (others ignored).
    #[arg(long, value_name = "CSV", requires = "output")]
    pub input: Option<PathBuf>,
    /// Batch output CSV: t0.. (clamped) and raw_t0.. (net output), N; written atomically.
    #[arg(long, value_name = "CSV", requires = "input")]
    pub output: Option<PathBuf>,
}

/// Run `tendril ik`.
pub fn run(a: IkArgs) -> anyhow::Result<()> {
    let (robot, _) = a.robot.load()?;
    let ik = IkNet::load(&a.model, &robot, a.allow_extrapolation)?;
    if let Some(text) = &a.pose {
        let values = parse_list(text, "--pose")?;
        let Ok(pose) = <[f64; 7]>::try_from(values.as_slice()) else {
            bail!(
                "--pose needs 7 numbers px,py,pz,qw,qx,qy,qz, got {}",
                values.len()
            );
        };
        let answer = ik.solve(&pose)?;
        if !answer.extrapolated.is_empty() {
            log::warn!(
                "pose outside the net's training range in {}: the net extrapolates",
                answer.extrapolated.join(", ")
            );
        }
        if !answer.beyond_limits.is_empty() {
            log::warn!(
                "net output {:?} N is beyond the robot's limits: clamped",
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
    let s = solve_csv(&ik, input, output)?;
    eprintln!(
        "wrote {} ({} {}, {} beyond the limits and clamped, {} extrapolated)",
        output.display(),
        s.rows,
        if s.rows == 1 { "row" } else { "rows" },
        s.beyond_limits,
        s.extrapolated
    );
    Ok(())
}
