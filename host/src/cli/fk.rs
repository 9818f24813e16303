//! `tendril fk`: forward statics, one pose or a CSV batch (DESIGN §7).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use serde_json::json;

use super::common::{parse_list, stop_flag, RobotArg};
use crate::dataset::generate::{solve_bar, solve_batch, Outcome};
use crate::dataset::io::format_value;
use crate::dataset::POSE_COLUMNS;
use crate::fsutil::write_atomic_with;
use crate::statics::{SolverSettings, Statics};

/// Tip pose for given tendon tensions (Cosserat-rod statics).
#[derive(clap::Args, Debug)]
pub struct FkArgs {
    #[command(flatten)]
    robot: RobotArg,
    /// Tensions in newtons, one per tendon: `2,0,0,0`.
    #[arg(
        long,
        value_name = "T0,T1,..",
        conflicts_with = "input",
        required_unless_present = "input"
    )]
    tensions: Option<String>,
    /// Print one JSON object: position, quaternion (w,x,y,z), converged, residual, iterations.
    #[arg(long)]
    json: bool,
    /// Also report N backbone points, base to tip.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..=100_000))]
    shape: Option<u32>,
    /// Batch mode: CSV with columns t0..t{n-1}.
    #[arg(long, value_name = "CSV", requires = "output")]
    input: Option<PathBuf>,
    /// Batch output: input columns plus px,py,pz,qw,qx,qy,qz,converged.
    #[arg(long, value_name = "CSV", requires = "input")]
    output: Option<PathBuf>,
    /// RK4 steps over the length.
    #[arg(long, default_value_t = SolverSettings::default().steps)]
    steps: usize,
}

/// Run `tendril fk`.
pub fn run(args: FkArgs) -> anyhow::Result<()> {
    let (robot, _) = args.robot.load()?;
    let settings = SolverSettings {
        steps: args.steps.max(1),
        ..SolverSettings::default()
    };
    let statics = Statics::new(&robot, settings);
    match (&args.tensions, &args.input, &args.output) {
        (Some(t), _, _) => single(&statics, &parse_list(t, "--tensions")?, &args),
        (None, Some(input), Some(output)) => batch(&statics, input, output),
        _ => bail!("give --tensions, or --input and --output"),
    }
}

fn single(statics: &Statics, tensions: &[f64], args: &FkArgs) -> anyhow::Result<()> {
    let sol = statics.solve(tensions, None)?;
    let shape = args.shape.map(|n| statics.shape(&sol, n as usize));
    let p = sol.position;
    if args.json {
        let mut obj = json!({
            "position": [p.x, p.y, p.z],
            "quaternion": sol.quaternion,
            "converged": true,
            "residual": sol.residual,
            "iterations": sol.iterations,
        });
        if let Some(shape) = &shape {
            obj["shape"] = json!(shape.iter().map(|q| [q.x, q.y, q.z]).collect::<Vec<_>>());
        }
        println!("{obj}");
    } else {
        let q = sol.quaternion;
        println!("position   [m]  {:+.9} {:+.9} {:+.9}", p.x, p.y, p.z);
        println!(
            "quaternion wxyz {:+.9} {:+.9} {:+.9} {:+.9}",
            q[0], q[1], q[2], q[3]
        );
        println!(
            "converged: residual {:.2e} after {} iterations",
            sol.residual, sol.iterations
        );
        for (k, q) in shape.iter().flatten().enumerate() {
            println!("shape[{k}] {:+.6} {:+.6} {:+.6}", q.x, q.y, q.z);
        }
    }
    Ok(())
}

fn batch(statics: &Statics, input: &Path, output: &Path) -> anyhow::Result<()> {
    let n = statics.robot().n_tendons();
    let mut reader = csv::Reader::from_path(input)
        .with_context(|| format!("{}: cannot open", input.display()))?;
    let header = reader
        .headers()
        .with_context(|| format!("{}: bad header", input.display()))?
        .clone();
    let mut cols = Vec::with_capacity(n);
    for i in 0..n {
        let name = format!("t{i}");
        let c = header
            .iter()
            .position(|h| h.trim() == name)
            .with_context(|| {
                format!(
                    "{}: no column {name} (robot has {n} tendons)",
                    input.display()
                )
            })?;
        cols.push(c);
    }
    let mut records = Vec::new();
    let mut tensions = Vec::new();
    for (k, rec) in reader.records().enumerate() {
        let rec = rec.with_context(|| format!("{}: line {}", input.display(), k + 2))?;
        let t = cols
            .iter()
            .map(|&c| {
                let field = rec.get(c).unwrap_or("").trim();
                field.parse::<f64>().with_context(|| {
                    format!(
                        "{}: line {}: {:?} is not a number",
                        input.display(),
                        k + 2,
                        field
                    )
                })
            })
            .collect::<anyhow::Result<Vec<f64>>>()?;
        statics
            .robot()
            .check_tensions(&t)
            .with_context(|| format!("{}: line {}", input.display(), k + 2))?;
        records.push(rec);
        tensions.push(t);
    }
    let order: Vec<usize> = (0..tensions.len()).collect();
    let bar = solve_bar(tensions.len(), true);
    let outcomes = solve_batch(statics, &tensions, &order, &bar, stop_flag())
        .context("interrupted; nothing was written")?;
    bar.finish_and_clear();
    let mut failed = 0;
    write_atomic_with(output, |w| {
        let mut out = csv::Writer::from_writer(w);
        let mut head: Vec<String> = header.iter().map(str::to_string).collect();
        head.extend(POSE_COLUMNS.iter().map(|s| s.to_string()));
        head.push("converged".into());
        out.write_record(&head)?;
        for (rec, outcome) in records.iter().zip(&outcomes) {
            let mut row: Vec<String> = rec.iter().map(str::to_string).collect();
            match outcome {
                Outcome::Solved(s) | Outcome::ResolvedCold(s) => {
                    row.extend(s.pose().iter().map(|&x| format_value(x)));
                    row.push("true".into());
                }
                Outcome::Failed(_) => {
                    failed += 1;
                    row.extend(std::iter::repeat_n(String::new(), 7));
                    row.push("false".into());
                }
            }
            out.write_record(&row)?;
        }
        out.flush()?;
        Ok(())
    })
    .with_context(|| format!("{}: cannot write", output.display()))?;
    if failed > 0 {
        log::warn!(
            "{failed} of {} rows did not converge (converged=false)",
            outcomes.len()
        );
    }
    Ok(())
}
