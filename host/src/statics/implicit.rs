//! How a solution moves with the rod's parameters — E, G, ρ, L, the tendons'
//! offsets and angles, the tensions — without solving again
//! (`docs/design.md` §11, "Sensitivities"). A solution is the tip of the rod
//! integrated from the unknowns x* where the tip residual r(x, θ) vanishes,
//! so by the implicit function theorem
//!
//! ```text
//! dtip/dθ = ∂tip/∂θ − (∂tip/∂x) R_x⁻¹ ∂r/∂θ,     R_x = ∂r/∂x,
//! ```
//!
//! where ∂tip/∂θ and ∂r/∂θ are taken at the fixed x* (plain passes of the
//! changed rod: [`Statics::at_unknowns_of`]) and ∂tip/∂x and R_x come from
//! one pass with the six x columns on the solve's own grid, exact for the
//! discrete map (`tangent.rs`: [`Statics::unknowns_tangent`]). A calibration's
//! Jacobian then costs a plain pass per parameter and side instead of a warm
//! solve (≈ 6 plain passes).

use nalgebra::{SMatrix, SVector, Vector6};

use super::facade::Statics;
use super::shoot::{base_state, jacobian_steps, Shooting};
use super::solution::{pose_vector, Solution};
use super::tangent::{integrate_with_sensitivity, ShootingSensitivity};

/// A tip pose as twelve numbers: position (m), then the rotation R column by
/// column.
pub type TipVector = SVector<f64, 12>;

/// (∂tip/∂x) R_x⁻¹ at a solution: what turns a change of the tip and the
/// residual at fixed unknowns into the change of the solved tip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnknownsTangent {
    k: SMatrix<f64, 12, 6>,
}

impl UnknownsTangent {
    /// The solved tip's change: δtip − (∂tip/∂x) R_x⁻¹ δr, from the change
    /// of the tip `d_tip` and of the residual `d_residual` at fixed x.
    pub fn solved(&self, d_tip: &TipVector, d_residual: &Vector6<f64>) -> TipVector {
        d_tip - self.k * d_residual
    }
}

impl Statics {
    /// The shooting problem of `sol`'s tensions, tip load and friction
    /// profile on this statics' rod, and that rod.
    fn with_problem<T>(
        &self,
        sol: &Solution,
        tensions: &[f64],
        f: impl FnOnce(&Shooting<'_>) -> Option<T>,
    ) -> Option<T> {
        let mut rod = self.rod_for(tensions);
        rod.set_profile(sol.profile.clone());
        let [f_ext, m_ext] = sol.warm.load;
        let problem = Shooting {
            rod: &rod,
            steps: self.settings.steps,
            jacobian_steps: jacobian_steps(self.settings.steps),
            f_ext,
            m_ext,
            track_rotation: true,
        };
        f(&problem)
    }

    /// [`UnknownsTangent`] at `sol` (a solution of this statics): one pass
    /// with the six x columns carrying ∂p and ∂R, on the solve's grid.
    /// `None` when the pass meets a singular system or R_x is singular.
    pub fn unknowns_tangent(&self, sol: &Solution) -> Option<UnknownsTangent> {
        self.with_problem(sol, &sol.tensions, |p| {
            let start = ShootingSensitivity::at_base(&p.rod.kse, 0, true, true);
            let (tip, t) =
                integrate_with_sensitivity(p.rod, base_state(p.rod, &sol.warm.x), p.steps, start)
                    .ok()?;
            let r_x = p.rod.tip_residual_jacobian(&tip, &t, &p.f_ext, &p.m_ext);
            let mut tip_x = SMatrix::<f64, 12, 6>::zeros();
            for j in 0..6 {
                tip_x.fixed_view_mut::<3, 1>(0, j).copy_from(&t.p[j]);
                tip_x
                    .fixed_view_mut::<9, 1>(3, j)
                    .copy_from_slice(t.rot[j].as_slice());
            }
            // K = T_x R_x⁻¹, i.e. R_xᵀ Kᵀ = T_xᵀ.
            let kt = r_x.transpose().lu().solve(&tip_x.transpose())?;
            let k = kt.transpose();
            k.iter()
                .all(|v| v.is_finite())
                .then_some(UnknownsTangent { k })
        })
    }

    /// The tip (as a [`TipVector`]) and the tip residual of *this* statics'
    /// rod under `tensions` (checked by the caller), integrated from the
    /// unknowns of `sol` — a solution of a neighbouring robot — with its
    /// tip load and profile: one plain pass, no solve. `None` on a
    /// singular system.
    pub fn at_unknowns_of(
        &self,
        sol: &Solution,
        tensions: &[f64],
    ) -> Option<(TipVector, Vector6<f64>)> {
        self.with_problem(sol, tensions, |p| {
            let (residual, tip) = p.residual(&sol.warm.x);
            Some((pose_vector(&tip?), residual))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::repo_robot;
    use crate::statics::SolverSettings;

    /// dtip/dθ by the implicit function theorem against central
    /// differences of converged solves (to 1e-12 N), for E, ρ, a tendon's
    /// offset and angle, L and a tension, on the default robot under gravity
    /// and on the two-segment robot across its anchors (no gravity, so no ρ).
    #[test]
    fn the_implicit_derivative_is_the_derivative_of_the_solved_tip() {
        let tight = SolverSettings {
            tol: 1e-12,
            ..SolverSettings::default()
        };
        for (file, tau) in [
            ("seed-4t.toml", vec![2.0, 0.5, 0.0, 0.3]),
            ("tdcr-2seg.toml", vec![3.0, 0.5, 1.0, 0.0, 2.0, 0.5]),
            (
                "tdcr-2seg.toml",
                vec![4.888903309754697, 2.7687334241083734, 0.0, 0.0, 0.0, 0.0],
            ),
        ] {
            let robot = repo_robot(file);
            let statics = Statics::new(&robot, tight);
            let sol = statics.solve(&tau, None).unwrap();
            let k = statics.unknowns_tangent(&sol).expect("a tangent");
            type Change = Box<dyn Fn(&mut crate::robot::Robot, &mut Vec<f64>, f64)>;
            let changes: Vec<(&str, Change, f64)> = vec![
                ("E", Box::new(|r, _, h| r.youngs_modulus *= 1.0 + h), 1e-5),
                ("ρ", Box::new(|r, _, h| r.density *= 1.0 + h), 1e-5),
                (
                    "offset 1",
                    Box::new(|r, _, h| r.tendons[1].offset += h * 1e-2),
                    1e-5,
                ),
                ("angle 1", Box::new(|r, _, h| r.tendons[1].angle += h), 1e-5),
                (
                    "L",
                    Box::new(|r, _, h| {
                        r.length *= 1.0 + h;
                        r.tendons.iter_mut().for_each(|t| t.end *= 1.0 + h);
                    }),
                    1e-5,
                ),
                ("τ0", Box::new(|_, t, h| t[0] += h), 1e-5),
            ];
            for (name, change, h) in &changes {
                if *name == "ρ" && robot.gravity.norm() == 0.0 {
                    continue; // weight moves nothing without gravity
                }
                let side = |sign: f64| {
                    let (mut r, mut t) = (robot.clone(), tau.clone());
                    change(&mut r, &mut t, sign * h);
                    (Statics::new(&r, tight), t)
                };
                let ((sp, tp), (sm, tm)) = (side(1.0), side(-1.0));
                let (tip_p, res_p) = sp.at_unknowns_of(&sol, &tp).unwrap();
                let (tip_m, res_m) = sm.at_unknowns_of(&sol, &tm).unwrap();
                let implicit = k.solved(&(tip_p - tip_m), &(res_p - res_m)) / (2.0 * h);
                let solved =
                    |s: &Statics, t: &[f64]| pose_vector_of(&s.solve(t, Some(&sol.warm)).unwrap());
                let by_solves = (solved(&sp, &tp) - solved(&sm, &tm)) / (2.0 * h);
                let scale = by_solves.norm();
                assert!(scale > 1e-6, "{file} {name}: no sensitivity to test");
                let err = (implicit - by_solves).norm() / scale;
                assert!(
                    err < 1e-5,
                    "{file} {name}: {err:.2e} relative ({implicit} vs {by_solves})"
                );
            }
        }
    }

    fn pose_vector_of(sol: &Solution) -> TipVector {
        let mut v = TipVector::zeros();
        v.fixed_rows_mut::<3>(0).copy_from(&sol.position);
        v.fixed_rows_mut::<9>(3)
            .copy_from_slice(sol.rotation.as_slice());
        v
    }
}
