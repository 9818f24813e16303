//! Multi-output regression tree (CART, Breiman et al. 1984): greedy binary
//! splits minimising the summed squared error over all outputs, leaves
//! predicting the mean target. Written here because neither `smartcore` nor
//! `linfa` fits one tree to several targets (`docs/design.md` §4).
//!
//! Tuning: one tree is grown per candidate minimum leaf size, to the largest
//! candidate depth; every node stores its mean, so the tree truncated at a
//! smaller depth is exactly the tree CART would grow with that depth limit
//! (greedy splits do not depend on the limit). Each depth is then scored on
//! the validation split for free.

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::linalg::{argmin, check_splits, rmse};
use super::{LearnError, Learner, Split};

#[derive(Clone, Debug)]
struct Node {
    /// Split feature, or `usize::MAX` for a leaf.
    feature: usize,
    threshold: f64,
    left: u32,
    right: u32,
    depth: u32,
}

/// A grown tree: nodes plus each node's mean target (row `i` of `values`).
#[derive(Clone, Debug)]
struct Grown {
    nodes: Vec<Node>,
    values: Vec<f64>,
    outputs: usize,
}

impl Grown {
    fn grow(x: &DMatrix<f64>, y: &DMatrix<f64>, max_depth: usize, min_leaf: usize) -> Grown {
        let xr: Vec<Vec<f64>> = (0..x.ncols())
            .map(|j| x.column(j).iter().copied().collect())
            .collect();
        let yr: Vec<f64> = y.transpose().as_slice().to_vec();
        let mut g = Grown {
            nodes: Vec::new(),
            values: Vec::new(),
            outputs: y.ncols(),
        };
        let mut idx: Vec<usize> = (0..x.nrows()).collect();
        g.build(&xr, &yr, &mut idx, 0, max_depth, min_leaf.max(1));
        g
    }

    fn mean(&self, yr: &[f64], idx: &[usize]) -> Vec<f64> {
        let m = self.outputs;
        let mut s = vec![0.0; m];
        for &i in idx {
            for (o, v) in s.iter_mut().zip(&yr[i * m..(i + 1) * m]) {
                *o += v;
            }
        }
        s.iter_mut().for_each(|v| *v /= idx.len() as f64);
        s
    }

    /// Best split of the rows `idx`: (feature, threshold, rows going left).
    fn best_split(
        &self,
        xr: &[Vec<f64>],
        yr: &[f64],
        idx: &[usize],
        min_leaf: usize,
    ) -> Option<(usize, f64, usize)> {
        let m = self.outputs;
        let n = idx.len();
        let mut total = vec![0.0; m];
        for &i in idx {
            for (t, v) in total.iter_mut().zip(&yr[i * m..(i + 1) * m]) {
                *t += v;
            }
        }
        let parent: f64 = total.iter().map(|t| t * t).sum::<f64>() / n as f64;
        // Maximise Σ_o (S_L,o² / n_L + S_R,o² / n_R): the same as minimising the
        // children's summed squared error.
        let mut best: Option<(f64, usize, f64, usize)> = None;
        let mut order: Vec<usize> = idx.to_vec();
        let mut left = vec![0.0; m];
        for (f, col) in xr.iter().enumerate() {
            order.sort_unstable_by(|&a, &b| col[a].total_cmp(&col[b]).then(a.cmp(&b)));
            left.iter_mut().for_each(|v| *v = 0.0);
            for k in 0..n - 1 {
                let i = order[k];
                for (l, v) in left.iter_mut().zip(&yr[i * m..(i + 1) * m]) {
                    *l += v;
                }
                let nl = k + 1;
                let nr = n - nl;
                let (a, b) = (col[i], col[order[k + 1]]);
                if nl < min_leaf || nr < min_leaf || a == b {
                    continue;
                }
                let mut score = 0.0;
                for o in 0..m {
                    let r = total[o] - left[o];
                    score += left[o] * left[o] / nl as f64 + r * r / nr as f64;
                }
                if score > parent * (1.0 + 1e-12) + 1e-15 && best.is_none_or(|bb| score > bb.0) {
                    best = Some((score, f, a + 0.5 * (b - a), nl));
                }
            }
        }
        best.map(|(_, f, t, nl)| (f, t, nl))
    }

    fn build(
        &mut self,
        xr: &[Vec<f64>],
        yr: &[f64],
        idx: &mut [usize],
        depth: usize,
        max_depth: usize,
        min_leaf: usize,
    ) -> u32 {
        let id = self.nodes.len() as u32;
        let mean = self.mean(yr, idx);
        self.values.extend_from_slice(&mean);
        self.nodes.push(Node {
            feature: usize::MAX,
            threshold: 0.0,
            left: 0,
            right: 0,
            depth: depth as u32,
        });
        if depth >= max_depth || idx.len() < 2 * min_leaf {
            return id;
        }
        let Some((f, t, nl)) = self.best_split(xr, yr, idx, min_leaf) else {
            return id;
        };
        // Partition rows (stable order keeps the growth deterministic).
        let (mut l, mut r): (Vec<usize>, Vec<usize>) = idx.iter().partition(|&&i| xr[f][i] <= t);
        debug_assert_eq!(l.len(), nl);
        let left = self.build(xr, yr, &mut l, depth + 1, max_depth, min_leaf);
        let right = self.build(xr, yr, &mut r, depth + 1, max_depth, min_leaf);
        let node = &mut self.nodes[id as usize];
        node.feature = f;
        node.threshold = t;
        node.left = left;
        node.right = right;
        id
    }

    /// Node reached by `row` when the tree is cut at `depth`.
    fn leaf(&self, row: &[f64], depth: usize) -> usize {
        let mut k = 0usize;
        loop {
            let n = &self.nodes[k];
            if n.feature == usize::MAX || n.depth as usize >= depth {
                return k;
            }
            k = if row[n.feature] <= n.threshold {
                n.left
            } else {
                n.right
            } as usize;
        }
    }

    fn predict(&self, x: &DMatrix<f64>, depth: usize) -> DMatrix<f64> {
        let m = self.outputs;
        let mut out = DMatrix::zeros(x.nrows(), m);
        let mut row = vec![0.0; x.ncols()];
        for i in 0..x.nrows() {
            for (j, r) in row.iter_mut().enumerate() {
                *r = x[(i, j)];
            }
            let k = self.leaf(&row, depth);
            for o in 0..m {
                out[(i, o)] = self.values[k * m + o];
            }
        }
        out
    }

    /// Stored numbers of the tree cut at `depth`: (feature, threshold) per
    /// internal node, the mean per leaf.
    fn size(&self, depth: usize) -> usize {
        self.nodes
            .iter()
            .filter(|n| (n.depth as usize) <= depth)
            .map(|n| {
                if n.feature == usize::MAX || n.depth as usize == depth {
                    self.outputs
                } else {
                    2
                }
            })
            .sum()
    }
}

/// CART regression tree over all outputs at once.
pub struct RegressionTree {
    /// Candidate depth limits tried on the validation split.
    pub depths: Vec<usize>,
    /// Candidate minimum samples per leaf tried on the validation split.
    pub min_leaves: Vec<usize>,
    depth: usize,
    min_leaf: usize,
    tree: Option<Grown>,
}

impl Default for RegressionTree {
    /// The grid used by `tendril compare`: depths 4–24 × leaf sizes {1, 2, 4, 8, 16}
    /// (five grown trees, 105 candidates scored).
    fn default() -> Self {
        RegressionTree::with_grid((4..=24).collect(), vec![1, 2, 4, 8, 16])
    }
}

impl RegressionTree {
    /// A tree choosing depth and minimum leaf size from the given candidates.
    pub fn with_grid(depths: Vec<usize>, min_leaves: Vec<usize>) -> RegressionTree {
        RegressionTree {
            depths,
            min_leaves,
            depth: 0,
            min_leaf: 1,
            tree: None,
        }
    }

    /// A tree with fixed depth limit and minimum leaf size.
    pub fn fixed(depth: usize, min_leaf: usize) -> RegressionTree {
        RegressionTree::with_grid(vec![depth], vec![min_leaf])
    }

    /// The chosen depth limit.
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// The chosen minimum leaf size.
    pub fn min_leaf(&self) -> usize {
        self.min_leaf
    }
}

impl Learner for RegressionTree {
    fn name(&self) -> &str {
        "Regression tree"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, _seed: u64) -> Result<(), LearnError> {
        check_splits(train, valid)?;
        if self.depths.is_empty() || self.min_leaves.is_empty() || self.min_leaves.contains(&0) {
            return Err(LearnError::BadParameter {
                name: "tree grid",
                why: "need at least one depth and one minimum leaf size ≥ 1".into(),
            });
        }
        let max_depth = self.depths.iter().copied().max().unwrap_or(0);
        let grown: Vec<Grown> = self
            .min_leaves
            .par_iter()
            .map(|&ml| Grown::grow(train.x, train.y, max_depth, ml))
            .collect();
        let cands: Vec<(usize, usize)> = (0..grown.len())
            .flat_map(|g| self.depths.iter().map(move |&d| (g, d)))
            .collect();
        let scores: Vec<f64> = cands
            .par_iter()
            .map(|&(g, d)| rmse(&grown[g].predict(valid.x, d), valid.y))
            .collect();
        let best = argmin(&scores)
            .ok_or_else(|| LearnError::Numerical("every tree candidate gave NaN".into()))?;
        let (g, d) = cands[best];
        self.depth = d;
        self.min_leaf = self.min_leaves[g];
        self.tree = grown.into_iter().nth(g);
        log::debug!(
            "Regression tree: depth={} min_leaf={} (valid RMSE {:.5})",
            self.depth,
            self.min_leaf,
            scores[best]
        );
        Ok(())
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.tree {
            Some(t) => t.predict(x, self.depth),
            None => DMatrix::from_element(x.nrows(), 0, f64::NAN),
        }
    }

    fn parameter_count(&self) -> usize {
        self.tree.as_ref().map_or(0, |t| t.size(self.depth))
    }

    fn describe(&self) -> String {
        format!("max depth={}, min leaf={}", self.depth, self.min_leaf)
    }
}
