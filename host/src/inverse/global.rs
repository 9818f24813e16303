//! The global search (`docs/design.md` §4.1): a local run from the given
//! start, and when it does not reach the target, further local runs from
//! the samples of the forward-kinematics table ([`super::table`]) nearest
//! the target. The answer is the first run that reaches the target, else
//! the closest of the locally closest points found; a run that ran out of
//! solves while still descending and is better than every closest point
//! gets [`EXTRA_BUDGET`] more budgets, and only if they too run out is the target a
//! failure ([`InverseError::NotConverged`]), never a closest pose that is
//! not one.

use super::solve::{Local, Point};
use super::{ExactIk, IkSolution, InverseError, Target};
use crate::statics::WarmStart;

/// The best run still descending when its budget ran out continues with
/// this many budgets: far from a target out of reach on a flexible robot the
/// error falls slowly along a curved valley (Gauss–Newton's model holds only
/// for short steps there).
const EXTRA_BUDGET: usize = 5;

/// The best point met so far and whether it is a locally closest one.
struct Best {
    point: Point,
    stationary: bool,
}

impl Best {
    fn offer(best: &mut Option<Best>, point: Point, stationary: bool) {
        let better = match best {
            None => true,
            Some(b) => {
                point.cost < b.cost() || (point.cost == b.cost() && stationary && !b.stationary)
            }
        };
        if better {
            *best = Some(Best { point, stationary });
        }
    }

    fn cost(&self) -> f64 {
        self.point.cost
    }
}

impl ExactIk {
    /// Tensions reaching `target`, starting from `start` (clamped into the
    /// limits; `None`: every tendon at its floor, a cold start) with the
    /// statics warm start `warm` of a nearby solution if there is one; when
    /// that start does not reach the target, from up to
    /// [`super::IkSettings::restarts`] seeds of the forward-kinematics
    /// table. Out of reach: [`InverseError::Unreachable`] with the closest
    /// pose found.
    pub fn solve(
        &self,
        target: &Target,
        start: Option<&[f64]>,
        warm: Option<&WarmStart>,
    ) -> Result<IkSolution, InverseError> {
        let tau0 = self.start_tensions(start)?;
        let mut solves = 0;
        let mut best: Option<Best> = None;
        let mut failure: Option<InverseError> = None;
        let mut run = |tau: Vec<f64>,
                       warm: Option<&WarmStart>,
                       max_solves: usize,
                       solves: &mut usize,
                       best: &mut Option<Best>| {
            match self.local(target, tau, warm, solves, max_solves) {
                Ok(Local::Reached(answer)) => Some(answer),
                Ok(Local::Stationary(p)) => {
                    Best::offer(best, p, true);
                    None
                }
                Ok(Local::Budget(p)) => {
                    Best::offer(best, p, false);
                    None
                }
                Err(e) => {
                    failure.get_or_insert(e);
                    None
                }
            }
        };
        let max = self.settings().max_solves;
        if let Some(answer) = run(tau0.clone(), warm, max, &mut solves, &mut best) {
            return Ok(*answer);
        }
        if self.settings().restarts > 0 {
            let seeds = self
                .seed_table()
                .seeds(self, target, self.settings().restarts, &tau0);
            for (seed, warm) in seeds {
                if let Some(answer) = run(seed, Some(&warm), max, &mut solves, &mut best) {
                    return Ok(*answer);
                }
            }
        }
        if let Some(Best {
            point,
            stationary: false,
        }) = &best
        {
            let (tau, warm) = (point.tau.clone(), point.sol.warm.clone());
            let more = EXTRA_BUDGET * max;
            if let Some(answer) = run(tau, Some(&warm), more, &mut solves, &mut best) {
                return Ok(*answer);
            }
        }
        match best {
            Some(Best {
                point,
                stationary: true,
            }) => Err(InverseError::Unreachable {
                closest: Box::new(self.answer(target, &point, solves)),
            }),
            Some(Best { point, .. }) => Err(InverseError::NotConverged {
                position_error: self.answer(target, &point, solves).position_error,
                solves,
            }),
            None => Err(failure.unwrap_or(InverseError::NotConverged {
                position_error: f64::NAN,
                solves,
            })),
        }
    }
}
