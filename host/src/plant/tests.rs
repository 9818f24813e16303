//! The plant against the rod's identified modes (`docs/design.md` §6.4):
//! what the plant shows after a step is what `dynamics::modes` says.

use super::reality::Reality;
use super::{PlantModel, PlantParams};
use crate::dynamics::modes::{identify, ModeSearch};
use crate::robot::groups::anchor_groups;
use crate::robot::repo_robot;
use crate::statics::{SolverSettings, Statics};

/// Each built-in robot with the lightly damped dynamic rod: a step of one
/// tendon through the motors, and the tip's ringing afterwards — its
/// period read from the crossings of the equilibrium the statics give for
/// the commanded tensions — is the identified first mode's damped
/// frequency within 5 %.
#[test]
fn the_plant_rings_after_a_step_at_the_identified_first_mode() {
    let reality = Reality::builtin("dynamic-light-damping").unwrap();
    for name in ["seed-4t.toml", "tdcr-2seg.toml", "tdcr-3seg.toml"] {
        let robot = repo_robot(name);
        let n = robot.n_tendons();
        // The outermost segment's first tendon, to a tenth of its range.
        let i = *anchor_groups(&robot).last().unwrap().first().unwrap();
        let mut command = vec![0.0; n];
        command[i] = 0.1 * robot.max_tensions()[i];
        let real = reality.real_robot(&robot).unwrap();
        let mode = identify(
            &real,
            reality.damping(&real),
            &command,
            &ModeSearch::default(),
        )
        .unwrap()[0];
        let rest = Statics::new(&real, SolverSettings::default())
            .solve(&command, None)
            .unwrap()
            .position;
        let mut plant = PlantModel::new(
            &robot,
            PlantParams {
                noise_m: 0.0,
                noise_quat: 0.0,
                reality: Some(reality.clone()),
                ..PlantParams::default()
            },
        )
        .unwrap();
        let start = plant.pose();
        let direction = (rest - nalgebra::Vector3::new(start[0], start[1], start[2])).normalize();
        // From 0.3 s (the motors have settled, the second mode has died),
        // five periods of the first.
        let dt = 1e-3;
        let (from_s, to_s) = (0.3, 0.3 + 5.0 / mode.damped_freq_hz());
        let mut last: Option<(f64, f64)> = None;
        let mut crossings = Vec::new();
        let mut t = 0.0;
        while t < to_s {
            plant.command(&command);
            assert!(plant.step(dt), "{name}: step at {t} s failed");
            t += dt;
            let p = plant.pose();
            let x = (nalgebra::Vector3::new(p[0], p[1], p[2]) - rest).dot(&direction);
            if let Some((t0, x0)) = last {
                if t >= from_s && x0 < 0.0 && x >= 0.0 {
                    crossings.push(t0 + dt * x0 / (x0 - x));
                }
            }
            last = Some((t, x));
        }
        assert!(crossings.len() >= 3, "{name}: {crossings:?}");
        let period = (crossings.last().unwrap() - crossings[0]) / (crossings.len() - 1) as f64;
        let ringing_hz = 1.0 / period;
        let gap = ringing_hz / mode.damped_freq_hz() - 1.0;
        eprintln!(
            "{name}: identified f1 {:.4} Hz (zeta {:.4}, damped {:.4} Hz), plant rings at {ringing_hz:.4} Hz ({:+.2} %)",
            mode.freq_hz,
            mode.damping_ratio,
            mode.damped_freq_hz(),
            100.0 * gap
        );
        assert!(gap.abs() < 0.05, "{name}: {:+.2} %", 100.0 * gap);
    }
}
