//! Task-space evaluation agrees with independent statics solves of the
//! commanded tensions: through the command stage (`task_space_errors`) and
//! through the plain clip (`task_space_errors_plain_clip`).

use nalgebra::DMatrix;
use tendril::evaluate::{
    task_space_errors, task_space_errors_plain_clip, tension_rmse_normalised, ErrorStats,
};

/// The command stage of docs/design.md §5.2 written out for the seed robot's
/// opposite pairs (0, 2) and (1, 3), range [0, 10] N, in f64: shift each
/// pair by the smallest α that fits it (the middle one when it cannot fit),
/// then clip.
fn staged(t: &[f64; 4]) -> Vec<f64> {
    let mut out = t.to_vec();
    for (i, j) in [(0, 2), (1, 3)] {
        let lo = (0.0 - t[i]).max(0.0 - t[j]);
        let hi = (10.0 - t[i]).min(10.0 - t[j]);
        let alpha = if lo <= 0.0 && 0.0 <= hi {
            0.0
        } else if lo <= hi {
            if hi < 0.0 {
                hi
            } else {
                lo
            }
        } else {
            0.5 * (lo + hi)
        };
        out[i] += alpha;
        out[j] += alpha;
    }
    out.iter().map(|v| v.clamp(0.0, 10.0)).collect()
}
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

#[test]
fn task_space_error_matches_independent_solves() {
    let robot = repo_robot("seed-4t.toml");
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
    let clip = task_space_errors_plain_clip(&statics, &pred, &poses).unwrap();
    assert_eq!(errs.failed + clip.failed, 0);
    for r in 0..4 {
        let p = nalgebra::Vector3::new(poses[(r, 0)], poses[(r, 1)], poses[(r, 2)]);
        let clamped: Vec<f64> = pred_t[r].iter().map(|v| v.clamp(0.0, 10.0)).collect();
        // The stage runs in f32 as on the MCU: tensions agree to ~1e-6 N.
        for (commanded, got, tol_mm) in [(staged(&pred_t[r]), &errs, 1e-5), (clamped, &clip, 1e-9)]
        {
            let s = statics.solve(&commanded, None).unwrap();
            let expect_mm = 1000.0 * (s.position - p).norm();
            assert!(
                (got.position_mm[r] - expect_mm).abs() < tol_mm,
                "row {r}: {} vs {expect_mm} for {commanded:?}",
                got.position_mm[r]
            );
            let dot: f64 = (0..4).map(|i| s.quaternion[i] * poses[(r, 3 + i)]).sum();
            let expect_deg = (2.0 * dot.abs().min(1.0).acos()).to_degrees();
            assert!((got.orientation_deg[r] - expect_deg).abs() < 1e-5);
        }
    }
    // Row 2 asks for 11 N on tendon 3 with 0 N on its antagonist: a pair
    // wider than its range, so the tip misses by a visible amount either way.
    assert!(errs.position_mm[2] > 1.0 && clip.position_mm[2] > 1.0);
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
