//! Exact IK time per target (`docs/design.md` §4.1; BENCHMARKS.md "Exact IK"),
//! default robot, one thread, position targets.
//!
//! warm: the previous point of a path as start (its tensions and statics warm
//! start), the next target the tip of tensions 0.05 N away; cold: from every tendon at
//! its floor; net: from the `.tnet` net's guess (firmware/vectors/default.tnet,
//! trained on the default robot), the net's own time included; pose: a full
//! pose target, cold; lift_path: the planner's lift (lateral target, least
//! total tension, tangent), one point after another along the default 30 mm
//! circle (500 points, 0.19 mm apart), each from the previous one.
//! Run: `cargo bench -p tendril --bench inverse`.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use tendril::inverse::{ExactIk, IkSettings, Target};
use tendril::net::GuardedNet;
use tendril::plan::Lifter;
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn targets(c: &mut Criterion) {
    let robot = repo_robot("seed-4t.toml");
    let statics = Statics::new(&robot, SolverSettings::default());
    let ik = ExactIk::new(&robot, IkSettings::default());
    let truth = [4.0, 3.0, 0.0, 0.0];
    let pose = statics.solve(&truth, None).unwrap().pose();
    let target = Target::from_pose(&pose, true).unwrap();

    c.bench_function("inverse/cold", |b| {
        b.iter(|| ik.solve(black_box(&target), None, None).unwrap())
    });

    // The next path point: the tip of a nearby tension set (≈ 0.7 mm away),
    // so it is reachable by construction. (A point 1 mm along the circle
    // about the axis at the same height is not: gravity along x makes the
    // reachable surface non-axisymmetric, 4 µm off.)
    let previous = ik.solve(&target, None, None).unwrap();
    let next_pose = statics.solve(&[4.05, 3.0, 0.0, 0.0], None).unwrap().pose();
    let next = Target::from_pose(&next_pose, true).unwrap();
    c.bench_function("inverse/warm", |b| {
        b.iter(|| {
            ik.solve(
                black_box(&next),
                Some(&previous.tensions),
                Some(&previous.warm),
            )
            .unwrap()
        })
    });

    let net = GuardedNet::load(
        &root().join("firmware/vectors/default.tnet"),
        &robot,
        true,
        false,
    )
    .unwrap();
    c.bench_function("inverse/net", |b| {
        b.iter(|| {
            let guess = net.solve(black_box(&pose)).unwrap();
            ik.solve(&target, Some(&guess.tensions), None).unwrap()
        })
    });

    let circle: Vec<[f64; 2]> = (0..500)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / 500.0;
            [0.015 * a.cos(), 0.015 * a.sin()]
        })
        .collect();
    let mut lifter = Lifter::new(&statics).unwrap();
    let mut next_point = circle.iter().cycle();
    c.bench_function("inverse/lift_path", |b| {
        b.iter(|| {
            let xy = *next_point.next().expect("cycles");
            lifter.lifted(black_box(xy)).unwrap()
        })
    });

    let full = Target::from_pose(&pose, false).unwrap();
    c.bench_function("inverse/pose_cold", |b| {
        b.iter(|| ik.solve(black_box(&full), None, None).unwrap())
    });
}

criterion_group!(benches, targets);
criterion_main!(benches);
