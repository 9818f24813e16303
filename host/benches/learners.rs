//! Baseline learners: single-query inference time (the control-loop cost of
//! each model) and fit time with fixed hyper-parameters, on a synthetic smooth
//! 7 → 4 map with the shape of the IK problem.
//!
//! `CARGO_TARGET_DIR=... cargo bench -p tendril --bench learners`

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril::learn::cascade_forward::CascadeForward;
use tendril::learn::elm::Elm;
use tendril::learn::knn::{Knn, Weighting};
use tendril::learn::mlp::{Mlp, Training};
use tendril::learn::rbf::Rbf;
use tendril::learn::tree::RegressionTree;
use tendril::learn::{Learner, Split};

fn data(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let x = DMatrix::from_fn(n, 7, |_, _| r.random_range(0.0..1.0));
    let y = DMatrix::from_fn(n, 4, |i, j| {
        let s: f64 = (0..7)
            .map(|k| x[(i, k)] * ((j + k) as f64 * 0.7).sin())
            .sum();
        0.5 + 0.4 * (s + j as f64).sin()
    });
    (x, y)
}

fn quick() -> Training {
    Training {
        epochs: 10,
        ..Training::default()
    }
}

fn learners() -> Vec<Box<dyn Learner>> {
    vec![
        Box::new(Knn::fixed(5, Weighting::Distance)),
        Box::new(Rbf::fixed(400, 1.0, 1e-8)),
        Box::new(Mlp::with_grid(vec![vec![64]], quick())),
        Box::new(Elm::fixed(1000, 1e-8, 1.0)),
        Box::new(RegressionTree::fixed(14, 2)),
        Box::new(CascadeForward::with_grid(vec![vec![64]], quick())),
    ]
}

fn bench(c: &mut Criterion) {
    let (tx, ty) = data(5000, 1);
    let (vx, vy) = data(500, 2);
    let (qx, _) = data(64, 3);
    let mut g = c.benchmark_group("predict_one");
    for mut l in learners() {
        l.fit(Split { x: &tx, y: &ty }, Split { x: &vx, y: &vy }, 1)
            .expect("fit");
        let rows: Vec<DMatrix<f64>> = (0..qx.nrows())
            .map(|i| qx.rows(i, 1).into_owned())
            .collect();
        let mut k = 0;
        g.bench_function(l.name().to_string(), |b| {
            b.iter(|| {
                k = (k + 1) % rows.len();
                l.predict(&rows[k])
            })
        });
    }
    g.finish();

    let (fx, fy) = data(2000, 4);
    let mut g = c.benchmark_group("fit_2000_rows");
    g.sample_size(10);
    for l in learners() {
        let name = l.name().to_string();
        let mut slot = Some(l);
        g.bench_function(name, |b| {
            b.iter_batched(
                || (),
                |_| {
                    if let Some(l) = slot.as_mut() {
                        l.fit(Split { x: &fx, y: &fy }, Split { x: &vx, y: &vy }, 1)
                            .expect("fit");
                    }
                },
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
