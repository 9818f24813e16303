//! Robot kinematics beside the statics (`docs/design.md` §2, §4.1, §6): the
//! robot's family of reachable tip positions ([`family`]), the planner's
//! lift of tip coordinates on it to a reachable pose with its tangent on the
//! exact IK ([`lift`]), the bend family of tensions ([`bend`]) and the
//! constant-curvature arc ([`arc`]). The planner and the loop use them; they
//! know nothing of IPC.

pub mod arc;
pub mod bend;
pub mod family;
pub mod lift;

pub use bend::bend_tensions;
pub use family::Family;
pub use lift::{family_shift, Lifted, Lifter, Tangent};

use crate::inverse::InverseError;

/// "(15.0, -2.0, 380.0)" from coordinates in metres, in mm.
fn in_mm(u: &[f64]) -> String {
    let parts: Vec<String> = u.iter().map(|v| format!("{:.1}", v * 1e3)).collect();
    format!("({})", parts.join(", "))
}

/// What can go wrong lifting tip coordinates to a pose.
#[derive(Debug, thiserror::Error)]
pub enum KinematicsError {
    /// A coordinate is NaN or infinite.
    #[error("tip coordinates are not all finite numbers")]
    NotFinite,
    /// The target has a different number of coordinates than the family.
    #[error("a tip target with {got} coordinates on a robot whose tip reaches {family}")]
    Dimension {
        /// Coordinates given.
        got: usize,
        /// The robot's family, described.
        family: String,
    },
    /// No tension moves the tip sideways (no tendon off the backbone).
    #[error("no tendon tension moves the robot's tip sideways")]
    Immobile,
    /// The exact IK failed (statics or no convergence).
    #[error("lifting a tip position: {0}")]
    Inverse(InverseError),
    /// No tendon tensions within the limits put the tip there.
    #[error("tip target {} mm is outside the robot's workspace (closest reachable {distance_mm:.2} mm away)", in_mm(.coordinates_m))]
    OutsideWorkspace {
        /// The target's coordinates along the family's axes, m.
        coordinates_m: Vec<f64>,
        /// Distance to the closest reachable target, mm.
        distance_mm: f64,
    },
    /// The tip cannot move along every axis there (singular Jacobian).
    #[error("tip target {} mm: the robot cannot move its tip along every axis there", in_mm(.coordinates_m))]
    Singular {
        /// The target's coordinates along the family's axes, m.
        coordinates_m: Vec<f64>,
    },
    /// No height keeps a circle reachable all round.
    #[error("no height at which a circle of radius {radius_mm:.1} mm about {} mm is reachable all round", in_mm(.center_m))]
    NoHeight {
        /// Lateral centre, m.
        center_m: Vec<f64>,
        /// Radius, mm.
        radius_mm: f64,
    },
}
