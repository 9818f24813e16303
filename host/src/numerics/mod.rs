//! Numerical building blocks shared by the statics, their sensitivities and
//! the dynamics: one classical RK4 step ([`rk4`]) and the small dense
//! solvers ([`dense`]).

pub mod dense;
pub mod rk4;
