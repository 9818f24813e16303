//! The output phase: cached features of one output configuration and the two
//! solvers of its output weights — exact ridge least squares (linear outputs,
//! λ chosen on validation) and Quickprop descent (Fahlman 1988).

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use nalgebra::{DMatrix, SymmetricEigen};

use super::net::{logistic, OutputKind};
use super::options::{CascorOptions, OutputSolver};
use super::quickprop::{Patience, Quickprop};
use super::unit_log::UnitLog;

/// Working state of one output configuration.
#[derive(Clone)]
pub(super) struct State {
    pub(super) kind: OutputKind,
    pub(super) solver: OutputSolver,
    /// Cached features on training rows: bias, centred inputs, hidden activations.
    pub(super) f: DMatrix<f64>,
    pub(super) fv: DMatrix<f64>,
    pub(super) gram: DMatrix<f64>,
    pub(super) fty: DMatrix<f64>,
    pub(super) hidden: Vec<Vec<f64>>,
    /// Output weights, `m × O`.
    pub(super) w: DMatrix<f64>,
    pub(super) history: Vec<UnitLog>,
    pub(super) best: Option<(f64, Vec<Vec<f64>>, DMatrix<f64>)>,
    pub(super) since_best: usize,
}

/// What every phase of one training run reads.
pub(super) struct Data<'a> {
    pub(super) y: &'a DMatrix<f64>,
    pub(super) vy: &'a DMatrix<f64>,
    pub(super) opts: &'a CascorOptions,
    pub(super) seed: u64,
    pub(super) start: Instant,
    /// Set by Ctrl-C: [`State::grow`] refuses to start another unit.
    pub(super) stop: &'a AtomicBool,
}

pub(super) fn features(x: &DMatrix<f64>) -> DMatrix<f64> {
    let (n, i) = x.shape();
    DMatrix::from_fn(n, 1 + i, |r, c| {
        if c == 0 {
            1.0
        } else {
            2.0 * x[(r, c - 1)] - 1.0
        }
    })
}

pub(super) fn rmse(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    ((a - b).norm_squared() / a.len() as f64).sqrt()
}

impl State {
    pub(super) fn new(
        kind: OutputKind,
        solver: OutputSolver,
        x: &DMatrix<f64>,
        vx: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> State {
        let f = features(x);
        let fv = features(vx);
        let gram = f.tr_mul(&f);
        let fty = f.tr_mul(y);
        let w = DMatrix::zeros(f.ncols(), y.ncols());
        State {
            kind,
            solver,
            f,
            fv,
            gram,
            fty,
            hidden: Vec::new(),
            w,
            history: Vec::new(),
            best: None,
            since_best: 0,
        }
    }

    pub(super) fn outputs(&self, f: &DMatrix<f64>) -> DMatrix<f64> {
        let mut p = f * &self.w;
        if self.kind == OutputKind::Sigmoid {
            p.apply(|v| *v = logistic(*v));
        }
        p
    }

    /// Ridge solve with λ picked on validation; returns the chosen weights.
    pub(super) fn ridge(
        &self,
        gram: &DMatrix<f64>,
        fty: &DMatrix<f64>,
        fv: &DMatrix<f64>,
        d: &Data<'_>,
    ) -> DMatrix<f64> {
        let m = gram.nrows();
        let scale = (gram.trace() / m as f64).max(f64::MIN_POSITIVE);
        let eig = SymmetricEigen::new(gram.clone());
        let vtb = eig.eigenvectors.tr_mul(fty);
        let mut best: Option<(f64, DMatrix<f64>)> = None;
        for &lam in &d.opts.ridge_lambdas {
            let mut s = vtb.clone();
            for (i, mut row) in s.row_iter_mut().enumerate() {
                let denom = eig.eigenvalues[i].max(0.0) + lam * scale;
                row /= denom;
            }
            let w = &eig.eigenvectors * s;
            let err = if d.vy.nrows() > 0 {
                rmse(&(fv * &w), d.vy)
            } else {
                0.0
            };
            if best.as_ref().is_none_or(|(e, _)| err < *e) {
                best = Some((err, w));
            }
        }
        best.map(|b| b.1)
            .unwrap_or_else(|| DMatrix::zeros(m, fty.ncols()))
    }

    /// Output phase; returns epochs used (0 for the exact solve).
    pub(super) fn train_outputs(&mut self, d: &Data<'_>) -> usize {
        match (self.kind, self.solver) {
            (OutputKind::Linear, OutputSolver::Ridge) => {
                self.w = self.ridge(&self.gram, &self.fty, &self.fv, d);
                0
            }
            _ => self.quickprop_outputs(d),
        }
    }

    pub(super) fn quickprop_outputs(&mut self, d: &Data<'_>) -> usize {
        let p = d.opts.output;
        let n = self.f.nrows();
        let mut qp = Quickprop::new(self.w.len(), p.epsilon / n as f64, p.mu, p.decay);
        let mut patience = Patience::new(p.patience, p.threshold, true);
        let mut epochs = 0;
        for epoch in 0..p.max_epochs.max(1) {
            epochs = epoch + 1;
            let err = self.error_prime(d.y, d.opts.output_prime_offset);
            let sse = err.norm_squared();
            if !sse.is_finite() || patience.stagnant(epoch, sse) {
                break;
            }
            let slopes = self.f.tr_mul(&err);
            qp.step(self.w.as_mut_slice(), slopes.as_slice());
        }
        epochs
    }

    /// (out − target) scaled by the output derivative (+ offset) for sigmoid outputs.
    pub(super) fn error_prime(&self, y: &DMatrix<f64>, offset: f64) -> DMatrix<f64> {
        let mut out = self.outputs(&self.f);
        match self.kind {
            OutputKind::Linear => out - y,
            OutputKind::Sigmoid => {
                out.zip_apply(y, |o, t| {
                    let prime = *o * (1.0 - *o) + offset;
                    *o = (*o - t) * prime;
                });
                out
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The output phase's slopes Fᵀ·E′ (sigmoid-prime offset 0) must be the
    /// gradient of ½‖outputs − y‖² with respect to the output weights, for
    /// linear and sigmoid outputs: central differences of the loss itself.
    #[test]
    fn output_gradient_matches_finite_differences() {
        let x = DMatrix::from_fn(40, 3, |r, c| ((r * 7 + c * 13) % 17) as f64 / 17.0);
        let y = DMatrix::from_fn(40, 2, |r, c| ((r * 5 + c * 3) % 11) as f64 / 11.0);
        for kind in [OutputKind::Linear, OutputKind::Sigmoid] {
            let mut s = State::new(kind, OutputSolver::Quickprop, &x, &x, &y);
            s.w = DMatrix::from_fn(s.w.nrows(), s.w.ncols(), |r, c| {
                0.3 * ((r + 2 * c) as f64 + 0.5).sin()
            });
            let slopes = s.f.tr_mul(&s.error_prime(&y, 0.0));
            let loss = |s: &State| 0.5 * (s.outputs(&s.f) - &y).norm_squared();
            let h = 1e-6;
            for i in 0..s.w.len() {
                let w0 = s.w[i];
                s.w[i] = w0 + h;
                let plus = loss(&s);
                s.w[i] = w0 - h;
                let minus = loss(&s);
                s.w[i] = w0;
                let fd = (plus - minus) / (2.0 * h);
                assert!(
                    (fd - slopes[i]).abs() <= 1e-6 * fd.abs().max(1.0),
                    "{kind:?} weight {i}: analytic {} vs finite difference {fd}",
                    slopes[i]
                );
            }
            // The offset (Fahlman's sigmoid-prime offset) deliberately biases
            // the sigmoid gradient; the linear one has no derivative to offset.
            if kind == OutputKind::Sigmoid {
                let biased = s.f.tr_mul(&s.error_prime(&y, 0.1));
                assert!((biased - &slopes).norm() > 1e-3);
            }
        }
    }
}
