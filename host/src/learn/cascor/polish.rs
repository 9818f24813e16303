//! The polish phase (`docs/design.md` §4, "Polish"): after cascade correlation has
//! grown and frozen its units, every weight — hidden and output — is
//! trained together by full-batch L-BFGS on the training rows' error —
//! squared, weighted per row by the tip metric, optionally robust — keeping
//! the weights with the lowest validation error.
//!
//! Why: cascade correlation trains each unit once, against the residual of
//! the units before it, and never moves it again; on a capacity-bound net
//! (the two-segment robot) the frozen units are a greedy basis, and moving
//! them all together buys what many more units would. The net keeps its
//! shape, so the firmware runs it unchanged.
//!
//! Written by hand because the gradient is the cascade's own backpropagation
//! (each unit feeds every later one) and L-BFGS is forty lines; the crates
//! that offer it (`argmin`) would bring a framework for one loop. The
//! gradient is summed over fixed row blocks in a fixed order, so the result
//! does not depend on the number of rayon threads.

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::batch::{self, sum_blocks, Batch};
use super::lbfgs::{dot, Memory};
use super::net::{hidden_prime, GrowingNet, OutputKind};

/// What the polish minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PolishLoss {
    /// The squared tip displacement the output error causes
    /// (`super::tip_metric`; needs the robot; without one, `Plain`).
    Tip,
    /// The squared output error, as the growth phases.
    Plain,
}

/// Curvature pairs the polish's L-BFGS keeps. A 7-64-6 net has ≈ 3,000
/// weights whose curvatures span orders of magnitude even after the
/// Gauss–Newton diagonal; a short memory forgets the directions it has
/// learned. On the two-segment robot (1,500 steps from the same grown net,
/// validation RMSE ×100): 12 pairs 0.0197, 40 0.0177, 100 0.0162, 250
/// 0.0152, 600 0.0142, 1,200 0.0139; 600 pairs cost ≈ 2 ms a step on top
/// of the ≈ 21 ms loss and gradient (`super::lbfgs`).
pub const POLISH_MEMORY: usize = 600;

/// Settings of the polish phase.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolishOptions {
    /// L-BFGS iterations at most (0: no polish).
    pub max_iterations: usize,
    /// What it minimises.
    pub loss: PolishLoss,
    /// Robust loss: δ = this × the median row error at the start (0:
    /// squared loss). See [`Rows::delta`].
    #[serde(default)]
    pub robust: f64,
    /// Stop after this many iterations without a new best validation RMSE.
    pub patience: usize,
    /// Curvature pairs kept by L-BFGS.
    pub memory: usize,
}

impl Default for PolishOptions {
    fn default() -> Self {
        PolishOptions {
            max_iterations: 0,
            loss: PolishLoss::Tip,
            robust: 0.0,
            patience: 200,
            memory: POLISH_MEMORY,
        }
    }
}

impl PolishOptions {
    /// Refuse what no polish can run with: a memory of no pairs, a robust
    /// scale that is not a finite number ≥ 0.
    pub fn check(&self) -> Result<(), crate::learn::LearnError> {
        let bad = |name, why: &str| {
            Err(crate::learn::LearnError::BadParameter {
                name,
                why: why.into(),
            })
        };
        if self.memory == 0 {
            return bad("polish memory", "must be at least 1 curvature pair");
        }
        if !(self.robust.is_finite() && self.robust >= 0.0) {
            return bad("polish robust scale", "must be a finite number ≥ 0");
        }
        Ok(())
    }
}

/// What the polish did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolishReport {
    /// Iterations run.
    pub iterations: usize,
    /// Training RMSE before and after (normalised outputs, in the metric's units).
    pub train_rmse: (f64, f64),
    /// Validation RMSE before and after (as `train_rmse`); "after" is the kept weights'.
    pub valid_rmse: (f64, f64),
    /// Iteration of the kept weights (0: the unpolished net was best).
    pub best_iteration: usize,
    /// δ of the robust loss, when there was one (the RMSEs above are then its counterparts).
    #[serde(default)]
    pub delta: Option<f64>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Each row's error r = √(eᵀ M_r e) under `net`.
pub fn row_errors(net: &GrowingNet, rows: Rows<'_>) -> Vec<f64> {
    let mut scratch = Scratch::new(net);
    (0..rows.x.nrows())
        .map(|r| scratch.row_error(net, rows, r))
        .collect()
}

/// δ of the robust loss: `scale` × the median row error of `net` on `rows`.
pub fn robust_delta(net: &GrowingNet, rows: Rows<'_>, scale: f64) -> Option<f64> {
    let mut r = row_errors(net, rows);
    if r.is_empty() || scale.is_nan() || scale <= 0.0 {
        return None;
    }
    r.sort_by(f64::total_cmp);
    let median = r[r.len() / 2];
    (median > 0.0 && median.is_finite()).then_some(scale * median)
}

/// A per-row metric on the output error: row r's loss is ½ eᵀ M_r e, with
/// M_r symmetric positive semi-definite (`O × O`). The tip metric
/// (`super::tip_metric`) makes it the squared tip displacement the error
/// causes; without one, every row's M is the identity (plain squared error).
#[derive(Clone, Debug, PartialEq)]
pub struct RowMetrics {
    /// Outputs O.
    pub outputs: usize,
    /// Row r's M at `r·O² ..`, row-major.
    pub m: Vec<f64>,
}

impl RowMetrics {
    /// Rows held.
    pub fn rows(&self) -> usize {
        self.m.len() / (self.outputs * self.outputs).max(1)
    }

    /// M_r e.
    fn apply(&self, r: usize, e: &[f64], out: &mut [f64]) {
        let o = self.outputs;
        let m = &self.m[r * o * o..(r + 1) * o * o];
        for (i, oi) in out.iter_mut().enumerate() {
            *oi = dot(&m[i * o..(i + 1) * o], e);
        }
    }
}

/// Rows the polish fits or judges: inputs as the net takes them, targets,
/// and an optional per-row metric.
#[derive(Clone, Copy, Debug)]
pub struct Rows<'a> {
    /// Inputs, `n × I`.
    pub x: &'a DMatrix<f64>,
    /// Targets, `n × O`.
    pub y: &'a DMatrix<f64>,
    /// Per-row metric (`None`: plain squared error).
    pub metric: Option<&'a RowMetrics>,
    /// Robust loss: row r costs δ²(√(1 + r²/δ²) − 1) with r² = eᵀ M_r e
    /// (pseudo-Huber: r²/2 for r ≪ δ, growing like δ·r past it) instead
    /// of r²/2. `None`: squared.
    pub delta: Option<f64>,
}

impl<'a> Rows<'a> {
    /// Rows with the plain squared error: no metric, no robust loss.
    pub fn plain(x: &'a DMatrix<f64>, y: &'a DMatrix<f64>) -> Self {
        Rows {
            x,
            y,
            metric: None,
            delta: None,
        }
    }

    /// √(Σ_r eᵀ M_r e / (n·O)) of `net`: the RMSE in the metric's units
    /// (with `delta`, √(2 Σ_r loss_r / (n·O)), its robust counterpart).
    pub fn rmse(&self, net: &GrowingNet) -> f64 {
        if self.y.is_empty() {
            return 0.0;
        }
        let (loss, _) = loss_and_gradient(net, *self, false);
        (2.0 * loss / self.y.len() as f64).sqrt()
    }
}

/// The net's weights as one vector: hidden rows, then output rows.
pub fn flatten(net: &GrowingNet) -> Vec<f64> {
    net.hidden
        .iter()
        .chain(net.outputs.iter())
        .flat_map(|r| r.iter().copied())
        .collect()
}

/// Write `theta` (laid out as [`flatten`]'s) back into `net`.
pub fn unflatten(net: &mut GrowingNet, theta: &[f64]) {
    let mut at = 0;
    for row in net.hidden.iter_mut().chain(net.outputs.iter_mut()) {
        let n = row.len();
        row.copy_from_slice(&theta[at..at + n]);
        at += n;
    }
}

/// Half the summed (metric-weighted) squared error of `net` over `rows`,
/// and, when `with_gradient`, its gradient with respect to [`flatten`]'s
/// vector (else an empty vector). Computed over tiles of rows
/// (`super::batch`); [`loss_and_gradient_per_row`] is its reference.
pub fn loss_and_gradient(net: &GrowingNet, rows: Rows<'_>, with_gradient: bool) -> (f64, Vec<f64>) {
    let batch = Batch {
        x: rows.x,
        y: rows.y,
        metric: rows.metric.map(|m| &m.m[..]),
        delta: rows.delta,
    };
    batch::loss_and_gradient(net, batch, with_gradient)
}

/// [`loss_and_gradient`] one row at a time through the net's own forward
/// pass: the reference the batched kernel is tested and benchmarked against.
pub fn loss_and_gradient_per_row(
    net: &GrowingNet,
    rows: Rows<'_>,
    with_gradient: bool,
) -> (f64, Vec<f64>) {
    let p = if with_gradient {
        net.parameter_count()
    } else {
        0
    };
    sum_blocks(rows.x.nrows(), p, |block| {
        let mut grad = vec![0.0; p];
        let mut loss = 0.0;
        let mut scratch = Scratch::new(net);
        for r in block {
            loss += scratch.accumulate(net, rows, r, &mut grad);
        }
        (loss, grad)
    })
}

/// Per-row buffers of the backward pass.
struct Scratch {
    x: Vec<f64>,
    z: Vec<f64>,
    dz: Vec<f64>,
    out: Vec<f64>,
    e: Vec<f64>,
    me: Vec<f64>,
}

impl Scratch {
    fn new(net: &GrowingNet) -> Scratch {
        let m = 1 + net.n_inputs + net.n_hidden();
        Scratch {
            x: vec![0.0; net.n_inputs],
            z: Vec::with_capacity(m),
            dz: vec![0.0; m],
            out: vec![0.0; net.n_outputs],
            e: vec![0.0; net.n_outputs],
            me: vec![0.0; net.n_outputs],
        }
    }

    /// Row `r` through `net`: features into `z`, outputs into `out`.
    fn forward(&mut self, net: &GrowingNet, rows: Rows<'_>, r: usize) {
        for (c, xc) in self.x.iter_mut().enumerate() {
            *xc = rows.x[(r, c)];
        }
        net.forward_into(&self.x, &mut self.z, &mut self.out);
    }

    /// Add row `r`'s gradient to `grad` (when it is not empty); return its loss.
    fn accumulate(&mut self, net: &GrowingNet, rows: Rows<'_>, r: usize, grad: &mut [f64]) -> f64 {
        self.forward(net, rows, r);
        for o in 0..net.n_outputs {
            self.e[o] = self.out[o] - rows.y[(r, o)];
        }
        match rows.metric {
            Some(m) => m.apply(r, &self.e, &mut self.me),
            None => self.me.copy_from_slice(&self.e),
        }
        let r2 = dot(&self.e, &self.me);
        let loss = match rows.delta {
            Some(delta) => {
                let root = (1.0 + r2 / (delta * delta)).sqrt();
                // ∂loss/∂e = M e / √(1 + r²/δ²).
                self.me.iter_mut().for_each(|v| *v /= root);
                delta * delta * (root - 1.0)
            }
            None => 0.5 * r2,
        };
        if grad.is_empty() {
            return loss;
        }
        self.backward(net, grad);
        loss
    }

    /// Row `r`'s tip error r = √(eᵀ M_r e).
    fn row_error(&mut self, net: &GrowingNet, rows: Rows<'_>, r: usize) -> f64 {
        let plain = Rows {
            delta: None,
            ..rows
        };
        (2.0 * self.accumulate(net, plain, r, &mut [])).sqrt()
    }

    /// ∂out_k/∂θ of row `r` into `grad`.
    fn output_gradient(
        &mut self,
        net: &GrowingNet,
        rows: Rows<'_>,
        r: usize,
        k: usize,
        grad: &mut [f64],
    ) {
        self.forward(net, rows, r);
        self.me.iter_mut().for_each(|v| *v = 0.0);
        self.me[k] = 1.0;
        self.backward(net, grad);
    }

    /// Backpropagate `me` (∂L/∂out) through the forward pass in `z`, `out`.
    fn backward(&mut self, net: &GrowingNet, grad: &mut [f64]) {
        let base = 1 + net.n_inputs;
        let hidden_len: usize = net.hidden.iter().map(Vec::len).sum();
        self.dz.iter_mut().for_each(|v| *v = 0.0);
        let mut at = hidden_len;
        for (o, w) in net.outputs.iter().enumerate() {
            // dL/ds for the output's weighted sum.
            let d = match net.output_kind {
                OutputKind::Linear => self.me[o],
                OutputKind::Sigmoid => self.me[o] * self.out[o] * (1.0 - self.out[o]),
            };
            for (j, wj) in w.iter().enumerate() {
                grad[at + j] += d * self.z[j];
                self.dz[j] += d * wj;
            }
            at += w.len();
        }
        // Hidden units from the last: unit k's value z[base + k] feeds the
        // outputs and the units after it, all already added into dz.
        let mut at = hidden_len;
        for (k, w) in net.hidden.iter().enumerate().rev() {
            at -= w.len();
            let d = self.dz[base + k] * hidden_prime(self.z[base + k]);
            if d == 0.0 {
                continue;
            }
            for (j, wj) in w.iter().enumerate() {
                grad[at + j] += d * self.z[j];
                self.dz[j] += d * wj;
            }
        }
    }
}

/// 1/(d + ε) with ε a millionth of the mean d: weights no row moves get a
/// large but finite step.
fn inverse_diagonal(d: &[f64]) -> Vec<f64> {
    let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
    let eps = 1e-6 * mean.max(1e-300);
    d.iter().map(|v| 1.0 / (v + eps)).collect()
}

/// The diagonal of the Gauss–Newton matrix Σ_r J_rᵀ M_r J_r (J_r = ∂out/∂θ
/// of row r), with M_r taken by its diagonal: one backward pass per
/// output and row.
pub fn gauss_newton_diagonal(net: &GrowingNet, rows: Rows<'_>) -> Vec<f64> {
    let p = net.parameter_count();
    let o = net.n_outputs;
    let (_, diag) = sum_blocks(rows.x.nrows(), p, |block| {
        let mut diag = vec![0.0; p];
        let mut g = vec![0.0; p];
        let mut scratch = Scratch::new(net);
        for r in block {
            for k in 0..o {
                let weight = rows.metric.map_or(1.0, |m| m.m[r * o * o + k * o + k]);
                g.iter_mut().for_each(|v| *v = 0.0);
                scratch.output_gradient(net, rows, r, k, &mut g);
                diag.iter_mut()
                    .zip(&g)
                    .for_each(|(d, gi)| *d += weight * gi * gi);
            }
        }
        (0.0, diag)
    });
    diag
}

/// Polish every weight of `net` on the `train` rows, keeping the weights
/// with the lowest RMSE (in the metric's units) on the `valid` rows (empty:
/// the training RMSE decides).
/// `on_iteration(i, valid_rmse)` is called after every iteration (for a
/// progress bar). Once `stop` is set it returns at the next iteration with
/// the best weights so far.
pub fn polish(
    net: &mut GrowingNet,
    train: Rows<'_>,
    valid: Rows<'_>,
    opts: &PolishOptions,
    stop: &AtomicBool,
    mut on_iteration: impl FnMut(usize, f64),
) -> PolishReport {
    let start = std::time::Instant::now();
    let delta = robust_delta(net, train, opts.robust);
    let train = Rows { delta, ..train };
    let valid = Rows { delta, ..valid };
    let judge = if valid.x.nrows() > 0 { valid } else { train };
    let valid_of = |n: &GrowingNet| judge.rmse(n);
    let train0 = train.rmse(net);
    let valid0 = valid_of(net);
    let mut best = (valid0, flatten(net), 0usize);
    let mut theta = best.1.clone();
    let mut work = net.clone();
    let (mut f, mut g) = loss_and_gradient(&work, train, true);
    // Once, at the start: re-evaluating it every 1,000 steps on the
    // two-segment robot changed the validation RMSE by 1 % (not better).
    let inv_d = inverse_diagonal(&gauss_newton_diagonal(&work, train));
    let mut memory = Memory::new(opts.memory);
    let mut iterations = 0;
    for it in 1..=opts.max_iterations {
        if stop.load(Ordering::SeqCst) || !f.is_finite() {
            break;
        }
        // H₀ = γ · diag(1/d), d the Gauss–Newton diagonal: the weights'
        // curvatures differ by orders of magnitude (|w| from 0.01 to 200),
        // and a scalar H₀ leaves L-BFGS crawling along the flat ones.
        let mut d = memory.direction(&g, &inv_d);
        let mut slope = dot(&g, &d);
        if slope >= 0.0 {
            // Not a descent direction (curvature lost): restart from −g.
            memory.clear();
            let scale = 1.0 / dot(&g, &g).sqrt().max(1e-300);
            d = g.iter().map(|v| -v * scale).collect();
            slope = dot(&g, &d);
        }
        // Backtracking line search on the Armijo condition.
        let mut step = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let trial: Vec<f64> = theta.iter().zip(&d).map(|(t, di)| t + step * di).collect();
            unflatten(&mut work, &trial);
            let (ft, gt) = loss_and_gradient(&work, train, true);
            if ft.is_finite() && ft <= f + 1e-4 * step * slope {
                accepted = Some((trial, ft, gt));
                break;
            }
            step *= 0.5;
        }
        let Some((trial, ft, gt)) = accepted else {
            break;
        };
        let s: Vec<f64> = trial.iter().zip(&theta).map(|(a, b)| a - b).collect();
        let yv: Vec<f64> = gt.iter().zip(&g).map(|(a, b)| a - b).collect();
        memory.push(&s, &yv);
        log::trace!("polish step {it}: loss {f:e} → {ft:e}, step {step:e}, slope {slope:e}");
        theta = trial;
        f = ft;
        g = gt;
        iterations = it;
        let v = valid_of(&work);
        if v < best.0 {
            best = (v, theta.clone(), it);
        }
        on_iteration(it, v);
        if it - best.2 >= opts.patience {
            break;
        }
    }
    unflatten(net, &best.1);
    PolishReport {
        iterations,
        train_rmse: (train0, train.rmse(net)),
        valid_rmse: (valid0, best.0),
        best_iteration: best.2,
        delta,
        seconds: start.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_options_refuse_a_memory_of_no_pairs_and_a_bad_robust_scale() {
        assert!(PolishOptions::default().check().is_ok());
        for bad in [
            PolishOptions {
                memory: 0,
                ..PolishOptions::default()
            },
            PolishOptions {
                robust: -1.0,
                ..PolishOptions::default()
            },
            PolishOptions {
                robust: f64::NAN,
                ..PolishOptions::default()
            },
        ] {
            let e = bad.check().unwrap_err().to_string();
            assert!(e.contains("polish"), "{e}");
        }
    }

    fn toy_net(kind: OutputKind) -> GrowingNet {
        GrowingNet {
            n_inputs: 2,
            n_outputs: 2,
            hidden: vec![
                vec![0.1, 0.5, -0.3],
                vec![-0.2, 0.4, 0.9, 1.5],
                vec![0.3, -1.1, 0.2, -0.7, 0.8],
            ],
            outputs: vec![
                vec![0.3, -0.7, 0.2, 1.1, -0.6, 0.4],
                vec![-0.1, 0.2, 0.5, -0.9, 0.3, 1.2],
            ],
            output_kind: kind,
        }
    }

    fn toy_data(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
        let x = DMatrix::from_fn(n, 2, |r, c| {
            ((r * 7 + c * 13) % 29) as f64 / 28.0 * 2.0 - 1.0
        });
        let y = DMatrix::from_fn(n, 2, |r, c| {
            let (a, b) = (x[(r, 0)], x[(r, 1)]);
            if c == 0 {
                0.5 + 0.3 * (2.0 * a).sin() * b
            } else {
                0.4 + 0.2 * (a * b + b * b)
            }
        });
        (x, y)
    }

    #[test]
    fn the_gradient_is_the_losss_derivative() {
        for kind in [OutputKind::Linear, OutputKind::Sigmoid] {
            let net = toy_net(kind);
            let (x, y) = toy_data(300);
            let m = toy_metric(x.nrows());
            for metric in [None, Some(&m)] {
                for delta in [None, Some(0.05)] {
                    let rows = Rows {
                        metric,
                        delta,
                        ..Rows::plain(&x, &y)
                    };
                    let (_, g) = loss_and_gradient(&net, rows, true);
                    let theta = flatten(&net);
                    let mut probe = net.clone();
                    for k in 0..theta.len() {
                        let h = 1e-6;
                        let mut t = theta.clone();
                        t[k] += h;
                        unflatten(&mut probe, &t);
                        let (fp, _) = loss_and_gradient(&probe, rows, false);
                        t[k] -= 2.0 * h;
                        unflatten(&mut probe, &t);
                        let (fm, _) = loss_and_gradient(&probe, rows, false);
                        let fd = (fp - fm) / (2.0 * h);
                        assert!(
                            (fd - g[k]).abs() <= 1e-6 * (1.0 + fd.abs()),
                            "{kind} weight {k}: finite difference {fd}, backprop {}",
                            g[k]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn the_robust_loss_is_half_the_square_for_small_errors_and_linear_for_large() {
        let net = toy_net(OutputKind::Linear);
        let (x, y) = toy_data(50);
        let plain = Rows::plain(&x, &y);
        let r = row_errors(&net, plain);
        let (squared, _) = loss_and_gradient(&net, plain, false);
        assert!((0.5 * r.iter().map(|v| v * v).sum::<f64>() - squared).abs() < 1e-12);
        // δ far above every row's error: the squared loss to first order.
        let wide = Rows {
            delta: Some(1e3),
            ..plain
        };
        assert!((loss_and_gradient(&net, wide, false).0 - squared).abs() < 1e-6 * squared);
        // δ far below: each row costs about δ·r.
        let delta = 1e-6;
        let narrow = Rows {
            delta: Some(delta),
            ..plain
        };
        let linear: f64 = r.iter().map(|v| delta * v).sum();
        let robust = loss_and_gradient(&net, narrow, false).0;
        assert!(
            (robust - linear).abs() < 1e-3 * linear,
            "{robust} vs {linear}"
        );
        // δ from the median: scale × the middle row error.
        let mut sorted = r.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(robust_delta(&net, plain, 3.0), Some(3.0 * sorted[25]));
        assert_eq!(robust_delta(&net, plain, 0.0), None);
    }

    /// A different symmetric positive definite 2×2 per row.
    fn toy_metric(n: usize) -> RowMetrics {
        let mut m = Vec::new();
        for r in 0..n {
            let (a, b) = (1.0 + (r % 5) as f64, 0.3 * ((r % 3) as f64 - 1.0));
            m.extend_from_slice(&[a, b, b, 2.0]);
        }
        RowMetrics { outputs: 2, m }
    }

    #[test]
    fn polishing_lowers_the_error_and_never_returns_a_worse_validation_net() {
        let (x, y) = toy_data(400);
        let (vx, vy) = (x.rows(0, 100).into_owned(), y.rows(0, 100).into_owned());
        let (tx, ty) = (x.rows(100, 300).into_owned(), y.rows(100, 300).into_owned());
        let mut net = toy_net(OutputKind::Linear);
        let opts = PolishOptions {
            max_iterations: 300,
            ..PolishOptions::default()
        };
        let train = Rows::plain(&tx, &ty);
        let valid = Rows::plain(&vx, &vy);
        let r = polish(
            &mut net,
            train,
            valid,
            &opts,
            &AtomicBool::new(false),
            |_, _| {},
        );
        assert!(r.iterations > 10, "{r:?}");
        assert!(r.train_rmse.1 < 0.2 * r.train_rmse.0, "{r:?}");
        assert!(r.valid_rmse.1 <= r.valid_rmse.0, "{r:?}");
        let plain = ((net.predict(&vx) - &vy).norm_squared() / vy.len() as f64).sqrt();
        assert!((plain - r.valid_rmse.1).abs() < 1e-12);
    }

    #[test]
    fn a_set_stop_leaves_the_net_as_it_was() {
        let (x, y) = toy_data(200);
        let mut net = toy_net(OutputKind::Linear);
        let before = net.clone();
        let opts = PolishOptions {
            max_iterations: 50,
            ..PolishOptions::default()
        };
        let rows = Rows::plain(&x, &y);
        let r = polish(
            &mut net,
            rows,
            rows,
            &opts,
            &AtomicBool::new(true),
            |_, _| {},
        );
        assert_eq!(r.iterations, 0);
        assert_eq!(net, before);
    }

    #[test]
    fn the_gradient_does_not_depend_on_the_thread_count() {
        let net = toy_net(OutputKind::Linear);
        let (x, y) = toy_data(1000);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let rows = Rows::plain(&x, &y);
        let a = one.install(|| loss_and_gradient(&net, rows, true));
        let b = two.install(|| loss_and_gradient(&net, rows, true));
        assert_eq!(a.0.to_bits(), b.0.to_bits());
        assert!(a
            .1
            .iter()
            .zip(&b.1)
            .all(|(p, q)| p.to_bits() == q.to_bits()));
    }
}
