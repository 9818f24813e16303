//! Dataset files: CSV rows `t0..t{n-1},px,py,pz,qw,qx,qy,qz` and a JSON
//! sidecar that says how the rows were made. Reading checks the header and
//! every value; writing is atomic.

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::POSE_COLUMNS;
use crate::fsutil::write_atomic_with;
use crate::statics::SolverSettings;

/// Tensions and the tip poses they produce, one row per sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// Tendons per sample.
    pub n_tendons: usize,
    /// `n × n_tendons`, N.
    pub tensions: DMatrix<f64>,
    /// `n × 7`: px, py, pz (m), qw, qx, qy, qz.
    pub poses: DMatrix<f64>,
}

/// A dataset file that could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// I/O failure (the cause is the error's source, printed after the path).
    #[error("{}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The header is not `t0..t{n-1},px,py,pz,qw,qx,qy,qz`.
    #[error("{}: bad header: {why}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// A row is malformed.
    #[error("{}: line {line}: {why}", path.display())]
    Row {
        /// The file.
        path: PathBuf,
        /// 1-based line number (header = line 1).
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// The file holds no sample.
    #[error("{}: no data rows", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
}

impl Dataset {
    /// Every row's pose through `map` (measured tips from the tracker's
    /// frame to the base's, `docs/design.md` §2.4).
    pub fn map_poses(&mut self, map: &crate::robot::RigidMap) {
        for mut row in self.poses.row_iter_mut() {
            let pose: [f64; 7] = std::array::from_fn(|c| row[c]);
            for (c, v) in map.pose(pose).into_iter().enumerate() {
                row[c] = v;
            }
        }
    }

    /// An empty dataset for `n_tendons` tendons.
    pub fn empty(n_tendons: usize) -> Dataset {
        Dataset {
            n_tendons,
            tensions: DMatrix::zeros(0, n_tendons),
            poses: DMatrix::zeros(0, 7),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.tensions.nrows()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The samples at `idx`, in that order.
    pub fn rows(&self, idx: &[usize]) -> Dataset {
        Dataset {
            n_tendons: self.n_tendons,
            tensions: self.tensions.select_rows(idx),
            poses: self.poses.select_rows(idx),
        }
    }

    /// Column names of the CSV form.
    pub fn header(n_tendons: usize) -> Vec<String> {
        (0..n_tendons)
            .map(|i| format!("t{i}"))
            .chain(POSE_COLUMNS.iter().map(|s| s.to_string()))
            .collect()
    }

    /// Read a dataset CSV, checking the header and that every value is a finite number.
    pub fn read_csv(path: &Path) -> Result<Dataset, DatasetError> {
        let io = |source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = crate::fsutil::open_input(path).map_err(io)?;
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            // Row lengths are checked below, with a message naming the line.
            .flexible(true)
            .from_reader(crate::fsutil::LineCapped::new(file));
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| DatasetError::Header {
                path: path.to_path_buf(),
                why: e.to_string(),
            })?
            .iter()
            .map(|s| s.trim().to_string())
            .collect();
        let n_tendons = header.iter().take_while(|h| h.starts_with('t')).count();
        let expected = Self::header(n_tendons);
        if n_tendons == 0
            || header.len() < expected.len()
            || header[..expected.len()] != expected[..]
        {
            return Err(DatasetError::Header {
                path: path.to_path_buf(),
                why: format!(
                    "expected columns {} (found {})",
                    if n_tendons == 0 {
                        "t0.., px, py, pz, qw, qx, qy, qz".to_string()
                    } else {
                        expected.join(",")
                    },
                    header.join(",")
                ),
            });
        }
        // A tension column after the pose (`…,qz,t4`) would be ignored: the
        // file is for a robot with more tendons, or was edited by hand.
        if let Some(extra) = header[expected.len()..].iter().find(|h| {
            h.strip_prefix('t')
                .is_some_and(|k| k.parse::<usize>().is_ok())
        }) {
            return Err(DatasetError::Header {
                path: path.to_path_buf(),
                why: format!(
                    "column {extra} is a tension, but the tension columns t0..t{} come first \
                     ({n_tendons} tendons); a dataset lists each tendon once, before the pose",
                    n_tendons - 1
                ),
            });
        }
        let width = expected.len();
        let mut values = Vec::new();
        for (k, record) in reader.records().enumerate() {
            let line = k + 2;
            let record = record.map_err(|e| DatasetError::Row {
                path: path.to_path_buf(),
                line,
                why: e.to_string(),
            })?;
            if record.len() != header.len() {
                return Err(DatasetError::Row {
                    path: path.to_path_buf(),
                    line,
                    why: format!(
                        "{} fields, but the header has {} ({})",
                        record.len(),
                        header.len(),
                        header.join(",")
                    ),
                });
            }
            for (c, field) in record.iter().take(width).enumerate() {
                let x: f64 = field.trim().parse().map_err(|_| DatasetError::Row {
                    path: path.to_path_buf(),
                    line,
                    why: format!("column {}: {field:?} is not a number", expected[c]),
                })?;
                if !x.is_finite() {
                    return Err(DatasetError::Row {
                        path: path.to_path_buf(),
                        line,
                        why: format!("column {}: {field} is not finite", expected[c]),
                    });
                }
                values.push(x);
            }
        }
        let n = values.len() / width;
        if n == 0 {
            return Err(DatasetError::Empty {
                path: path.to_path_buf(),
            });
        }
        let all = DMatrix::from_row_slice(n, width, &values);
        Ok(Dataset {
            n_tendons,
            tensions: all.columns(0, n_tendons).into_owned(),
            poses: all.columns(n_tendons, 7).into_owned(),
        })
    }

    /// Write as CSV, atomically. Values are written with Rust's shortest
    /// round-trip formatting, so reading back gives bit-identical numbers.
    pub fn write_csv(&self, path: &Path) -> Result<(), DatasetError> {
        write_atomic_with(path, |w| {
            let mut rows = RowWriter::new(w, self.n_tendons)?;
            for i in 0..self.len() {
                let t = self.tensions.row(i);
                let p = self.poses.row(i);
                rows.write(t.iter().chain(p.iter()).copied())?;
            }
            Ok(())
        })
        .map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Writes dataset CSV rows one at a time (the header first), so a dataset
/// can be streamed to disk as it is generated.
pub struct RowWriter<W: Write> {
    out: W,
    line: String,
}

impl<W: Write> RowWriter<W> {
    /// Write the header for `n_tendons` tendons and get ready for rows.
    pub fn new(mut out: W, n_tendons: usize) -> std::io::Result<Self> {
        writeln!(out, "{}", Dataset::header(n_tendons).join(","))?;
        Ok(RowWriter {
            out,
            line: String::with_capacity(256),
        })
    }

    /// Write one row: the tensions, then px, py, pz, qw, qx, qy, qz.
    pub fn write(&mut self, values: impl Iterator<Item = f64>) -> std::io::Result<()> {
        self.line.clear();
        for x in values {
            self.line.push_str(&format_value(x));
            self.line.push(',');
        }
        self.line.pop();
        self.line.push('\n');
        self.out.write_all(self.line.as_bytes())
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

/// An upper bound on the bytes of one CSV value: the longest shortest
/// round-trip text of an f64 (`-2.2250738585072014e-308`) and its separator.
pub const MAX_VALUE_BYTES: u64 = 25;

/// Shortest text that reads back as exactly `x`: plain decimal for ordinary
/// magnitudes, scientific notation for tiny or huge ones (Rust's `Display`
/// would spell 1e-18 with eighteen zeros).
pub fn format_value(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && !(1e-5..1e15).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// The range of one dataset column.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColumnRange {
    /// Column name (`t0`, `px`, …).
    pub column: String,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

/// How a dataset was made: written beside the CSV as `<name>.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Robot file path as given.
    pub robot_file: String,
    /// SHA-256 of the robot file's bytes.
    pub robot_sha256: String,
    /// The robot's fingerprint ([`crate::robot::Robot::fingerprint`], hex):
    /// what it is, not how its file is written, so a file that differs only
    /// by a comment is the same robot. Empty in sidecars written before it
    /// was recorded.
    #[serde(default)]
    pub robot_fingerprint: String,
    /// Robot name.
    pub robot_name: String,
    /// Sampler name (`adjacent` or `uniform`).
    pub sampler: String,
    /// The adjacent sampler's tendon groups (one per anchor, each in ring
    /// order; two neighbours of each pull in every sample); empty for
    /// `uniform`, and in sidecars written before it was recorded.
    #[serde(default)]
    pub sampler_groups: Vec<Vec<usize>>,
    /// Which tensions each row keeps ([`super::Resolve`]: `drawn`, or
    /// `least-bending` for each drawn tip position); `drawn` in sidecars
    /// written before it was recorded.
    #[serde(default = "drawn")]
    pub resolve: super::Resolve,
    /// Random seed.
    pub seed: u64,
    /// Samples asked for.
    pub requested: usize,
    /// Rows written.
    pub count: usize,
    /// Statics settings used.
    pub solver: SolverSettings,
    /// Per-column value range over the written rows.
    pub ranges: Vec<ColumnRange>,
    /// Warm-started solves that did not meet the tolerance and were re-solved cold.
    pub resolved_cold: usize,
    /// Samples dropped because even the cold solve failed.
    pub dropped: usize,
    /// What was done with the failures, in words.
    pub failure_policy: String,
    /// Held-out test fraction the learners use.
    pub test_fraction: f64,
    /// Min–max ranges of the training split (poses in, tensions out).
    pub train_ranges: Option<super::split::Ranges>,
    /// Wall time of the generation, s.
    pub seconds: f64,
    /// tendril version that wrote it.
    pub tendril_version: String,
    /// The residual of measured rows every pose carries (`generate
    /// --residual-from`, docs/design.md §11.5); absent for the model's own
    /// rows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual: Option<ResidualRecord>,
}

/// What a dataset's residual was fitted from and how well it explains the
/// measured rows (`crate::calibrate::residual`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualRecord {
    /// The measured rows' file, as given.
    pub file: String,
    /// Measured rows.
    pub rows: usize,
    /// Rows left out as outliers.
    pub outliers: usize,
    /// Degree of the tension polynomial.
    pub degree: usize,
    /// Ridge strength (relative to the mean diagonal of the Gram matrix).
    pub lambda: f64,
    /// The model's position error on the validation rows, RMS mm, without
    /// and with the residual.
    pub valid_position_rms_mm: (f64, f64),
    /// The same for the orientation, RMS degrees.
    pub valid_angle_rms_deg: (f64, f64),
}

/// The resolution of sidecars written before it was recorded.
fn drawn() -> super::Resolve {
    super::Resolve::Drawn
}

impl Sidecar {
    /// The sidecar path for a dataset path: `data.csv` → `data.json`.
    pub fn path_for(csv: &Path) -> PathBuf {
        csv.with_extension("json")
    }

    /// Whether this sidecar describes `data`: the same row count and, per
    /// column, the same smallest and largest value (to the CSV's printed
    /// precision). `Err` says how it differs: a sidecar left beside a CSV
    /// that was replaced (measured rows saved over a generated file) would
    /// make the rows pass for exact solves.
    pub fn describes(&self, data: &Dataset) -> Result<(), String> {
        if self.count != data.len() {
            return Err(format!(
                "it records {} rows, the CSV has {}",
                self.count,
                data.len()
            ));
        }
        let columns = (0..data.n_tendons)
            .map(|j| data.tensions.column(j))
            .chain((0..7).map(|k| data.poses.column(k)));
        for (range, column) in self.ranges.iter().zip(columns) {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-3);
            if !(close(range.min, column.min()) && close(range.max, column.max())) {
                return Err(format!(
                    "column {} spans [{}, {}] in the CSV, [{}, {}] in the sidecar",
                    range.column,
                    column.min(),
                    column.max(),
                    range.min,
                    range.max
                ));
            }
        }
        Ok(())
    }

    /// Write atomically as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), DatasetError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| DatasetError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::other(e),
        })?;
        crate::fsutil::write_atomic(path, text.as_bytes()).map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Read a sidecar.
    /// A sidecar is a few KiB of JSON: one of more than 1 MiB, or a path
    /// that is not a regular file, is refused before it is read whole.
    pub fn read(path: &Path) -> Result<Sidecar, DatasetError> {
        let text =
            crate::fsutil::read_capped(path, 1 << 20).map_err(|source| DatasetError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        serde_json::from_slice(&text).map_err(|e| DatasetError::Header {
            path: path.to_path_buf(),
            why: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Dataset {
        Dataset {
            n_tendons: 2,
            tensions: DMatrix::from_row_slice(2, 2, &[0.1, 2.0, 3.0, 0.0]),
            poses: DMatrix::from_row_slice(
                2,
                7,
                &[
                    0.01, 0.0, 0.39, 1.0, 0.0, 0.0, 0.0, -0.02, 1e-9, 0.398, 0.99, 0.1, 0.0, 0.0,
                ],
            ),
        }
    }

    #[test]
    fn csv_round_trip_is_bit_identical() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.csv");
        let mut d = sample();
        d.poses[(0, 0)] = 0.1 + 0.2; // not exactly representable in short decimal
        d.write_csv(&path).unwrap();
        assert_eq!(Dataset::read_csv(&path).unwrap(), d);
    }

    #[test]
    fn malformed_files_name_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.csv");
        std::fs::write(&path, "t0,px,py\n1,2,3\n").unwrap();
        let e = Dataset::read_csv(&path).unwrap_err().to_string();
        assert!(e.contains("bad header"), "{e}");

        std::fs::write(&path, "t0,px,py,pz,qw,qx,qy,qz,t1\n1,2,3,4,5,6,7,8,9\n").unwrap();
        let e = Dataset::read_csv(&path).unwrap_err().to_string();
        assert!(e.contains("column t1 is a tension"), "{e}");

        std::fs::write(&path, "t0,px,py,pz,qw,qx,qy,qz\n1,2,3,4,5,6,7,oops\n").unwrap();
        let e = Dataset::read_csv(&path).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("qz"), "{e}");

        std::fs::write(&path, "t0,px,py,pz,qw,qx,qy,qz\n1,2,3,4,5,6,7,NaN\n").unwrap();
        let e = Dataset::read_csv(&path).unwrap_err().to_string();
        assert!(e.contains("not finite"), "{e}");

        std::fs::write(&path, "t0,px,py,pz,qw,qx,qy,qz\n").unwrap();
        assert!(matches!(
            Dataset::read_csv(&path),
            Err(DatasetError::Empty { .. })
        ));
    }
}
