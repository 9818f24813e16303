//! The fit's sensitivities (`docs/design.md` §11, "Sensitivities"):
//! d(residuals)/dθ from the statics' tangent — each row's solved tip moved
//! by the implicit function theorem ([`crate::statics::implicit`]) — with
//! central differences through warm-started solves as the fallback and the
//! reference the tests hold the tangent to.

use nalgebra::{DMatrix, DVector, Vector6};
use rayon::prelude::*;

use super::params::{scale, Param, Values};
use super::problem::{tips, ModelTip, Problem, FD_STEP};
use super::CalibError;
use crate::statics::{Solution, SolverSettings, Statics, TipVector, UnknownsTangent};

/// Relative step of the explicit part's one-sided difference (of the
/// parameter's scale, as [`FD_STEP`]).
const EXPLICIT_STEP: f64 = 1e-7;
/// The tangent's passes (the six x columns, and the explicit part's plain
/// passes) run on a grid this many times coarser than the solves' ...
/// Twice coarser, every column of the Jacobian is within 0.5 % of the
/// solves' on the default and the two-segment robot (a test; four times
/// coarser was not, on the latter). A Jacobian's error moves where the fit
/// converges by a like fraction of a parameter's uncertainty, not its
/// residuals (BENCHMARKS.md, "Calibration fit time").
const TANGENT_COARSENING: usize = 2;
/// ... of at least this many RK4 steps.
const MIN_TANGENT_STEPS: usize = 4;

impl Problem<'_> {
    /// d(residuals)/dθ for the fitted parameters at `v` (θ_j = p_j / scale_j)
    /// from the statics' tangent: each row's solved tip moves by the
    /// implicit function theorem (`statics::implicit`), the explicit part by
    /// a one-sided difference of one plain pass a parameter at the row's
    /// unknowns; the residuals of the tips so moved (± the change over the
    /// parameter's [`FD_STEP`]) are differenced. Falls back to
    /// [`Problem::jacobian_by_solves`] when a row's tangent or pass meets a
    /// singular system. Returns the Jacobian and the solves spent (none).
    pub(super) fn jacobian(
        &self,
        v: &Values,
        params: &[Param],
        rows: &[usize],
        sols: &[Solution],
    ) -> Result<(DMatrix<f64>, usize), CalibError> {
        let grid = SolverSettings {
            steps: (self.settings.steps / TANGENT_COARSENING).max(MIN_TANGENT_STEPS),
            ..self.settings
        };
        let base = Statics::new(&v.solving_robot(self.nominal), grid);
        // Each row's tangent, and its tip and residual at its own unknowns
        // (the base point of the one-sided explicit part).
        let tangents: Option<Vec<(UnknownsTangent, TipVector, Vector6<f64>)>> = rows
            .par_iter()
            .enumerate()
            .map(|(k, &i)| {
                let (tip, res) =
                    base.at_unknowns_of(&sols[k], &v.scaled_tensions(&self.data.tensions[i]))?;
                Some((base.unknowns_tangent(&sols[k])?, tip, res))
            })
            .collect();
        let Some(tangents) = tangents else {
            return self.jacobian_by_solves(v, params, rows, sols);
        };
        let at = tips(sols);
        let mut jac = DMatrix::zeros(rows.len() * self.dims(), params.len());
        for (j, &p) in params.iter().enumerate() {
            let h = FD_STEP * scale(p, &self.nominal_values);
            let moved = |sign: f64| {
                let mut vp = v.clone();
                vp.set(p, v.get(p) + sign * h);
                vp
            };
            let (vp, vm) = (moved(1.0), moved(-1.0));
            let (plus, minus) = if p.moves_rod() {
                // The explicit part, one-sided over a step EXPLICIT_STEP /
                // FD_STEP times the parameter's: a plain pass has no
                // solver tolerance to drown a small step, and the implicit
                // correction cancels most of the explicit change, which
                // magnifies a one-sided step's O(h) error (2 % on the
                // two-segment robot's tension scales at FD_STEP).
                let mut vx = v.clone();
                vx.set(p, v.get(p) + EXPLICIT_STEP * scale(p, &self.nominal_values));
                let sx = Statics::new(&vx.solving_robot(self.nominal), grid);
                let per_step = FD_STEP / EXPLICIT_STEP;
                let changes: Option<Vec<TipVector>> = rows
                    .par_iter()
                    .enumerate()
                    .map(|(k, &i)| {
                        let tau = &self.data.tensions[i];
                        let (tip_x, res_x) =
                            sx.at_unknowns_of(&sols[k], &vx.scaled_tensions(tau))?;
                        let (tangent, tip, res) = &tangents[k];
                        Some(tangent.solved(&(tip_x - tip), &(res_x - res)) * per_step)
                    })
                    .collect();
                let Some(changes) = changes else {
                    return self.jacobian_by_solves(v, params, rows, sols);
                };
                let side = |sign: f64| -> Vec<ModelTip> {
                    sols.iter()
                        .zip(&changes)
                        .map(|(s, d)| ModelTip::moved(s, d, sign))
                        .collect()
                };
                (
                    self.residuals(&vp, rows, &side(1.0)),
                    self.residuals(&vm, rows, &side(-1.0)),
                )
            } else {
                (
                    self.residuals(&vp, rows, &at),
                    self.residuals(&vm, rows, &at),
                )
            };
            // d r / d θ = scale × d r / d p.
            jac.set_column(j, &((plus - minus) / (2.0 * FD_STEP)));
        }
        Ok((jac, 0))
    }

    /// The tip scatter per axis, m, that `sigma_n` of independent noise on
    /// every recorded tension makes at `v`: the RMS over `rows` of
    /// σ_τ √(Σ_i ‖∂p/∂τ_i‖² / 3), ∂p/∂τ_i by the implicit function theorem
    /// (one tangent pass and a plain pass per tendon a row). `None` when a
    /// tangent is singular.
    pub(super) fn tension_scatter_m(
        &self,
        v: &Values,
        rows: &[usize],
        sols: &[Solution],
        sigma_n: f64,
    ) -> Option<f64> {
        let statics = Statics::new(&v.solving_robot(self.nominal), self.settings);
        // A step far below any tension, far above the pass's rounding.
        const H_N: f64 = 1e-5;
        let squares: Option<Vec<f64>> = rows
            .par_iter()
            .enumerate()
            .map(|(k, &i)| {
                let recorded = &self.data.tensions[i];
                let tangent = statics.unknowns_tangent(&sols[k])?;
                let (tip, res) = statics.at_unknowns_of(&sols[k], &v.scaled_tensions(recorded))?;
                let mut sum = 0.0;
                for t in 0..recorded.len() {
                    let mut moved = recorded.clone();
                    moved[t] += H_N;
                    let (tip_t, res_t) =
                        statics.at_unknowns_of(&sols[k], &v.scaled_tensions(&moved))?;
                    let d = tangent.solved(&(tip_t - tip), &(res_t - res)) / H_N;
                    sum += d.fixed_rows::<3>(0).norm_squared();
                }
                Some(sum / 3.0)
            })
            .collect();
        let squares = squares?;
        Some(sigma_n * (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt())
    }

    /// [`Problem::jacobian`] by central differences through warm-started
    /// solves: `sols` seed every perturbed solve.
    pub(super) fn jacobian_by_solves(
        &self,
        v: &Values,
        params: &[Param],
        rows: &[usize],
        sols: &[Solution],
    ) -> Result<(DMatrix<f64>, usize), CalibError> {
        let m = rows.len() * self.dims();
        let mut jac = DMatrix::zeros(m, params.len());
        let mut solves = 0;
        for (j, &p) in params.iter().enumerate() {
            let h = FD_STEP * scale(p, &self.nominal_values);
            let mut side = |sign: f64| -> Result<DVector<f64>, CalibError> {
                let mut vp = v.clone();
                vp.set(p, v.get(p) + sign * h);
                if p.moves_rod() {
                    let s = self.solve(&vp, rows, Some(sols))?;
                    solves += rows.len();
                    Ok(self.residuals(&vp, rows, &tips(&s)))
                } else {
                    Ok(self.residuals(&vp, rows, &tips(sols)))
                }
            };
            let plus = side(1.0)?;
            let minus = side(-1.0)?;
            // d r / d θ = scale × d r / d p.
            jac.set_column(j, &((plus - minus) / (2.0 * FD_STEP)));
        }
        Ok((jac, solves))
    }
}
