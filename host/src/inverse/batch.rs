//! `tendril ik --exact`: one target or a CSV of targets (`docs/design.md`
//! §4.1, §7), started from a `.tnet` net's guess when one is given, else
//! from the tendons' floors. Rows are independent and solved in parallel;
//! the output keeps the input order, so it is the same on any thread count.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::{ExactIk, IkSolution, InverseError, Target};
use crate::dataset::POSE_COLUMNS;
use crate::net::{read_poses, GuardedNet, IkError};

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

/// Why a batch failed (nothing is written then).
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The input could not be read, or a row could not be parsed.
    #[error(transparent)]
    Input(#[from] IkError),
    /// A row's target was refused or its solve failed.
    #[error("{}: line {line}: {source}", path.display())]
    Row {
        /// The input file.
        path: PathBuf,
        /// 1-based line (header = 1).
        line: usize,
        /// The reason.
        source: InverseError,
    },
    /// The output could not be written.
    #[error("{}: {why}", path.display())]
    Output {
        /// The output file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

/// The exact IK for `pose`, from `net`'s guess when given. An unreachable
/// target is an answer (the closest pose, `reachable: false`); every other
/// failure is an error.
pub fn answer(
    ik: &ExactIk,
    net: Option<&GuardedNet>,
    pose: &[f64; 7],
    position_only: bool,
) -> Result<Answer, InverseError> {
    let target = Target::from_pose(pose, position_only)?;
    // The net's guess is only a start: a pose it refuses starts cold.
    let guess = net.and_then(|n| n.solve(pose).ok()).map(|a| a.tensions);
    match ik.solve(&target, guess.as_deref(), None) {
        Ok(solution) => Ok(Answer {
            solution,
            reachable: true,
        }),
        Err(InverseError::Unreachable { closest }) => Ok(Answer {
            solution: *closest,
            reachable: false,
        }),
        Err(e) => Err(e),
    }
}

/// What a batch did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    /// Rows answered.
    pub rows: usize,
    /// Rows whose target is out of reach (the closest pose written).
    pub unreachable: usize,
    /// Largest position error among the reached rows, m.
    pub worst_reached: f64,
}

/// Answer every pose of `input` and write `output` atomically: `t0..` (N),
/// the reached pose `px..qz`, `position_error` (m), `orientation_error`
/// (rad, empty for position targets) and `reachable` (0/1).
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
    let poses = read_poses(input)?;
    let answers: Vec<Answer> = poses
        .par_iter()
        .enumerate()
        .map(|(i, pose)| {
            answer(ik, net, pose, position_only).map_err(|source| BatchError::Row {
                path: input.to_path_buf(),
                line: i + 2,
                source,
            })
        })
        .collect::<Result<_, _>>()?;
    let mut summary = Summary {
        rows: answers.len(),
        ..Summary::default()
    };
    for a in &answers {
        if a.reachable {
            summary.worst_reached = summary.worst_reached.max(a.solution.position_error);
        } else {
            summary.unreachable += 1;
        }
    }
    let n = ik.robot().n_tendons();
    crate::fsutil::write_atomic_with(output, |w| {
        let head: Vec<String> = (0..n)
            .map(|i| format!("t{i}"))
            .chain(POSE_COLUMNS.iter().map(|c| c.to_string()))
            .chain(["position_error", "orientation_error", "reachable"].map(String::from))
            .collect();
        writeln!(w, "{}", head.join(","))?;
        for a in &answers {
            let s = &a.solution;
            let mut cells: Vec<String> = s
                .tensions
                .iter()
                .chain(&s.pose)
                .chain([&s.position_error])
                .map(f64::to_string)
                .collect();
            cells.push(
                s.orientation_error
                    .map(|e| e.to_string())
                    .unwrap_or_default(),
            );
            cells.push(u8::from(a.reachable).to_string());
            writeln!(w, "{}", cells.join(","))?;
        }
        Ok(())
    })
    .map_err(|e| BatchError::Output {
        path: output.to_path_buf(),
        why: e.to_string(),
    })?;
    Ok(summary)
}
