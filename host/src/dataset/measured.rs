//! Measured rows (`docs/design.md` §3.1): what a real robot and a tracker
//! give — a few thousand rows with jitter on the pose and some outliers —
//! rather than the exact solves of `tendril generate`.
//!
//! - [`check_rows`] refuses rows no robot can have produced (a negative or
//!   over-limit tension, a quaternion that is not a rotation), naming the
//!   line and column;
//! - [`canonical_quaternions`] makes the tracker's quaternions unit length
//!   with w ≥ 0 (q and −q are one rotation, but a learner sees two inputs);
//! - [`LocalForward`] is a data-driven forward model, tensions → tip
//!   position, fitted locally (weighted quadratic least squares over the k
//!   nearest rows in tension space). The forward map is a smooth function
//!   whatever the sampler, so a row whose measured tip disagrees with its
//!   neighbours' by many noise widths is an outlier of the pose
//!   ([`flag_outliers`]), and the same fit turns a learner's predicted
//!   tensions into the tip a real robot would reach, to judge it against the
//!   noise floor without a trusted model ([`held_out_vs_noise`]).

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::{Dataset, DatasetError, POSE_COLUMNS};
use crate::numerics::kdtree::KdTree;
use crate::robot::Robot;

/// Largest |‖q‖ − 1| accepted in a row: a tracker's quaternions are unit to
/// a few parts in a million; 1 % off is a different quantity (a scaled or
/// truncated column), not noise.
pub const QUATERNION_TOLERANCE: f64 = 0.01;

/// Neighbours of the local fit. A quadratic in the tension space of two
/// pulling tendons has 6 coefficients; 40 rows keep the fit's own variance
/// (≈ σ² · 6/40 of the residual) well under the jitter it is judging.
pub const NEIGHBOURS: usize = 40;

/// Residuals beyond this many robust standard deviations (per axis) mark a
/// row as an outlier: for Gaussian jitter |r|²/σ² is χ² with 3 degrees of
/// freedom, above 5² = 25 with probability 1.4e-5, so an honest row is
/// almost never dropped.
pub const OUTLIER_SIGMAS: f64 = 5.0;

/// A measured tension may sit this far below its tendon's `min_tension`
/// (as a fraction of `max_tension`): a load cell's noise around a
/// pretension the drive keeps. Further below, the rows are another robot's.
pub const BELOW_FLOOR_TOLERANCE: f64 = 0.01;

/// Refuse rows that no robot produced: a tension below zero, below the
/// robot's `min_tension` (by more than [`BELOW_FLOOR_TOLERANCE`] of its
/// range) or above its `max_tension`, a quaternion whose norm is off 1 by more than
/// [`QUATERNION_TOLERANCE`]. The error names the file's line (header = 1)
/// and the column. The tendon count must be the robot's.
pub fn check_rows(data: &Dataset, robot: &Robot, file: &Path) -> Result<(), DatasetError> {
    let row_err = |i: usize, why: String| DatasetError::Row {
        path: file.to_path_buf(),
        line: i + 2,
        why,
    };
    if data.n_tendons != robot.n_tendons() {
        return Err(DatasetError::Header {
            path: file.to_path_buf(),
            why: format!(
                "{} tension columns, but robot {} has {} tendons",
                data.n_tendons,
                robot.name,
                robot.n_tendons()
            ),
        });
    }
    let max = robot.max_tensions();
    let min = robot.min_tensions();
    for i in 0..data.len() {
        for (j, &hi) in max.iter().enumerate() {
            let t = data.tensions[(i, j)];
            if t < 0.0 {
                return Err(row_err(
                    i,
                    format!("column t{j}: tension {t} N is negative (a tendon cannot push)"),
                ));
            }
            if t < min[j] - BELOW_FLOOR_TOLERANCE * hi {
                return Err(row_err(
                    i,
                    format!(
                        "column t{j}: tension {t} N is below the robot's min_tension {} N for \
                         tendon {j}: rows of another robot (robot {})?",
                        min[j], robot.name
                    ),
                ));
            }
            if t > hi {
                return Err(row_err(
                    i,
                    format!(
                        "column t{j}: tension {t} N is above the robot's max_tension {hi} N \
                         for tendon {j}"
                    ),
                ));
            }
        }
        let norm = (3..7)
            .map(|k| data.poses[(i, k)].powi(2))
            .sum::<f64>()
            .sqrt();
        if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
            return Err(row_err(
                i,
                format!(
                    "columns {}: the quaternion's norm is {norm:.6}, not 1 (±{QUATERNION_TOLERANCE}): \
                     not an orientation",
                    POSE_COLUMNS[3..].join(",")
                ),
            ));
        }
    }
    Ok(())
}

/// Scale every quaternion to unit length and flip it to w ≥ 0 (after
/// [`check_rows`]: the norms are near 1).
pub fn canonical_quaternions(data: &mut Dataset) {
    for i in 0..data.len() {
        let norm = (3..7)
            .map(|k| data.poses[(i, k)].powi(2))
            .sum::<f64>()
            .sqrt();
        let sign = if data.poses[(i, 3)] < 0.0 { -1.0 } else { 1.0 };
        for k in 3..7 {
            data.poses[(i, k)] *= sign / norm;
        }
    }
}

/// A data-driven forward model tensions → tip position over a set of rows
/// (module docs). Tensions are scaled by each column's range in the rows so
/// that every tendon counts alike in the neighbour search.
pub struct LocalForward {
    tensions: DMatrix<f64>,
    positions: DMatrix<f64>,
    scale: Vec<f64>,
    k: usize,
    /// The rows in range-scaled tension space; `None` past
    /// [`crate::numerics::kdtree::MAX_DIM`] tendons (then a full scan).
    tree: Option<KdTree>,
}

impl LocalForward {
    /// The model over `data`'s rows (at least 8 rows), on [`NEIGHBOURS`].
    pub fn new(data: &Dataset) -> LocalForward {
        Self::with_neighbours(data, NEIGHBOURS)
    }

    /// The model over `data`'s rows, fitting each point on its `k` nearest.
    pub fn with_neighbours(data: &Dataset, k: usize) -> LocalForward {
        let scale: Vec<f64> = (0..data.n_tendons)
            .map(|j| {
                let c = data.tensions.column(j);
                let r = c.max() - c.min();
                if r > 0.0 {
                    1.0 / r
                } else {
                    1.0
                }
            })
            .collect();
        let scaled = DMatrix::from_fn(data.len(), data.n_tendons, |i, j| {
            data.tensions[(i, j)] * scale[j]
        });
        LocalForward {
            tensions: data.tensions.clone(),
            positions: data.poses.columns(0, 3).into_owned(),
            k: k.min(data.len().saturating_sub(1)).max(1),
            tree: KdTree::build(&scaled).ok(),
            scale,
        }
    }

    /// Rows of the model.
    pub fn len(&self) -> usize {
        self.tensions.nrows()
    }

    /// Whether the model has no row.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The tip position at tensions `t`, fitted on the nearest rows for
    /// which `usable(row)` holds (leave a row out by refusing it).
    pub fn predict(&self, t: &[f64], usable: impl Fn(usize) -> bool) -> [f64; 3] {
        let n_t = self.tensions.ncols();
        let near = self.nearest_usable(t, &usable);
        let k = near.len();
        if k == 0 {
            return [f64::NAN; 3];
        }
        // Tricube-free Gaussian-ish weights would need a bandwidth; equal
        // weights over the k nearest keep the fit's variance known (≈ p/k).
        let n_q = n_t * (n_t + 1) / 2;
        let p = 1 + n_t + n_q;
        let mut a = DMatrix::zeros(k, p);
        let mut y = DMatrix::zeros(k, 3);
        for (r, &(_, i)) in near.iter().enumerate() {
            let dx: Vec<f64> = (0..n_t)
                .map(|j| (self.tensions[(i, j)] - t[j]) * self.scale[j])
                .collect();
            a[(r, 0)] = 1.0;
            let mut c = 1;
            for &v in &dx {
                a[(r, c)] = v;
                c += 1;
            }
            for u in 0..n_t {
                for v in u..n_t {
                    a[(r, c)] = dx[u] * dx[v];
                    c += 1;
                }
            }
            for m in 0..3 {
                y[(r, m)] = self.positions[(i, m)];
            }
        }
        // A small ridge on all but the intercept: the neighbours of an
        // `adjacent` row share the floors of the idle tendons, so those
        // columns are zero and the plain normal equations singular.
        let mut g = a.transpose() * &a;
        let ridge = 1e-9 * (g.trace() / p as f64).max(1e-300);
        for d in 1..p {
            g[(d, d)] += ridge;
        }
        let rhs = a.transpose() * &y;
        match g.cholesky() {
            Some(ch) => {
                let beta = ch.solve(&rhs);
                [beta[(0, 0)], beta[(0, 1)], beta[(0, 2)]]
            }
            None => {
                let mean = y.row_mean();
                [mean[0], mean[1], mean[2]]
            }
        }
    }

    /// The (up to) `k` rows nearest `t` in range-scaled tension space that
    /// `usable` allows, as (a distance, row). From the k-d tree, asking for
    /// a few more than `k` and more again while refused rows leave fewer
    /// than `k` (O(k log n) for the few outliers and the row itself a
    /// leave-one-out fit refuses); without a tree, a scan.
    fn nearest_usable(&self, t: &[f64], usable: &impl Fn(usize) -> bool) -> Vec<(f64, usize)> {
        let n = self.len();
        let Some(tree) = &self.tree else {
            let mut near: Vec<(f64, usize)> = (0..n)
                .filter(|&i| usable(i))
                .map(|i| {
                    let d: f64 = (0..self.scale.len())
                        .map(|j| ((self.tensions[(i, j)] - t[j]) * self.scale[j]).powi(2))
                        .sum();
                    (d, i)
                })
                .collect();
            let k = self.k.min(near.len());
            if k > 0 {
                near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            }
            near.truncate(k);
            return near;
        };
        let q: Vec<f64> = t.iter().zip(&self.scale).map(|(x, s)| x * s).collect();
        let mut ask = self.k + 8;
        loop {
            let near: Vec<(f64, usize)> = tree
                .nearest(&q, ask.min(n))
                .into_iter()
                .filter(|&(_, i)| usable(i))
                .take(self.k)
                .collect();
            if near.len() >= self.k || ask >= n {
                return near;
            }
            ask *= 4;
        }
    }

    /// Leave-one-out residuals (measured − fitted position, m) of every row,
    /// each fitted on its neighbours among the rows `usable` allows.
    pub fn loo_residuals(&self, usable: &[bool]) -> DMatrix<f64> {
        use rayon::prelude::*;
        let rows: Vec<[f64; 3]> = (0..self.len())
            .into_par_iter()
            .map(|i| {
                let t: Vec<f64> = self.tensions.row(i).iter().copied().collect();
                let f = self.predict(&t, |j| j != i && usable[j]);
                [0, 1, 2].map(|m| self.positions[(i, m)] - f[m])
            })
            .collect();
        DMatrix::from_fn(self.len(), 3, |i, m| rows[i][m])
    }
}

/// Robust standard deviation per axis of residual rows (1.4826 × the median
/// absolute value over all three axes); `None` with no finite residual.
fn robust_sigma(res: &DMatrix<f64>, keep: impl Fn(usize) -> bool) -> Option<f64> {
    let mut abs: Vec<f64> = (0..res.nrows())
        .filter(|&i| keep(i))
        .flat_map(|i| (0..3).map(move |m| (i, m)))
        .map(|(i, m)| res[(i, m)].abs())
        .filter(|v| v.is_finite())
        .collect();
    if abs.is_empty() {
        return None;
    }
    let mid = abs.len() / 2;
    abs.select_nth_unstable_by(mid, f64::total_cmp);
    Some(1.4826 * abs[mid])
}

/// What outlier rejection found in a set of rows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OutlierReport {
    /// `flagged[i]`: row `i` (of the rows given) is an outlier.
    #[serde(skip)]
    pub flagged: Vec<bool>,
    /// How many rows were flagged.
    pub count: usize,
    /// Rows examined.
    pub rows: usize,
    /// Robust per-axis standard deviation of the leave-one-out residuals of
    /// the kept rows, mm (jitter and the local fit's own error together).
    pub residual_sigma_mm: f64,
    /// A row is flagged when its residual exceeds this, mm
    /// ([`OUTLIER_SIGMAS`] × `residual_sigma_mm`).
    pub threshold_mm: f64,
    /// The jitter per axis the residuals imply, mm: `residual_sigma_mm`
    /// without the local fit's share (≈ p/k of the variance) — `None` when
    /// the rows cannot tell (see `noise_check`).
    pub noise_sigma_mm: Option<f64>,
    /// The same estimate from fits over [`NEIGHBOURS`] and twice as many
    /// rows, mm. Jitter alone gives the same σ from both; when the wider
    /// fit's is more than [`NOISE_CHECK_RATIO`] times the narrower's, the
    /// local fit's own error (the curvature of the map between rows) is in
    /// the residuals and the noise floor cannot be estimated from them.
    pub noise_check: [f64; 2],
}

/// See [`OutlierReport::noise_check`].
pub const NOISE_CHECK_RATIO: f64 = 1.3;

/// Flag rows whose measured tip disagrees with the local fit of their
/// neighbours by more than [`OUTLIER_SIGMAS`] robust standard deviations.
/// Two passes: the second fits without the first pass's outliers, so a
/// neighbour's wild pose does not hide or frame a row.
pub fn flag_outliers(data: &Dataset) -> OutlierReport {
    let n = data.len();
    let model = LocalForward::new(data);
    let mut usable = vec![true; n];
    let mut flagged = vec![false; n];
    let mut sigma = 0.0;
    for _pass in 0..2 {
        let res = model.loo_residuals(&usable);
        sigma = robust_sigma(&res, |i| usable[i]).unwrap_or(0.0);
        // A floor of 1 nm: noiseless rows would otherwise flag the fit's
        // round-off.
        let limit = OUTLIER_SIGMAS * sigma.max(1e-9);
        for (i, f) in flagged.iter_mut().enumerate() {
            // A NaN residual (no usable neighbour) counts as an outlier.
            let r = res.row(i).norm();
            *f = r.is_nan() || r > limit;
        }
        usable = flagged.iter().map(|f| !f).collect();
    }
    let n_t = data.n_tendons;
    let p = (1 + n_t + n_t * (n_t + 1) / 2) as f64;
    let jitter = |sigma: f64, k: usize| sigma * 1e3 / (1.0 + (p / k as f64).min(1.0)).sqrt();
    let narrow = jitter(sigma, model.k);
    let wide_model = LocalForward::with_neighbours(data, 2 * NEIGHBOURS);
    let wide_sigma = robust_sigma(&wide_model.loo_residuals(&usable), |i| usable[i]).unwrap_or(0.0);
    let wide = jitter(wide_sigma, wide_model.k);
    let consistent = wide <= NOISE_CHECK_RATIO * narrow && wide_model.k > model.k;
    OutlierReport {
        count: flagged.iter().filter(|&&f| f).count(),
        rows: n,
        residual_sigma_mm: sigma * 1e3,
        threshold_mm: OUTLIER_SIGMAS * sigma.max(1e-9) * 1e3,
        noise_sigma_mm: consistent.then_some(narrow),
        noise_check: [narrow, wide],
        flagged,
    }
}

/// [`flag_outliers`] over the training rows of the split
/// ([`super::split_indices`] with `test_fraction` and `seed`) only, so the
/// test rows play no part in what is dropped: the marks over every row of
/// `data` (test rows never marked) for [`super::prepare_excluding`], and
/// the report over the training rows.
pub fn training_outliers(
    data: &Dataset,
    test_fraction: f64,
    seed: u64,
) -> (Vec<bool>, OutlierReport) {
    let (train_idx, _) = super::split_indices(data.len(), test_fraction, seed);
    let report = flag_outliers(&data.rows(&train_idx));
    let mut exclude = vec![false; data.len()];
    for (k, &i) in train_idx.iter().enumerate() {
        exclude[i] = report.flagged[k];
    }
    (exclude, report)
}

/// `data` without the rows that copy an earlier row exactly (tensions and
/// pose, bit for bit), and the file lines (header = 1) of the copies. A
/// tracker never measures one pose twice to the last bit: such rows are
/// copies (a concatenated file), not repeated measurements, and would pass
/// for noiseless repeats and land on both sides of the held-out split.
pub fn drop_copies(data: &Dataset) -> (Dataset, Vec<usize>) {
    use std::collections::HashSet;
    let mut seen: HashSet<Vec<u64>> = HashSet::new();
    let (mut keep, mut copies) = (Vec::new(), Vec::new());
    for i in 0..data.len() {
        let key: Vec<u64> = (data.tensions.row(i).iter())
            .chain(data.poses.row(i).iter())
            .map(|x| x.to_bits())
            .collect();
        if seen.insert(key) {
            keep.push(i);
        } else {
            copies.push(i + 2);
        }
    }
    (data.rows(&keep), copies)
}

/// Jitter per axis estimated from rows measured more than once (the same
/// tension vector, bit for bit): the pooled within-group standard deviation
/// of the positions, m, and its degrees of freedom; `None` with fewer than
/// 10 degrees of freedom.
pub fn noise_from_repeats(data: &Dataset) -> Option<(f64, usize)> {
    use std::collections::HashMap;
    let mut groups: HashMap<Vec<u64>, Vec<usize>> = HashMap::new();
    for i in 0..data.len() {
        let key = data.tensions.row(i).iter().map(|t| t.to_bits()).collect();
        groups.entry(key).or_default().push(i);
    }
    let (mut ss, mut dof) = (0.0, 0usize);
    for rows in groups.values().filter(|g| g.len() > 1) {
        for m in 0..3 {
            let mean = rows.iter().map(|&i| data.poses[(i, m)]).sum::<f64>() / rows.len() as f64;
            ss += rows
                .iter()
                .map(|&i| (data.poses[(i, m)] - mean).powi(2))
                .sum::<f64>();
        }
        dof += 3 * (rows.len() - 1);
    }
    (dof >= 10).then(|| ((ss / dof as f64).sqrt(), dof))
}

/// Where the noise floor came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseSource {
    /// Given by the user (`--noise-mm`).
    Given,
    /// Pooled from rows measured more than once.
    RepeatedRows,
    /// From the local fit's residuals ([`OutlierReport::noise_sigma_mm`]).
    LocalFit,
}

/// A learner's held-out error on measured rows against the noise floor.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NoiseFloorReport {
    /// Jitter per position axis, mm; `None` when it could not be estimated.
    pub noise_sigma_mm: Option<f64>,
    /// Where it came from.
    pub noise_source: NoiseSource,
    /// The RMS 3-D distance between a measured and the true tip, √3 σ, mm.
    /// A learner asked for the measured pose follows the jitter along the
    /// directions the robot can move, so its RMS against measured tips can
    /// fall below this; well above it, the learner is the larger error.
    pub floor_rms_mm: Option<f64>,
    /// Held-out rows judged (their own measured tip not an outlier).
    pub rows: usize,
    /// Held-out rows left out because their measured tip is an outlier.
    pub outlier_rows: usize,
    /// RMS distance between the tip the predicted tensions reach (the local
    /// fit over the training rows) and the measured tip, mm.
    pub held_out_rms_mm: f64,
    /// Its mean, mm.
    pub held_out_mean_mm: f64,
    /// The learner's own share, √max(0, rms² − floor²), mm.
    pub excess_rms_mm: Option<f64>,
}

/// Judge predicted tensions `pred` for the measured `test` rows: the tip
/// they reach according to the local fit over `train` (the rows the learner
/// was fitted on, outliers already out), against the measured tips. Test
/// rows whose own measured tip is an outlier (its residual at its own
/// tensions beyond [`OUTLIER_SIGMAS`] × the training residual σ) are left
/// out and counted.
pub fn held_out_vs_noise(
    train: &Dataset,
    train_outliers: &OutlierReport,
    test: &Dataset,
    pred: &DMatrix<f64>,
    noise: (Option<f64>, NoiseSource),
) -> NoiseFloorReport {
    let model = LocalForward::new(train);
    let limit = train_outliers.threshold_mm * 1e-3;
    let (mut ss, mut sum, mut rows, mut outliers) = (0.0, 0.0, 0usize, 0usize);
    for i in 0..test.len() {
        let p_meas = DVector::from_iterator(3, (0..3).map(|m| test.poses[(i, m)]));
        let own: Vec<f64> = test.tensions.row(i).iter().copied().collect();
        let at_own = DVector::from_row_slice(&model.predict(&own, |_| true));
        if (&p_meas - at_own).norm() > limit {
            outliers += 1;
            continue;
        }
        let t: Vec<f64> = pred.row(i).iter().copied().collect();
        let reached = DVector::from_row_slice(&model.predict(&t, |_| true));
        let e = (&p_meas - reached).norm();
        ss += e * e;
        sum += e;
        rows += 1;
    }
    let (sigma_mm, source) = noise;
    let floor = sigma_mm.map(|s| 3f64.sqrt() * s);
    let rms = (ss / rows.max(1) as f64).sqrt() * 1e3;
    NoiseFloorReport {
        noise_sigma_mm: sigma_mm,
        noise_source: source,
        floor_rms_mm: floor,
        rows,
        outlier_rows: outliers,
        held_out_rms_mm: rms,
        held_out_mean_mm: sum / rows.max(1) as f64 * 1e3,
        excess_rms_mm: floor.map(|f| (rms * rms - f * f).max(0.0).sqrt()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a smooth two-tendon "robot": tip = f(t0, t1), with Gaussian
    /// jitter `sigma` (m) and a few rows moved 5 mm.
    fn rows(n: usize, sigma: f64, outliers: &[usize]) -> Dataset {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut t = DMatrix::zeros(n, 2);
        let mut p = DMatrix::zeros(n, 7);
        for i in 0..n {
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            t[(i, 0)] = 5.0 * a;
            t[(i, 1)] = 5.0 * b;
            let g = |rng: &mut rand_chacha::ChaCha8Rng| {
                let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            };
            p[(i, 0)] = 0.05 * (a - b) + 0.01 * a * a + sigma * g(&mut rng);
            p[(i, 1)] = 0.03 * (a * b).sin() + sigma * g(&mut rng);
            p[(i, 2)] = 0.4 - 0.02 * (a * a + b * b) + sigma * g(&mut rng);
            p[(i, 3)] = 1.0;
        }
        for &i in outliers {
            p[(i, 0)] += 0.005;
        }
        Dataset {
            n_tendons: 2,
            tensions: t,
            poses: p,
        }
    }

    #[test]
    fn outliers_are_flagged_and_the_jitter_estimated() {
        let bad = [3, 50, 400, 777];
        let data = rows(1000, 1.4e-4, &bad);
        let r = flag_outliers(&data);
        let found: Vec<usize> = (0..1000).filter(|&i| r.flagged[i]).collect();
        for i in bad {
            assert!(r.flagged[i], "row {i} not flagged: {found:?}");
        }
        assert!(r.count <= bad.len() + 2, "{found:?}");
        // The true jitter is 0.14 mm per axis.
        let sigma = r.noise_sigma_mm.expect("jitter alone: estimated");
        assert!((sigma - 0.14).abs() < 0.03, "{sigma} ({:?})", r.noise_check);
    }

    #[test]
    fn a_map_the_local_fit_cannot_follow_gives_no_noise_floor() {
        // A quartic the local quadratic cannot follow: its error grows as
        // the fourth power of the neighbourhood's radius, so the wider fit
        // misses far more than the narrow one; jitter alone would not.
        let mut data = rows(1000, 1.4e-4, &[]);
        for i in 0..data.len() {
            let t = data.tensions[(i, 0)] - 2.5;
            data.poses[(i, 0)] += 0.2 * t.powi(4);
        }
        let r = flag_outliers(&data);
        assert_eq!(r.noise_sigma_mm, None, "{:?}", r.noise_check);
        assert!(r.noise_check[1] > NOISE_CHECK_RATIO * r.noise_check[0]);
    }

    #[test]
    fn exact_copies_are_dropped_and_named_by_line() {
        let data = rows(20, 1e-4, &[]);
        let doubled = data.rows(&(0..20).chain([3, 7]).collect::<Vec<_>>());
        let (kept, copies) = drop_copies(&doubled);
        assert_eq!(kept.len(), 20);
        assert_eq!(copies, vec![22, 23]);
    }

    #[test]
    fn repeated_rows_give_the_jitter() {
        // 100 tension vectors, each measured four times with 0.2 mm jitter.
        let clean = rows(100, 0.0, &[]);
        let noise = rows(400, 2e-4, &[]);
        let noiseless = rows(400, 0.0, &[]);
        let mut data = Dataset {
            n_tendons: 2,
            tensions: DMatrix::from_fn(400, 2, |i, j| clean.tensions[(i / 4, j)]),
            poses: DMatrix::from_fn(400, 7, |i, j| clean.poses[(i / 4, j)]),
        };
        for i in 0..400 {
            for m in 0..3 {
                data.poses[(i, m)] += noise.poses[(i, m)] - noiseless.poses[(i, m)];
            }
        }
        let (s, dof) = noise_from_repeats(&data).unwrap();
        assert_eq!(dof, 3 * 300);
        assert!((s - 2e-4).abs() < 2e-5, "{s}");
        assert!(noise_from_repeats(&rows(100, 1e-4, &[])).is_none());
    }

    #[test]
    fn impossible_rows_are_refused_naming_line_and_column() {
        let robot = Robot::load(Path::new(crate::robot::DEFAULT_ROBOT)).unwrap();
        let mut data = Dataset {
            n_tendons: 4,
            tensions: DMatrix::from_element(3, 4, 1.0),
            poses: DMatrix::from_fn(3, 7, |_, j| if j == 3 { 1.0 } else { 0.0 }),
        };
        let f = Path::new("m.csv");
        check_rows(&data, &robot, f).unwrap();
        data.tensions[(1, 2)] = -0.5;
        let e = check_rows(&data, &robot, f).unwrap_err().to_string();
        assert!(
            e.contains("line 3") && e.contains("t2") && e.contains("negative"),
            "{e}"
        );
        data.tensions[(1, 2)] = 1e6;
        let e = check_rows(&data, &robot, f).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("max_tension"), "{e}");
        data.tensions[(1, 2)] = 1.0;
        data.poses[(2, 3)] = 0.5;
        let e = check_rows(&data, &robot, f).unwrap_err().to_string();
        assert!(e.contains("line 4") && e.contains("qw,qx,qy,qz"), "{e}");
        data.poses[(2, 3)] = -1.0005;
        check_rows(&data, &robot, f).unwrap();
        canonical_quaternions(&mut data);
        assert_eq!(data.poses[(2, 3)], 1.0);
    }
}
