//! Statics solve times (`docs/design.md` §2, §2.1; BENCHMARKS.md "Statics").
//!
//! cold: no caller-supplied guess (the solver seeds itself from its analytic
//! straight-rod estimate); warm: the previous solution's warm start, one
//! tension changed by 0.1 N; multi: the two-segment tdcr-2seg robot and the
//! same robot with every tendon anchored at the tip (equal steps per metre);
//! batch: 600 uniformly random rows through `tendril fk --input`'s library
//! call on one thread, per row; till-4t: the robot of the public C++
//! reference at 20 steps (bench/cpp-reference/run times both in one run).
//! mid and till-4t also time warm solves from a state carrying dx/dτ
//! (`warm_predicted`, as the dataset chains and the plant solve), and both
//! kinds at the tolerance whose tips are as accurate as the C++ reference's
//! (`warm_equal_accuracy`, `warm_equal_accuracy_no_predict`; BENCHMARKS.md,
//! "Warm statics at the C++ reference's accuracy"), and at that tolerance
//! allowed to end on an unverified chord step of at most 1 µm
//! (`warm_one_pass`, `SolverSettings::final_step_m`).
//! Run: `cargo bench -p tendril --bench statics`.

use std::hint::black_box;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use tendril::dataset::Sampler;
use tendril::robot::{repo_robot as robot, Robot};
use tendril::statics::batch::{solve_all, Load};
use tendril::statics::{SolverSettings, Statics};

fn cold_and_warm(c: &mut Criterion, group: &str, statics: &Statics, tau: &[f64]) {
    c.bench_function(&format!("statics/{group}/cold"), |b| {
        b.iter(|| statics.solve(black_box(tau), None).unwrap())
    });
    let prev = statics.solve(tau, None).unwrap();
    let mut next = tau.to_vec();
    let max = statics.robot().tendons[0].max_tension;
    next[0] += if tau[0] + 0.1 <= max { 0.1 } else { -0.1 };
    c.bench_function(&format!("statics/{group}/warm"), |b| {
        b.iter(|| statics.solve(black_box(&next), Some(&prev.warm)).unwrap())
    });
}

/// The loosest residual tolerance (N, N·m) at which every warm-solved tip of
/// the till-4t chain (`statics_cost tips`) is within the C++ reference's tip
/// error of the converged answer at the same tensions (BENCHMARKS.md,
/// "Warm statics at the C++ reference's accuracy").
const EQUAL_ACCURACY_TOL: f64 = 1e-7;

/// The final-step bound of `warm_one_pass` (m): its tips stay within 3.1e-8 m
/// of the converged answer on the default robot's chain and 7.3e-9 m on
/// till-4t's, inside the C++ reference's smallest error, 4.7e-8 m.
const ONE_PASS_FINAL_STEP_M: f64 = 1e-6;

/// Warm solves 0.1 N from `tau`: from a state carrying dx/dτ
/// (`Statics::add_tension_sensitivity`, as a chain or the plant has it) at
/// the default tolerance, and at [`EQUAL_ACCURACY_TOL`] with and without it.
fn predicted_warm(c: &mut Criterion, group: &str, robot: &Robot, steps: usize, tau: &[f64]) {
    let mut next = tau.to_vec();
    let max = robot.tendons[0].max_tension;
    next[0] += if tau[0] + 0.1 <= max { 0.1 } else { -0.1 };
    let cases = [
        ("warm_predicted", SolverSettings::default().tol, true, 0.0),
        ("warm_equal_accuracy", EQUAL_ACCURACY_TOL, true, 0.0),
        (
            "warm_equal_accuracy_no_predict",
            EQUAL_ACCURACY_TOL,
            false,
            0.0,
        ),
        (
            "warm_one_pass",
            EQUAL_ACCURACY_TOL,
            true,
            ONE_PASS_FINAL_STEP_M,
        ),
    ];
    for (name, tol, predict, final_step_m) in cases {
        let statics = Statics::new(
            robot,
            SolverSettings {
                steps,
                tol,
                final_step_m,
                ..SolverSettings::default()
            },
        );
        let mut prev = statics.solve(tau, None).unwrap();
        if predict {
            statics.add_tension_sensitivity(&mut prev);
        }
        c.bench_function(&format!("statics/{group}/{name}"), |b| {
            b.iter(|| statics.solve(black_box(&next), Some(&prev.warm)).unwrap())
        });
    }
}

fn solves(c: &mut Criterion) {
    let seed = robot("seed-4t.toml");
    let statics = Statics::new(&seed, SolverSettings::default());
    cold_and_warm(c, "mid", &statics, &[4.0, 3.0, 0.0, 0.0]);
    predicted_warm(c, "mid", &seed, 16, &[4.0, 3.0, 0.0, 0.0]);
    cold_and_warm(c, "max", &statics, &[10.0, 10.0, 0.0, 0.0]);

    // Multi-segment against the same rod with every tendon at the tip.
    let two = robot("tdcr-2seg.toml");
    let mut one = two.clone();
    for t in &mut one.tendons {
        t.end = one.length;
    }
    let tau = [3.0, 0.0, 1.0, 0.0, 2.0, 0.5];
    cold_and_warm(
        c,
        "tdcr-2seg",
        &Statics::new(&two, SolverSettings::default()),
        &tau,
    );
    cold_and_warm(
        c,
        "tdcr-tip-anchored",
        &Statics::new(&one, SolverSettings::default()),
        &tau,
    );

    // John Till's public C++ example robot with its tensions, at the 20 RK4
    // steps bench/cpp-reference/run times the C++ code with (same run).
    let till = Robot::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/cpp-reference/till-4t.toml"),
    )
    .unwrap();
    cold_and_warm(
        c,
        "till-4t",
        &Statics::new(
            &till,
            SolverSettings {
                steps: 20,
                ..SolverSettings::default()
            },
        ),
        &[15.0, 0.0, 0.0, 0.0],
    );
    predicted_warm(c, "till-4t", &till, 20, &[15.0, 0.0, 0.0, 0.0]);

    // One RK4 pass alone: the unit of cost of everything above.
    let sol = statics.solve(&[4.0, 3.0, 0.0, 0.0], None).unwrap();
    c.bench_function("statics/one_integration_16_steps", |b| {
        b.iter(|| statics.tip_state(black_box(&[4.0, 3.0, 0.0, 0.0]), &sol.warm.x, 16))
    });

    // Batch fk on rows in random order, one thread, time per row.
    let loads: Vec<Load> = Sampler::Uniform
        .draw(600, &seed.max_tensions(), 5)
        .into_iter()
        .map(Load::tensions)
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let stop = AtomicBool::new(false);
    let mut group = c.benchmark_group("statics/batch");
    group.throughput(Throughput::Elements(loads.len() as u64));
    group.sample_size(10);
    group.bench_function("600_uniform_rows_1_thread", |b| {
        b.iter(|| pool.install(|| solve_all(&statics, black_box(&loads), &stop, &|_| {})))
    });
    group.finish();
}

criterion_group!(benches, solves);
criterion_main!(benches);
