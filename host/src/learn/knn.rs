//! k-nearest-neighbour regression on a k-d tree (`kiddo`'s immutable tree):
//! the prediction is the (optionally inverse-distance weighted) mean target of
//! the k training points nearest in normalised input space. k and the
//! weighting are chosen on the validation split.

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::linalg::{argmin, check_splits, rmse};
use super::{LearnError, Learner, Split};
use crate::numerics::kdtree::KdTree as Tree;

/// How the k neighbours' targets are averaged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weighting {
    /// Plain mean.
    Uniform,
    /// Weights 1/distance; an exact match (distance 0) takes the mean of the exact matches.
    Distance,
}

impl Weighting {
    fn label(self) -> &'static str {
        match self {
            Weighting::Uniform => "uniform",
            Weighting::Distance => "distance",
        }
    }
}

/// Largest input dimension the k-d tree is compiled for (a pose has 7).
pub const MAX_DIM: usize = crate::numerics::kdtree::MAX_DIM;

fn build_tree(x: &DMatrix<f64>) -> Result<Tree, LearnError> {
    Tree::build(x).map_err(|e| LearnError::BadData(format!("KNN: {e}")))
}

/// k-nearest-neighbour regressor.
pub struct Knn {
    /// Candidate k values tried on the validation split.
    pub ks: Vec<usize>,
    /// Candidate weightings tried on the validation split.
    pub weightings: Vec<Weighting>,
    k: usize,
    weighting: Weighting,
    tree: Option<Tree>,
    train_y: DMatrix<f64>,
    n_inputs: usize,
}

impl Default for Knn {
    /// The tuning grid used by `tendril compare`: 14 candidates, each one k-d
    /// tree query of the validation split (all share a single query).
    fn default() -> Self {
        Knn::with_grid(
            vec![1, 2, 3, 4, 5, 7, 10, 15, 20],
            vec![Weighting::Uniform, Weighting::Distance],
        )
    }
}

impl Knn {
    /// A KNN choosing among the given k values and weightings by validation RMSE.
    pub fn with_grid(ks: Vec<usize>, weightings: Vec<Weighting>) -> Knn {
        Knn {
            ks,
            weightings,
            k: 1,
            weighting: Weighting::Uniform,
            tree: None,
            train_y: DMatrix::zeros(0, 0),
            n_inputs: 0,
        }
    }

    /// A KNN with fixed hyper-parameters (no tuning).
    pub fn fixed(k: usize, weighting: Weighting) -> Knn {
        Knn::with_grid(vec![k], vec![weighting])
    }

    /// The chosen k.
    pub fn k(&self) -> usize {
        self.k
    }

    /// The chosen weighting.
    pub fn weighting(&self) -> Weighting {
        self.weighting
    }

    fn combine(neigh: &[(f64, usize)], k: usize, w: Weighting, y: &DMatrix<f64>, out: &mut [f64]) {
        out.iter_mut().for_each(|o| *o = 0.0);
        let neigh = &neigh[..k.min(neigh.len())];
        let exact: Vec<usize> = neigh.iter().filter(|n| n.0 == 0.0).map(|n| n.1).collect();
        let mut total = 0.0;
        let mut add = |row: usize, wt: f64, out: &mut [f64]| {
            for (j, o) in out.iter_mut().enumerate() {
                *o += wt * y[(row, j)];
            }
            total += wt;
        };
        match w {
            Weighting::Distance if !exact.is_empty() => {
                exact.iter().for_each(|&r| add(r, 1.0, out))
            }
            Weighting::Distance => neigh.iter().for_each(|&(d, r)| add(r, 1.0 / d, out)),
            Weighting::Uniform => neigh.iter().for_each(|&(_, r)| add(r, 1.0, out)),
        }
        out.iter_mut().for_each(|o| *o /= total);
    }

    fn predict_with(&self, x: &DMatrix<f64>, k: usize, w: Weighting) -> DMatrix<f64> {
        let m = self.train_y.ncols();
        let Some(tree) = &self.tree else {
            return DMatrix::from_element(x.nrows(), m, f64::NAN);
        };
        let rows: Vec<Vec<f64>> = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let q: Vec<f64> = x.row(i).iter().copied().collect();
                let mut out = vec![0.0; m];
                Self::combine(&tree.nearest(&q, k), k, w, &self.train_y, &mut out);
                out
            })
            .collect();
        DMatrix::from_fn(x.nrows(), m, |i, j| rows[i][j])
    }
}

impl Learner for Knn {
    fn name(&self) -> &str {
        "KNN"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, _seed: u64) -> Result<(), LearnError> {
        check_splits(train, valid)?;
        if self.ks.is_empty() || self.weightings.is_empty() || self.ks.contains(&0) {
            return Err(LearnError::BadParameter {
                name: "k",
                why: "need at least one k ≥ 1 and one weighting".into(),
            });
        }
        self.tree = Some(build_tree(train.x)?);
        self.train_y = train.y.clone();
        self.n_inputs = train.x.ncols();
        let tree = self
            .tree
            .as_ref()
            .ok_or_else(|| LearnError::Numerical("no tree".into()))?;
        let k_max = self.ks.iter().copied().max().unwrap_or(1).min(train.len());
        // One query of the validation split with the largest k serves every candidate.
        let neigh: Vec<Vec<(f64, usize)>> = (0..valid.len())
            .into_par_iter()
            .map(|i| {
                let q: Vec<f64> = valid.x.row(i).iter().copied().collect();
                tree.nearest(&q, k_max)
            })
            .collect();
        let cands: Vec<(usize, Weighting)> = self
            .ks
            .iter()
            .flat_map(|&k| self.weightings.iter().map(move |&w| (k, w)))
            .collect();
        let m = train.y.ncols();
        let scores: Vec<f64> = cands
            .iter()
            .map(|&(k, w)| {
                let mut pred = DMatrix::zeros(valid.len(), m);
                let mut out = vec![0.0; m];
                for (i, nb) in neigh.iter().enumerate() {
                    Self::combine(nb, k, w, train.y, &mut out);
                    for j in 0..m {
                        pred[(i, j)] = out[j];
                    }
                }
                rmse(&pred, valid.y)
            })
            .collect();
        let best = argmin(&scores)
            .ok_or_else(|| LearnError::Numerical("every KNN candidate gave NaN".into()))?;
        (self.k, self.weighting) = cands[best];
        log::debug!(
            "KNN: k={} weights={} (valid RMSE {:.5})",
            self.k,
            self.weighting.label(),
            scores[best]
        );
        Ok(())
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        self.predict_with(x, self.k, self.weighting)
    }

    fn parameter_count(&self) -> usize {
        self.train_y.nrows() * (self.n_inputs + self.train_y.ncols())
    }

    fn describe(&self) -> String {
        format!("k={}, weights={}", self.k, self.weighting.label())
    }
}
