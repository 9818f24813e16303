//! `tendril fk`: forward statics, one pose or a CSV batch (`docs/design.md` §7).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde_json::json;

use super::common::{parse_list, stop_flag, RobotArg};
use crate::dataset::generate::solve_bar;
use crate::dataset::io::format_value;
use crate::dataset::POSE_COLUMNS;
use crate::fsutil::write_atomic_with;
use crate::robot::count;
use crate::statics::batch::{solve_all, Load};
use crate::statics::{SolveError, SolverSettings, Statics, MAX_STEPS};

/// Optional batch columns of the tip wrench (base frame; N, N m).
const LOAD_COLUMNS: [&str; 6] = ["fx", "fy", "fz", "mx", "my", "mz"];

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
    #[arg(long, conflicts_with = "input")]
    json: bool,
    /// Also report N backbone points, base to tip.
    #[arg(long, value_name = "N", conflicts_with = "input",
          value_parser = clap::value_parser!(u32).range(2..=100_000))]
    shape: Option<u32>,
    /// Batch mode: CSV with columns t0..t{n-1}, optionally fx,fy,fz,mx,my,mz
    /// (tip wrench, base frame). Exits non-zero, after writing the output,
    /// when any row did not converge.
    #[arg(long, value_name = "CSV", requires = "output")]
    input: Option<PathBuf>,
    /// Batch output: input columns plus px,py,pz,qw,qx,qy,qz,converged
    /// (columns of those names already in the input are overwritten).
    #[arg(long, value_name = "CSV", requires = "input")]
    output: Option<PathBuf>,
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
    let (robot, _) = args.robot.load()?;
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
            single(&statics, &load, &args)
        }
        (None, Some(input), Some(output)) => batch(&statics, input, output),
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

/// The position of the one column named `name`; an error if there are two.
fn column(header: &csv::StringRecord, name: &str, input: &Path) -> anyhow::Result<Option<usize>> {
    let mut found = header
        .iter()
        .enumerate()
        .filter(|(_, h)| h.trim() == name)
        .map(|(c, _)| c);
    let first = found.next();
    if found.next().is_some() {
        bail!("{}: column {name} appears twice", input.display());
    }
    Ok(first)
}

fn batch(statics: &Statics, input: &Path, output: &Path) -> anyhow::Result<()> {
    let n = statics.robot().n_tendons();
    let mut reader = csv::Reader::from_path(input)
        .with_context(|| format!("{}: cannot open", input.display()))?;
    let header = reader
        .headers()
        .with_context(|| format!("{}: bad header", input.display()))?
        .clone();
    let mut tension_cols = Vec::with_capacity(n);
    for i in 0..n {
        let name = format!("t{i}");
        let c = column(&header, &name, input)?.with_context(|| {
            format!(
                "{}: no column {name} (the robot has {})",
                input.display(),
                count(n, "tendon")
            )
        })?;
        tension_cols.push(c);
    }
    let load_cols = LOAD_COLUMNS
        .iter()
        .map(|name| column(&header, name, input))
        .collect::<anyhow::Result<Vec<Option<usize>>>>()?;
    let mut output_cols = Vec::new();
    for name in POSE_COLUMNS.iter().copied().chain(["converged"]) {
        output_cols.push(column(&header, name, input)?);
    }

    let mut records = Vec::new();
    let mut loads = Vec::new();
    for (k, rec) in reader.records().enumerate() {
        let line = k + 2;
        let rec = rec.with_context(|| format!("{}: line {line}", input.display()))?;
        let number = |c: usize| -> anyhow::Result<f64> {
            let field = rec.get(c).unwrap_or("").trim();
            field.parse::<f64>().with_context(|| {
                format!(
                    "{}: line {line}: {field:?} is not a number",
                    input.display()
                )
            })
        };
        let tensions = tension_cols
            .iter()
            .map(|&c| number(c))
            .collect::<anyhow::Result<Vec<f64>>>()?;
        statics
            .robot()
            .check_tensions(&tensions)
            .with_context(|| format!("{}: line {line}", input.display()))?;
        let mut wrench = [0.0; 6];
        for (w, (c, name)) in wrench.iter_mut().zip(load_cols.iter().zip(LOAD_COLUMNS)) {
            if let Some(c) = c {
                *w = number(*c)?;
                if !w.is_finite() {
                    bail!("{}: line {line}: {name} is not finite", input.display());
                }
            }
        }
        records.push(rec);
        loads.push(Load {
            tensions,
            tip_force: Vector3::new(wrench[0], wrench[1], wrench[2]),
            tip_moment: Vector3::new(wrench[3], wrench[4], wrench[5]),
        });
    }
    let bar = solve_bar(loads.len(), true);
    let results = solve_all(statics, &loads, stop_flag(), &|k| bar.inc(k as u64))
        .context("interrupted; nothing was written")?;
    bar.finish_and_clear();

    let mut head: Vec<String> = header.iter().map(str::to_string).collect();
    let mut place = Vec::with_capacity(output_cols.len());
    for (name, existing) in POSE_COLUMNS
        .iter()
        .copied()
        .chain(["converged"])
        .zip(&output_cols)
    {
        place.push(existing.unwrap_or_else(|| {
            head.push(name.to_string());
            head.len() - 1
        }));
    }
    let (mut failed, mut unstable) = (0, 0);
    write_atomic_with(output, |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record(&head)?;
        for (rec, result) in records.iter().zip(&results) {
            let mut row: Vec<String> = rec.iter().map(str::to_string).collect();
            row.resize(head.len(), String::new());
            let values: Vec<String> = match result {
                Ok(sol) => sol
                    .pose()
                    .iter()
                    .map(|&x| format_value(x))
                    .chain(["true".to_string()])
                    .collect(),
                Err(e) => {
                    failed += 1;
                    unstable += usize::from(matches!(
                        e,
                        SolveError::Unstable { .. } | SolveError::NonUnique { .. }
                    ));
                    std::iter::repeat_n(String::new(), 7)
                        .chain(["false".to_string()])
                        .collect()
                }
            };
            for (&c, v) in place.iter().zip(values) {
                row[c] = v;
            }
            out.write_record(&row)?;
        }
        out.flush()?;
        Ok(())
    })
    .with_context(|| format!("{}: cannot write", output.display()))?;
    if failed > 0 {
        bail!(
            "{failed} of {} did not converge or have no stable equilibrium ({unstable} \
             unstable or not unique; converged=false in {})",
            count(results.len(), "row"),
            output.display()
        );
    }
    Ok(())
}
