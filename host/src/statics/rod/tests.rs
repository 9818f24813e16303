//! Checks of the strain-rate system and the cold guess's arc against closed
//! forms (kept apart so that `rod.rs` reads as the equations).

use super::*;

fn seed() -> Robot {
    crate::robot::repo_robot("seed-4t.toml")
}

#[test]
fn constant_curvature_arc_has_zero_strain_rates_without_gravity() {
    // A straight tendon on a constant-curvature arc: n, m constant in the
    // body frame, so v' = u' = 0 must solve the system exactly.
    let robot = seed().without_gravity();
    let mut rod = Rod::new(&robot);
    let tau = 3.0;
    rod.set_tensions(&[tau, 0.0, 0.0, 0.0]);
    let ei = robot.kbt().x;
    let ea = robot.kse().z;
    let d = robot.tendons[0].offset;
    let state = RodState {
        p: Vector3::zeros(),
        rot: Matrix3::identity(),
        w: Vector3::new(0.0, 0.0, -tau / ea),
        u: Vector3::new(0.0, tau * d / ei, 0.0),
    };
    let (dv, du) = rod.strain_rates(0.1, &state, rod.running_to(0.4)).unwrap();
    assert!(dv.norm() < 1e-9, "v' = {dv}");
    assert!(du.norm() < 1e-9, "u' = {du}");
}

#[test]
fn straight_rod_under_gravity_bends_at_the_rate_of_its_weight() {
    // No tendons, straight rod: u' = Kbt⁻¹(−v̂ n) with n = 0 at first order,
    // but n' = −f_e gives the classic m' = −e3 × n: check the force part,
    // v'_x = −f_e,x / GA when n = 0.
    let robot = seed();
    let rod = Rod::new(&robot);
    let state = RodState {
        p: Vector3::zeros(),
        rot: Matrix3::identity(),
        w: Vector3::zeros(),
        u: Vector3::zeros(),
    };
    let (dv, du) = rod.strain_rates(0.0, &state, rod.running_to(0.4)).unwrap();
    let expected = -robot.weight_per_length().x / robot.kse().x;
    assert!((dv.x - expected).abs() < 1e-15);
    assert!(du.norm() < 1e-15);
}

/// The cold guess's arc moments against the arc itself: R(s) = exp(s û)
/// for constant u, p' = R e3, integrated by the trapezoidal rule on a
/// fine grid — for a bent arc (closed form) and a nearly straight one
/// (the series branch).
#[test]
fn arc_moments_match_the_integrated_arc() {
    for u in [Vector3::new(0.3, -1.2, 0.0), Vector3::new(1e-4, 2e-4, 0.0)] {
        let l = 0.4;
        let n = 20_000;
        let h = l / n as f64;
        let tangent = |s: f64| nalgebra::Rotation3::from_scaled_axis(u * s) * Vector3::z();
        let (mut p, mut first_moment) = (Vector3::zeros(), Vector3::zeros());
        for k in 0..n {
            let s = k as f64 * h;
            let next = p + (tangent(s) + tangent(s + h)) * (0.5 * h);
            first_moment += (p + next) * (0.5 * h);
            p = next;
        }
        let (mean, tip) = arc_moments(&u, l);
        assert!((tip - p).norm() < 1e-9, "{u}: tip {tip} vs {p}");
        assert!(
            (mean - first_moment).norm() < 1e-9,
            "{u}: first moment {mean} vs {first_moment}"
        );
    }
}

#[test]
fn singular_system_is_an_error_not_a_zero_rate() {
    // No shear/extension stiffness and no tendons: the 6×6 matrix has a
    // zero 3×3 block, which neither Cholesky nor LU can solve.
    let mut rod = Rod::new(&seed());
    rod.kse = Vector3::zeros();
    let state = RodState {
        p: Vector3::zeros(),
        rot: Matrix3::identity(),
        w: Vector3::zeros(),
        u: Vector3::new(0.0, 1.0, 0.0),
    };
    let running = rod.running_to(0.4);
    assert_eq!(
        rod.strain_rates(0.25, &state, running),
        Err(SingularSystem { s: 0.25 })
    );
    // A non-finite state is reported the same way, not passed on as NaN rates.
    let rod = Rod::new(&seed());
    let nan = RodState {
        u: Vector3::new(f64::NAN, 0.0, 0.0),
        ..state
    };
    assert!(rod.strain_rates(0.1, &nan, running).is_err());
}
