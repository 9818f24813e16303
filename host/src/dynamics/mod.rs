//! Dynamics of a tendon-driven continuum robot: the Cosserat rod of the
//! statics with translational and rotary inertia and Kelvin–Voigt material
//! damping, stepped in time by the implicit BDF-α scheme of Till, Aloi &
//! Rucker, "Real-time dynamics of soft and continuum robots based on Cosserat
//! rod models", IJRR 38(6), 2019 (`docs/design.md` §4.2).
//!
//! Each time derivative ∂y/∂t is replaced by c₀ y + y_h, the history term y_h
//! built from earlier steps at the same grid point, so every time step is a
//! boundary-value problem in arc length of the same shape as the statics,
//! solved by shooting warm-started from the previous step.
//!
//! `params` holds the time scheme and the material constants, `section` the
//! semi-discretised balance laws at one grid point (rates, anchors, tip),
//! `solver` the grid of histories and the Newton shooting per step,
//! `offline` and `figure` the step response `tendril dynamics` writes.

pub mod modes;
pub mod params;
pub mod section;
pub mod solver;

pub use modes::{Mode, ModeSearch, ModesError};
pub use params::{BdfAlpha, Damping, DynamicsSettings};
pub use section::{DynState, TimeVars};
pub use solver::{Dynamics, DynamicsError, TipState};

#[cfg(test)]
mod tests;
