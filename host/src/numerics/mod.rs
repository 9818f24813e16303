//! Numerical building blocks shared by the statics, their sensitivities and
//! the dynamics: one classical RK4 step ([`rk4`]) and the small dense
//! solvers ([`dense`]); and the nearest-neighbour search of the KNN
//! learner and the measured rows' local model ([`kdtree`]); polylines
//! resampled evenly ([`polyline`]); the nearest-rank percentile every
//! report uses ([`percentile`]).

pub mod dense;
pub mod kdtree;
pub mod percentile;
pub mod polyline;
pub mod rk4;
