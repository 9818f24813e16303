//! The time-stepping solver: the grid of histories and, per time step, the
//! shooting problem in arc length solved by Newton (`docs/design.md` §4.2).
//!
//! The grid is the statics' RK4 schedule (pieces between anchors): every RK4
//! stage is a grid point with its own history, and so is the end of every
//! piece (the state before an anchor, or the tip), where the damped internal
//! wrench enters a boundary condition. The unknowns are the base strains
//! x = [w(0); u(0)]; the residual is the tip's force and moment balance.
//! The Jacobian is taken by finite differences and kept across iterations
//! and time steps (a chord method), kept consistent with every step taken by
//! Broyden's rank-one update, and refreshed only when a step contracts the
//! residual too little. Each step starts from the base strains extrapolated
//! quadratically from the last three steps.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::numerics::rk4::rk4_step;
use crate::robot::{Robot, TensionError};
use crate::statics::integrate::{pieces, Piece};
use crate::statics::{
    SingularSystem, SolveError, SolverSettings, Statics, TensionProfile, MAX_STEPS,
};

use super::params::{Damping, DynamicsSettings};
use super::section::{DynState, DynamicRod, TimeVars};

/// Why a dynamics run could not start or step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DynamicsError {
    /// A setting is out of its range.
    #[error("dynamics settings: {0}")]
    BadSettings(String),
    /// The tension vector does not fit the robot.
    #[error(transparent)]
    BadTensions(#[from] TensionError),
    /// The external tip load is NaN or infinite.
    #[error("external tip load is not finite")]
    BadLoad,
    /// The initial statics solve failed.
    #[error("initial statics: {0}")]
    Statics(#[from] SolveError),
    /// Newton did not reach the tolerance in one time step.
    #[error("dynamics step at t = {time_s:.4} s did not converge: tip residual {residual:.3e} after {iterations} iterations")]
    NotConverged {
        /// Time of the step, s.
        time_s: f64,
        /// Residual norm reached.
        residual: f64,
        /// Iterations spent.
        iterations: usize,
    },
    /// The strain-rate system could not be solved.
    #[error(transparent)]
    Singular(#[from] SingularSystem),
}

/// The tip at the current time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipState {
    /// Time since the start, s.
    pub time_s: f64,
    /// Position, base frame, m.
    pub position: Vector3<f64>,
    /// Orientation (columns = body axes in the base frame).
    pub rotation: Matrix3<f64>,
    /// Linear velocity, base frame, m/s.
    pub velocity: Vector3<f64>,
}

/// One grid point's past: y(i−1), y(i−2), y_t(i−1), and the history term
/// y_h(i) = c₁ y(i−1) + c₂ y(i−2) + d₁ y_t(i−1) they make for the next step.
#[derive(Clone, Copy, Debug, Default)]
struct History {
    last: TimeVars,
    before_last: TimeVars,
    last_rate: TimeVars,
    term: TimeVars,
}

/// Finite-difference steps for the unknowns [w(0); u(0)]: the strain w is
/// ~1e-5 under newton-level loads (EA ≈ 5e5 N), the curvature ~1 1/m.
const FD_STEP_W: f64 = 1e-9;
const FD_STEP_U: f64 = 1e-7;
/// Largest residual change (N, N·m) a finite-difference step may cause.
const FD_TARGET: f64 = 1e-3;
/// A step with the carried Jacobian that leaves more than this fraction of
/// the residual gets the next iteration a fresh (finite-difference) one.
const REFRESH_CONTRACTION: f64 = 0.25;

/// A dynamic robot: state, history and solver.
#[derive(Clone, Debug)]
pub struct Dynamics {
    robot: Robot,
    model: DynamicRod,
    settings: DynamicsSettings,
    pieces: Vec<Piece>,
    history: Vec<History>,
    current: Vec<TimeVars>,
    scratch: Vec<TimeVars>,
    /// Backbone points of the pass that recorded `current` (base frame, m):
    /// the base and each RK4 step's end, base to tip.
    backbone: Vec<Vector3<f64>>,
    /// The backbone of the pass that recorded `scratch`.
    scratch_backbone: Vec<Vector3<f64>>,
    /// Base strains of the last three steps, newest first.
    x_past: [Vector6<f64>; 3],
    /// Steps taken since the start (how many of `x_past` are the dynamics').
    steps_taken: u64,
    /// The residual's Jacobian in use: finite differences, then Broyden.
    jacobian: Option<Matrix6<f64>>,
    tip: TipState,
    passes: u64,
    coarse_passes: u64,
}

impl Dynamics {
    /// The robot at rest in its statics equilibrium under `tensions` (N) and
    /// the external tip force (N) and moment (N·m, base frame): the initial
    /// state of a run.
    pub fn at_rest(
        robot: &Robot,
        damping: Damping,
        settings: DynamicsSettings,
        tensions: &[f64],
        tip_force: Vector3<f64>,
        tip_moment: Vector3<f64>,
    ) -> Result<Dynamics, DynamicsError> {
        check_settings(&settings)?;
        robot.check_tensions(tensions)?;
        let statics = Statics::new(
            robot,
            SolverSettings {
                steps: settings.steps,
                ..SolverSettings::default()
            },
        );
        let sol = statics.solve_loaded(tensions, tip_force, tip_moment, None)?;
        let mut model = DynamicRod::new(robot, damping);
        model.set_tensions(tensions);
        model.set_tip_load(tip_force, tip_moment);
        let schedule: Vec<Piece> = pieces(&model.rod, settings.steps).collect();
        let slots: usize = schedule.iter().map(|p| 4 * p.n + 1).sum();
        let kse = model.rod.kse;
        let n0 = Vector3::new(sol.warm.x[0], sol.warm.x[1], sol.warm.x[2]);
        let w0 = n0.component_div(&kse);
        let guess = Vector6::new(
            w0.x,
            w0.y,
            w0.z,
            sol.warm.x[3],
            sol.warm.x[4],
            sol.warm.x[5],
        );
        let mut dynamics = Dynamics {
            robot: robot.clone(),
            model,
            settings,
            pieces: schedule,
            history: vec![History::default(); slots],
            current: vec![TimeVars::default(); slots],
            scratch: vec![TimeVars::default(); slots],
            backbone: Vec::with_capacity(slots / 4 + 2),
            scratch_backbone: Vec::with_capacity(slots / 4 + 2),
            x_past: [guess; 3],
            steps_taken: 0,
            jacobian: None,
            tip: TipState {
                time_s: 0.0,
                position: sol.position,
                rotation: sol.rotation,
                velocity: Vector3::zeros(),
            },
            passes: 0,
            coarse_passes: 0,
        };
        // The statics are the dynamics with c₀ = 0 and no history.
        dynamics.solve(guess, 0.0, false)?;
        // At rest: y(−1) = y(−2) = y(0), y_t = 0, so y_h = (c₁ + c₂) y = −c₀ y.
        let scheme = settings.scheme();
        for (h, z) in dynamics.history.iter_mut().zip(&dynamics.current) {
            *h = History {
                last: *z,
                before_last: *z,
                last_rate: TimeVars::default(),
                term: *z * (scheme.c1() + scheme.c2()),
            };
        }
        dynamics.jacobian = None;
        Ok(dynamics)
    }

    /// Capstan tendon friction from the next step on (`docs/design.md`
    /// §2.3): the tensions given to [`Dynamics::step`] become the motors'
    /// and each tendon carries τ_i,m e_i(s) along its path. The profile is
    /// the caller's, e.g. [`crate::statics::Solution::profile`] of a
    /// [`crate::statics::FrictionState::solve`] at the same motor tensions
    /// (quasi-static angles); `None` removes friction.
    pub fn set_friction_profile(&mut self, profile: Option<std::sync::Arc<TensionProfile>>) {
        self.model.set_profile(profile);
        self.jacobian = None;
    }

    /// Change the external tip load (N, N·m, base frame) from the next step on.
    pub fn set_tip_load(
        &mut self,
        force: Vector3<f64>,
        moment: Vector3<f64>,
    ) -> Result<(), DynamicsError> {
        if !(force.iter().chain(moment.iter()).all(|v| v.is_finite())) {
            return Err(DynamicsError::BadLoad);
        }
        self.model.set_tip_load(force, moment);
        Ok(())
    }

    /// Advance one time step δt with `tensions` (N) held over it.
    pub fn step(&mut self, tensions: &[f64]) -> Result<TipState, DynamicsError> {
        self.step_checked(tensions).map_err(|e| match e {
            DynamicsError::NotConverged {
                residual,
                iterations,
                ..
            } => DynamicsError::NotConverged {
                time_s: self.tip.time_s + self.settings.dt_s,
                residual,
                iterations,
            },
            other => other,
        })
    }

    fn step_checked(&mut self, tensions: &[f64]) -> Result<TipState, DynamicsError> {
        self.robot.check_tensions(tensions)?;
        self.model.set_tensions(tensions);
        let scheme = self.settings.scheme();
        let guess = self.prediction();
        let x_before = self.x_past;
        self.solve(guess, scheme.c0(), true)?;
        self.x_past = [self.x_past[0], x_before[0], x_before[1]];
        self.steps_taken += 1;
        let (c0, c1, c2, d1) = (scheme.c0(), scheme.c1(), scheme.c2(), scheme.d1());
        for (h, z) in self.history.iter_mut().zip(&self.current) {
            let rate = *z * c0 + h.term;
            h.before_last = h.last;
            h.last = *z;
            h.last_rate = rate;
            h.term = h.last * c1 + h.before_last * c2 + rate * d1;
        }
        self.tip.time_s += self.settings.dt_s;
        Ok(self.tip)
    }

    /// The base strains this step is predicted to end at: the quadratic
    /// through the last three steps' (x(i) ≈ 3 x(i−1) − 3 x(i−2) + x(i−3),
    /// error O(δt³ x_ttt)), linear after the first step, the last one at
    /// the start (the rod is at rest then).
    fn prediction(&self) -> Vector6<f64> {
        let [x1, x2, x3] = self.x_past;
        match self.steps_taken {
            0 => x1,
            1 => x1 * 2.0 - x2,
            _ => (x1 - x2) * 3.0 + x3,
        }
    }

    /// The backbone now, base to tip (base frame, m): the base and the end
    /// of every RK4 step of the last converged pass (the tip is the last
    /// point). Its spacing is the solver's grid, not uniform across pieces.
    pub fn backbone(&self) -> &[Vector3<f64>] {
        &self.backbone
    }

    /// The tip now.
    pub fn tip(&self) -> TipState {
        self.tip
    }

    /// The settings of this run.
    pub fn settings(&self) -> &DynamicsSettings {
        &self.settings
    }

    /// Rod passes (integrations base to tip) on the solve's grid spent so
    /// far.
    pub fn passes(&self) -> u64 {
        self.passes
    }

    /// Passes on the Jacobian's grid (finite differences) spent so far,
    /// each about 1 / [`DynamicsSettings::jacobian_coarsening`] of a pass
    /// on the solve's grid; not counted in [`Dynamics::passes`].
    pub fn coarse_passes(&self) -> u64 {
        self.coarse_passes
    }

    /// Newton on the base strains from `guess`; on success `current` holds
    /// the grid at the solution and `x_past[0]`, `tip` are updated. The
    /// Jacobian carried from the last step (or iteration) is corrected by
    /// Broyden's update after every accepted step, so it follows the slowly
    /// changing step-to-step problem for the price of the passes Newton
    /// takes anyway; it is refreshed by finite differences only when a step
    /// with it contracts the residual by less than [`REFRESH_CONTRACTION`]
    /// or does not reduce it at all. With a fresh Jacobian the step is
    /// backtracked. When no step improves the residual any more (the
    /// roundoff floor of a stiff step), a residual within
    /// [`DynamicsSettings::floor_tol`] is accepted. Trials are integrated
    /// into `scratch` and swapped into `current` when accepted, so a
    /// rejected trial costs no pass to re-record the grid.
    fn solve(&mut self, guess: Vector6<f64>, c0: f64, dynamic: bool) -> Result<(), DynamicsError> {
        let mut x = guess;
        let (mut tip, mut r) = self.residual(&x, c0, dynamic, false)?;
        let mut norm = r.norm();
        for _ in 0..self.settings.max_iter {
            if norm <= self.settings.tol {
                break;
            }
            let fresh = self.jacobian.is_none();
            let jac = match self.jacobian {
                Some(j) => j,
                None => self.fd_jacobian(&x, c0, dynamic)?,
            };
            self.jacobian = Some(jac);
            let Some(dx) = jac.lu().solve(&(-r)) else {
                break;
            };
            let mut accepted = false;
            let mut scale = 1.0;
            // A carried Jacobian gets one try; a fresh one backtracks.
            for _ in 0..if fresh { 4 } else { 1 } {
                let step = dx * scale;
                if let Ok((trial_tip, trial_r)) = self.residual(&(x + step), c0, dynamic, true) {
                    let trial_norm = trial_r.norm();
                    if trial_norm < norm {
                        // Broyden: the secant condition J s = Δr along the
                        // step just taken, the rest of J unchanged.
                        let update =
                            (trial_r - r - jac * step) * step.transpose() / step.norm_squared();
                        let weak = trial_norm > REFRESH_CONTRACTION * norm
                            && trial_norm > self.settings.tol;
                        self.jacobian = (fresh || !weak).then_some(jac + update);
                        std::mem::swap(&mut self.current, &mut self.scratch);
                        std::mem::swap(&mut self.backbone, &mut self.scratch_backbone);
                        (x, tip, r, norm) = (x + step, trial_tip, trial_r, trial_norm);
                        accepted = true;
                        break;
                    }
                }
                scale *= 0.25;
            }
            if !accepted {
                if fresh {
                    break;
                }
                self.jacobian = None;
            }
        }
        if norm > self.settings.floor_tol {
            return Err(DynamicsError::NotConverged {
                time_s: 0.0,
                residual: norm,
                iterations: self.settings.max_iter,
            });
        }
        self.x_past[0] = x;
        self.tip.position = tip.p;
        self.tip.rotation = tip.rot;
        self.tip.velocity = tip.rot * tip.q;
        Ok(())
    }

    /// ∂residual/∂x by forward differences on the grid
    /// [`DynamicsSettings::jacobian_coarsening`] times coarser than the
    /// solve's: Newton needs the Jacobian only to choose its steps (the
    /// residual, and so the answer, is always the fine grid's), and the
    /// Broyden updates then correct it along the steps taken. Seven passes
    /// on that grid (the default is the solve's own grid: see
    /// [`super::params::JACOBIAN_COARSENING`]). Small time steps make the
    /// shooting problem stiff (the beam's implicit step is a beam on an
    /// elastic foundation ρA c₀², whose solutions grow like e^{λs} with
    /// λ⁴ ~ ρA c₀²/EI): a step that changes the residual by more than
    /// [`FD_TARGET`] is shrunk to stay in the linear range.
    fn fd_jacobian(
        &mut self,
        x: &Vector6<f64>,
        c0: f64,
        dynamic: bool,
    ) -> Result<Matrix6<f64>, DynamicsError> {
        let r = self.coarse_residual(x, c0, dynamic)?;
        let mut jac = Matrix6::zeros();
        for j in 0..6 {
            let mut step = if j < 3 { FD_STEP_W } else { FD_STEP_U };
            let mut column = Vector6::zeros();
            for _ in 0..4 {
                let mut xj = *x;
                xj[j] += step;
                let rj = self.coarse_residual(&xj, c0, dynamic)?;
                let change = (rj - r).norm();
                column = (rj - r) / step;
                if change <= FD_TARGET || !change.is_finite() && step < 1e-30 {
                    break;
                }
                step *= if change.is_finite() {
                    0.5 * FD_TARGET / change
                } else {
                    1e-4
                };
            }
            jac.set_column(j, &column);
        }
        Ok(jac)
    }

    /// One pass base to tip from the base strains `x`: the tip state and
    /// residual. Records the grid and backbone into `current` or, for a
    /// trial or finite-difference pass, `scratch`. `dynamic` false: no
    /// history (statics).
    fn residual(
        &mut self,
        x: &Vector6<f64>,
        c0: f64,
        dynamic: bool,
        into_scratch: bool,
    ) -> Result<(DynState, Vector6<f64>), DynamicsError> {
        self.passes += 1;
        let history = dynamic.then_some(self.history.as_slice());
        let (record, backbone) = if into_scratch {
            (&mut self.scratch, &mut self.scratch_backbone)
        } else {
            (&mut self.current, &mut self.backbone)
        };
        Ok(pass(
            &self.model,
            &self.pieces,
            x,
            c0,
            history,
            1,
            Some(record),
            Some(backbone),
        )?)
    }

    /// The residual at `x` from a pass on the grid
    /// [`DynamicsSettings::jacobian_coarsening`] times coarser, for the
    /// finite-difference Jacobian; records nothing.
    fn coarse_residual(
        &mut self,
        x: &Vector6<f64>,
        c0: f64,
        dynamic: bool,
    ) -> Result<Vector6<f64>, DynamicsError> {
        self.coarse_passes += 1;
        let history = dynamic.then_some(self.history.as_slice());
        let coarsen = self.settings.jacobian_coarsening.max(1);
        Ok(pass(
            &self.model,
            &self.pieces,
            x,
            c0,
            history,
            coarsen,
            None,
            None,
        )?
        .1)
    }
}

/// Integrate base to tip with RK4 on the schedule `pieces`, each stage and
/// each piece end a grid point with its history term; returns the tip state
/// and the tip residual. With `record`, every grid point's time variables
/// are written into it, and with `backbone`, the base and every step's end
/// position.
///
/// `coarsen` > 1 integrates each piece with steps that many times longer
/// ([`coarse_factor`]), for the Jacobian only: a coarse step spans `f` fine
/// steps and takes its stages' history terms from the fine grid points at
/// the same arc length ([`coarse_slot`]), so the coarse pass solves the same
/// time step on a coarser grid. It records nothing (`record` must be
/// `None`). With `coarsen` = 1 it is the fine pass, operation for operation.
#[allow(clippy::too_many_arguments)]
fn pass(
    model: &DynamicRod,
    pieces: &[Piece],
    x: &Vector6<f64>,
    c0: f64,
    history: Option<&[History]>,
    coarsen: usize,
    mut record: Option<&mut [TimeVars]>,
    mut backbone: Option<&mut Vec<Vector3<f64>>>,
) -> Result<(DynState, Vector6<f64>), SingularSystem> {
    let term = |k: usize| history.map_or(TimeVars::default(), |h| h[k].term);
    let length = model.rod.length;
    let mut y = DynState::at_base(
        Vector3::new(x[0], x[1], x[2]),
        Vector3::new(x[3], x[4], x[5]),
    );
    if let Some(b) = backbone.as_deref_mut() {
        b.clear();
        b.push(y.p);
    }
    // Slot of the piece's first grid point.
    let mut base = 0;
    for piece in pieces {
        let f = coarse_factor(piece.n, coarsen);
        let hh = piece.h * f as f64;
        for j in (0..piece.n).step_by(f) {
            let s = piece.a + j as f64 * piece.h;
            // Each stage is a grid point with its own history term; its
            // time variables are recorded for the next time step.
            y = rk4_step(s, &y, hh, |stage, s, y| {
                let k = base + coarse_slot(j, f, stage);
                let (r, z) = model.rates(s, y, &term(k), c0, piece.running)?;
                if let Some(rec) = record.as_deref_mut() {
                    rec[k] = z;
                }
                Ok(r)
            })?;
            if let Some(b) = backbone.as_deref_mut() {
                b.push(y.p);
            }
        }
        let k = base + 4 * piece.n;
        if let Some(rec) = record.as_deref_mut() {
            rec[k] = y.time_vars(Vector3::zeros(), Vector3::zeros());
        }
        let end_term = term(k);
        base = k + 1;
        if piece.ends_at_anchor(length) {
            y = model.across_anchor(piece.b, &y, &end_term, &term(base), c0);
        } else {
            return Ok((y, model.tip_residual(&y, &end_term, c0)));
        }
    }
    Ok((y, model.tip_residual(&y, &TimeVars::default(), c0)))
}

/// The coarsening of a piece of `n` fine steps: the largest factor f ≤
/// `coarsen` that divides n and leaves at least two coarse steps (1 when
/// none does), so coarse steps end on fine grid points.
fn coarse_factor(n: usize, coarsen: usize) -> usize {
    (1..=coarsen.min(n / 2))
        .rev()
        .find(|f| n.is_multiple_of(*f))
        .unwrap_or(1)
}

/// Slot (from the piece's first) of the fine grid point whose history a
/// stage of the coarse step spanning fine steps j..j+f takes: the start is
/// fine step j's first stage, the end fine step j+f−1's last (both at the
/// same arc length as the coarse stage), the midpoint fine step j+f/2's
/// first stage (f even) or fine step j+(f−1)/2's own midpoint stages (f odd).
/// f = 1 gives the fine grid's own slots.
fn coarse_slot(j: usize, f: usize, stage: usize) -> usize {
    match stage {
        0 => 4 * j,
        3 => 4 * (j + f - 1) + 3,
        _ if f.is_multiple_of(2) => 4 * (j + f / 2),
        _ => 4 * (j + (f - 1) / 2) + stage,
    }
}

fn check_settings(s: &DynamicsSettings) -> Result<(), DynamicsError> {
    let bad = |m: String| Err(DynamicsError::BadSettings(m));
    if !(s.dt_s.is_finite() && s.dt_s > 0.0) {
        return bad(format!("time step {} s must be positive", s.dt_s));
    }
    if !(-0.5..=0.0).contains(&s.alpha) {
        return bad(format!("BDF-alpha {} must be in [-0.5, 0]", s.alpha));
    }
    if s.steps == 0 || s.steps > MAX_STEPS {
        return bad(format!(
            "{} spatial steps: must be 1..={MAX_STEPS}",
            s.steps
        ));
    }
    if !(s.tol.is_finite() && s.tol > 0.0 && s.floor_tol >= s.tol) || s.max_iter == 0 {
        return bad(
            "tolerance must be positive (floor at least the tolerance) and iterations at least 1"
                .into(),
        );
    }
    Ok(())
}
