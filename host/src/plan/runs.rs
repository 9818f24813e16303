//! The closed-loop runs the main job does on a robot, chosen by its family
//! (`docs/design.md` §6).

use serde::Serialize;

use super::{Lifter, PathShape, PlanError, TENSION_HEADROOM};
use crate::statics::Statics;

/// One closed-loop run the main job does on a robot ([`default_loop_runs`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LoopRun {
    /// Short name, fit for a directory (`circle`, `steps`, `helix`, `sweep`).
    pub name: &'static str,
    /// What it is, for the report ("20 mm circle at 395.5 mm height, 0.2 Hz").
    pub label: String,
    /// The trajectory.
    pub shape: PathShape,
    /// Seconds of trajectory after the settle hold.
    pub duration_s: f64,
}

/// The closed-loop runs the main job does for `statics`' robot, by its
/// family ([`super::Family`], `docs/design.md` §6):
///
/// - k = 2 (one bending segment): the 30 mm circle (radius 15 mm) at
///   0.2 Hz and 10 mm steps, as always;
/// - k = 3 (a volume): a 20 mm circle (radius 10 mm) at the robot's mid
///   height ([`Lifter::mid_height`]), 3-D steps of ± 8 mm sideways and
///   ± 2 mm in height about it, and a helix of radius 10 mm rising 4 mm
///   about it in one turn and back; where the band of heights with
///   [`TENSION_HEADROOM`] ([`Lifter::planning_band`]; the reachable band
///   where no height has it) is narrower than 8 mm, the height moves
///   shrink to a quarter of it;
/// - k = 1 (a curve): a sweep along the axis between where 10 % and 50 %
///   of every tendon's maximum tension puts the tip.
///
/// Each run is meant with and without the correction (the caller sets
/// `SimConfig::set_correction` in `ipc::sim`).
pub fn default_loop_runs(statics: &Statics) -> Result<Vec<LoopRun>, PlanError> {
    let mut lifter = Lifter::new(statics)?;
    let family = lifter.family();
    let mm = |v: f64| v * 1e3;
    Ok(match family.dim() {
        2 => vec![
            LoopRun {
                name: "circle",
                label: "30 mm circle at 0.2 Hz".into(),
                shape: PathShape::default_circle(),
                duration_s: 10.0,
            },
            LoopRun {
                name: "steps",
                label: "10 mm steps".into(),
                shape: PathShape::Steps {
                    targets_m: vec![
                        vec![0.01, 0.0],
                        vec![0.0, 0.01],
                        vec![-0.01, 0.0],
                        vec![0.0, -0.01],
                    ],
                    dwell_s: 2.0,
                    height_m: None,
                },
                duration_s: 10.0,
            },
        ],
        3 => {
            // The heights with headroom, else the reachable ones (the
            // planner then says how little room the paths leave).
            let (lo, hi) = lifter
                .planning_band([0.0, 0.0], 0.01, TENSION_HEADROOM)?
                .heights();
            let z = 0.5 * (lo + hi);
            // ± 2 mm in height, or a quarter of the band where it is
            // narrower (a long robot resolved by least tension reaches only
            // a thin band just under its straight height off the axis).
            let dz = (0.002f64).min(0.25 * (hi - lo));
            vec![
                LoopRun {
                    name: "circle",
                    label: format!("20 mm circle at the mid height {:.1} mm, 0.2 Hz", mm(z)),
                    shape: PathShape::Circle {
                        center_m: [0.0, 0.0],
                        radius_m: 0.01,
                        freq_hz: 0.2,
                        height_m: Some(z),
                    },
                    duration_s: 10.0,
                },
                LoopRun {
                    name: "steps",
                    label: format!(
                        "3-D steps, ± 8 mm sideways and ± {:.1} mm about {:.1} mm height",
                        mm(dz),
                        mm(z)
                    ),
                    shape: PathShape::Steps {
                        targets_m: vec![
                            vec![0.008, 0.0, z],
                            vec![0.0, 0.008, z + dz],
                            vec![-0.008, 0.0, z - dz],
                            vec![0.0, -0.008, z],
                        ],
                        dwell_s: 2.0,
                        height_m: None,
                    },
                    duration_s: 8.0,
                },
                LoopRun {
                    name: "helix",
                    label: format!(
                        "helix of radius 10 mm between {:.1} and {:.1} mm height, 0.2 Hz",
                        mm(z - dz),
                        mm(z + dz)
                    ),
                    shape: PathShape::Helix {
                        center_m: [0.0, 0.0],
                        radius_m: 0.01,
                        freq_hz: 0.2,
                        heights_m: [z - dz, z + dz],
                        turns: 1.0,
                    },
                    duration_s: 10.0,
                },
            ]
        }
        _ => {
            let robot = statics.robot();
            let floors = robot.min_tensions();
            let at = |fraction: f64| -> Result<f64, PlanError> {
                let tau: Vec<f64> = floors
                    .iter()
                    .zip(robot.max_tensions())
                    .map(|(lo, hi)| lo + fraction * (hi - lo))
                    .collect();
                let sol = statics
                    .solve(&tau, None)
                    .map_err(|e| PlanError::Statics(format!("sweep range: {e}")))?;
                Ok(family.coordinates(&sol.position.into())[0])
            };
            let (from, to) = (at(0.1)?, at(0.5)?);
            // Both ends must lift (a robot whose pull saturates early).
            lifter.lift([from])?;
            lifter.lift([to])?;
            vec![LoopRun {
                name: "sweep",
                label: format!(
                    "sweep along the axis from {:.1} to {:.1} mm, 0.2 Hz",
                    mm(from),
                    mm(to)
                ),
                shape: PathShape::Sweep {
                    from_m: from,
                    to_m: to,
                    freq_hz: 0.2,
                },
                duration_s: 10.0,
            }]
        }
    })
}

/// The sub-directory of a run: `sim` for the circle (the name the main
/// job has always used), else `sim-<name>`; `-ik-only` is appended for the
/// run without the correction.
pub fn run_dir(run: &LoopRun, correction: bool) -> String {
    let base = if run.name == "circle" {
        "sim".to_string()
    } else {
        format!("sim-{}", run.name)
    };
    if correction {
        base
    } else {
        format!("{base}-ik-only")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Trajectory;

    use crate::statics::repo_statics as statics_of;

    /// Each robot gets the runs of its family (the default robot the two it
    /// always had), and every run's trajectory lifts on that robot.
    #[test]
    fn default_loop_runs_follow_the_family_and_all_lift() {
        for (file, names) in [
            ("seed-4t.toml", vec!["circle", "steps"]),
            ("tdcr-2seg.toml", vec!["circle", "steps", "helix"]),
            ("seed-1t.toml", vec!["sweep"]),
        ] {
            let s = statics_of(file);
            let runs = default_loop_runs(&s).unwrap();
            let got: Vec<&str> = runs.iter().map(|r| r.name).collect();
            assert_eq!(got, names, "{file}");
            for run in &runs {
                let traj = Trajectory::new(&run.shape, &s)
                    .unwrap_or_else(|e| panic!("{file} {}: {e}", run.name));
                assert!(traj.duration() > 0.0 && run.duration_s > 0.0);
                // The volume's runs are planned with headroom (the band
                // is sampled at 8 points of the circle, the path at 500:
                // a little slack). On the two-segment robot only: the
                // three-segment robot's runs take a minute to lift in a
                // release build (the main job's run checks them).
                if file == "tdcr-2seg.toml" {
                    let h = traj.tension_headroom(s.robot()).unwrap();
                    assert!(h.fraction > TENSION_HEADROOM - 0.01, "{}: {h:?}", run.name);
                }
            }
        }
        let four = default_loop_runs(&statics_of("seed-4t.toml")).unwrap();
        assert_eq!(four[0].shape, PathShape::default_circle());
    }
}
