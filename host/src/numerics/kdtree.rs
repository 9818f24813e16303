//! Nearest neighbours in a few dimensions, chosen at run time: `kiddo`'s
//! immutable k-d tree fixes the dimension at compile time, so [`KdTree`]
//! holds one variant per dimension up to [`MAX_DIM`]. Shared by the KNN
//! learner (poses, 7 inputs) and the measured rows' local forward model
//! (tensions, up to nine tendons).

use std::num::NonZero;

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use nalgebra::DMatrix;

/// Largest dimension a [`KdTree`] is compiled for: a pose has 7, a robot
/// up to `tendril_shared::MAX_TENDONS` = 9 tensions.
pub const MAX_DIM: usize = 9;

/// Points of more dimensions than [`MAX_DIM`] (or none).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("nearest-neighbour search supports 1–{MAX_DIM} dimensions, got {0}")]
pub struct DimensionError(pub usize);

type Tree<const K: usize> = ImmutableKdTree<f64, u32, K, 32>;

/// A k-d tree over the rows of a matrix.
pub enum KdTree {
    /// One dimension.
    D1(Tree<1>),
    /// Two dimensions.
    D2(Tree<2>),
    /// Three dimensions.
    D3(Tree<3>),
    /// Four dimensions.
    D4(Tree<4>),
    /// Five dimensions.
    D5(Tree<5>),
    /// Six dimensions.
    D6(Tree<6>),
    /// Seven dimensions.
    D7(Tree<7>),
    /// Eight dimensions.
    D8(Tree<8>),
    /// Nine dimensions.
    D9(Tree<9>),
}

fn points<const K: usize>(x: &DMatrix<f64>) -> Vec<[f64; K]> {
    (0..x.nrows())
        .map(|i| std::array::from_fn(|j| x[(i, j)]))
        .collect()
}

fn query<const K: usize>(t: &Tree<K>, q: &[f64], k: NonZero<usize>) -> Vec<(f64, usize)> {
    let q: [f64; K] = std::array::from_fn(|j| q.get(j).copied().unwrap_or(0.0));
    t.nearest_n::<SquaredEuclidean>(&q, k)
        .into_iter()
        .map(|n| (n.distance.sqrt(), n.item as usize))
        .collect()
}

impl KdTree {
    /// The tree over the rows of `x` (row index = item).
    pub fn build(x: &DMatrix<f64>) -> Result<KdTree, DimensionError> {
        Ok(match x.ncols() {
            1 => KdTree::D1(Tree::new_from_slice(&points::<1>(x))),
            2 => KdTree::D2(Tree::new_from_slice(&points::<2>(x))),
            3 => KdTree::D3(Tree::new_from_slice(&points::<3>(x))),
            4 => KdTree::D4(Tree::new_from_slice(&points::<4>(x))),
            5 => KdTree::D5(Tree::new_from_slice(&points::<5>(x))),
            6 => KdTree::D6(Tree::new_from_slice(&points::<6>(x))),
            7 => KdTree::D7(Tree::new_from_slice(&points::<7>(x))),
            8 => KdTree::D8(Tree::new_from_slice(&points::<8>(x))),
            9 => KdTree::D9(Tree::new_from_slice(&points::<9>(x))),
            d => return Err(DimensionError(d)),
        })
    }

    /// The `k` rows nearest `q` (Euclidean): (distance, row), nearest
    /// first, ties broken by row index so the result never depends on the
    /// tree's layout. Fewer if the tree has fewer rows.
    pub fn nearest(&self, q: &[f64], k: usize) -> Vec<(f64, usize)> {
        let k = NonZero::new(k.max(1)).unwrap_or(NonZero::<usize>::MIN);
        let mut v = match self {
            KdTree::D1(t) => query(t, q, k),
            KdTree::D2(t) => query(t, q, k),
            KdTree::D3(t) => query(t, q, k),
            KdTree::D4(t) => query(t, q, k),
            KdTree::D5(t) => query(t, q, k),
            KdTree::D6(t) => query(t, q, k),
            KdTree::D7(t) => query(t, q, k),
            KdTree::D8(t) => query(t, q, k),
            KdTree::D9(t) => query(t, q, k),
        };
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        v
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Against a brute-force scan, in every dimension: the same distances
    /// (the rows may differ only among equal distances).
    #[test]
    fn nearest_matches_a_brute_force_scan() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for d in 1..=MAX_DIM {
            // A coarse grid makes ties, the case the index order settles.
            let x = DMatrix::from_fn(500, d, |_, _| f64::from(rng.random_range(0..6u8)) * 0.5);
            let tree = KdTree::build(&x).unwrap();
            for _ in 0..20 {
                let q: Vec<f64> = (0..d).map(|_| rng.random_range(-0.5..3.0)).collect();
                let mut all: Vec<f64> = (0..x.nrows())
                    .map(|i| {
                        (0..d)
                            .map(|j| (x[(i, j)] - q[j]).powi(2))
                            .sum::<f64>()
                            .sqrt()
                    })
                    .collect();
                all.sort_by(f64::total_cmp);
                let got = tree.nearest(&q, 12);
                assert_eq!(got.len(), 12);
                for ((dist, row), want) in got.iter().zip(&all) {
                    assert!((dist - want).abs() < 1e-12, "d = {d}: {dist} vs {want}");
                    let own: f64 = (0..d)
                        .map(|j| (x[(*row, j)] - q[j]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!((own - dist).abs() < 1e-12, "row {row} is not at {dist}");
                }
            }
        }
        assert_eq!(
            KdTree::build(&DMatrix::zeros(3, 10)).err(),
            Some(DimensionError(10))
        );
    }
}
