//! Exact inverse kinematics (docs/design.md §4.1), each test against an
//! independent fact: forward statics of the answer, closed forms, central
//! differences of full solves.

use std::path::{Path, PathBuf};

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use tendril::inverse::{tip_jacobian, ExactIk, IkSettings, InverseError, Target};
use tendril::robot::Robot;
use tendril::statics::rod::Rod;
use tendril::statics::{SolverSettings, Statics};

fn robot(name: &str) -> Robot {
    Robot::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../robots")
            .join(name),
    )
    .unwrap()
}

fn fk(robot: &Robot, tau: &[f64]) -> [f64; 7] {
    Statics::new(robot, SolverSettings::default())
        .solve(tau, None)
        .unwrap()
        .pose()
}

fn distance(a: &[f64; 7], b: &[f64; 7]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A robot file written to a temp dir (kept alive by the returned guard).
fn robot_from_toml(text: &str) -> (tempfile::TempDir, Robot) {
    let dir = tempfile::tempdir().unwrap();
    let path: PathBuf = dir.path().join("robot.toml");
    std::fs::write(&path, text).unwrap();
    let robot = Robot::load(&path).unwrap();
    (dir, robot)
}

/// Central differences of full statics solves, position and rotation vector.
fn jacobian_by_differences(robot: &Robot, tau: &[f64], h: f64) -> Vec<[f64; 6]> {
    let statics = Statics::new(robot, SolverSettings::default());
    (0..tau.len())
        .map(|i| {
            let mut plus = tau.to_vec();
            let mut minus = tau.to_vec();
            plus[i] += h;
            minus[i] -= h;
            let a = statics.solve(&plus, None).unwrap();
            let b = statics.solve(&minus, None).unwrap();
            let dp = (a.position - b.position) / (2.0 * h);
            let dtheta = Rotation3::from_matrix_unchecked(a.rotation * b.rotation.transpose())
                .scaled_axis()
                / (2.0 * h);
            [dp.x, dp.y, dp.z, dtheta.x, dtheta.y, dtheta.z]
        })
        .collect()
}

fn assert_jacobian_matches_differences(robot: &Robot, tau: &[f64]) {
    let settings = SolverSettings::default();
    let sol = Statics::new(robot, settings).solve(tau, None).unwrap();
    let mut rod = Rod::new(robot);
    rod.set_tensions(tau);
    let exact = tip_jacobian(&rod, &sol.warm.x, settings.steps).unwrap();
    assert!(
        (exact.position - sol.position).norm() == 0.0,
        "same tip as the solver"
    );
    let fd = jacobian_by_differences(robot, tau, 1e-4);
    for (i, col) in fd.iter().enumerate() {
        let norm = |rows: std::ops::Range<usize>, f: &dyn Fn(usize) -> f64| {
            rows.map(|r| f(r).powi(2)).sum::<f64>().sqrt()
        };
        let position_diff = norm(0..3, &|r| exact.jacobian[(r, i)] - col[r]);
        let rotation_diff = norm(3..6, &|r| exact.jacobian[(r, i)] - col[r]);
        // Positions agree to the differences' own roundoff. The rotation
        // rows differentiate R as integrated, the differences its
        // orthonormalised copy; RK4 leaves R orthogonal only to ~1e-5, so
        // the two agree to that relative level.
        assert!(
            position_diff <= 1e-8 * norm(0..3, &|r| col[r])
                && rotation_diff <= 2e-5 * norm(3..6, &|r| col[r]),
            "{}: tension {i}: exact {:?} vs differences {col:?} ({position_diff:e}, {rotation_diff:e})",
            robot.name,
            exact.jacobian.column(i).as_slice()
        );
    }
}

#[test]
fn tip_jacobian_matches_central_differences_of_full_solves() {
    // Gravity, tip anchors.
    assert_jacobian_matches_differences(&robot("seed-4t.toml"), &[4.0, 2.5, 0.5, 0.2]);
    // Anchors inside the rod: the tensions enter the anchor jumps.
    assert_jacobian_matches_differences(&robot("tdcr-2seg.toml"), &[3.0, 0.5, 1.0, 0.2, 2.0, 0.7]);
}

#[test]
fn round_trip_random_tensions_to_a_micron_within_limits() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
    for name in ["seed-4t.toml", "seed-paper.toml", "tdcr-2seg.toml"] {
        let robot = robot(name);
        let ik = ExactIk::new(&robot, IkSettings::default());
        let (lo, hi) = (robot.min_tensions(), robot.max_tensions());
        for case in 0..4 {
            let tau: Vec<f64> = lo
                .iter()
                .zip(&hi)
                .map(|(&l, &h)| rng.random_range(l..=h))
                .collect();
            let pose = fk(&robot, &tau);
            let position_only = case % 2 == 0;
            let target = Target::from_pose(&pose, position_only).unwrap();
            let answer = ik
                .solve(&target, None, None)
                .unwrap_or_else(|e| panic!("{name} {tau:?}: {e}"));
            for ((&t, &l), &h) in answer.tensions.iter().zip(&lo).zip(&hi) {
                assert!(t >= l && t <= h, "{name}: {t} outside [{l}, {h}]");
            }
            // Independent check: forward statics of the answer.
            let reached = fk(&robot, &answer.tensions);
            let err = distance(&reached, &pose);
            assert!(err <= 1e-6, "{name} {tau:?}: tip {err:e} m from the target");
            if !position_only {
                let angle = tendril::statics::pose::angle_between(
                    &[reached[3], reached[4], reached[5], reached[6]],
                    &[pose[3], pose[4], pose[5], pose[6]],
                );
                assert!(
                    angle <= 1e-5,
                    "{name} {tau:?}: orientation off by {angle:e} rad"
                );
            }
        }
    }
}

const PAIR: &str = r#"
name = "antagonistic-pair"
[backbone]
length = 0.4
radius = 0.0009
youngs_modulus = 207e9
shear_modulus = 79.6e9
density = 39317.0
[environment]
gravity = [0.0, 0.0, 0.0]
[[tendon]]
offset = 0.019
angle_deg = 0.0
max_tension = 10.0
routing = "straight"
[[tendon]]
offset = 0.019
angle_deg = 180.0
max_tension = 10.0
routing = "straight"
"#;

#[test]
fn pure_co_contraction_resolves_to_the_facing_tendon_alone() {
    // Gravity off, one tendon pulling with τ: a constant-curvature arc,
    // κ = τ d/(E I), v_z = 1 − τ/(E A) (docs/design.md §2). The target is
    // that arc's tip, computed in closed form for τ = 2 N; the statics of
    // the facing tendon alone reproduce it, and the IK target is the
    // statics' own tip (RK4 is 1e-7 m from the closed form).
    let (_dir, robot) = robot_from_toml(PAIR);
    let (tau, d, l) = (2.0, 0.019, 0.4);
    let ei = 207e9 * std::f64::consts::PI * 0.0009f64.powi(4) / 4.0;
    let ea = 207e9 * std::f64::consts::PI * 0.0009f64.powi(2);
    let kappa = tau * d / ei;
    let vz = 1.0 - tau / ea;
    let theta = kappa * l;
    let arc = Vector3::new(
        vz * (1.0 - theta.cos()) / kappa,
        0.0,
        vz * theta.sin() / kappa,
    );
    let pose = fk(&robot, &[tau, 0.0]);
    let tip = Vector3::new(pose[0], pose[1], pose[2]);
    assert!(
        (tip - arc).norm() < 1e-6,
        "statics {tip} vs closed form {arc}"
    );
    let target = Target::Position(tip);
    let ik = ExactIk::new(&robot, IkSettings::default());
    // From a co-contracted start: both pull, the tip nearly where it should be.
    let answer = ik.solve(&target, Some(&[6.0, 4.0]), None).unwrap();
    assert!(
        (answer.tensions[0] - tau).abs() < 1e-4 && answer.tensions[1] == 0.0,
        "{:?}",
        answer.tensions
    );
    assert_eq!(answer.at_min, vec![1]);
}

#[test]
fn least_total_tension_uses_only_the_two_adjacent_facing_tendons() {
    // Gravity off, four tendons, a position target bent between tendons 0
    // (0°) and 1 (90°): tendons 2 and 3 face away and stay at their floor.
    let robot = robot("seed-4t.toml").without_gravity();
    let truth = [3.0, 2.0, 0.0, 0.0];
    let pose = fk(&robot, &truth);
    let target = Target::from_pose(&pose, true).unwrap();
    let ik = ExactIk::new(&robot, IkSettings::default());
    for start in [None, Some(&[7.0, 6.0, 4.0, 4.0][..])] {
        let answer = ik.solve(&target, start, None).unwrap();
        assert_eq!(answer.at_min, vec![2, 3], "{:?}", answer.tensions);
        assert!(answer.tensions[2] <= 1e-9 && answer.tensions[3] <= 1e-9);
        for (got, want) in answer.tensions.iter().zip(&truth).take(2) {
            assert!((got - want).abs() < 1e-4, "{:?}", answer.tensions);
        }
        assert!(distance(&fk(&robot, &answer.tensions), &pose) <= 1e-6);
    }
}

#[test]
fn seed_paper_co_contraction_resolves_to_the_floors() {
    // All four tendons ≥ 5 N (the seed authors' sampling): many tension sets
    // reach a tip position; the least-total-tension one keeps the two
    // tendons facing away at their 5 N floor.
    let robot = robot("seed-paper.toml");
    let truth = [12.0, 9.0, 5.0, 5.0];
    let pose = fk(&robot, &truth);
    let target = Target::from_pose(&pose, true).unwrap();
    let ik = ExactIk::new(&robot, IkSettings::default());
    let answer = ik
        .solve(&target, Some(&[15.0, 13.0, 9.0, 8.0]), None)
        .unwrap();
    assert_eq!(answer.at_min, vec![2, 3], "{:?}", answer.tensions);
    for (got, want) in answer.tensions.iter().zip(&truth).take(2) {
        assert!((got - want).abs() < 1e-4, "{:?}", answer.tensions);
    }
    assert!(distance(&fk(&robot, &answer.tensions), &pose) <= 1e-6);
}

#[test]
fn unreachable_target_gives_the_closest_reachable_pose_and_its_limits() {
    let robot = robot("seed-4t.toml");
    let ik = ExactIk::new(&robot, IkSettings::default());
    // 0.3 m sideways along tendon 0's side: far beyond a 10 N bend.
    let target = Target::Position(Vector3::new(0.3, 0.0, 0.2));
    let Err(InverseError::Unreachable { closest }) = ik.solve(&target, None, None) else {
        panic!("an unreachable target must be reported as such");
    };
    assert!(closest.position_error > 0.01, "{}", closest.position_error);
    assert!(closest.at_max.contains(&0), "{}", closest.active_limits());
    // The closest pose is what the statics give for its tensions.
    let reached = fk(&robot, &closest.tensions);
    assert!(distance(&reached, &closest.pose) < 1e-9);
    let to_target =
        (Vector3::new(reached[0], reached[1], reached[2]) - target.position().unwrap()).norm();
    assert!((to_target - closest.position_error).abs() < 1e-9);
    let message = InverseError::Unreachable { closest }.to_string();
    assert!(message.contains("at max: tendon 0"), "{message}");
}

#[test]
fn bad_targets_are_refused_with_the_reason() {
    let nan = Target::from_pose(&[f64::NAN, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], true).unwrap_err();
    assert!(nan.to_string().contains("px"), "{nan}");
    let skew = Target::from_pose(&[0.0, 0.0, 0.4, 0.5, 0.0, 0.0, 0.0], false).unwrap_err();
    assert!(skew.to_string().contains("norm"), "{skew}");
    let q = UnitQuaternion::identity();
    let ok = Target::from_pose(&[0.0, 0.0, 0.4, q.w, q.i, q.j, q.k], false).unwrap();
    assert!(matches!(ok, Target::Pose(..)));
}
