//! Robot kinematics beside the statics (`docs/design.md` §2, §4.1): the
//! planner's lift of a lateral tip position to a reachable pose with its
//! tangent on the exact IK ([`lift`]), the bend family of tensions
//! ([`bend`]) and the constant-curvature arc ([`arc`]). The planner and the
//! loop use them; they know nothing of IPC.

pub mod arc;
pub mod bend;
pub mod lift;

pub use bend::bend_tensions;
pub use lift::{family_shift, Lifted, Lifter, Tangent};

use crate::inverse::InverseError;

/// What can go wrong lifting a lateral position to a pose.
#[derive(Debug, thiserror::Error)]
pub enum KinematicsError {
    /// A coordinate is NaN or infinite.
    #[error("lateral tip position is not a pair of finite numbers")]
    NotFinite,
    /// The exact IK failed (statics or no convergence).
    #[error("lifting a tip position: {0}")]
    Inverse(InverseError),
    /// No tendon tensions within the limits put the tip there.
    #[error("tip position ({x_mm:.1}, {y_mm:.1}) mm is outside the robot's workspace (closest reachable {distance_mm:.2} mm away)")]
    OutsideWorkspace {
        /// Lateral x, mm.
        x_mm: f64,
        /// Lateral y, mm.
        y_mm: f64,
        /// Distance to the closest reachable lateral position, mm.
        distance_mm: f64,
    },
    /// The tip cannot move laterally there (singular Jacobian).
    #[error("tip position ({x_mm:.1}, {y_mm:.1}) mm: the robot cannot move laterally there")]
    Singular {
        /// Lateral x, mm.
        x_mm: f64,
        /// Lateral y, mm.
        y_mm: f64,
    },
}
