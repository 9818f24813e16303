//! Forward statics of a tendon-driven continuum robot: a Cosserat rod
//! (backbone) loaded by Cosserat strings (tendons), after Rucker & Webster,
//! "Statics and Dynamics of Continuum Robots With General Tendon Routing and
//! External Loading", IEEE T-RO 27(6), 2011. `docs/design.md` §2 and §2.1 fix
//! the equations.
//!
//! `rod` holds the constitutive law, strain-rate system and anchor loads,
//! `integrate` the piecewise RK4 pass from base to tip, `tangent` the one
//! sensitivity propagation, `shoot` the boundary-value solve, `pose` the
//! quaternion conventions, `batch` many solves in a canonical order,
//! `stability` the conjugate-point test of a solution and `continuation` the
//! equilibrium a rod loaded from rest reaches (`docs/design.md` §2.2). The RK4
//! step and the 6×6 solvers are [`crate::numerics`]'s.

pub mod batch;
pub mod continuation;
pub mod friction;
pub mod integrate;
pub mod pose;
pub mod rod;
pub mod shoot;
pub mod stability;
pub mod tangent;

pub use friction::{Friction, FrictionError, FrictionState, TensionProfile};
pub use rod::SingularSystem;
pub use shoot::{
    RodShape, Solution, SolveError, SolverSettings, Statics, TensionSensitivity, TipSensitivity,
    WarmStart, MAX_STEPS,
};

#[cfg(test)]
mod friction_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_final_step;
#[cfg(test)]
mod tests_general;
#[cfg(test)]
mod tests_stability;
#[cfg(test)]
mod tests_three_segment;

/// [`crate::robot::repo_robot`]'s statics with the default solver settings:
/// the repository's robot files for tests, benches and examples.
pub fn repo_statics(file: &str) -> Statics {
    Statics::new(&crate::robot::repo_robot(file), SolverSettings::default())
}
