//! Many independent statics solves (`tendril fk --input`): rows in any order,
//! results that depend neither on that order nor on the thread count.
//!
//! The rows are put in a canonical order that depends only on their values
//! (a snake walk over a grid in tension space, ties broken by the values
//! themselves), cut into fixed-length chains, and each chain is solved
//! sequentially, a row warm-started from its predecessor only when that one
//! has the same values, and cold otherwise. A row's result is therefore a
//! function of the set of rows alone. (Warm starts from merely close rows
//! were measured: on 600 uniform rows of the default robot they cost more
//! instructions per row than cold solves, because a start that wanders is
//! re-solved cold; see BENCHMARKS.md.)

use std::cmp::Ordering as CmpOrdering;
use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{Solution, SolveError, Statics, WarmStart};

/// Rows per warm-started chain: long enough that chains rarely start cold,
/// short enough to balance two or more threads on a few hundred rows.
pub const CHAIN: usize = 32;

/// Largest distance, in the ∞-norm of tensions scaled by each tendon's
/// max_tension (and tip loads by 1 N or 1 N m), from which a row is
/// warm-started: only repeated rows are.
pub const WARM_RADIUS: f64 = 0.0;

/// The result of one row's solve.
pub type RowResult = Result<Solution, SolveError>;

/// One row of a batch: tensions (N) and a tip wrench in the base frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Load {
    /// Tendon tensions, N, tendon 0 first.
    pub tensions: Vec<f64>,
    /// Tip force, base frame, N.
    pub tip_force: Vector3<f64>,
    /// Tip moment, base frame, N m.
    pub tip_moment: Vector3<f64>,
}

impl Load {
    /// Tensions only, no tip load.
    pub fn tensions(tensions: Vec<f64>) -> Load {
        Load {
            tensions,
            tip_force: Vector3::zeros(),
            tip_moment: Vector3::zeros(),
        }
    }

    fn values(&self) -> impl Iterator<Item = f64> + '_ {
        self.tensions
            .iter()
            .chain(self.tip_force.iter())
            .chain(self.tip_moment.iter())
            .copied()
    }

    /// Scaled ∞-norm distance to `other` (see [`WARM_RADIUS`]).
    fn distance(&self, other: &Load, max: &[f64]) -> f64 {
        let tensions = self
            .tensions
            .iter()
            .zip(&other.tensions)
            .zip(max)
            .map(|((a, b), m)| (a - b).abs() / m);
        let loads = (self.tip_force - other.tip_force)
            .iter()
            .chain((self.tip_moment - other.tip_moment).iter())
            .map(|d| d.abs())
            .collect::<Vec<_>>();
        tensions.chain(loads).fold(0.0, f64::max)
    }
}

/// The canonical visiting order of `loads`: a snake (boustrophedon) walk over
/// a grid in scaled tension space with about one row per cell, ties broken by
/// comparing the rows' values. Depends only on the values, never on the
/// positions of the rows.
pub fn canonical_order(loads: &[Load], max: &[f64]) -> Vec<usize> {
    let dims = max.len().max(1) as f64;
    let cells = ((loads.len() as f64).powf(1.0 / dims).ceil() as usize).clamp(1, 64);
    let key = |load: &Load| -> Vec<usize> {
        let mut parity = 0usize;
        load.tensions
            .iter()
            .zip(max)
            .map(|(&t, &m)| {
                let c = ((t / m * cells as f64).max(0.0) as usize).min(cells - 1);
                let c = if parity % 2 == 1 { cells - 1 - c } else { c };
                parity += c;
                c
            })
            .collect()
    };
    let keys: Vec<Vec<usize>> = loads.iter().map(key).collect();
    let mut order: Vec<usize> = (0..loads.len()).collect();
    order.sort_by(|&a, &b| {
        keys[a].cmp(&keys[b]).then_with(|| {
            loads[a]
                .values()
                .zip(loads[b].values())
                .map(|(x, y)| x.total_cmp(&y))
                .find(|o| *o != CmpOrdering::Equal)
                .unwrap_or(CmpOrdering::Equal)
        })
    });
    order
}

/// Solve every row of `loads` (in parallel chains, see the module doc).
/// `done(k)` is called as chains of `k` rows finish. Returns the results in
/// the order of `loads`, or `None` when `stop` was set before the end.
pub fn solve_all(
    statics: &Statics,
    loads: &[Load],
    stop: &AtomicBool,
    done: &(dyn Fn(usize) + Sync),
) -> Option<Vec<RowResult>> {
    let max = statics.robot().max_tensions();
    let order = canonical_order(loads, &max);
    let chains: Vec<Option<Vec<(usize, RowResult)>>> = order
        .par_chunks(CHAIN)
        .map(|chain| {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            let mut previous: Option<(&Load, WarmStart)> = None;
            let mut out = Vec::with_capacity(chain.len());
            for &i in chain {
                let load = &loads[i];
                let warm = previous
                    .as_ref()
                    .filter(|(p, _)| load.distance(p, &max) <= WARM_RADIUS)
                    .map(|(_, w)| w);
                // The stable equilibrium reached from rest, or why there is
                // none (`continuation`).
                let result =
                    statics.equilibrium(&load.tensions, load.tip_force, load.tip_moment, warm);
                if let Ok(sol) = &result {
                    previous = Some((load, sol.warm.clone()));
                }
                out.push((i, result));
            }
            done(chain.len());
            Some(out)
        })
        .collect();
    if stop.load(Ordering::Relaxed) {
        return None;
    }
    let mut slots: Vec<Option<RowResult>> = (0..loads.len()).map(|_| None).collect();
    for chain in chains {
        for (i, result) in chain? {
            slots[i] = Some(result);
        }
    }
    slots.into_iter().collect()
}
