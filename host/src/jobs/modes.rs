//! The rod's modes over its workspace (`tendril modes`, `docs/design.md`
//! §6.4): [`crate::dynamics::modes::identify`] at rest and with each
//! segment bent, so a user sees how far the modes move from pose to pose —
//! what a mode-based design (the input shaper's tolerance) must cover.

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
