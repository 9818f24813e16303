//! The six baseline learners on a known smooth function: each recovers it on
//! held-out points, KNN with k = 1 interpolates its training points, the tree
//! is piecewise constant with at most 2^depth pieces, and fitting is
//! deterministic for a seed.

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

/// The target function: smooth, non-linear, coupled, values in [0, 1].
fn target(x: &[f64]) -> [f64; 3] {
    [
        0.5 + 0.4 * (2.0 * x[0] + x[1]).sin() * (1.0 - 0.5 * x[2]),
        0.3 + 0.5 * x[0] * x[1] + 0.2 * x[2] * x[2],
        0.5 + 0.3 * (3.0 * x[1] - x[2]).cos() * x[0],
    ]
}

/// `n` seeded uniform inputs in [0, 1]³ and their exact targets.
fn sample(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let x = DMatrix::from_fn(n, 3, |_, _| r.random_range(0.0..1.0));
    let mut y = DMatrix::zeros(n, 3);
    for i in 0..n {
        let xi: Vec<f64> = x.row(i).iter().copied().collect();
        for (j, v) in target(&xi).into_iter().enumerate() {
            y[(i, j)] = v;
        }
    }
    (x, y)
}

fn rmse(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    ((a - b).norm_squared() / a.len() as f64).sqrt()
}

struct Data {
    tx: DMatrix<f64>,
    ty: DMatrix<f64>,
    vx: DMatrix<f64>,
    vy: DMatrix<f64>,
    sx: DMatrix<f64>,
    sy: DMatrix<f64>,
}

fn data(n_train: usize) -> Data {
    let (tx, ty) = sample(n_train, 1);
    let (vx, vy) = sample(400, 2);
    let (sx, sy) = sample(500, 3);
    Data {
        tx,
        ty,
        vx,
        vy,
        sx,
        sy,
    }
}

/// Fit on train (tuning on valid), return the RMSE on the unseen test points.
fn held_out_rmse(l: &mut dyn Learner, d: &Data) -> f64 {
    l.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        5,
    )
    .expect("fit");
    rmse(&l.predict(&d.sx), &d.sy)
}

/// Predicting the mean gives this RMSE; every learner must do far better.
fn baseline_rmse(d: &Data) -> f64 {
    let mean = DMatrix::from_fn(d.sy.nrows(), 3, |_, j| d.ty.column(j).mean());
    rmse(&mean, &d.sy)
}

fn quick_training() -> Training {
    Training {
        epochs: 200,
        batch: 32,
        lr: 5e-3,
        lr_final_fraction: 0.01,
        eval_every: 5,
    }
}

#[test]
fn elm_recovers_smooth_function() {
    let d = data(3000);
    let mut l = Elm::with_grid(vec![100, 300], vec![1e-10, 1e-8], vec![1.0, 4.0]);
    let e = held_out_rmse(&mut l, &d);
    assert!(
        e < 1e-3,
        "ELM test RMSE {e} (mean predictor {})",
        baseline_rmse(&d)
    );
}

#[test]
fn rbf_recovers_smooth_function() {
    let d = data(3000);
    let mut l = Rbf::with_grid(vec![100, 200], vec![1.0, 2.0], vec![1e-10, 1e-7]);
    let e = held_out_rmse(&mut l, &d);
    assert!(e < 1e-3, "RBF test RMSE {e}");
}

#[test]
fn mlp_recovers_smooth_function() {
    let d = data(3000);
    let mut l = Mlp::with_grid(vec![vec![16], vec![32]], quick_training());
    let e = held_out_rmse(&mut l, &d);
    assert!(e < 5e-3, "MLP test RMSE {e}");
}

#[test]
fn cascade_forward_recovers_smooth_function() {
    let d = data(3000);
    let mut l = CascadeForward::with_grid(vec![vec![16], vec![8, 8]], quick_training());
    let e = held_out_rmse(&mut l, &d);
    assert!(e < 5e-3, "cascade-forward test RMSE {e}");
}

#[test]
fn knn_recovers_smooth_function() {
    let d = data(3000);
    let mut l = Knn::default();
    let e = held_out_rmse(&mut l, &d);
    // Nearest-neighbour spacing in 3-D with 3000 points is ~0.07: a local mean is that coarse.
    assert!(e < 0.02, "KNN test RMSE {e}");
    assert!(e < 0.1 * baseline_rmse(&d));
}

#[test]
fn tree_recovers_smooth_function() {
    let d = data(3000);
    let mut l = RegressionTree::default();
    let e = held_out_rmse(&mut l, &d);
    assert!(e < 0.03, "tree test RMSE {e}");
    assert!(
        e < 0.2 * baseline_rmse(&d),
        "tree {e} vs mean predictor {}",
        baseline_rmse(&d)
    );
}

#[test]
fn knn_with_one_neighbour_reproduces_training_points() {
    let d = data(1500);
    for w in [Weighting::Uniform, Weighting::Distance] {
        let mut l = Knn::fixed(1, w);
        l.fit(
            Split { x: &d.tx, y: &d.ty },
            Split { x: &d.vx, y: &d.vy },
            0,
        )
        .unwrap();
        assert_eq!(l.predict(&d.tx), d.ty, "{w:?}");
    }
}

#[test]
fn distance_weighted_knn_is_exact_at_training_points_for_any_k() {
    let d = data(1500);
    let mut l = Knn::fixed(7, Weighting::Distance);
    l.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        0,
    )
    .unwrap();
    assert_eq!(l.predict(&d.tx), d.ty);
}

#[test]
fn uniform_knn_is_the_mean_of_the_k_nearest_by_brute_force() {
    let d = data(800);
    let mut l = Knn::fixed(4, Weighting::Uniform);
    l.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        0,
    )
    .unwrap();
    let p = l.predict(&d.sx);
    for i in 0..50 {
        let mut dist: Vec<(f64, usize)> = (0..d.tx.nrows())
            .map(|r| ((d.tx.row(r) - d.sx.row(i)).norm_squared(), r))
            .collect();
        dist.sort_by(|a, b| a.0.total_cmp(&b.0));
        for j in 0..3 {
            let m: f64 = dist[..4].iter().map(|&(_, r)| d.ty[(r, j)]).sum::<f64>() / 4.0;
            assert!((p[(i, j)] - m).abs() < 1e-12);
        }
    }
}

fn distinct_rows(m: &DMatrix<f64>) -> usize {
    let mut rows: Vec<Vec<u64>> = (0..m.nrows())
        .map(|i| m.row(i).iter().map(|v| v.to_bits()).collect())
        .collect();
    rows.sort();
    rows.dedup();
    rows.len()
}

#[test]
fn tree_is_piecewise_constant_with_at_most_two_to_the_depth_pieces() {
    let d = data(2000);
    let (dense, _) = sample(5000, 9);
    for depth in [1, 3, 5, 7] {
        let mut t = RegressionTree::fixed(depth, 1);
        t.fit(
            Split { x: &d.tx, y: &d.ty },
            Split { x: &d.vx, y: &d.vy },
            0,
        )
        .unwrap();
        let n = distinct_rows(&t.predict(&dense));
        assert!(n <= 1 << depth, "depth {depth}: {n} distinct outputs");
        // Greedy CART on continuous data splits until the limit: it does use the depth.
        assert!(
            n > 1 << (depth - 1),
            "depth {depth}: only {n} distinct outputs"
        );
    }
}

#[test]
fn unlimited_tree_with_unit_leaves_interpolates_training_data() {
    let d = data(500);
    let mut t = RegressionTree::fixed(64, 1);
    t.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        0,
    )
    .unwrap();
    assert!(rmse(&t.predict(&d.tx), &d.ty) < 1e-12);
}

#[test]
fn tree_depth_one_is_the_best_single_split_by_brute_force() {
    let d = data(300);
    let mut t = RegressionTree::fixed(1, 1);
    t.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        0,
    )
    .unwrap();
    let sse = |p: &DMatrix<f64>| (p - &d.ty).norm_squared();
    let got = sse(&t.predict(&d.tx));
    // Every threshold at a data point on every feature, means on each side.
    let mut best = f64::INFINITY;
    for f in 0..3 {
        for r in 0..d.tx.nrows() {
            let thr = d.tx[(r, f)];
            let left: Vec<usize> = (0..d.tx.nrows()).filter(|&i| d.tx[(i, f)] <= thr).collect();
            let right: Vec<usize> = (0..d.tx.nrows()).filter(|&i| d.tx[(i, f)] > thr).collect();
            if left.is_empty() || right.is_empty() {
                continue;
            }
            let mut s = 0.0;
            for side in [&left, &right] {
                for j in 0..3 {
                    let m = side.iter().map(|&i| d.ty[(i, j)]).sum::<f64>() / side.len() as f64;
                    s += side
                        .iter()
                        .map(|&i| (d.ty[(i, j)] - m).powi(2))
                        .sum::<f64>();
                }
            }
            best = best.min(s);
        }
    }
    assert!(
        (got - best).abs() < 1e-9 * best.max(1.0),
        "tree {got} vs brute force {best}"
    );
}

fn fitted_predictions(make: &dyn Fn() -> Box<dyn Learner>, seed: u64, d: &Data) -> DMatrix<f64> {
    let mut l = make();
    l.fit(
        Split { x: &d.tx, y: &d.ty },
        Split { x: &d.vx, y: &d.vy },
        seed,
    )
    .unwrap();
    l.predict(&d.sx)
}

#[test]
fn fitting_is_deterministic_for_a_seed() {
    let d = data(1000);
    let makers: Vec<Box<dyn Fn() -> Box<dyn Learner>>> = vec![
        Box::new(|| Box::new(Elm::with_grid(vec![50, 100], vec![1e-8], vec![1.0]))),
        Box::new(|| Box::new(Rbf::with_grid(vec![30], vec![1.0], vec![1e-8]))),
        Box::new(|| {
            Box::new(Mlp::with_grid(
                vec![vec![8], vec![4, 4]],
                Training {
                    epochs: 5,
                    ..Training::default()
                },
            ))
        }),
        Box::new(|| {
            Box::new(CascadeForward::with_grid(
                vec![vec![8], vec![4, 4]],
                Training {
                    epochs: 5,
                    ..Training::default()
                },
            ))
        }),
        Box::new(|| Box::new(Knn::default())),
        Box::new(|| Box::new(RegressionTree::fixed(6, 2))),
    ];
    for (i, make) in makers.iter().enumerate() {
        let a = fitted_predictions(make.as_ref(), 11, &d);
        let b = fitted_predictions(make.as_ref(), 11, &d);
        assert_eq!(a, b, "learner {i} differs between two fits with one seed");
        if i < 4 {
            // The randomised learners really use the seed.
            let c = fitted_predictions(make.as_ref(), 12, &d);
            assert_ne!(a, c, "learner {i} ignores its seed");
        }
    }
}

#[test]
fn fitting_does_not_depend_on_the_thread_count() {
    let d = data(1000);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut l = Elm::with_grid(vec![50, 200], vec![1e-8, 1e-6], vec![1.0]);
            l.fit(
                Split { x: &d.tx, y: &d.ty },
                Split { x: &d.vx, y: &d.vy },
                3,
            )
            .unwrap();
            let mut m = Mlp::with_grid(
                vec![vec![8], vec![4]],
                Training {
                    epochs: 3,
                    ..Training::default()
                },
            );
            m.fit(
                Split { x: &d.tx, y: &d.ty },
                Split { x: &d.vx, y: &d.vy },
                3,
            )
            .unwrap();
            (l.predict(&d.sx), m.predict(&d.sx))
        })
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn bad_data_is_rejected_with_a_reason() {
    let d = data(100);
    let mut nan = d.tx.clone();
    nan[(3, 1)] = f64::NAN;
    let mut l = Elm::default();
    let e = l
        .fit(Split { x: &nan, y: &d.ty }, Split { x: &d.vx, y: &d.vy }, 0)
        .unwrap_err();
    assert!(e.to_string().contains("non-finite"), "{e}");
    let short = d.ty.rows(0, 50).into_owned();
    let e = Knn::default()
        .fit(
            Split {
                x: &d.tx,
                y: &short,
            },
            Split { x: &d.vx, y: &d.vy },
            0,
        )
        .unwrap_err();
    assert!(e.to_string().contains("rows"), "{e}");
}
