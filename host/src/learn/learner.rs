//! The one interface every learner implements.

use nalgebra::DMatrix;

/// A view of normalised data: one row per sample.
#[derive(Clone, Copy, Debug)]
pub struct Split<'a> {
    /// Inputs, `n × inputs`, each column in [0, 1] on the training split.
    pub x: &'a DMatrix<f64>,
    /// Targets, `n × outputs`, each column in [0, 1] on the training split.
    pub y: &'a DMatrix<f64>,
}

impl Split<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.x.nrows()
    }

    /// Whether the split holds no sample.
    pub fn is_empty(&self) -> bool {
        self.x.nrows() == 0
    }
}

/// Why fitting a learner failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// The data cannot be learnt from (empty, mismatched shapes, non-finite values).
    #[error("bad training data: {0}")]
    BadData(String),
    /// A hyper-parameter is out of its valid range.
    #[error("bad hyper-parameter {name}: {why}")]
    BadParameter {
        /// The option's name.
        name: &'static str,
        /// What is wrong with it.
        why: String,
    },
    /// A numerical step failed (singular system, divergence).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// Training was stopped (Ctrl-C) before it finished; nothing was produced.
    #[error("interrupted")]
    Interrupted,
}

/// A regression learner trained on normalised data.
///
/// `fit` may tune its own hyper-parameters, but only on `valid` — a split
/// carved from the training data, never the test split.
pub trait Learner: Send {
    /// Short display name for tables and plots ("KNN", "Cascade correlation", …).
    fn name(&self) -> &str;

    /// Fit on `train`, choosing hyper-parameters on `valid`. Deterministic for a `seed`.
    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError>;

    /// Predict normalised outputs for normalised inputs (`n × inputs` → `n × outputs`).
    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64>;

    /// One row's prediction by a faster path that gives up the deployed
    /// arithmetic (cascade correlation's relaxed kernel: fused
    /// multiply-adds, not bit-identical to the firmware, docs/design.md
    /// §5.1), for the comparison's timing; `None`: the learner has no such
    /// path (its `predict` is already its fastest).
    fn predict_fast(&self, _x: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        None
    }

    /// Number of stored numbers the model needs at inference (weights, centres, tree nodes…).
    fn parameter_count(&self) -> usize;

    /// The hyper-parameters chosen by `fit`, for the comparison table.
    fn describe(&self) -> String;

    /// Wall time of the last fit (s), when the learner knows it better than
    /// a clock around `fit` (a [`Prefitted`] learner); `None`: time the call.
    fn fit_seconds(&self) -> Option<f64> {
        None
    }
}

/// Cheap fingerprint of a (train, valid) split: row counts and sums.
/// Enough to tell the split a model was fitted on from another one.
fn split_fingerprint(train: &Split<'_>, valid: &Split<'_>) -> [f64; 6] {
    [
        train.x.nrows() as f64,
        valid.x.nrows() as f64,
        train.x.sum(),
        train.y.sum(),
        valid.x.sum(),
        valid.y.sum(),
    ]
}

/// A learner already fitted on a known split, handed to a comparison so it
/// is not trained twice (the main job trains cascade correlation once, for
/// the weight file). `fit` on that same split keeps the model and reports
/// the original training time; on any other split it trains afresh.
pub struct Prefitted<L> {
    inner: L,
    fingerprint: [f64; 6],
    seconds: Option<f64>,
}

impl<L: Learner> Prefitted<L> {
    /// `inner`, fitted on (`train`, `valid`) in `seconds` of wall time.
    pub fn new(inner: L, train: Split<'_>, valid: Split<'_>, seconds: f64) -> Prefitted<L> {
        Prefitted {
            inner,
            fingerprint: split_fingerprint(&train, &valid),
            seconds: Some(seconds),
        }
    }
}

impl<L: Learner> Learner for Prefitted<L> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        if self.seconds.is_some() && split_fingerprint(&train, &valid) == self.fingerprint {
            return Ok(());
        }
        self.seconds = None;
        self.inner.fit(train, valid, seed)
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        self.inner.predict(x)
    }

    // The comparison times the inner learner's fast path too: without this
    // the main job's prefitted cascade net reported none ("n/a").
    fn predict_fast(&self, x: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        self.inner.predict_fast(x)
    }

    fn parameter_count(&self) -> usize {
        self.inner.parameter_count()
    }

    fn describe(&self) -> String {
        match self.seconds {
            Some(_) => format!(
                "{}; trained once before the comparison on this split (time of that run)",
                self.inner.describe()
            ),
            None => self.inner.describe(),
        }
    }

    fn fit_seconds(&self) -> Option<f64> {
        self.seconds
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts its fits; predicts the fit count, and by its fast path the
    /// count negated.
    struct Counter(usize);

    impl Learner for Counter {
        fn name(&self) -> &str {
            "counter"
        }
        fn fit(&mut self, _: Split<'_>, _: Split<'_>, _: u64) -> Result<(), LearnError> {
            self.0 += 1;
            Ok(())
        }
        fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
            DMatrix::from_element(x.nrows(), 1, self.0 as f64)
        }
        fn predict_fast(&self, x: &DMatrix<f64>) -> Option<DMatrix<f64>> {
            Some(-self.predict(x))
        }
        fn parameter_count(&self) -> usize {
            0
        }
        fn describe(&self) -> String {
            String::new()
        }
    }

    #[test]
    fn prefitted_keeps_its_model_on_its_split_and_retrains_on_another() {
        let x = DMatrix::from_fn(6, 2, |i, j| (i * 2 + j) as f64);
        let y = DMatrix::from_fn(6, 1, |i, _| i as f64);
        let (xv, yv) = (x.rows(0, 2).into_owned(), y.rows(0, 2).into_owned());
        let s = |x, y| Split { x, y };
        let mut p = Prefitted::new(Counter(1), s(&x, &y), s(&xv, &yv), 2.5);
        p.fit(s(&x, &y), s(&xv, &yv), 0).unwrap();
        assert_eq!(p.predict(&x)[0], 1.0, "refitted on its own split");
        let fast = p.predict_fast(&x).expect("the inner learner's fast path");
        assert_eq!(fast[0], -1.0);
        assert_eq!(p.fit_seconds(), Some(2.5));
        // Another split (one value changed): train afresh, time the call.
        let mut y2 = y.clone();
        y2[3] += 1.0;
        p.fit(s(&x, &y2), s(&xv, &yv), 0).unwrap();
        assert_eq!(p.predict(&x)[0], 2.0);
        assert_eq!(p.fit_seconds(), None);
    }
}
