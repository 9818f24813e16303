//! What the learners learn (`docs/design.md` §4): the dataset's tensions
//! with each co-contraction set's component along its weight direction
//! removed — "tensions up to co-contraction".
//!
//! The dataset's least-tension rows keep a tendon of every set at its
//! floor, and which tendon that is flips with the bend direction: the raw
//! targets are kinked functions of the pose, costly for a 64-unit net. Their
//! centred version τ' = τ − (w·τ / w·w) w (per set, weights `w`) is smooth,
//! and the firmware's command stage (`command_stage::command_for`, its
//! `co_contract`) shifts each set back up along `w` until its lowest member
//! sits at its floor: exactly the dataset's tension again (tested below).
//! Tendons in no set are left as they are.

use nalgebra::DMatrix;
use serde::Serialize;
use tendril_shared::CoContraction;

use crate::dataset::{Dataset, Sampler, Sidecar};
use crate::robot::cocontraction_sets;
use crate::robot::Robot;

/// How the learners' targets are formed from a dataset's tensions.
#[derive(Clone, Debug, PartialEq)]
pub enum Targets {
    /// The tensions as they are (a robot with no co-contraction set, or a
    /// dataset whose rows are not least-tension, where centring would lose
    /// the co-contraction the stage cannot restore).
    Tensions,
    /// Each co-contraction set's component along its weights removed.
    Centred(CoContraction),
}

/// The targets as recorded in a training report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetsSummary {
    /// Whether the targets were centred.
    pub centred: bool,
    /// The co-contraction sets used: member tendons of each set.
    pub sets: Vec<Vec<usize>>,
    /// Their weights, in the same order.
    pub weights: Vec<Vec<f64>>,
}

impl Targets {
    /// Centred on `robot`'s co-contraction sets, or the tensions when it has none.
    pub fn for_robot(robot: &Robot) -> Targets {
        let sets = cocontraction_sets(robot);
        if sets.is_empty() {
            Targets::Tensions
        } else {
            Targets::Centred(sets)
        }
    }

    /// [`Targets::for_robot`], unless the dataset's sidecar says its rows
    /// come from the `uniform` sampler: those rows co-contract at random, the
    /// stage could not give that back, so the targets stay the tensions.
    pub fn for_dataset(robot: &Robot, sidecar: Option<&Sidecar>) -> Targets {
        Targets::for_sampler(robot, sidecar.map(|s| s.sampler.as_str()))
    }

    /// [`Targets::for_dataset`] from the sampler's name alone.
    pub fn for_sampler(robot: &Robot, sampler: Option<&str>) -> Targets {
        if sampler == Some(Sampler::Uniform.name()) {
            Targets::Tensions
        } else {
            Targets::for_robot(robot)
        }
    }

    /// Member tendons and weights of each set (empty for [`Targets::Tensions`]).
    fn groups(&self) -> Vec<(Vec<usize>, Vec<f64>)> {
        let Targets::Centred(sets) = self else {
            return Vec::new();
        };
        let (set, weight) = (sets.sets(), sets.weights());
        let mut ids: Vec<u8> = set
            .iter()
            .copied()
            .filter(|&s| s != CoContraction::NONE)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids.into_iter()
            .map(|id| {
                let members: Vec<usize> = (0..set.len()).filter(|&i| set[i] == id).collect();
                let w = members.iter().map(|&i| f64::from(weight[i])).collect();
                (members, w)
            })
            .collect()
    }

    /// Centre one row of tensions in place: τ ← τ − (w·τ / w·w) w per set.
    pub fn centre_row(&self, tensions: &mut [f64]) {
        for (members, w) in self.groups() {
            if members.iter().any(|&i| i >= tensions.len()) {
                continue;
            }
            let along: f64 = members.iter().zip(&w).map(|(&i, w)| w * tensions[i]).sum();
            let norm2: f64 = w.iter().map(|w| w * w).sum();
            let c = along / norm2;
            for (&i, w) in members.iter().zip(&w) {
                tensions[i] -= c * w;
            }
        }
    }

    /// `tensions` (`n × T`, N) with every row centred.
    pub fn of(&self, tensions: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = tensions.clone();
        if *self == Targets::Tensions {
            return out;
        }
        let mut row = vec![0.0; out.ncols()];
        for r in 0..out.nrows() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = out[(r, c)];
            }
            self.centre_row(&mut row);
            for (c, v) in row.iter().enumerate() {
                out[(r, c)] = *v;
            }
        }
        out
    }

    /// `data` with its tensions replaced by these targets (poses unchanged).
    pub fn learning_data(&self, data: &Dataset) -> Dataset {
        Dataset {
            n_tendons: data.n_tendons,
            tensions: self.of(&data.tensions),
            poses: data.poses.clone(),
        }
    }

    /// For the training report.
    pub fn summary(&self) -> TargetsSummary {
        let groups = self.groups();
        TargetsSummary {
            centred: matches!(self, Targets::Centred(_)),
            sets: groups.iter().map(|(m, _)| m.clone()).collect(),
            weights: groups.into_iter().map(|(_, w)| w).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command_stage::{command_for, limits_for};
    use crate::robot::anchor_groups;

    use crate::robot::repo_robot as robot;

    /// The co-contraction shift in f64: each set moved along `w` by the
    /// smallest α that brings every member to or above its floor — the
    /// arithmetic of the firmware's `co_contract` for a centred row (all
    /// members then sit at or below their range).
    fn lift_to_floor(targets: &Targets, floor: &[f64], t: &mut [f64]) {
        for (members, w) in targets.groups() {
            let alpha = members
                .iter()
                .zip(&w)
                .map(|(&i, w)| (floor[i] - t[i]) / w)
                .fold(f64::NEG_INFINITY, f64::max);
            for (&i, w) in members.iter().zip(&w) {
                t[i] += alpha * w;
            }
        }
    }

    /// Centring, then the command stage, gives the grouped sampler's rows
    /// back: the sampler leaves a tendon of every set at its floor, so the
    /// lift to the floor undoes the centring exactly (f64: 1e-12 N; the
    /// firmware's f32 stage: to f32 rounding of the tensions).
    fn centring_is_undone_by_the_stage(name: &str, expect_sets: usize) {
        let r = robot(name);
        let targets = Targets::for_robot(&r);
        assert_eq!(targets.summary().sets.len(), expect_sets, "{name}");
        let limits = limits_for(&r, 1.0).unwrap();
        let (floor, top) = (r.min_tensions(), r.max_tensions());
        let rows = Sampler::Adjacent.draw_grouped(500, &floor, &top, &anchor_groups(&r), 11);
        let mut moved = 0.0f64;
        for t in rows {
            let mut centred = t.clone();
            targets.centre_row(&mut centred);
            moved = moved.max(
                centred
                    .iter()
                    .zip(&t)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max),
            );
            let mut lifted = centred.clone();
            lift_to_floor(&targets, &floor, &mut lifted);
            for (k, (a, b)) in lifted.iter().zip(&t).enumerate() {
                assert!((a - b).abs() <= 1e-12, "{name} tendon {k}: {a} vs {b}");
            }
            let staged = command_for(&limits, &centred);
            for (k, (a, b)) in staged.iter().zip(&t).enumerate() {
                let f32_ulps = 4.0 * f64::from(f32::EPSILON) * top[k];
                assert!((a - b).abs() <= f32_ulps, "{name} tendon {k}: {a} vs {b}");
            }
        }
        assert!(moved > 0.1, "{name}: centring moved nothing ({moved} N)");
    }

    #[test]
    fn centring_then_the_stage_gives_two_segment_rows_back() {
        centring_is_undone_by_the_stage("tdcr-2seg.toml", 2);
    }

    #[test]
    fn centring_then_the_stage_gives_default_robot_rows_back() {
        centring_is_undone_by_the_stage("seed-4t.toml", 2);
    }

    #[test]
    fn centred_rows_have_no_component_along_any_set() {
        let r = robot("tdcr-2seg.toml");
        let targets = Targets::for_robot(&r);
        let mut t = vec![1.0, 4.0, 2.5, 0.0, 3.0, 5.0];
        targets.centre_row(&mut t);
        for (members, w) in targets.groups() {
            let along: f64 = members.iter().zip(&w).map(|(&i, w)| w * t[i]).sum();
            assert!(along.abs() < 1e-12, "{members:?}: {along}");
        }
        // Differences inside a set (the bend) are kept.
        assert!((t[1] - t[0] - 3.0).abs() < 1e-12 && (t[5] - t[4] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_robot_without_sets_and_uniform_data_keep_the_tensions() {
        assert_eq!(
            Targets::for_robot(&robot("seed-1t.toml")),
            Targets::Tensions
        );
        let r = robot("seed-4t.toml");
        assert_eq!(Targets::for_sampler(&r, Some("uniform")), Targets::Tensions);
        assert!(Targets::for_sampler(&r, Some("adjacent")).summary().centred);
        assert!(Targets::for_sampler(&r, None).summary().centred);
    }
}
