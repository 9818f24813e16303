//! Task-space evaluation agrees with independent statics solves of the
//! (clamped) predicted tensions.

use nalgebra::DMatrix;
use tendril::evaluate::{task_space_errors, tension_rmse_normalised, ErrorStats};
use tendril::robot::Robot;
use tendril::statics::{SolverSettings, Statics};

#[test]
fn task_space_error_matches_independent_solves() {
    let robot = Robot::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../robots/seed-4t.toml"
    )))
    .unwrap();
    let statics = Statics::new(&robot, SolverSettings::default());
    let truth_t = [
        [2.0, 1.0, 0.0, 0.0],
        [0.0, 5.0, 3.0, 0.0],
        [0.0, 0.0, 7.0, 9.0],
        [4.0, 0.0, 0.0, 6.0],
    ];
    // "Predictions": perturbed, one below 0 and one above the limit (clamped to 0 and 10).
    let pred_t = [
        [2.1, 0.95, -0.2, 0.0],
        [0.0, 5.0, 3.05, 0.0],
        [0.0, 0.0, 7.0, 11.0],
        [3.9, 0.0, 0.0, 6.1],
    ];
    let mut poses = DMatrix::zeros(4, 7);
    for (r, t) in truth_t.iter().enumerate() {
        let s = statics.solve(t, None).unwrap();
        for (c, v) in s.pose().iter().enumerate() {
            poses[(r, c)] = *v;
        }
    }
    let pred = DMatrix::from_fn(4, 4, |r, c| pred_t[r][c]);
    let errs = task_space_errors(&statics, &pred, &poses).unwrap();
    assert_eq!(errs.failed, 0);
    for r in 0..4 {
        let clamped: Vec<f64> = pred_t[r].iter().map(|v| v.clamp(0.0, 10.0)).collect();
        let s = statics.solve(&clamped, None).unwrap();
        let p = nalgebra::Vector3::new(poses[(r, 0)], poses[(r, 1)], poses[(r, 2)]);
        let expect_mm = 1000.0 * (s.position - p).norm();
        assert!(
            (errs.position_mm[r] - expect_mm).abs() < 1e-9,
            "row {r}: {} vs {expect_mm}",
            errs.position_mm[r]
        );
        let dot: f64 = (0..4).map(|i| s.quaternion[i] * poses[(r, 3 + i)]).sum();
        let expect_deg = (2.0 * dot.abs().min(1.0).acos()).to_degrees();
        assert!((errs.orientation_deg[r] - expect_deg).abs() < 1e-6);
    }
    // Row 2 asks for 11 N on tendon 3: clamped to 10 N, so the tip misses by a visible amount.
    assert!(errs.position_mm[2] > 1.0);
    let s = errs.position_stats();
    assert_eq!(s, ErrorStats::of(&errs.position_mm));
    let nr = tension_rmse_normalised(
        &pred,
        &DMatrix::from_fn(4, 4, |r, c| truth_t[r][c]),
        &[0.0; 4],
        &[10.0; 4],
    )
    .unwrap();
    assert!(nr > 0.0);
}
