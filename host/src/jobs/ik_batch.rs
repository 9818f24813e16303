//! `tendril ik --exact`: one target or a CSV of targets (`docs/design.md`
//! §4.1, §7), started from a `.tnet` net's guess when one is given, else
//! from the tendons' floors. Rows are independent: read, solved in parallel
//! and written a chunk at a time (bounded memory on any input); the output
//! keeps the input order, so it is the same on any thread count. Every row
//! is answered — reached, the closest pose, or failed — and the summary
//! counts them, so the caller's exit status can say how many missed.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::dataset::POSE_COLUMNS;
use crate::inverse::{ExactIk, IkSolution, InverseError, Target};
use crate::net::{GuardedNet, IkError};

/// One target's answer: reached, or the closest reachable pose.
#[derive(Clone, Debug)]
pub struct Answer {
    /// The tensions and the pose they reach.
    pub solution: IkSolution,
    /// Whether the target was reached (else `solution` is the closest pose).
    pub reachable: bool,
}

impl Answer {
    /// `{"tensions":[...],"reached":[px..qz],"position_error":m,
    /// "orientation_error":rad|null,"reachable":bool,"at_min":[..],"at_max":[..],
    /// "solves":k}`.
    pub fn to_json(&self) -> serde_json::Value {
        let s = &self.solution;
        serde_json::json!({
            "tensions": s.tensions,
            "reached": s.pose,
            "position_error": s.position_error,
            "orientation_error": s.orientation_error,
            "reachable": self.reachable,
            "at_min": s.at_min,
            "at_max": s.at_max,
            "solves": s.solves,
        })
    }
}

/// Why a batch failed. The output is written atomically, so a regular
/// file is left as it was; a device, FIFO or stdout has the rows streamed
/// before the failure.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The input could not be read, or a row could not be parsed.
    #[error(transparent)]
    Input(#[from] IkError),
    /// A row's target was refused (not finite, not a unit quaternion): the
    /// input is wrong, as a row that is not a number.
    #[error("{}: line {line}: {why}", path.display())]
    Row {
        /// The input file.
        path: PathBuf,
        /// 1-based line (header = 1).
        line: usize,
        /// The reason (not a `source`: the message says it once).
        why: InverseError,
    },
    /// The output could not be written.
    #[error("{}: {why}", path.display())]
    Output {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
    /// Interrupted (SIGINT, SIGTERM, SIGHUP) between chunks.
    #[error("interrupted after {rows} rows; {} was left as it was", path.display())]
    Interrupted {
        /// The output file.
        path: PathBuf,
        /// Rows answered before the stop.
        rows: usize,
    },
}

/// The exact IK for `pose`, from `net`'s guess when given. An unreachable
/// target is an answer (the closest pose, `reachable: false`); every other
/// failure is an error. `pose` and the answer's pose are in the tracker's
/// frame of the robot's `[base]` (`docs/design.md` §2.4); the IK and the
/// net work in the base frame.
pub fn answer(
    ik: &ExactIk,
    net: Option<&GuardedNet>,
    pose: &[f64; 7],
    position_only: bool,
) -> Result<Answer, InverseError> {
    let base = ik.robot().base;
    let pose = &base.to_base().pose(*pose);
    let target = Target::from_pose(pose, position_only)?;
    // The net's guess is only a start: a pose it refuses starts cold.
    let guess = net.and_then(|n| n.solve(pose).ok()).map(|a| a.tensions);
    let mut answer = match ik.solve(&target, guess.as_deref(), None) {
        Ok(solution) => Answer {
            solution,
            reachable: true,
        },
        Err(InverseError::Unreachable { closest }) => Answer {
            solution: *closest,
            reachable: false,
        },
        Err(e) => return Err(e),
    };
    answer.solution.pose = base.to_tracker().pose(answer.solution.pose);
    Ok(answer)
}

/// What a batch did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    /// Rows answered (every input row: reached, closest or failed).
    pub rows: usize,
    /// Rows whose target is out of reach (`status` = `closest`: the closest
    /// pose written).
    pub unreachable: usize,
    /// Rows the IK failed on (`status` = `failed`: no tensions written).
    pub failed: usize,
    /// Largest position error among the reached rows, m.
    pub worst_reached: f64,
}

impl Summary {
    /// Whether every row reached its target.
    pub fn all_reached(&self) -> bool {
        self.unreachable == 0 && self.failed == 0
    }
}

/// Rows read, solved (in parallel) and written per chunk: the memory a
/// batch holds is this many rows, whatever the input's size.
pub const CHUNK_ROWS: usize = 256;

/// One row's result: an answer, or the IK's failure on a valid target.
type RowResult = Result<Answer, InverseError>;

/// Answer every pose of `input` (columns px,py,pz,qw,qx,qy,qz; others
/// ignored) and write `output` atomically, streaming [`CHUNK_ROWS`] rows at
/// a time: `t0..` (N), the reached pose `px..qz`, `position_error` (m),
/// `orientation_error` (rad, empty for position targets), `reachable` (1,
/// 0, empty when failed) and `status`: `exact` (reached to the tolerance),
/// `closest` (out of reach: the closest reachable pose) or `failed` (the IK
/// did not converge: tensions and pose empty, `position_error` the best
/// reached; the reason in a warning naming the line). Every row is
/// answered; a row that is not a valid target (not a number, not finite, a
/// non-unit quaternion) is bad input and fails the batch.
pub fn solve_csv(
    ik: &ExactIk,
    net: Option<&GuardedNet>,
    position_only: bool,
    input: &Path,
    output: &Path,
) -> Result<Summary, BatchError> {
    if crate::dataset::disk::same_file(input, output) {
        return Err(BatchError::Output {
            path: output.to_path_buf(),
            why: "the output would overwrite the input; choose another --output".into(),
        });
    }
    let mut poses = PoseReader::open(input)?;
    // Built before the parallel rows so that its build runs in parallel.
    if ik.settings().restarts > 0 {
        ik.seed_table();
    }
    let stop = crate::interrupt::stop_flag();
    let n = ik.robot().n_tendons();
    let mut summary = Summary::default();
    let mut fault: Option<BatchError> = None;
    let written = crate::fsutil::write_atomic_with(output, |w| {
        let head: Vec<String> = (0..n)
            .map(|i| format!("t{i}"))
            .chain(POSE_COLUMNS.iter().map(|c| c.to_string()))
            .chain(["position_error", "orientation_error", "reachable", "status"].map(String::from))
            .collect();
        writeln!(w, "{}", head.join(","))?;
        loop {
            if stop.load(std::sync::atomic::Ordering::SeqCst) {
                fault = Some(BatchError::Interrupted {
                    path: output.to_path_buf(),
                    rows: summary.rows,
                });
                return Err(std::io::Error::other("interrupted"));
            }
            let chunk = match poses.next_chunk(CHUNK_ROWS) {
                Ok(chunk) => chunk,
                Err(e) => {
                    fault = Some(e);
                    return Err(std::io::Error::other("bad input"));
                }
            };
            if chunk.is_empty() {
                return Ok(());
            }
            let results: Vec<(usize, RowResult)> = chunk
                .par_iter()
                .map(|(line, pose)| (*line, answer(ik, net, pose, position_only)))
                .collect();
            for (line, result) in results {
                let result = match result {
                    Err(e @ (InverseError::NotFinite { .. } | InverseError::NotUnit { .. })) => {
                        fault = Some(BatchError::Row {
                            path: input.to_path_buf(),
                            line,
                            why: e,
                        });
                        return Err(std::io::Error::other("bad input"));
                    }
                    other => other,
                };
                summary.rows += 1;
                writeln!(w, "{}", row(n, input, line, &result, &mut summary))?;
            }
        }
    });
    if let Some(fault) = fault {
        return Err(fault);
    }
    written.map_err(|e| BatchError::Output {
        path: output.to_path_buf(),
        why: e.to_string(),
    })?;
    Ok(summary)
}

/// One output row for `result` (see [`solve_csv`]), counted into `summary`.
fn row(n: usize, input: &Path, line: usize, result: &RowResult, summary: &mut Summary) -> String {
    let mut cells: Vec<String> = Vec::with_capacity(n + 11);
    match result {
        Ok(a) => {
            let s = &a.solution;
            cells.extend(s.tensions.iter().chain(&s.pose).map(f64::to_string));
            cells.push(s.position_error.to_string());
            cells.push(
                s.orientation_error
                    .map(|e| e.to_string())
                    .unwrap_or_default(),
            );
            cells.push(u8::from(a.reachable).to_string());
            if a.reachable {
                summary.worst_reached = summary.worst_reached.max(s.position_error);
                cells.push("exact".into());
            } else {
                summary.unreachable += 1;
                cells.push("closest".into());
            }
        }
        Err(e) => {
            summary.failed += 1;
            log::warn!("{}: line {line}: {e}", input.display());
            cells.extend(std::iter::repeat_n(String::new(), n + 7));
            cells.push(match e {
                InverseError::NotConverged { position_error, .. } => position_error.to_string(),
                _ => String::new(),
            });
            cells.extend([String::new(), String::new(), "failed".into()]);
        }
    }
    cells.join(",")
}

/// The input's poses, read a chunk at a time.
struct PoseReader {
    path: PathBuf,
    records: csv::StringRecordsIntoIter<crate::fsutil::LineCapped<Box<dyn std::io::Read + Send>>>,
    cols: Vec<usize>,
    line: usize,
}

impl PoseReader {
    fn open(input: &Path) -> Result<PoseReader, IkError> {
        let (reader, cols) = crate::net::guarded::open_pose_csv(input)?;
        Ok(PoseReader {
            path: input.to_path_buf(),
            records: reader.into_records(),
            cols,
            line: 1,
        })
    }

    /// Up to `count` (line, pose) rows; empty at the end.
    fn next_chunk(&mut self, count: usize) -> Result<Vec<(usize, [f64; 7])>, BatchError> {
        let mut chunk = Vec::with_capacity(count);
        while chunk.len() < count {
            let Some(record) = self.records.next() else {
                break;
            };
            self.line += 1;
            let row_error = |why: String| {
                BatchError::Input(IkError::Row {
                    path: self.path.clone(),
                    line: self.line,
                    why,
                })
            };
            let record = record.map_err(|e| row_error(e.to_string()))?;
            let pose =
                crate::net::guarded::pose_of_record(&record, &self.cols).map_err(row_error)?;
            chunk.push((self.line, pose));
        }
        Ok(chunk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A failed row keeps its place: empty tensions and pose, the best
    /// distance met, `status` failed, counted.
    #[test]
    fn a_failed_row_is_written_empty_with_its_status_and_counted() {
        let mut summary = Summary::default();
        let failed: RowResult = Err(InverseError::NotConverged {
            position_error: 0.004,
            solves: 1400,
        });
        let line = row(4, Path::new("in.csv"), 7, &failed, &mut summary);
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), 4 + 7 + 4);
        assert!(cells[..11].iter().all(|c| c.is_empty()), "{line}");
        assert_eq!(cells[11], "0.004");
        assert_eq!(&cells[12..], ["", "", "failed"]);
        assert_eq!(summary.failed, 1);
        assert!(!summary.all_reached());
    }
}
