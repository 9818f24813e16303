//! Phase 2 of the exact IK (`docs/design.md` §4.1): among the tensions
//! that reach the target, the least total tension above the floors, and the
//! final snap of tensions within [`AT_LIMIT`] onto their limits.

use nalgebra::{DMatrix, DVector};

use super::{Budget, ExactIk, Point, Reach, AT_LIMIT};
use crate::inverse::{InverseError, Target};

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

impl ExactIk {
    /// The descent direction of Σ τ on the target set at `tau`: −1 projected
    /// on the null space of the free tensions' Jacobian, the free set
    /// shrunk until no tension at a limit is pushed out. `None` when it
    /// vanishes (first-order optimum).
    fn descent(&self, j: &DMatrix<f64>, tau: &[f64]) -> Option<(DVector<f64>, Vec<usize>)> {
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
            let ones = DVector::from_element(free.len(), 1.0);
            let d = -(&ones - pinv * (jf * &ones));
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

    /// Phase 2: least total tension on the target set (module docs).
    pub(super) fn least_tension(
        &self,
        target: &Target,
        mut best: Point,
        solves: &mut usize,
        budget: Budget,
    ) -> Result<Point, InverseError> {
        let mut trust = 0.5 * self.span();
        let mut refused = 0;
        for _ in 0..MAX_REDUNDANCY_MOVES {
            if budget.spent(*solves) || refused >= MAX_REFUSED_MOVES {
                break;
            }
            let j = self.jacobian(target, &mut best)?.clone();
            let Some((d, free)) = self.descent(&j, &best.tau) else {
                break;
            };
            let mut alpha = trust / d.norm();
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
            let total = |t: &[f64]| t.iter().sum::<f64>();
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
