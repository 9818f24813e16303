//! Forward statics of a tendon-driven continuum robot: a Cosserat rod
//! (backbone) loaded by Cosserat strings (tendons), after Rucker & Webster,
//! "Statics and Dynamics of Continuum Robots With General Tendon Routing and
//! External Loading", IEEE T-RO 2011. `DESIGN.md` §2 fixes the equations.

pub mod integrate;
pub mod pose;
pub mod rod;
pub mod shoot;
