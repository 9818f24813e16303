//! The two Python classes' data, below the modules that give them their
//! methods ([`crate::robot`], [`crate::net`]): each class's methods take
//! the other as an argument (``Robot.ik(net=…)``, ``Net.load(robot=…)``).

use std::path::PathBuf;

use pyo3::prelude::*;
use tendril::net::GuardedNet;
use tendril::robot::Robot as RobotModel;

/// Where the built-in default robot says it came from, in errors and reprs.
pub const BUILTIN_ORIGIN: &str = "<built-in robots/seed-4t.toml>";

/// A tendon-driven continuum robot (the TOML schema of docs/design.md §2).
///
/// Make one with ``Robot.load(path)``, ``Robot.from_toml(text)`` or
/// ``Robot.default()``. Units: m, N, Pa.
#[pyclass(frozen, module = "tendril._tendril")]
pub struct Robot {
    pub model: RobotModel,
    /// The exact TOML text it was made from.
    pub source: String,
    /// The file it was loaded from, if any.
    pub file: Option<PathBuf>,
    /// Whether this is the built-in default robot.
    pub builtin: bool,
}

/// A trained inverse-kinematics net (a ``.tnet`` file) for one robot.
#[pyclass(frozen, module = "tendril._tendril")]
pub struct Net {
    pub(crate) ik: GuardedNet,
    /// The robot's `[base]`: poses come in the tracker's frame, as for
    /// `tendril ik` (docs/design.md §2.4).
    pub(crate) to_base: tendril::robot::RigidMap,
}
