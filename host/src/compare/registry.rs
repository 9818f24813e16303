//! The learners of the comparison, with the tuning grids `tendril compare`
//! uses (documented on each learner's `Default`).

use crate::learn::cascade_forward::CascadeForward;
use crate::learn::elm::Elm;
use crate::learn::knn::Knn;
use crate::learn::mlp::Mlp;
use crate::learn::rbf::Rbf;
use crate::learn::tree::RegressionTree;
use crate::learn::Learner;

/// Name of the learner every baseline is measured against.
pub const REFERENCE: &str = "Cascade correlation";
/// The six baselines with the tuning grids used by `tendril compare`
/// (documented on each learner's `Default`).
pub fn baselines() -> Vec<Box<dyn Learner>> {
    vec![
        Box::new(Knn::default()),
        Box::new(Rbf::default()),
        Box::new(Mlp::default()),
        Box::new(Elm::default()),
        Box::new(RegressionTree::default()),
        Box::new(CascadeForward::default()),
    ]
}

/// Every learner of the comparison: cascade correlation first, then the baselines.
pub fn all_learners() -> Vec<Box<dyn Learner>> {
    learners_with(crate::learn::cascor::CascorOptions::default())
}

/// [`all_learners`] with cascade correlation trained as `tendril train`
/// trains it for `robot` (`CascorOptions::for_robot`).
pub fn all_learners_for(robot: &crate::robot::Robot) -> Vec<Box<dyn Learner>> {
    learners_with(crate::learn::cascor::CascorOptions::for_robot(robot))
}

fn learners_with(cascor: crate::learn::cascor::CascorOptions) -> Vec<Box<dyn Learner>> {
    let mut v: Vec<Box<dyn Learner>> = vec![Box::new(crate::learn::cascor::Cascor::new(cascor))];
    v.extend(baselines());
    v
}
