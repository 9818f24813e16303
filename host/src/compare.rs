//! The paper's comparison (Table II, Figure 3), done fairly: every learner is
//! trained on the same split with the same normalisation, tunes its
//! hyper-parameters on the same validation split (never the test split) with
//! a comparable budget, and is judged by the same metrics (`DESIGN.md` §4) —
//! tension RMSE and, what a user of the robot cares about, the task-space tip
//! error after pushing the predicted tensions through the Cosserat model.

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::DMatrix;

use crate::dataset::split::{SPLIT_SEED, TEST_FRACTION, VALID_FRACTION};
use crate::dataset::{prepare, Dataset, Prepared};
use crate::evaluate::{
    task_space_errors, tension_rmse, tension_rmse_normalised, EvalError, SplitMetrics,
};
use crate::learn::cascade_forward::CascadeForward;
use crate::learn::elm::Elm;
use crate::learn::knn::Knn;
use crate::learn::mlp::Mlp;
use crate::learn::rbf::Rbf;
use crate::learn::tree::RegressionTree;
use crate::learn::{LearnError, Learner, Split};
use crate::plot::compare::{draw_comparison, LearnerBars};
use crate::robot::Robot;
use crate::statics::{SolverSettings, Statics};

/// Name of the learner every baseline is measured against.
pub const REFERENCE: &str = "Cascade correlation";

/// Why the comparison failed.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The dataset does not fit the robot or is too small to split.
    #[error("{0}")]
    BadInput(String),
    /// A learner failed to fit.
    #[error("{name}: {source}")]
    Learn {
        /// The learner.
        name: String,
        /// Its error.
        source: LearnError,
    },
    /// A metric could not be computed.
    #[error("evaluating {name}: {source}")]
    Eval {
        /// The learner.
        name: String,
        /// Why.
        source: EvalError,
    },
    /// Writing an output failed.
    #[error("writing {path}: {why}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

/// Settings of one comparison run.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// Fraction of rows held out for testing (the paper's 3 %).
    pub test_fraction: f64,
    /// Fraction of the training rows carved off for validation (hyper-parameter choice).
    pub valid_fraction: f64,
    /// Seed of the split and of every learner.
    pub seed: u64,
    /// Training rows pushed through the statics for the train-split task-space
    /// error (a seeded subsample: the full split would cost one Cosserat solve
    /// per row per learner; 0 = all).
    pub train_task_rows: usize,
    /// Single queries timed for the inference time.
    pub timing_queries: usize,
    /// Show a progress bar over learners on stderr.
    pub progress: bool,
    /// Also write the normalised fit / valid / test splits as CSV into this
    /// directory (for the scikit-learn reference in `scripts/python/`).
    pub dump_splits: Option<PathBuf>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            test_fraction: TEST_FRACTION,
            valid_fraction: VALID_FRACTION,
            seed: SPLIT_SEED,
            train_task_rows: 1000,
            timing_queries: 300,
            progress: true,
            dump_splits: None,
        }
    }
}

/// One learner's row of the table.
#[derive(Clone, Debug)]
pub struct Entry {
    /// Learner name.
    pub name: String,
    /// Hyper-parameters chosen on the validation split.
    pub hyper: String,
    /// Stored numbers needed at inference.
    pub parameters: usize,
    /// Wall time of `fit` (tuning included), seconds.
    pub train_seconds: f64,
    /// Mean wall time of one single-row prediction, microseconds.
    pub infer_us: f64,
    /// Metrics on the training split (validation rows excluded); the
    /// task-space part on a seeded subsample of `train_task_rows` rows.
    pub train: SplitMetrics,
    /// Rows of the training split that went through the statics.
    pub train_task_rows: usize,
    /// Metrics on the held-out test split (task space on every row).
    pub test: SplitMetrics,
}

/// The whole comparison.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// Robot name.
    pub robot: String,
    /// Rows used for fitting, validation and testing.
    pub sizes: (usize, usize, usize),
    /// Options it ran with.
    pub options: CompareOptions,
    /// One entry per learner, in the order they ran.
    pub entries: Vec<Entry>,
}

/// The six baselines with the tuning grids used by `tendril compare`
/// (documented on each learner's `Default`).
pub fn baselines() -> Vec<Box<dyn Learner>> {
    vec![
        Box::new(Knn::default()),
        Box::new(Rbf::default()),
        Box::new(Mlp::default()),
        Box::new(Elm::default()),
        Box::new(RegressionTree::default()),
        Box::new(CascadeForward::default()),
    ]
}

/// Every learner of the comparison: cascade correlation first, then the baselines.
pub fn all_learners() -> Vec<Box<dyn Learner>> {
    let mut v: Vec<Box<dyn Learner>> = vec![Box::new(crate::learn::cascor::Cascor::new(
        crate::learn::cascor::CascorOptions::default(),
    ))];
    v.extend(baselines());
    v
}

/// Mean wall time of one single-row prediction over up to `count` test rows.
fn time_queries(l: &dyn Learner, x: &DMatrix<f64>, count: usize) -> f64 {
    let n = x.nrows().min(count.max(1));
    let rows: Vec<DMatrix<f64>> = (0..n).map(|i| x.rows(i, 1).into_owned()).collect();
    // Warm caches and lazily built state first.
    let _ = l.predict(&rows[0]);
    let t = Instant::now();
    let mut sink = 0.0;
    for r in &rows {
        sink += l.predict(r)[0];
    }
    let us = t.elapsed().as_secs_f64() * 1e6 / n as f64;
    std::hint::black_box(sink);
    us
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

/// The `DESIGN.md` §4 metrics of predicted tensions (newtons): tension RMSE
/// over every row, task-space error over the rows `task_idx`.
fn split_metrics(
    statics: &Statics,
    p: &Prepared,
    pred: &DMatrix<f64>,
    truth: &DMatrix<f64>,
    poses: &DMatrix<f64>,
    task_idx: &[usize],
    infer_us: f64,
) -> Result<SplitMetrics, EvalError> {
    let task = task_space_errors(
        statics,
        &pred.select_rows(task_idx),
        &poses.select_rows(task_idx),
    )?;
    Ok(SplitMetrics {
        samples: pred.nrows(),
        tension_rmse_norm100: tension_rmse_normalised(pred, truth, &p.y_range.lo, &p.y_range.hi)?,
        tension_rmse_newton: tension_rmse(pred, truth)?,
        position_mm: task.position_stats(),
        orientation_deg: task.orientation_stats(),
        failed_solves: task.failed,
        inference_ns_per_query: infer_us * 1e3,
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
    let p = prepare(data, opts.test_fraction, opts.valid_fraction, opts.seed);
    if let Some(dir) = &opts.dump_splits {
        dump_splits(&p, dir)?;
    }
    let statics = Statics::new(robot, SolverSettings::default());
    // Physical-unit truth of the fit split (validation rows excluded) and of the test split.
    let fit_poses = p.x_range.denormalise(&p.train_x);
    let fit_tensions = p.y_range.denormalise(&p.train_y);
    let task_idx = subsample(p.train_x.nrows(), opts.train_task_rows, opts.seed);
    let bar = if opts.progress {
        ProgressBar::new(learners.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} learners, {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix("compare");
    let mut entries = Vec::new();
    for l in learners.iter_mut() {
        let name = l.name().to_string();
        bar.set_message(format!("training {name}"));
        log::info!("compare: training {name}");
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
        let infer_us = time_queries(l.as_ref(), &p.test_x, opts.timing_queries);
        let eval_err = |source| CompareError::Eval {
            name: name.clone(),
            source,
        };
        let pred_fit = p.y_range.denormalise(&l.predict(&p.train_x));
        let train = split_metrics(
            &statics,
            &p,
            &pred_fit,
            &fit_tensions,
            &fit_poses,
            &task_idx,
            infer_us,
        )
        .map_err(eval_err)?;
        let pred_test = p.y_range.denormalise(&l.predict(&p.test_x));
        let all_test: Vec<usize> = (0..p.test.len()).collect();
        let test = split_metrics(
            &statics,
            &p,
            &pred_test,
            &p.test.tensions,
            &p.test.poses,
            &all_test,
            infer_us,
        )
        .map_err(eval_err)?;
        log::info!(
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
            infer_us,
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
    })
}

/// A metric column: header, how to read it from an entry, and whether
/// smaller is better (every column here is "smaller is better" except none).
struct Column {
    header: &'static str,
    csv: &'static str,
    get: fn(&Entry) -> f64,
    digits: usize,
}

fn columns() -> Vec<Column> {
    vec![
        Column {
            header: "RMSE×100 train",
            csv: "rmse_norm100_train",
            get: |e| e.train.tension_rmse_norm100,
            digits: 3,
        },
        Column {
            header: "RMSE×100 test",
            csv: "rmse_norm100_test",
            get: |e| e.test.tension_rmse_norm100,
            digits: 3,
        },
        Column {
            header: "RMSE N train",
            csv: "rmse_newton_train",
            get: |e| e.train.tension_rmse_newton,
            digits: 4,
        },
        Column {
            header: "RMSE N test",
            csv: "rmse_newton_test",
            get: |e| e.test.tension_rmse_newton,
            digits: 4,
        },
        Column {
            header: "tip mean mm (train)",
            csv: "tip_mean_mm_train",
            get: |e| e.train.position_mm.mean,
            digits: 3,
        },
        Column {
            header: "tip mean mm",
            csv: "tip_mean_mm_test",
            get: |e| e.test.position_mm.mean,
            digits: 3,
        },
        Column {
            header: "tip p95 mm",
            csv: "tip_p95_mm_test",
            get: |e| e.test.position_mm.p95,
            digits: 3,
        },
        Column {
            header: "tip max mm",
            csv: "tip_max_mm_test",
            get: |e| e.test.position_mm.max,
            digits: 3,
        },
        Column {
            header: "angle mean °",
            csv: "angle_mean_deg_test",
            get: |e| e.test.orientation_deg.mean,
            digits: 3,
        },
        Column {
            header: "solve failures",
            csv: "failed_solves_test",
            get: |e| e.test.failed_solves as f64,
            digits: 0,
        },
        Column {
            header: "train s",
            csv: "train_seconds",
            get: |e| e.train_seconds,
            digits: 2,
        },
        Column {
            header: "µs/query",
            csv: "infer_us_per_query",
            get: |e| e.infer_us,
            digits: 1,
        },
        Column {
            header: "parameters",
            csv: "parameters",
            get: |e| e.parameters as f64,
            digits: 0,
        },
    ]
}

impl Comparison {
    /// The reference learner's entry (cascade correlation), if it ran.
    pub fn reference(&self) -> Option<&Entry> {
        self.entries.iter().find(|e| e.name == REFERENCE)
    }

    /// For each baseline that is strictly better than cascade correlation on
    /// some column (at the precision the table shows), one sentence listing
    /// those columns with both values.
    pub fn beats(&self) -> Vec<String> {
        let Some(r) = self.reference() else {
            return Vec::new();
        };
        let cols = columns();
        let round = |v: f64, d: usize| (v * 10f64.powi(d as i32)).round();
        let mut v = Vec::new();
        for e in self.entries.iter().filter(|e| e.name != REFERENCE) {
            let wins: Vec<String> = cols
                .iter()
                .filter_map(|c| {
                    let (ev, rv) = ((c.get)(e), (c.get)(r));
                    let better = ev.is_finite()
                        && (!rv.is_finite() || round(ev, c.digits) < round(rv, c.digits));
                    better.then(|| {
                        format!("{} ({:.*} vs {:.*})", c.header, c.digits, ev, c.digits, rv)
                    })
                })
                .collect();
            if !wins.is_empty() {
                v.push(format!(
                    "{} beats {REFERENCE} on {}",
                    e.name,
                    wins.join(", ")
                ));
            }
        }
        v
    }

    /// Table II as Markdown, with the chosen hyper-parameters, the best value
    /// of each column in bold, and every metric where a baseline beats
    /// cascade correlation listed below.
    pub fn to_markdown(&self) -> String {
        let cols = columns();
        let (nf, nv, nt) = self.sizes;
        let o = &self.options;
        let mut s = format!(
            "# Learner comparison ({})\n\n\
             Same split and normalisation for every learner: {nf} training rows, {nv} validation rows \
             (hyper-parameters chosen on these only), {nt} test rows; seed {}. \
             Tension RMSE over all tendons (normalised units ×100 and newtons). Task-space error: \
             predicted tensions clamped to [0, τ_max] → Cosserat statics → tip, against the true tip; \
             test split in full, train split on a seeded subsample of {} rows. \
             Inference time: single-row queries, mean over {} test rows. Best value per column in bold. \
             KNN (distance-weighted) and a deep tree reproduce their training rows by construction, \
             so their train-split columns measure memorisation, not accuracy: judge on the test split.\n\n",
            self.robot,
            o.seed,
            self.entries.first().map_or(0, |e| e.train_task_rows),
            o.timing_queries.min(nt),
        );
        s.push_str("| learner |");
        for c in &cols {
            s.push_str(&format!(" {} |", c.header));
        }
        s.push_str(" hyper-parameters (chosen on validation) |\n|---|");
        for _ in &cols {
            s.push_str("---:|");
        }
        s.push_str("---|\n");
        let best: Vec<f64> = cols
            .iter()
            .map(|c| {
                self.entries
                    .iter()
                    .map(|e| (c.get)(e))
                    .filter(|v| v.is_finite())
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        for e in &self.entries {
            s.push_str(&format!("| {} |", e.name));
            for (c, b) in cols.iter().zip(&best) {
                let v = (c.get)(e);
                let txt = format!("{:.*}", c.digits, v);
                if v == *b && self.entries.len() > 1 {
                    s.push_str(&format!(" **{txt}** |"));
                } else {
                    s.push_str(&format!(" {txt} |"));
                }
            }
            s.push_str(&format!(" {} |\n", e.hyper.replace('|', "/")));
        }
        let beats = self.beats();
        if self.reference().is_some() {
            s.push_str(&format!("\n## Where a baseline beats {REFERENCE}\n\n"));
            if beats.is_empty() {
                s.push_str("Nowhere: cascade correlation is best or tied on every column.\n");
            } else {
                for b in beats {
                    s.push_str(&format!("- {b}\n"));
                }
            }
        } else {
            s.push_str(&format!("\n{REFERENCE} did not run in this comparison.\n"));
        }
        s
    }

    /// One CSV row per learner with every column of the table.
    pub fn to_csv(&self) -> String {
        let cols = columns();
        let mut s = String::from("learner");
        for c in &cols {
            s.push(',');
            s.push_str(c.csv);
        }
        s.push_str(",rows_train,rows_test,task_rows_train,task_rows_test,tip_p95_mm_train,tip_max_mm_train,angle_mean_deg_train,failed_solves_train,hyper_parameters\n");
        for e in &self.entries {
            s.push_str(&csv_field(&e.name));
            for c in &cols {
                s.push_str(&format!(",{}", (c.get)(e)));
            }
            s.push_str(&format!(
                ",{},{},{},{},{},{},{},{},{}\n",
                e.train.samples,
                e.test.samples,
                e.train_task_rows,
                e.test.samples,
                e.train.position_mm.p95,
                e.train.position_mm.max,
                e.train.orientation_deg.mean,
                e.train.failed_solves,
                csv_field(&e.hyper)
            ));
        }
        s
    }

    /// Bars for Figure 3.
    pub fn bars(&self) -> Vec<LearnerBars> {
        self.entries
            .iter()
            .map(|e| LearnerBars {
                name: e.name.clone(),
                train_rmse: e.train.tension_rmse_norm100,
                test_rmse: e.test.tension_rmse_norm100,
                tip_mean_mm: e.test.position_mm.mean,
                tip_p95_mm: e.test.position_mm.p95,
            })
            .collect()
    }

    /// Write `compare.md`, `compare.csv` and `compare.png` into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, CompareError> {
        let md = dir.join("compare.md");
        let csv = dir.join("compare.csv");
        let png = dir.join("compare.png");
        let werr = |path: &Path, why: String| CompareError::Write {
            path: path.to_path_buf(),
            why,
        };
        std::fs::create_dir_all(dir).map_err(|e| werr(dir, e.to_string()))?;
        crate::fsutil::write_atomic(&md, self.to_markdown().as_bytes())
            .map_err(|e| werr(&md, e.to_string()))?;
        crate::fsutil::write_atomic(&csv, self.to_csv().as_bytes())
            .map_err(|e| werr(&csv, e.to_string()))?;
        let title = format!(
            "{}: IK learners compared (test split: {} rows)",
            self.robot, self.sizes.2
        );
        draw_comparison(&self.bars(), &title, &png).map_err(|e| werr(&png, e.to_string()))?;
        Ok(vec![md, csv, png])
    }
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

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str, test_rmse: f64, tip: f64) -> Entry {
        let mut test = SplitMetrics {
            samples: 10,
            tension_rmse_norm100: test_rmse,
            tension_rmse_newton: test_rmse / 10.0,
            ..SplitMetrics::default()
        };
        test.position_mm.mean = tip;
        Entry {
            name: name.into(),
            hyper: "h=1".into(),
            parameters: 10,
            train_seconds: 1.0,
            infer_us: 1.0,
            train: test.clone(),
            train_task_rows: 10,
            test,
        }
    }

    fn table(entries: Vec<Entry>) -> Comparison {
        Comparison {
            robot: "r".into(),
            sizes: (80, 10, 10),
            options: CompareOptions::default(),
            entries,
        }
    }

    #[test]
    fn table_says_where_a_baseline_beats_cascade_correlation() {
        let c = table(vec![entry(REFERENCE, 0.5, 1.0), entry("ELM", 0.2, 2.0)]);
        let beats = c.beats();
        assert_eq!(beats.len(), 1, "{beats:?}");
        assert!(
            beats[0].starts_with("ELM beats Cascade correlation on"),
            "{beats:?}"
        );
        assert!(
            beats[0].contains("RMSE×100 test (0.200 vs 0.500)"),
            "{beats:?}"
        );
        assert!(!beats[0].contains("tip mean mm ("), "{beats:?}");
        let md = c.to_markdown();
        assert!(md.contains("## Where a baseline beats Cascade correlation"));
        assert!(md.contains("| ELM | **0.200** | **0.200** |"), "{md}");
    }

    #[test]
    fn table_says_when_no_baseline_beats_cascade_correlation() {
        let c = table(vec![entry(REFERENCE, 0.1, 0.1), entry("KNN", 0.2, 2.0)]);
        assert!(c.beats().is_empty());
        assert!(c.to_markdown().contains("Nowhere"));
    }

    #[test]
    fn csv_quotes_fields_with_commas() {
        let c = table(vec![entry("KNN", 0.2, 2.0)]);
        let mut e = c.entries[0].clone();
        e.hyper = "k=5, weights=distance".into();
        let c = table(vec![e]);
        assert!(c
            .to_csv()
            .lines()
            .nth(1)
            .unwrap()
            .ends_with(",\"k=5, weights=distance\""));
    }

    #[test]
    fn subsample_is_sorted_distinct_and_seeded() {
        let a = subsample(1000, 50, 3);
        assert_eq!(a.len(), 50);
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(a, subsample(1000, 50, 3));
        assert_ne!(a, subsample(1000, 50, 4));
        assert_eq!(subsample(10, 0, 1), (0..10).collect::<Vec<_>>());
    }
}
