//! Which tensions a dataset row keeps for its tip (`docs/design.md` §3,
//! "Redundant robots").
//!
//! A robot with more bending freedom than a tip pose can pin down well has
//! no inverse a learner can follow. Three segments bend in six directions
//! and a pose has six coordinates, but near the straight rod only four of
//! them move to first order (tip position across and the tip's tilt); the
//! height and the twist move to second order, so many S-shaped bends reach
//! nearly the same pose and the inverse is steep, folded and several-valued
//! (measured: a 63-unit net's held-out tension error 15 % of the range).
//! Such a robot's rows are resolved: each drawn row's tip *position* is
//! solved again by the exact IK for the tensions of least bending effort
//! ([`Redundancy::LeastBending`]), and the row keeps those tensions and the
//! pose they reach. The net then learns the position-resolved family a
//! planner lifts its paths onto ([`crate::plan::Lifter`] resolves the same
//! way on these robots), a smooth three-dimensional family.

use tendril_shared::CoContraction;

use crate::inverse::Redundancy;
use crate::robot::{bending_dof, cocontraction_sets, Robot};

/// Bending degrees of freedom a full tip pose still determines well: one
/// segment (two) or two (four). Past this the rows are resolved.
pub const POSE_BENDING_DOF: usize = 4;

/// Which tensions a row keeps.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Resolve {
    /// The drawn tensions, as the sampler drew them.
    Drawn,
    /// The tensions of least bending effort that reach the drawn row's tip
    /// position ([`Redundancy::LeastBending`]).
    LeastBending,
}

impl Resolve {
    /// The default for `robot`: [`Resolve::LeastBending`] past
    /// [`POSE_BENDING_DOF`] bending degrees of freedom, else
    /// [`Resolve::Drawn`].
    pub fn default_for(robot: &Robot) -> Resolve {
        if bending_dof(robot) > POSE_BENDING_DOF {
            Resolve::LeastBending
        } else {
            Resolve::Drawn
        }
    }

    /// Name as used on the command line and in sidecars.
    pub fn name(&self) -> &'static str {
        match self {
            Resolve::Drawn => "drawn",
            Resolve::LeastBending => "least-bending",
        }
    }

    /// The redundancy resolution a planner lifting paths for a net trained
    /// on such rows must use: the rows' own, or for drawn rows the least
    /// total tension (any reachable pose is in their family).
    pub fn redundancy(&self) -> Redundancy {
        match self {
            Resolve::Drawn => Redundancy::LeastTotal,
            Resolve::LeastBending => Redundancy::LeastBending,
        }
    }
}

/// Each co-contraction set of `tau` shifted down along its weights until
/// its lowest member sits at its floor: the tensions the firmware's command
/// stage makes of the net's centred output (`learn::targets`), so a
/// resolved row is what the robot would be commanded. The least bending
/// effort leaves co-contraction free; this takes it out. The tip moves by
/// the axial strain only (µm); the row keeps the pose of the shifted
/// tensions.
pub fn slacken(robot: &Robot, tau: &mut [f64]) {
    let sets = cocontraction_sets(robot);
    let lo = robot.min_tensions();
    let (set, weight) = (sets.sets(), sets.weights());
    for (first, &s) in set.iter().enumerate().take(tau.len()) {
        if s == CoContraction::NONE || set[..first].contains(&s) {
            continue;
        }
        let members: Vec<usize> = (first..tau.len()).filter(|&i| set[i] == s).collect();
        let w = |i: usize| f64::from(weight[i]);
        let slack = members
            .iter()
            .map(|&i| (tau[i] - lo[i]) / w(i))
            .fold(f64::INFINITY, f64::min);
        for &i in &members {
            tau[i] = (tau[i] - slack * w(i)).max(lo[i]);
        }
    }
}
