//! Cascade-forward backpropagation network (MATLAB's `cascadeforwardnet`):
//! a feed-forward net in which every layer also sees the inputs and every
//! earlier layer, and the outputs see everything. Unlike cascade correlation
//! its architecture is fixed before training and all weights are trained
//! together, by the same mini-batch Adam as the MLP (`mlp.rs`).

use nalgebra::DMatrix;

use super::mlp::{describe_net, fit_best, Net, Training};
use super::{LearnError, Learner, Split};

/// Cascade-forward net regressor.
pub struct CascadeForward {
    /// Candidate hidden-layer configurations tried on the validation split.
    pub candidates: Vec<Vec<usize>>,
    /// Optimiser settings (the MLP's defaults, for a like-for-like comparison).
    pub training: Training,
    net: Option<Net>,
}

impl Default for CascadeForward {
    /// The same grid and training budget as [`super::mlp::Mlp`]'s default.
    fn default() -> Self {
        CascadeForward::with_grid(
            vec![vec![16], vec![32], vec![64], vec![32, 32]],
            Training::default(),
        )
    }
}

impl CascadeForward {
    /// A cascade-forward net choosing among hidden configurations by validation.
    pub fn with_grid(candidates: Vec<Vec<usize>>, training: Training) -> CascadeForward {
        CascadeForward {
            candidates,
            training,
            net: None,
        }
    }

    /// The trained network, if any.
    pub fn net(&self) -> Option<&Net> {
        self.net.as_ref()
    }
}

impl Learner for CascadeForward {
    fn name(&self) -> &str {
        "Cascade-forward net"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        let (net, score) = fit_best(&self.candidates, true, &self.training, train, valid, seed)?;
        log::debug!(
            "Cascade-forward: hidden={:?} (valid RMSE {score:.5})",
            net.hidden()
        );
        self.net = Some(net);
        Ok(())
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.net {
            Some(n) => n.predict(x),
            None => DMatrix::from_element(x.nrows(), 0, f64::NAN),
        }
    }

    fn parameter_count(&self) -> usize {
        self.net.as_ref().map_or(0, Net::parameter_count)
    }

    fn describe(&self) -> String {
        describe_net(self.net.as_ref(), &self.training)
    }
}
