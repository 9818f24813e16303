//! The candidate phase: a pool of candidate hidden units, each fed by every
//! column of the cached feature matrix (bias, inputs, installed hidden units),
//! trained by Quickprop ascent on its objective, independently and in parallel.
//!
//! Objectives:
//! - [`Objective::Covariance`] — Fahlman & Lebiere 1990:
//!   S = Σ_o |Σ_p (V_p − V̄)(E_po − Ē_o)| / Σ_po (E_po − Ē_o)², normalised by the
//!   summed squared error as in Fahlman's `cascor1.c`; the gradient uses the sign
//!   of each correlation.
//! - [`Objective::Cascade2`] — the error-minimising objective of Cascade 2
//!   (Prechelt 1997): the candidate's own output weights predict the residual
//!   and it is scored by the squared error it removes. Here those output weights
//!   sit at their least-squares optimum given every current output feature
//!   (variable projection), so the score is exactly the fraction of the residual
//!   SSE that installing the unit and re-solving linear outputs would remove:
//!   S₂ = Σ_o (E⊥_oᵀ V)² / (|P⊥V|² · |E⊥|²), P⊥ the projector off span(features).

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::net::{hidden_activation, hidden_prime};
use super::quickprop::{Patience, Quickprop, QuickpropParams};

/// What a candidate unit maximises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Objective {
    /// Fahlman's covariance with the residual error.
    Covariance,
    /// Cascade 2's error reduction (Prechelt 1997).
    Cascade2,
}

impl std::fmt::Display for Objective {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Objective::Covariance => "covariance",
            Objective::Cascade2 => "cascade2",
        })
    }
}

/// Projection off the span of the feature columns, through the Cholesky
/// factor of their (slightly regularised) Gram matrix: P v = F G⁻¹ Fᵀ v.
pub struct Projector {
    chol: Cholesky<f64, Dyn>,
}

impl Projector {
    /// Factor `gram` = FᵀF; `None` if it is not positive definite even regularised.
    pub fn new(gram: &DMatrix<f64>) -> Option<Projector> {
        let m = gram.nrows();
        let scale = (gram.trace() / m.max(1) as f64).max(f64::MIN_POSITIVE);
        let mut g = gram.clone();
        for i in 0..m {
            g[(i, i)] += 1e-11 * scale;
        }
        Cholesky::new(g).map(|chol| Projector { chol })
    }

    /// G⁻¹ z.
    pub fn solve(&self, z: &DVector<f64>) -> DVector<f64> {
        self.chol.solve(z)
    }

    /// Residual errors projected off span(F): E − F G⁻¹ FᵀE.
    pub fn project_off(&self, f: &DMatrix<f64>, e: &DMatrix<f64>) -> DMatrix<f64> {
        let fte = f.tr_mul(e);
        let coef = self.chol.solve(&fte);
        e - f * coef
    }
}

/// What a candidate is trained against in one candidate phase.
pub struct Context<'a> {
    /// Cached features, `N × m` (bias, inputs, installed hidden units).
    pub f: &'a DMatrix<f64>,
    /// Residual errors centred per output, `N × O` (covariance objective).
    pub e_centred: &'a DMatrix<f64>,
    /// Σ of `e_centred`², the covariance normaliser.
    pub sse_centred: f64,
    /// Residual errors projected off span(F), `N × O` (Cascade 2 objective).
    pub e_perp: &'a DMatrix<f64>,
    /// Σ of `e_perp`², the Cascade 2 normaliser.
    pub sse_perp: f64,
    /// Projector off span(F).
    pub proj: &'a Projector,
    /// Quickprop settings (ε before scaling by patterns × fan-in).
    pub params: QuickpropParams,
    /// Added to the sigmoid derivative where it scales an error (Fahlman's offset).
    pub prime_offset: f64,
    /// Pattern count in the ε scaling ε / (patterns × fan-in): the full training
    /// set even when candidates see a subset, so the step does not change with it.
    pub patterns: usize,
}

/// A trained candidate.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Incoming weights over the feature columns.
    pub weights: Vec<f64>,
    /// Objective it was trained on.
    pub objective: Objective,
    /// Best value of its own objective.
    pub score: f64,
    /// Fraction of the projected residual SSE removed if installed (common currency across objectives).
    pub reduction: f64,
    /// Epochs trained.
    pub epochs: usize,
    /// Its activations on the training patterns.
    pub values: DVector<f64>,
}

/// Seed of candidate `cand` for hidden unit `unit`: a fixed mix of the three,
/// so results do not depend on how rayon schedules the pool.
pub fn candidate_seed(seed: u64, unit: usize, cand: usize) -> u64 {
    let mut z = seed
        ^ (unit as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (cand as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    // splitmix64 finaliser
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Objective value and its gradient with respect to the weights.
/// `buf_*` are scratch of length N.
pub fn objective_and_gradient(
    ctx: &Context<'_>,
    objective: Objective,
    w: &DVector<f64>,
    values: &mut DVector<f64>,
    g_v: &mut DVector<f64>,
    grad: &mut DVector<f64>,
) -> f64 {
    let f = ctx.f;
    values.gemv(1.0, f, w, 0.0);
    values.apply(|v| *v = hidden_activation(*v));
    let score = match objective {
        Objective::Covariance => {
            // C_o = Σ_p V_p Ẽ_po (Ẽ centred, so V need not be).
            let c = ctx.e_centred.tr_mul(values);
            let sign = c.map(|x| if x < 0.0 { -1.0 } else { 1.0 });
            g_v.gemv(1.0 / ctx.sse_centred, ctx.e_centred, &sign, 0.0);
            c.iter().map(|x| x.abs()).sum::<f64>() / ctx.sse_centred
        }
        Objective::Cascade2 => {
            let Cascade2Terms { c, u, q } = cascade2_terms(ctx, values);
            let c2 = c.norm_squared();
            // V⊥ = V − F u
            let mut v_perp = values.clone();
            v_perp.gemv(-1.0, f, &u, 1.0);
            g_v.gemv(2.0 / (q * ctx.sse_perp), ctx.e_perp, &c, 0.0);
            g_v.axpy(-2.0 * c2 / (q * q * ctx.sse_perp), &v_perp, 1.0);
            c2 / (q * ctx.sse_perp)
        }
    };
    let off = ctx.prime_offset;
    g_v.zip_apply(values, |g, v| *g *= hidden_prime(v) + off);
    grad.gemv_tr(1.0, f, g_v, 0.0);
    score
}

/// Fraction of the projected residual SSE removed by installing a unit with
/// activations `values` and re-solving the (linear) outputs.
pub fn error_reduction(ctx: &Context<'_>, values: &DVector<f64>) -> f64 {
    let Cascade2Terms { c, q, .. } = cascade2_terms(ctx, values);
    (c.norm_squared() / (q * ctx.sse_perp)).min(1.0)
}

/// The pieces of the Cascade-2 score ‖E⊥ᵀV‖² / (q · SSE⊥) for activations V.
struct Cascade2Terms {
    /// C = E⊥ᵀ V, the new unit's covariance with the projected residual.
    c: DVector<f64>,
    /// u = (FᵀF)⁻¹ Fᵀ V: V's least-squares fit by the existing features.
    u: DVector<f64>,
    /// q = ‖V − F u‖², kept away from zero for a unit the features already span.
    q: f64,
}

fn cascade2_terms(ctx: &Context<'_>, values: &DVector<f64>) -> Cascade2Terms {
    let c = ctx.e_perp.tr_mul(values);
    let z = ctx.f.tr_mul(values);
    let u = ctx.proj.solve(&z);
    let vv = values.norm_squared();
    let q = (vv - z.dot(&u)).max(0.0) + 1e-12 * vv + f64::MIN_POSITIVE;
    Cascade2Terms { c, u, q }
}

/// Train one candidate from its seed.
pub fn train_candidate(ctx: &Context<'_>, objective: Objective, seed: u64) -> Candidate {
    let (n, m) = ctx.f.shape();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut w = DVector::from_fn(m, |_, _| rng.random_range(-1.0..=1.0));
    let p = ctx.params;
    let mut qp = Quickprop::new(
        m,
        p.epsilon / (ctx.patterns.max(1) as f64 * m as f64),
        p.mu,
        p.decay,
    );
    let mut patience = Patience::new(p.patience, p.threshold, false);
    let mut values = DVector::zeros(n);
    let mut g_v = DVector::zeros(n);
    let mut grad = DVector::zeros(m);
    let mut best_w = w.clone();
    let mut best = f64::NEG_INFINITY;
    let mut epochs = 0;
    for epoch in 0..p.max_epochs.max(1) {
        epochs = epoch + 1;
        let s = objective_and_gradient(ctx, objective, &w, &mut values, &mut g_v, &mut grad);
        if !s.is_finite() {
            break;
        }
        if s > best {
            best = s;
            best_w.copy_from(&w);
        }
        if patience.stagnant(epoch, s) {
            break;
        }
        // Ascent: Quickprop minimises, so hand it −∂S/∂w.
        grad.neg_mut();
        qp.step(w.as_mut_slice(), grad.as_slice());
    }
    values.gemv(1.0, ctx.f, &best_w, 0.0);
    values.apply(|v| *v = hidden_activation(*v));
    let reduction = error_reduction(ctx, &values);
    Candidate {
        weights: best_w.as_slice().to_vec(),
        objective,
        score: best,
        reduction,
        epochs,
        values,
    }
}

/// Train a pool in parallel; candidate i uses `objectives[i % len]` and a seed
/// from (seed, unit, i). The result is ordered by candidate index and is the
/// same for any number of threads.
pub fn train_pool(
    ctx: &Context<'_>,
    objectives: &[Objective],
    pool: usize,
    seed: u64,
    unit: usize,
) -> Vec<Candidate> {
    (0..pool)
        .into_par_iter()
        .map(|i| {
            train_candidate(
                ctx,
                objectives[i % objectives.len()],
                candidate_seed(seed, unit, i),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup(n: usize, m: usize, o: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut f = DMatrix::from_fn(n, m, |_, _| rng.random_range(-1.0..1.0));
        f.column_mut(0).fill(1.0);
        let e = DMatrix::from_fn(n, o, |r, c| {
            (f[(r, 1)] * (c as f64 + 1.0)).sin() + 0.3 * rng.random_range(-1.0..1.0)
        });
        (f, e)
    }

    fn check_gradient(objective: Objective) {
        let (f, e) = setup(60, 5, 3, 7);
        let gram = f.tr_mul(&f);
        let proj = Projector::new(&gram).unwrap();
        let mean = e.row_mean();
        let ec = DMatrix::from_fn(e.nrows(), e.ncols(), |r, c| e[(r, c)] - mean[c]);
        let ep = proj.project_off(&f, &e);
        let ctx = Context {
            f: &f,
            e_centred: &ec,
            sse_centred: ec.norm_squared(),
            e_perp: &ep,
            sse_perp: ep.norm_squared(),
            proj: &proj,
            params: QuickpropParams {
                mu: 2.0,
                epsilon: 1.0,
                decay: 0.0,
                patience: 8,
                threshold: 0.03,
                max_epochs: 10,
            },
            prime_offset: 0.0, // the true gradient; the offset deliberately biases it
            patterns: 60,
        };
        let w = DVector::from_vec(vec![0.3, -0.8, 0.5, 0.9, -0.2]);
        let (mut v, mut gv, mut g) = (DVector::zeros(60), DVector::zeros(60), DVector::zeros(5));
        objective_and_gradient(&ctx, objective, &w, &mut v, &mut gv, &mut g);
        for i in 0..5 {
            let h = 1e-6;
            let mut wp = w.clone();
            wp[i] += h;
            let mut wm = w.clone();
            wm[i] -= h;
            let sp = objective_and_gradient(
                &ctx,
                objective,
                &wp,
                &mut v,
                &mut gv,
                &mut DVector::zeros(5),
            );
            let sm = objective_and_gradient(
                &ctx,
                objective,
                &wm,
                &mut v,
                &mut gv,
                &mut DVector::zeros(5),
            );
            let fd = (sp - sm) / (2.0 * h);
            assert!(
                (fd - g[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                "{objective} ∂S/∂w{i}: analytic {} vs fd {fd}",
                g[i]
            );
        }
    }

    #[test]
    fn covariance_gradient_matches_finite_differences() {
        check_gradient(Objective::Covariance);
    }

    #[test]
    fn cascade2_gradient_matches_finite_differences() {
        check_gradient(Objective::Cascade2);
    }

    #[test]
    fn cascade2_score_is_the_sse_removed_by_a_least_squares_refit() {
        let (f, e) = setup(80, 4, 2, 3);
        let gram = f.tr_mul(&f);
        let proj = Projector::new(&gram).unwrap();
        let ep = proj.project_off(&f, &e);
        let ec = ep.clone();
        let ctx = Context {
            f: &f,
            e_centred: &ec,
            sse_centred: ec.norm_squared(),
            e_perp: &ep,
            sse_perp: ep.norm_squared(),
            proj: &proj,
            params: QuickpropParams {
                mu: 2.0,
                epsilon: 1.0,
                decay: 0.0,
                patience: 8,
                threshold: 0.03,
                max_epochs: 1,
            },
            prime_offset: 0.0,
            patterns: 80,
        };
        let v = DVector::from_fn(80, |r, _| (3.0 * f[(r, 1)] + f[(r, 2)]).tanh());
        let s = error_reduction(&ctx, &v);
        // Independent: least squares of E on [F, v] by QR.
        let mut fa = f.clone().insert_column(4, 0.0);
        fa.set_column(4, &v);
        let qr = fa.clone().qr();
        let coef = qr.r().try_inverse().unwrap() * qr.q().transpose() * &e;
        let resid = &e - &fa * coef;
        let expect = 1.0 - resid.norm_squared() / ep.norm_squared();
        assert!((s - expect).abs() < 1e-8, "{s} vs {expect}");
    }

    #[test]
    fn pool_is_independent_of_thread_count() {
        let (f, e) = setup(200, 6, 2, 11);
        let gram = f.tr_mul(&f);
        let proj = Projector::new(&gram).unwrap();
        let mean = e.row_mean();
        let ec = DMatrix::from_fn(e.nrows(), e.ncols(), |r, c| e[(r, c)] - mean[c]);
        let ep = proj.project_off(&f, &e);
        let ctx = Context {
            f: &f,
            e_centred: &ec,
            sse_centred: ec.norm_squared(),
            e_perp: &ep,
            sse_perp: ep.norm_squared(),
            proj: &proj,
            params: QuickpropParams {
                mu: 2.0,
                epsilon: 1.0,
                decay: 0.0,
                patience: 8,
                threshold: 0.03,
                max_epochs: 50,
            },
            prime_offset: 0.1,
            patterns: 200,
        };
        let objs = [Objective::Covariance, Objective::Cascade2];
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let a = one.install(|| train_pool(&ctx, &objs, 6, 42, 3));
        let b = two.install(|| train_pool(&ctx, &objs, 6, 42, 3));
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.weights, y.weights);
        }
        // Training increases the objective over the random start.
        assert!(a.iter().all(|c| c.score.is_finite() && c.epochs > 1));
    }
}
