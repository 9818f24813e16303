//! Why a statics solve failed ([`SolveError`]).

use super::profile::FrictionError;
use super::rod::SingularSystem;
use crate::robot::TensionError;

/// Why a statics solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The tension vector does not fit the robot.
    #[error(transparent)]
    BadTensions(#[from] TensionError),
    /// An external load is NaN or infinite.
    #[error("external tip load is not finite")]
    BadLoad,
    /// Newton did not reach the tolerance.
    #[error("statics did not converge: tip residual {residual:.3e} after {iterations} iterations")]
    NotConverged {
        /// Residual norm reached.
        residual: f64,
        /// Iterations spent.
        iterations: usize,
    },
    /// The equilibrium found is unstable: a conjugate point lies on the rod
    /// (`stability`), so a real rod would not stay there.
    #[error(
        "the equilibrium is unstable (a conjugate point at s = {conjugate_at_m:.4} m of the \
         backbone): a real rod would buckle or snap away from it, so it is not an answer"
    )]
    Unstable {
        /// Arc length of the first conjugate point, m.
        conjugate_at_m: f64,
    },
    /// Loading the rod from rest to the asked tip load, the equilibrium
    /// branch turned unstable (a bifurcation) or ended (a fold) on the way:
    /// which equilibrium the rod reaches is not unique.
    #[error(
        "the equilibrium is not unique: loading the rod from rest, its equilibrium turns \
         unstable or ends (a bifurcation or fold, where the rod would buckle or snap) at \
         {percent:.1} % of the tip load",
        percent = load_fraction * 100.0
    )]
    NonUnique {
        /// Fraction of the asked tip load where it happened, 0..1.
        load_fraction: f64,
    },
    /// Continuation from rest spent its budget of load steps
    /// (`continuation`) before reaching the full tip load: the load is too
    /// large for the grid to follow (more RK4 steps may), not a proven fold.
    #[error(
        "statics did not converge: loading the rod from rest, the solve could not follow its \
         equilibrium past {percent:.1} % of the tip load (a load this large may need more \
         --steps)",
        percent = load_fraction * 100.0
    )]
    Stalled {
        /// Fraction of the tip load reached, 0..1.
        load_fraction: f64,
    },
    /// The strain-rate system of the rod could not be solved at the start
    /// of the solve (`docs/design.md` §2: it is positive definite for any
    /// physical robot, so this means non-physical numbers).
    #[error(transparent)]
    Singular(#[from] SingularSystem),
    /// The friction numbers or state do not fit (`docs/design.md` §2.3).
    #[error(transparent)]
    BadFriction(#[from] FrictionError),
}
