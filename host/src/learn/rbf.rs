//! Radial-basis-function network (Moody & Darken 1989): Gaussian units at
//! centres found by k-means, a common width, and a linear output layer
//! (plus bias) fitted by ridge least squares.
//!
//! Width σ = factor × the mean distance from each centre to its nearest other
//! centre; the number of centres, the factor and the ridge are chosen on the
//! validation split.

use nalgebra::DMatrix;
use rand::seq::index::sample;
use rand::Rng;
use rayon::prelude::*;

use super::linalg::{
    check_splits, cross, dist2, gram, ridge_solve, rmse, rng, row_major, sub_seed,
};
use super::{LearnError, Learner, Split};

/// Rows used by k-means (a seeded subsample above this): centres need the
/// input distribution, not every sample.
const KMEANS_ROWS: usize = 6000;
/// Lloyd iterations of k-means.
const KMEANS_ITERS: usize = 15;

/// k-means (Lloyd) from k-means++ seeds; returns `k × d` centres row-major.
/// Empty clusters keep their previous centre.
pub fn kmeans(x: &DMatrix<f64>, k: usize, seed: u64) -> Vec<f64> {
    let n = x.nrows();
    let d = x.ncols();
    let mut r = rng(seed);
    let rows: Vec<usize> = if n > KMEANS_ROWS {
        let mut v = sample(&mut r, n, KMEANS_ROWS).into_vec();
        v.sort_unstable();
        v
    } else {
        (0..n).collect()
    };
    let pts: Vec<f64> = rows
        .iter()
        .flat_map(|&i| (0..d).map(move |j| x[(i, j)]))
        .collect();
    let np = rows.len();
    let k = k.min(np);
    let mut c = kmeans_plus_plus(&pts, d, k, &mut r);
    for _ in 0..KMEANS_ITERS {
        let assign: Vec<usize> = (0..np)
            .into_par_iter()
            .map(|i| nearest(&pts[i * d..(i + 1) * d], &c, d))
            .collect();
        let mut sum = vec![0.0; k * d];
        let mut cnt = vec![0usize; k];
        for (i, &a) in assign.iter().enumerate() {
            cnt[a] += 1;
            for j in 0..d {
                sum[a * d + j] += pts[i * d + j];
            }
        }
        for a in 0..k {
            if cnt[a] > 0 {
                for j in 0..d {
                    c[a * d + j] = sum[a * d + j] / cnt[a] as f64;
                }
            }
        }
    }
    c
}

/// k-means++ seeding (Arthur & Vassilvitskii 2007): each next centre drawn
/// with probability ∝ squared distance to the nearest centre so far, which
/// spreads the centres over the data (random seeding leaves clumps and holes).
fn kmeans_plus_plus(pts: &[f64], d: usize, k: usize, r: &mut impl Rng) -> Vec<f64> {
    let np = pts.len() / d;
    let mut c = Vec::with_capacity(k * d);
    let first = r.random_range(0..np);
    c.extend_from_slice(&pts[first * d..(first + 1) * d]);
    let mut d2: Vec<f64> = pts.par_chunks(d).map(|p| dist2(p, &c[..d])).collect();
    while c.len() < k * d {
        let total: f64 = d2.iter().sum();
        let pick = if total > 0.0 {
            let mut t = r.random::<f64>() * total;
            let mut pick = np - 1;
            for (i, v) in d2.iter().enumerate() {
                if t < *v {
                    pick = i;
                    break;
                }
                t -= v;
            }
            pick
        } else {
            // Fewer distinct points than centres: repeat one.
            r.random_range(0..np)
        };
        let new = pts[pick * d..(pick + 1) * d].to_vec();
        d2.par_iter_mut()
            .zip(pts.par_chunks(d))
            .for_each(|(v, p)| *v = v.min(dist2(p, &new)));
        c.extend_from_slice(&new);
    }
    c
}

fn nearest(p: &[f64], c: &[f64], d: usize) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (a, ca) in c.chunks_exact(d).enumerate() {
        let e = dist2(p, ca);
        if e < best.0 {
            best = (e, a);
        }
    }
    best.1
}

/// Mean distance from each centre to its nearest other centre.
fn mean_spacing(c: &[f64], d: usize) -> f64 {
    let k = c.len() / d;
    if k < 2 {
        return 1.0;
    }
    let s: f64 = (0..k)
        .map(|a| {
            (0..k)
                .filter(|&b| b != a)
                .map(|b| dist2(&c[a * d..(a + 1) * d], &c[b * d..(b + 1) * d]))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .sum();
    (s / k as f64).max(1e-12)
}

/// Gaussian activations `exp(−|x − c|² / 2σ²)` with a trailing bias column.
fn features(x: &DMatrix<f64>, c: &[f64], sigma: f64) -> DMatrix<f64> {
    let d = x.ncols();
    let k = c.len() / d;
    let xr = row_major(x);
    let inv = 1.0 / (2.0 * sigma * sigma);
    let rows: Vec<Vec<f64>> = xr
        .par_chunks(d.max(1))
        .map(|p| {
            c.chunks_exact(d)
                .map(|ca| (-dist2(p, ca) * inv).exp())
                .collect()
        })
        .collect();
    DMatrix::from_fn(
        x.nrows(),
        k + 1,
        |i, j| if j == k { 1.0 } else { rows[i][j] },
    )
}

/// RBF network regressor.
pub struct Rbf {
    /// Candidate numbers of centres.
    pub centres: Vec<usize>,
    /// Candidate width factors (× mean nearest-centre spacing).
    pub width_factors: Vec<f64>,
    /// Candidate ridge factors (relative to the Gram matrix's mean diagonal).
    pub ridges: Vec<f64>,
    c: Vec<f64>,
    d: usize,
    sigma: f64,
    out: DMatrix<f64>,
    chosen: (usize, f64, f64),
}

impl Default for Rbf {
    /// The grid used by `tendril compare`: centres {100, 200, 400, 800} ×
    /// width factors {0.5, 1, 2, 4} × ridges {1e-10, 1e-7, 1e-4}
    /// (16 Gram matrices, 48 solves).
    fn default() -> Self {
        Rbf::with_grid(
            vec![100, 200, 400, 800],
            vec![0.5, 1.0, 2.0, 4.0],
            vec![1e-10, 1e-7, 1e-4],
        )
    }
}

impl Rbf {
    /// An RBF network choosing centres, width and ridge from the given candidates.
    pub fn with_grid(centres: Vec<usize>, width_factors: Vec<f64>, ridges: Vec<f64>) -> Rbf {
        Rbf {
            centres,
            width_factors,
            ridges,
            c: Vec::new(),
            d: 0,
            sigma: 1.0,
            out: DMatrix::zeros(0, 0),
            chosen: (0, 0.0, 0.0),
        }
    }

    /// An RBF network with fixed hyper-parameters.
    pub fn fixed(centres: usize, width_factor: f64, ridge: f64) -> Rbf {
        Rbf::with_grid(vec![centres], vec![width_factor], vec![ridge])
    }

    /// Chosen (centres, width factor, ridge).
    pub fn chosen(&self) -> (usize, f64, f64) {
        self.chosen
    }

    /// The common width σ of the chosen model (normalised input units).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }
}

impl Learner for Rbf {
    fn name(&self) -> &str {
        "RBF network"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        check_splits(train, valid)?;
        if self.centres.is_empty()
            || self.centres.contains(&0)
            || self.width_factors.is_empty()
            || self.ridges.is_empty()
            || self
                .width_factors
                .iter()
                .any(|f| !f.is_finite() || *f <= 0.0)
            || self.ridges.iter().any(|r| !r.is_finite() || *r < 0.0)
        {
            return Err(LearnError::BadParameter {
                name: "RBF grid",
                why: "need centres ≥ 1, width factors > 0, ridges ≥ 0".into(),
            });
        }
        let d = train.x.ncols();
        // (valid RMSE, centres, width factor, ridge, centres, σ, output weights)
        type Best = (f64, usize, f64, f64, Vec<f64>, f64, DMatrix<f64>);
        let mut best: Option<Best> = None;
        for (ci, &k) in self.centres.iter().enumerate() {
            let c = kmeans(train.x, k, sub_seed(seed, ci as u64));
            let spacing = mean_spacing(&c, d);
            for &wf in &self.width_factors {
                let sigma = wf * spacing;
                let f = features(train.x, &c, sigma);
                let fv = features(valid.x, &c, sigma);
                let g = gram(&f);
                let cr = cross(&f, train.y);
                let fits: Vec<Option<(f64, DMatrix<f64>)>> = self
                    .ridges
                    .par_iter()
                    .map(|&r| {
                        let w = ridge_solve(&g, &cr, r).ok()?;
                        Some((rmse(&(&fv * &w), valid.y), w))
                    })
                    .collect();
                for (ri, fit) in fits.into_iter().enumerate() {
                    if let Some((score, w)) = fit {
                        if !score.is_nan() && best.as_ref().is_none_or(|b| score < b.0) {
                            best = Some((
                                score,
                                c.len() / d,
                                wf,
                                self.ridges[ri],
                                c.clone(),
                                sigma,
                                w,
                            ));
                        }
                    }
                }
            }
        }
        let (score, k, wf, r, c, sigma, w) = best
            .ok_or_else(|| LearnError::Numerical("every RBF candidate failed to solve".into()))?;
        self.c = c;
        self.d = d;
        self.sigma = sigma;
        self.out = w;
        self.chosen = (k, wf, r);
        log::debug!(
            "RBF: centres={k} width factor={wf} (σ={sigma:.4}) ridge={r:e} (valid RMSE {score:.5})"
        );
        Ok(())
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        if self.d == 0 || x.ncols() != self.d {
            return DMatrix::from_element(x.nrows(), self.out.ncols(), f64::NAN);
        }
        features(x, &self.c, self.sigma) * &self.out
    }

    fn parameter_count(&self) -> usize {
        self.c.len() + 1 + self.out.len()
    }

    fn describe(&self) -> String {
        let (k, wf, r) = self.chosen;
        format!(
            "centres={k}, width={wf}×spacing (σ={:.4}), ridge={r:e}",
            self.sigma
        )
    }
}
