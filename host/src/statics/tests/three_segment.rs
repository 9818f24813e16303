//! The three-segment, nine-tendon robot (`robots/tdcr-3seg.toml`, issue 30):
//! the file says what its header says, and its statics meet closed forms that
//! involve each anchor group (docs/design.md §2.1): a tendon of the first
//! segment bends an arc and leaves the two others straight; a group pulled
//! evenly only shortens the rod up to its anchor.

use nalgebra::Vector3;

use crate::robot::repo_robot;
use crate::statics::{SolverSettings, Statics};

fn statics(steps: usize) -> Statics {
    Statics::new(
        &repo_robot("tdcr-3seg.toml"),
        SolverSettings {
            steps,
            ..SolverSettings::default()
        },
    )
}

#[test]
fn the_file_is_three_benchmark_segments_with_nine_staggered_tendons() {
    let robot = repo_robot("tdcr-3seg.toml");
    assert_eq!(robot.n_tendons(), 9);
    assert!((robot.length - 0.6).abs() < 1e-12);
    assert!(robot.gravity.norm() == 0.0);
    // The benchmark's backbone with its disks: ≈ 0.0215 kg/m, E/G = 2.6.
    assert!((robot.density * robot.area() - 0.0215).abs() < 1e-6);
    assert!((robot.youngs_modulus / robot.shear_modulus - 2.6).abs() < 1e-12);
    let ends: Vec<f64> = robot.tendons.iter().map(|t| t.end).collect();
    assert_eq!(ends, [0.2, 0.2, 0.2, 0.4, 0.4, 0.4, 0.6, 0.6, 0.6]);
    // Nine distinct holes, 40° apart.
    let mut angles: Vec<f64> = robot
        .tendons
        .iter()
        .map(|t| t.angle.to_degrees().rem_euclid(360.0))
        .collect();
    angles.sort_by(f64::total_cmp);
    for pair in angles.windows(2) {
        assert!((pair[1] - pair[0] - 40.0).abs() < 1e-9, "{angles:?}");
    }
    assert!(robot.tendons.iter().all(|t| t.offset == 0.010));
}

#[test]
fn a_first_segment_tendon_bends_an_arc_and_leaves_the_rest_straight() {
    // Tendon 0 (90°, anchored at s₁ = 0.2 m): an arc of κ = τ d/(E I) in the
    // y–z plane with the axial strain v_z = 1 − τ/(E A) on [0, s₁], then the
    // unloaded rod straight along the arc's end tangent.
    let robot = repo_robot("tdcr-3seg.toml");
    let s1 = robot.tendons[0].end;
    for &tau in &[0.2, 0.6, 1.0] {
        let kappa = tau * robot.tendons[0].offset / (robot.youngs_modulus * robot.second_moment());
        let vz = 1.0 - tau / (robot.youngs_modulus * robot.area());
        let theta = kappa * s1;
        let rest = robot.length - s1;
        let expected = Vector3::new(
            0.0,
            vz * (1.0 - theta.cos()) / kappa + theta.sin() * rest,
            vz * theta.sin() / kappa + theta.cos() * rest,
        );
        let mut t = [0.0; 9];
        t[0] = tau;
        let p = statics(256).solve(&t, None).unwrap().position;
        let err = (p - expected).norm();
        assert!(err < 1e-8, "{tau} N: tip {p} vs {expected} ({err:e} m)");
    }
}

#[test]
fn a_group_pulled_evenly_only_shortens_the_rod_up_to_its_anchor() {
    // Three tendons 120° apart at equal tension: their moments cancel, so
    // the rod stays straight and shortens by τ_total s_j/(E A) up to the
    // group's anchor s_j.
    let robot = repo_robot("tdcr-3seg.toml");
    let ea = robot.youngs_modulus * robot.area();
    let solver = statics(64);
    for group in 0..3 {
        let tau = 0.8;
        let mut t = [0.0; 9];
        for i in 0..3 {
            t[3 * group + i] = tau;
        }
        let anchor = robot.tendons[3 * group].end;
        let p = solver.solve(&t, None).unwrap().position;
        let z = robot.length - 3.0 * tau * anchor / ea;
        assert!(
            p.x.abs() < 1e-10 && p.y.abs() < 1e-10 && (p.z - z).abs() < 1e-10,
            "group {group}: tip {p} vs (0, 0, {z})"
        );
    }
}
