//! The equilibrium a real rod reaches: continuation from zero tip load and
//! the stability test of every solution on the way (`docs/design.md` §2.3).
//!
//! A shooting solve started cold from the analytic guess finds *an*
//! equilibrium, not necessarily the one a rod loaded from rest reaches:
//! under a large tip load Newton can land on a branch bent back on itself,
//! and a straight column above its buckling load is an equilibrium too.
//! [`Statics::equilibrium`] therefore solves the unloaded rod (tensions and
//! weight) first, then ramps the tip load λ·(F, M), λ: 0 → 1, warm-starting
//! each step from the last with a tangent predictor and halving the step when
//! the corrector fails or jumps. Every accepted step passes the stability test
//! (`stability`); a step that is not stable means the branch from rest turned
//! unstable (a bifurcation) or folded between the two loads, and the answer
//! is reported as not unique rather than printed.
//!
//! Cost: a solve without tip load costs the plain solve plus one stability
//! pass (a pass with rotation sensitivities, ≈ 5–6 plain passes); a tip load
//! adds a corrector and a stability pass per load step (BENCHMARKS.md). The
//! hot loops (dataset generation, the plant) keep [`Statics::solve`].

use nalgebra::{Vector3, Vector6};

use super::shoot::{base_state, NewtonOk, Shooting, SENSITIVITY_PASS_COST};
use super::stability::{stability_pass, StabilityPass};
use super::{Solution, SolveError, Statics, WarmStart};

/// The first load step, as a fraction of the tip load; also the largest.
const FIRST_STEP: f64 = 0.25;
/// A load step below this fraction ends the continuation: the branch from
/// rest ends (a fold) or the solver cannot follow it.
const MIN_STEP: f64 = 1.0 / 4096.0;
/// Most corrector solves one continuation spends (a bound on its time).
const MAX_SOLVES: usize = 400;
/// A corrector that moves the unknowns (scaled, see [`scale`]) further than
/// this fraction of the predictor's step, plus [`CORRECTION_FLOOR`], has
/// jumped towards another branch: the step is halved instead.
const MAX_CORRECTION: f64 = 0.5;
/// The absolute part of the jump test (scaled unknowns).
const CORRECTION_FLOOR: f64 = 1e-6;
/// Residual tolerance per newton of tip load (a moment counts as moment / L):
/// the roundoff floor of the tip residual grows with the load — on the
/// default robot under a 9 N lateral tip force Newton stalls near 9e-9 N
/// at 16 steps, taking 50–60 iterations a step. 1e-8 N per N moves the tip
/// by ~2e-9 m per N, below the discretisation error (1e-7 m at 16 steps).
const LOAD_RELATIVE_TOL: f64 = 1e-8;
/// Largest predicted change of the scaled unknowns ([`scale`]) in one load
/// step: an Euler predictor much further than this sent the corrector to
/// another branch (the default robot under a 50 N lateral tip force).
const MAX_PREDICTED: f64 = 1.0;
/// The stability pass's cost in plain passes: a sensitivity pass on the
/// solve's own grid that carries ∂R as well.
const STABILITY_PASS_COST: f64 = SENSITIVITY_PASS_COST * 1.3;

impl Statics {
    /// The stable equilibrium a rod loaded from rest reaches under
    /// `tensions` (N) and a tip force (N) and moment (N·m) in the base frame.
    /// Without a tip load this is [`Statics::solve`] (`warm` as there) plus
    /// the stability test; with one, continuation from zero tip load (module
    /// doc). Errors: [`SolveError::Unstable`] when the solution has a
    /// conjugate point, [`SolveError::NonUnique`] when the branch from rest
    /// turns unstable or ends before the full load, and those of
    /// [`Statics::solve_loaded`].
    pub fn equilibrium(
        &self,
        tensions: &[f64],
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        let loaded = tip_force != Vector3::zeros() || tip_moment != Vector3::zeros();
        if !(tip_force.iter().all(|x| x.is_finite()) && tip_moment.iter().all(|x| x.is_finite())) {
            return Err(SolveError::BadLoad);
        }
        let rest = self.solve_loaded(
            tensions,
            Vector3::zeros(),
            Vector3::zeros(),
            warm.filter(|_| !loaded),
        )?;
        if !loaded && !self.may_lose_stability_unloaded() {
            return Ok(rest);
        }
        let rod = self.rod_for(tensions);
        let steps = self.settings().steps;
        let zero = Vector3::zeros();
        let pass = stability_pass(&rod, base_state(&rod, &rest.warm.x), steps, &zero, &zero)?;
        if let Some(s) = pass.conjugate_at_m {
            return Err(SolveError::Unstable { conjugate_at_m: s });
        }
        if !loaded {
            let mut sol = rest;
            sol.integrations += STABILITY_PASS_COST;
            return Ok(sol);
        }
        self.continue_load(tensions, tip_force, tip_moment, rest, pass)
    }

    /// Whether a rod without tip load can be in an unstable equilibrium
    /// here: only when its weight has a component along the base axis (a
    /// standing or hanging column: Greenhill's self-weight buckling) or a
    /// tendon is not straight (helical routing can snap). Straight tendons at
    /// fixed tension compress the rod without buckling it (their pull follows
    /// the rod), and weight across the base axis bends it without
    /// compressing the straight rod: those equilibria are stable — every
    /// pose of a 3ⁿ tension grid to the limits on `seed-4t` and `tdcr-2seg`
    /// passes the test (`tendon_poses_are_stable_and_unchanged_by_the_test`)
    /// — and skipping the test keeps `fk --input` of tension-only rows at
    /// the plain solve's cost (the test more than doubled it).
    fn may_lose_stability_unloaded(&self) -> bool {
        let robot = self.robot();
        robot.weight_per_length().z != 0.0 || robot.tendons.iter().any(|t| !t.is_straight())
    }

    /// The stability test alone (`stability`) of a converged `sol` of this
    /// robot under the tip load it was solved for (base frame, N and N·m):
    /// [`SolveError::Unstable`] when a conjugate point lies on the rod.
    pub fn check_stable(
        &self,
        sol: &Solution,
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
    ) -> Result<(), SolveError> {
        let rod = self.rod_for(sol.tensions());
        let base = base_state(&rod, &sol.warm.x);
        let pass = stability_pass(&rod, base, self.settings().steps, &tip_force, &tip_moment)?;
        match pass.conjugate_at_m {
            Some(s) => Err(SolveError::Unstable { conjugate_at_m: s }),
            None => Ok(()),
        }
    }

    /// Ramp the tip load from 0 (the solution `rest` with its stability
    /// `pass`) to (F, M): the continuation of the module doc.
    fn continue_load(
        &self,
        tensions: &[f64],
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
        rest: Solution,
        mut pass: StabilityPass,
    ) -> Result<Solution, SolveError> {
        let rod = self.rod_for(tensions);
        let mut settings = *self.settings();
        let load = tip_force.norm() + tip_moment.norm() / self.robot().length;
        settings.tol = settings.tol.max(LOAD_RELATIVE_TOL * load);
        let scale = scale(self);
        let mut x = rest.warm.x;
        let mut rotation = rest.rotation;
        let mut iterations = rest.iterations;
        let mut integrations = rest.integrations + STABILITY_PASS_COST;
        let mut lambda = 0.0;
        let mut step = FIRST_STEP;
        for _ in 0..MAX_SOLVES {
            // Tangent predictor: r(x, λ) = r₀(x) + λ [Rᵀ F; Rᵀ M], so
            // dx/dλ = −J⁻¹ [Rᵀ F; Rᵀ M]. The step is cut so that the
            // predicted change of the scaled unknowns stays within
            // MAX_PREDICTED.
            let f = rotation.tr_mul(&tip_force);
            let m = rotation.tr_mul(&tip_moment);
            let dr = Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z);
            let slope = pass
                .jacobian
                .lu()
                .solve(&(-dr))
                .filter(|d| d.iter().all(|v| v.is_finite()))
                .unwrap_or_else(Vector6::zeros);
            let rate = slope.component_mul(&scale).norm();
            if rate * step > MAX_PREDICTED {
                step = (MAX_PREDICTED / rate).max(MIN_STEP);
            }
            let target = (lambda + step).min(1.0);
            let problem = Shooting {
                rod: &rod,
                steps: settings.steps,
                // The coarse grid's Jacobian is too poor for a rod bent
                // through most of a right angle (the corrector stalled for
                // thousands of iterations on 16 steps): the fine one.
                jacobian_steps: settings.steps,
                f_ext: tip_force * target,
                m_ext: tip_moment * target,
                track_rotation: true,
            };
            let predicted = slope * (target - lambda);
            let x_pred = x + predicted;
            let corrected = problem
                .newton(x_pred, Some(pass.jacobian), false, None, &settings)
                .map_err(|(_, it, int)| (it, int));
            let accepted = match corrected {
                Ok(ok) => {
                    iterations += ok.iterations;
                    integrations += ok.integrations;
                    let jump = (ok.x - x_pred).component_mul(&scale).norm();
                    let limit =
                        MAX_CORRECTION * predicted.component_mul(&scale).norm() + CORRECTION_FLOOR;
                    (jump <= limit).then_some(ok)
                }
                Err((it, int)) => {
                    iterations += it;
                    integrations += int;
                    None
                }
            };
            // An unstable corrector result is either the branch turning
            // unstable or a jump to another branch: a shorter step tells.
            let next = match accepted {
                Some(ok) => {
                    let next = stability_pass(
                        &rod,
                        base_state(&rod, &ok.x),
                        settings.steps,
                        &problem.f_ext,
                        &problem.m_ext,
                    )?;
                    integrations += STABILITY_PASS_COST;
                    next.conjugate_at_m.is_none().then_some((ok, next))
                }
                None => None,
            };
            let Some((ok, next)) = next else {
                if step <= MIN_STEP {
                    return Err(SolveError::NonUnique {
                        load_fraction: lambda,
                    });
                }
                step = (step * 0.5).max(MIN_STEP);
                continue;
            };
            pass = next;
            x = ok.x;
            rotation = ok.tip.rot;
            lambda = target;
            if lambda >= 1.0 {
                let guess = rod.initial_guess(&tip_force, &tip_moment);
                return Ok(self.solution(
                    NewtonOk {
                        iterations,
                        integrations,
                        ..ok
                    },
                    guess,
                    tensions,
                ));
            }
            step = (step * 2.0).min(FIRST_STEP);
        }
        Err(SolveError::Stalled {
            load_fraction: lambda,
        })
    }
}

/// Scale of the unknowns [n(0); u(0)] that makes them dimensionless: forces
/// by EI/L², curvatures by 1/L.
fn scale(statics: &Statics) -> Vector6<f64> {
    let robot = statics.robot();
    let l = robot.length;
    let ei = robot.kbt().x;
    let f = l * l / ei;
    Vector6::new(f, f, f, l, l, l)
}
