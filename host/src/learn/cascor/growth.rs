//! The candidate phase and installation: train a pool of candidate units
//! against the residual, pick one, freeze its input weights, cache its
//! activations as a new feature column and retrain the outputs
//! (Fahlman & Lebiere 1990; Cascade 2, Prechelt 1997).

use std::sync::atomic::Ordering;

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::candidates::{
    candidate_seed, error_reduction, train_pool, Candidate, Context, Objective, Projector,
};
use super::net::{hidden_activation, OutputKind};
use super::options::{ObjectiveChoice, OutputSolver};
use super::outputs::{rmse, Data, State};
use super::unit_log::UnitLog;
use crate::learn::LearnError;

impl State {
    /// Candidate phase + installation + output phase.
    pub(super) fn grow(&mut self, d: &Data<'_>) -> Result<UnitLog, LearnError> {
        if d.stop.load(Ordering::Relaxed) {
            return Err(LearnError::Interrupted);
        }
        let err = self.error_prime(d.y, d.opts.output_prime_offset);
        let proj = Projector::new(&self.gram).ok_or_else(|| {
            LearnError::Numerical("feature Gram matrix is not positive definite".into())
        })?;
        let e_perp = proj.project_off(&self.f, &err);
        let objectives: &[Objective] = match d.opts.objective {
            ObjectiveChoice::Covariance => &[Objective::Covariance],
            ObjectiveChoice::Cascade2 => &[Objective::Cascade2],
            ObjectiveChoice::Mixed => &[Objective::Covariance, Objective::Cascade2],
        };
        let unit = self.hidden.len();
        let n = self.f.nrows();
        let k = d.opts.candidate_patterns;
        // Rows the candidates train on: all, or a seeded subset drawn per unit.
        let rows: Option<Vec<usize>> = (k > 0 && k < n).then(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(candidate_seed(d.seed, unit, usize::MAX));
            let mut idx = rand::seq::index::sample(&mut rng, n, k).into_vec();
            idx.sort_unstable();
            idx
        });
        let (f_c, err_c) = match &rows {
            Some(r) => (self.f.select_rows(r), err.select_rows(r)),
            None => (self.f.clone(), err.clone()),
        };
        // Project on the rows the candidates see: a residual that is not exactly
        // orthogonal to their span lets a candidate score by copying a feature.
        let (proj_c, e_perp_c) = match &rows {
            Some(_) => {
                let p = Projector::new(&f_c.tr_mul(&f_c)).ok_or_else(|| {
                    LearnError::Numerical("candidate Gram matrix is not positive definite".into())
                })?;
                let e = p.project_off(&f_c, &err_c);
                (p, e)
            }
            None => (
                Projector::new(&self.gram).ok_or_else(|| {
                    LearnError::Numerical("feature Gram matrix is not positive definite".into())
                })?,
                e_perp.clone(),
            ),
        };
        let mean = err_c.row_mean();
        let e_centred =
            DMatrix::from_fn(err_c.nrows(), err_c.ncols(), |r, c| err_c[(r, c)] - mean[c]);
        let ctx = Context {
            f: &f_c,
            sse_centred: e_centred.norm_squared().max(f64::MIN_POSITIVE),
            e_centred: &e_centred,
            sse_perp: e_perp_c.norm_squared().max(f64::MIN_POSITIVE),
            e_perp: &e_perp_c,
            proj: &proj_c,
            params: d.opts.candidate,
            prime_offset: d.opts.candidate_prime_offset,
            patterns: n,
        };
        let mut pool = train_pool(&ctx, objectives, d.opts.pool.max(1), d.seed, unit);
        if rows.is_some() {
            // Re-evaluate every candidate on all training rows.
            let e_full = DMatrix::zeros(0, 0);
            let full = Context {
                f: &self.f,
                e_centred: &e_full,
                sse_centred: 1.0,
                sse_perp: e_perp.norm_squared().max(f64::MIN_POSITIVE),
                e_perp: &e_perp,
                proj: &proj,
                params: d.opts.candidate,
                prime_offset: d.opts.candidate_prime_offset,
                patterns: n,
            };
            for c in &mut pool {
                let mut v = &self.f * DVector::from_column_slice(&c.weights);
                v.apply(|x| *x = hidden_activation(*x));
                c.reduction = error_reduction(&full, &v);
                c.values = v;
            }
        }
        let best = self.pick(&pool, d);
        let cand = pool
            .into_iter()
            .nth(best)
            .ok_or_else(|| LearnError::Numerical("empty candidate pool".into()))?;
        let epochs = self.install(&cand, &err, d);
        Ok(self.log(d, Some(&cand), epochs))
    }

    /// Index of the candidate to install: with exact linear outputs, the one
    /// whose trial solve gives the lowest validation RMSE; otherwise the one
    /// removing most training error.
    pub(super) fn pick(&self, pool: &[Candidate], d: &Data<'_>) -> usize {
        let by_reduction = || {
            (0..pool.len())
                .max_by(|&a, &b| pool[a].reduction.total_cmp(&pool[b].reduction))
                .unwrap_or(0)
        };
        if !(self.kind == OutputKind::Linear && self.solver == OutputSolver::Ridge)
            || d.vy.nrows() == 0
        {
            return by_reduction();
        }
        let mut best = (f64::INFINITY, by_reduction());
        for (i, c) in pool.iter().enumerate() {
            let vv = self.valid_values(&c.weights);
            let (gram, fty) = self.extended_gram(&c.values, d.y);
            let fv = self.fv.clone().insert_column(self.fv.ncols(), 0.0);
            let mut fv = fv;
            fv.set_column(fv.ncols() - 1, &vv);
            let w = self.ridge(&gram, &fty, &fv, d);
            let e = rmse(&(&fv * &w), d.vy);
            if e < best.0 {
                best = (e, i);
            }
        }
        best.1
    }

    pub(super) fn valid_values(&self, w: &[f64]) -> DVector<f64> {
        let mut v = &self.fv * DVector::from_column_slice(w);
        v.apply(|x| *x = hidden_activation(*x));
        v
    }

    pub(super) fn extended_gram(
        &self,
        v: &DVector<f64>,
        y: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let m = self.gram.nrows();
        let ftv = self.f.tr_mul(v);
        let mut g = self.gram.clone().insert_column(m, 0.0).insert_row(m, 0.0);
        for i in 0..m {
            g[(i, m)] = ftv[i];
            g[(m, i)] = ftv[i];
        }
        g[(m, m)] = v.norm_squared();
        let vty = v.tr_mul(y);
        let fty = self.fty.clone().insert_row(m, 0.0);
        let mut fty = fty;
        fty.row_mut(m).copy_from(&vty);
        (g, fty)
    }

    /// Freeze the candidate as hidden unit k, cache its activations, retrain outputs.
    pub(super) fn install(&mut self, cand: &Candidate, err: &DMatrix<f64>, d: &Data<'_>) -> usize {
        let m = self.f.ncols();
        let vv = self.valid_values(&cand.weights);
        let (gram, fty) = self.extended_gram(&cand.values, d.y);
        self.gram = gram;
        self.fty = fty;
        self.f = std::mem::replace(&mut self.f, DMatrix::zeros(0, 0)).insert_column(m, 0.0);
        self.f.set_column(m, &cand.values);
        self.fv = std::mem::replace(&mut self.fv, DMatrix::zeros(0, 0)).insert_column(m, 0.0);
        self.fv.set_column(m, &vv);
        self.hidden.push(cand.weights.clone());
        // New output weights: the 1-D least-squares step against the residual,
        // i.e. minus the correlation sign (Fahlman) with a sensible magnitude.
        let vbar = cand.values.mean();
        let q: f64 = cand
            .values
            .iter()
            .map(|v| (v - vbar) * (v - vbar))
            .sum::<f64>()
            .max(f64::MIN_POSITIVE);
        let mut w = std::mem::replace(&mut self.w, DMatrix::zeros(0, 0)).insert_row(m, 0.0);
        for o in 0..w.ncols() {
            let c: f64 = cand
                .values
                .iter()
                .zip(err.column(o).iter())
                .map(|(v, e)| (v - vbar) * e)
                .sum();
            let wo = -c / q;
            w[(m, o)] = wo;
            w[(0, o)] -= wo * vbar;
        }
        self.w = w;
        self.train_outputs(d)
    }
}
