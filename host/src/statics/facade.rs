//! [`Statics`]: forward statics of one robot, tensions (and an optional tip
//! load) → the tip pose and the rod's shape; the public face of the
//! shooting solver ([`super::shoot`]).

use std::sync::Arc;

use nalgebra::{Vector3, Vector6};

use super::error::SolveError;
use super::integrate::{integrate, integrate_sampled, integrate_sampled_states};
use super::pose::{orthonormalise, quaternion_wxyz};
use super::profile::TensionProfile;
use super::rod::{Rod, RodState, SingularSystem};
use super::settings::SolverSettings;
use super::shoot::*;
use super::solution::{pose_vector, Solution, WarmStart};
use crate::robot::{Robot, MAX_TENDONS};

/// Forward statics of one robot: tensions (and optional tip load) → tip pose.
#[derive(Clone, Debug)]
pub struct Statics {
    pub(super) robot: Robot,
    pub(super) settings: SolverSettings,
    pub(super) rod: Rod,
}

impl Statics {
    /// The statics of `robot` with `settings`.
    pub fn new(robot: &Robot, settings: SolverSettings) -> Statics {
        Statics {
            robot: robot.clone(),
            settings,
            rod: Rod::new(robot),
        }
    }

    /// The robot this solves for.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The solver settings.
    pub fn settings(&self) -> &SolverSettings {
        &self.settings
    }

    /// Tip pose for `tensions` (N, one per tendon). `warm`: the warm start of a
    /// nearby solution, or `None` for a cold start.
    pub fn solve(
        &self,
        tensions: &[f64],
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        self.solve_loaded(tensions, Vector3::zeros(), Vector3::zeros(), warm)
    }

    /// As [`Statics::solve`], with an external tip force (N) and moment (N·m)
    /// given in the base frame.
    pub fn solve_loaded(
        &self,
        tensions: &[f64],
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        self.solve_rod(tensions, None, tip_force, tip_moment, warm)
    }

    /// As [`Statics::solve`], with capstan friction: `tensions` are the
    /// motors' (at s = 0) and `profile` says how each tendon's tension
    /// changes along its path (`docs/design.md` §2.3; built by
    /// [`super::friction::FrictionState`]). `None` is [`Statics::solve`].
    pub(crate) fn solve_with_profile(
        &self,
        tensions: &[f64],
        profile: Option<Arc<TensionProfile>>,
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        self.solve_rod(tensions, profile, Vector3::zeros(), Vector3::zeros(), warm)
    }

    /// The shooting solve of this robot's rod under `tensions`, friction
    /// `profile` and tip load.
    pub(super) fn solve_rod(
        &self,
        tensions: &[f64],
        profile: Option<Arc<TensionProfile>>,
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        self.robot.check_tensions(tensions)?;
        if !(tip_force.iter().all(|x| x.is_finite()) && tip_moment.iter().all(|x| x.is_finite())) {
            return Err(SolveError::BadLoad);
        }
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        rod.set_profile(profile);
        let problem = Shooting {
            rod: &rod,
            steps: self.settings.steps,
            jacobian_steps: jacobian_steps(self.settings.steps),
            f_ext: tip_force,
            m_ext: tip_moment,
            track_rotation: rod.f_e != Vector3::zeros()
                || tip_force != Vector3::zeros()
                || tip_moment != Vector3::zeros(),
        };
        let warm_ok = warm.filter(|w| {
            w.x.iter().all(|v| v.is_finite()) && w.jacobian.iter().all(|v| v.is_finite())
        });
        let guess = rod.initial_guess(&tip_force, &tip_moment);
        let load = [tip_force, tip_moment];
        // dx/dτ for the next solve: this solve's prediction, Broyden-updated
        // with the step it turned out to be.
        let mut carried = None;
        // ∂tip/∂x for the next solve, when this one may end unverified.
        let mut carried_tip_dx = None;
        let result = match warm_ok {
            Some(w) => match (w.dx_dtau.as_deref(), w.tension_step(tensions, &load)) {
                // First-order prediction x + (dx/dτ) Δτ, corrected by chord
                // steps with the carried Jacobian.
                (Some(s), Some(dtau)) => {
                    let x_p = w.x + s * dtau;
                    let mut tip_dx = w
                        .tip_dx
                        .as_deref()
                        .copied()
                        .filter(|_| self.settings.final_step_m > 0.0);
                    // The pass at the prediction is taken here when the solve
                    // may end unverified, so that one which goes on to verify
                    // has the secant of ∂tip/∂x from it.
                    let first = tip_dx.map(|_| problem.residual(&x_p));
                    let out = problem.newton(
                        x_p,
                        Some(w.jacobian),
                        true,
                        tip_dx.as_ref().map(|t| (t, first)),
                        &self.settings,
                    );
                    if let Ok(ok) = &out {
                        // Broyden's update of dx/dτ: exact along the step
                        // just taken, for the next solve of a chain.
                        let n2 = dtau.norm_squared();
                        carried = Some(if n2 > 0.0 {
                            s + (ok.x - w.x - s * dtau) * dtau.transpose() / n2
                        } else {
                            *s
                        });
                        // And of ∂tip/∂x, along the steps this solve verified
                        // (at one tension vector: the tip moves with τ too).
                        if let (Some(t), Some((_, Some(tip_p)))) = (tip_dx.as_mut(), first) {
                            let step = ok.x - x_p;
                            let n2 = step.norm_squared();
                            if !ok.extrapolated && n2 > 0.0 {
                                let moved = pose_vector(&ok.tip) - pose_vector(&tip_p);
                                *t += (moved - *t * step) * step.transpose() / n2;
                            }
                        }
                        carried_tip_dx = tip_dx.filter(|t| t.iter().all(|v| v.is_finite()));
                    }
                    out
                }
                // Without dx/dτ (or with another tip load): x moved by the
                // change of the analytic guess.
                _ => problem.newton(
                    w.x + (guess - w.guess),
                    Some(w.jacobian),
                    false,
                    None,
                    &self.settings,
                ),
            },
            None => Err((f64::INFINITY, 0, 0.0)),
        };
        // A warm start that fails (a far neighbour) falls back to a cold start
        // from the analytic guess rather than reporting failure.
        let ok = match result {
            Ok(ok) => ok,
            Err((_, it0, int0)) => {
                match problem.newton(guess, None, false, None, &self.settings) {
                    Ok(ok) => NewtonOk {
                        iterations: ok.iterations + it0,
                        integrations: ok.integrations + int0,
                        ..ok
                    },
                    Err((residual, it, _)) => {
                        // A singular system at the start point is the cause
                        // worth naming, not the NaN residual it leads to.
                        problem.tip(&guess)?;
                        return Err(SolveError::NotConverged {
                            residual,
                            iterations: it + it0,
                        });
                    }
                }
            }
        };
        let mut solution = self.solution(ok, guess, tensions);
        solution.profile = rod.profile().cloned();
        solution.warm.load = load;
        if let Some(s) = carried.filter(|s| s.iter().all(|v| v.is_finite())) {
            solution.warm.dx_dtau = Some(Box::new(s));
            solution.warm.tip_dx = carried_tip_dx.map(Box::new);
        }
        Ok(solution)
    }

    /// The rod of a solution of this robot: its tensions and friction profile.
    pub(super) fn solution_rod(&self, sol: &Solution) -> Rod {
        let mut rod = self.rod.clone();
        rod.set_tensions(&sol.tensions);
        rod.set_profile(sol.profile.clone());
        rod
    }

    /// The rod of this robot under `tensions` (checked by the caller).
    pub(super) fn rod_for(&self, tensions: &[f64]) -> Rod {
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        rod
    }

    /// The [`Solution`] of a Newton solve that ended at `ok` for `tensions`
    /// and the tip load whose analytic guess is `guess`.
    pub(super) fn solution(&self, ok: NewtonOk, guess: Vector6<f64>, tensions: &[f64]) -> Solution {
        let rotation = orthonormalise(&ok.tip.rot);
        Solution {
            position: ok.tip.p,
            quaternion: quaternion_wxyz(&rotation),
            rotation,
            residual: ok.residual,
            extrapolated: ok.extrapolated,
            iterations: ok.iterations,
            integrations: ok.integrations,
            warm: WarmStart {
                x: ok.x,
                jacobian: ok.jacobian,
                guess,
                tensions: {
                    let mut t = [0.0; MAX_TENDONS];
                    t[..tensions.len()].copy_from_slice(tensions);
                    t
                },
                tendons: tensions.len(),
                load: [Vector3::zeros(); 2],
                dx_dtau: None,
                tip_dx: None,
            },
            tensions: tensions.to_vec(),
            profile: None,
        }
    }

    /// Backbone points (base frame, m) at `points` ≥ 2 evenly spaced arc
    /// lengths, for a converged `sol` of this robot. Integrated on a grid at
    /// least as fine as the solver's.
    pub fn shape(&self, sol: &Solution, points: usize) -> Vec<Vector3<f64>> {
        let rod = self.solution_rod(sol);
        let base = base_state(&rod, &sol.warm.x);
        // The solve integrated this rod from this base without a singular
        // system; the finer grid can only differ by roundoff near one.
        integrate_sampled(&rod, base, self.settings.steps, points).unwrap_or_default()
    }

    /// The backbone as [`Statics::shape`], and each tendon's path beside it
    /// (base frame, m; a tendon's path stops at its anchor): what a run log
    /// draws.
    pub fn shape_with_tendons(&self, sol: &Solution, points: usize) -> RodShape {
        let rod = self.solution_rod(sol);
        let base = base_state(&rod, &sol.warm.x);
        let states =
            integrate_sampled_states(&rod, base, self.settings.steps, points).unwrap_or_default();
        let backbone = states.iter().map(|(_, y)| y.p).collect();
        let tendons = (0..rod.n_tendons)
            .map(|i| {
                states
                    .iter()
                    .filter_map(|(s, y)| rod.tendon_point(i, *s, y))
                    .collect()
            })
            .collect();
        RodShape { backbone, tendons }
    }

    /// Tip state for `tensions` integrated from the base unknowns `x`
    /// ([n(0); u(0)]) with `steps` RK4 steps — for convergence studies and
    /// independent checks of a solution.
    pub fn tip_state(
        &self,
        tensions: &[f64],
        x: &Vector6<f64>,
        steps: usize,
    ) -> Result<RodState, SingularSystem> {
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        integrate(&rod, base_state(&rod, x), steps)
    }
}

impl Statics {
    /// Gives `sol`'s warm start dx/dτ, the first-order prediction of a
    /// nearby solve's unknowns (`docs/design.md` §2, "Solve"), from one
    /// coarse-grid pass with the tension columns (≈ 0.9 plain passes on the
    /// default robot). A warm solve from it starts at x + (dx/dτ) Δτ and
    /// hands dx/dτ on, Broyden-updated with the step it took, so a chain of
    /// nearby solves (a plant, a path) pays this once. Without it a warm
    /// solve starts from the analytic guess's shift. With
    /// [`SolverSettings::final_step_m`] the pass also carries the tip's
    /// position and orientation, for ∂tip/∂x (6 % more). A pass
    /// that meets a singular system leaves `sol` as it was.
    pub fn add_tension_sensitivity(&self, sol: &mut Solution) {
        let rod = self.solution_rod(sol);
        let [f_ext, m_ext] = sol.warm.load;
        let problem = Shooting {
            rod: &rod,
            steps: self.settings.steps,
            jacobian_steps: jacobian_steps(self.settings.steps),
            f_ext,
            m_ext,
            track_rotation: rod.f_e != Vector3::zeros()
                || f_ext != Vector3::zeros()
                || m_ext != Vector3::zeros(),
        };
        let with_tip = self.settings.final_step_m > 0.0;
        if let Some(pass) = problem.tension_sensitivity(&sol.warm.x, with_tip) {
            sol.warm.set_tension_sensitivity(pass.dx_dtau);
            sol.warm.tip_dx = pass.tip_dx.map(Box::new);
            sol.integrations += problem.tension_sensitivity_cost(with_tip);
        }
    }
}
