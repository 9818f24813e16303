//! The tip metric of the polish phase (`docs/design.md` §4, "Polish"): what an error
//! in the net's output costs at the tip, row by row.
//!
//! A tension error Δτ moves the tip by J Δτ to first order, J = ∂pose/∂τ the
//! tip Jacobian at the row's solution (`inverse::jacobian`, rows
//! [∂p/∂τ; ∂θ/∂τ]). With the output normalisation τ = lo + y (hi − lo),
//! D = diag(hi − lo), an output error e moves the tip by J D e, so
//!
//! ```text
//! M_r = Dᵀ (J_pᵀ J_p + ℓ² J_θᵀ J_θ) D / s  +  κ I
//! ```
//!
//! is the squared tip displacement (position, and orientation at ℓ metres
//! per radian, the exact IK's weight: the backbone length) the error
//! causes. `s` scales the mean of trace(M)/O to one, so the polish's step
//! sizes and RMSE stay on the plain loss's scale; κ keeps a little of the
//! plain squared error, so directions the tip hardly sees are not left to
//! drift. The command stage's shift along a co-contraction set's weights
//! (which the centred targets leave out) bends nothing, so J of the
//! centred error is J of the commanded one up to the set's axial part.

use std::sync::atomic::AtomicBool;

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::polish::RowMetrics;
use crate::inverse::tip_jacobian;
use crate::learn::LearnError;
use crate::robot::Robot;
use crate::statics::batch::{solve_all, Load};
use crate::statics::rod::Rod;
use crate::statics::{Solution, SolverSettings, Statics};

/// Share of the plain squared error kept beside the tip's (κ).
pub const PLAIN_SHARE: f64 = 0.05;

/// The tip metric of every row of `tensions` (N, `n × T`, the dataset's own
/// tensions, not the centred targets), for outputs normalised by `span`
/// (hi − lo per tendon). A row whose statics or Jacobian fails gets the
/// mean metric of the rows that did not. `None` when `stop` was set.
pub fn tip_metrics(
    robot: &Robot,
    tensions: &DMatrix<f64>,
    span: &[f64],
    stop: &AtomicBool,
    done: &(dyn Fn(usize) + Sync),
) -> Result<Option<RowMetrics>, LearnError> {
    let t = robot.n_tendons();
    if tensions.ncols() != t || span.len() != t {
        return Err(LearnError::BadData(format!(
            "tip metric: {} tension columns and {} output spans for a robot with {t} tendons",
            tensions.ncols(),
            span.len()
        )));
    }
    let settings = SolverSettings::default();
    let statics = Statics::new(robot, settings);
    let rod = Rod::new(robot);
    let loads: Vec<Load> = (0..tensions.nrows())
        .map(|r| Load::tensions(tensions.row(r).iter().copied().collect()))
        .collect();
    let Some(solutions) = solve_all(&statics, &loads, stop, done) else {
        return Ok(None);
    };
    let raw: Vec<Option<Vec<f64>>> = solutions
        .par_iter()
        .zip(loads.par_iter())
        .map(|(sol, load)| {
            raw_metric(
                &rod,
                robot.length,
                settings.steps,
                sol.as_ref().ok()?,
                &load.tensions,
                span,
            )
        })
        .collect();
    let good: Vec<&Vec<f64>> = raw.iter().flatten().collect();
    if good.is_empty() {
        return Err(LearnError::BadData(
            "tip metric: the statics solved none of the rows".into(),
        ));
    }
    let mut mean = vec![0.0; t * t];
    for m in &good {
        mean.iter_mut().zip(m.iter()).for_each(|(a, b)| *a += b);
    }
    mean.iter_mut().for_each(|v| *v /= good.len() as f64);
    let mean_trace: f64 = (0..t).map(|i| mean[i * t + i]).sum::<f64>() / t as f64;
    let s = if mean_trace > 0.0 { mean_trace } else { 1.0 };
    let failed = raw.iter().filter(|m| m.is_none()).count();
    if failed > 0 {
        log::info!(
            "tip metric: {failed} of {} rows did not solve; they get the mean metric",
            raw.len()
        );
    }
    let mut out = Vec::with_capacity(raw.len() * t * t);
    for m in &raw {
        let m = m.as_ref().unwrap_or(&mean);
        for i in 0..t {
            for c in 0..t {
                let plain = if i == c { PLAIN_SHARE } else { 0.0 };
                out.push(m[i * t + c] / s + plain);
            }
        }
    }
    Ok(Some(RowMetrics { outputs: t, m: out }))
}

/// Row-major Dᵀ (J_pᵀ J_p + ℓ² J_θᵀ J_θ) D at the solution `sol` of
/// `tensions`, before the scale s and the plain share; `None` where the
/// Jacobian cannot be formed or is not finite.
fn raw_metric(
    rod: &Rod,
    ell: f64,
    steps: usize,
    sol: &Solution,
    tensions: &[f64],
    span: &[f64],
) -> Option<Vec<f64>> {
    let mut rod = rod.clone();
    rod.set_tensions(tensions);
    let j = tip_jacobian(&rod, &sol.warm.x, steps).ok()?.jacobian;
    // J D: columns scaled to the normalised outputs.
    let jd = DMatrix::from_fn(6, span.len(), |i, c| j[(i, c)] * span[c]);
    let jp = jd.rows(0, 3);
    let jt = jd.rows(3, 3);
    let m = jp.transpose() * jp + (jt.transpose() * jt) * (ell * ell);
    // Symmetric, so its column-major storage is its row-major layout.
    m.iter()
        .all(|v| v.is_finite())
        .then(|| m.as_slice().to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::robot::repo_robot;

    /// The metric predicts the tip displacement of a small tension change:
    /// eᵀ M e against |Δp|² + ℓ²|Δθ|² from two statics solves.
    #[test]
    fn the_metric_is_the_squared_tip_displacement_of_an_output_error() {
        let robot = repo_robot("seed-4t.toml");
        let t = robot.n_tendons();
        let tau = [1.5, 0.2, 0.4, 0.3];
        let span = vec![2.0; t];
        let settings = SolverSettings::default();
        let statics = Statics::new(&robot, settings);
        let a = statics.solve(&tau, None).unwrap();
        let raw = raw_metric(
            &Rod::new(&robot),
            robot.length,
            settings.steps,
            &a,
            &tau,
            &span,
        )
        .unwrap();
        let e = [0.004, -0.003, 0.002, 0.001];
        let moved: Vec<f64> = (0..t).map(|i| tau[i] + span[i] * e[i]).collect();
        let b = statics.solve(&moved, None).unwrap();
        let dp = (b.position - a.position).norm_squared();
        let dth = nalgebra::Rotation3::from_matrix_unchecked(b.rotation * a.rotation.transpose())
            .scaled_axis()
            .norm_squared();
        let truth = dp + robot.length * robot.length * dth;
        let m = DMatrix::from_row_slice(t, t, &raw);
        let ev = nalgebra::DVector::from_column_slice(&e);
        let predicted = (ev.transpose() * &m * &ev)[(0, 0)];
        assert!(
            (predicted - truth).abs() < 1e-3 * truth,
            "eᵀMe {predicted:e} vs displacement² {truth:e}"
        );
        // tip_metrics scales it to a mean trace of one and adds the plain share.
        let rows = DMatrix::from_row_slice(1, t, &tau);
        let scaled = tip_metrics(&robot, &rows, &span, &AtomicBool::new(false), &|_| {})
            .unwrap()
            .unwrap();
        let s = m.trace() / t as f64;
        for (k, (got, r)) in scaled.m.iter().zip(&raw).enumerate() {
            let plain = if k % (t + 1) == 0 { PLAIN_SHARE } else { 0.0 };
            assert!(
                (got - (r / s + plain)).abs() < 1e-9,
                "entry {k}: {got} vs {}",
                r / s + plain
            );
        }
    }
}
