//! The rod's modes over its workspace (`tendril modes`, `docs/design.md`
//! §6.4): [`crate::dynamics::modes::identify`] at rest and with each
//! segment bent, or along a run's tensions, so a user sees how far the
//! modes move from pose to pose — what a mode-based design (the input
//! shaper's tolerance) must cover.

use rayon::prelude::*;
use serde::Serialize;

use crate::dynamics::modes::{identify, Mode, ModeSearch, ModesError};
use crate::dynamics::Damping;
use crate::robot::groups::anchor_groups;
use crate::robot::{first_bending_mode_rad_s, Robot};

/// The modes at one pose.
#[derive(Clone, Debug, Serialize)]
pub struct ModesAt {
    /// What the pose is ("rest", "segment 2 bent (tendon 4 at 50 %)", "given").
    pub pose: String,
    /// Tensions, N.
    pub tensions: Vec<f64>,
    /// Underdamped modes, lowest first (at most two: the first two bending modes).
    pub modes: Vec<Mode>,
}

/// The modes of a robot at several poses.
#[derive(Clone, Debug, Serialize)]
pub struct ModesTable {
    /// The Euler–Bernoulli first mode of the backbone (uniform cantilever), Hz.
    pub beam_first_mode_hz: f64,
    /// One row per pose.
    pub rows: Vec<ModesAt>,
}

impl ModesTable {
    /// The lowest and highest first-mode frequency over the rows, Hz.
    pub fn first_mode_range_hz(&self) -> Option<(f64, f64)> {
        let f: Vec<f64> = self
            .rows
            .iter()
            .filter_map(|r| r.modes.first().map(|m| m.freq_hz))
            .collect();
        let lo = f.iter().copied().reduce(f64::min)?;
        let hi = f.iter().copied().reduce(f64::max)?;
        Some((lo, hi))
    }
}

/// Fraction of a tendon's maximum that bends a segment for the table.
pub const BENT_FRACTION: f64 = 0.5;

/// The poses of the table: `at` alone when given, else rest and each
/// segment bent by its first tendon at [`BENT_FRACTION`] of its maximum.
pub fn poses(robot: &Robot, at: Option<&[f64]>) -> Vec<(String, Vec<f64>)> {
    let n = robot.n_tendons();
    if let Some(at) = at {
        return vec![("given".into(), at.to_vec())];
    }
    let max = robot.max_tensions();
    let mut poses = vec![("rest".to_string(), vec![0.0; n])];
    for (k, group) in anchor_groups(robot).iter().enumerate() {
        let mut t = vec![0.0; n];
        t[group[0]] = BENT_FRACTION * max[group[0]];
        poses.push((
            format!(
                "segment {} bent (tendon {} at {:.0} %)",
                k + 1,
                group[0],
                100.0 * BENT_FRACTION
            ),
            t,
        ));
    }
    poses
}

/// Why a file of tensions could not give poses ([`poses_along`]).
#[derive(Debug, thiserror::Error)]
pub enum AlongError {
    /// The file could not be read as CSV.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// What failed.
        source: csv::Error,
    },
    /// Neither a plant log's `tau0..` nor a batch input's `t0..` columns
    /// for every tendon.
    #[error("{path}: no tension columns for the robot's {n} tendons (a plant log's tau0..tau{last} or fk's t0..t{last})")]
    Columns {
        /// The file.
        path: String,
        /// The robot's tendons.
        n: usize,
        /// The last column's index.
        last: usize,
    },
    /// A tension that is not a finite number ≥ 0.
    #[error("{path}, line {line}: tension {value:?} in column {column} is not a number ≥ 0")]
    Value {
        /// The file.
        path: String,
        /// Its line (1 = the header).
        line: usize,
        /// The column.
        column: String,
        /// The text.
        value: String,
    },
    /// No row with tensions.
    #[error("{path}: no rows")]
    Empty {
        /// The file.
        path: String,
    },
}

/// Poses along a run: `count` rows evenly spaced over the tension columns of
/// `path` — a run's plant log (`plant-0.csv`, columns `tau0..`: the tensions
/// the rod had) or `tendril fk --input`'s table (`t0..`). Where a path's
/// poses move the modes (the three-segment robot's bending pair splits to
/// 0.80 and 1.15 Hz on parts of its circle, BENCHMARKS.md), the table at
/// rest and bent does not show it.
pub fn poses_along(
    path: &std::path::Path,
    n: usize,
    count: usize,
) -> Result<Vec<(String, Vec<f64>)>, AlongError> {
    let name = path.display().to_string();
    let read = |source| AlongError::Read {
        path: name.clone(),
        source,
    };
    let mut reader = csv::Reader::from_path(path).map_err(read)?;
    let headers = reader.headers().map_err(read)?.clone();
    let find = |prefix: &str| -> Option<Vec<usize>> {
        (0..n)
            .map(|i| {
                headers
                    .iter()
                    .position(|h| h.trim() == format!("{prefix}{i}"))
            })
            .collect()
    };
    let columns =
        find("tau")
            .or_else(|| find("t"))
            .filter(|_| n > 0)
            .ok_or(AlongError::Columns {
                path: name.clone(),
                n,
                last: n.saturating_sub(1),
            })?;
    let mut rows = Vec::new();
    for (k, record) in reader.records().enumerate() {
        let record = record.map_err(read)?;
        let mut t = Vec::with_capacity(n);
        for &c in &columns {
            let text = record.get(c).unwrap_or("");
            match text.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v >= 0.0 => t.push(v),
                _ => {
                    return Err(AlongError::Value {
                        path: name.clone(),
                        line: k + 2,
                        column: headers.get(c).unwrap_or("").to_string(),
                        value: text.to_string(),
                    })
                }
            }
        }
        rows.push((k + 2, t));
    }
    if rows.is_empty() {
        return Err(AlongError::Empty { path: name });
    }
    let count = count.clamp(1, rows.len());
    Ok((0..count)
        .map(|i| {
            // Evenly spaced, first and last rows included.
            let k = if count == 1 {
                0
            } else {
                i * (rows.len() - 1) / (count - 1)
            };
            let (line, t) = &rows[k];
            (format!("line {line}"), t.clone())
        })
        .collect())
}

/// The first two modes of `robot` with `damping` at each of `poses`, in
/// parallel.
pub fn table(
    robot: &Robot,
    damping: Damping,
    poses: &[(String, Vec<f64>)],
    search: &ModeSearch,
) -> Result<ModesTable, ModesError> {
    let rows = poses
        .par_iter()
        .map(|(pose, tensions)| {
            let mut modes = identify(robot, damping, tensions, search)?;
            modes.truncate(2);
            Ok(ModesAt {
                pose: pose.clone(),
                tensions: tensions.clone(),
                modes,
            })
        })
        .collect::<Result<Vec<_>, ModesError>>()?;
    Ok(ModesTable {
        beam_first_mode_hz: first_bending_mode_rad_s(robot) / std::f64::consts::TAU,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> tempfile::NamedTempFile {
        let f = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(f.path(), text).unwrap();
        f
    }

    #[test]
    fn a_plant_log_gives_evenly_spaced_rows_first_and_last_included() {
        let mut text = String::from("t_ns,cmd0,cmd1,tau0,tau1,px\n");
        for k in 0..10 {
            text.push_str(&format!("{k},9,9,{k}.5,0,0.1\n"));
        }
        let f = write(&text);
        let p = poses_along(f.path(), 2, 4).unwrap();
        let firsts: Vec<f64> = p.iter().map(|(_, t)| t[0]).collect();
        assert_eq!(firsts, [0.5, 3.5, 6.5, 9.5]);
        assert_eq!(p[0].0, "line 2");
        assert_eq!(p[3].0, "line 11");
        // More rows asked for than there are: every row once.
        assert_eq!(poses_along(f.path(), 2, 50).unwrap().len(), 10);
    }

    #[test]
    fn fk_input_columns_serve_too_and_bad_files_are_named() {
        let f = write("t0,t1\n1,0\n");
        assert_eq!(
            poses_along(f.path(), 2, 3).unwrap(),
            [("line 2".to_string(), vec![1.0, 0.0])]
        );
        let e = poses_along(f.path(), 3, 3).unwrap_err().to_string();
        assert!(
            e.contains("no tension columns for the robot's 3 tendons"),
            "{e}"
        );
        let f = write("tau0,tau1\n1,-2\n");
        let e = poses_along(f.path(), 2, 3).unwrap_err().to_string();
        assert!(
            e.contains("line 2") && e.contains("tau1") && e.contains("-2"),
            "{e}"
        );
        let f = write("tau0,tau1\n");
        let e = poses_along(f.path(), 2, 3).unwrap_err().to_string();
        assert!(e.contains("no rows"), "{e}");
    }
}
