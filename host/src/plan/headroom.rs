//! Tension headroom (`docs/design.md` §6, "Heights with headroom"): how far
//! the tensions a path asks for stay below the tendons' limits, and the
//! heights where a robot that reaches a volume keeps that room.
//!
//! The loop adds to the feed-forward tensions: the integral correction, the
//! dynamic offset, and the stiffness adaptation on a robot stiffer than its
//! file (whose tensions scale with the stiffness). A path planned where a
//! tendon already sits at its limit leaves none of them room: on the
//! three-segment robot the helix's lowest turn asked for a proximal tendon's
//! whole 1 N, the net errs by millimetres there (held-out rows with a
//! tendon at its limit: p95 6.5 mm), and the corrected helix missed its
//! 2 mm bound in `tendril run` (BENCHMARKS.md). So the heights a robot's
//! default 3-D paths use are those where the lift keeps every tendon
//! [`TENSION_HEADROOM`] of its range below its limit, and the planner says
//! when a path it was given does not.

use super::lift::HEIGHT_SAMPLES;
use super::{Lifter, PlanError, Trajectory};
use crate::dataset::resolve::slacken;
use crate::robot::Robot;

/// The share of each tendon's range (limit − floor) the default paths leave
/// free below its limit: a tenth for a robot up to 10 % stiffer than its
/// file (the robot off its file; the tensions that reach a pose
/// scale with the stiffness), a tenth for the correction and the dynamic
/// offset on top of the feed-forward.
pub const TENSION_HEADROOM: f64 = 0.2;

/// Heights scanned across the reachable band by [`Lifter::headroom_band`].
const BAND_SCAN: usize = 12;
/// Bisections refining each end of the headroom band past the scan.
const BAND_BISECTIONS: usize = 3;

/// The heights a lateral path of a robot that reaches a volume is planned
/// in ([`Lifter::planning_band`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanningBand {
    /// The heights reachable all round the circle, m ([`Lifter::height_band`]).
    pub reachable: (f64, f64),
    /// Those with the headroom asked for, m; `None` where no height has it.
    pub with_headroom: Option<(f64, f64)>,
}

impl PlanningBand {
    /// The heights with headroom, else the reachable ones.
    pub fn heights(&self) -> (f64, f64) {
        self.with_headroom.unwrap_or(self.reachable)
    }
}

/// The least headroom of a set of tensions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Headroom {
    /// `min_k (τ_max,k − τ_k) / (τ_max,k − τ_min,k)`: 1 with every tendon at
    /// its floor, 0 with one at its limit.
    pub fraction: f64,
    /// The tendon that has it.
    pub tendon: usize,
    /// Its tension, N (as commanded: co-contraction taken out).
    pub tension_n: f64,
}

/// The headroom of `tau` (N) on `robot`, as the robot is commanded: each
/// co-contraction set shifted down to its floor first ([`slacken`]: the
/// firmware's command stage does the same to the net's output, and the
/// least-bending lift leaves co-contraction wherever its first phase did).
/// A tendon whose floor is its limit (held at one tension: nothing to
/// correct with, nothing to leave) does not count. `None` without a
/// tendon that counts or with a non-finite tension.
pub fn headroom(robot: &Robot, tau: &[f64]) -> Option<Headroom> {
    if tau.iter().any(|t| !t.is_finite()) {
        return None;
    }
    let mut commanded = tau.to_vec();
    slacken(robot, &mut commanded);
    let (lo, hi) = (robot.min_tensions(), robot.max_tensions());
    commanded
        .iter()
        .enumerate()
        .filter(|&(k, _)| hi[k] > lo[k])
        .map(|(k, &t)| Headroom {
            fraction: (hi[k] - t) / (hi[k] - lo[k]),
            tendon: k,
            tension_n: t,
        })
        .min_by(|a, b| a.fraction.total_cmp(&b.fraction))
}

impl Trajectory {
    /// The least headroom along the path's feed-forward tensions (rows the
    /// exact IK gave no answer for left out); `None` without any.
    pub fn tension_headroom(&self, robot: &Robot) -> Option<Headroom> {
        self.feedforward_rows()
            .iter()
            .filter_map(|row| headroom(robot, row))
            .min_by(|a, b| a.fraction.total_cmp(&b.fraction))
    }
}

impl Lifter {
    /// The robot's mid height for a circle of `radius` (m) about lateral
    /// `center` (m): the middle of its [`Lifter::planning_band`] (the
    /// heights with [`TENSION_HEADROOM`] below every
    /// tendon's limit, else the reachable ones).
    pub fn mid_height(&self, center: [f64; 2], radius: f64) -> Result<f64, PlanError> {
        let (lo, hi) = self
            .planning_band(center, radius, TENSION_HEADROOM)?
            .heights();
        Ok(0.5 * (lo + hi))
    }

    /// The band a circle of `radius` (m) about lateral `center` (m) is
    /// planned in: the reachable heights, and within them those with
    /// `margin` headroom ([`Lifter::headroom_band`]); where none has it, a
    /// warning says the reachable band is used instead.
    pub fn planning_band(
        &self,
        center: [f64; 2],
        radius: f64,
        margin: f64,
    ) -> Result<PlanningBand, PlanError> {
        let reachable = self.height_band(center, radius)?;
        let with_headroom = self.headroom_band(center, radius, margin, reachable);
        if with_headroom.is_none() {
            log::warn!(
                "lift: no height keeps {:.0} % of every tendon's range below its limit on a \
                 {:.1} mm circle: the middle of the reachable heights instead",
                margin * 1e2,
                radius * 2e3
            );
        }
        Ok(PlanningBand {
            reachable,
            with_headroom,
        })
    }

    /// The heights (m) within the reachable band `(lo, hi)` at which a
    /// circle of `radius` (m) about lateral `center` (m) lifts with at
    /// least `margin` headroom at every one of [`HEIGHT_SAMPLES`] points
    /// around it (one point for a circle of radius 0): the longest run of
    /// heights of a [`BAND_SCAN`]-point scan that keep it, each end refined
    /// by bisection. Each height is lifted from a cold start and then warm
    /// around the circle, as a path is. `None` when no scanned height
    /// keeps it.
    pub fn headroom_band(
        &self,
        center: [f64; 2],
        radius: f64,
        margin: f64,
        (lo, hi): (f64, f64),
    ) -> Option<(f64, f64)> {
        let robot = self.ik().robot().clone();
        let samples = if radius > 0.0 { HEIGHT_SAMPLES } else { 1 };
        let keeps = |z: f64| -> bool {
            let mut lifter = self.fresh();
            (0..samples).all(|i| {
                let a = std::f64::consts::TAU * i as f64 / samples as f64;
                let u = [
                    center[0] + radius * a.cos(),
                    center[1] + radius * a.sin(),
                    z,
                ];
                lifter
                    .lifted(u)
                    .ok()
                    .and_then(|l| headroom(&robot, &l.tensions))
                    .is_some_and(|h| h.fraction >= margin)
            })
        };
        // Scan at the cells' centres: the band's own ends are where the lift
        // stops reaching.
        let step = (hi - lo) / BAND_SCAN as f64;
        let heights: Vec<f64> = (0..BAND_SCAN)
            .map(|i| lo + (i as f64 + 0.5) * step)
            .collect();
        let ok: Vec<bool> = heights.iter().map(|&z| keeps(z)).collect();
        // The longest run of consecutive heights that keep the margin (the
        // pass at BAND_SCAN closes a run that reaches the top).
        let mut best: Option<(usize, usize)> = None;
        let mut start = None;
        for i in 0..=BAND_SCAN {
            match (ok.get(i).copied().unwrap_or(false), start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    if best.is_none_or(|(a, b)| i - s > b - a + 1) {
                        best = Some((s, i - 1));
                    }
                    start = None;
                }
                _ => {}
            }
        }
        let (first, last) = best?;
        // Each end between the last height that keeps the margin and the
        // next that does not (or the band's end).
        let refine = |inside: f64, outside: f64| {
            let (mut inside, mut outside) = (inside, outside);
            for _ in 0..BAND_BISECTIONS {
                let z = 0.5 * (inside + outside);
                if keeps(z) {
                    inside = z;
                } else {
                    outside = z;
                }
            }
            inside
        };
        let below = if first == 0 { lo } else { heights[first - 1] };
        let above = if last + 1 == BAND_SCAN {
            hi
        } else {
            heights[last + 1]
        };
        Some((refine(heights[first], below), refine(heights[last], above)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::PathShape;
    use crate::statics::repo_statics as statics_of;

    /// Headroom against the closed form: a tendon at its floor has 1, one
    /// at its limit 0, half-way 0.5; a co-contraction set's common part is
    /// not counted (three tendons 120° apart pulled alike bend nothing and
    /// are commanded at their floors).
    #[test]
    fn headroom_is_the_least_share_of_the_range_left_as_commanded() {
        let robot = crate::robot::repo_robot("tdcr-2seg.toml");
        let hi = robot.max_tensions();
        let mut tau = robot.min_tensions();
        assert_eq!(headroom(&robot, &tau).unwrap().fraction, 1.0);
        tau[4] = 0.5 * hi[4];
        let h = headroom(&robot, &tau).unwrap();
        assert_eq!(h.tendon, 4);
        assert!((h.fraction - 0.5).abs() < 1e-12, "{h:?}");
        tau[1] = hi[1];
        assert_eq!(headroom(&robot, &tau).unwrap().fraction, 0.0);
        // A common part on top of a set: the same headroom once taken out.
        let sets = crate::robot::cocontraction_sets(&robot);
        let set = sets.sets()[0];
        let mut pulled = robot.min_tensions();
        pulled[4] = 0.5 * hi[4];
        let plain = headroom(&robot, &pulled).unwrap();
        for (k, &s) in sets.sets().iter().enumerate() {
            if s == set {
                pulled[k] += 0.3 * f64::from(sets.weights()[k]);
            }
        }
        assert!((headroom(&robot, &pulled).unwrap().fraction - plain.fraction).abs() < 1e-12);
        tau[0] = f64::NAN;
        assert!(headroom(&robot, &tau).is_none());
        // A tendon held at one tension (floor = limit) does not count.
        let mut held = robot.clone();
        held.tendons[1].min_tension = held.tendons[1].max_tension;
        let mut tau = held.min_tensions();
        tau[4] = 0.5 * hi[4];
        let h = headroom(&held, &tau).unwrap();
        assert_eq!(h.tendon, 4, "{h:?}");
    }

    /// On the two-segment robot the band is a part of the reachable band,
    /// a circle lifted anywhere in it keeps the margin, and just below it
    /// one does not (the band's lower end is where the margin runs out,
    /// to the bisection's resolution, an eighth of a scan cell).
    #[test]
    fn a_circle_in_the_headroom_band_keeps_its_margin() {
        let s = statics_of("tdcr-2seg.toml");
        let lifter = Lifter::new(&s).unwrap();
        let band = lifter
            .planning_band([0.0, 0.0], 0.01, TENSION_HEADROOM)
            .unwrap();
        let (lo, hi) = band.reachable;
        let (bottom, top) = band.with_headroom.unwrap();
        assert_eq!(band.heights(), (bottom, top));
        assert!(
            lo < bottom && bottom < top && top < hi,
            "{lo} {bottom} {top} {hi}"
        );
        let circle = |z: f64| {
            let shape = PathShape::Circle {
                center_m: [0.0, 0.0],
                radius_m: 0.01,
                freq_hz: 0.2,
                height_m: Some(z),
            };
            Trajectory::new(&shape, &s)
                .unwrap()
                .tension_headroom(s.robot())
                .unwrap()
                .fraction
        };
        for z in [bottom, 0.5 * (bottom + top), top] {
            assert!(circle(z) >= TENSION_HEADROOM - 0.01, "{z}: {}", circle(z));
        }
        // A quarter of a scan cell under the bottom (bisected to an
        // eighth) the margin is gone.
        let below = bottom - 0.25 * (hi - lo) / BAND_SCAN as f64;
        assert!(
            circle(below) < TENSION_HEADROOM,
            "{below}: {}",
            circle(below)
        );
    }
}
