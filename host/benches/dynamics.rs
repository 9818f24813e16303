//! Dynamic plant step: one BDF-α time step of the Cosserat rod with inertia
//! and damping at δt = 1 ms (a shooting solve warm-started from the last
//! step), the tensions moving along the tension path of a 30 mm circle at
//! 0.2 Hz. Target (docs/design.md §4.2, issue 16): median ≤ 500 µs on one
//! core, so the dynamic plant keeps up with the 1 kHz loop.
//!
//! `cargo bench -p tendril --bench dynamics`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use tendril::dynamics::{Damping, Dynamics, DynamicsSettings};
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

#[path = "workloads/circle.rs"]
mod workloads;

fn dynamics_step(c: &mut Criterion) {
    let robot = repo_robot("seed-4t.toml");
    let statics = Statics::new(&robot, SolverSettings::default());
    let path = workloads::circle_tensions(&statics, 5000);
    let mut group = c.benchmark_group("dynamics");
    for steps in [16usize, 24] {
        let settings = DynamicsSettings {
            steps,
            ..DynamicsSettings::default()
        };
        let mut dynamics = Dynamics::at_rest(
            &robot,
            Damping::of_robot(&robot),
            settings,
            &path[0],
            Vector3::zeros(),
            Vector3::zeros(),
        )
        .unwrap();
        let mut k = 0;
        group.bench_function(format!("step_1ms_rk4_{steps}"), |b| {
            b.iter(|| {
                k += 1;
                dynamics.step(&path[k % path.len()]).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, dynamics_step);
criterion_main!(benches);
