//! The cascade-correlation trainer learns known functions to a tight error on
//! held-out points, and is deterministic for a seed whatever the thread count.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril::learn::cascor::{
    train, Cascor, CascorOptions, ObjectiveChoice, OutputKind, OutputSolver, PolishOptions,
};
use tendril::learn::{Learner, Split};

fn sample(n: usize, seed: u64, f: impl Fn(f64, f64) -> f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x = DMatrix::from_fn(n, 2, |_, _| rng.random_range(0.0..1.0));
    let y = DMatrix::from_fn(n, 1, |r, _| f(x[(r, 0)], x[(r, 1)]));
    (x, y)
}

fn rmse(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    ((a - b).norm_squared() / a.len() as f64).sqrt()
}

fn quick() -> CascorOptions {
    CascorOptions {
        max_hidden: 30,
        candidate_patterns: 0,
        progress: false,
        ..CascorOptions::default()
    }
}

fn smooth_xor(a: f64, b: f64) -> f64 {
    0.5 + 0.45 * (6.0 * (a - 0.5)).tanh() * (6.0 * (b - 0.5)).tanh()
}

#[test]
fn learns_a_smooth_xor_surface_on_held_out_points() {
    let (x, y) = sample(600, 1, smooth_xor);
    let (vx, vy) = sample(200, 2, smooth_xor);
    let (tx, ty) = sample(400, 3, smooth_xor);
    // Linear outputs cannot represent XOR: the start is poor.
    let linear_only = CascorOptions {
        max_hidden: 0,
        ..quick()
    };
    let (lin, _) = train(&x, &y, &vx, &vy, &linear_only, 5).unwrap();
    assert!(rmse(&lin.predict(&tx), &ty) > 0.2);
    let (net, report) = train(&x, &y, &vx, &vy, &quick(), 5).unwrap();
    let e = rmse(&net.predict(&tx), &ty);
    // Within 2 % of the target range (0.9), ten times better than the linear start.
    assert!(e < 0.02, "test RMSE {e} with {} units", report.best_hidden);
}

#[test]
fn learns_a_smooth_2d_function_tightly() {
    let f = |a: f64, b: f64| 0.5 + 0.3 * (3.0 * a).sin() * (2.0 * b + 0.5).cos();
    let (x, y) = sample(1000, 11, f);
    let (vx, vy) = sample(300, 12, f);
    let (tx, ty) = sample(500, 13, f);
    for objective in [ObjectiveChoice::Covariance, ObjectiveChoice::Cascade2] {
        let o = CascorOptions {
            objective,
            ..quick()
        };
        let (net, report) = train(&x, &y, &vx, &vy, &o, 7).unwrap();
        let e = rmse(&net.predict(&tx), &ty);
        // Within 1 % of the target range (0.6).
        assert!(
            e < 6e-3,
            "{objective:?}: test RMSE {e} with {} units",
            report.best_hidden
        );
        // The learning curve falls: the kept net beats the linear start.
        assert!(report.best_valid_rmse < 0.2 * report.history[0].valid_rmse);
    }
}

#[test]
fn quickprop_outputs_and_sigmoid_outputs_also_learn() {
    let (x, y) = sample(500, 21, smooth_xor);
    let (vx, vy) = sample(200, 22, smooth_xor);
    let (tx, ty) = sample(300, 23, smooth_xor);
    for (kind, solver) in [
        (OutputKind::Linear, OutputSolver::Quickprop),
        (OutputKind::Sigmoid, OutputSolver::Quickprop),
    ] {
        let o = CascorOptions {
            output_kinds: vec![kind],
            output_solvers: vec![solver],
            max_hidden: 10,
            ..quick()
        };
        let (net, _) = train(&x, &y, &vx, &vy, &o, 3).unwrap();
        assert_eq!(net.output_kind, kind);
        let e = rmse(&net.predict(&tx), &ty);
        assert!(e < 0.05, "{kind} / {solver}: test RMSE {e}");
    }
}

#[test]
fn training_is_deterministic_whatever_the_thread_count() {
    let (x, y) = sample(300, 31, smooth_xor);
    let (vx, vy) = sample(100, 32, smooth_xor);
    let o = CascorOptions {
        max_hidden: 4,
        candidate_patterns: 150,
        objective: ObjectiveChoice::Mixed,
        // The polish's gradient sums rows in fixed blocks: it too must not
        // depend on the thread count.
        polish: PolishOptions {
            max_iterations: 60,
            ..PolishOptions::default()
        },
        ..quick()
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| train(&x, &y, &vx, &vy, &o, 9).unwrap().0)
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn learner_trait_fits_and_predicts() {
    let (x, y) = sample(400, 41, smooth_xor);
    let (vx, vy) = sample(100, 42, smooth_xor);
    let mut l = Cascor::new(CascorOptions {
        max_hidden: 6,
        ..quick()
    });
    assert_eq!(l.name(), "Cascade correlation");
    assert_eq!(l.predict(&vx).ncols(), 0);
    l.fit(Split { x: &x, y: &y }, Split { x: &vx, y: &vy }, 1)
        .unwrap();
    assert_eq!(l.predict(&vx).shape(), (100, 1));
    assert!(l.parameter_count() > 0);
    assert!(l.describe().contains("hidden units"));
    let bad = DMatrix::from_element(400, 1, f64::NAN);
    assert!(l
        .fit(Split { x: &x, y: &bad }, Split { x: &vx, y: &vy }, 1)
        .is_err());
}

#[test]
fn polishing_a_small_net_beats_its_greedy_weights_on_held_out_points() {
    let f = |a: f64, b: f64| 0.5 + 0.3 * (3.0 * a).sin() * (2.0 * b + 0.5).cos();
    let (x, y) = sample(800, 21, f);
    let (vx, vy) = sample(200, 22, f);
    let (tx, ty) = sample(500, 23, f);
    let small = CascorOptions {
        max_hidden: 4,
        ..quick()
    };
    let (greedy, _) = train(&x, &y, &vx, &vy, &small, 3).unwrap();
    let polished_opts = CascorOptions {
        polish: PolishOptions {
            max_iterations: 400,
            ..PolishOptions::default()
        },
        ..small
    };
    let (polished, report) = train(&x, &y, &vx, &vy, &polished_opts, 3).unwrap();
    let p = report.polish.expect("the polish ran");
    assert!(p.iterations > 50, "{p:?}");
    assert!(p.valid_rmse.1 < p.valid_rmse.0, "{p:?}");
    assert_eq!(polished.n_hidden(), greedy.n_hidden());
    let (eg, ep) = (
        rmse(&greedy.predict(&tx), &ty),
        rmse(&polished.predict(&tx), &ty),
    );
    // The same four units, every weight trained together: held-out RMSE at
    // least halves.
    assert!(ep < 0.5 * eg, "held-out RMSE greedy {eg}, polished {ep}");
}
