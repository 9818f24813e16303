//! Small numerical kernels shared by the baseline learners: ridge least
//! squares by Cholesky of the normal equations, a deterministic parallel Gram
//! matrix, RMSE, input checks and seeded random numbers.

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::{LearnError, Split};

/// Rows per block of the parallel Gram product. Fixed (not derived from the
/// thread count) so that the summation order, and so every bit of the
/// result, is the same on any machine.
const GRAM_BLOCK: usize = 1024;

/// A seeded generator for everything random in the baselines: ChaCha8 is
/// portable, so a seed means the same model on every platform.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Derive an independent stream for candidate `i` of a tuning grid, so the
/// candidates can be trained in parallel without sharing a generator.
pub fn sub_seed(seed: u64, i: u64) -> u64 {
    // SplitMix64 step: well-mixed streams from consecutive indices.
    let mut z = seed ^ i.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `AᵀA`, summed over fixed row blocks computed in parallel.
pub fn gram(a: &DMatrix<f64>) -> DMatrix<f64> {
    let (n, h) = a.shape();
    let blocks: Vec<usize> = (0..n).step_by(GRAM_BLOCK).collect();
    let parts: Vec<DMatrix<f64>> = blocks
        .par_iter()
        .map(|&start| {
            let len = GRAM_BLOCK.min(n - start);
            let block = a.rows(start, len).into_owned();
            block.transpose() * block
        })
        .collect();
    let mut g = DMatrix::zeros(h, h);
    for p in parts {
        g += p;
    }
    g
}

/// `AᵀY`, summed over the same fixed row blocks as [`gram`].
pub fn cross(a: &DMatrix<f64>, y: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let blocks: Vec<usize> = (0..n).step_by(GRAM_BLOCK).collect();
    let parts: Vec<DMatrix<f64>> = blocks
        .par_iter()
        .map(|&start| {
            let len = GRAM_BLOCK.min(n - start);
            a.rows(start, len).transpose() * y.rows(start, len)
        })
        .collect();
    let mut c = DMatrix::zeros(a.ncols(), y.ncols());
    for p in parts {
        c += p;
    }
    c
}

/// Solve the ridge normal equations `(G + λ·s·I) W = C` by Cholesky, where
/// `s` is the mean diagonal of `G`: scaling the ridge by the Gram matrix's own
/// size makes `lambda` mean the same for any number of features.
pub fn ridge_solve(
    g: &DMatrix<f64>,
    c: &DMatrix<f64>,
    lambda: f64,
) -> Result<DMatrix<f64>, LearnError> {
    let h = g.nrows();
    let scale = (g.trace() / h.max(1) as f64).max(f64::MIN_POSITIVE);
    let mut a = g.clone();
    for i in 0..h {
        a[(i, i)] += lambda * scale;
    }
    let chol = a.cholesky().ok_or_else(|| {
        LearnError::Numerical(format!(
            "normal equations ({h}×{h}) not positive definite at ridge {lambda:e}"
        ))
    })?;
    Ok(chol.solve(c))
}

/// Ridge least squares `argmin |A W − Y|² + λ·s·|W|²` (see [`ridge_solve`]).
pub fn ridge_fit(
    a: &DMatrix<f64>,
    y: &DMatrix<f64>,
    lambda: f64,
) -> Result<DMatrix<f64>, LearnError> {
    ridge_solve(&gram(a), &cross(a, y), lambda)
}

/// Root-mean-square error over every entry (all samples, all outputs).
pub fn rmse(pred: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
    let n = y.len().max(1) as f64;
    ((pred - y).norm_squared() / n).sqrt()
}

/// Logistic sigmoid 1 / (1 + e^−z).
pub fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// Append a column of ones (the bias feature).
pub fn with_bias(a: DMatrix<f64>) -> DMatrix<f64> {
    let h = a.ncols();
    a.insert_column(h, 1.0)
}

/// Reject data no learner can use: empty splits, shape mismatches, NaN/∞.
pub fn check_splits(train: Split<'_>, valid: Split<'_>) -> Result<(), LearnError> {
    for (name, s) in [("train", train), ("valid", valid)] {
        if s.is_empty() {
            return Err(LearnError::BadData(format!("{name} split is empty")));
        }
        if s.y.nrows() != s.x.nrows() {
            return Err(LearnError::BadData(format!(
                "{name} split has {} input rows but {} target rows",
                s.x.nrows(),
                s.y.nrows()
            )));
        }
        if s.x.iter().chain(s.y.iter()).any(|v| !v.is_finite()) {
            return Err(LearnError::BadData(format!(
                "{name} split holds a non-finite value"
            )));
        }
    }
    if train.x.ncols() != valid.x.ncols() || train.y.ncols() != valid.y.ncols() {
        return Err(LearnError::BadData(format!(
            "train is {}→{} columns but valid is {}→{}",
            train.x.ncols(),
            train.y.ncols(),
            valid.x.ncols(),
            valid.y.ncols()
        )));
    }
    if train.x.ncols() == 0 || train.y.ncols() == 0 {
        return Err(LearnError::BadData("no input or no output column".into()));
    }
    Ok(())
}

/// Index of the smallest score; ties go to the earlier (simpler) candidate,
/// NaN scores never win.
pub fn argmin(scores: &[f64]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, &s) in scores.iter().enumerate() {
        if s.is_nan() {
            continue;
        }
        match best {
            Some(b) if scores[b] <= s => {}
            _ => best = Some(i),
        }
    }
    best
}

/// Squared Euclidean distance between two equally long slices.
pub fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Rows of a column-major matrix as row-major `Vec`s (cache-friendly for
/// per-sample loops).
pub fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

/// A column vector of a row of `m`.
pub fn row_vec(m: &DMatrix<f64>, i: usize) -> DVector<f64> {
    m.row(i).transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gram_matches_direct_product() {
        let a = DMatrix::from_fn(2500, 7, |i, j| ((i * 31 + j * 17) % 23) as f64 / 23.0);
        let direct = a.transpose() * &a;
        assert!((gram(&a) - direct).amax() < 1e-9);
        let y = DMatrix::from_fn(2500, 3, |i, j| ((i + 5 * j) % 7) as f64);
        assert!((cross(&a, &y) - a.transpose() * y).amax() < 1e-9);
    }

    #[test]
    fn ridge_recovers_exact_linear_map() {
        let a = DMatrix::from_fn(200, 4, |i, j| {
            ((i * 7 + j * 13) % 19) as f64 / 19.0 + (j == 0) as u8 as f64
        });
        let w = DMatrix::from_row_slice(4, 2, &[1.0, -2.0, 0.5, 3.0, -1.5, 0.25, 2.0, 1.0]);
        let y = &a * &w;
        let fit = ridge_fit(&a, &y, 1e-12).unwrap();
        assert!((fit - w).amax() < 1e-6);
    }

    #[test]
    fn with_bias_appends_ones() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 3.0, 4.0]);
        let b = with_bias(a);
        assert_eq!(
            b,
            DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 1.0, 3.0, 4.0, 1.0])
        );
    }

    #[test]
    fn argmin_prefers_first_and_skips_nan() {
        assert_eq!(argmin(&[f64::NAN, 2.0, 1.0, 1.0]), Some(2));
        assert_eq!(argmin(&[f64::NAN]), None);
    }
}
