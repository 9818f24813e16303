//! Phase 2 of the exact IK (`docs/design.md` §4.1): among the tensions
//! that reach the target, the least total tension above the floors (or the
//! least bending effort, [`Redundancy`]), and the final snap of tensions
//! within [`AT_LIMIT`] onto their limits.

use nalgebra::{DMatrix, DVector};

use super::{Budget, ExactIk, Point, Reach, AT_LIMIT};
use tendril_shared::CoContraction;

use crate::inverse::{InverseError, Redundancy, Target};

/// Singular values below this fraction of the largest count as a null
/// direction of the target set in phase 2: co-contraction moves the tip by
/// the axial strain only (~1.5 µm per N on the seed robot, 1e-4 of the
/// bending sensitivity), so within the target tolerance the tensions along
/// it are free and the least total tension picks them.
const NEAR_NULL: f64 = 1e-3;
/// Phase-2 moves that may fail to lower Σ τ before it stops: along the
/// near-null (axial) direction re-reaching the target undoes the move, and
/// each try costs solves.
const MAX_REFUSED_MOVES: usize = 2;
/// Most phase-2 moves along the target set.
const MAX_REDUNDANCY_MOVES: usize = 20;
/// ... for the bending effort: its optimum is interior (many tensions
/// free), approached by projected-gradient moves that a tendon reaching its
/// floor cuts short, and the lift's tangent differences it over 0.2 mm, so
/// it must be found to ~1e-6 rad (20 moves left the tangent 5 % off).
const MAX_BENDING_MOVES: usize = 100;

impl ExactIk {
    /// τ − τ_min with each co-contraction set's component along its
    /// weights w taken out (x − (w·x / w·w) w per set): the part of the
    /// tensions that bends the robot.
    fn bending_part(&self, tau: &[f64]) -> Vec<f64> {
        let mut x: Vec<f64> = tau.iter().zip(&self.lo).map(|(t, lo)| t - lo).collect();
        for members in self.set_members() {
            let w = |i: usize| f64::from(self.sets.weights()[i]);
            let wx: f64 = members.iter().map(|&i| w(i) * x[i]).sum();
            let ww: f64 = members.iter().map(|&i| w(i) * w(i)).sum();
            for &i in &members {
                x[i] -= wx / ww * w(i);
            }
        }
        x
    }

    /// The tendons of each co-contraction set.
    fn set_members(&self) -> Vec<Vec<usize>> {
        let n = self.lo.len();
        let mut sets: Vec<Vec<usize>> = Vec::new();
        for (i, &s) in self.sets.sets().iter().enumerate().take(n) {
            if s == CoContraction::NONE {
                continue;
            }
            let s = usize::from(s);
            if sets.len() <= s {
                sets.resize(s + 1, Vec::new());
            }
            sets[s].push(i);
        }
        sets
    }

    /// The objective's value at `tau`.
    fn objective(&self, objective: Redundancy, tau: &[f64]) -> f64 {
        match objective {
            Redundancy::LeastBending => self.bending_part(tau).iter().map(|x| x * x).sum(),
            _ => tau.iter().zip(&self.lo).map(|(t, lo)| t - lo).sum(),
        }
    }

    /// The descent direction of the objective on the target set at `tau`:
    /// minus its gradient (1 for the total, the bending part for half the
    /// bending effort) projected on the null space of the free tensions'
    /// Jacobian, the free set shrunk until no tension at a limit is pushed
    /// out. For the bending effort, a quadratic, the full step is the
    /// minimum on the linearised target set. `None` when it vanishes
    /// (first-order optimum).
    fn descent(
        &self,
        j: &DMatrix<f64>,
        tau: &[f64],
        objective: Redundancy,
    ) -> Option<(DVector<f64>, Vec<usize>)> {
        if !j.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut free: Vec<usize> = (0..tau.len()).collect();
        loop {
            if free.is_empty() {
                return None;
            }
            let jf = j.select_columns(&free);
            let svd = jf.clone().svd(true, true);
            let eps = NEAR_NULL * svd.singular_values.max();
            let pinv = svd.pseudo_inverse(eps).ok()?;
            let gradient = match objective {
                Redundancy::LeastBending => {
                    let bending = self.bending_part(tau);
                    DVector::from_iterator(free.len(), free.iter().map(|&i| bending[i]))
                }
                _ => DVector::from_element(free.len(), 1.0),
            };
            let d = -(&gradient - pinv * (jf * &gradient));
            let before = free.len();
            let mut k = 0;
            free.retain(|&i| {
                let dk = d[k];
                k += 1;
                let out_below = tau[i] <= self.lo[i] + AT_LIMIT && dk < 0.0;
                let out_above = tau[i] >= self.hi[i] - AT_LIMIT && dk > 0.0;
                !(out_below || out_above)
            });
            if free.len() == before {
                return (d.norm() > 1e-9).then_some((d, free));
            }
        }
    }

    /// Phase 2: the least `objective` on the target set (module docs).
    pub(super) fn least_tension(
        &self,
        target: &Target,
        mut best: Point,
        objective: Redundancy,
        solves: &mut usize,
        budget: Budget,
    ) -> Result<Point, InverseError> {
        let mut trust = 0.5 * self.span();
        let mut refused = 0;
        let moves = match objective {
            Redundancy::LeastBending => MAX_BENDING_MOVES,
            _ => MAX_REDUNDANCY_MOVES,
        };
        for _ in 0..moves {
            if budget.spent(*solves) || refused >= MAX_REFUSED_MOVES {
                break;
            }
            let j = self.jacobian(target, &mut best)?.clone();
            let Some((d, free)) = self.descent(&j, &best.tau, objective) else {
                break;
            };
            let mut alpha = trust / d.norm();
            if objective == Redundancy::LeastBending {
                alpha = alpha.min(1.0);
            }
            for (k, &i) in free.iter().enumerate() {
                if d[k] < 0.0 {
                    alpha = alpha.min((best.tau[i] - self.lo[i]) / -d[k]);
                } else if d[k] > 0.0 {
                    alpha = alpha.min((self.hi[i] - best.tau[i]) / d[k]);
                }
            }
            if alpha * d.norm() <= 1e-12 {
                break;
            }
            let mut tau = best.tau.clone();
            for (k, &i) in free.iter().enumerate() {
                tau[i] = (tau[i] + alpha * d[k]).clamp(self.lo[i], self.hi[i]);
            }
            let total = |t: &[f64]| self.objective(objective, t);
            let moved = match self.point(target, tau, Some(&best.sol.warm), solves) {
                Ok(mut p) => {
                    self.broyden(&best, &mut p);
                    match self.reach(target, p, solves, budget) {
                        Ok(Reach::Converged(p)) if total(&p.tau) < total(&best.tau) - 1e-12 => {
                            Some(p)
                        }
                        Ok(_) => None,
                        Err(e) => return Err(e),
                    }
                }
                Err(InverseError::Statics(_)) => None,
                Err(e) => return Err(e),
            };
            match moved {
                Some(p) => best = p,
                None => {
                    refused += 1;
                    trust = 0.25 * alpha * d.norm();
                }
            }
        }
        Ok(best)
    }

    /// Tensions within [`AT_LIMIT`] of a limit are put on it (a slack
    /// tendon reads 0 N, not 3e-11 N, after the last Gauss–Newton step
    /// nudged it), and the pose is solved again for them, if the result
    /// still reaches the target; otherwise `p` as it is.
    pub(super) fn onto_limits(
        &self,
        target: &Target,
        p: Point,
        solves: &mut usize,
    ) -> Result<Point, InverseError> {
        let snapped: Vec<f64> = p
            .tau
            .iter()
            .zip(self.lo.iter().zip(&self.hi))
            .map(|(&t, (&lo, &hi))| {
                if t - lo <= AT_LIMIT {
                    lo
                } else if hi - t <= AT_LIMIT {
                    hi
                } else {
                    t
                }
            })
            .collect();
        if snapped == p.tau {
            return Ok(p);
        }
        match self.point(target, snapped, Some(&p.sol.warm), solves) {
            Ok(mut q) if self.converged(target, &q) => {
                // The Jacobians of tensions 1e-9 N away are the same to
                // far below their use (the lift's tangent, Broyden).
                q.jac = p.jac;
                q.tip_jac = p.tip_jac;
                Ok(q)
            }
            Ok(_) | Err(InverseError::Statics(_)) => Ok(p),
            Err(e) => Err(e),
        }
    }
}
