//! The Cascade-Correlation training loop (Fahlman & Lebiere 1990,
//! `docs/design.md` §4): output phase → candidate phase → install the best
//! candidate (input weights frozen, activations cached as a new feature
//! column) → repeat, keeping the network with the lowest validation error.
//! Also the choice between output configurations (pilot units, validation
//! picks), stopping, and the progress bar.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::ProgressBar;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::candidates::{Candidate, Objective};
use super::net::{GrowingNet, OutputKind};
use super::outputs::{rmse, Data, State};
use super::polish::{polish, PolishReport, RowMetrics, Rows};
use crate::learn::LearnError;

pub use super::options::{CascorOptions, ObjectiveChoice, OutputSolver};
pub use super::unit_log::UnitLog;

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
    /// What the polish phase did, when it ran.
    #[serde(default)]
    pub polish: Option<PolishReport>,
    /// Total wall time, seconds.
    pub seconds: f64,
}

/// Model selection: every logged row may become the kept net (lowest
/// validation RMSE); training stops on the cap, patience or target.
impl State {
    /// Record the net after a unit (or none) and remember it if it is the best so far.
    pub(super) fn log(
        &mut self,
        d: &Data<'_>,
        cand: Option<&Candidate>,
        output_epochs: usize,
    ) -> UnitLog {
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

    /// The kept net, taking the centred inputs `2x − 1` the phases train on.
    pub(super) fn finish(&self, n_inputs: usize) -> GrowingNet {
        let (hidden, w) = match &self.best {
            Some((_, h, w)) => (h.clone(), w.clone()),
            None => (self.hidden.clone(), self.w.clone()),
        };
        let m = w.nrows();
        GrowingNet {
            n_inputs,
            n_outputs: w.ncols(),
            hidden,
            outputs: (0..w.ncols())
                .map(|o| (0..m).map(|r| w[(r, o)]).collect())
                .collect(),
            output_kind: self.kind,
        }
    }

    pub(super) fn done(&self, opts: &CascorOptions) -> bool {
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
) -> Result<(GrowingNet, TrainReport), LearnError> {
    train_with_stop(
        x,
        y,
        vx,
        vy,
        opts,
        seed,
        &AtomicBool::new(false),
        Metrics::default(),
    )
}

/// Per-row metrics the polish phase weighs the training and validation
/// rows' errors by (`super::tip_metric`); `None`: plain squared error.
#[derive(Clone, Copy, Debug, Default)]
pub struct Metrics<'a> {
    /// One per training row.
    pub train: Option<&'a RowMetrics>,
    /// One per validation row.
    pub valid: Option<&'a RowMetrics>,
}

/// [`train`], checking `stop` before every unit it grows: once it is set,
/// training ends with [`LearnError::Interrupted`] and returns no net. The
/// polish phase, when the options ask for it, weighs errors by `metrics`.
#[allow(clippy::too_many_arguments)]
pub fn train_with_stop(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    vx: &DMatrix<f64>,
    vy: &DMatrix<f64>,
    opts: &CascorOptions,
    seed: u64,
    stop: &AtomicBool,
    metrics: Metrics<'_>,
) -> Result<(GrowingNet, TrainReport), LearnError> {
    check(x, y, "training split")?;
    for (m, rows, what) in [
        (metrics.train, x.nrows(), "training"),
        (metrics.valid, vx.nrows(), "validation"),
    ] {
        if let Some(m) = m {
            if m.rows() != rows || m.outputs != y.ncols() {
                return Err(LearnError::BadData(format!(
                    "{what} metric: {} rows of {} outputs for {rows} rows of {}",
                    m.rows(),
                    m.outputs,
                    y.ncols()
                )));
            }
        }
    }
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
    opts.polish.check()?;
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
        stop,
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

    let bar = progress_bar(
        opts,
        opts.max_hidden,
        "cascor {bar:30} {pos}/{len} units {msg} [{elapsed_precise}]",
    );

    let mut states: Vec<State> = configs
        .iter()
        .map(|&(k, s)| State::new(k, s, x, vx, y))
        .collect();
    for st in &mut states {
        let e = st.train_outputs(&d);
        let row = st.log(&d, None, e);
        log::debug!(
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
        log::debug!(
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
    let mut net = st.finish(x.ncols());
    let polish = (opts.polish.max_iterations > 0 && !stop.load(Ordering::SeqCst))
        .then(|| polish_net(&mut net, x, vx, &d, metrics));
    net.fold_input_affine(&vec![2.0; x.ncols()], &vec![-1.0; x.ncols()]);
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
        polish,
        seconds: d.start.elapsed().as_secs_f64(),
    };
    log::debug!(
        "cascor: kept {} hidden units, validation RMSE ×100 {:.4}, {:.1} s",
        report.best_hidden,
        100.0 * report.best_valid_rmse,
        report.seconds
    );
    Ok((net, report))
}

/// A bar of `len` on stderr in `template`, when the options ask for
/// progress and info logging is on; else hidden.
fn progress_bar(opts: &CascorOptions, len: usize, template: &str) -> ProgressBar {
    crate::progress::bar(len as u64, opts.progress, template)
}

/// Polish `net` (centred inputs) on the training rows with a progress bar.
pub(super) fn polish_net(
    net: &mut GrowingNet,
    x: &DMatrix<f64>,
    vx: &DMatrix<f64>,
    d: &Data<'_>,
    metrics: Metrics<'_>,
) -> PolishReport {
    let centre = |m: &DMatrix<f64>| m.map(|v| 2.0 * v - 1.0);
    let (cx, cvx) = (centre(x), centre(vx));
    let train = Rows {
        metric: metrics.train,
        ..Rows::plain(&cx, d.y)
    };
    let valid = Rows {
        metric: metrics.valid,
        ..Rows::plain(&cvx, d.vy)
    };
    let opts = &d.opts.polish;
    let bar = progress_bar(
        d.opts,
        opts.max_iterations,
        "polish {bar:30} {pos}/{len} steps {msg} [{elapsed_precise}]",
    );
    let r = polish(net, train, valid, opts, d.stop, |i, v| {
        bar.set_position(i as u64);
        bar.set_message(format!("valid RMSE×100 {:.4}", 100.0 * v));
        if i % 100 == 0 {
            log::debug!("cascor polish: step {i}, valid RMSE {v:.6}");
        }
    });
    bar.finish_and_clear();
    log::debug!(
        "cascor polish: {} iterations (best {}), train RMSE {:.6} → {:.6}, valid RMSE {:.6} → {:.6}, {:.1} s",
        r.iterations,
        r.best_iteration,
        r.train_rmse.0,
        r.train_rmse.1,
        r.valid_rmse.0,
        r.valid_rmse.1,
        r.seconds
    );
    r
}

fn log_unit(st: &State, row: &UnitLog) {
    log::debug!(
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
