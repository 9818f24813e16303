//! The trained cascade network in f64: inputs and a bias feed every hidden
//! unit and every output; hidden unit k also sees hidden units 0..k (the
//! cascade). Feature vector of a unit: `[1, x_0 … x_{I−1}, h_0 … h_{k−1}]`.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Activation of the output units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum OutputKind {
    /// Identity: the natural choice for continuous targets (Fahlman's default).
    Linear,
    /// Logistic sigmoid 1/(1+e^−x), range (0, 1), like the normalised targets.
    Sigmoid,
}

impl std::fmt::Display for OutputKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OutputKind::Linear => "linear",
            OutputKind::Sigmoid => "sigmoid",
        })
    }
}

/// Symmetric sigmoid of the hidden units, range (−0.5, 0.5) (Fahlman's cascor).
#[inline]
pub fn hidden_activation(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp()) - 0.5
}

/// Derivative of [`hidden_activation`] from its value `v`: 0.25 − v².
#[inline]
pub fn hidden_prime(v: f64) -> f64 {
    0.25 - v * v
}

/// Logistic sigmoid of sigmoid output units.
#[inline]
pub fn logistic(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// A cascade-correlation network as the trainer grows it (weights in f64,
/// inputs normalised to [0, 1]); exported, it becomes the firmware's
/// fixed-capacity [`tendril_shared::CascadeNet`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GrowingNet {
    /// Number of inputs.
    pub n_inputs: usize,
    /// Number of outputs.
    pub n_outputs: usize,
    /// Hidden unit k's incoming weights, `1 + n_inputs + k` long: bias, inputs, earlier hidden units.
    pub hidden: Vec<Vec<f64>>,
    /// Output o's incoming weights, `1 + n_inputs + hidden.len()` long.
    pub outputs: Vec<Vec<f64>>,
    /// Activation of the outputs.
    pub output_kind: OutputKind,
}

impl GrowingNet {
    /// Number of hidden units.
    pub fn n_hidden(&self) -> usize {
        self.hidden.len()
    }

    /// Number of weights.
    pub fn parameter_count(&self) -> usize {
        self.hidden.iter().map(Vec::len).sum::<usize>()
            + self.outputs.iter().map(Vec::len).sum::<usize>()
    }

    /// Outputs for one input vector; `features` is scratch of any length.
    pub fn forward_into(&self, x: &[f64], features: &mut Vec<f64>, out: &mut [f64]) {
        features.clear();
        features.push(1.0);
        features.extend_from_slice(x);
        for w in &self.hidden {
            let s: f64 = w.iter().zip(features.iter()).map(|(a, b)| a * b).sum();
            features.push(hidden_activation(s));
        }
        for (o, w) in self.outputs.iter().enumerate() {
            let s: f64 = w.iter().zip(features.iter()).map(|(a, b)| a * b).sum();
            out[o] = match self.output_kind {
                OutputKind::Linear => s,
                OutputKind::Sigmoid => logistic(s),
            };
        }
    }

    /// Outputs for a batch (`n × n_inputs` → `n × n_outputs`).
    pub fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let mut y = DMatrix::zeros(x.nrows(), self.n_outputs);
        let mut feats = Vec::with_capacity(1 + self.n_inputs + self.n_hidden());
        let mut xi = vec![0.0; self.n_inputs];
        let mut yo = vec![0.0; self.n_outputs];
        for r in 0..x.nrows() {
            for c in 0..self.n_inputs {
                xi[c] = x[(r, c)];
            }
            self.forward_into(&xi, &mut feats, &mut yo);
            for c in 0..self.n_outputs {
                y[(r, c)] = yo[c];
            }
        }
        y
    }

    /// Rewrite the weights so the net takes `x` where it took `a ⊙ x + b`
    /// (training works on centred inputs; the exported net takes [0, 1] inputs).
    pub fn fold_input_affine(&mut self, a: &[f64], b: &[f64]) {
        let n = self.n_inputs;
        let fold = |w: &mut Vec<f64>| {
            for i in 0..n {
                w[0] += w[1 + i] * b[i];
                w[1 + i] *= a[i];
            }
        };
        self.hidden.iter_mut().for_each(fold);
        self.outputs.iter_mut().for_each(fold);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_prime_matches_finite_difference() {
        for &x in &[-3.0, -0.5, 0.0, 0.7, 4.0] {
            let h = 1e-6;
            let fd = (hidden_activation(x + h) - hidden_activation(x - h)) / (2.0 * h);
            assert!((fd - hidden_prime(hidden_activation(x))).abs() < 1e-9);
        }
    }

    #[test]
    fn folding_an_affine_input_map_keeps_outputs() {
        let net = GrowingNet {
            n_inputs: 2,
            n_outputs: 1,
            hidden: vec![vec![0.1, 0.5, -0.3], vec![-0.2, 0.4, 0.9, 1.5]],
            outputs: vec![vec![0.3, -0.7, 0.2, 1.1, -0.6]],
            output_kind: OutputKind::Linear,
        };
        let (a, b) = ([2.0, 2.0], [-1.0, -1.0]);
        let mut folded = net.clone();
        folded.fold_input_affine(&a, &b);
        let x = DMatrix::from_row_slice(2, 2, &[0.2, 0.9, 0.6, 0.1]);
        let xs = x.map_with_location(|_, c, v| a[c] * v + b[c]);
        let d = (net.predict(&xs) - folded.predict(&x)).abs().max();
        assert!(d < 1e-12);
    }
}
