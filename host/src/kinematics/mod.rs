//! Robot kinematics beside the statics (`docs/design.md` §2): the
//! model-based lift of a lateral tip position to a reachable pose with its
//! tangent ([`lift`]), and the constant-curvature arc ([`arc`]). The planner
//! and the loop use them; they know nothing of IPC.

pub mod arc;
pub mod lift;

pub use lift::{bend_tensions, family_shift, Lifter, Tangent};

/// What can go wrong lifting a lateral position to a pose.
#[derive(Debug, thiserror::Error)]
pub enum KinematicsError {
    /// The statics did not converge.
    #[error("lifting a tip position: statics: {0}")]
    Statics(String),
    /// No tendon tensions within the limits put the tip there.
    #[error("tip position ({x_mm:.1}, {y_mm:.1}) mm is outside the robot's workspace")]
    OutsideWorkspace {
        /// Lateral x, mm.
        x_mm: f64,
        /// Lateral y, mm.
        y_mm: f64,
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
