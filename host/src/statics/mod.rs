//! Forward statics of a tendon-driven continuum robot: a Cosserat rod
//! (backbone) loaded by Cosserat strings (tendons), after Rucker & Webster,
//! "Statics and Dynamics of Continuum Robots With General Tendon Routing and
//! External Loading", IEEE T-RO 27(6), 2011. `DESIGN.md` §2 fixes the equations.
//!
//! `rod` holds the constitutive law and strain-rate system, `integrate` the
//! RK4 pass from base to tip, `shoot` the boundary-value solve, `pose` the
//! quaternion conventions.

pub mod integrate;
pub mod pose;
pub mod rod;
pub mod shoot;

pub use shoot::{Solution, SolveError, SolverSettings, Statics, WarmStart};

#[cfg(test)]
mod tests;
