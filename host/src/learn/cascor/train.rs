//! The Cascade-Correlation training loop (Fahlman & Lebiere 1990, `DESIGN.md` §4):
//! output phase → candidate phase → install the best candidate (input weights
//! frozen, activations cached as a new feature column) → repeat, keeping the
//! network with the lowest validation error.

use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::candidates::{
    candidate_seed, error_reduction, train_pool, Candidate, Context, Objective, Projector,
};
use super::net::{hidden_activation, logistic, CascadeNet, OutputKind};
use super::quickprop::{Patience, Quickprop, QuickpropParams};
use crate::learn::LearnError;

/// How the output weights are trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum OutputSolver {
    /// Fahlman's Quickprop descent on the squared error.
    Quickprop,
    /// Exact ridge least squares over the cached features (linear outputs only),
    /// the ridge strength chosen on the validation split.
    Ridge,
}

impl std::fmt::Display for OutputSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OutputSolver::Quickprop => "quickprop",
            OutputSolver::Ridge => "ridge",
        })
    }
}

/// Which candidate objectives the pool uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObjectiveChoice {
    /// Every candidate maximises Fahlman's covariance.
    Covariance,
    /// Every candidate maximises Cascade 2's error reduction.
    Cascade2,
    /// Half the pool each; the installed unit is chosen by validation, so the
    /// objective is picked per unit.
    Mixed,
}

/// Hyper-parameters of [`train`]; defaults follow Fahlman's cascor code where it has one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CascorOptions {
    /// Hidden-unit cap (the firmware's capacity bounds it; ≤ 64).
    pub max_hidden: usize,
    /// Candidates trained per installed unit.
    pub pool: usize,
    /// Candidate objective(s).
    pub objective: ObjectiveChoice,
    /// Output activations to try (`[Linear, Sigmoid]` = choose by validation).
    pub output_kinds: Vec<OutputKind>,
    /// Output solvers to try for linear outputs (sigmoid outputs always use Quickprop).
    pub output_solvers: Vec<OutputSolver>,
    /// Output-phase Quickprop (ε is divided by the number of patterns).
    pub output: QuickpropParams,
    /// Candidate-phase Quickprop (ε is divided by patterns × candidate fan-in).
    pub candidate: QuickpropParams,
    /// Sigmoid-prime offset in the output error of sigmoid outputs (Fahlman: 0.1).
    pub output_prime_offset: f64,
    /// Sigmoid-prime offset in the candidate gradient.
    pub candidate_prime_offset: f64,
    /// Ridge strengths tried, relative to the mean diagonal of the Gram matrix.
    pub ridge_lambdas: Vec<f64>,
    /// Stop after this many installed units without a new best validation RMSE.
    pub valid_patience: usize,
    /// Stop once the validation RMSE (normalised units) is at or below this.
    pub target_rmse: f64,
    /// Hidden units grown by every output configuration before validation picks one
    /// (only when more than one configuration is allowed).
    pub pilot_units: usize,
    /// Train candidates on a fixed random subset of this many training rows
    /// (re-drawn per unit; 0 = all rows). Installation and outputs use all rows.
    pub candidate_patterns: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

impl Default for CascorOptions {
    fn default() -> Self {
        CascorOptions {
            max_hidden: 64,
            pool: 8,
            objective: ObjectiveChoice::Cascade2,
            output_kinds: vec![OutputKind::Linear, OutputKind::Sigmoid],
            output_solvers: vec![OutputSolver::Ridge, OutputSolver::Quickprop],
            output: QuickpropParams {
                mu: 2.0,
                epsilon: 0.35,
                decay: 1e-4,
                patience: 8,
                threshold: 0.01,
                max_epochs: 1000,
            },
            // Fahlman: ε 1.0, patience 8, threshold 3 %. With normalised objectives that
            // leaves candidates almost untrained on the IK data (test RMSE ×100 0.21 vs
            // 0.065 at 40 units, BENCHMARKS.md), so the defaults train them longer.
            candidate: QuickpropParams {
                mu: 2.0,
                epsilon: 1000.0,
                decay: 0.0,
                patience: 25,
                threshold: 0.01,
                max_epochs: 1000,
            },
            output_prime_offset: 0.1,
            candidate_prime_offset: 0.1,
            ridge_lambdas: vec![1e-12, 1e-10, 1e-8, 1e-6, 1e-4],
            valid_patience: 8,
            target_rmse: 0.0,
            pilot_units: 3,
            candidate_patterns: 3000,
            progress: true,
        }
    }
}

/// One row of the training log: the net after installing `hidden` units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitLog {
    /// Hidden units installed.
    pub hidden: usize,
    /// Training RMSE (normalised units).
    pub train_rmse: f64,
    /// Validation RMSE (normalised units).
    pub valid_rmse: f64,
    /// Objective score of the installed candidate (NaN for the first row).
    pub score: f64,
    /// Fraction of the residual SSE the installed candidate was predicted to remove.
    pub reduction: f64,
    /// Objective of the installed candidate, if any.
    pub objective: Option<Objective>,
    /// Candidate-phase epochs of the installed candidate.
    pub candidate_epochs: usize,
    /// Output-phase epochs (0 for the ridge solve).
    pub output_epochs: usize,
    /// Wall time since training started, seconds.
    pub seconds: f64,
}

/// What [`train`] did, for logs, tables and the learning-curve plot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Output activation that won on validation.
    pub output_kind: OutputKind,
    /// Output solver that won on validation.
    pub output_solver: OutputSolver,
    /// Validation RMSE of every pilot configuration, when there was a choice.
    pub pilot: Vec<(String, f64)>,
    /// Learning curve of the winning configuration.
    pub history: Vec<UnitLog>,
    /// Hidden units of the returned (best-validation) net.
    pub best_hidden: usize,
    /// Validation RMSE of the returned net.
    pub best_valid_rmse: f64,
    /// Installed units per objective: (covariance, cascade2).
    pub objective_wins: (usize, usize),
    /// Total wall time, seconds.
    pub seconds: f64,
}

/// Working state of one output configuration.
#[derive(Clone)]
struct State {
    kind: OutputKind,
    solver: OutputSolver,
    /// Cached features on training rows: bias, centred inputs, hidden activations.
    f: DMatrix<f64>,
    fv: DMatrix<f64>,
    gram: DMatrix<f64>,
    fty: DMatrix<f64>,
    hidden: Vec<Vec<f64>>,
    /// Output weights, `m × O`.
    w: DMatrix<f64>,
    history: Vec<UnitLog>,
    best: Option<(f64, Vec<Vec<f64>>, DMatrix<f64>)>,
    since_best: usize,
}

struct Data<'a> {
    y: &'a DMatrix<f64>,
    vy: &'a DMatrix<f64>,
    opts: &'a CascorOptions,
    seed: u64,
    start: Instant,
}

fn features(x: &DMatrix<f64>) -> DMatrix<f64> {
    let (n, i) = x.shape();
    DMatrix::from_fn(n, 1 + i, |r, c| {
        if c == 0 {
            1.0
        } else {
            2.0 * x[(r, c - 1)] - 1.0
        }
    })
}

fn rmse(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    ((a - b).norm_squared() / a.len() as f64).sqrt()
}

impl State {
    fn new(
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

    fn outputs(&self, f: &DMatrix<f64>) -> DMatrix<f64> {
        let mut p = f * &self.w;
        if self.kind == OutputKind::Sigmoid {
            p.apply(|v| *v = logistic(*v));
        }
        p
    }

    /// Ridge solve with λ picked on validation; returns the chosen weights.
    fn ridge(
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
    fn train_outputs(&mut self, d: &Data<'_>) -> usize {
        match (self.kind, self.solver) {
            (OutputKind::Linear, OutputSolver::Ridge) => {
                self.w = self.ridge(&self.gram, &self.fty, &self.fv, d);
                0
            }
            _ => self.quickprop_outputs(d),
        }
    }

    fn quickprop_outputs(&mut self, d: &Data<'_>) -> usize {
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
    fn error_prime(&self, y: &DMatrix<f64>, offset: f64) -> DMatrix<f64> {
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

    fn log(&mut self, d: &Data<'_>, cand: Option<&Candidate>, output_epochs: usize) -> UnitLog {
        let train_rmse = rmse(&self.outputs(&self.f), d.y);
        let valid_rmse = if d.vy.nrows() > 0 {
            rmse(&self.outputs(&self.fv), d.vy)
        } else {
            train_rmse
        };
        let row = UnitLog {
            hidden: self.hidden.len(),
            train_rmse,
            valid_rmse,
            score: cand.map_or(f64::NAN, |c| c.score),
            reduction: cand.map_or(f64::NAN, |c| c.reduction),
            objective: cand.map(|c| c.objective),
            candidate_epochs: cand.map_or(0, |c| c.epochs),
            output_epochs,
            seconds: d.start.elapsed().as_secs_f64(),
        };
        if self.best.as_ref().is_none_or(|b| valid_rmse < b.0) {
            self.best = Some((valid_rmse, self.hidden.clone(), self.w.clone()));
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
        self.history.push(row.clone());
        row
    }

    /// Candidate phase + installation + output phase.
    fn grow(&mut self, d: &Data<'_>) -> Result<UnitLog, LearnError> {
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
    fn pick(&self, pool: &[Candidate], d: &Data<'_>) -> usize {
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

    fn valid_values(&self, w: &[f64]) -> DVector<f64> {
        let mut v = &self.fv * DVector::from_column_slice(w);
        v.apply(|x| *x = hidden_activation(*x));
        v
    }

    fn extended_gram(&self, v: &DVector<f64>, y: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
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
    fn install(&mut self, cand: &Candidate, err: &DMatrix<f64>, d: &Data<'_>) -> usize {
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

    fn finish(&self, n_inputs: usize) -> CascadeNet {
        let (hidden, w) = match &self.best {
            Some((_, h, w)) => (h.clone(), w.clone()),
            None => (self.hidden.clone(), self.w.clone()),
        };
        let m = w.nrows();
        let mut net = CascadeNet {
            n_inputs,
            n_outputs: w.ncols(),
            hidden,
            outputs: (0..w.ncols())
                .map(|o| (0..m).map(|r| w[(r, o)]).collect())
                .collect(),
            output_kind: self.kind,
        };
        net.fold_input_affine(&vec![2.0; n_inputs], &vec![-1.0; n_inputs]);
        net
    }

    fn done(&self, opts: &CascorOptions) -> bool {
        let last = self.history.last().map_or(f64::INFINITY, |r| r.valid_rmse);
        self.hidden.len() >= opts.max_hidden
            || self.since_best >= opts.valid_patience
            || last <= opts.target_rmse
    }
}

fn check(x: &DMatrix<f64>, y: &DMatrix<f64>, what: &str) -> Result<(), LearnError> {
    if x.nrows() != y.nrows() {
        return Err(LearnError::BadData(format!(
            "{what}: {} input rows but {} target rows",
            x.nrows(),
            y.nrows()
        )));
    }
    if x.iter().chain(y.iter()).any(|v| !v.is_finite()) {
        return Err(LearnError::BadData(format!("{what}: non-finite value")));
    }
    Ok(())
}

/// Train a cascade-correlation net on normalised data; `valid` may be empty
/// (then the training error stands in for it). Deterministic for a `seed`,
/// whatever the number of rayon threads.
pub fn train(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    vx: &DMatrix<f64>,
    vy: &DMatrix<f64>,
    opts: &CascorOptions,
    seed: u64,
) -> Result<(CascadeNet, TrainReport), LearnError> {
    check(x, y, "training split")?;
    check(vx, vy, "validation split")?;
    if x.nrows() < 2 || x.ncols() == 0 || y.ncols() == 0 {
        return Err(LearnError::BadData(format!(
            "training split is {}×{} → {}",
            x.nrows(),
            x.ncols(),
            y.ncols()
        )));
    }
    if vx.nrows() > 0 && (vx.ncols() != x.ncols() || vy.ncols() != y.ncols()) {
        return Err(LearnError::BadData(
            "validation split has other columns than the training split".into(),
        ));
    }
    if opts.pool == 0 {
        return Err(LearnError::BadParameter {
            name: "pool",
            why: "must be at least 1".into(),
        });
    }
    if opts.output_kinds.is_empty() || opts.output_solvers.is_empty() {
        return Err(LearnError::BadParameter {
            name: "output",
            why: "no output kind or solver allowed".into(),
        });
    }
    let d = Data {
        y,
        vy,
        opts,
        seed,
        start: Instant::now(),
    };
    let mut configs = Vec::new();
    for &k in &opts.output_kinds {
        match k {
            OutputKind::Linear => {
                for &s in &opts.output_solvers {
                    configs.push((k, s));
                }
            }
            OutputKind::Sigmoid => configs.push((k, OutputSolver::Quickprop)),
        }
    }
    configs.dedup();

    let bar = ProgressBar::with_draw_target(
        Some(opts.max_hidden as u64),
        if opts.progress {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    bar.set_style(
        ProgressStyle::with_template("cascor {bar:30} {pos}/{len} units {msg} [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );

    let mut states: Vec<State> = configs
        .iter()
        .map(|&(k, s)| State::new(k, s, x, vx, y))
        .collect();
    for st in &mut states {
        let e = st.train_outputs(&d);
        let row = st.log(&d, None, e);
        log::info!(
            "cascor [{} outputs, {}] 0 hidden: train RMSE {:.5}, valid RMSE {:.5}",
            st.kind,
            st.solver,
            row.train_rmse,
            row.valid_rmse
        );
    }
    let mut pilot = Vec::new();
    if states.len() > 1 {
        for st in &mut states {
            for _ in 0..opts.pilot_units.min(opts.max_hidden) {
                let row = st.grow(&d)?;
                log_unit(st, &row);
            }
            let v = st.best.as_ref().map_or(f64::INFINITY, |b| b.0);
            pilot.push((format!("{} outputs, {}", st.kind, st.solver), v));
        }
    }
    let pick = (0..states.len())
        .min_by(|&a, &b| {
            let va = states[a].best.as_ref().map_or(f64::INFINITY, |b| b.0);
            let vb = states[b].best.as_ref().map_or(f64::INFINITY, |b| b.0);
            va.total_cmp(&vb)
        })
        .unwrap_or(0);
    let mut st = states.swap_remove(pick);
    drop(states);
    if !pilot.is_empty() {
        log::info!(
            "cascor: validation picked {} outputs with {} ({:?})",
            st.kind,
            st.solver,
            pilot
        );
    }
    bar.set_position(st.hidden.len() as u64);
    while !st.done(opts) {
        let row = st.grow(&d)?;
        log_unit(&st, &row);
        bar.set_position(st.hidden.len() as u64);
        bar.set_message(format!("valid RMSE×100 {:.4}", 100.0 * row.valid_rmse));
    }
    bar.finish_and_clear();
    let net = st.finish(x.ncols());
    let wins = st
        .history
        .iter()
        .fold((0, 0), |(c, k), r| match r.objective {
            Some(Objective::Covariance) => (c + 1, k),
            Some(Objective::Cascade2) => (c, k + 1),
            None => (c, k),
        });
    let report = TrainReport {
        output_kind: st.kind,
        output_solver: st.solver,
        pilot,
        best_hidden: net.n_hidden(),
        best_valid_rmse: st.best.as_ref().map_or(f64::NAN, |b| b.0),
        history: st.history,
        objective_wins: wins,
        seconds: d.start.elapsed().as_secs_f64(),
    };
    log::info!(
        "cascor: kept {} hidden units, validation RMSE ×100 {:.4}, {:.1} s",
        report.best_hidden,
        100.0 * report.best_valid_rmse,
        report.seconds
    );
    Ok((net, report))
}

fn log_unit(st: &State, row: &UnitLog) {
    log::info!(
        "cascor [{} outputs, {}] unit {:>2}: train RMSE {:.6}, valid RMSE {:.6}, {} score {:.4} (removes {:.1} %), {} candidate epochs, {} output epochs, {:.1} s",
        st.kind,
        st.solver,
        row.hidden,
        row.train_rmse,
        row.valid_rmse,
        row.objective.map_or("-".to_string(), |o| o.to_string()),
        row.score,
        100.0 * row.reduction,
        row.candidate_epochs,
        row.output_epochs,
        row.seconds
    );
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
