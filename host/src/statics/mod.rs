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
mod error;
mod facade;
pub mod friction;
pub mod implicit;
pub mod integrate;
pub mod pose;
pub mod profile;
pub mod rod;
mod settings;
pub mod shoot;
mod solution;
pub mod stability;
mod state;
pub mod tangent;

pub use error::SolveError;
pub use facade::Statics;
pub use friction::{Friction, FrictionState};
pub use implicit::{TipVector, UnknownsTangent};
pub use profile::{FrictionError, TensionProfile};
pub use rod::SingularSystem;
pub use settings::{SolverSettings, MAX_STEPS};
pub use shoot::RodShape;
pub use solution::{Solution, TensionSensitivity, TipSensitivity, WarmStart};

#[cfg(test)]
mod tests;

/// One step of the fixed pseudo-random walk that chains of warm solves
/// follow in the statics benchmarks and tests (`examples/statics_cost`
/// chain and tips, BENCHMARKS.md "Statics"): ±0.1 N on one tendon, both
/// picked by a 64-bit LCG in `state`, clamped to [0, `max`].
pub fn walk_step(state: &mut u64, tau: &mut [f64], max: &[f64]) {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let i = (*state >> 33) as usize % tau.len();
    let up = (*state >> 40) & 1 == 1;
    tau[i] = (tau[i] + if up { 0.1 } else { -0.1 }).clamp(0.0, max[i]);
}

/// [`crate::robot::repo_robot`]'s statics with the default solver settings:
/// the repository's robot files for tests, benches and examples.
pub fn repo_statics(file: &str) -> Statics {
    Statics::new(&crate::robot::repo_robot(file), SolverSettings::default())
}
