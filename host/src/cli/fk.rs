//! `tendril fk`: forward statics, one pose or a CSV batch (`docs/design.md` §7;
//! the batch is the job [`crate::jobs::fk_batch`]).

use std::path::PathBuf;

use anyhow::bail;
use nalgebra::Vector3;
use serde_json::json;

use super::common::{parse_list, stop_flag, RobotArg};
use crate::jobs::fk_batch;
use crate::robot::count;
use crate::statics::batch::Load;
use crate::statics::{SolverSettings, Statics, MAX_STEPS};

/// Tip pose for given tendon tensions (Cosserat-rod statics).
#[derive(clap::Args, Debug)]
pub struct FkArgs {
    #[command(flatten)]
    robot: RobotArg,
    /// Tensions in newtons, one per tendon: `2,0,0,0`.
    #[arg(
        long,
        value_name = "T0,T1,..",
        allow_hyphen_values = true,
        conflicts_with = "input",
        required_unless_present = "input"
    )]
    tensions: Option<String>,
    /// External force on the tip, base frame, N: `fx,fy,fz`.
    #[arg(
        long,
        value_name = "FX,FY,FZ",
        allow_hyphen_values = true,
        conflicts_with = "input"
    )]
    tip_force: Option<String>,
    /// External moment on the tip, base frame, N m: `mx,my,mz`.
    #[arg(
        long,
        value_name = "MX,MY,MZ",
        allow_hyphen_values = true,
        conflicts_with = "input"
    )]
    tip_moment: Option<String>,
    /// Print one JSON object: position, quaternion (w,x,y,z), converged, residual, iterations.
    #[arg(long, conflicts_with_all = ["input", "output"])]
    json: bool,
    /// Also report N backbone points, base to tip.
    #[arg(long, value_name = "N", conflicts_with_all = ["input", "output"],
          value_parser = clap::value_parser!(u32).range(2..=100_000))]
    shape: Option<u32>,
    /// Batch mode: CSV with columns t0..t{n-1}, optionally fx,fy,fz,mx,my,mz
    /// (tip wrench, base frame). Exits non-zero, after writing the output,
    /// when any row did not converge.
    #[arg(long, value_name = "CSV", requires = "output")]
    input: Option<PathBuf>,
    /// Batch output: input columns plus px,py,pz,qw,qx,qy,qz,converged
    /// (columns of those names already in the input are overwritten). With
    /// --tensions: that one row (t0.., the tip load if given, the pose) as CSV.
    #[arg(long, value_name = "CSV")]
    output: Option<PathBuf>,
    /// Give poses in the robot's base frame, not the tracker's frame of the
    /// robot file's `[base]` (the same without one).
    #[arg(long)]
    base_frame: bool,
    /// RK4 steps over the length, 1 to 100000.
    #[arg(long, default_value_t = SolverSettings::default().steps)]
    steps: usize,
}

/// Run `tendril fk`.
pub fn run(args: FkArgs) -> anyhow::Result<()> {
    if !(1..=MAX_STEPS).contains(&args.steps) {
        bail!(
            "--steps: {} is outside 1..={MAX_STEPS} (RK4 steps over the backbone length)",
            args.steps
        );
    }
    let (mut robot, _) = args.robot.load()?;
    if args.base_frame {
        robot.base = crate::robot::BasePose::IDENTITY;
    }
    let settings = SolverSettings {
        steps: args.steps,
        ..SolverSettings::default()
    };
    let statics = Statics::new(&robot, settings);
    match (&args.tensions, &args.input, &args.output) {
        (Some(t), _, _) => {
            let load = Load {
                tensions: parse_list(t, "--tensions")?,
                tip_force: parse_vector(args.tip_force.as_deref(), "--tip-force")?,
                tip_moment: parse_vector(args.tip_moment.as_deref(), "--tip-moment")?,
            };
            match &args.output {
                Some(output) => fk_batch::single_to_csv(&statics, &load, t, output),
                None => single(&statics, &load, &args),
            }
        }
        (None, Some(input), Some(output)) => {
            let s = fk_batch::solve_csv(&statics, input, output, stop_flag(), true)?;
            if s.failed > 0 {
                bail!(
                    "{} of {} did not converge or have no stable equilibrium ({} \
                     unstable or not unique; converged=false in {})",
                    s.failed,
                    count(s.rows, "row"),
                    s.unstable,
                    output.display()
                );
            }
            Ok(())
        }
        _ => bail!("give --tensions, or --input and --output"),
    }
}

/// Three finite numbers `x,y,z`, or zero when the option is absent.
fn parse_vector(text: Option<&str>, what: &str) -> anyhow::Result<Vector3<f64>> {
    let Some(text) = text else {
        return Ok(Vector3::zeros());
    };
    let v = parse_list(text, what)?;
    if v.len() != 3 {
        bail!(
            "{what}: expected 3 numbers x,y,z (base frame), got {}",
            count(v.len(), "number")
        );
    }
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        bail!("{what}: {bad} is not a finite number");
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

fn single(statics: &Statics, load: &Load, args: &FkArgs) -> anyhow::Result<()> {
    let sol = statics.equilibrium(&load.tensions, load.tip_force, load.tip_moment, None)?;
    // Reported in the tracker's frame (the robot's `[base]`).
    let to_tracker = statics.robot().base.to_tracker();
    let shape = args.shape.map(|n| {
        let points = statics.shape(&sol, n as usize);
        points
            .iter()
            .map(|q| Vector3::from(to_tracker.point([q.x, q.y, q.z])))
            .collect::<Vec<_>>()
    });
    let pose = to_tracker.pose(sol.pose());
    let p = Vector3::new(pose[0], pose[1], pose[2]);
    let q = [pose[3], pose[4], pose[5], pose[6]];
    if args.json {
        let mut obj = json!({
            "position": [p.x, p.y, p.z],
            "quaternion": q,
            "converged": true,
            "residual": sol.residual,
            "iterations": sol.iterations,
        });
        if let Some(shape) = &shape {
            obj["shape"] = json!(shape.iter().map(|q| [q.x, q.y, q.z]).collect::<Vec<_>>());
        }
        println!("{obj}");
    } else {
        println!("position   [m]  {:+.9} {:+.9} {:+.9}", p.x, p.y, p.z);
        println!(
            "quaternion wxyz {:+.9} {:+.9} {:+.9} {:+.9}",
            q[0], q[1], q[2], q[3]
        );
        println!(
            "converged: residual {:.2e} after {}",
            sol.residual,
            count(sol.iterations, "iteration")
        );
        for (k, q) in shape.iter().flatten().enumerate() {
            println!("shape[{k}] {:+.6} {:+.6} {:+.6}", q.x, q.y, q.z);
        }
    }
    Ok(())
}
