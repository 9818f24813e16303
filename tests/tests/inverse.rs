//! Inverse kinematics, each test against an independent fact
//! (docs/design.md §4.1, §7):
//! - the exact model-based IK of the library: forward statics of the
//!   answer, closed forms, central differences of full solves;
//! - `tendril ik --exact` through the real binary: the printed tensions
//!   reach the target under `tendril fk`, the batch writes one checked row
//!   per target, bad input fails with one line and writes nothing;
//! - `tendril ik` with a net never hands out an impossible tension: the
//!   cases of a hostile probe (a non-unit quaternion, w < 0, a pose far
//!   outside the workspace, px = 1e39, a zero quaternion, outputs beyond the
//!   tendon limits), with the firmware's built-in net for the seed robot.

use std::path::PathBuf;

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use tendril::inverse::{tip_jacobian, ExactIk, IkSettings, InverseError, Redundancy, Target};
use tendril::robot::{repo_robot as robot, Robot};
use tendril::statics::rod::Rod;
use tendril::statics::{SolverSettings, Statics};
use tendril_tests::{assert_ok, json as json_file, tendril, workspace_root};

// --- the exact IK of the library -------------------------------------------

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

/// Σ over each segment's three tendons (120° apart) of (τ − their mean)²:
/// 2/3 of the squared bending moment each segment's tendons apply.
fn bending_effort(t: &[f64]) -> f64 {
    t.chunks(3)
        .map(|g| {
            let mean = g.iter().sum::<f64>() / 3.0;
            g.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
        })
        .sum()
}

#[test]
fn least_bending_resolution_is_a_local_minimum_on_the_target_set() {
    // Three segments, nine tendons (listed segment by segment), position
    // targets: a six-dimensional target set. Independent of phase 2's
    // projection: from random nearby starts, phase 1 alone (Gauss–Newton
    // back onto the target set) never finds tensions of less bending
    // effort; neither the drawn tensions nor the least-total answer has
    // less.
    let robot = robot("tdcr-3seg.toml");
    let with = |redundancy| {
        ExactIk::new(
            &robot,
            IkSettings {
                redundancy,
                ..IkSettings::default()
            },
        )
    };
    let (least_bending, any, least_total) = (
        with(Redundancy::LeastBending),
        with(Redundancy::Any),
        with(Redundancy::LeastTotal),
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
    for drawn in [
        [0.3, 0.2, 0.0, 0.0, 0.4, 0.1, 0.2, 0.0, 0.5],
        [0.0, 0.6, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.3],
        [0.1, 0.0, 0.7, 0.0, 0.2, 0.6, 0.4, 0.4, 0.0],
    ] {
        let pose = fk(&robot, &drawn);
        let target = Target::from_pose(&pose, true).unwrap();
        let answer = least_bending.solve(&target, None, None).unwrap();
        assert!(distance(&fk(&robot, &answer.tensions), &pose) <= 1e-6);
        let least = bending_effort(&answer.tensions);
        let total = least_total.solve(&target, None, None).unwrap();
        assert!(
            least <= bending_effort(&drawn),
            "{least} vs drawn {drawn:?}"
        );
        assert!(
            least <= bending_effort(&total.tensions) + 1e-9,
            "{:?}",
            total.tensions
        );
        for _ in 0..12 {
            let start: Vec<f64> = answer
                .tensions
                .iter()
                .map(|t| (t + rng.random_range(-0.03..0.03)).clamp(0.0, 1.0))
                .collect();
            let other = any.solve(&target, Some(&start), None).unwrap();
            assert!(distance(&fk(&robot, &other.tensions), &pose) <= 1e-6);
            assert!(
                bending_effort(&other.tensions) >= least - 1e-7,
                "{:?} ({}) below the answer {:?} ({least})",
                other.tensions,
                bending_effort(&other.tensions),
                answer.tensions
            );
        }
    }
}

#[test]
fn least_bending_tensions_follow_a_moving_target_without_jumps() {
    // Along a 20 mm straight line of tip positions, 1 mm apart, each solved
    // cold: the least-bending answer moves by a similar amount per step (a
    // function a learner can follow; the least total tension jumps between
    // tendon sets).
    let robot = robot("tdcr-3seg.toml");
    let ik = ExactIk::new(
        &robot,
        IkSettings {
            redundancy: Redundancy::LeastBending,
            ..IkSettings::default()
        },
    );
    let start = fk(&robot, &[0.3, 0.2, 0.0, 0.0, 0.4, 0.1, 0.2, 0.0, 0.5]);
    let answers: Vec<Vec<f64>> = (0..=20)
        .map(|k| {
            let p = Vector3::new(start[0] - 0.001 * k as f64, start[1], start[2]);
            let target = Target::Position(p);
            ik.solve(&target, None, None).unwrap().tensions
        })
        .collect();
    let steps: Vec<f64> = answers
        .windows(2)
        .map(|w| {
            w[0].iter()
                .zip(&w[1])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        })
        .collect();
    let mut sorted = steps.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(median > 0.0);
    assert!(
        sorted[sorted.len() - 1] <= 3.0 * median,
        "largest tension step {} N against a median {median} N: {steps:?}",
        sorted[sorted.len() - 1]
    );
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

// --- `tendril ik --exact` through the binary ----------------------------------

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

fn fk_pose(tensions: &str) -> Vec<f64> {
    let v = json(&tendril(&["fk", "--tensions", tensions, "--json"]));
    v["position"]
        .as_array()
        .unwrap()
        .iter()
        .chain(v["quaternion"].as_array().unwrap())
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn join(v: &[f64]) -> String {
    v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
}

#[test]
fn exact_single_pose_reaches_the_target_under_forward_statics() {
    let pose = fk_pose("4,3,0,0");
    let v = json(&tendril(&[
        "ik",
        "--exact",
        "--pose",
        &join(&pose),
        "--json",
    ]));
    assert_eq!(v["reachable"], true);
    let tau: Vec<f64> = v["tensions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    // Independent check: the statics of the printed tensions.
    let reached = fk_pose(&join(&tau));
    let err = (0..3)
        .map(|k| (reached[k] - pose[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(err <= 1e-6, "tip {err:e} m from the target");
    assert!(v["orientation_error"].as_f64().unwrap() <= 1e-5);

    // Position only, beyond reach: the closest pose is printed, exit non-zero.
    let out = tendril(&[
        "ik",
        "--exact",
        "--position-only",
        "--pose",
        "0.3,0,0.2,1,0,0,0",
        "--json",
    ]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["reachable"], false);
    assert!(v["position_error"].as_f64().unwrap() > 0.01);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("out of reach"), "{stderr}");
}

#[test]
fn exact_batch_writes_checked_rows_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poses.csv");
    let output = dir.path().join("tensions.csv");
    let a = fk_pose("2,0,0,0");
    let b = fk_pose("0,5,1,0");
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n{}\n", join(&a), join(&b)),
    )
    .unwrap();
    let (i, o) = (input.to_str().unwrap(), output.to_str().unwrap());
    let out = tendril(&[
        "ik",
        "--exact",
        "--position-only",
        "--input",
        i,
        "--output",
        o,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&output).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t0,t1,t2,t3,px,py,pz,qw,qx,qy,qz,position_error,orientation_error,reachable,status"
    );
    for (line, pose) in lines.zip([&a, &b]) {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[13], "1");
        let reached = fk_pose(&cells[..4].join(","));
        let err = (0..3)
            .map(|k| (reached[k] - pose[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err <= 1e-6, "{line}: tip {err:e} m from the target");
    }

    // A non-unit quaternion on line 3: one line naming it, nothing written.
    let bad_out = dir.path().join("bad.csv");
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n0.1,0,0.3,0.5,0,0,0\n", join(&a)),
    )
    .unwrap();
    let out = tendril(&[
        "ik",
        "--exact",
        "--input",
        i,
        "--output",
        bad_out.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("line 3") && stderr.contains("norm"),
        "{stderr}"
    );
    assert!(!bad_out.exists());
}

/// `tendril evaluate --model M --data D [--robot R]` (tempdir paths): the
/// report, and stdout.
fn evaluate_built_in_net(
    dir: &std::path::Path,
    data: &str,
    robot: &[&str],
) -> (serde_json::Value, String) {
    let json_out = dir.join(format!("{data}.e.json"));
    let data = dir.join(data);
    let args = [
        &[
            "evaluate",
            "--model",
            "firmware/vectors/default.tnet",
            "--data",
            data.to_str().unwrap(),
            "--json-out",
            json_out.to_str().unwrap(),
        ][..],
        robot,
    ]
    .concat();
    let out = tendril(&args);
    assert_ok(&out, "evaluate the built-in net");
    (
        json_file(&json_out),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

/// `evaluate` refines the net's answers with exact IK beside the net alone.
/// On a robot whose backbone is 10 % stiffer than the net's file the net
/// alone is off by about a millimetre and the refinement, which solves the
/// given robot's statics, reaches a micron; on the net's own robot the
/// built-in net (the main job's, BENCHMARKS "The built-in net re-shipped")
/// is within a micron alone. The refinement's "net alone" is the
/// evaluation's own tip error of the net over the same rows (30, under the
/// refinement's `REFINE_ROWS`).
#[test]
fn evaluate_reports_net_alone_and_exact_refinement_side_by_side() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(workspace_root().join("robots/seed-4t.toml")).unwrap();
    let stiffer = text.replace("youngs_modulus = 207e9", "youngs_modulus = 227.7e9");
    assert_ne!(stiffer, text, "the robot file's modulus line moved");
    let real = dir.path().join("stiffer.toml");
    std::fs::write(&real, stiffer).unwrap();
    for (robot, data) in [(None, "d.csv"), (Some(&real), "stiffer.csv")] {
        let mut args = vec!["generate", "--samples", "30", "--seed", "5", "--quiet"];
        if let Some(r) = robot {
            args.extend(["--robot", r.to_str().unwrap()]);
        }
        let out = dir.path().join(data);
        args.extend(["--out", out.to_str().unwrap()]);
        assert_ok(&tendril(&args), &format!("generate {data}"));
    }
    let close = |a: &serde_json::Value, b: &serde_json::Value| {
        ["mean", "rms", "p95", "max"].iter().all(|k| {
            let (x, y) = (a[k].as_f64().unwrap(), b[k].as_f64().unwrap());
            (x - y).abs() <= 1e-12 * x.abs().max(y.abs())
        })
    };
    // The net's own robot.
    let (v, stdout) = evaluate_built_in_net(dir.path(), "d.csv", &[]);
    let r = &v["refinement"];
    assert_eq!(r["rows"], 30);
    assert_eq!((&r["unreachable"], &r["failed"]), (&0.into(), &0.into()));
    let net = r["net_tip_error_mm"]["mean"].as_f64().unwrap();
    assert!(
        close(&r["net_tip_error_mm"], &v["metrics"]["position_mm"]),
        "{r} vs {}",
        v["metrics"]["position_mm"]
    );
    assert!(
        net <= 1e-3,
        "the built-in net alone errs {net} mm on average"
    );
    assert!(stdout.contains("net + exact IK"), "{stdout}");
    // A stiffer backbone than the net's: every row a solved pose of that
    // robot, reachable, and refined to a micron from the net's guess.
    let stiffer = ["--robot", real.to_str().unwrap(), "--allow-robot-mismatch"];
    let (v, _) = evaluate_built_in_net(dir.path(), "stiffer.csv", &stiffer);
    let r = &v["refinement"];
    assert_eq!(r["rows"], 30);
    assert_eq!((&r["unreachable"], &r["failed"]), (&0.into(), &0.into()));
    let net = r["net_tip_error_mm"]["mean"].as_f64().unwrap();
    let refined = r["refined_tip_error_mm"]["max"].as_f64().unwrap();
    assert!(
        net > 0.1,
        "the net alone errs only {net} mm on a stiffer robot"
    );
    assert!(
        refined <= 1e-3,
        "refined max {refined} mm (net alone {net} mm)"
    );
}

// --- `tendril ik` with a net through the binary: the hostile probe ----------

const MODEL: &str = "firmware/vectors/default.tnet";
/// A pose from a generated dataset row (t = 0, 0, 2.19, 2.84 N).
const REACHABLE: [f64; 7] = [
    -0.0017361729555610112,
    -0.040367970340843176,
    0.3971615897926132,
    0.9944566157206342,
    0.10108433112606939,
    -0.028940347157138543,
    0.0006736146396597819,
];
/// Limit of every tendon of the seed robot, N.
const MAX_TENSION: f64 = 10.0;

fn pose_arg(p: &[f64]) -> String {
    let s: Vec<String> = p.iter().map(|x| x.to_string()).collect();
    format!("--pose={}", s.join(","))
}

/// Run `ik --json` on `pose`; (exit ok, parsed stdout if any, stderr).
fn ik(pose: &[f64], extra: &[&str]) -> (bool, Option<serde_json::Value>, String) {
    let arg = pose_arg(pose);
    let mut args = vec!["ik", "--model", MODEL, "--json", arg.as_str()];
    args.extend_from_slice(extra);
    let out = tendril(&args);
    let json = serde_json::from_slice(&out.stdout).ok();
    (
        out.status.success(),
        json,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// What the firmware's command stage commands for the net's `raw` output on
/// the seed robot (co-contraction shift, then the clip).
fn staged(raw: &[f64]) -> Vec<f64> {
    let robot = robot("seed-4t.toml");
    let limits = tendril::command_stage::limits_for(&robot, 1.0).unwrap();
    tendril::command_stage::command_for(&limits, raw)
}

/// `a` and `b` agree to 1e-9 N (serde_json's float parsing may miss the
/// last bit).
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a finite number"))
        .collect()
}

#[test]
fn a_reachable_pose_gets_tensions_within_the_limits_and_the_raw_output() {
    let (ok, json, err) = ik(&REACHABLE, &[]);
    assert!(ok, "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert_eq!((t.len(), raw.len()), (4, 4));
    assert!(t.iter().all(|a| (0.0..=MAX_TENSION).contains(a)), "{t:?}");
    assert!(same(&t, &staged(&raw)), "{t:?} vs {raw:?}");
    // The row was made by pulling tendons 2 and 3 (2.19 N, 2.84 N).
    assert!(
        (t[2] - 2.19).abs() < 0.5 && (t[3] - 2.84).abs() < 0.5,
        "{t:?}"
    );
}

#[test]
fn a_quaternion_with_negative_w_is_the_same_rotation() {
    let mut flipped = REACHABLE;
    for q in &mut flipped[3..] {
        *q = -*q;
    }
    let (ok_a, a, _) = ik(&REACHABLE, &[]);
    let (ok_b, b, err) = ik(&flipped, &[]);
    assert!(ok_a && ok_b, "{err}");
    assert_eq!(a.unwrap()["raw"], b.unwrap()["raw"]);
}

#[test]
fn non_unit_and_zero_quaternions_are_refused() {
    // The README's old example: |q| = 0.9963.
    let readme = [0.02, 0.01, 0.39, 0.99, -0.05, 0.1, 0.0];
    let zero = [0.0, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0];
    for pose in [readme, zero] {
        let (ok, json, err) = ik(&pose, &["--allow-extrapolation"]);
        assert!(!ok && json.is_none(), "accepted {pose:?}");
        assert!(
            err.contains("not 1") && err.contains("unit quaternion"),
            "{err}"
        );
    }
}

#[test]
fn a_pose_far_outside_the_training_range_is_refused_or_clamped_when_allowed() {
    let far = [0.3, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0];
    let (ok, _, err) = ik(&far, &[]);
    assert!(!ok);
    assert!(
        err.contains("px = 0.3 is outside the net's training range"),
        "{err}"
    );
    let (ok, json, err) = ik(&far, &["--allow-extrapolation"]);
    assert!(ok, "{err}");
    assert!(err.contains("extrapolates"), "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert!(t.iter().all(|x| (0.0..=MAX_TENSION).contains(x)), "{t:?}");
    // The net's own answer is impossible (hundreds of N, some negative): that is why it is clamped.
    assert!(
        raw.iter().any(|x| !(0.0..=MAX_TENSION).contains(x)),
        "{raw:?}"
    );
}

#[test]
fn outputs_beyond_the_tendon_limit_are_brought_into_range_beside_the_raw_value() {
    // Past the training range in px: the net's pair (tendon 0 and its
    // opposite 2) bends by raw₀ − raw₂ ≈ 11.3 N, more than the 10 N tendon
    // can pull. The command stage pulls tendon 0 to its limit, leaves its
    // opposite slack, and says it clipped; `raw` keeps the net's answer.
    // (That the stage lowers a co-contracted pair together, keeping its
    // bend, is `command_stage`'s unit tests': the built-in net, the main
    // job's since 2026-12-07, answers each pair as a difference and never
    // co-contracts.)
    let pose = [
        0.14,
        -0.08,
        0.34,
        0.9021620048402939,
        0.1901972676422696,
        0.3872051799119095,
        0.0009300824385327374,
    ];
    let (ok, json, err) = ik(&pose, &["--allow-extrapolation"]);
    assert!(ok, "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert!(raw[0] - raw[2] > MAX_TENSION, "{raw:?}");
    assert!(t.iter().all(|x| (0.0..=MAX_TENSION).contains(x)), "{t:?}");
    assert!(same(&t, &staged(&raw)), "{t:?} vs {raw:?}");
    assert!(t[0] == MAX_TENSION && t[2] == 0.0, "{t:?} vs {raw:?}");
    assert!(err.contains("clipped"), "{err}");
    // Plain output prints the staged tensions.
    let arg = pose_arg(&pose);
    let out = tendril(&["ik", "--model", MODEL, "--allow-extrapolation", &arg]);
    let plain: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .trim()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert_eq!(plain, t);
}

#[test]
fn a_huge_coordinate_never_gives_a_non_finite_tension() {
    let huge = [1e39, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0];
    for extra in [&[][..], &["--allow-extrapolation"][..]] {
        let (ok, json, err) = ik(&huge, extra);
        assert!(!ok, "exit 0 for px = 1e39 ({extra:?})");
        assert!(json.is_none(), "printed {json:?}");
        assert!(err.starts_with("tendril: error:"), "{err}");
    }
    let (_, _, err) = ik(&[f64::NAN, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], &[]);
    assert!(err.contains("px = NaN is not a finite number"), "{err}");
}

#[test]
fn batch_output_has_clamped_and_raw_columns_and_refuses_bad_rows() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poses.csv");
    let output = dir.path().join("t.csv");
    let row = |p: &[f64]| {
        p.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n", row(&REACHABLE)),
    )
    .unwrap();
    let (i, o) = (input.to_str().unwrap(), output.to_str().unwrap());
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", o]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("(1 row,"));
    let text = std::fs::read_to_string(&output).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t0,t1,t2,t3,raw_t0,raw_t1,raw_t2,raw_t3")
    );
    let cells: Vec<f64> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert_eq!(cells[..4], staged(&cells[4..]));
    // A zero quaternion on line 3 fails the batch and keeps the old output.
    std::fs::write(
        &input,
        format!(
            "px,py,pz,qw,qx,qy,qz\n{}\n0,0,0.4,0,0,0,0\n",
            row(&REACHABLE)
        ),
    )
    .unwrap();
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", o]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3") && err.contains("norm 0"), "{err}");
    assert_eq!(std::fs::read_to_string(&output).unwrap(), text);
    // The output may not be the input.
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", i]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("overwrite the input"));
}

#[test]
fn a_truncated_model_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(workspace_root().join(MODEL)).unwrap();
    let model = dir.path().join("cut.tnet");
    std::fs::write(&model, &bytes[..100]).unwrap();
    let arg = pose_arg(&REACHABLE);
    let out = tendril(&["ik", "--model", model.to_str().unwrap(), &arg]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("truncated").count(), 1, "{err}");
}
