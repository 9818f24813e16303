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

use std::sync::Arc;

use nalgebra::{Matrix3, Matrix6, SMatrix, Vector3, Vector6};

use super::friction::{FrictionError, TensionProfile};

use super::integrate::{integrate, integrate_sampled, integrate_sampled_states};
use super::pose::{orthonormalise, quaternion_wxyz};
use super::rod::{Rod, RodState, SingularSystem};
use super::tangent::{integrate_with_sensitivity, FullSensitivity, ShootingSensitivity};
use crate::robot::{Robot, TensionError, MAX_TENDONS};

/// Most RK4 steps over the length a solve accepts (`tendril fk --steps`):
/// 6000 times the default, far past where the discretisation error meets
/// roundoff, and a solve there still takes well under a second.
pub const MAX_STEPS: usize = 100_000;

/// Discretisation and convergence settings of the statics solve.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverSettings {
    /// RK4 steps over the length. 16 puts the default robot's tip within
    /// 1e-7 m of the converged answer (see `BENCHMARKS.md`).
    pub steps: usize,
    /// Convergence: Euclidean norm of the tip residual [force N; moment N·m].
    pub tol: f64,
    /// Newton iterations before giving up.
    pub max_iter: usize,
    /// A warm solve predicted by dx/dτ ([`Statics::add_tension_sensitivity`])
    /// may end on a chord step that no further pass verifies, when that
    /// step moves the tip by at most this (m): the tip is then the last
    /// pass's, moved by the carried ∂tip/∂x, and the solution says so
    /// ([`Solution::extrapolated`]). The step contracts the residual
    /// 10–1000-fold, so the tip's error is a few percent of this bound
    /// (`docs/design.md` §2, "Solve"). 0, the default: every solve ends on
    /// a pass whose residual is below `tol`.
    #[serde(default)]
    pub final_step_m: f64,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            steps: 16,
            tol: 5e-10,
            max_iter: 60,
            final_step_m: 0.0,
        }
    }
}

/// dx/dτ: how the shooting unknowns x = [n(0); u(0)] of a solution move
/// with the tensions, one column per tendon (the unused columns zero).
pub type TensionSensitivity = SMatrix<f64, 6, MAX_TENDONS>;

/// ∂tip/∂x: how the tip pose of the rod integrated from the unknowns x
/// moves with them, one column per unknown; rows 0..3 the position (m),
/// rows 3..12 the orientation R, column by column.
pub type TipSensitivity = SMatrix<f64, 12, 6>;

/// A tip pose as twelve numbers: position (m), then R column by column.
pub(super) type PoseVector = SMatrix<f64, 12, 1>;

/// The tip pose of `tip` as a [`PoseVector`].
pub(super) fn pose_vector(tip: &RodState) -> PoseVector {
    let mut v = PoseVector::zeros();
    v.fixed_rows_mut::<3>(0).copy_from(&tip.p);
    v.fixed_rows_mut::<9>(3).copy_from_slice(tip.rot.as_slice());
    v
}

/// What a previous solve leaves for the next nearby one.
#[derive(Clone, Debug, PartialEq)]
pub struct WarmStart {
    /// Unknowns [n(0) (N); u(0) (1/m)].
    pub x: Vector6<f64>,
    /// Residual Jacobian at or near `x` (the last one Newton used).
    pub jacobian: Matrix6<f64>,
    /// The analytic guess ([`Rod::initial_guess`]) for the tensions and tip
    /// load solved: without `dx_dtau`, or when the tip load changed, a warm
    /// solve starts from `x` moved by how much the guess moves.
    guess: Vector6<f64>,
    /// The tensions solved for (the first `tendons` entries), N.
    tensions: [f64; MAX_TENDONS],
    tendons: usize,
    /// The tip force and moment solved for (base frame).
    load: [Vector3<f64>; 2],
    /// dx/dτ near `x`: the first-order prediction of the next solve's
    /// unknowns, x + (dx/dτ) Δτ. `None` until a warm solve (or
    /// [`WarmStart::set_tension_sensitivity`]) provides it.
    // Boxed: 432 bytes that most solutions (a dataset's, a batch's) never
    // carry would otherwise sit in every `Solution` (`fk --input` keeps a
    // chunk of 4,096 of them).
    dx_dtau: Option<Box<TensionSensitivity>>,
    /// ∂tip/∂x near `x`, carried with `dx_dtau` when the solver may end on
    /// an unverified chord step ([`SolverSettings::final_step_m`]).
    tip_dx: Option<Box<TipSensitivity>>,
}

impl WarmStart {
    /// The tensions this warm start was solved for, N.
    pub fn tensions(&self) -> &[f64] {
        &self.tensions[..self.tendons]
    }

    /// dx/dτ carried for the next solve's prediction, if any.
    pub fn tension_sensitivity(&self) -> Option<&TensionSensitivity> {
        self.dx_dtau.as_deref()
    }

    /// Carries `dx_dtau` (e.g. from the tip Jacobian's pass, which has it
    /// for free: `inverse::jacobian`) for the next solve's prediction.
    pub fn set_tension_sensitivity(&mut self, dx_dtau: TensionSensitivity) {
        if dx_dtau.iter().all(|v| v.is_finite()) {
            self.dx_dtau = Some(Box::new(dx_dtau));
        }
    }

    /// The change of tensions from this warm start to `tensions`, when the
    /// tip load is the same (`None` otherwise: the prediction covers only
    /// the tensions).
    fn tension_step(
        &self,
        tensions: &[f64],
        load: &[Vector3<f64>; 2],
    ) -> Option<SMatrix<f64, MAX_TENDONS, 1>> {
        if tensions.len() != self.tendons || *load != self.load {
            return None;
        }
        let mut d = SMatrix::<f64, MAX_TENDONS, 1>::zeros();
        for (i, t) in tensions.iter().enumerate() {
            d[i] = t - self.tensions[i];
        }
        Some(d)
    }
}

/// A converged statics solution.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Tip position, base frame, m.
    pub position: Vector3<f64>,
    /// Tip orientation quaternion (w, x, y, z), w ≥ 0.
    pub quaternion: [f64; 4],
    /// Tip orientation (orthonormalised), columns = body axes in the base frame.
    pub rotation: Matrix3<f64>,
    /// Norm of the tip residual at the solution; when `extrapolated`, an
    /// estimate: the last pass's residual times the least contraction a
    /// carried Jacobian is trusted with.
    pub residual: f64,
    /// Whether the solve ended on a chord step that no pass verified
    /// ([`SolverSettings::final_step_m`]): the pose is then the last
    /// pass's tip moved by ∂tip/∂x, within a few percent of that bound.
    pub extrapolated: bool,
    /// Newton iterations used.
    pub iterations: usize,
    /// Rod passes used, in plain-pass equivalents: a pass with
    /// sensitivities, which gives the Jacobian, counts as
    /// [`SENSITIVITY_PASS_COST`] times its share of the solver's steps.
    pub integrations: f64,
    /// Warm start for a neighbouring solve.
    pub warm: WarmStart,
    tensions: Vec<f64>,
    /// The capstan friction profile solved with (`docs/design.md` §2.3), if any.
    profile: Option<Arc<TensionProfile>>,
}

impl Solution {
    /// The pose as the dataset stores it: px, py, pz (m), qw, qx, qy, qz.
    pub fn pose(&self) -> [f64; 7] {
        let p = &self.position;
        let q = &self.quaternion;
        [p.x, p.y, p.z, q[0], q[1], q[2], q[3]]
    }

    /// The tendon tensions solved for, N (with friction: the motors').
    pub fn tensions(&self) -> &[f64] {
        &self.tensions
    }

    /// The capstan friction profile this was solved with; `None` for the
    /// frictionless model.
    pub fn profile(&self) -> Option<&Arc<TensionProfile>> {
        self.profile.as_ref()
    }

    /// Base internal force n(0), N.
    pub fn base_force(&self) -> Vector3<f64> {
        self.warm.x.fixed_rows::<3>(0).into()
    }
}

/// Why a statics solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The tension vector does not fit the robot.
    #[error(transparent)]
    BadTensions(#[from] TensionError),
    /// An external load is NaN or infinite.
    #[error("external tip load is not finite")]
    BadLoad,
    /// Newton did not reach the tolerance.
    #[error("statics did not converge: tip residual {residual:.3e} after {iterations} iterations")]
    NotConverged {
        /// Residual norm reached.
        residual: f64,
        /// Iterations spent.
        iterations: usize,
    },
    /// The equilibrium found is unstable: a conjugate point lies on the rod
    /// (`stability`), so a real rod would not stay there.
    #[error(
        "the equilibrium is unstable (a conjugate point at s = {conjugate_at_m:.4} m of the \
         backbone): a real rod would buckle or snap away from it, so it is not an answer"
    )]
    Unstable {
        /// Arc length of the first conjugate point, m.
        conjugate_at_m: f64,
    },
    /// Loading the rod from rest to the asked tip load, the equilibrium
    /// branch turned unstable (a bifurcation) or ended (a fold) on the way:
    /// which equilibrium the rod reaches is not unique.
    #[error(
        "the equilibrium is not unique: loading the rod from rest, its equilibrium turns \
         unstable or ends (a bifurcation or fold, where the rod would buckle or snap) at \
         {percent:.1} % of the tip load",
        percent = load_fraction * 100.0
    )]
    NonUnique {
        /// Fraction of the asked tip load where it happened, 0..1.
        load_fraction: f64,
    },
    /// Continuation from rest spent its budget of load steps
    /// (`continuation`) before reaching the full tip load: the load is too
    /// large for the grid to follow (more RK4 steps may), not a proven fold.
    #[error(
        "statics did not converge: loading the rod from rest, the solve could not follow its \
         equilibrium past {percent:.1} % of the tip load (a load this large may need more \
         --steps)",
        percent = load_fraction * 100.0
    )]
    Stalled {
        /// Fraction of the tip load reached, 0..1.
        load_fraction: f64,
    },
    /// The strain-rate system of the rod could not be solved at the start
    /// of the solve (`docs/design.md` §2: it is positive definite for any
    /// physical robot, so this means non-physical numbers).
    #[error(transparent)]
    Singular(#[from] SingularSystem),
    /// The friction numbers or state do not fit (`docs/design.md` §2.3).
    #[error(transparent)]
    BadFriction(#[from] FrictionError),
}

/// Forward statics of one robot: tensions (and optional tip load) → tip pose.
#[derive(Clone, Debug)]
pub struct Statics {
    robot: Robot,
    settings: SolverSettings,
    rod: Rod,
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
    fn solve_rod(
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
const TIP_COLUMNS_COST: f64 = 1.06;

/// The Jacobian is integrated on a grid this many times coarser than the
/// solve's. Newton needs the Jacobian only to pick its steps: the residual,
/// and so the answer, is always the fine grid's. A Jacobian from a grid 8×
/// coarser differs from the fine one by about the coarse grid's relative
/// discretisation error (RK4: 8⁴ ≈ 4000× the fine grid's), so a step still
/// cuts the residual 20- to 1000-fold (measured on the default robot), at an
/// eighth of the cost: −37 % instructions per cold solve against the
/// fine-grid Jacobian (callgrind, 2026-12-02; 4× coarser gave −32 %).
const JACOBIAN_COARSENING: usize = 8;

/// RK4 steps of the pass that gives Newton its Jacobian in a solve with
/// `steps` steps: [`JACOBIAN_COARSENING`] times fewer, at least 2.
pub fn jacobian_steps(steps: usize) -> usize {
    (steps / JACOBIAN_COARSENING).max(2).min(steps.max(1))
}

/// Halvings of a step along a fresh Newton direction before giving up.
const MAX_HALVINGS: usize = 8;
/// A step that cuts the residual to less than this fraction keeps its
/// Jacobian for the next step (a chord step, one plain pass); otherwise the
/// next step gets a fresh Jacobian (a coarse pass with sensitivities, cheaper
/// than the several chord steps a weaker contraction would need).
const CHORD_CONTRACTION: f64 = 0.01;
/// [`CHORD_CONTRACTION`] for a solve started from a first-order prediction
/// with a carried Jacobian (`Shooting::newton`'s `trust`).
const TRUSTED_CHORD_CONTRACTION: f64 = 0.1;
/// How much a step with a warm start's Jacobian cuts the residual when the
/// tensions moved (measured 0.01–0.07 for a 0.1 N change on the default
/// robot). A warm start whose residual this would not bring under the
/// tolerance in one step gets a fresh Jacobian first.
const STALE_CONTRACTION: f64 = 0.05;

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
    fn jacobian(&self, x: &Vector6<f64>, grid: Grid) -> Option<Matrix6<f64>> {
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
    fn jacobian_cost(&self, grid: Grid) -> f64 {
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
enum Grid {
    /// [`jacobian_steps`] steps.
    Coarse,
    /// The solve's own steps.
    Fine,
}
