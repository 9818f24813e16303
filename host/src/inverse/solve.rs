//! Bounded Gauss–Newton in a trust region on the tensions, then the
//! redundancy (`docs/design.md` §4.1).
//!
//! Phase 1 reaches the target: minimise ½|e(τ)|² over the box
//! [τ_min, τ_max], e = [p − p*] or [p − p*; ℓ θ] with θ the rotation vector
//! of R R*ᵀ (base frame) and ℓ the orientation weight in metres per radian
//! (default: the backbone length, so a radian of tip rotation weighs like a
//! backbone length of tip travel). Each step is the minimum-norm
//! Gauss–Newton step on the free tensions (off their limits, or at a limit
//! with the step pointing inside), cut to a trust radius and at the first
//! limit it meets; a step that does not lower the error shrinks the radius.
//! When no step can lower it any more, or the error is orthogonal to every
//! move the free tensions can make ([`STATIONARY`]), the run has stalled at
//! a locally closest point; [`super::global`] restarts it elsewhere before
//! calling the target out of reach. After a small step the Jacobian is
//! Broyden's update of the last one, refreshed when a step it proposes
//! fails. A lateral target (the planner's lift) is e = [px − x*, py − y*].
//!
//! Phase 2 resolves the redundancy: antagonistic tendons co-contract with
//! almost no tip motion, so many τ reach a position. Among them it takes the
//! least total tension Σ (τ_i − τ_min,i): it moves along −1 projected on the
//! null space of the free tensions' Jacobian (dropping tensions at a limit
//! that the move would push out), up to the first limit hit, and re-reaches
//! the target with phase 1; it stops when the projected direction vanishes
//! (Σ τ is stationary on the target set, the first-order optimum of this
//! linear objective) or a move no longer lowers Σ τ.

use std::sync::{Arc, OnceLock};

use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

use super::jacobian::tip_jacobian;
use super::table::SeedTable;

mod redundancy;
use super::{IkSolution, InverseError, Target};
use tendril_shared::CoContraction;

use crate::robot::{cocontraction_sets, Robot};
use crate::statics::pose::angle_between;
use crate::statics::rod::Rod;
use crate::statics::{Solution, SolverSettings, Statics, WarmStart};

/// Settings of the exact IK.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkSettings {
    /// Reached when the tip is within this distance of the target, m.
    pub position_tol: f64,
    /// ... and, for a pose target, within this angle, rad.
    pub orientation_tol: f64,
    /// Metres per radian weighing orientation error against position error;
    /// `None`: the backbone length.
    pub orientation_weight: Option<f64>,
    /// Most statics solves of one local run (each start of the global
    /// search has its own).
    pub max_solves: usize,
    /// Further starts of the global search, from the forward-kinematics
    /// table's samples nearest the target, when the first start does not
    /// reach it (`docs/design.md` §4.1); 0: a local answer only.
    pub restarts: usize,
    /// How phase 2 resolves the redundancy among the tensions that reach
    /// the target.
    pub redundancy: Redundancy,
    /// The forward statics' settings.
    pub statics: SolverSettings,
}

/// Which of the tensions that reach a target phase 2 picks
/// (`docs/design.md` §4.1). Tension counts above the floors τ_min.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Redundancy {
    /// Wherever phase 1 ends.
    Any,
    /// The least total tension Σ (τ − τ_min): the cheapest to hold, a
    /// vertex of the tension box's faces, so the answer jumps between
    /// tendon sets as the target moves.
    LeastTotal,
    /// The least bending effort: Σ of the squared tensions once each
    /// co-contraction set's common part is taken out (for three tendons
    /// 120° apart, 2/3 of the squared bending moment the set applies).
    /// Smooth in the target wherever no tendon meets its upper limit: the
    /// family a learner can follow on a robot with more bending freedom
    /// than its tip position uses (three segments, `docs/design.md` §3).
    /// Co-contraction costs no bending effort, so it stays where phase 1
    /// left it ([`crate::dataset::resolve::slacken`] takes it out).
    LeastBending,
}

impl Default for IkSettings {
    fn default() -> Self {
        IkSettings {
            position_tol: 1e-7,
            orientation_tol: 1e-6,
            orientation_weight: None,
            max_solves: 200,
            restarts: 6,
            redundancy: Redundancy::LeastTotal,
            statics: SolverSettings::default(),
        }
    }
}

/// A point is a closest one when the free gradient |Jᵀe| is at most this
/// fraction of |J| |e|: within the Gauss–Newton model, moving on could
/// bring the tip closer by about ½ STATIONARY² |e| (1e-8 of the distance).
const STATIONARY: f64 = 1e-4;
/// Tensions are "at a limit" within this much, N.
pub(crate) const AT_LIMIT: f64 = 1e-9;
/// Singular values below this fraction of the largest are dropped from a
/// Gauss–Newton step (roundoff).
const RANK_TOLERANCE: f64 = 1e-12;
/// Steps no longer than this fraction of the widest tension range update
/// the last ∂e/∂τ (Broyden) instead of a new sensitivity pass, which costs
/// ~1.6 statics solves: a warm path step is a few hundredths of a newton.
const BROYDEN_STEP: f64 = 0.02;
/// Steps shorter than this fraction of the range keep the last ∂e/∂τ as it
/// is (the change Δe would be the statics' round-off).
const CHORD_STEP: f64 = 1e-7;
/// Most Broyden updates in a row before an exact Jacobian again (their
/// errors add up).
const MAX_BROYDEN_AGE: usize = 3;

/// The exact IK of one robot.
#[derive(Clone, Debug)]
pub struct ExactIk {
    statics: Statics,
    rod: Rod,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// The robot's co-contraction sets, which [`Redundancy::LeastBending`]
    /// takes out of the tensions.
    sets: CoContraction,
    weight: f64,
    settings: IkSettings,
    /// The coarse forward-kinematics table of the tension box the global
    /// search seeds from, built at its first use and shared by clones.
    table: Arc<OnceLock<SeedTable>>,
}

/// One evaluated point of the iteration.
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub(super) tau: Vec<f64>,
    pub(super) sol: Solution,
    err: DVector<f64>,
    pub(super) cost: f64,
    /// ∂e/∂τ.
    jac: Option<DMatrix<f64>>,
    /// The tip Jacobian ∂pose/∂τ it was cut from (unweighted, 6 rows);
    /// `None` when `jac` is a Broyden update.
    tip_jac: Option<DMatrix<f64>>,
    /// Broyden updates since `jac` was last computed exactly.
    age: usize,
}

/// How phase 1 ended.
enum Reach {
    Converged(Point),
    /// No step lowers the error, or the error is orthogonal to every
    /// feasible move ([`ExactIk::stationary`]): a locally closest point.
    Stalled(Point),
    /// The run's statics solves ran out first.
    Budget(Point),
}

/// How one local run ended ([`ExactIk::local`]).
pub(super) enum Local {
    /// The target is reached: the answer, redundancy resolved.
    Reached(Box<IkSolution>),
    /// A locally closest point (first-order stationary, or no step lowers
    /// the error).
    Stationary(Point),
    /// The run's budget ran out at this point, still descending.
    Budget(Point),
}

/// The statics solves one local run may spend.
#[derive(Clone, Copy)]
struct Budget {
    spent_before: usize,
    max: usize,
}

impl Budget {
    fn spent(&self, solves: usize) -> bool {
        solves - self.spent_before >= self.max
    }
}

impl ExactIk {
    /// The exact IK of `robot`.
    pub fn new(robot: &Robot, settings: IkSettings) -> ExactIk {
        ExactIk {
            statics: Statics::new(robot, settings.statics),
            rod: Rod::new(robot),
            lo: robot.min_tensions(),
            hi: robot.max_tensions(),
            sets: cocontraction_sets(robot),
            weight: settings.orientation_weight.unwrap_or(robot.length),
            settings,
            table: Arc::new(OnceLock::new()),
        }
    }

    /// The robot.
    pub fn robot(&self) -> &Robot {
        self.statics.robot()
    }

    /// The settings.
    pub fn settings(&self) -> &IkSettings {
        &self.settings
    }

    /// The statics of the robot.
    pub(super) fn statics(&self) -> &Statics {
        &self.statics
    }

    /// The seed table of the global search ([`SeedTable`]), built on first
    /// use: call it once before a parallel batch so that the build itself
    /// runs in parallel.
    pub fn seed_table(&self) -> &SeedTable {
        self.table.get_or_init(|| SeedTable::build(self))
    }

    /// The tension limits (τ_min, τ_max), N.
    pub fn limits(&self) -> (&[f64], &[f64]) {
        (&self.lo, &self.hi)
    }

    /// The start tensions `start` clamped into the limits (a non-finite
    /// value: its floor); `None`: every tendon at its floor, a cold start.
    pub(super) fn start_tensions(&self, start: Option<&[f64]>) -> Result<Vec<f64>, InverseError> {
        let n = self.lo.len();
        Ok(match start {
            Some(s) if s.len() != n => {
                return Err(InverseError::StartCount {
                    expected: n,
                    got: s.len(),
                })
            }
            Some(s) => s
                .iter()
                .zip(self.lo.iter().zip(&self.hi))
                .map(|(&t, (&lo, &hi))| if t.is_finite() { t.clamp(lo, hi) } else { lo })
                .collect(),
            None => self.lo.clone(),
        })
    }

    /// One local run from `tau0` (within the limits) with its own budget of
    /// `max_solves` statics solves, counted into `solves`:
    /// phase 1, then for a reached target phase 2 and the snap onto the
    /// limits ([`super::global`] runs it from several starts).
    pub(super) fn local(
        &self,
        target: &Target,
        tau0: Vec<f64>,
        warm: Option<&WarmStart>,
        solves: &mut usize,
        max_solves: usize,
    ) -> Result<Local, InverseError> {
        let budget = Budget {
            spent_before: *solves,
            max: max_solves,
        };
        let first = self.point(target, tau0, warm, solves)?;
        match self.reach(target, first, solves, budget)? {
            Reach::Converged(p) => {
                let p = match self.settings.redundancy {
                    Redundancy::Any => p,
                    objective => self.least_tension(target, p, objective, solves, budget)?,
                };
                let p = self.onto_limits(target, p, solves)?;
                Ok(Local::Reached(Box::new(self.answer(target, &p, *solves))))
            }
            Reach::Stalled(p) => Ok(Local::Stationary(p)),
            Reach::Budget(p) => Ok(Local::Budget(p)),
        }
    }

    fn point(
        &self,
        target: &Target,
        tau: Vec<f64>,
        warm: Option<&WarmStart>,
        solves: &mut usize,
    ) -> Result<Point, InverseError> {
        *solves += 1;
        let sol = self.statics.solve(&tau, warm)?;
        let err = self.error(target, &sol);
        Ok(Point {
            cost: 0.5 * err.norm_squared(),
            tau,
            sol,
            err,
            jac: None,
            tip_jac: None,
            age: 0,
        })
    }

    fn error(&self, target: &Target, sol: &Solution) -> DVector<f64> {
        self.error_at(target, &sol.position, &sol.rotation)
    }

    /// e = [p − p*], [p − p*; ℓ θ(R R*ᵀ)], [px − x*, py − y*] or [a · p − u*]
    /// for the tip at `position` (m) turned by `rotation`.
    pub(super) fn error_at(
        &self,
        target: &Target,
        position: &Vector3<f64>,
        rotation: &Matrix3<f64>,
    ) -> DVector<f64> {
        match target {
            Target::Position(p) => DVector::from_column_slice((position - p).as_slice()),
            Target::Pose(p, q) => {
                let dp = position - p;
                let r = rotation * q.to_rotation_matrix().matrix().transpose();
                let theta = Rotation3::from_matrix_unchecked(r).scaled_axis() * self.weight;
                DVector::from_iterator(6, dp.iter().chain(theta.iter()).copied())
            }
            Target::Lateral(xy) => DVector::from_vec(vec![position.x - xy.x, position.y - xy.y]),
            Target::Along(axis, u) => DVector::from_element(1, axis.dot(position) - u),
        }
    }

    /// The tip Jacobian ∂pose/∂τ (6 × tendons, rows as
    /// [`super::TipJacobian::jacobian`]) of the statics solution `warm` at
    /// `tensions`.
    pub fn tip_jacobian_at(
        &self,
        tensions: &[f64],
        warm: &WarmStart,
    ) -> Result<DMatrix<f64>, InverseError> {
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        Ok(self.tip_jacobian_full(tensions, warm)?.jacobian)
    }

    /// [`ExactIk::tip_jacobian_at`] with the pass's dx/dτ.
    fn tip_jacobian_full(
        &self,
        tensions: &[f64],
        warm: &WarmStart,
    ) -> Result<super::TipJacobian, InverseError> {
        let mut rod = self.rod.clone();
        rod.set_tensions(tensions);
        Ok(tip_jacobian(&rod, &warm.x, self.settings.statics.steps)?)
    }

    /// Broyden's rank-one update of `from`'s ∂e/∂τ for `to` when the step
    /// between them is small: J + (Δe − J Δτ) Δτᵀ / |Δτ|², exact along the
    /// step taken. A step it proposes that fails gets a fresh Jacobian
    /// ([`ExactIk::refresh`]) before the trust radius shrinks.
    fn broyden(&self, from: &Point, to: &mut Point) {
        let Some(j) = &from.jac else { return };
        if to.jac.is_some() || from.age >= MAX_BROYDEN_AGE {
            return;
        }
        let dtau = DVector::from_iterator(
            to.tau.len(),
            to.tau.iter().zip(&from.tau).map(|(a, b)| a - b),
        );
        let norm2 = dtau.norm_squared();
        let step = norm2.sqrt();
        if step > BROYDEN_STEP * self.span() {
            return;
        }
        let updated = if step < CHORD_STEP * self.span() {
            j.clone()
        } else {
            let de = &to.err - &from.err;
            j + (de - j * &dtau) * dtau.transpose() / norm2
        };
        if updated.iter().all(|v| v.is_finite()) {
            to.jac = Some(updated);
            to.tip_jac = None;
            to.age = from.age + 1;
        }
    }

    /// Drops a Broyden ∂e/∂τ so that the next use computes it anew;
    /// `false` when it was exact already.
    fn refresh(p: &mut Point) -> bool {
        if p.jac.is_some() && p.tip_jac.is_none() {
            p.jac = None;
            true
        } else {
            false
        }
    }

    /// ∂e/∂τ at `p` (computed once per point).
    fn jacobian<'a>(
        &self,
        target: &Target,
        p: &'a mut Point,
    ) -> Result<&'a DMatrix<f64>, InverseError> {
        if p.jac.is_none() {
            let pass = self.tip_jacobian_full(&p.tau, &p.sol.warm)?;
            // The pass's dx/dτ lets every statics solve started from this
            // point predict its unknowns (`docs/design.md` §2, "Solve").
            p.sol.warm.set_tension_sensitivity(pass.dx_dtau);
            let full = pass.jacobian;
            p.jac = Some(match target {
                Target::Position(_) => full.rows(0, 3).into_owned(),
                Target::Lateral(_) => full.rows(0, 2).into_owned(),
                Target::Along(axis, _) => {
                    let row = axis.transpose() * full.rows(0, 3);
                    DMatrix::from_iterator(1, full.ncols(), row.iter().copied())
                }
                Target::Pose(..) => {
                    let mut j = full.clone();
                    j.rows_mut(3, 3).scale_mut(self.weight);
                    j
                }
            });
            p.tip_jac = Some(full);
            p.age = 0;
        }
        Ok(p.jac.as_ref().expect("set above"))
    }

    fn converged(&self, target: &Target, p: &Point) -> bool {
        let position_ok =
            p.err.rows(0, target.position_rows()).norm() <= self.settings.position_tol;
        match target {
            Target::Position(_) | Target::Lateral(_) | Target::Along(..) => position_ok,
            Target::Pose(..) => {
                position_ok
                    && p.err.rows(3, 3).norm() / self.weight <= self.settings.orientation_tol
            }
        }
    }

    /// Whether `p` is a first-order stationary point of ½|e|² on the box:
    /// the gradient g = Jᵀe on the free tensions (off their limits, or at a
    /// limit with −g pointing inside) is at most [`STATIONARY`] of |J| |e|,
    /// i.e. the error is orthogonal to every move the free tensions can make.
    /// Only with an exact Jacobian.
    fn stationary(&self, p: &Point) -> bool {
        p.tip_jac.is_some() && self.cosine(p) <= STATIONARY
    }

    /// |Jᵀe| on the free tensions over |J| |e| (∞ without a Jacobian).
    fn cosine(&self, p: &Point) -> f64 {
        let Some(j) = &p.jac else {
            return f64::INFINITY;
        };
        let g = j.tr_mul(&p.err);
        let free: f64 = (0..self.lo.len())
            .filter(|&i| {
                let held_below = p.tau[i] <= self.lo[i] + AT_LIMIT && g[i] >= 0.0;
                let held_above = p.tau[i] >= self.hi[i] - AT_LIMIT && g[i] <= 0.0;
                !(held_below || held_above)
            })
            .map(|i| g[i] * g[i])
            .sum();
        free.sqrt() / (j.norm() * p.err.norm())
    }

    /// Phase 1 (module docs).
    fn reach(
        &self,
        target: &Target,
        mut cur: Point,
        solves: &mut usize,
        budget: Budget,
    ) -> Result<Reach, InverseError> {
        let mut radius = 0.25 * self.span();
        let mut slow = 0;
        loop {
            if self.converged(target, &cur) {
                return Ok(Reach::Converged(cur));
            }
            if budget.spent(*solves) {
                return Ok(Reach::Budget(cur));
            }
            let j = self.jacobian(target, &mut cur)?.clone();
            if self.stationary(&cur) {
                return Ok(Reach::Stalled(cur));
            }
            let Some((free, full)) = self.gauss_newton_step(&j, &cur) else {
                if Self::refresh(&mut cur) {
                    continue;
                }
                return Ok(Reach::Stalled(cur));
            };
            loop {
                // Along the step until the first limit, which is then met
                // exactly (it joins the active set next time if the step
                // still pushes against it).
                let mut scale = (radius / full.norm()).min(1.0);
                let mut blocking = None;
                for (k, &i) in free.iter().enumerate() {
                    let room = if full[k] < 0.0 {
                        (self.lo[i] - cur.tau[i]) / full[k]
                    } else if full[k] > 0.0 {
                        (self.hi[i] - cur.tau[i]) / full[k]
                    } else {
                        f64::INFINITY
                    };
                    if room < scale {
                        scale = room.max(0.0);
                        blocking = Some((k, i));
                    }
                }
                let mut tau = cur.tau.clone();
                for (k, &i) in free.iter().enumerate() {
                    tau[i] = (tau[i] + scale * full[k]).clamp(self.lo[i], self.hi[i]);
                }
                if let Some((k, i)) = blocking {
                    tau[i] = if full[k] < 0.0 {
                        self.lo[i]
                    } else {
                        self.hi[i]
                    };
                }
                let moved = tau
                    .iter()
                    .zip(&cur.tau)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
                    .sqrt();
                if moved <= 1e-13 * (1.0 + self.span()) {
                    if Self::refresh(&mut cur) {
                        break;
                    }
                    return Ok(Reach::Stalled(cur));
                }
                let trial = self.point(target, tau, Some(&cur.sol.warm), solves);
                match trial {
                    Ok(mut trial) if trial.cost < cur.cost => {
                        let gain = (cur.cost - trial.cost) / cur.cost;
                        slow = if gain < 1e-10 { slow + 1 } else { 0 };
                        self.broyden(&cur, &mut trial);
                        cur = trial;
                        radius = (4.0 * moved).max(radius).min(self.span());
                        if slow >= 3 {
                            if Self::refresh(&mut cur) {
                                slow = 0;
                                break;
                            }
                            return Ok(Reach::Stalled(cur));
                        }
                        break;
                    }
                    // A worse point, or one the statics cannot solve: with
                    // a Broyden Jacobian, a fresh one first; else shrink.
                    Ok(_) | Err(InverseError::Statics(_)) => {
                        if Self::refresh(&mut cur) {
                            break;
                        }
                    }
                    Err(e) => return Err(e),
                }
                radius = 0.25 * moved;
                if budget.spent(*solves) {
                    return Ok(Reach::Budget(cur));
                }
            }
        }
    }

    /// The minimum-norm Gauss–Newton step on the free tensions, `None` when
    /// none is free. Free: off its limits, or at a limit with the step
    /// pointing inside; a tension the step would push out of its limit is
    /// held and the step recomputed. Taking the stiff directions
    /// (co-contraction against the axial stiffness, ~µm per N) at full
    /// length matters: a Marquardt damping scaled by the bending terms
    /// stalls there.
    fn gauss_newton_step(
        &self,
        j: &DMatrix<f64>,
        cur: &Point,
    ) -> Option<(Vec<usize>, DVector<f64>)> {
        if !j.iter().all(|v| v.is_finite()) {
            return None;
        }
        let g = j.tr_mul(&cur.err);
        let mut free: Vec<usize> = (0..self.lo.len())
            .filter(|&i| {
                let pushed_below = cur.tau[i] <= self.lo[i] + AT_LIMIT && g[i] >= 0.0;
                let pushed_above = cur.tau[i] >= self.hi[i] - AT_LIMIT && g[i] <= 0.0;
                !(pushed_below || pushed_above)
            })
            .collect();
        loop {
            if free.is_empty() {
                return None;
            }
            let svd = j.select_columns(&free).svd(true, true);
            let eps = RANK_TOLERANCE * svd.singular_values.max();
            let step = -(svd.pseudo_inverse(eps).ok()? * &cur.err);
            if !step.iter().all(|v| v.is_finite()) {
                return None;
            }
            let before = free.len();
            let mut k = 0;
            free.retain(|&i| {
                let dk = step[k];
                k += 1;
                let out_below = cur.tau[i] <= self.lo[i] + AT_LIMIT && dk < 0.0;
                let out_above = cur.tau[i] >= self.hi[i] - AT_LIMIT && dk > 0.0;
                !(out_below || out_above)
            });
            if free.len() == before {
                return Some((free, step));
            }
        }
    }

    /// The widest tension range of any tendon, N.
    pub(super) fn span(&self) -> f64 {
        self.hi
            .iter()
            .zip(&self.lo)
            .map(|(h, l)| h - l)
            .fold(0.0, f64::max)
    }

    pub(super) fn answer(&self, target: &Target, p: &Point, solves: usize) -> IkSolution {
        let pose = p.sol.pose();
        let orientation_error = match target {
            Target::Position(_) | Target::Lateral(_) | Target::Along(..) => None,
            Target::Pose(_, q) => Some(angle_between(
                &[pose[3], pose[4], pose[5], pose[6]],
                &[q.w, q.i, q.j, q.k],
            )),
        };
        let select = |at: &dyn Fn(usize) -> bool| (0..p.tau.len()).filter(|&i| at(i)).collect();
        IkSolution {
            tensions: p.tau.clone(),
            pose,
            position_error: p.err.rows(0, target.position_rows()).norm(),
            orientation_error,
            at_min: select(&|i| p.tau[i] <= self.lo[i] + AT_LIMIT),
            at_max: select(&|i| p.tau[i] >= self.hi[i] - AT_LIMIT),
            solves,
            warm: p.sol.warm.clone(),
            jacobian: p.tip_jac.clone(),
        }
    }
}
