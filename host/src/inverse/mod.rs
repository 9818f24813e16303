//! Exact, model-based inverse kinematics (`docs/design.md` §4.1): the
//! tensions τ ∈ [τ_min, τ_max] whose statics put the tip at a target — a tip
//! position, a full pose with orientation, or a lateral position (x, y) with
//! height and orientation free (the planner's lift) — to a micron.
//!
//! `jacobian` gives ∂pose/∂τ exactly from the shooting sensitivities,
//! `solve` runs one local bounded Gauss–Newton on τ and then resolves the
//! redundancy (least total tension above the floors), `global` restarts it
//! from the nearest samples of a forward-kinematics `table` when it does not
//! reach the target (so a closest pose is the closest, not a local one),
//! `batch` streams a CSV of targets, every row answered.

mod global;
pub mod jacobian;
pub mod solve;
pub mod table;

use nalgebra::{DMatrix, UnitQuaternion, Vector2, Vector3};

pub use jacobian::{tip_jacobian, JacobianError, TipJacobian};
pub use solve::{ExactIk, IkSettings, Redundancy};
pub use table::SeedTable;

use crate::statics::{SolveError, WarmStart};

/// Largest accepted deviation of a target quaternion's norm from 1.
pub const UNIT_TOLERANCE: f64 = 1e-3;

/// What the tip should reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// Tip position only (base frame, m).
    Position(Vector3<f64>),
    /// Tip position (m) and orientation.
    Pose(Vector3<f64>, UnitQuaternion<f64>),
    /// Lateral tip position (x, y) in the base frame, m; height and
    /// orientation follow from the tensions (a bending robot's two degrees
    /// of freedom, `docs/design.md` §6).
    Lateral(Vector2<f64>),
    /// The tip's coordinate `a · p` along the unit axis `a` (base frame, m);
    /// the rest of the pose follows from the tensions (a robot whose tip
    /// moves along a curve, e.g. one tendon, `docs/design.md` §6).
    Along(Vector3<f64>, f64),
}

impl Target {
    /// A target from a pose px, py, pz, qw, qx, qy, qz (the dataset's
    /// columns); `position_only` drops the orientation. The quaternion must
    /// be finite and of unit length within [`UNIT_TOLERANCE`] even when it is
    /// dropped, so a garbled row never passes.
    pub fn from_pose(pose: &[f64; 7], position_only: bool) -> Result<Target, InverseError> {
        const NAMES: [&str; 7] = ["px", "py", "pz", "qw", "qx", "qy", "qz"];
        for (&value, column) in pose.iter().zip(NAMES) {
            if !value.is_finite() {
                return Err(InverseError::NotFinite { column, value });
            }
        }
        let norm = pose[3..].iter().map(|q| q * q).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(InverseError::NotUnit { norm });
        }
        let position = Vector3::new(pose[0], pose[1], pose[2]);
        if position_only {
            return Ok(Target::Position(position));
        }
        let q = nalgebra::Quaternion::new(pose[3], pose[4], pose[5], pose[6]);
        Ok(Target::Pose(position, UnitQuaternion::from_quaternion(q)))
    }

    /// The target position, m (`None` for a lateral or axis target: part
    /// of the position is free).
    pub fn position(&self) -> Option<Vector3<f64>> {
        match self {
            Target::Position(p) | Target::Pose(p, _) => Some(*p),
            Target::Lateral(_) | Target::Along(..) => None,
        }
    }

    /// How many leading components of the error are position (m): 2 for a
    /// lateral target, 1 along an axis, else 3.
    pub(crate) fn position_rows(&self) -> usize {
        match self {
            Target::Along(..) => 1,
            Target::Lateral(_) => 2,
            Target::Position(_) | Target::Pose(..) => 3,
        }
    }
}

/// The answer for one target.
#[derive(Clone, Debug)]
pub struct IkSolution {
    /// Tensions, N, within the robot's limits.
    pub tensions: Vec<f64>,
    /// The pose these tensions reach: px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// Distance from the reached tip to the target position (for a lateral
    /// target: the lateral distance; along an axis: the distance along it), m.
    pub position_error: f64,
    /// Angle between reached and target orientation, rad (pose targets only).
    pub orientation_error: Option<f64>,
    /// Tendons at their floor τ_min.
    pub at_min: Vec<usize>,
    /// Tendons at their ceiling τ_max.
    pub at_max: Vec<usize>,
    /// Statics solves spent.
    pub solves: usize,
    /// Warm start of the statics at the answer (for the next point of a path).
    pub warm: WarmStart,
    /// The tip Jacobian ∂pose/∂τ at the answer (6 × tendons, rows as
    /// [`TipJacobian::jacobian`]) when the iteration formed it there.
    pub jacobian: Option<DMatrix<f64>>,
}

impl IkSolution {
    /// "tendon 0 at max, tendons 2, 3 at min" style list of the active limits.
    pub fn active_limits(&self) -> String {
        let list = |v: &[usize]| {
            v.iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut parts = Vec::new();
        if !self.at_max.is_empty() {
            parts.push(format!("at max: tendon {}", list(&self.at_max)));
        }
        if !self.at_min.is_empty() {
            parts.push(format!("at min: tendon {}", list(&self.at_min)));
        }
        if parts.is_empty() {
            "no limit active".into()
        } else {
            parts.join("; ")
        }
    }
}

/// Why no exact answer could be given.
#[derive(Debug, Clone, thiserror::Error)]
pub enum InverseError {
    /// A target value is NaN or infinite.
    #[error("target {column} = {value} is not a finite number")]
    NotFinite {
        /// Column name.
        column: &'static str,
        /// The value.
        value: f64,
    },
    /// The target quaternion is not of unit length.
    #[error("target quaternion has norm {norm}, not 1 (tolerance {UNIT_TOLERANCE})")]
    NotUnit {
        /// Its norm.
        norm: f64,
    },
    /// The start tensions do not fit the robot.
    #[error("start tensions: expected {expected} values, got {got}")]
    StartCount {
        /// Tendons of the robot.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A statics solve failed.
    #[error(transparent)]
    Statics(#[from] SolveError),
    /// The tip Jacobian could not be formed.
    #[error(transparent)]
    Jacobian(#[from] JacobianError),
    /// Every start of the global search ran out of solves before reaching
    /// the target or a closest point (`position_error`: the best met).
    #[error("exact IK did not converge: tip {position_error:.3e} m from the target after {solves} statics solves")]
    NotConverged {
        /// Distance left, m.
        position_error: f64,
        /// Statics solves spent.
        solves: usize,
    },
    /// The target is out of reach: `closest` is the nearest reachable pose
    /// the global search found (no farther than its table's best sample).
    #[error(
        "target out of reach: the closest reachable tip is {:.6} m away ({})",
        closest.position_error,
        closest.active_limits()
    )]
    Unreachable {
        /// The closest reachable answer (its errors are the distance).
        closest: Box<IkSolution>,
    },
}
