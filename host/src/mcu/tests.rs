//! The link's fixed-point units against what the loop does with them: a
//! setpoint rounded to the link's units must command the tip where the
//! exact setpoint does, to a few microns (the tracking errors the loop
//! works on are tens of microns). Measured end to end: the default net's
//! tensions for a pose and for its link copy, through the statics.

use std::path::Path;

use tendril_shared::link::wire::{units, WirePose};

use crate::net::GuardedNet;
use crate::robot::repo_robot;
use crate::statics::repo_statics;

/// Largest tip shift, m, over poses the robot reaches (forward statics of
/// 40 tension vectors inside the default net's box), between the net's
/// command for each pose and for `rounded(pose)`.
fn largest_tip_shift(rounded: impl Fn([f32; 7]) -> [f32; 7]) -> f64 {
    let robot = repo_robot("seed-4t.toml");
    let statics = repo_statics("seed-4t.toml");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let net = GuardedNet::load(
        &root.join("firmware/vectors/default.tnet"),
        &robot,
        false,
        false,
    )
    .unwrap();
    let tip = |pose: &[f64; 7]| {
        let t = net.solve(pose).unwrap().tensions;
        statics.solve(&t, None).unwrap().pose()
    };
    (0..40)
        .map(|i| {
            // 0–0.6 N on each tendon, a fixed scatter.
            let tensions: Vec<f64> = (0..4)
                .map(|k| ((i * 7 + k * 13) % 17) as f64 / 16.0 * 0.6)
                .collect();
            let pose = statics.solve(&tensions, None).unwrap().pose();
            let exact = pose.map(|v| f64::from(v as f32));
            let linked = rounded(pose.map(|v| v as f32)).map(f64::from);
            let (a, b) = (tip(&exact), tip(&linked));
            (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_setpoint_through_the_link_commands_the_tip_within_five_microns() {
    let shift = largest_tip_shift(|p| WirePose::from_pose(&p).pose());
    assert!(
        shift < 5e-6,
        "link units move the tip by {:.4} mm",
        shift * 1e3
    );
}

#[test]
fn the_measure_sees_a_coarse_quaternion_unit() {
    // The quaternion in 1e-4 (protocol 3) moved the tip by ~0.1 mm: the
    // measure above would have failed on it.
    let coarse = units::QUATERNION * 100.0;
    let shift = largest_tip_shift(|mut p| {
        for q in &mut p[3..] {
            *q = units::from_i32(units::to_i32(*q, coarse), coarse);
        }
        p
    });
    assert!(shift > 20e-6, "{:.4} mm", shift * 1e3);
}
