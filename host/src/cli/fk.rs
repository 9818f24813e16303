//! `tendril fk`: forward statics, one pose or a CSV batch (`docs/design.md` §7).
//!
//! A batch streams: rows are read [`CHUNK`] at a time, each chunk solved in
//! parallel ([`solve_all`]) and written before the next is read, so memory
//! does not grow with the row count. A row's result depends only on the
//! rows of its chunk (chunks are cut by row position, never by thread count).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde_json::json;

use super::common::{parse_list, stop_flag, RobotArg};
use crate::dataset::generate::solve_bar;
use crate::dataset::io::format_value;
use crate::fsutil::write_atomic_with;
use crate::robot::count;
use crate::statics::batch::{solve_all, Load, RowResult};
use crate::statics::{SolveError, SolverSettings, Statics, MAX_STEPS};

/// Optional batch columns of the tip wrench (base frame; N, N m).
const LOAD_COLUMNS: [&str; 6] = ["fx", "fy", "fz", "mx", "my", "mz"];

/// Rows read, solved and written at a time: a few MB whatever the input's
/// length, and enough rows to keep every core busy.
pub const CHUNK: usize = 4096;

/// The columns `fk` adds (or overwrites) for each row: the pose, then the row's status.
const RESULT_COLUMNS: [&str; 8] = ["px", "py", "pz", "qw", "qx", "qy", "qz", "converged"];

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
            match &args.output {
                Some(output) => single_to_csv(&statics, &load, t, output),
                None => single(&statics, &load, &args),
            }
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

/// `--tensions … --output FILE`: the pose as the one-row CSV a batch of
/// that row would write (the tensions as typed, the load columns if given).
fn single_to_csv(statics: &Statics, load: &Load, typed: &str, output: &Path) -> anyhow::Result<()> {
    let sol = statics.solve_loaded(&load.tensions, load.tip_force, load.tip_moment, None)?;
    let mut head: Vec<String> = (0..load.tensions.len()).map(|i| format!("t{i}")).collect();
    let mut row: Vec<String> = typed.split(',').map(|x| x.trim().to_string()).collect();
    let wrench = load.tip_force.iter().chain(load.tip_moment.iter());
    if load.tip_force != Vector3::zeros() || load.tip_moment != Vector3::zeros() {
        head.extend(LOAD_COLUMNS.iter().map(|c| c.to_string()));
        row.extend(wrench.map(|&x| format_value(x)));
    }
    head.extend(RESULT_COLUMNS.iter().map(|c| c.to_string()));
    row.extend(result_values(&Ok(sol)).0);
    write_atomic_with(output, |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record(&head)?;
        out.write_record(&row)?;
        out.flush()
    })
    .with_context(|| format!("{}: cannot write", output.display()))
}

/// The values of [`RESULT_COLUMNS`] for one row's result, and whether it
/// failed. Every status a row can end with is decided here.
fn result_values(result: &RowResult) -> (Vec<String>, bool) {
    match result {
        Ok(sol) => (
            sol.pose()
                .iter()
                .map(|&x| format_value(x))
                .chain(["true".to_string()])
                .collect(),
            false,
        ),
        Err(_) => (
            std::iter::repeat_n(String::new(), 7)
                .chain(["false".to_string()])
                .collect(),
            true,
        ),
    }
}

/// Where a batch's columns are: the tensions, the optional load columns,
/// and the output columns (existing ones are overwritten, others appended).
struct Columns {
    tensions: Vec<usize>,
    loads: Vec<Option<usize>>,
    /// The output header.
    head: Vec<String>,
    /// The output column of each of [`RESULT_COLUMNS`].
    place: Vec<usize>,
}

impl Columns {
    fn of(header: &csv::StringRecord, n: usize, input: &Path) -> anyhow::Result<Columns> {
        let mut tensions = Vec::with_capacity(n);
        for i in 0..n {
            let name = format!("t{i}");
            let c = column(header, &name, input)?.with_context(|| {
                format!(
                    "{}: no column {name} (the robot has {})",
                    input.display(),
                    count(n, "tendon")
                )
            })?;
            tensions.push(c);
        }
        // A tension column the robot has no tendon for would pass through
        // unused: the user meant another robot, or a typo.
        if let Some(extra) = header.iter().map(str::trim).find(|h| {
            h.strip_prefix('t')
                .and_then(|k| k.parse::<usize>().ok())
                .is_some_and(|k| k >= n)
        }) {
            bail!(
                "{}: column {extra} is a tension but the robot has {} (t0..t{}); \
                 give its robot with --robot, or drop the column",
                input.display(),
                count(n, "tendon"),
                n - 1
            );
        }
        let loads = LOAD_COLUMNS
            .iter()
            .map(|name| column(header, name, input))
            .collect::<anyhow::Result<Vec<Option<usize>>>>()?;
        let mut head: Vec<String> = header.iter().map(str::to_string).collect();
        let mut place = Vec::with_capacity(RESULT_COLUMNS.len());
        for name in RESULT_COLUMNS {
            let existing = column(header, name, input)?;
            place.push(existing.unwrap_or_else(|| {
                head.push(name.to_string());
                head.len() - 1
            }));
        }
        Ok(Columns {
            tensions,
            loads,
            head,
            place,
        })
    }

    /// The load of one input row (`line` for messages).
    fn load(
        &self,
        rec: &csv::StringRecord,
        line: usize,
        statics: &Statics,
        input: &Path,
    ) -> anyhow::Result<Load> {
        let number = |c: usize| -> anyhow::Result<f64> {
            let field = rec.get(c).unwrap_or("").trim();
            field.parse::<f64>().with_context(|| {
                format!(
                    "{}: line {line}: {field:?} is not a number",
                    input.display()
                )
            })
        };
        let tensions = self
            .tensions
            .iter()
            .map(|&c| number(c))
            .collect::<anyhow::Result<Vec<f64>>>()?;
        statics
            .robot()
            .check_tensions(&tensions)
            .with_context(|| format!("{}: line {line}", input.display()))?;
        let mut wrench = [0.0; 6];
        for (w, (c, name)) in wrench.iter_mut().zip(self.loads.iter().zip(LOAD_COLUMNS)) {
            if let Some(c) = c {
                *w = number(*c)?;
                if !w.is_finite() {
                    bail!("{}: line {line}: {name} is not finite", input.display());
                }
            }
        }
        Ok(Load {
            tensions,
            tip_force: Vector3::new(wrench[0], wrench[1], wrench[2]),
            tip_moment: Vector3::new(wrench[3], wrench[4], wrench[5]),
        })
    }
}

fn batch(statics: &Statics, input: &Path, output: &Path) -> anyhow::Result<()> {
    let n = statics.robot().n_tendons();
    let file = crate::fsutil::open_input(input)
        .with_context(|| format!("{}: cannot open", input.display()))?;
    let mut reader = csv::Reader::from_reader(crate::fsutil::LineCapped::new(file));
    let header = reader
        .headers()
        .with_context(|| format!("{}: bad header", input.display()))?
        .clone();
    let cols = Columns::of(&header, n, input)?;

    let bar = solve_bar(0, true);
    let (mut rows, mut failed, mut unstable) = (0usize, 0usize, 0usize);
    // The first error met inside the streaming writer (it can only return io::Error).
    let mut fault: Option<anyhow::Error> = None;
    let written = write_atomic_with(output, |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record(&cols.head)?;
        let mut records = Vec::with_capacity(CHUNK);
        let mut loads = Vec::with_capacity(CHUNK);
        let mut recs = reader.records().enumerate().peekable();
        while recs.peek().is_some() {
            records.clear();
            loads.clear();
            for (k, rec) in recs.by_ref().take(CHUNK) {
                let line = k + 2;
                let parsed = rec
                    .with_context(|| format!("{}: line {line}", input.display()))
                    .and_then(|rec| Ok((cols.load(&rec, line, statics, input)?, rec)));
                match parsed {
                    Ok((load, rec)) => {
                        loads.push(load);
                        records.push(rec);
                    }
                    Err(e) => {
                        fault = Some(e);
                        return Err(std::io::Error::other("bad input row"));
                    }
                }
            }
            bar.inc_length(loads.len() as u64);
            let Some(results) = solve_all(statics, &loads, stop_flag(), &|k| bar.inc(k as u64))
            else {
                fault = Some(anyhow::anyhow!("interrupted; nothing was written"));
                return Err(std::io::Error::other("interrupted"));
            };
            for (rec, result) in records.iter().zip(&results) {
                let mut row: Vec<String> = rec.iter().map(str::to_string).collect();
                row.resize(cols.head.len(), String::new());
                let (values, bad) = result_values(result);
                failed += usize::from(bad);
                unstable += usize::from(matches!(
                    result,
                    Err(SolveError::Unstable { .. } | SolveError::NonUnique { .. })
                ));
                for (&c, v) in cols.place.iter().zip(values) {
                    row[c] = v;
                }
                out.write_record(&row)?;
            }
            rows += results.len();
        }
        out.flush()?;
        Ok(())
    });
    bar.finish_and_clear();
    if let Some(e) = fault {
        return Err(e);
    }
    written.with_context(|| format!("{}: cannot write", output.display()))?;
    if failed > 0 {
        bail!(
            "{failed} of {} did not converge or have no stable equilibrium ({unstable} \
             unstable or not unique; converged=false in {})",
            count(rows, "row"),
            output.display()
        );
    }
    Ok(())
}
