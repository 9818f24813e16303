//! Train / validation / test splits and min–max normalisation. Ranges always
//! come from the training rows only, so the test split never leaks into what
//! a learner sees.

use nalgebra::DMatrix;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::Dataset;

/// Default held-out test fraction (the paper's 97 % / 3 %).
pub const TEST_FRACTION: f64 = 0.03;
/// Default validation fraction, carved from the training rows.
pub const VALID_FRACTION: f64 = 0.1;
/// Default split seed.
pub const SPLIT_SEED: u64 = 1;
/// Largest held-out test fraction: above it a learner would be fitted on
/// fewer rows than it is judged on.
pub const MAX_TEST_FRACTION: f64 = 0.5;

/// The one check of a `--test-fraction` (`generate` records it, `train` and
/// `compare` split by it): in (0, [`MAX_TEST_FRACTION`]]. Zero would leave
/// no test rows to judge a learner on.
pub fn check_test_fraction(t: f64) -> Result<(), String> {
    if t > 0.0 && t <= MAX_TEST_FRACTION {
        Ok(())
    } else {
        Err(format!(
            "--test-fraction must be in (0, {MAX_TEST_FRACTION}], got {t}"
        ))
    }
}

/// The one check of a `--valid-fraction` (the validation rows carved from
/// the training rows): in [0, [`MAX_TEST_FRACTION`]].
pub fn check_valid_fraction(v: f64) -> Result<(), String> {
    if (0.0..=MAX_TEST_FRACTION).contains(&v) {
        Ok(())
    } else {
        Err(format!(
            "--valid-fraction must be in [0, {MAX_TEST_FRACTION}], got {v}"
        ))
    }
}

/// Seeded shuffle of `0..n` into (train, test), `round(n · test_fraction)`
/// test rows (at least one when n ≥ 2 and the fraction is positive).
/// Both lists come back sorted, so row order within a split is the file's.
pub fn split_indices(n: usize, test_fraction: f64, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let n_test = test_count(n, test_fraction);
    let mut test = idx[..n_test].to_vec();
    let mut train = idx[n_test..].to_vec();
    train.sort_unstable();
    test.sort_unstable();
    (train, test)
}

/// Rows of `n` that go to the test split.
fn test_count(n: usize, test_fraction: f64) -> usize {
    let n_test = (n as f64 * test_fraction.clamp(0.0, 1.0)).round() as usize;
    if test_fraction > 0.0 && n >= 2 {
        n_test.clamp(1, n - 1)
    } else {
        n_test
    }
}

/// `mask[i]` says whether [`split_indices`] puts row `i` in the test split.
/// The same permutation (a shuffle's swaps do not depend on the element
/// type) at 5 bytes per row instead of 16, for datasets streamed to disk.
pub fn test_mask(n: usize, test_fraction: f64, seed: u64) -> Vec<bool> {
    let n_test = test_count(n, test_fraction);
    let mut mask = vec![false; n];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    match u32::try_from(n) {
        Ok(_) => {
            let mut idx: Vec<u32> = (0..n as u32).collect();
            idx.shuffle(&mut rng);
            for &i in &idx[..n_test] {
                mask[i as usize] = true;
            }
        }
        Err(_) => {
            let mut idx: Vec<usize> = (0..n).collect();
            idx.shuffle(&mut rng);
            for &i in &idx[..n_test] {
                mask[i] = true;
            }
        }
    }
    mask
}

/// Per-column min–max normalisation to [0, 1].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MinMax {
    /// Column minima.
    pub lo: Vec<f64>,
    /// Column maxima (a constant column gets `lo + 1`, so it maps to 0).
    pub hi: Vec<f64>,
}

impl MinMax {
    /// Ranges of the columns of `m`.
    pub fn fit(m: &DMatrix<f64>) -> MinMax {
        let (lo, hi) = m.column_iter().map(|c| (c.min(), c.max())).unzip();
        MinMax::from_bounds(lo, hi)
    }

    /// Ranges from per-column minima and maxima found elsewhere (a streamed
    /// pass), with the same widening of constant columns as [`MinMax::fit`].
    pub fn from_bounds(lo: Vec<f64>, mut hi: Vec<f64>) -> MinMax {
        for (a, b) in lo.iter().zip(hi.iter_mut()) {
            if *b - *a <= f64::EPSILON * a.abs().max(1.0) {
                *b = *a + 1.0;
            }
        }
        MinMax { lo, hi }
    }

    /// (x − lo) / (hi − lo), column by column.
    pub fn normalise(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
            (m[(i, j)] - self.lo[j]) / (self.hi[j] - self.lo[j])
        })
    }

    /// lo + x (hi − lo), column by column.
    pub fn denormalise(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
            self.lo[j] + m[(i, j)] * (self.hi[j] - self.lo[j])
        })
    }
}

/// Normalisation ranges of a training split: poses in, tensions out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ranges {
    /// Pose ranges (px, py, pz, qw, qx, qy, qz).
    pub poses: MinMax,
    /// Tension ranges.
    pub tensions: MinMax,
}

/// Everything a learner needs, normalised with the training split's ranges.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Training rows (validation rows included), physical units.
    pub train: Dataset,
    /// Held-out test rows, physical units.
    pub test: Dataset,
    /// Input (pose) ranges from the training rows.
    pub x_range: MinMax,
    /// Output (tension) ranges from the training rows.
    pub y_range: MinMax,
    /// Normalised training inputs, validation rows excluded.
    pub train_x: DMatrix<f64>,
    /// Normalised training targets, validation rows excluded.
    pub train_y: DMatrix<f64>,
    /// Normalised validation inputs (carved from the training rows).
    pub valid_x: DMatrix<f64>,
    /// Normalised validation targets.
    pub valid_y: DMatrix<f64>,
    /// Normalised test inputs.
    pub test_x: DMatrix<f64>,
    /// Normalised test targets.
    pub test_y: DMatrix<f64>,
    /// The dataset's row of each `train_x` row.
    pub fit_rows: Vec<usize>,
    /// The dataset's row of each `valid_x` row.
    pub valid_rows: Vec<usize>,
}

impl Prepared {
    /// The ranges as stored in sidecars and weight files.
    pub fn ranges(&self) -> Ranges {
        Ranges {
            poses: self.x_range.clone(),
            tensions: self.y_range.clone(),
        }
    }

    /// The same split normalised with other ranges (a trained net's, which
    /// a fine-tune keeps): inputs `x_lo..x_hi`, outputs `y_lo..y_hi`. Rows
    /// outside them fall outside [0, 1], as they would for the net.
    pub fn in_ranges(self, x_lo: &[f64], x_hi: &[f64], y_lo: &[f64], y_hi: &[f64]) -> Prepared {
        let x_range = MinMax::from_bounds(x_lo.to_vec(), x_hi.to_vec());
        let y_range = MinMax::from_bounds(y_lo.to_vec(), y_hi.to_vec());
        let x = |m: &DMatrix<f64>| x_range.normalise(&self.x_range.denormalise(m));
        let y = |m: &DMatrix<f64>| y_range.normalise(&self.y_range.denormalise(m));
        Prepared {
            train_x: x(&self.train_x),
            train_y: y(&self.train_y),
            valid_x: x(&self.valid_x),
            valid_y: y(&self.valid_y),
            test_x: x(&self.test_x),
            test_y: y(&self.test_y),
            x_range,
            y_range,
            ..self
        }
    }
}

/// Split `data` into train / test (`test_fraction`), carve a validation split
/// (`valid_fraction` of the training rows) and normalise everything with the
/// ranges of the training rows.
pub fn prepare(data: &Dataset, test_fraction: f64, valid_fraction: f64, seed: u64) -> Prepared {
    prepare_excluding(data, test_fraction, valid_fraction, seed, &[])
}

/// [`prepare`], with the rows `exclude[i]` marks (outliers of measured data,
/// [`super::measured`]) left out of the training and validation rows. The
/// test split is [`split_indices`]'s whatever is excluded, so `tendril
/// evaluate --rows test` finds the same rows from the seed and fraction
/// alone; an `exclude` shorter than the data excludes nothing past its end.
pub fn prepare_excluding(
    data: &Dataset,
    test_fraction: f64,
    valid_fraction: f64,
    seed: u64,
    exclude: &[bool],
) -> Prepared {
    let (mut train_idx, test_idx) = split_indices(data.len(), test_fraction, seed);
    train_idx.retain(|&i| !exclude.get(i).copied().unwrap_or(false));
    let train = data.rows(&train_idx);
    let test = data.rows(&test_idx);
    let x_range = MinMax::fit(&train.poses);
    let y_range = MinMax::fit(&train.tensions);
    let (fit_idx, valid_idx) =
        split_indices(train.len(), valid_fraction, seed.wrapping_add(0x5eed));
    let fit = train.rows(&fit_idx);
    let valid = train.rows(&valid_idx);
    Prepared {
        train_x: x_range.normalise(&fit.poses),
        train_y: y_range.normalise(&fit.tensions),
        valid_x: x_range.normalise(&valid.poses),
        valid_y: y_range.normalise(&valid.tensions),
        test_x: x_range.normalise(&test.poses),
        test_y: y_range.normalise(&test.tensions),
        fit_rows: fit_idx.iter().map(|&k| train_idx[k]).collect(),
        valid_rows: valid_idx.iter().map(|&k| train_idx[k]).collect(),
        train,
        test,
        x_range,
        y_range,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_a_seeded_partition() {
        let (train, test) = split_indices(1000, 0.03, 7);
        assert_eq!(test.len(), 30);
        assert_eq!(train.len(), 970);
        let mut all: Vec<_> = train.iter().chain(&test).copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..1000).collect::<Vec<_>>());
        assert_eq!(split_indices(1000, 0.03, 7), (train.clone(), test.clone()));
        assert_ne!(split_indices(1000, 0.03, 8).1, test);
    }

    #[test]
    fn test_mask_marks_exactly_the_test_split() {
        for (n, fraction, seed) in [(1000, 0.03, 7), (2, 0.5, 1), (1, 0.03, 1), (577, 0.2, 9)] {
            let (_, test) = split_indices(n, fraction, seed);
            let mask = test_mask(n, fraction, seed);
            let from_mask: Vec<usize> = (0..n).filter(|&i| mask[i]).collect();
            assert_eq!(from_mask, test, "n = {n}");
        }
    }

    #[test]
    fn normalisation_round_trips_and_maps_training_range_to_unit_interval() {
        let m = DMatrix::from_row_slice(3, 2, &[1.0, 5.0, 3.0, 5.0, 2.0, 5.0]);
        let r = MinMax::fit(&m);
        let n = r.normalise(&m);
        assert_eq!(n.column(0).min(), 0.0);
        assert_eq!(n.column(0).max(), 1.0);
        assert!(
            n.column(1).iter().all(|&x| x == 0.0),
            "constant column maps to 0"
        );
        assert!((r.denormalise(&n) - m).abs().max() < 1e-15);
    }

    #[test]
    fn prepare_takes_ranges_from_training_rows_only() {
        let n = 200;
        let t = DMatrix::from_fn(n, 2, |i, j| (i * (j + 1)) as f64);
        let p = DMatrix::from_fn(n, 7, |i, j| (i as f64) * 0.01 + j as f64);
        let data = Dataset {
            n_tendons: 2,
            tensions: t,
            poses: p,
        };
        let prep = prepare(&data, 0.1, 0.1, 3);
        assert_eq!(prep.test.len(), 20);
        assert_eq!(prep.train_x.nrows() + prep.valid_x.nrows(), 180);
        assert_eq!(MinMax::fit(&prep.train.poses), prep.x_range);
        // Training-row inputs sit in [0, 1].
        assert!(prep.train_x.iter().all(|&x| (0.0..=1.0).contains(&x)));
    }
}
