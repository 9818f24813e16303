//! Multi-layer perceptron trained by backpropagation with mini-batch Adam
//! (Kingma & Ba 2015) — tanh hidden units, linear outputs, squared error.
//!
//! The dense network here also serves the cascade-forward net
//! (`cascade_forward.rs`): with `cascade = true` every layer sees the inputs
//! and all earlier layers, which in the activation buffer
//! `[x, h₀, h₁, …, ŷ]` is just a longer prefix as the layer's input.
//!
//! Training: Glorot-uniform initialisation, shuffled mini-batches, a cosine
//! learning-rate decay over a fixed number of epochs; the weights with the
//! lowest validation RMSE (checked every few epochs) are kept. The hidden
//! layer sizes are chosen on the validation split; candidates train in
//! parallel, each from its own seed, so the result does not depend on the
//! number of threads.

use nalgebra::DMatrix;
use rand::seq::SliceRandom;
use rand::Rng;
use rayon::prelude::*;

use super::linalg::{argmin, check_splits, rmse, rng, row_major, sub_seed};
use super::{LearnError, Learner, Split};

/// Where one layer reads and writes in the activation buffer, and its weights.
#[derive(Clone, Debug)]
struct LayerSpec {
    in_start: usize,
    in_len: usize,
    out_start: usize,
    out_len: usize,
    /// Offset of the `out_len × in_len` row-major weights, then `out_len` biases.
    w_off: usize,
}

/// A dense feed-forward network, plain or cascade-forward.
#[derive(Clone, Debug)]
pub struct Net {
    n_in: usize,
    n_out: usize,
    hidden: Vec<usize>,
    cascade: bool,
    layers: Vec<LayerSpec>,
    params: Vec<f64>,
}

impl Net {
    /// A Glorot-uniform initialised network. `cascade` wires every layer to
    /// the inputs and all earlier layers (outputs see everything).
    pub fn new(n_in: usize, hidden: &[usize], n_out: usize, cascade: bool, seed: u64) -> Net {
        let mut layers = Vec::new();
        let mut off = 0;
        let mut start = n_in;
        let mut prev = n_in;
        let sizes: Vec<usize> = hidden
            .iter()
            .copied()
            .chain(std::iter::once(n_out))
            .collect();
        for &len in &sizes {
            let (in_start, in_len) = if cascade {
                (0, start)
            } else {
                (start - prev, prev)
            };
            layers.push(LayerSpec {
                in_start,
                in_len,
                out_start: start,
                out_len: len,
                w_off: off,
            });
            off += len * (in_len + 1);
            start += len;
            prev = len;
        }
        let mut r = rng(seed);
        let mut params = vec![0.0; off];
        for l in &layers {
            let bound = (6.0 / (l.in_len + l.out_len) as f64).sqrt();
            for p in &mut params[l.w_off..l.w_off + l.out_len * (l.in_len + 1)] {
                *p = r.random_range(-bound..bound);
            }
        }
        Net {
            n_in,
            n_out,
            hidden: hidden.to_vec(),
            cascade,
            layers,
            params,
        }
    }

    fn act_len(&self) -> usize {
        self.n_in + self.hidden.iter().sum::<usize>() + self.n_out
    }

    /// Number of weights and biases.
    pub fn parameter_count(&self) -> usize {
        self.params.len()
    }

    /// Forward pass of one sample; `acts` must hold `x` in its first `n_in` slots.
    fn forward(&self, params: &[f64], acts: &mut [f64]) {
        let last = self.layers.len() - 1;
        for (li, l) in self.layers.iter().enumerate() {
            let (input, rest) = acts.split_at_mut(l.out_start);
            let input = &input[l.in_start..l.in_start + l.in_len];
            let w = &params[l.w_off..l.w_off + l.out_len * l.in_len];
            let b = &params[l.w_off + l.out_len * l.in_len..l.w_off + l.out_len * (l.in_len + 1)];
            for j in 0..l.out_len {
                let row = &w[j * l.in_len..(j + 1) * l.in_len];
                let z = b[j] + row.iter().zip(input).map(|(a, b)| a * b).sum::<f64>();
                rest[j] = if li == last { z } else { z.tanh() };
            }
        }
    }

    /// Add the gradient of ½|ŷ − y|²·`scale` for one forward-passed sample.
    fn backward(&self, acts: &[f64], y: &[f64], scale: f64, gacts: &mut [f64], grad: &mut [f64]) {
        gacts.iter_mut().for_each(|g| *g = 0.0);
        let last = self.layers.len() - 1;
        let out = self.layers[last].out_start;
        for (o, &t) in y.iter().enumerate() {
            gacts[out + o] = (acts[out + o] - t) * scale;
        }
        for (li, l) in self.layers.iter().enumerate().rev() {
            // Turn d/d(activation) into d/d(pre-activation) in place.
            if li != last {
                for j in 0..l.out_len {
                    let a = acts[l.out_start + j];
                    gacts[l.out_start + j] *= 1.0 - a * a;
                }
            }
            let input = &acts[l.in_start..l.in_start + l.in_len];
            let nw = l.out_len * l.in_len;
            let (gw, gb) = grad[l.w_off..l.w_off + nw + l.out_len].split_at_mut(nw);
            let w = &self.params[l.w_off..l.w_off + nw];
            // Inputs below n_in are the data: no gradient needed there.
            let skip = self.n_in.saturating_sub(l.in_start).min(l.in_len);
            for j in 0..l.out_len {
                let d = gacts[l.out_start + j];
                if d == 0.0 {
                    continue;
                }
                gb[j] += d;
                let gr = &mut gw[j * l.in_len..(j + 1) * l.in_len];
                for (g, a) in gr.iter_mut().zip(input) {
                    *g += d * a;
                }
                let wr = &w[j * l.in_len + skip..(j + 1) * l.in_len];
                let gin = &mut gacts[l.in_start + skip..l.in_start + l.in_len];
                for (g, wv) in gin.iter_mut().zip(wr) {
                    *g += d * wv;
                }
            }
        }
    }

    fn predict_with(&self, params: &[f64], x: &DMatrix<f64>) -> DMatrix<f64> {
        let n = x.nrows();
        let xr = row_major(x);
        let out0 = self.layers[self.layers.len() - 1].out_start;
        let rows: Vec<Vec<f64>> = xr
            .par_chunks(self.n_in.max(1))
            .map(|xi| {
                let mut acts = vec![0.0; self.act_len()];
                acts[..self.n_in].copy_from_slice(xi);
                self.forward(params, &mut acts);
                acts[out0..out0 + self.n_out].to_vec()
            })
            .collect();
        DMatrix::from_fn(n, self.n_out, |i, j| rows[i][j])
    }

    /// Network outputs for every row of `x`.
    pub fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        if x.ncols() != self.n_in {
            return DMatrix::from_element(x.nrows(), self.n_out, f64::NAN);
        }
        self.predict_with(&self.params, x)
    }

    /// Hidden sizes, e.g. `[32]` or `[16, 16]`.
    pub fn hidden(&self) -> &[usize] {
        &self.hidden
    }

    /// Whether the net is cascade-forward.
    pub fn is_cascade(&self) -> bool {
        self.cascade
    }
}

/// Mini-batch Adam settings shared by the MLP and the cascade-forward net.
#[derive(Clone, Debug)]
pub struct Training {
    /// Passes over the training split.
    pub epochs: usize,
    /// Samples per Adam step.
    pub batch: usize,
    /// Initial Adam step size.
    pub lr: f64,
    /// Final step size as a fraction of `lr` (cosine decay in between).
    pub lr_final_fraction: f64,
    /// Validation RMSE is checked (and the best weights kept) every this many epochs.
    pub eval_every: usize,
}

impl Default for Training {
    fn default() -> Self {
        Training {
            epochs: 150,
            batch: 32,
            lr: 3e-3,
            lr_final_fraction: 0.01,
            eval_every: 5,
        }
    }
}

impl Training {
    /// Step size for `epoch` (0-based) of a cosine decay from `lr` to `lr·lr_final_fraction`.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        let lo = self.lr * self.lr_final_fraction;
        let t = epoch as f64 / self.epochs.max(1) as f64;
        lo + 0.5 * (self.lr - lo) * (1.0 + (std::f64::consts::PI * t).cos())
    }

    fn check(&self) -> Result<(), LearnError> {
        if self.epochs == 0 || self.batch == 0 || self.eval_every == 0 {
            return Err(LearnError::BadParameter {
                name: "training",
                why: "epochs, batch and eval_every must be ≥ 1".into(),
            });
        }
        if !(self.lr.is_finite() && self.lr > 0.0 && (0.0..=1.0).contains(&self.lr_final_fraction))
        {
            return Err(LearnError::BadParameter {
                name: "learning rate",
                why: "need lr > 0 and a final fraction in [0, 1]".into(),
            });
        }
        Ok(())
    }
}

/// Train `net` by mini-batch Adam; returns the validation RMSE of the kept weights.
pub fn train(net: &mut Net, train: Split<'_>, valid: Split<'_>, cfg: &Training, seed: u64) -> f64 {
    let n = train.len();
    let xr = row_major(train.x);
    let yr = row_major(train.y);
    let (ni, no) = (net.n_in, net.n_out);
    let np = net.params.len();
    let (b1, b2, eps) = (0.9, 0.999, 1e-8);
    let mut m = vec![0.0; np];
    let mut v = vec![0.0; np];
    let mut grad = vec![0.0; np];
    let mut acts = vec![0.0; net.act_len()];
    let mut gacts = vec![0.0; net.act_len()];
    let mut order: Vec<usize> = (0..n).collect();
    let mut r = rng(seed);
    let mut t = 0i32;
    let mut best = (rmse(&net.predict(valid.x), valid.y), net.params.clone());
    for epoch in 0..cfg.epochs {
        order.shuffle(&mut r);
        let lr = cfg.lr_at(epoch);
        for batch in order.chunks(cfg.batch) {
            grad.iter_mut().for_each(|g| *g = 0.0);
            let scale = 1.0 / batch.len() as f64;
            for &i in batch {
                acts[..ni].copy_from_slice(&xr[i * ni..(i + 1) * ni]);
                net.forward(&net.params, &mut acts);
                net.backward(
                    &acts,
                    &yr[i * no..(i + 1) * no],
                    scale,
                    &mut gacts,
                    &mut grad,
                );
            }
            t += 1;
            let step = lr * (1.0 - f64::powi(b2, t)).sqrt() / (1.0 - f64::powi(b1, t));
            for k in 0..np {
                m[k] = b1 * m[k] + (1.0 - b1) * grad[k];
                v[k] = b2 * v[k] + (1.0 - b2) * grad[k] * grad[k];
                net.params[k] -= step * m[k] / (v[k].sqrt() + eps);
            }
        }
        if (epoch + 1) % cfg.eval_every == 0 || epoch + 1 == cfg.epochs {
            let s = rmse(&net.predict(valid.x), valid.y);
            if s < best.0 {
                best = (s, net.params.clone());
            }
        }
    }
    net.params = best.1;
    best.0
}

/// Fit one net per candidate hidden configuration (in parallel) and keep the
/// best on validation.
pub(crate) fn fit_best(
    candidates: &[Vec<usize>],
    cascade: bool,
    cfg: &Training,
    train_s: Split<'_>,
    valid: Split<'_>,
    seed: u64,
) -> Result<(Net, f64), LearnError> {
    check_splits(train_s, valid)?;
    cfg.check()?;
    if candidates.is_empty() || candidates.iter().any(|c| c.contains(&0)) {
        return Err(LearnError::BadParameter {
            name: "hidden sizes",
            why: "need at least one candidate and no zero-width layer".into(),
        });
    }
    let (ni, no) = (train_s.x.ncols(), train_s.y.ncols());
    let nets: Vec<(Net, f64)> = candidates
        .par_iter()
        .enumerate()
        .map(|(i, h)| {
            let s = sub_seed(seed, i as u64);
            let mut net = Net::new(ni, h, no, cascade, s);
            let score = train(&mut net, train_s, valid, cfg, s.wrapping_add(1));
            (net, score)
        })
        .collect();
    let scores: Vec<f64> = nets.iter().map(|n| n.1).collect();
    let best = argmin(&scores)
        .ok_or_else(|| LearnError::Numerical("training diverged for every candidate".into()))?;
    nets.into_iter()
        .nth(best)
        .ok_or_else(|| LearnError::Numerical("lost the best net".into()))
}

fn hidden_label(h: &[usize]) -> String {
    h.iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join("-")
}

/// Describe a trained net's shape and training for the comparison table.
pub(crate) fn describe_net(net: Option<&Net>, cfg: &Training) -> String {
    match net {
        Some(n) => format!(
            "hidden={}, Adam lr={:e} cosine, batch={}, epochs={}",
            hidden_label(n.hidden()),
            cfg.lr,
            cfg.batch,
            cfg.epochs
        ),
        None => "untrained".into(),
    }
}

/// MLP regressor (tanh hidden layers, linear outputs) trained by mini-batch Adam.
pub struct Mlp {
    /// Candidate hidden-layer configurations tried on the validation split.
    pub candidates: Vec<Vec<usize>>,
    /// Optimiser settings.
    pub training: Training,
    net: Option<Net>,
}

impl Default for Mlp {
    /// The grid used by `tendril compare`: one hidden layer of 16, 32 or 64 tanh units, or two of 32.
    fn default() -> Self {
        Mlp::with_grid(
            vec![vec![16], vec![32], vec![64], vec![32, 32]],
            Training::default(),
        )
    }
}

impl Mlp {
    /// An MLP choosing among hidden configurations by validation.
    pub fn with_grid(candidates: Vec<Vec<usize>>, training: Training) -> Mlp {
        Mlp {
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

impl Learner for Mlp {
    fn name(&self) -> &str {
        "MLP"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        let (net, score) = fit_best(&self.candidates, false, &self.training, train, valid, seed)?;
        log::debug!(
            "MLP: hidden={} (valid RMSE {score:.5})",
            hidden_label(net.hidden())
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Loss ½Σ(ŷ−y)² for one sample, for finite differences.
    fn loss(net: &Net, params: &[f64], x: &[f64], y: &[f64]) -> f64 {
        let mut acts = vec![0.0; net.act_len()];
        acts[..net.n_in].copy_from_slice(x);
        net.forward(params, &mut acts);
        let out = net.layers[net.layers.len() - 1].out_start;
        y.iter()
            .enumerate()
            .map(|(o, t)| 0.5 * (acts[out + o] - t).powi(2))
            .sum()
    }

    fn check_gradient(cascade: bool) {
        let net = Net::new(3, &[4, 3], 2, cascade, 7);
        let x = [0.3, -0.2, 0.9];
        let y = [0.5, -0.1];
        let mut acts = vec![0.0; net.act_len()];
        acts[..3].copy_from_slice(&x);
        net.forward(&net.params, &mut acts);
        let mut g = vec![0.0; net.params.len()];
        let mut ga = vec![0.0; net.act_len()];
        net.backward(&acts, &y, 1.0, &mut ga, &mut g);
        for k in 0..net.params.len() {
            let mut p = net.params.clone();
            let h = 1e-6;
            p[k] += h;
            let up = loss(&net, &p, &x, &y);
            p[k] -= 2.0 * h;
            let down = loss(&net, &p, &x, &y);
            let fd = (up - down) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-7,
                "param {k}: fd {fd} vs backprop {}",
                g[k]
            );
        }
    }

    #[test]
    fn backprop_matches_finite_differences_plain() {
        check_gradient(false);
    }

    #[test]
    fn backprop_matches_finite_differences_cascade() {
        check_gradient(true);
    }

    #[test]
    fn cascade_wiring_counts_every_connection() {
        // Plain 3-4-3-2: 4·4 + 3·5 + 2·4 = 39. Cascade: 4·4 + 3·8 + 2·11 = 62.
        assert_eq!(Net::new(3, &[4, 3], 2, false, 0).parameter_count(), 39);
        assert_eq!(Net::new(3, &[4, 3], 2, true, 0).parameter_count(), 62);
    }
}
