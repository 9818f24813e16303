//! The estimator (`docs/design.md` §11): Levenberg–Marquardt on the chosen
//! parameters, a Huber loss by iteratively reweighted rows, sensitivities
//! from the statics' tangent (the implicit function theorem through each
//! row's solution, [`crate::statics::implicit`]; central differences through
//! warm-started solves where a tangent is singular), 95 % intervals from the
//! covariance and the identifiability rule.

use std::time::Instant;

use nalgebra::{DMatrix, DVector, Vector3};

use super::data::Measurements;
use super::identify::identify;
use super::params::{bounds, scale, Param, Values};
pub use super::problem::FD_STEP;
use super::problem::{tips, Problem};
use super::report::{DownWeighted, FittedParam, Report, ResidualStats};
use super::rows::{check_rows, split};
use super::CalibError;
use crate::robot::Robot;
use crate::statics::{Solution, SolverSettings};

/// 95 % two-sided normal quantile.
const Z95: f64 = 1.959963984540054;
/// A row whose Huber weight falls below this is named as down-weighted.
const NAMED_WEIGHT: f64 = 0.5;

/// How to fit.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Parameters to fit (the rest keep the nominal file's values).
    pub fit: Vec<Param>,
    /// Fraction of the rows held out of the fit to judge it, in [0, 0.5].
    pub holdout_fraction: f64,
    /// Seed of the held-out split.
    pub seed: u64,
    /// Use the `qw..qz` columns when present.
    pub use_orientation: bool,
    /// How an orientation error weighs against a position error, m/rad.
    pub orientation_m_per_rad: f64,
    /// Huber threshold on a row's residual norm, in units of the robust
    /// per-axis noise scale.
    pub huber_k: f64,
    /// The smallest noise the identifiability rule assumes, m: noiseless
    /// synthetic data is judged as if a very good tracker measured it.
    pub noise_floor_m: f64,
    /// A direction of the parameters is unidentifiable when the data pins
    /// it no better than this fraction of the parameters' scales.
    pub identifiable_fraction: f64,
    /// Levenberg–Marquardt iterations at most (per fit round).
    pub max_iterations: usize,
    /// Statics settings of every solve.
    pub settings: SolverSettings,
    /// Standard deviation of the recorded tensions' noise (load cells), N:
    /// its scatter at the tip, through the robot's compliance, is added to
    /// the residual a calibration may leave ([`super::verdict`]).
    pub tension_noise_n: f64,
}

impl FitOptions {
    /// The defaults for fitting `fit`.
    pub fn new(fit: Vec<Param>) -> FitOptions {
        FitOptions {
            fit,
            holdout_fraction: 0.2,
            seed: 1,
            use_orientation: true,
            orientation_m_per_rad: 0.1,
            huber_k: 2.8,
            noise_floor_m: 1e-5,
            identifiable_fraction: 0.05,
            max_iterations: 40,
            settings: SolverSettings::default(),
            tension_noise_n: 0.0,
        }
    }
}

/// A finished calibration: the robot, the values (including what the
/// robot file cannot hold: tension scales, the tracker frame), the report
/// and the tips for the figure.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The calibrated robot (tension limits as in the nominal file).
    pub robot: Robot,
    /// Every value after the fit.
    pub values: Values,
    /// What the fit found, for JSON and markdown.
    pub report: Report,
    /// Measured positions (tracker frame), m, every row.
    pub measured: Vec<[f64; 3]>,
    /// The nominal model's tips (tracker frame = base frame), m.
    pub before: Vec<[f64; 3]>,
    /// The calibrated model's tips in the tracker frame, m.
    pub after: Vec<[f64; 3]>,
    /// Whether each row was held out of the fit.
    pub held_out: Vec<bool>,
}

/// What a fit of `data` will cost, in words, before it starts: the solves
/// of one Levenberg–Marquardt iteration and a typical fit's dozen, timed
/// by one solve of the robot on this machine.
pub fn cost_estimate(robot: &Robot, data: &Measurements, opts: &FitOptions) -> String {
    let rod = opts.fit.iter().filter(|p| p.moves_rod()).count();
    // An iteration: a trial solve or two a row, and the Jacobian's tangent
    // pass (≈ 4.5 plain passes) and two plain passes per parameter that
    // moves the rod; a warm solve is ≈ 6 plain passes (BENCHMARKS.md).
    let solves = 2.0 + (2 * rod) as f64 / 6.0 + 4.5 / 6.0;
    let per_iteration = (data.len() as f64 * solves).round() as usize;
    let threads = rayon::current_num_threads().max(1);
    let seconds = 12.0 * per_iteration as f64 * super::seconds_per_solve(robot) / threads as f64;
    format!(
        "fitting {} parameters to {} rows: about {per_iteration} statics solves' work per \
         iteration, about {seconds:.0} s for a typical dozen iterations on {threads} threads",
        opts.fit.len(),
        data.len()
    )
}

/// Per-row norms of a row-major residual vector with `d` entries a row.
fn row_norms(r: &DVector<f64>, d: usize) -> Vec<f64> {
    r.as_slice()
        .chunks(d)
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
        .collect()
}

/// Robust per-axis noise scale from row norms: the median norm over the
/// median of the χ distribution with `d` degrees of freedom (Wilson–Hilferty).
fn robust_sigma(norms: &[f64], d: usize) -> f64 {
    let mut s = norms.to_vec();
    s.sort_by(f64::total_cmp);
    let median = if s.is_empty() { 0.0 } else { s[s.len() / 2] };
    let k = d as f64;
    let chi_median = (k * (1.0 - 2.0 / (9.0 * k)).powi(3)).sqrt();
    (median / chi_median).max(1e-15)
}

/// Huber weights of rows: 1 within k σ, k σ / ‖r_i‖ beyond (IRLS).
fn huber_weights(norms: &[f64], sigma: f64, k: f64) -> Vec<f64> {
    norms
        .iter()
        .map(|&n| if n <= k * sigma { 1.0 } else { k * sigma / n })
        .collect()
}

/// Jᵀ W J and Jᵀ W r with one weight per row of `d` entries.
fn normal_equations(
    jac: &DMatrix<f64>,
    r: &DVector<f64>,
    w: &[f64],
    d: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    let mut wj = jac.clone();
    let mut wr = r.clone();
    for (i, &wi) in w.iter().enumerate() {
        for k in 0..d {
            wj.row_mut(i * d + k).scale_mut(wi);
            wr[i * d + k] *= wi;
        }
    }
    (jac.transpose() * &wj, jac.transpose() * &wr)
}

/// Weighted cost Σ w_i ‖r_i‖².
fn cost(norms: &[f64], w: &[f64]) -> f64 {
    norms.iter().zip(w).map(|(n, w)| w * n * n).sum()
}

/// Fit `opts.fit` of `nominal` to `data` (checked against `nominal` by
/// [`super::data::parse_measurements`]).
pub fn calibrate(
    nominal: &Robot,
    data: &Measurements,
    opts: &FitOptions,
) -> Result<Calibration, CalibError> {
    let started = Instant::now();
    if !(0.0..=0.5).contains(&opts.holdout_fraction) {
        return Err(CalibError::Options(format!(
            "the held-out fraction must be in [0, 0.5], got {}",
            opts.holdout_fraction
        )));
    }
    check_rows(nominal, data)?;
    let (rows, held) = split(data, opts.holdout_fraction, opts.seed);
    if rows.len() < opts.fit.len() {
        return Err(CalibError::TooFewRows {
            rows: rows.len(),
            params: opts.fit.len(),
        });
    }
    let use_orientation = opts.use_orientation && data.quaternions.is_some();
    let problem = Problem {
        nominal,
        nominal_values: Values::of(nominal),
        data,
        use_orientation,
        orientation_m_per_rad: opts.orientation_m_per_rad,
        settings: opts.settings,
    };
    let d = problem.dims();
    let nv = &problem.nominal_values;
    let mut solves = 0;

    // Identifiability before the fit, at the nominal values, with the
    // noise floor: what the rows cannot separate is fixed now.
    let mut v = nv.clone();
    let mut sols = problem.solve(&v, &rows, None)?;
    solves += rows.len();
    let (jac0, s0) = problem.jacobian(&v, &opts.fit, &rows, &sols)?;
    solves += s0;
    let ones = vec![1.0; rows.len()];
    let r0 = problem.residuals(&v, &rows, &tips(&sols));
    let (a0, _) = normal_equations(&jac0, &r0, &ones, d);
    let any_moment = data.tip_moments.iter().any(|m| m.iter().any(|x| *x != 0.0));
    let g_unseen =
        super::identify::shear_modulus_unseen(nominal, &opts.fit, use_orientation, any_moment);
    let candidates: Vec<Param> = match &g_unseen {
        Some(_) => (opts.fit.iter().copied())
            .filter(|p| *p != Param::ShearModulus)
            .collect(),
        None => opts.fit.clone(),
    };
    let keep: Vec<usize> = (0..opts.fit.len())
        .filter(|&j| candidates.contains(&opts.fit[j]))
        .collect();
    let a0 = DMatrix::from_fn(keep.len(), keep.len(), |i, j| a0[(keep[i], keep[j])]);
    let (mut free, mut unidentified) = identify(
        &a0,
        &candidates,
        opts.noise_floor_m,
        opts.identifiable_fraction,
    );
    unidentified.extend(g_unseen);

    let mut iterations = 0;
    let mut weights;
    let mut sigma;
    let (a, r) = loop {
        let (it, s) = levenberg_marquardt(&problem, &mut v, &free, &rows, &mut sols, opts)?;
        iterations += it;
        solves += s;
        // The covariance at the solution, with its final weights.
        let r = problem.residuals(&v, &rows, &tips(&sols));
        let norms = row_norms(&r, d);
        sigma = robust_sigma(&norms, d);
        weights = huber_weights(&norms, sigma, opts.huber_k);
        let (jac, s) = problem.jacobian(&v, &free, &rows, &sols)?;
        solves += s;
        let (a, _) = normal_equations(&jac, &r, &weights, d);
        let dof = (rows.len() * d).saturating_sub(free.len()).max(1);
        let var = cost(&norms, &weights) / dof as f64;
        let (still_free, more) = identify(
            &a,
            &free,
            var.sqrt().max(opts.noise_floor_m),
            opts.identifiable_fraction,
        );
        // Each round fixes at least one parameter, so this ends.
        if more.is_empty() {
            break (a, (r, var));
        }
        // Fixed after the fit: back to the nominal value, and fit again.
        for u in &more {
            if let Some(p) = free.iter().find(|p| p.to_string() == u.fixed) {
                v.set(*p, nv.get(*p));
            }
        }
        unidentified.extend(more);
        free = still_free;
        sols = problem.solve(&v, &rows, Some(&sols))?;
        solves += rows.len();
    };
    let (r_fit, var) = r;
    let cov = a
        .clone()
        .try_inverse()
        .map(|inv| inv * var)
        .unwrap_or_else(|| DMatrix::from_element(free.len(), free.len(), f64::NAN));

    let mut parameters = Vec::new();
    for &p in &opts.fit {
        let sc = scale(p, nv);
        let (std, fixed) = match free.iter().position(|&q| q == p) {
            Some(j) => (cov[(j, j)].max(0.0).sqrt() * sc, false),
            None => (f64::NAN, true),
        };
        parameters.push(FittedParam {
            name: p.to_string(),
            unit: p.unit().into(),
            nominal: nv.get(p),
            fitted: v.get(p),
            std,
            half_width_95: Z95 * std,
            fixed,
        });
    }
    let mut correlated = Vec::new();
    for i in 0..free.len() {
        for j in i + 1..free.len() {
            let c = cov[(i, j)] / (cov[(i, i)] * cov[(j, j)]).sqrt();
            if c.abs() > 0.95 {
                correlated.push((free[i].to_string(), free[j].to_string(), c));
            }
        }
    }

    // Before/after on every row, fit and held out.
    let all: Vec<usize> = (0..data.len()).collect();
    let before_sols = problem.solve(nv, &all, None)?;
    let after_sols = problem.solve(&v, &all, None)?;
    solves += 2 * all.len();
    let in_tracker = |values: &Values, sols: &[Solution]| -> Vec<[f64; 3]> {
        let to_tracker = values.base().to_tracker();
        sols.iter()
            .map(|s| to_tracker.point(s.position.into()))
            .collect()
    };
    let (before, after) = (in_tracker(nv, &before_sols), in_tracker(&v, &after_sols));
    let stats = |tips: &[[f64; 3]], idx: &[usize]| {
        ResidualStats::of(
            idx.iter()
                .map(|&i| (Vector3::from(data.positions[i]) - Vector3::from(tips[i])).norm()),
        )
    };
    let norms = row_norms(&r_fit, d);
    let mut downweighted: Vec<DownWeighted> = rows
        .iter()
        .zip(norms.iter().zip(&weights))
        .filter(|(_, (_, &w))| w < NAMED_WEIGHT)
        .map(|(&i, (&n, &w))| DownWeighted {
            line: data.lines[i],
            residual_m: n,
            weight: w,
        })
        .collect();
    downweighted.sort_by_key(|x| x.line);
    let robot = v.robot(nominal);
    let at_bound: Vec<String> = (free.iter())
        .filter(|&&p| {
            let (lo, hi) = bounds(p, nv);
            let tol = 1e-9 * scale(p, nv);
            v.get(p) <= lo + tol || v.get(p) >= hi - tol
        })
        .map(|p| p.to_string())
        .collect();
    let measured_tips: Vec<Vector3<f64>> =
        data.positions.iter().map(|&x| Vector3::from(x)).collect();
    let tension_scatter_m = (opts.tension_noise_n > 0.0)
        .then(|| problem.tension_scatter_m(&v, &rows, &sols, opts.tension_noise_n))
        .flatten();
    let evidence = super::verdict::Evidence {
        at_bound,
        median_spread_m: super::rows::median_spread_m(&measured_tips),
    };
    let mut report = Report {
        robot: nominal.name.clone(),
        rows_fit: rows.len(),
        rows_held_out: held.len(),
        used_orientation: problem.use_orientation,
        fd_step_relative: FD_STEP,
        parameters,
        unidentifiable: unidentified,
        correlated,
        residual_sigma_m: var.sqrt(),
        robust_sigma_m: sigma,
        tension_noise_n: opts.tension_noise_n,
        tension_scatter_m,
        rows_with_weight_below_1: weights.iter().filter(|&&w| w < 1.0).count(),
        downweighted,
        fit_before: stats(&before, &rows),
        fit_after: stats(&after, &rows),
        held_out_before: stats(&before, &held),
        held_out_after: stats(&after, &held),
        iterations,
        solves,
        seconds: started.elapsed().as_secs_f64(),
        verdict: Default::default(),
    };
    report.verdict = super::verdict::judge(&report, &evidence);
    let mut held_out = vec![false; data.len()];
    for &i in &held {
        held_out[i] = true;
    }
    Ok(Calibration {
        robot,
        values: v,
        report,
        measured: data.positions.clone(),
        before,
        after,
        held_out,
    })
}

/// A step smaller than this (in θ = p / scale) keeps the Jacobian for the
/// next iteration: over a step of a few per cent of each parameter's scale
/// the sensitivities move by about as much, which changes the next step's
/// direction, not the point the fit converges to (the fit only stops on a
/// fresh Jacobian). Measured on the calibration benchmark's rows
/// (BENCHMARKS.md, "Calibration fit time").
const KEEP_JACOBIAN_STEP: f64 = 0.05;
/// Iterations a Jacobian is kept for at most: kept longer, the IRLS
/// weights' drift turns the fit's last digits into a slow creep (the
/// benchmark's first fit ran into the 40-iteration cap).
const KEPT_JACOBIAN_ITERATIONS: usize = 1;
/// Tries of a kept Jacobian that does not lower the cost before it is
/// refreshed (a fresh one gets the usual dozen as λ grows).
const KEPT_JACOBIAN_TRIES: usize = 2;

/// Levenberg–Marquardt with Marquardt's diagonal scaling on θ = p / scale,
/// the Huber weights recomputed from the residuals at each iterate (IRLS),
/// every step projected into the bounds. The Jacobian is kept over small
/// steps ([`KEEP_JACOBIAN_STEP`]) and refreshed after a large one, when a
/// kept one finds no lower cost, and before the fit stops: the fit ends
/// only on a fresh Jacobian, so where it stops is the stationary point of
/// the true one. Updates `v` and `sols`; returns iterations and solves
/// spent.
fn levenberg_marquardt(
    problem: &Problem<'_>,
    v: &mut Values,
    free: &[Param],
    rows: &[usize],
    sols: &mut Vec<Solution>,
    opts: &FitOptions,
) -> Result<(usize, usize), CalibError> {
    let d = problem.dims();
    let nv = &problem.nominal_values;
    let mut lambda = 1e-3;
    let mut solves = 0;
    let mut iterations = 0;
    if free.is_empty() {
        return Ok((0, 0));
    }
    let mut kept: Option<DMatrix<f64>> = None;
    let mut kept_for = 0;
    for _ in 0..opts.max_iterations {
        iterations += 1;
        let r = problem.residuals(v, rows, &tips(sols));
        let norms = row_norms(&r, d);
        let w = huber_weights(&norms, robust_sigma(&norms, d), opts.huber_k);
        let c0 = cost(&norms, &w);
        let fresh = kept.is_none();
        let jac = match kept.take() {
            Some(jac) => jac,
            None => {
                let (jac, s) = problem.jacobian(v, free, rows, sols)?;
                solves += s;
                jac
            }
        };
        // J = ∂r/∂θ, so a step δ leaves the residual r + J δ: the damped
        // normal equations (JᵀWJ + λ diag) δ = −JᵀW r.
        let (a, g) = normal_equations(&jac, &r, &w, d);
        let mut accepted = None;
        let lambda_before = lambda;
        for _ in 0..if fresh { 12 } else { KEPT_JACOBIAN_TRIES } {
            let mut damped = a.clone();
            for j in 0..free.len() {
                damped[(j, j)] += lambda * a[(j, j)].max(1e-30);
            }
            let Some(delta) = damped.cholesky().map(|c| -c.solve(&g)) else {
                lambda *= 4.0;
                continue;
            };
            let mut trial = v.clone();
            let mut step = 0.0f64;
            for (j, &p) in free.iter().enumerate() {
                let sc = scale(p, nv);
                let (lo, hi) = bounds(p, nv);
                let x = (v.get(p) + delta[j] * sc).clamp(lo, hi);
                step = step.max(((x - v.get(p)) / sc).abs());
                trial.set(p, x);
            }
            let trial_sols = match problem.solve(&trial, rows, Some(sols)) {
                Ok(s) => s,
                Err(_) => {
                    lambda *= 4.0;
                    continue;
                }
            };
            solves += rows.len();
            let c1 = cost(
                &row_norms(&problem.residuals(&trial, rows, &tips(&trial_sols)), d),
                &w,
            );
            if c1 < c0 {
                accepted = Some((trial, trial_sols, step, c1));
                lambda = (lambda / 3.0).max(1e-12);
                break;
            }
            lambda *= 4.0;
        }
        let Some((trial, trial_sols, step, c1)) = accepted else {
            if fresh {
                break;
            }
            // A kept Jacobian found nothing lower: refresh it, and try
            // again from the damping it had.
            lambda = lambda_before;
            continue;
        };
        *v = trial;
        *sols = trial_sols;
        let converged = step < 1e-10 || c0 - c1 <= 1e-14 * c0;
        if converged && fresh {
            break;
        }
        if !converged && step < KEEP_JACOBIAN_STEP && kept_for < KEPT_JACOBIAN_ITERATIONS {
            kept = Some(jac);
            kept_for += 1;
        } else {
            kept_for = 0;
        }
    }
    Ok((iterations, solves))
}
