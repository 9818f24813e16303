//! The coarse forward-kinematics table the global search seeds from
//! (`docs/design.md` §4.1): the tip pose at a grid of tensions over the box
//! [τ_min, τ_max], solved once per robot. The closest-pose problem is not
//! convex (a target at the base is closest to the robot bent fully to one
//! side, and a local descent from the floors only ever straightens it), so
//! the search restarts from the table's samples whose tips are nearest the
//! target; every local run only lowers the error, so the answer is never
//! farther than the best sample.

use nalgebra::{Matrix3, Vector3};

use super::{ExactIk, Target};
use crate::statics::{Solution, WarmStart};

/// Most samples of the table: with ~80 µs a statics solve, 729 solves take
/// ~60 ms once per robot (release).
pub const MAX_SAMPLES: usize = 729;
/// Most grid levels per tendon (a one-tendon robot's table).
const MAX_LEVELS: usize = 33;
/// Two seeds are at least this fraction of the widest tension range apart,
/// so that the restarts explore different basins, not one basin twice.
const SEPARATION: f64 = 0.3;
/// Steps of the continuation from a neighbouring sample when the direct
/// warm solve fails (a flexible robot's strongly bent poses).
const CONTINUATION_STEPS: usize = 8;

/// Sampled tip poses over the tension box.
#[derive(Clone, Debug)]
pub struct SeedTable {
    samples: Vec<Sample>,
}

#[derive(Clone, Debug)]
struct Sample {
    tensions: Vec<f64>,
    position: Vector3<f64>,
    rotation: Matrix3<f64>,
    warm: WarmStart,
}

impl SeedTable {
    /// The table of `ik`'s robot: k levels per tendon, evenly spaced from
    /// τ_min to τ_max, k the largest with kⁿ ≤ [`MAX_SAMPLES`] (5 on four
    /// tendons, 3 on six); past 9 tendons, [`MAX_SAMPLES`] pseudo-random
    /// points on the grid of {τ_min, mid, τ_max}, the floors first. Each
    /// sample is solved warm from the one before it in the grid (one level
    /// lower in one tendon), by continuation in [`CONTINUATION_STEPS`] when
    /// that fails — cold, a flexible robot's strongly bent poses need not
    /// converge. Samples that still fail are left out. Sequential, so that
    /// a lazy build inside a rayon worker cannot deadlock (~60 ms release).
    pub fn build(ik: &ExactIk) -> SeedTable {
        let (lo, hi) = ik.limits();
        let points = grid(lo, hi);
        let mut solved: Vec<Option<Solution>> = Vec::with_capacity(points.len());
        for (k, point) in points.iter().enumerate() {
            let from = (k > 0)
                .then(|| previous(k, lo.len(), points.len()))
                .and_then(|j| Some((points[j].as_slice(), solved[j].as_ref()?)))
                .or_else(|| Some((points[0].as_slice(), solved.first()?.as_ref()?)));
            solved.push(solve_near(ik, point, from));
        }
        let samples = points
            .into_iter()
            .zip(solved)
            .filter_map(|(tensions, sol)| {
                let sol = sol?;
                Some(Sample {
                    tensions,
                    position: sol.position,
                    rotation: sol.rotation,
                    warm: sol.warm,
                })
            })
            .collect();
        SeedTable { samples }
    }

    /// Samples in the table.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no sample solved.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Up to `count` seed tensions for `target`: the samples by increasing
    /// error (as the IK weighs it), each at least [`SEPARATION`] of the
    /// widest range from the seeds before it and from `avoid` (the start
    /// already tried).
    pub fn seeds(
        &self,
        ik: &ExactIk,
        target: &Target,
        count: usize,
        avoid: &[f64],
    ) -> Vec<(Vec<f64>, WarmStart)> {
        let mut ranked: Vec<(f64, &Sample)> = self
            .samples
            .iter()
            .map(|s| {
                let cost = ik.error_at(target, &s.position, &s.rotation).norm();
                (cost, s)
            })
            .filter(|(cost, _)| cost.is_finite())
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        let min_gap = SEPARATION * ik.span();
        let distance = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let mut seeds: Vec<(Vec<f64>, WarmStart)> = Vec::with_capacity(count);
        for (_, s) in ranked {
            if seeds.len() == count {
                break;
            }
            let apart = distance(&s.tensions, avoid) >= min_gap
                && seeds
                    .iter()
                    .all(|(t, _)| distance(&s.tensions, t) >= min_gap);
            if apart {
                seeds.push((s.tensions.clone(), s.warm.clone()));
            }
        }
        seeds
    }
}

/// The statics at `tensions`: warm from `from` (a solved neighbour), by
/// continuation from it if that fails, cold last.
fn solve_near(
    ik: &ExactIk,
    tensions: &[f64],
    from: Option<(&[f64], &Solution)>,
) -> Option<Solution> {
    let statics = ik.statics();
    let Some((start, near)) = from else {
        return statics.solve(tensions, None).ok();
    };
    if let Ok(sol) = statics.solve(tensions, Some(&near.warm)) {
        return Some(sol);
    }
    let mut warm = near.warm.clone();
    let mut last = None;
    for step in 1..=CONTINUATION_STEPS {
        let f = step as f64 / CONTINUATION_STEPS as f64;
        let t: Vec<f64> = start
            .iter()
            .zip(tensions)
            .map(|(a, b)| a + f * (b - a))
            .collect();
        match statics.solve(&t, Some(&warm)) {
            Ok(sol) => {
                warm = sol.warm.clone();
                last = Some(sol);
            }
            Err(_) => return statics.solve(tensions, None).ok(),
        }
    }
    last
}

/// The grid index of the point one level lower in its first non-floor
/// tendon (solved before `k` in grid order), for a grid of `total` points
/// on `n` tendons; 0 (the floors) for the pseudo-random points.
fn previous(k: usize, n: usize, total: usize) -> usize {
    let levels = (1..=MAX_LEVELS)
        .find(|l| l.checked_pow(n as u32) == Some(total))
        .unwrap_or(0);
    if levels < 2 {
        return 0;
    }
    let mut stride = 1;
    while (k / stride).is_multiple_of(levels) {
        stride *= levels;
    }
    k - stride
}

/// The table's tension points (see [`SeedTable::build`]).
fn grid(lo: &[f64], hi: &[f64]) -> Vec<Vec<f64>> {
    let n = lo.len();
    let level = |i: usize, k: usize, of: usize| {
        if of < 2 {
            lo[i]
        } else {
            lo[i] + (hi[i] - lo[i]) * k as f64 / (of - 1) as f64
        }
    };
    let mut levels = 2;
    while levels < MAX_LEVELS
        && (levels + 1).checked_pow(n as u32).unwrap_or(usize::MAX) <= MAX_SAMPLES
    {
        levels += 1;
    }
    match levels.checked_pow(n as u32) {
        Some(total) if total <= MAX_SAMPLES => (0..total)
            .map(|mut code| {
                (0..n)
                    .map(|i| {
                        let k = code % levels;
                        code /= levels;
                        level(i, k, levels)
                    })
                    .collect()
            })
            .collect(),
        _ => {
            // A fixed linear congruential sequence: the same table every run.
            let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
            let mut next = move || {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (state >> 33) as usize % 3
            };
            (0..MAX_SAMPLES)
                .map(|j| {
                    (0..n)
                        .map(|i| if j == 0 { lo[i] } else { level(i, next(), 3) })
                        .collect()
                })
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_has_k_to_the_n_points_with_the_box_corners() {
        let g = grid(&[0.0; 4], &[10.0; 4]);
        assert_eq!(g.len(), 5usize.pow(4));
        assert!(g.contains(&vec![10.0, 10.0, 0.0, 0.0]));
        assert!(g.contains(&vec![0.0; 4]));
        let g6 = grid(&[0.0; 6], &[5.0; 6]);
        assert_eq!(g6.len(), 3usize.pow(6));
        assert_eq!(grid(&[1.0], &[2.0]).len(), MAX_LEVELS);
        let g12 = grid(&[0.0; 12], &[1.0; 12]);
        assert_eq!(g12.len(), MAX_SAMPLES);
        assert_eq!(g12[0], vec![0.0; 12]);
        assert!(g12
            .iter()
            .flatten()
            .all(|&t| t == 0.0 || t == 0.5 || t == 1.0));
    }

    #[test]
    fn previous_is_one_level_lower_in_one_tendon() {
        let g = grid(&[0.0; 4], &[10.0; 4]);
        for k in 1..g.len() {
            let j = previous(k, 4, g.len());
            let differ: Vec<usize> = (0..4).filter(|&i| g[k][i] != g[j][i]).collect();
            assert_eq!(differ.len(), 1, "{k} {j}");
            assert!((g[k][differ[0]] - g[j][differ[0]] - 2.5).abs() < 1e-12);
        }
        assert_eq!(previous(5, 12, MAX_SAMPLES), 0);
    }

    /// Every sample of the default and the two-segment robot's tables
    /// solves (continuation reaches the strongly bent corners).
    #[test]
    fn tables_of_the_repo_robots_solve_every_sample() {
        for name in ["seed-4t.toml", "tdcr-2seg.toml"] {
            let robot = crate::robot::repo_robot(name);
            let ik = ExactIk::new(&robot, super::super::IkSettings::default());
            let table = SeedTable::build(&ik);
            let (lo, hi) = ik.limits();
            assert_eq!(table.len(), grid(lo, hi).len(), "{name}");
        }
    }
}
