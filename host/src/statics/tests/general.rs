//! Checks of general robots (`docs/design.md` §2.1) against independent facts:
//! tendons anchored mid-length (closed form, the public tdcr-modeling
//! benchmark), the §2.1 combined-wrench formulation along the whole rod,
//! RK4's order with knots, tip wrenches against linear beam theory.

use std::path::Path;

use nalgebra::Vector3;

use crate::robot::{repo_robot as load, Robot};
use crate::statics::integrate::integrate_observed;
use crate::statics::rod::{Rod, RodState};
use crate::statics::*;

fn with_steps(steps: usize) -> SolverSettings {
    SolverSettings {
        steps,
        ..SolverSettings::default()
    }
}

#[test]
fn tendon_anchored_mid_length_bends_an_arc_then_leaves_the_rod_straight() {
    // docs/design.md §2.1 fact: arc of κ = τ d/(E I), v_z = 1 − τ/(E A) on
    // [0, s₁], then straight and unloaded: p(L) = p(s₁) + (sin κs₁, 0, cos κs₁)(L − s₁).
    let base = load("seed-1t.toml").without_gravity();
    for &s1 in &[0.05, 0.13, 0.2, 0.31, 0.39] {
        let mut robot = base.clone();
        robot.tendons[0].end = s1;
        let statics = Statics::new(&robot, with_steps(256));
        for &tau in &[0.5, 3.0, 9.5] {
            let kappa = tau * robot.tendons[0].offset / robot.kbt().x;
            let vz = 1.0 - tau / robot.kse().z;
            let theta = kappa * s1;
            let rest = robot.length - s1;
            let expected = Vector3::new(
                vz * (1.0 - theta.cos()) / kappa + theta.sin() * rest,
                0.0,
                vz * theta.sin() / kappa + theta.cos() * rest,
            );
            let sol = statics.solve(&[tau], None).unwrap();
            let err = (sol.position - expected).norm();
            assert!(
                err < 1e-9,
                "s1 = {s1}, {tau} N: tip {} vs {expected} ({err:e} m)",
                sol.position
            );
            // The tip is rotated by θ about +y only.
            let q = sol.quaternion;
            assert!(
                (q[0] - (theta / 2.0).cos()).abs() < 1e-9
                    && (q[2] - (theta / 2.0).sin()).abs() < 1e-9,
                "s1 = {s1}, {tau} N: q = {q:?}"
            );
        }
    }
}

/// The three tip positions the public tdcr-modeling benchmark's Cosserat
/// model gives for its two-segment robot (`docs/design.md` §2.1, 6 digits).
const TDCR_CASES: [([f64; 6], [f64; 3]); 3] = [
    (
        [4.0, 0.0, 0.0, 0.0, 2.0, 0.0],
        [0.127608, 0.143467, 0.336407],
    ),
    (
        [2.0, 0.0, 0.0, 0.0, 2.0, 0.0],
        [0.130492, 0.0365621, 0.367513],
    ),
    (
        [0.0, 2.0, 0.0, 1.0, 0.0, 1.0],
        [0.033908, -0.0195768, 0.397419],
    ),
];

#[test]
fn two_segment_robot_matches_the_tdcr_modeling_benchmark() {
    let robot = load("tdcr-2seg.toml");
    for steps in [SolverSettings::default().steps, 128] {
        let statics = Statics::new(&robot, with_steps(steps));
        for (tau, tip) in TDCR_CASES {
            let p = statics.solve(&tau, None).unwrap().position;
            let err = (p - Vector3::from(tip)).norm();
            // The reference keeps 6 significant digits: ≤ 1e-6 m.
            assert!(
                err <= 1e-6,
                "{steps} steps, {tau:?}: tip {p} vs {tip:?} ({err:e} m)"
            );
        }
    }
}

#[test]
fn two_segment_robot_file_says_what_the_benchmark_says() {
    let robot = load("tdcr-2seg.toml");
    assert_eq!(robot.n_tendons(), 6);
    assert!(robot.gravity.norm() == 0.0);
    // Effective linear density of NiTi backbone plus disks, ≈ 0.0215 kg/m.
    assert!((robot.density * robot.area() - 0.0215).abs() < 1e-6);
    let ends: Vec<f64> = robot.tendons.iter().map(|t| t.end).collect();
    assert_eq!(ends, [0.2, 0.2, 0.2, 0.4, 0.4, 0.4]);
    assert!((robot.youngs_modulus / robot.shear_modulus - 2.6).abs() < 1e-12);
}

#[test]
fn seed_paper_robot_keeps_every_tendon_between_5_and_15_newtons() {
    let robot = load("seed-paper.toml");
    assert_eq!(robot.min_tensions(), vec![5.0; 4]);
    assert_eq!(robot.max_tensions(), vec![15.0; 4]);
    // Otherwise the default robot: same backbone, same tendons.
    let seed = load("seed-4t.toml");
    assert_eq!(robot.length, seed.length);
    assert_eq!(robot.kbt(), seed.kbt());
    assert_eq!(robot.weight_per_length(), seed.weight_per_length());
}

/// The §2.1 combined wrench of backbone and the tendons passing a section,
/// in the base frame: N = R (n + Σ τᵢ tᵢ), M = R (m + Σ rᵢ × τᵢ tᵢ).
fn combined_wrench(
    robot: &Robot,
    tau: &[f64],
    s: f64,
    y: &RodState,
) -> (Vector3<f64>, Vector3<f64>) {
    let n = robot.kse().component_mul(&y.w);
    let m = robot.kbt().component_mul(&y.u);
    let (mut force, mut moment) = (n, m);
    for (t, &tau_i) in robot.tendons.iter().zip(tau) {
        // Nodes land on a knot up to roundoff; a tendon anchored there still passes.
        if t.end < s - 1e-12 {
            continue;
        }
        let o = t.offset_at(s, robot.length);
        let q = y.u.cross(&o.r) + o.dr + y.v();
        let pull = q.normalize() * tau_i;
        force += pull;
        moment += o.r.cross(&pull);
    }
    (y.rot * force, y.rot * moment)
}

/// Along the whole converged rod, anchors included: N(s) = F_tip + ρ A g (L − s)
/// and, without gravity, M(s) = L_tip + (p(L) − p(s)) × F_tip — the balance
/// of everything beyond the section, which the solver never imposes there.
fn assert_section_balance(robot: &Robot, tau: &[f64], f_tip: Vector3<f64>, l_tip: Vector3<f64>) {
    let statics = Statics::new(robot, with_steps(128));
    let sol = statics.solve_loaded(tau, f_tip, l_tip, None).unwrap();
    let mut rod = Rod::new(robot);
    rod.set_tensions(tau);
    let x = sol.warm.x;
    let base = RodState::at_base(
        &Vector3::new(x[0], x[1], x[2]),
        &Vector3::new(x[3], x[4], x[5]),
        &robot.kse(),
    );
    let mut nodes = Vec::new();
    let tip = integrate_observed(&rod, base, 128, |s, y| nodes.push((s, *y))).unwrap();
    assert!((tip.p - sol.position).norm() < 1e-12);
    let f_e = robot.weight_per_length();
    let mut checked_past_anchor = false;
    for (s, y) in &nodes {
        let (big_n, big_m) = combined_wrench(robot, tau, *s, y);
        let expected_n = f_tip + f_e * (robot.length - s);
        assert!(
            (big_n - expected_n).norm() < 1e-8,
            "s = {s}: N = {big_n}, expected {expected_n}"
        );
        if f_e.norm() == 0.0 {
            let expected_m = l_tip + (tip.p - y.p).cross(&f_tip);
            assert!(
                (big_m - expected_m).norm() < 1e-8,
                "s = {s}: M = {big_m}, expected {expected_m}"
            );
        }
        checked_past_anchor |= robot.tendons.iter().any(|t| t.end < *s && tau[0] > 0.0);
    }
    assert!(checked_past_anchor, "no node beyond an anchor was checked");
}

#[test]
fn combined_wrench_balances_along_a_rod_with_mid_length_anchors_and_a_tip_wrench() {
    let tdcr = load("tdcr-2seg.toml");
    assert_section_balance(
        &tdcr,
        &[3.0, 0.0, 1.0, 0.5, 2.0, 0.0],
        Vector3::new(0.05, -0.1, 0.02),
        Vector3::new(0.004, 0.0, -0.002),
    );
    // With gravity and anchors at three different places.
    let mut seed = load("seed-4t.toml");
    seed.tendons[0].end = 0.15;
    seed.tendons[1].end = 0.3;
    seed.tendons[3].end = 0.3;
    assert_section_balance(
        &seed,
        &[6.0, 4.0, 0.0, 1.0],
        Vector3::new(0.0, 0.2, -0.1),
        Vector3::new(0.01, 0.0, 0.0),
    );
}

#[test]
fn base_wrench_balances_weight_tendon_pulls_and_tip_wrench_with_anchors() {
    // The global balance at the base (tests.rs): the anchors are internal to
    // the rod-plus-tendons body, so it holds unchanged wherever they are.
    let mut seed = load("seed-4t.toml");
    seed.tendons[0].end = 0.1;
    seed.tendons[1].end = 0.25;
    super::assert_global_equilibrium(
        &seed,
        &[7.0, 5.0, 0.0, 2.0],
        Vector3::new(0.1, -0.2, 0.05),
        Vector3::new(0.0, 0.01, 0.0),
    );
}

#[test]
fn rk4_converges_at_fourth_order_with_knots() {
    let robot = load("tdcr-2seg.toml");
    let tau = [3.0, 0.0, 1.0, 0.0, 2.0, 0.5];
    let reference = Statics::new(&robot, with_steps(1024))
        .solve(&tau, None)
        .unwrap()
        .position;
    let err = |steps| {
        (Statics::new(&robot, with_steps(steps))
            .solve(&tau, None)
            .unwrap()
            .position
            - reference)
            .norm()
    };
    let (e8, e16, e32) = (err(8), err(16), err(32));
    for (coarse, finer) in [(e8, e16), (e16, e32)] {
        let ratio = coarse / finer;
        assert!(
            (12.0..20.0).contains(&ratio),
            "halving the step cut the error by {ratio} ({coarse:e} → {finer:e})"
        );
    }
}

#[test]
fn small_tip_moment_matches_cantilever_theory() {
    // A pure tip moment bends a weightless cantilever into an arc; at small
    // load the tip deflects δ = M L² / (2 E I).
    let robot = load("seed-4t.toml").without_gravity();
    let m = 1e-4;
    let sol = Statics::new(&robot, with_steps(128))
        .solve_loaded(&[0.0; 4], Vector3::zeros(), Vector3::new(0.0, m, 0.0), None)
        .unwrap();
    let beam = m * robot.length.powi(2) / (2.0 * robot.kbt().x);
    // A moment about +y turns the tip toward +x.
    let rel = (sol.position.x - beam).abs() / beam;
    assert!(
        rel < 1e-3,
        "deflection {} vs {beam} (rel {rel:e})",
        sol.position.x
    );
}

#[test]
fn explicit_default_anchor_and_floor_change_nothing() {
    // `end = L` and `min_tension = 0` written out are the defaults: same bits.
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml"),
    )
    .unwrap();
    let explicit = text.replace(
        "max_tension = 10.0\n",
        "max_tension = 10.0\nmin_tension = 0.0\nend = 0.4\n",
    );
    let a = Statics::new(&load("seed-4t.toml"), SolverSettings::default());
    let b = Statics::new(
        &Robot::from_toml(&explicit, Path::new("explicit.toml")).unwrap(),
        SolverSettings::default(),
    );
    for tau in [[3.0, 1.0, 0.0, 0.0], [0.0, 0.0, 9.0, 2.0]] {
        let (pa, pb) = (a.solve(&tau, None).unwrap(), b.solve(&tau, None).unwrap());
        assert_eq!(pa.pose().map(f64::to_bits), pb.pose().map(f64::to_bits));
    }
}

#[test]
fn multi_segment_shape_is_continuous_and_ends_at_the_tip() {
    let robot = load("tdcr-2seg.toml");
    let statics = Statics::new(&robot, SolverSettings::default());
    let sol = statics
        .solve(&[4.0, 0.0, 0.0, 0.0, 2.0, 0.0], None)
        .unwrap();
    let shape = statics.shape(&sol, 8);
    assert_eq!(shape.len(), 8);
    assert!((shape[7] - sol.position).norm() < 1e-7);
    // Inextensible to 1e-4: the chords of evenly spaced points are ≈ L/7 each.
    for w in shape.windows(2) {
        let chord = (w[1] - w[0]).norm();
        assert!(
            chord < 0.4 / 7.0 + 1e-6 && chord > 0.4 / 7.0 * 0.98,
            "chord {chord}"
        );
    }
}

#[test]
fn singular_robot_is_a_typed_error() {
    // Zero stiffness cannot come from a robot file (validation), only from code.
    let mut robot = load("seed-4t.toml");
    robot.shear_modulus = 0.0;
    let err = Statics::new(&robot, SolverSettings::default())
        .solve(&[0.0; 4], None)
        .unwrap_err();
    assert!(matches!(err, SolveError::Singular(_)), "{err:?}");
}
