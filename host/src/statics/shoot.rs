//! Shooting on the base wrench: find n(0), u(0) such that the rod integrated
//! from the base meets the tip boundary condition.
//!
//! Root finder: damped Newton with Broyden rank-one Jacobian updates. The
//! Jacobian is built by forward differences only when needed: at a cold start,
//! or when a Broyden-updated Jacobian stops giving descent. A warm start
//! carries the previous solution's Jacobian, so a nearby solve usually costs
//! two or three integrations instead of the seven a finite-difference Newton
//! step needs. (The `levenberg-marquardt` crate was not used: it recomputes a
//! full Jacobian every iteration, which is exactly the cost this avoids.)

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use super::integrate::{integrate, integrate_sampled};
use super::pose::{orthonormalise, quaternion_wxyz};
use super::rod::{Rod, RodState, SingularSystem};
use crate::robot::{Robot, TensionError};

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
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            steps: 16,
            tol: 5e-10,
            max_iter: 60,
        }
    }
}

/// What a previous solve leaves for the next nearby one.
#[derive(Clone, Debug, PartialEq)]
pub struct WarmStart {
    /// Unknowns [n(0) (N); u(0) (1/m)].
    pub x: Vector6<f64>,
    /// Residual Jacobian at `x` (possibly Broyden-updated).
    pub jacobian: Matrix6<f64>,
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
    /// Norm of the tip residual at the solution.
    pub residual: f64,
    /// Newton iterations used.
    pub iterations: usize,
    /// Rod passes used (a finite-difference Jacobian adds seven passes on a
    /// half-resolution grid).
    pub integrations: usize,
    /// Warm start for a neighbouring solve.
    pub warm: WarmStart,
    tensions: Vec<f64>,
}

impl Solution {
    /// The pose as the dataset stores it: px, py, pz (m), qw, qx, qy, qz.
    pub fn pose(&self) -> [f64; 7] {
        let p = &self.position;
        let q = &self.quaternion;
        [p.x, p.y, p.z, q[0], q[1], q[2], q[3]]
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
    /// The strain-rate system of the rod could not be solved at the start
    /// of the solve (`docs/design.md` §2: it is positive definite for any
    /// physical robot, so this means non-physical numbers).
    #[error(transparent)]
    Singular(#[from] SingularSystem),
}

/// Forward statics of one robot: tensions (and optional tip load) → tip pose.
#[derive(Clone, Debug)]
pub struct Statics {
    robot: Robot,
    settings: SolverSettings,
    rod: Rod,
}

/// Finite-difference step for unknown j: relative, with a floor at the
/// scale of each unknown (1 N for force, 1e-2 /m for curvature).
fn fd_step(x: &Vector6<f64>, j: usize) -> f64 {
    let floor = if j < 3 { 1.0 } else { 1e-2 };
    1e-7 * x[j].abs().max(floor)
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
        self.robot.check_tensions(tensions)?;
        if !(tip_force.iter().all(|x| x.is_finite()) && tip_moment.iter().all(|x| x.is_finite())) {
            return Err(SolveError::BadLoad);
        }
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        let problem = Shooting {
            rod: &rod,
            steps: self.settings.steps,
            f_ext: tip_force,
            m_ext: tip_moment,
        };
        let warm_ok = warm.filter(|w| {
            w.x.iter().all(|v| v.is_finite()) && w.jacobian.iter().all(|v| v.is_finite())
        });
        let result = match warm_ok {
            Some(w) => problem.newton(w.x, Some(w.jacobian), &self.settings),
            None => Err((f64::INFINITY, 0, 0)),
        };
        // A warm start that fails (a far neighbour) falls back to a cold start
        // from the analytic guess rather than reporting failure.
        let (x, jac, res, iterations, integrations) = match result {
            Ok(ok) => ok,
            Err((_, it0, int0)) => {
                let guess = rod.initial_guess(&tip_force, &tip_moment);
                match problem.newton(guess, None, &self.settings) {
                    Ok((x, j, r, it, int)) => (x, j, r, it + it0, int + int0),
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
        let tip = problem.tip(&x)?;
        let rotation = orthonormalise(&tip.rot);
        Ok(Solution {
            position: tip.p,
            quaternion: quaternion_wxyz(&rotation),
            rotation,
            residual: res,
            iterations,
            integrations,
            warm: WarmStart { x, jacobian: jac },
            tensions: tensions.to_vec(),
        })
    }

    /// Backbone points (base frame, m) at `points` ≥ 2 evenly spaced arc
    /// lengths, for a converged `sol` of this robot. Integrated on a grid at
    /// least as fine as the solver's.
    pub fn shape(&self, sol: &Solution, points: usize) -> Vec<Vector3<f64>> {
        let mut rod = self.rod.clone();
        rod.set_tensions(&sol.tensions);
        let base = base_state(&rod, &sol.warm.x);
        // The solve integrated this rod from this base without a singular
        // system; the finer grid can only differ by roundoff near one.
        integrate_sampled(&rod, base, self.settings.steps, points).unwrap_or_default()
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

fn base_state(rod: &Rod, x: &Vector6<f64>) -> RodState {
    RodState::at_base(
        &Vector3::new(x[0], x[1], x[2]),
        &Vector3::new(x[3], x[4], x[5]),
        &rod.kse,
    )
}

/// One shooting problem: the rod with its tensions and tip load.
#[derive(Clone, Copy)]
struct Shooting<'a> {
    rod: &'a Rod,
    steps: usize,
    f_ext: Vector3<f64>,
    m_ext: Vector3<f64>,
}

/// (unknowns, Jacobian, residual norm, iterations, integrations)
type NewtonOk = (Vector6<f64>, Matrix6<f64>, f64, usize, usize);
/// (best residual norm, iterations, integrations)
type NewtonErr = (f64, usize, usize);

impl Shooting<'_> {
    fn tip(&self, x: &Vector6<f64>) -> Result<RodState, SingularSystem> {
        integrate(self.rod, base_state(self.rod, x), self.steps)
    }

    /// The tip residual at `x`; a singular system on the way makes it
    /// infinite, which the Newton iteration treats as a failed step.
    fn residual(&self, x: &Vector6<f64>) -> Vector6<f64> {
        match self.tip(x) {
            Ok(tip) => self.rod.tip_residual(&tip, &self.f_ext, &self.m_ext),
            Err(_) => Vector6::from_element(f64::INFINITY),
        }
    }

    /// Forward-difference Jacobian of the residual at `x`. It is built on
    /// half the RK4 steps: Newton only needs a good approximation of the
    /// Jacobian (the residual itself stays on the full grid, so the answer
    /// does not change), and this halves the cost of every refresh.
    fn jacobian(&self, x: &Vector6<f64>) -> Matrix6<f64> {
        let coarse = Shooting {
            steps: self.steps.div_ceil(2),
            ..*self
        };
        let r = coarse.residual(x);
        let mut j = Matrix6::zeros();
        for c in 0..6 {
            let h = fd_step(x, c);
            let mut xp = *x;
            xp[c] += h;
            j.set_column(c, &((coarse.residual(&xp) - r) / h));
        }
        j
    }

    /// Damped Newton with Broyden updates from `x0`.
    fn newton(
        &self,
        x0: Vector6<f64>,
        j0: Option<Matrix6<f64>>,
        settings: &SolverSettings,
    ) -> Result<NewtonOk, NewtonErr> {
        let mut x = x0;
        let mut r = self.residual(&x);
        let mut integrations = 1;
        let (mut jac, mut fresh) = match j0 {
            Some(j) => (j, false),
            None => {
                integrations += 7;
                (self.jacobian(&x), true)
            }
        };
        let mut norm = r.norm();
        for iter in 0..settings.max_iter {
            if !norm.is_finite() {
                return Err((norm, iter, integrations));
            }
            if norm < settings.tol {
                return Ok((x, jac, norm, iter, integrations));
            }
            let step = jac.lu().solve(&(-r));
            let mut accepted = false;
            if let Some(dx) = step.filter(|d| d.iter().all(|v| v.is_finite())) {
                // Backtracking on the residual norm; a full Newton step is
                // almost always taken near the solution.
                let mut alpha = 1.0;
                for _ in 0..6 {
                    let s = dx * alpha;
                    let x_try = x + s;
                    let r_try = self.residual(&x_try);
                    integrations += 1;
                    let n_try = r_try.norm();
                    if n_try.is_finite() && n_try < (1.0 - 1e-4 * alpha) * norm {
                        // Broyden's "good" rank-one update.
                        let y = r_try - r;
                        jac += (y - jac * s) * s.transpose() / s.norm_squared();
                        x = x_try;
                        r = r_try;
                        norm = n_try;
                        fresh = false;
                        accepted = true;
                        break;
                    }
                    alpha *= 0.5;
                }
            }
            if !accepted {
                if fresh {
                    return Err((norm, iter + 1, integrations));
                }
                jac = self.jacobian(&x);
                integrations += 7;
                fresh = true;
            }
        }
        if norm < settings.tol {
            Ok((x, jac, norm, settings.max_iter, integrations))
        } else {
            Err((norm, settings.max_iter, integrations))
        }
    }
}
