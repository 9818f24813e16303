//! `tendril fk --input`: forward statics for a CSV of tensions (and tip
//! loads), callable from the CLI, the pipeline and Python alike
//! (`docs/design.md` §7).
//!
//! A batch streams: rows are read [`CHUNK`] at a time, each chunk solved in
//! parallel ([`solve_all`]) and written before the next is read, so memory
//! does not grow with the row count. A row's result depends only on the
//! rows of its chunk (chunks are cut by row position, never by thread count).

use std::path::Path;

use anyhow::{bail, Context};
use nalgebra::Vector3;

use crate::dataset::generate::solve_bar;
use crate::dataset::io::format_value;
use crate::fsutil::write_atomic_with;
use crate::robot::{count, RigidMap};
use crate::statics::batch::{solve_all, Load, RowResult};
use crate::statics::{SolveError, Statics};

/// Optional batch columns of the tip wrench (base frame; N, N m).
pub const LOAD_COLUMNS: [&str; 6] = ["fx", "fy", "fz", "mx", "my", "mz"];

/// Rows read, solved and written at a time: a few MB whatever the input's
/// length, and enough rows to keep every core busy.
pub const CHUNK: usize = 4096;

/// The columns `fk` adds (or overwrites) for each row: the pose, then the row's status.
pub const RESULT_COLUMNS: [&str; 8] = ["px", "py", "pz", "qw", "qx", "qy", "qz", "converged"];

/// What a batch did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    /// Rows solved and written.
    pub rows: usize,
    /// Rows that did not converge or have no stable equilibrium
    /// (`converged` = false).
    pub failed: usize,
    /// Of those, the rows whose equilibrium is unstable or not unique.
    pub unstable: usize,
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
pub fn single_to_csv(
    statics: &Statics,
    load: &Load,
    typed: &str,
    output: &Path,
) -> anyhow::Result<()> {
    let sol = statics.solve_loaded(&load.tensions, load.tip_force, load.tip_moment, None)?;
    let mut head: Vec<String> = (0..load.tensions.len()).map(|i| format!("t{i}")).collect();
    let mut row: Vec<String> = typed.split(',').map(|x| x.trim().to_string()).collect();
    let wrench = load.tip_force.iter().chain(load.tip_moment.iter());
    if load.tip_force != Vector3::zeros() || load.tip_moment != Vector3::zeros() {
        head.extend(LOAD_COLUMNS.iter().map(|c| c.to_string()));
        row.extend(wrench.map(|&x| format_value(x)));
    }
    head.extend(RESULT_COLUMNS.iter().map(|c| c.to_string()));
    row.extend(result_values(&Ok(sol), &statics.robot().base.to_tracker()).0);
    write_atomic_with(output, |w| {
        let mut out = csv::Writer::from_writer(w);
        out.write_record(&head)?;
        out.write_record(&row)?;
        out.flush()
    })
    .with_context(|| format!("{}: cannot write", output.display()))
}

/// The values of [`RESULT_COLUMNS`] for one row's result, the pose in the
/// tracker's frame (`to_tracker`, the robot's `[base]`), and whether it
/// failed. Every status a row can end with is decided here.
fn result_values(result: &RowResult, to_tracker: &RigidMap) -> (Vec<String>, bool) {
    match result {
        Ok(sol) => (
            to_tracker
                .pose(sol.pose())
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

/// Solve every row of `input` (columns `t0..`, optionally [`LOAD_COLUMNS`];
/// others pass through) and write `output` atomically: the input's columns
/// plus [`RESULT_COLUMNS`] (columns of those names already in the input
/// are overwritten). A row that is not a number or out of the robot's
/// tension range fails the batch naming its line; a row that does not
/// converge is written with `converged` = false and counted. `stop` set:
/// nothing is written. `progress` shows a bar.
pub fn solve_csv(
    statics: &Statics,
    input: &Path,
    output: &Path,
    stop: &std::sync::atomic::AtomicBool,
    progress: bool,
) -> anyhow::Result<Summary> {
    if crate::dataset::disk::same_file(input, output) {
        bail!(
            "{}: the output would overwrite the input; choose another --output",
            output.display()
        );
    }
    let n = statics.robot().n_tendons();
    let file = crate::fsutil::open_input(input)
        .with_context(|| format!("{}: cannot open", input.display()))?;
    let mut reader = csv::Reader::from_reader(crate::fsutil::LineCapped::new(file));
    let header = reader
        .headers()
        .with_context(|| format!("{}: bad header", input.display()))?
        .clone();
    let cols = Columns::of(&header, n, input)?;

    let to_tracker = statics.robot().base.to_tracker();
    let bar = solve_bar(0, progress);
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
            let Some(results) = solve_all(statics, &loads, stop, &|k| bar.inc(k as u64)) else {
                fault = Some(anyhow::anyhow!("interrupted; nothing was written"));
                return Err(std::io::Error::other("interrupted"));
            };
            for (rec, result) in records.iter().zip(&results) {
                let mut row: Vec<String> = rec.iter().map(str::to_string).collect();
                row.resize(cols.head.len(), String::new());
                let (values, bad) = result_values(result, &to_tracker);
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
    Ok(Summary {
        rows,
        failed,
        unstable,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::statics::SolverSettings;

    fn statics() -> Statics {
        let robot = crate::robot::Robot::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../robots/seed-4t.toml"
        )))
        .unwrap();
        Statics::new(&robot, SolverSettings::default())
    }

    /// Called as a library job: every row answered with the pose the
    /// statics give for it, the input's other columns kept, the summary
    /// counting the rows.
    #[test]
    fn a_batch_called_as_a_job_writes_the_statics_pose_of_every_row() {
        let dir = tempfile::tempdir().unwrap();
        let (input, output) = (dir.path().join("in.csv"), dir.path().join("out.csv"));
        std::fs::write(&input, "id,t0,t1,t2,t3\n7,1.0,0,0,0\n8,0,2.0,0,0.5\n").unwrap();
        let statics = statics();
        let stop = std::sync::atomic::AtomicBool::new(false);
        let s = solve_csv(&statics, &input, &output, &stop, false).unwrap();
        assert_eq!(
            s,
            Summary {
                rows: 2,
                failed: 0,
                unstable: 0
            }
        );
        let mut reader = csv::Reader::from_path(&output).unwrap();
        let head = reader.headers().unwrap().clone();
        assert_eq!(&head[0], "id");
        let px = head.iter().position(|h| h == "px").unwrap();
        for (rec, t) in reader
            .records()
            .zip([[1.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.5]])
        {
            let rec = rec.unwrap();
            let p = statics.solve(&t, None).unwrap().pose();
            for k in 0..7 {
                let got: f64 = rec[px + k].parse().unwrap();
                assert!((got - p[k]).abs() < 1e-12, "column {k}: {got} vs {}", p[k]);
            }
            assert_eq!(&rec[px + 7], "true");
        }
    }

    /// The output naming the input is refused before anything is read or
    /// written: the input stays as it was.
    #[test]
    fn an_output_that_is_the_input_is_refused_and_the_input_kept() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.csv");
        let text = "t0,t1,t2,t3\n1.0,0,0,0\n";
        std::fs::write(&input, text).unwrap();
        let stop = std::sync::atomic::AtomicBool::new(false);
        let err = solve_csv(&statics(), &input, &input, &stop, false).unwrap_err();
        assert!(err.to_string().contains("overwrite the input"), "{err}");
        assert_eq!(std::fs::read_to_string(&input).unwrap(), text);
    }
}
