//! `tendril::compare` end to end on a small real dataset (Cosserat solves of
//! the seed robot): a table row for every learner, metrics that agree with
//! an independent recomputation, and the three output files.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril::compare::{compare, CompareOptions};
use tendril::dataset::Dataset;
use tendril::learn::cascade_forward::CascadeForward;
use tendril::learn::cascor::{Cascor, CascorOptions};
use tendril::learn::elm::Elm;
use tendril::learn::knn::{Knn, Weighting};
use tendril::learn::mlp::{Mlp, Training};
use tendril::learn::rbf::Rbf;
use tendril::learn::tree::RegressionTree;
use tendril::learn::Learner;
use tendril::robot::{repo_robot, Robot};
use tendril::statics::{SolverSettings, Statics};

fn robot() -> Robot {
    repo_robot("seed-4t.toml")
}

/// `n` rows: two adjacent tendons pulled (the default sampler's shape), solved by the statics.
fn dataset(robot: &Robot, n: usize) -> Dataset {
    let statics = Statics::new(robot, SolverSettings::default());
    let mut r = ChaCha8Rng::seed_from_u64(4);
    let mut tensions = DMatrix::zeros(n, 4);
    let mut poses = DMatrix::zeros(n, 7);
    for i in 0..n {
        let a = r.random_range(0..4);
        tensions[(i, a)] = r.random_range(0.0..10.0);
        tensions[(i, (a + 1) % 4)] = r.random_range(0.0..10.0);
        let t: Vec<f64> = tensions.row(i).iter().copied().collect();
        let sol = statics.solve(&t, None).expect("solve");
        for (j, v) in sol.pose().into_iter().enumerate() {
            poses[(i, j)] = v;
        }
    }
    Dataset {
        n_tendons: 4,
        tensions,
        poses,
    }
}

fn small_learners() -> Vec<Box<dyn Learner>> {
    let quick = Training {
        epochs: 20,
        ..Training::default()
    };
    vec![
        Box::new(Cascor::new(CascorOptions {
            max_hidden: 2,
            pool: 2,
            progress: false,
            ..CascorOptions::default()
        })),
        Box::new(Knn::with_grid(
            vec![1, 3],
            vec![Weighting::Uniform, Weighting::Distance],
        )),
        Box::new(Rbf::with_grid(vec![10, 20], vec![1.0, 2.0], vec![1e-8])),
        Box::new(Mlp::with_grid(vec![vec![4], vec![8]], quick.clone())),
        Box::new(Elm::with_grid(vec![20, 40], vec![1e-8], vec![4.0])),
        Box::new(RegressionTree::with_grid(vec![2, 4], vec![1, 2])),
        Box::new(CascadeForward::with_grid(vec![vec![4], vec![8]], quick)),
    ]
}

#[test]
fn comparison_has_a_row_for_every_learner_and_writes_its_files() {
    let robot = robot();
    let data = dataset(&robot, 160);
    let opts = CompareOptions {
        test_fraction: 0.2,
        valid_fraction: 0.2,
        train_task_rows: 20,
        timing_queries: 10,
        progress: false,
        ..CompareOptions::default()
    };
    let learners = small_learners();
    let names: Vec<String> = learners.iter().map(|l| l.name().to_string()).collect();
    let cmp = compare(&data, &robot, learners, &opts).expect("compare");
    assert_eq!(cmp.entries.len(), names.len());
    let md = cmp.to_markdown();
    let csv = cmp.to_csv();
    assert_eq!(csv.lines().count(), names.len() + 1);
    for n in &names {
        assert_eq!(
            md.lines()
                .filter(|l| l.starts_with(&format!("| {n} |")))
                .count(),
            1,
            "{n} row in\n{md}"
        );
        assert_eq!(
            csv.lines()
                .filter(|l| l.starts_with(&format!("{n},")))
                .count(),
            1,
            "{n} row in\n{csv}"
        );
    }
    let (nf, nv, nt) = cmp.sizes;
    assert_eq!(nf + nv + nt, 160);
    for e in &cmp.entries {
        assert_eq!(e.test.samples, nt);
        assert_eq!(e.train.samples, nf);
        assert_eq!(e.train_task_rows, 20);
        assert!(
            e.test.position_mm.mean.is_finite() && e.test.position_mm.mean >= 0.0,
            "{}",
            e.name
        );
        // Newtons and normalised units are the same error on a 0–10 N range (up to the
        // training split's observed range): RMSE N ≈ RMSE×100 / 100 × range.
        let ratio = e.test.tension_rmse_newton / (e.test.tension_rmse_norm100 / 100.0);
        assert!(
            ratio > 8.0 && ratio <= 10.0 + 1e-9,
            "{}: N / normalised ratio {ratio}",
            e.name
        );
        assert!(e.parameters > 0 && e.train_seconds >= 0.0 && e.infer_us > 0.0);
        assert!(e.infer_batched_us > 0.0 && e.test.inference_ns_per_query > 0.0);
        assert!(!e.hyper.is_empty());
    }
    // A tree of depth ≤ 4 has at most 16 leaves: it cannot fit 96 rows exactly.
    let tree = cmp
        .entries
        .iter()
        .find(|e| e.name == "Regression tree")
        .unwrap();
    assert!(tree.train.tension_rmse_norm100 > 0.0);

    let dir = tempfile::tempdir().unwrap();
    let files = cmp.write(dir.path()).expect("write");
    for f in &files {
        assert!(
            std::fs::metadata(f).map(|m| m.len() > 100).unwrap_or(false),
            "{}",
            f.display()
        );
    }
    assert_eq!(
        std::fs::read_to_string(dir.path().join("compare.csv")).unwrap(),
        csv
    );
}

#[test]
fn comparison_rejects_a_dataset_for_another_robot() {
    let robot = robot();
    let data = Dataset {
        n_tendons: 2,
        tensions: DMatrix::zeros(100, 2),
        poses: DMatrix::zeros(100, 7),
    };
    let e = compare(&data, &robot, Vec::new(), &CompareOptions::default()).unwrap_err();
    assert!(e.to_string().contains("tendons"), "{e}");
}
