//! Stability of the statics solution and continuation from rest
//! (`continuation`, `stability`), against independent facts: Euler's
//! clamped–free column, the linear cantilever, and the bound of 90° on the
//! tip turned by a dead lateral force.

use nalgebra::Vector3;

use crate::robot::{repo_robot as load, Robot};
use crate::statics::pose::angle_between;
use crate::statics::*;

/// Euler's critical load of `robot` as a clamped–free column, N.
fn euler_load(robot: &Robot) -> f64 {
    std::f64::consts::PI.powi(2) * robot.kbt().x / (4.0 * robot.length.powi(2))
}

fn axial(p: f64) -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -p)
}

fn zero() -> Vector3<f64> {
    Vector3::zeros()
}

/// Rotation of the tip from the base frame, degrees.
fn tip_angle_deg(sol: &Solution) -> f64 {
    angle_between(&sol.quaternion, &[1.0, 0.0, 0.0, 0.0]).to_degrees()
}

#[test]
fn a_straight_column_is_stable_below_the_euler_load_and_unstable_above() {
    for name in ["seed-4t.toml", "tdcr-2seg.toml"] {
        let robot = load(name).without_gravity();
        let statics = Statics::new(&robot, SolverSettings::default());
        let tau = vec![0.0; robot.n_tendons()];
        let pcr = euler_load(&robot);
        for ratio in [0.5, 0.97] {
            let f = axial(ratio * pcr);
            let sol = statics.solve_loaded(&tau, f, zero(), None).unwrap();
            assert_eq!(
                statics.check_stable(&sol, f, zero()),
                Ok(()),
                "{name} at {ratio} P_cr"
            );
        }
        for ratio in [1.03, 1.5, 3.0] {
            let f = axial(ratio * pcr);
            // The shooting solve finds the straight column, which is an
            // equilibrium, and would print it.
            let sol = statics.solve_loaded(&tau, f, zero(), None).unwrap();
            assert!(sol.position.xy().norm() < 1e-12, "{name}: not straight");
            let Err(SolveError::Unstable { conjugate_at_m }) =
                statics.check_stable(&sol, f, zero())
            else {
                panic!("{name}: straight column at {ratio} P_cr not reported unstable");
            };
            // The piece [0, s] with the rest frozen (an arm of L − s carrying
            // P) is neutral where cot(k s) = k (L − s), k = √(P/EI); the test
            // reports the first grid node past it.
            let k = (ratio * pcr / robot.kbt().x).sqrt();
            let l = robot.length;
            let (mut lo, mut hi) = (1e-9, l);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if 1.0 / (k * mid).tan() > k * (l - mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let h = l / statics.settings().steps as f64;
            assert!(
                conjugate_at_m >= lo - 1e-9 && conjugate_at_m <= lo + h + 1e-9,
                "{name} at {ratio} P_cr: conjugate point {conjugate_at_m} vs {lo} (+ one node)"
            );
        }
    }
}

#[test]
fn loading_a_perfect_column_past_the_euler_load_is_reported_not_unique() {
    let robot = load("seed-4t.toml").without_gravity();
    let statics = Statics::new(&robot, SolverSettings::default());
    let ratio = 1.3;
    let result = statics.equilibrium(&[0.0; 4], axial(ratio * euler_load(&robot)), zero(), None);
    let Err(SolveError::NonUnique { load_fraction }) = result else {
        panic!("perfect column at {ratio} P_cr: {result:?}");
    };
    assert!(
        (load_fraction - 1.0 / ratio).abs() < 2e-3,
        "bifurcation at {load_fraction} of the load, Euler says {}",
        1.0 / ratio
    );
}

#[test]
fn a_buckled_column_follows_a_small_lateral_force() {
    let robot = load("seed-4t.toml").without_gravity();
    let statics = Statics::new(&robot, SolverSettings::default());
    let p = 1.5 * euler_load(&robot);
    for sign in [1.0, -1.0] {
        let lateral = sign * 1e-3 * p;
        let f = Vector3::new(0.0, lateral, -p);
        let sol = statics.equilibrium(&[0.0; 4], f, zero(), None).unwrap();
        // Far more than the small force alone would bend it (F L³ / 3EI).
        let linear = lateral.abs() * robot.length.powi(3) / (3.0 * robot.kbt().x);
        assert!(
            sign * sol.position.y > 50.0 * linear,
            "tip {:?} vs linear {linear}",
            sol.position
        );
        assert_eq!(statics.check_stable(&sol, f, zero()), Ok(()));
    }
}

#[test]
fn a_lateral_tip_force_bends_the_rod_toward_it_from_seven_to_ten_newtons() {
    // Gravity and the force both along +x: a dead lateral force turns the
    // tip toward it, never past 90°. The shooting solve alone found the tip
    // at −x turned 178° for 10 N and did not converge for 7–9 N.
    let statics = repo_statics("seed-4t.toml");
    let mut last_x = 0.0;
    for f in [7.0, 8.0, 9.0, 10.0] {
        let load = Vector3::new(f, 0.0, 0.0);
        let sol = statics.equilibrium(&[0.0; 4], load, zero(), None).unwrap();
        assert!(sol.position.x > last_x, "{f} N: x {}", sol.position.x);
        assert!(
            tip_angle_deg(&sol) < 90.0,
            "{f} N: {}°",
            tip_angle_deg(&sol)
        );
        last_x = sol.position.x;
    }
}

#[test]
fn the_reversed_equilibrium_of_a_ten_newton_lateral_force_is_unstable() {
    // The shooting solve started cold from the analytic guess converges to
    // a rod hooked back on itself, the tip beyond 90° at −x: an
    // equilibrium, and an unstable one, which the test must flag.
    let statics = repo_statics("seed-4t.toml");
    let load = Vector3::new(10.0, 0.0, 0.0);
    let hooked = statics.solve_loaded(&[0.0; 4], load, zero(), None).unwrap();
    assert!(tip_angle_deg(&hooked) > 90.0 && hooked.position.x < 0.0);
    assert!(matches!(
        statics.check_stable(&hooked, load, zero()),
        Err(SolveError::Unstable { .. })
    ));
}

#[test]
fn small_tip_force_through_continuation_matches_cantilever_theory() {
    // δ = F L³ / (3 E I) for a tip force on a weightless cantilever.
    let robot = load("seed-4t.toml").without_gravity();
    let statics = Statics::new(&robot, SolverSettings::default());
    let f = 1e-3;
    let sol = statics
        .equilibrium(&[0.0; 4], Vector3::new(0.0, f, 0.0), zero(), None)
        .unwrap();
    let beam = f * robot.length.powi(3) / (3.0 * robot.kbt().x);
    let rel = (sol.position.y - beam).abs() / beam;
    assert!(
        rel < 1e-3,
        "deflection {} vs {beam} (rel {rel:e})",
        sol.position.y
    );
}

#[test]
fn tendon_poses_are_stable_and_unchanged_by_the_test() {
    // The poses the datasets hold: every tension vector of a coarse grid up
    // to the limits. The unloaded equilibrium is the plain solve, bit for bit.
    for name in ["seed-4t.toml", "tdcr-2seg.toml"] {
        let statics = repo_statics(name);
        let max = statics.robot().max_tensions();
        let n = max.len();
        for code in 0..3usize.pow(n as u32) {
            let tau: Vec<f64> = (0..n)
                .map(|i| (code / 3usize.pow(i as u32) % 3) as f64 * 0.5 * max[i])
                .collect();
            let plain = statics.solve(&tau, None).unwrap();
            assert_eq!(
                statics.check_stable(&plain, zero(), zero()),
                Ok(()),
                "{name} {tau:?}"
            );
            let checked = statics.equilibrium(&tau, zero(), zero(), None).unwrap();
            assert_eq!(plain.position, checked.position, "{name} {tau:?}");
        }
    }
}

#[test]
fn a_load_the_grid_cannot_follow_is_reported_as_stalled_with_how_far_it_got() {
    // 1000 N sideways on seed-4t (F L²/EI ≈ 1500): the continuation spends
    // its steps and says how far it got, with no NaN in the message.
    let statics = repo_statics("seed-4t.toml");
    let result = statics.equilibrium(&[0.0; 4], Vector3::new(1000.0, 0.0, 0.0), zero(), None);
    match result {
        Ok(sol) => assert!(tip_angle_deg(&sol) < 90.0 && sol.position.x > 0.0),
        Err(SolveError::Stalled { load_fraction }) => {
            assert!((0.0..1.0).contains(&load_fraction))
        }
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn a_column_standing_under_its_own_weight_buckles_past_greenhills_load() {
    // A clamped–free column under its own weight q per length buckles at
    // q L³ = 7.837 E I (Greenhill). Gravity along −z makes the weight of
    // the rod standing on its base compress it.
    let base = load("seed-4t.toml");
    let unit = base.density * base.area();
    let greenhill = 7.837 * base.kbt().x / base.length.powi(3) / unit;
    for (ratio, stable) in [(0.9, true), (1.1, false)] {
        let mut robot = base.clone();
        robot.gravity = Vector3::new(0.0, 0.0, -ratio * greenhill);
        let statics = Statics::new(&robot, SolverSettings::default());
        let result = statics.equilibrium(&[0.0; 4], zero(), zero(), None);
        match (stable, &result) {
            (true, Ok(sol)) => assert!(sol.position.xy().norm() < 1e-12),
            (false, Err(SolveError::Unstable { .. })) => {}
            _ => panic!("{ratio} × Greenhill's load: {result:?}"),
        }
    }
}
