//! Shooting on the base wrench: find n(0), u(0) such that the rod integrated
//! from the base meets the tip boundary condition.
//!
//! Root finder: Newton's method with the exact Jacobian of the shooting map,
//! integrated alongside the rod from the variational equations (`tangent`):
//! one pass gives residual and Jacobian, and Newton converges quadratically.
//! A Jacobian that keeps contracting the residual fast is reused (chord
//! steps, one plain pass each), and a warm start carries the previous
//! solution's together with dx/dτ, the shooting unknowns' sensitivity to the
//! tensions: a nearby solve starts from the unknowns predicted to first
//! order, x + (dx/dτ) Δτ, and corrects them with the carried Jacobian, so it
//! costs two to three plain passes. Allowed to (`SolverSettings::final_step_m`),
//! it ends on the first of those chord steps without a pass to verify it,
//! the tip moved by a carried ∂tip/∂x: one plain pass.
//! (The `levenberg-marquardt` crate was not used: it recomputes a full
//! finite-difference Jacobian every iteration, the cost this avoids.)

use nalgebra::{Matrix6, Vector3, Vector6};

use super::integrate::integrate;
use super::rod::{Rod, RodState, SingularSystem};
use super::settings::SolverSettings;
use super::solution::{TensionSensitivity, TipSensitivity};
use super::tangent::{integrate_with_sensitivity, FullSensitivity, ShootingSensitivity};

pub(super) fn base_state(rod: &Rod, x: &Vector6<f64>) -> RodState {
    RodState::at_base(
        &Vector3::new(x[0], x[1], x[2]),
        &Vector3::new(x[3], x[4], x[5]),
        &rod.kse,
    )
}

/// A solved rod's shape: what [`Statics::shape_with_tendons`] returns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RodShape {
    /// Backbone points, base to tip (base frame, m).
    pub backbone: Vec<Vector3<f64>>,
    /// Each tendon's path, base to its anchor (base frame, m).
    pub tendons: Vec<Vec<Vector3<f64>>>,
}

/// One shooting problem: the rod with its tensions and tip load.
#[derive(Clone, Copy)]
pub(super) struct Shooting<'a> {
    pub(super) rod: &'a Rod,
    pub(super) steps: usize,
    /// RK4 steps of the pass that gives the Jacobian ([`jacobian_steps`]).
    pub(super) jacobian_steps: usize,
    pub(super) f_ext: Vector3<f64>,
    pub(super) m_ext: Vector3<f64>,
    /// Whether the residual depends on the rotation (gravity or a tip load).
    pub(super) track_rotation: bool,
}

/// What a rod pass with sensitivities costs in plain passes of the same
/// steps (callgrind instruction counts on the default robot, 2026-12-02:
/// ≈ 400 k against ≈ 90 k instructions for 16 steps; BENCHMARKS.md).
pub const SENSITIVITY_PASS_COST: f64 = 4.5;

/// How much more the tension-sensitivity pass costs when it carries ∂p and
/// ∂R too (callgrind on the default robot, 2026-12-04: 117,959 against
/// 111,507 instructions).
pub(super) const TIP_COLUMNS_COST: f64 = 1.06;

/// The Jacobian is integrated on a grid this many times coarser than the
/// solve's. Newton needs the Jacobian only to pick its steps: the residual,
/// and so the answer, is always the fine grid's. A Jacobian from a grid 8×
/// coarser differs from the fine one by about the coarse grid's relative
/// discretisation error (RK4: 8⁴ ≈ 4000× the fine grid's), so a step still
/// cuts the residual 20- to 1000-fold (measured on the default robot), at an
/// eighth of the cost: −37 % instructions per cold solve against the
/// fine-grid Jacobian (callgrind, 2026-12-02; 4× coarser gave −32 %).
pub(super) const JACOBIAN_COARSENING: usize = 8;

/// RK4 steps of the pass that gives Newton its Jacobian in a solve with
/// `steps` steps: [`JACOBIAN_COARSENING`] times fewer, at least 2.
pub fn jacobian_steps(steps: usize) -> usize {
    (steps / JACOBIAN_COARSENING).max(2).min(steps.max(1))
}

/// Halvings of a step along a fresh Newton direction before giving up.
pub(super) const MAX_HALVINGS: usize = 8;
/// A step that cuts the residual to less than this fraction keeps its
/// Jacobian for the next step (a chord step, one plain pass); otherwise the
/// next step gets a fresh Jacobian (a coarse pass with sensitivities, cheaper
/// than the several chord steps a weaker contraction would need).
pub(super) const CHORD_CONTRACTION: f64 = 0.01;
/// [`CHORD_CONTRACTION`] for a solve started from a first-order prediction
/// with a carried Jacobian (`Shooting::newton`'s `trust`).
pub(super) const TRUSTED_CHORD_CONTRACTION: f64 = 0.1;
/// How much a step with a warm start's Jacobian cuts the residual when the
/// tensions moved (measured 0.01–0.07 for a 0.1 N change on the default
/// robot). A warm start whose residual this would not bring under the
/// tolerance in one step gets a fresh Jacobian first.
pub(super) const STALE_CONTRACTION: f64 = 0.05;

/// Where a Newton solve ended.
#[derive(Clone, Copy, Debug)]
pub(super) struct NewtonOk {
    /// The unknowns.
    pub x: Vector6<f64>,
    /// The tip state there (when `extrapolated`, only its pose is moved to
    /// `x`; w and u are the last pass's).
    pub tip: RodState,
    /// The Jacobian last used.
    pub jacobian: Matrix6<f64>,
    /// The residual norm (an estimate when `extrapolated`).
    pub residual: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Plain-pass equivalents spent.
    pub integrations: f64,
    /// Whether the last step was taken without a pass to verify it.
    pub extrapolated: bool,
}

/// dx/dτ and, when asked for, ∂tip/∂x from one pass
/// ([`Shooting::tension_sensitivity`]).
pub(super) struct TensionPass {
    pub dx_dtau: TensionSensitivity,
    pub tip_dx: Option<TipSensitivity>,
}
/// (best residual norm, iterations, integrations)
pub(super) type NewtonErr = (f64, usize, f64);
/// The residual at a point and the tip state it came from (`None` when the
/// pass met a singular system).
pub(super) type Residual = (Vector6<f64>, Option<RodState>);

impl Shooting<'_> {
    pub(super) fn tip(&self, x: &Vector6<f64>) -> Result<RodState, SingularSystem> {
        integrate(self.rod, base_state(self.rod, x), self.steps)
    }

    /// The tip residual at `x` and the tip state it came from; a singular
    /// system on the way makes the residual infinite, which the Newton
    /// iteration treats as a failed step.
    pub(super) fn residual(&self, x: &Vector6<f64>) -> Residual {
        match self.tip(x) {
            Ok(tip) => (
                self.rod.tip_residual(&tip, &self.f_ext, &self.m_ext),
                Some(tip),
            ),
            Err(_) => (Vector6::from_element(f64::INFINITY), None),
        }
    }

    /// The Jacobian of the residual at `x`, exact for the grid of `steps`
    /// steps: one pass of the rod with its sensitivities (`tangent`).
    /// `None` when that pass meets a singular system.
    pub(super) fn jacobian(&self, x: &Vector6<f64>, grid: Grid) -> Option<Matrix6<f64>> {
        let steps = match grid {
            Grid::Coarse => self.jacobian_steps,
            Grid::Fine => self.steps,
        };
        let start = ShootingSensitivity::at_base(&self.rod.kse, 0, self.track_rotation, false);
        let (tip, t) =
            integrate_with_sensitivity(self.rod, base_state(self.rod, x), steps, start).ok()?;
        Some(
            self.rod
                .tip_residual_jacobian(&tip, &t, &self.f_ext, &self.m_ext),
        )
    }

    /// dx/dτ = −R_x⁻¹ R_τ (implicit function theorem through r(x, τ) = 0)
    /// from one coarse-grid pass of the rod with the six x
    /// columns and one column per tendon, at `x`; with `with_tip`, the
    /// pass carries ∂p and ∂R as well, for ∂tip/∂x. `None` when that pass
    /// meets a singular system or R_x is singular.
    pub(super) fn tension_sensitivity(
        &self,
        x: &Vector6<f64>,
        with_tip: bool,
    ) -> Option<TensionPass> {
        let start = FullSensitivity::at_base(
            &self.rod.kse,
            self.rod.n_tendons,
            self.track_rotation || with_tip,
            with_tip,
        );
        let (tip, t) = integrate_with_sensitivity(
            self.rod,
            base_state(self.rod, x),
            self.jacobian_steps,
            start,
        )
        .ok()?;
        let r = self
            .rod
            .tip_residual_jacobian(&tip, &t, &self.f_ext, &self.m_ext);
        let r_x: Matrix6<f64> = r.fixed_columns::<6>(0).into_owned();
        let lu = r_x.lu();
        let mut s = TensionSensitivity::zeros();
        for i in 0..self.rod.n_tendons {
            let r_tau: Vector6<f64> = r.column(6 + i).into();
            s.set_column(i, &lu.solve(&(-r_tau))?);
        }
        let tip_dx = with_tip.then(|| {
            let mut tip_dx = TipSensitivity::zeros();
            for j in 0..6 {
                tip_dx.fixed_view_mut::<3, 1>(0, j).copy_from(&t.p[j]);
                tip_dx
                    .fixed_view_mut::<9, 1>(3, j)
                    .copy_from_slice(t.rot[j].as_slice());
            }
            tip_dx
        });
        let finite = s.iter().all(|v| v.is_finite())
            && tip_dx.is_none_or(|t| t.iter().all(|v| v.is_finite()));
        finite.then_some(TensionPass { dx_dtau: s, tip_dx })
    }

    /// What a [`Shooting::tension_sensitivity`] pass costs in plain passes:
    /// a coarse Jacobian pass with (6 + tendons)/6 times the columns, and
    /// a little more when it carries ∂p and ∂R (`with_tip`).
    pub(super) fn tension_sensitivity_cost(&self, with_tip: bool) -> f64 {
        let columns = self.jacobian_cost(Grid::Coarse) * (6 + self.rod.n_tendons) as f64 / 6.0;
        if with_tip {
            columns * TIP_COLUMNS_COST
        } else {
            columns
        }
    }

    /// What a [`Shooting::jacobian`] pass costs in plain passes.
    pub(super) fn jacobian_cost(&self, grid: Grid) -> f64 {
        match grid {
            Grid::Coarse => SENSITIVITY_PASS_COST * self.jacobian_steps as f64 / self.steps as f64,
            Grid::Fine => SENSITIVITY_PASS_COST,
        }
    }

    /// Newton's method from `x0`: steps from a Jacobian of the coarse grid
    /// ([`jacobian_steps`]), kept while it keeps contracting the residual
    /// fast (a chord step costs one plain rod pass) and refreshed when it does
    /// not; backtracking when a step does not reduce the residual. A fresh
    /// coarse Jacobian that gives no descent at all is replaced by the fine
    /// grid's before the solve gives up. `j0`: a Jacobian from a nearby
    /// solution (warm start), used while it contracts; `trust`: use it even
    /// when one step would not reach the tolerance (the start is a
    /// first-order prediction, whose residual a few chord steps remove more
    /// cheaply than a fresh Jacobian and a step). `finish`: ∂tip/∂x near
    /// `x0`, with which the first chord step may end the solve unverified
    /// ([`SolverSettings::final_step_m`]), and the pass at `x0` when the
    /// caller has taken it.
    pub(super) fn newton(
        &self,
        x0: Vector6<f64>,
        j0: Option<Matrix6<f64>>,
        trust: bool,
        finish: Option<(&TipSensitivity, Option<Residual>)>,
        settings: &SolverSettings,
    ) -> Result<NewtonOk, NewtonErr> {
        let mut x = x0;
        // From a first-order prediction the residual is small and the
        // carried Jacobian contracts it ~100-fold per step (measured 0.005–0.02
        // on the default robot, 0.1 N changes): keep it while it contracts
        // at least 10-fold, cheaper than a fresh one.
        let chord_contraction = if trust {
            TRUSTED_CHORD_CONTRACTION
        } else {
            CHORD_CONTRACTION
        };
        let (mut r, mut tip) = match finish {
            Some((_, Some(first))) => first,
            _ => self.residual(&x),
        };
        let mut integrations = 1.0;
        let mut norm = r.norm();
        // The Jacobian in use and, when it was computed at the current x and
        // not updated since, on which grid.
        let (mut jac, mut fresh) = match j0 {
            Some(j) if trust || norm * STALE_CONTRACTION < settings.tol || !norm.is_finite() => {
                (j, None)
            }
            _ => {
                integrations += self.jacobian_cost(Grid::Coarse);
                match self.jacobian(&x, Grid::Coarse) {
                    Some(j) => (j, Some(Grid::Coarse)),
                    None => return Err((f64::INFINITY, 0, integrations)),
                }
            }
        };
        for iter in 0..settings.max_iter {
            if !norm.is_finite() {
                return Err((norm, iter, integrations));
            }
            if norm < settings.tol {
                if let Some(tip) = tip {
                    return Ok(NewtonOk {
                        x,
                        tip,
                        jacobian: jac,
                        residual: norm,
                        iterations: iter,
                        integrations,
                        extrapolated: false,
                    });
                }
            }
            let step = jac
                .lu()
                .solve(&(-r))
                .filter(|d| d.iter().all(|v| v.is_finite()));
            // The prediction's chord step, ended without a pass to verify it
            // when it moves the tip by at most `final_step_m`.
            if let (0, Some((tip_dx, _)), Some(dx), Some(at)) = (iter, finish, step, tip) {
                let moved = tip_dx * dx;
                let dp: Vector3<f64> = moved.fixed_rows::<3>(0).into();
                if dp.norm() <= settings.final_step_m {
                    let mut end = at;
                    end.p += dp;
                    for (r, d) in end.rot.iter_mut().zip(moved.fixed_rows::<9>(3).iter()) {
                        *r += d;
                    }
                    return Ok(NewtonOk {
                        x: x + dx,
                        tip: end,
                        jacobian: jac,
                        residual: norm * TRUSTED_CHORD_CONTRACTION,
                        iterations: 1,
                        integrations,
                        extrapolated: true,
                    });
                }
            }
            let mut refresh = None;
            let mut accepted = false;
            if let Some(dx) = step {
                // Backtracking on the residual norm; near the solution the
                // full step is taken. A stale Jacobian gets one try only.
                let tries = if fresh.is_some() { MAX_HALVINGS } else { 1 };
                let mut alpha = 1.0;
                for _ in 0..tries {
                    let x_try = x + dx * alpha;
                    let (r_try, tip_try) = self.residual(&x_try);
                    integrations += 1.0;
                    let n_try = r_try.norm();
                    if n_try.is_finite() && n_try < (1.0 - 1e-4 * alpha) * norm {
                        let contraction = n_try / norm;
                        // Broyden's rank-one update keeps a reused Jacobian
                        // consistent with the step just taken (superlinear
                        // chord steps for the price of plain passes).
                        let s = dx * alpha;
                        jac += (r_try - r - jac * s) * s.transpose() / s.norm_squared();
                        x = x_try;
                        r = r_try;
                        tip = tip_try;
                        norm = n_try;
                        accepted = true;
                        // A full step that cut the residual well keeps its
                        // Jacobian for the next (chord) step; otherwise the
                        // next step gets a fresh one.
                        if (alpha < 1.0 || contraction > chord_contraction) && norm >= settings.tol
                        {
                            refresh = Some(Grid::Coarse);
                        }
                        break;
                    }
                    alpha *= 0.5;
                }
            }
            if !accepted {
                refresh = match fresh {
                    None => Some(Grid::Coarse),
                    Some(Grid::Coarse) => Some(Grid::Fine),
                    Some(Grid::Fine) => return Err((norm, iter + 1, integrations)),
                };
            }
            fresh = None;
            if let Some(grid) = refresh {
                integrations += self.jacobian_cost(grid);
                match self.jacobian(&x, grid) {
                    Some(j) => {
                        jac = j;
                        fresh = Some(grid);
                    }
                    None => return Err((f64::INFINITY, iter + 1, integrations)),
                }
            }
        }
        match tip {
            Some(tip) if norm < settings.tol => Ok(NewtonOk {
                x,
                tip,
                jacobian: jac,
                residual: norm,
                iterations: settings.max_iter,
                integrations,
                extrapolated: false,
            }),
            _ => Err((norm, settings.max_iter, integrations)),
        }
    }
}

/// Which grid a Jacobian is integrated on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Grid {
    /// [`jacobian_steps`] steps.
    Coarse,
    /// The solve's own steps.
    Fine,
}
