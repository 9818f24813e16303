//! Fitting, timing and evaluating every learner on one split: same
//! normalisation, validation-only tuning, the same metrics for all.

use std::path::Path;
use std::time::Instant;

use nalgebra::DMatrix;

use super::{CompareError, CompareOptions, Comparison, Entry};
use crate::dataset::{prepare_excluding, split_indices, Dataset, MinMax, Prepared};
use crate::evaluate::{
    plain_clip_position_if_different, staged_tensions, task_space_errors, tension_rmse,
    tension_rmse_normalised, EvalError, SplitMetrics,
};
use crate::learn::targets::Targets;
use crate::learn::{Learner, Split};
use crate::robot::Robot;
use crate::statics::{SolverSettings, Statics};

/// Inference time of one learner, µs per row, measured the same way for
/// every learner (through [`Learner::predict`], whatever the learner does
/// inside it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InferenceTime {
    /// Single queries: `predict` on a 1-row matrix, once per test row.
    pub single_us: f64,
    /// Batched: `predict` on all the timed test rows at once, per row.
    pub batched_us: f64,
    /// Single queries by the learner's fast path (`Learner::predict_fast`;
    /// `None`: it has none).
    pub single_fast_us: Option<f64>,
}

/// Wall time spent on timing each of the two modes (at least one pass):
/// long enough that the clock's resolution and one-off effects vanish.
const TIMING_SECONDS: f64 = 0.05;

/// Times `l` on the first `count` (≥ 1) rows of `x`: single queries (each
/// row its own 1-row matrix, built before the clock starts) and the same
/// rows as one batch, each mode repeated in whole passes for ≥
/// [`TIMING_SECONDS`] after one warm-up call. Both include what every
/// learner's `predict` costs around the arithmetic (the output matrix), so
/// the learners stay comparable with each other.
pub fn time_inference(l: &dyn Learner, x: &DMatrix<f64>, count: usize) -> InferenceTime {
    let n = x.nrows().min(count.max(1));
    let rows: Vec<DMatrix<f64>> = (0..n).map(|i| x.rows(i, 1).into_owned()).collect();
    let batch = x.rows(0, n).into_owned();
    let mut sink = 0.0;
    let mut per_row = |pass: &mut dyn FnMut() -> f64| -> f64 {
        sink += pass(); // warm caches and lazily built state
        let (t, mut passes) = (Instant::now(), 0usize);
        while passes == 0 || t.elapsed().as_secs_f64() < TIMING_SECONDS {
            sink += pass();
            passes += 1;
        }
        t.elapsed().as_secs_f64() * 1e6 / (passes * n) as f64
    };
    let single_us = per_row(&mut || rows.iter().map(|r| first(&l.predict(r))).sum());
    let batched_us = per_row(&mut || first(&l.predict(&batch)));
    let single_fast_us = l.predict_fast(&rows[0]).is_some().then(|| {
        per_row(&mut || {
            rows.iter()
                .map(|r| l.predict_fast(r).as_ref().map_or(0.0, first))
                .sum()
        })
    });
    std::hint::black_box(sink);
    InferenceTime {
        single_us,
        batched_us,
        single_fast_us,
    }
}

/// The first value of a prediction (0 for an empty one): what the timing
/// keeps so the optimiser cannot drop the call.
fn first(y: &DMatrix<f64>) -> f64 {
    y.iter().next().copied().unwrap_or(0.0)
}

/// `k` seeded distinct indices of `0..n`, sorted (all of them when `k` is 0 or ≥ n).
fn subsample(n: usize, k: usize, seed: u64) -> Vec<usize> {
    if k == 0 || k >= n {
        return (0..n).collect();
    }
    let mut r = crate::learn::linalg::rng(seed ^ 0x7a5c_0b1e);
    let mut v = rand::seq::index::sample(&mut r, n, k).into_vec();
    v.sort_unstable();
    v
}

/// The `docs/design.md` §4 metrics of predicted tensions (newtons): tension RMSE
/// of the staged predictions over every row (normalised by the dataset's
/// training tension ranges `truth_ranges`), task-space error over the rows
/// `task_idx`.
fn split_metrics(
    statics: &Statics,
    truth_ranges: &MinMax,
    pred: &DMatrix<f64>,
    truth: &DMatrix<f64>,
    poses: &DMatrix<f64>,
    task_idx: &[usize],
    batched_us: f64,
) -> Result<SplitMetrics, EvalError> {
    let (pred_task, poses_task) = (pred.select_rows(task_idx), poses.select_rows(task_idx));
    let task = task_space_errors(statics, &pred_task, &poses_task)?;
    let plain_clip = plain_clip_position_if_different(statics, &pred_task, &poses_task)?;
    let staged = staged_tensions(statics, pred)?;
    let (lo, hi) = (&truth_ranges.lo, &truth_ranges.hi);
    Ok(SplitMetrics {
        samples: pred.nrows(),
        tension_rmse_norm100: tension_rmse_normalised(&staged, truth, lo, hi)?,
        tension_rmse_newton: tension_rmse(&staged, truth)?,
        position_mm: task.position_stats(),
        orientation_deg: task.orientation_stats(),
        failed_solves: task.failed,
        // Batched, like `tendril evaluate`'s figure of the same name.
        inference_ns_per_query: batched_us * 1e3,
        position_mm_plain_clip: plain_clip,
    })
}

/// Train, time and evaluate every learner on one split of `data`.
pub fn compare(
    data: &Dataset,
    robot: &Robot,
    mut learners: Vec<Box<dyn Learner>>,
    opts: &CompareOptions,
) -> Result<Comparison, CompareError> {
    if data.n_tendons != robot.n_tendons() {
        return Err(CompareError::BadInput(format!(
            "dataset has {} tension columns but robot {} has {} tendons",
            data.n_tendons,
            robot.name,
            robot.n_tendons()
        )));
    }
    if data.len() < 50 {
        return Err(CompareError::BadInput(format!(
            "dataset has only {} rows; the comparison needs at least 50",
            data.len()
        )));
    }
    // Every learner learns the same targets (centred on the robot's
    // co-contraction sets, docs/design.md §4) and is judged on the dataset's
    // tensions, the same rows split the same way.
    let targets = opts
        .targets
        .clone()
        .unwrap_or_else(|| Targets::for_robot(robot));
    let mut notes = Vec::new();
    let exclude = if opts.reject_outliers {
        let (exclude, r) =
            crate::dataset::measured::training_outliers(data, opts.test_fraction, opts.seed);
        notes.push(format!(
            "Measured rows: {} of {} training rows left out of every learner's fit as outliers \
             (tip off its neighbours' local fit by more than {}; residual σ {} per axis).",
            r.count,
            r.rows,
            crate::units::length_mm(r.threshold_mm),
            crate::units::length_mm(r.residual_sigma_mm)
        ));
        exclude
    } else {
        Vec::new()
    };
    let p = prepare_excluding(
        &targets.learning_data(data),
        opts.test_fraction,
        opts.valid_fraction,
        opts.seed,
        &exclude,
    );
    let truth = prepare_excluding(
        data,
        opts.test_fraction,
        opts.valid_fraction,
        opts.seed,
        &exclude,
    );
    // The test split's queries and what they are judged against: the
    // dataset's own poses on the given robot, or the true rows on the true
    // robot.
    let true_test = match &opts.true_rows {
        Some(t) => {
            if t.poses.nrows() != data.len() || t.poses.ncols() != 7 {
                return Err(CompareError::BadInput(format!(
                    "the true rows are {} × {}, the dataset {} × 7: they must be the same rows",
                    t.poses.nrows(),
                    t.poses.ncols(),
                    data.len()
                )));
            }
            if t.robot.n_tendons() != robot.n_tendons() {
                return Err(CompareError::BadInput(format!(
                    "the true robot {} has {} tendons, the robot {}",
                    t.robot.name,
                    t.robot.n_tendons(),
                    robot.n_tendons()
                )));
            }
            let (_, test_idx) = split_indices(data.len(), opts.test_fraction, opts.seed);
            let poses = t.poses.select_rows(&test_idx);
            notes.push(format!(
                "Test split judged against the truth: each learner is asked for the true pose \
                 of every test row, its tensions are solved on the true robot {} and the tip \
                 is compared with the true tip.",
                t.robot.name
            ));
            Some((
                p.x_range.normalise(&poses),
                poses,
                Statics::new(&t.robot, SolverSettings::default()),
            ))
        }
        None => None,
    };
    if let Some(dir) = &opts.dump_splits {
        dump_splits(&p, dir)?;
    }
    let statics = Statics::new(robot, SolverSettings::default());
    // Physical-unit truth of the fit split (validation rows excluded) and of the test split.
    let fit_poses = p.x_range.denormalise(&p.train_x);
    let fit_tensions = truth.y_range.denormalise(&truth.train_y);
    let task_idx = subsample(p.train_x.nrows(), opts.train_task_rows, opts.seed);
    let bar = crate::progress::bar(
        learners.len() as u64,
        opts.progress,
        "{prefix} [{bar:30}] {pos}/{len} learners, {elapsed} {msg}",
    );
    bar.set_prefix("compare");
    let mut entries = Vec::new();
    for l in learners.iter_mut() {
        // A stop ends the comparison between learners (each one's fit is
        // seconds at most): nothing half-compared is reported.
        if crate::interrupt::stop_requested() {
            bar.finish_and_clear();
            return Err(CompareError::Interrupted);
        }
        let name = l.name().to_string();
        bar.set_message(format!("training {name}"));
        log::debug!("compare: training {name}");
        let t = Instant::now();
        l.fit(
            Split {
                x: &p.train_x,
                y: &p.train_y,
            },
            Split {
                x: &p.valid_x,
                y: &p.valid_y,
            },
            opts.seed,
        )
        .map_err(|source| CompareError::Learn {
            name: name.clone(),
            source,
        })?;
        let train_seconds = l.fit_seconds().unwrap_or(t.elapsed().as_secs_f64());
        bar.set_message(format!("evaluating {name}"));
        let time = time_inference(l.as_ref(), &p.test_x, opts.timing_queries);
        let eval_err = |source| CompareError::Eval {
            name: name.clone(),
            source,
        };
        let pred_fit = p.y_range.denormalise(&l.predict(&p.train_x));
        let train = split_metrics(
            &statics,
            &truth.y_range,
            &pred_fit,
            &fit_tensions,
            &fit_poses,
            &task_idx,
            time.batched_us,
        )
        .map_err(eval_err)?;
        let (test_x, test_poses, test_statics) = match &true_test {
            Some((x, poses, st)) => (x, poses, st),
            None => (&p.test_x, &truth.test.poses, &statics),
        };
        let mut pred_test = p.y_range.denormalise(&l.predict(test_x));
        if true_test.is_some() {
            // The MCU stages with the robot file it is given (the nominal
            // one, whose co-contraction weights centred the targets); only
            // the physics is the true robot's. Staging again on the true
            // robot leaves a staged row as it is.
            pred_test = staged_tensions(&statics, &pred_test).map_err(eval_err)?;
        }
        let all_test: Vec<usize> = (0..p.test.len()).collect();
        let test = split_metrics(
            test_statics,
            &truth.y_range,
            &pred_test,
            &truth.test.tensions,
            test_poses,
            &all_test,
            time.batched_us,
        )
        .map_err(eval_err)?;
        log::debug!(
            "compare: {name}: test RMSE×100 {:.3}, tip mean {:.3} mm, train {:.1} s",
            test.tension_rmse_norm100,
            test.position_mm.mean,
            train_seconds
        );
        entries.push(Entry {
            name,
            hyper: l.describe(),
            parameters: l.parameter_count(),
            train_seconds,
            infer_us: time.single_us,
            infer_batched_us: time.batched_us,
            infer_fast_us: time.single_fast_us,
            train,
            train_task_rows: task_idx.len(),
            test,
        });
        bar.inc(1);
    }
    bar.finish_with_message("done");
    Ok(Comparison {
        robot: robot.name.clone(),
        sizes: (p.train_x.nrows(), p.valid_x.nrows(), p.test_x.nrows()),
        options: opts.clone(),
        entries,
        notes,
    })
}

/// Write the normalised splits as `fit.csv`, `valid.csv`, `test.csv`
/// (columns `x0..`, then `y0..`) into `dir`.
pub fn dump_splits(p: &Prepared, dir: &Path) -> Result<(), CompareError> {
    let werr = |path: &Path, why: String| CompareError::Write {
        path: path.to_path_buf(),
        why,
    };
    std::fs::create_dir_all(dir).map_err(|e| werr(dir, e.to_string()))?;
    for (name, x, y) in [
        ("fit.csv", &p.train_x, &p.train_y),
        ("valid.csv", &p.valid_x, &p.valid_y),
        ("test.csv", &p.test_x, &p.test_y),
    ] {
        let path = dir.join(name);
        crate::fsutil::write_atomic_with(&path, |w: &mut dyn std::io::Write| {
            let head: Vec<String> = (0..x.ncols())
                .map(|j| format!("x{j}"))
                .chain((0..y.ncols()).map(|j| format!("y{j}")))
                .collect();
            writeln!(w, "{}", head.join(","))?;
            for i in 0..x.nrows() {
                let row: Vec<String> = x
                    .row(i)
                    .iter()
                    .chain(y.row(i).iter())
                    .map(|v| format!("{v:e}"))
                    .collect();
                writeln!(w, "{}", row.join(","))?;
            }
            Ok(())
        })
        .map_err(|e| werr(&path, e.to_string()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsample_is_sorted_distinct_and_seeded() {
        let a = subsample(1000, 50, 3);
        assert_eq!(a.len(), 50);
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(a, subsample(1000, 50, 3));
        assert_ne!(a, subsample(1000, 50, 4));
        assert_eq!(subsample(10, 0, 1), (0..10).collect::<Vec<_>>());
    }

    /// Cascade correlation's fast path (issue 48, item 2) is timed where
    /// this CPU runs the relaxed kernel and nowhere else, and it answers
    /// what the deployed arithmetic answers, to f32's rounding; a learner
    /// without one gets no fast figure.
    #[test]
    fn the_fast_single_query_is_timed_where_the_relaxed_kernel_runs_and_agrees() {
        use crate::learn::cascor::{Cascor, CascorOptions};
        use crate::learn::learner::Split;
        let n = 300;
        let x = DMatrix::from_fn(n, 7, |r, c| ((r * 7 + c * 13) % 97) as f64 / 96.0);
        let y = DMatrix::from_fn(n, 4, |r, c| 0.5 + 0.4 * (x[(r, c)] - x[(r, c + 3)]) * 0.5);
        let mut cascor = Cascor::new(CascorOptions {
            max_hidden: 3,
            pool: 2,
            progress: false,
            ..CascorOptions::default()
        });
        let split = Split { x: &x, y: &y };
        cascor.fit(split, split, 1).unwrap();
        #[cfg(target_arch = "x86_64")]
        let relaxed = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
        #[cfg(not(target_arch = "x86_64"))]
        let relaxed = false;
        let t = time_inference(&cascor, &x, 20);
        assert_eq!(t.single_fast_us.is_some(), relaxed);
        match cascor.predict_fast(&x) {
            Some(fast) => {
                let deployed = cascor.predict(&x);
                let gap = (fast - &deployed).abs().max();
                assert!(gap < 1e-5, "the fast path is {gap:e} off the deployed one");
            }
            None => assert!(!relaxed),
        }
        let knn =
            crate::learn::knn::Knn::with_grid(vec![1], vec![crate::learn::knn::Weighting::Uniform]);
        assert_eq!(knn.predict_fast(&x), None);
    }
}
