//! Planning (`docs/design.md` §4.1, §6): what the planner follows and how it
//! becomes reachable poses, with no IPC in it.
//!
//! - [`shape`]: the path schema ([`PathShape`], a pose table's [`PoseRow`])
//!   and whether a robot's family can follow it;
//! - [`family`]: the robot's family of reachable tip positions ([`Family`]);
//! - [`path`]: pure path geometry (points on the family over time);
//! - [`headroom`]: how far a path's tensions stay below their limits, and
//!   the heights that keep a stated share of the range free;
//! - [`lift`]: lifting tip coordinates on the family to a reachable pose with
//!   its tangent on the exact IK ([`Lifter`], [`FamilyTangent`]);
//! - [`shaping`]: steps that excite no mode (minimum-jerk move and ZVD
//!   shaper on the rod's first mode, [`StepShaping`]);
//! - [`learning`]: learning for repeated paths (iterative learning control
//!   on the path's harmonics, its design and convergence check, [`Learner`]);
//! - [`stiffness`]: adapting to a backbone stiffer or softer than its file
//!   (the tip's direction of a stiffness change, the estimate from the
//!   tracker, [`StiffnessEstimator`]);
//! - [`motion`]: what the planner asks for at each instant: the settle
//!   hold or the approach from rest, the trajectory on its eased clock, the
//!   dynamic offset ([`Motion`]);
//! - [`trajectory`]: the lifted path tabulated once with its feed-forward
//!   tensions ([`Trajectory`]);
//! - [`table`]: pose tables (feed-forward by the exact IK, the CSV reader);
//! - [`runs`]: the closed-loop runs the main job does on a robot;
//! - [`stand_in`]: the samples of the quick stand-in net (fitted by
//!   [`crate::learn::quick`]);
//! - [`bend`]: the bend family of tensions, sweeping a tip around the
//!   workspace for fixtures and benchmarks.
//!
//! `ipc` uses this module (the planner process, the sim); it uses nothing of
//! `ipc`.

pub mod bend;
mod build;
pub mod family;
pub mod headroom;
pub mod learning;
pub mod lift;
pub mod motion;
pub mod net_error;
pub mod path;
pub mod runs;
pub mod shape;
pub mod shaping;
pub mod stand_in;
pub mod stiffness;
pub mod table;
pub mod trajectory;
pub mod turning_offset;

pub use bend::bend_tensions;
pub use family::Family;
pub use headroom::{headroom, Headroom, TENSION_HEADROOM};
pub use learning::IntegralGains;
pub use learning::{Learner, LearningChoice, LearningDesign, LoopModel};
pub use lift::{FamilyTangent, Lifted, Lifter};
pub use motion::{along_axes, Desired, Motion};
pub use net_error::NetErrorOffset;
pub use runs::{default_loop_runs, LoopRun};
pub use shape::{PathShape, PoseRow};
pub use shaping::{ModalInverse, ShapingChoice, StepShaping};
pub use stiffness::{StiffnessAdaptation, StiffnessDirections, StiffnessEstimator};
pub use table::read_pose_csv;
pub use trajectory::{PosePoint, Trajectory};
pub use turning_offset::{ExpectedError, LearnedFor, StartOffset, TurningOffset};

use std::path::PathBuf;

use crate::inverse::InverseError;

/// "(15.0, -2.0, 380.0)" from coordinates in metres, in mm.
fn in_mm(u: &[f64]) -> String {
    let parts: Vec<String> = u.iter().map(|v| format!("{:.1}", v * 1e3)).collect();
    format!("({})", parts.join(", "))
}

/// What can go wrong planning: a shape the robot cannot follow, a point it
/// cannot reach, a pose table that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A shape's parameters are out of range, or its robot cannot follow it.
    #[error("{0}")]
    Shape(String),
    /// A pose table could not be read.
    #[error("{}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause (in the message, not a `source`: printed once).
        cause: std::io::Error,
    },
    /// The quick stand-in net could not be fitted.
    #[error(transparent)]
    Learn(#[from] crate::learn::LearnError),
    /// The forward statics failed where a plan needed it.
    #[error("{0}")]
    Statics(String),
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
