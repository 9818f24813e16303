//! Learners of the inverse kinematics map tip pose → tendon tensions
//! (`DESIGN.md` §4). Every learner sees min–max normalised inputs and outputs
//! in [0, 1] (ranges from the training split) and implements [`Learner`], so
//! the comparison treats them all alike.

pub mod cascor;
pub mod learner;

pub use learner::{Learner, LearnError, Split};
