//! Plant step time: motor update + warm-started Cosserat statics, with the
//! commanded tensions moving along the tension path of a 30 mm circle at
//! 0.2 Hz sampled at 1 kHz (the load the plant sees in `tendril sim`).
//! The plant must step well inside one 1 kHz period (docs/design.md §6):
//! median ≤ 200 µs leaves the controller its share of the shared CPU.
//!
//! `cargo bench -p tendril --bench plant`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector2;
use tendril::ipc::plant::{PlantModel, PlantParams};
use tendril::plan::bend_tensions;
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

fn plant_step(c: &mut Criterion) {
    let robot = repo_robot("seed-4t.toml");
    let statics = Statics::new(&robot, SolverSettings::default());
    // Tension path: a bend vector turning like the circle's (≈ 3 N around −x).
    let path: Vec<Vec<f64>> = (0..5000)
        .map(|k| {
            let a = std::f64::consts::TAU * 0.2 * k as f64 * 1e-3;
            bend_tensions(&statics, &Vector2::new(-3.0 + 1.5 * a.cos(), 1.5 * a.sin()))
        })
        .collect();
    let mut group = c.benchmark_group("plant");
    // The default (one-pass warm solves, issue 48 item 3) beside every
    // solve verified to the statics' default tolerance, as before.
    let verified = PlantParams {
        statics_tol: SolverSettings::default().tol,
        statics_final_step_m: 0.0,
        ..PlantParams::default()
    };
    for (name, steps, base) in [
        ("", 16usize, PlantParams::default()),
        ("", 24, PlantParams::default()),
        ("_verified", 16, verified),
    ] {
        let params = PlantParams {
            statics_steps: steps,
            ..base
        };
        let mut plant = PlantModel::new(&robot, params).unwrap();
        let mut k = 0;
        group.bench_function(format!("step_1ms_rk4_{steps}{name}"), |b| {
            b.iter(|| {
                plant.command(&path[k % path.len()]);
                k += 1;
                plant.step(1e-3)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, plant_step);
criterion_main!(benches);
