//! Learners of the inverse kinematics map tip pose → tendon tensions
//! (`docs/design.md` §4). Every learner sees min–max normalised inputs and outputs
//! in [0, 1] (ranges from the training split) and implements [`Learner`], so
//! the comparison treats them all alike.

pub mod cascade_forward;
pub mod cascor;
pub mod elm;
pub mod knn;
pub mod learner;
pub mod linalg;
pub mod mlp;
pub mod quick;
pub mod rbf;
pub mod targets;
pub mod tree;

pub use learner::{LearnError, Learner, Split};
