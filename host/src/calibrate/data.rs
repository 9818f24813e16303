//! The measured-CSV schema (`docs/design.md` §11) and its reader.
//!
//! A measurement row is what a user records on the real robot: the tensions
//! commanded (or read from the load cells), the tracked tip position in the
//! tracker's frame, optionally the tracked orientation and a known tip load.
//! A `tendril generate` CSV is a valid measured CSV.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::robot::Robot;

/// Measured rows, checked against the robot they were taken on.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurements {
    /// Tensions per row, N, tendon 0 first.
    pub tensions: Vec<Vec<f64>>,
    /// Tracked tip position per row, tracker frame, m.
    pub positions: Vec<[f64; 3]>,
    /// Tracked tip orientation per row (w, x, y, z), when the file has it.
    pub quaternions: Option<Vec<[f64; 4]>>,
    /// Known tip force per row, base frame, N (zero when absent).
    pub tip_forces: Vec<[f64; 3]>,
    /// Known tip moment per row, base frame, N·m (zero when absent).
    pub tip_moments: Vec<[f64; 3]>,
    /// Line number in the file of each row (header = line 1), for reports.
    pub lines: Vec<usize>,
}

impl Measurements {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether there is no row.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The rows at `idx`, in that order.
    pub fn select(&self, idx: &[usize]) -> Measurements {
        Measurements {
            tensions: idx.iter().map(|&i| self.tensions[i].clone()).collect(),
            positions: idx.iter().map(|&i| self.positions[i]).collect(),
            quaternions: self
                .quaternions
                .as_ref()
                .map(|q| idx.iter().map(|&i| q[i]).collect()),
            tip_forces: idx.iter().map(|&i| self.tip_forces[i]).collect(),
            tip_moments: idx.iter().map(|&i| self.tip_moments[i]).collect(),
            lines: idx.iter().map(|&i| self.lines[i]).collect(),
        }
    }
}

/// A measured CSV that cannot be used: the file, and what is wrong where.
#[derive(Debug, thiserror::Error)]
#[error("{}: {problem}", file.display())]
pub struct DataError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong (names the line and column where there is one).
    pub problem: String,
}

/// Optional column groups: all of a group or none.
const GROUPS: [(&str, [&str; 4]); 3] = [
    ("orientation", ["qw", "qx", "qy", "qz"]),
    ("tip force", ["fx", "fy", "fz", ""]),
    ("tip moment", ["mx", "my", "mz", ""]),
];

/// Columns a dataset or batch-fk file may carry that calibration ignores.
const IGNORED: [&str; 1] = ["converged"];

/// Read and check a measured CSV for `robot` (see [`parse_measurements`]).
pub fn read_measurements(path: &Path, robot: &Robot) -> Result<Measurements, DataError> {
    let file = crate::fsutil::open_input(path).map_err(|e| DataError {
        file: path.to_path_buf(),
        problem: format!("cannot read: {e}"),
    })?;
    parse_measurements(crate::fsutil::LineCapped::new(file), path, robot)
}

/// Parse a measured CSV from `reader`; `origin` names it in errors.
///
/// Columns, by name in any order: `t0..t{n-1}` (N, exactly the robot's
/// tendons), `px,py,pz` (m); optionally `qw,qx,qy,qz`, `fx,fy,fz` (N),
/// `mx,my,mz` (N·m), each group whole. Every value must be a finite number
/// and every row's tensions within the robot's limits.
pub fn parse_measurements<R: std::io::Read>(
    reader: R,
    origin: &Path,
    robot: &Robot,
) -> Result<Measurements, DataError> {
    let err = |problem: String| DataError {
        file: origin.to_path_buf(),
        problem,
    };
    let mut csv = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(reader);
    let header: Vec<String> = csv
        .headers()
        .map_err(|e| err(format!("bad header: {e}")))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let mut index: HashMap<&str, usize> = HashMap::new();
    for (k, name) in header.iter().enumerate() {
        if index.insert(name.as_str(), k).is_some() {
            return Err(err(format!("column {name} appears twice")));
        }
    }
    let n = robot.n_tendons();
    let tension_names: Vec<String> = (0..n).map(|i| format!("t{i}")).collect();
    let mut known: Vec<&str> = tension_names.iter().map(String::as_str).collect();
    known.extend(["px", "py", "pz"]);
    for name in known.clone() {
        if !index.contains_key(name) {
            return Err(err(format!(
                "missing column {name} (a measured CSV needs t0..t{}, px, py, pz)",
                n - 1
            )));
        }
    }
    let mut present = [false; 3];
    for (g, (what, cols)) in GROUPS.iter().enumerate() {
        let cols: Vec<&str> = cols.iter().copied().filter(|c| !c.is_empty()).collect();
        let have: Vec<&str> = cols
            .iter()
            .copied()
            .filter(|c| index.contains_key(c))
            .collect();
        if !have.is_empty() && have.len() != cols.len() {
            return Err(err(format!(
                "{what} columns must come together ({}); found only {}",
                cols.join(", "),
                have.join(", ")
            )));
        }
        present[g] = !have.is_empty();
        known.extend(cols);
    }
    for name in &header {
        if !known.contains(&name.as_str()) && !IGNORED.contains(&name.as_str()) {
            let hint = if name.starts_with('t') {
                format!(" (the robot has {})", crate::robot::count(n, "tendon"))
            } else {
                String::new()
            };
            return Err(err(format!("unknown column {name}{hint}")));
        }
    }
    let col = |name: &str| index[name];
    let mut m = Measurements {
        tensions: Vec::new(),
        positions: Vec::new(),
        quaternions: present[0].then(Vec::new),
        tip_forces: Vec::new(),
        tip_moments: Vec::new(),
        lines: Vec::new(),
    };
    for (r, record) in csv.records().enumerate() {
        let line = r + 2;
        let record = record.map_err(|e| err(format!("line {line}: {e}")))?;
        let value = |name: &str| -> Result<f64, DataError> {
            let text = record.get(col(name)).unwrap_or("").trim();
            let x: f64 = text.parse().map_err(|_| {
                err(format!(
                    "line {line}: column {name}: {text:?} is not a number"
                ))
            })?;
            if !x.is_finite() {
                return Err(err(format!(
                    "line {line}: column {name}: {text} is not a finite number"
                )));
            }
            Ok(x)
        };
        let tau = tension_names
            .iter()
            .map(|c| value(c))
            .collect::<Result<Vec<_>, _>>()?;
        robot
            .check_tensions(&tau)
            .map_err(|e| err(format!("line {line}: {e}")))?;
        m.tensions.push(tau);
        m.positions.push([value("px")?, value("py")?, value("pz")?]);
        if let Some(q) = m.quaternions.as_mut() {
            let v = [value("qw")?, value("qx")?, value("qy")?, value("qz")?];
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-3 {
                return Err(err(format!(
                    "line {line}: quaternion qw..qz has norm {norm}, not 1"
                )));
            }
            q.push(v.map(|x| x / norm));
        }
        m.tip_forces.push(if present[1] {
            [value("fx")?, value("fy")?, value("fz")?]
        } else {
            [0.0; 3]
        });
        m.tip_moments.push(if present[2] {
            [value("mx")?, value("my")?, value("mz")?]
        } else {
            [0.0; 3]
        });
        m.lines.push(line);
    }
    if m.is_empty() {
        return Err(err("no data rows".into()));
    }
    Ok(m)
}
