//! Cascade-Correlation (Fahlman & Lebiere 1990) with Quickprop (Fahlman 1988),
//! plus the Cascade 2 error-minimising candidate objective (Prechelt 1997) and
//! an exact ridge solve for linear outputs (`docs/design.md` §4).
//!
//! - [`net`]: the trained network (f64) and its activations;
//! - [`quickprop`]: the optimiser and Fahlman's patience test;
//! - [`candidates`]: candidate objectives, gradients, the parallel pool;
//! - [`options`]: the hyper-parameters;
//! - `outputs`: cached features and the output solvers (ridge, Quickprop);
//! - `growth`: the candidate phase and installation of a unit;
//! - [`train`]: the grow-and-freeze loop, the choice of output configuration,
//!   stopping and progress;
//! - [`job`]: a whole `tendril train` run — split, train, write every output;
//! - [`export`]: the `.tnet` weight file (`docs/design.md` §5.1).

pub mod candidates;
mod data_robot;
pub mod export;
mod growth;
pub mod job;
pub mod net;
pub mod options;
mod outputs;
pub mod quickprop;
pub mod train;

use nalgebra::DMatrix;

pub use candidates::Objective;
pub use net::{GrowingNet, OutputKind};
pub use options::{CascorOptions, ObjectiveChoice, OutputSolver};
pub use quickprop::QuickpropParams;
pub use train::{train, train_with_stop, TrainReport, UnitLog};

use crate::learn::{LearnError, Learner, Split};

/// Cascade correlation as a [`Learner`]: `Cascor::new(CascorOptions::default())`.
#[derive(Clone, Debug)]
pub struct Cascor {
    /// Hyper-parameters used by `fit`.
    pub options: CascorOptions,
    net: Option<GrowingNet>,
    report: Option<TrainReport>,
}

impl Cascor {
    /// An untrained learner with these options.
    pub fn new(options: CascorOptions) -> Cascor {
        Cascor {
            options,
            net: None,
            report: None,
        }
    }

    /// A learner holding a net trained elsewhere (by [`train::train`] with
    /// these options), e.g. to wrap in a [`crate::learn::learner::Prefitted`].
    pub fn from_trained(options: CascorOptions, net: GrowingNet, report: TrainReport) -> Cascor {
        Cascor {
            options,
            net: Some(net),
            report: Some(report),
        }
    }

    /// The trained net, once `fit` has succeeded.
    pub fn net(&self) -> Option<&GrowingNet> {
        self.net.as_ref()
    }

    /// What the last `fit` did (learning curve, choices made).
    pub fn report(&self) -> Option<&TrainReport> {
        self.report.as_ref()
    }
}

impl Learner for Cascor {
    fn name(&self) -> &str {
        "Cascade correlation"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        let (net, report) = train::train(train.x, train.y, valid.x, valid.y, &self.options, seed)?;
        self.net = Some(net);
        self.report = Some(report);
        Ok(())
    }

    /// Predictions of the trained net; an untrained learner predicts an `n × 0` matrix.
    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.net {
            Some(net) => net.predict(x),
            None => DMatrix::zeros(x.nrows(), 0),
        }
    }

    fn parameter_count(&self) -> usize {
        self.net.as_ref().map_or(0, GrowingNet::parameter_count)
    }

    fn describe(&self) -> String {
        match &self.report {
            Some(r) => format!(
                "{} hidden units, {} outputs ({}), pool {}, objective wins cov/c2 {}/{}",
                r.best_hidden,
                r.output_kind,
                r.output_solver,
                self.options.pool,
                r.objective_wins.0,
                r.objective_wins.1
            ),
            None => "untrained".into(),
        }
    }
}
