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
//! - [`polish`]: every weight trained together after growth;
//! - `lbfgs`: the polish's curvature pairs and quasi-Newton direction;
//! - [`fine_tune`]: a trained net polished on other rows (measured ones);
//! - `batch`: the polish's loss and gradient over tiles of rows;
//! - [`tip_metric`]: what an output error costs at the tip, the polish's weights;
//! - (a whole `tendril train` run — split, train, write every output and the
//!   learning curve — is the job [`crate::jobs::train`]);
//! - [`export`]: the `.tnet` weight file (`docs/design.md` §5.1).

mod batch;
pub mod candidates;
mod data_robot;
mod error;
pub mod export;
pub mod fine_tune;
mod growth;
mod lbfgs;
pub mod net;
pub mod options;
mod outputs;
pub mod polish;
pub mod quickprop;
pub mod tip_metric;
pub mod train;
mod unit_log;

use nalgebra::DMatrix;

pub use candidates::Objective;
pub use data_robot::{robot_for_data, DataRobot};
pub use error::TrainError;
pub use net::{GrowingNet, OutputKind};
pub use options::{CascorOptions, ObjectiveChoice, OutputSolver};
pub use polish::{PolishLoss, PolishOptions, PolishReport};
pub use quickprop::QuickpropParams;
pub use train::{train, train_with_stop, Metrics, TrainReport, UnitLog};

use tendril_shared::POSE_DIM;

use crate::learn::{LearnError, Learner, Split};
use crate::net::{pose_rows, HostNet};

/// Cascade correlation as a [`Learner`]: `Cascor::new(CascorOptions::default())`.
///
/// `predict` runs the trained net the way it is deployed: exported to f32
/// (unit ranges, so normalised in → normalised out) and run by
/// [`HostNet`], the firmware's arithmetic laid out for the host. So the
/// comparison times and scores what `tendril ik` and the MCU run, not the
/// f64 training net (which it falls back to only if the export fails).
#[derive(Clone, Debug)]
pub struct Cascor {
    /// Hyper-parameters used by `fit`.
    pub options: CascorOptions,
    net: Option<GrowingNet>,
    report: Option<TrainReport>,
    fast: Option<HostNet>,
}

/// `net` as f32 with unit ranges (`(x − 0)/(1 − 0)` and `0 + y·(1 − 0)` are
/// exact), ready for [`HostNet`]; `None` if the format cannot hold it.
fn host_net(net: &GrowingNet) -> Option<HostNet> {
    let ranges = export::Ranges {
        input_lo: vec![0.0; net.n_inputs],
        input_hi: vec![1.0; net.n_inputs],
        output_lo: vec![0.0; net.n_outputs],
        output_hi: vec![1.0; net.n_outputs],
    };
    let bytes = export::to_bytes(net, &ranges).ok()?;
    crate::net::decode(&bytes).ok().map(|m| HostNet::new(&m))
}

impl Cascor {
    /// An untrained learner with these options.
    pub fn new(options: CascorOptions) -> Cascor {
        Cascor {
            options,
            net: None,
            report: None,
            fast: None,
        }
    }

    /// A learner holding a net trained elsewhere (by [`train::train`] with
    /// these options), e.g. to wrap in a [`crate::learn::learner::Prefitted`].
    pub fn from_trained(options: CascorOptions, net: GrowingNet, report: TrainReport) -> Cascor {
        Cascor {
            options,
            fast: host_net(&net),
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
        self.fast = host_net(&net);
        self.net = Some(net);
        self.report = Some(report);
        Ok(())
    }

    /// Predictions of the trained net through [`HostNet`] (f32, the
    /// firmware's arithmetic); an untrained learner predicts an `n × 0` matrix.
    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match (&self.fast, &self.net) {
            (Some(fast), _) if x.ncols() <= POSE_DIM => {
                let rows = pose_rows(x);
                let no = fast.outputs();
                let mut y = vec![0.0f32; rows.len() * no];
                fast.infer_rows(&rows, &mut y);
                DMatrix::from_fn(rows.len(), no, |r, c| f64::from(y[r * no + c]))
            }
            (_, Some(net)) => net.predict(x),
            (_, None) => DMatrix::zeros(x.nrows(), 0),
        }
    }

    /// Row by row through [`HostNet::infer_one_relaxed`], when this CPU
    /// runs its relaxed kernel (AVX2 and FMA).
    fn predict_fast(&self, x: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let fast = self.fast.as_ref().filter(|f| f.has_relaxed_kernel())?;
        if x.ncols() > POSE_DIM {
            return None;
        }
        let no = fast.outputs();
        let mut y = DMatrix::zeros(x.nrows(), no);
        let mut out = vec![0.0f32; no];
        for (r, pose) in pose_rows(x).iter().enumerate() {
            fast.infer_one_relaxed(pose, &mut out);
            for (c, v) in out.iter().enumerate() {
                y[(r, c)] = f64::from(*v);
            }
        }
        Some(y)
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
