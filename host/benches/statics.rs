//! Statics solve times on the default robot (issue: Cosserat-rod statics).
//!
//! cold: no caller-supplied guess (the solver seeds itself from its analytic
//! straight-rod estimate and builds a finite-difference Jacobian);
//! warm: the previous solution's warm start, one tension changed by +0.1 N.
//! Run: `cargo bench -p tendril --bench statics`.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use tendril::robot::Robot;
use tendril::statics::{SolverSettings, Statics};

fn robot() -> Robot {
    Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml")).unwrap()
}

fn solves(c: &mut Criterion) {
    let robot = robot();
    let statics = Statics::new(&robot, SolverSettings::default());
    let cases: [(&str, [f64; 4]); 2] = [
        ("mid", [4.0, 3.0, 0.0, 0.0]),
        ("max", [10.0, 10.0, 0.0, 0.0]),
    ];
    for (name, tau) in cases {
        c.bench_function(&format!("statics/cold/{name}"), |b| {
            b.iter(|| statics.solve(black_box(&tau), None).unwrap())
        });
        let prev = statics.solve(&tau, None).unwrap();
        // One tension moved by 0.1 N (down at the limit, where up is not allowed).
        let mut next = tau;
        next[0] += if tau[0] + 0.1 <= 10.0 { 0.1 } else { -0.1 };
        c.bench_function(&format!("statics/warm/{name}"), |b| {
            b.iter(|| statics.solve(black_box(&next), Some(&prev.warm)).unwrap())
        });
    }
    // One RK4 pass alone: the unit of cost of everything above.
    let sol = statics.solve(&[4.0, 3.0, 0.0, 0.0], None).unwrap();
    c.bench_function("statics/one_integration_16_steps", |b| {
        b.iter(|| statics.tip_state(black_box(&[4.0, 3.0, 0.0, 0.0]), &sol.warm.x, 16))
    });
}

criterion_group!(benches, solves);
criterion_main!(benches);
