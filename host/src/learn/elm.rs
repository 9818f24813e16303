//! Extreme learning machine (Huang, Zhu & Siew 2006): one hidden layer of
//! logistic sigmoid units with random, untrained input weights and biases;
//! only the linear output layer is fitted, by ridge least squares.
//!
//! Tuning: for each input-weight scale one random layer of the largest
//! candidate width is drawn and its Gram matrix computed once. A narrower
//! layer is a prefix of its units, whose Gram matrix is a leading block of
//! the big one, so every (width, ridge) pair costs only a Cholesky solve.

use nalgebra::DMatrix;
use rand::Rng;
use rayon::prelude::*;

use super::linalg::{argmin, check_splits, cross, gram, ridge_solve, rmse, rng, sigmoid, sub_seed};
use super::{LearnError, Learner, Split};

/// A random sigmoid layer: `h = σ(x W + b)`.
#[derive(Clone, Debug)]
struct Layer {
    /// `inputs × hidden`.
    w: DMatrix<f64>,
    b: Vec<f64>,
}

impl Layer {
    fn draw(inputs: usize, hidden: usize, scale: f64, seed: u64) -> Layer {
        let mut r = rng(seed);
        // Column by column so that the first k units are the same draw for any width.
        let mut w = DMatrix::zeros(inputs, hidden);
        let mut b = vec![0.0; hidden];
        for j in 0..hidden {
            for i in 0..inputs {
                w[(i, j)] = scale * r.random_range(-1.0..1.0);
            }
            b[j] = scale * r.random_range(-1.0..1.0);
        }
        Layer { w, b }
    }

    fn narrowed(&self, hidden: usize) -> Layer {
        Layer {
            w: self.w.columns(0, hidden).into_owned(),
            b: self.b[..hidden].to_vec(),
        }
    }

    /// Hidden activations with a trailing bias column of ones.
    fn features(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let h = self.b.len();
        let mut z = x * &self.w;
        for j in 0..h {
            let bj = self.b[j];
            z.column_mut(j).apply(|v| *v = sigmoid(*v + bj));
        }
        z.insert_column(h, 1.0)
    }
}

/// Extreme learning machine regressor.
pub struct Elm {
    /// Candidate hidden-layer widths.
    pub hiddens: Vec<usize>,
    /// Candidate ridge factors (relative to the mean diagonal of the Gram matrix).
    pub ridges: Vec<f64>,
    /// Candidate input-weight scales: weights and biases uniform in [−s, s].
    pub scales: Vec<f64>,
    layer: Option<Layer>,
    out: DMatrix<f64>,
    hidden: usize,
    ridge: f64,
    scale: f64,
}

impl Default for Elm {
    /// The grid used by `tendril compare`: widths {500, 1000, 1500, 2000} ×
    /// ridges {1e-13 … 1e-10} × scales {4, 8, 16} (three Gram matrices,
    /// 48 Cholesky solves). Small ridges matter: the sigmoid features are
    /// nearly collinear, and a ridge of 1e-10 already costs a factor 2–4 in
    /// accuracy on the IK data.
    fn default() -> Self {
        Elm::with_grid(
            vec![500, 1000, 1500, 2000],
            vec![1e-13, 1e-12, 1e-11, 1e-10],
            vec![4.0, 8.0, 16.0],
        )
    }
}

impl Elm {
    /// An ELM choosing width, ridge and weight scale from the given candidates.
    pub fn with_grid(hiddens: Vec<usize>, ridges: Vec<f64>, scales: Vec<f64>) -> Elm {
        Elm {
            hiddens,
            ridges,
            scales,
            layer: None,
            out: DMatrix::zeros(0, 0),
            hidden: 0,
            ridge: 0.0,
            scale: 0.0,
        }
    }

    /// An ELM with fixed hyper-parameters.
    pub fn fixed(hidden: usize, ridge: f64, scale: f64) -> Elm {
        Elm::with_grid(vec![hidden], vec![ridge], vec![scale])
    }

    /// Chosen (hidden width, ridge, weight scale).
    pub fn chosen(&self) -> (usize, f64, f64) {
        (self.hidden, self.ridge, self.scale)
    }

    /// The fitted machine as `.tnet` bytes: a cascade net whose hidden units
    /// (logistic sigmoid) ignore each other and whose linear outputs skip
    /// the inputs, with the min–max ranges its splits were normalised by
    /// (`input_lo`/`input_hi` per input, `output_lo`/`output_hi` per output).
    pub fn to_tnet(
        &self,
        input_lo: &[f64],
        input_hi: &[f64],
        output_lo: &[f64],
        output_hi: &[f64],
    ) -> Result<Vec<u8>, LearnError> {
        let layer = self
            .layer
            .as_ref()
            .ok_or_else(|| LearnError::Numerical("ELM: no fit to export".into()))?;
        let (inputs, hidden, outputs) = (layer.w.nrows(), layer.b.len(), self.out.ncols());
        let shape = tendril_shared::NetShape {
            inputs,
            hidden,
            outputs,
        };
        // Hidden row k: bias, inputs, then k earlier units (zero).
        let mut hidden_w = vec![0.0f32; shape.hidden_weight_count()];
        for k in 0..hidden {
            let off = shape.hidden_row_offset(k);
            hidden_w[off] = layer.b[k] as f32;
            for i in 0..inputs {
                hidden_w[off + 1 + i] = layer.w[(i, k)] as f32;
            }
        }
        // Output row: bias (the features' trailing ones column), inputs
        // (zero), hidden units.
        let row = shape.output_row_len();
        let mut output_w = vec![0.0f32; shape.output_weight_count()];
        for o in 0..outputs {
            output_w[o * row] = self.out[(hidden, o)] as f32;
            for k in 0..hidden {
                output_w[o * row + 1 + inputs + k] = self.out[(k, o)] as f32;
            }
        }
        let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let (ilo, ihi, olo, ohi) = (
            f32s(input_lo),
            f32s(input_hi),
            f32s(output_lo),
            f32s(output_hi),
        );
        let view = tendril_shared::TnetView {
            shape,
            hidden_activation: tendril_shared::Activation::Sigmoid,
            output_activation: tendril_shared::Activation::Linear,
            input_lo: &ilo,
            input_hi: &ihi,
            output_lo: &olo,
            output_hi: &ohi,
            hidden_weights: &hidden_w,
            output_weights: &output_w,
        };
        tendril_shared::encode_to_vec(&view)
            .map_err(|e| LearnError::Numerical(format!("ELM: encoding the net: {e:?}")))
    }
}

/// The ridge solution in the rows' space: `W = Fᵀ (K + λ I)⁻¹ Y` with
/// `K = F Fᵀ` (the push-through form of `(FᵀF + λ I)⁻¹ Fᵀ Y`); None when
/// `K + λ I` is not positive definite.
fn dual_ridge_solve(
    f: &DMatrix<f64>,
    kernel: &DMatrix<f64>,
    y: &DMatrix<f64>,
    lambda: f64,
) -> Option<DMatrix<f64>> {
    let mut a = kernel.clone();
    for i in 0..a.nrows() {
        a[(i, i)] += lambda;
    }
    Some(f.transpose() * a.cholesky()?.solve(y))
}

impl Learner for Elm {
    fn name(&self) -> &str {
        "ELM"
    }

    fn fit(&mut self, train: Split<'_>, valid: Split<'_>, seed: u64) -> Result<(), LearnError> {
        check_splits(train, valid)?;
        if self.hiddens.is_empty()
            || self.hiddens.contains(&0)
            || self.ridges.is_empty()
            || self.scales.is_empty()
        {
            return Err(LearnError::BadParameter {
                name: "ELM grid",
                why: "need at least one width ≥ 1, one ridge and one scale".into(),
            });
        }
        if self
            .ridges
            .iter()
            .chain(&self.scales)
            .any(|v| !v.is_finite() || *v < 0.0)
        {
            return Err(LearnError::BadParameter {
                name: "ELM grid",
                why: "ridges and scales must be finite and ≥ 0".into(),
            });
        }
        let h_max = self.hiddens.iter().copied().max().unwrap_or(1);
        let inputs = train.x.ncols();
        let mut best: Option<(f64, usize, f64, f64, Layer, DMatrix<f64>)> = None;
        for (si, &scale) in self.scales.iter().enumerate() {
            let layer = Layer::draw(inputs, h_max, scale, sub_seed(seed, si as u64));
            let f = layer.features(train.x);
            let fv = layer.features(valid.x);
            let g = gram(&f);
            let c = cross(&f, train.y);
            // (width's index, ridge).
            let cands: Vec<(usize, f64)> = (0..self.hiddens.len())
                .flat_map(|i| self.ridges.iter().map(move |&r| (i, r)))
                .collect();
            // Leading block: the first h units plus the bias (last column).
            let block = |h: usize| -> Vec<usize> { (0..h).chain(std::iter::once(h_max)).collect() };
            // A width beyond the training rows is solved in the rows' space,
            // W = Fᵀ (F Fᵀ + λ s I)⁻¹ Y, the same ridge solution (s still the
            // mean diagonal of FᵀF): an n × n system instead of an
            // (h + 1)-square one that has rank n at most (262 rows and
            // widths to 2,000: 9.5 s of a quick comparison's 11 s). Its
            // block of F and F Fᵀ, once per width.
            let n = train.x.nrows();
            let rows_space: Vec<Option<(DMatrix<f64>, DMatrix<f64>)>> = self
                .hiddens
                .par_iter()
                .map(|&h| {
                    (h + 1 > n).then(|| {
                        let fs = f.select_columns(&block(h));
                        let kernel = &fs * fs.transpose();
                        (fs, kernel)
                    })
                })
                .collect();
            let fits: Vec<Option<(f64, DMatrix<f64>)>> = cands
                .par_iter()
                .map(|&(i, r)| {
                    let idx = block(self.hiddens[i]);
                    let w = match &rows_space[i] {
                        Some((fs, kernel)) => {
                            let s = idx.iter().map(|&j| g[(j, j)]).sum::<f64>() / idx.len() as f64;
                            dual_ridge_solve(fs, kernel, train.y, r * s.max(f64::MIN_POSITIVE))?
                        }
                        None => {
                            let gs = g.select_rows(&idx).select_columns(&idx);
                            let cs = c.select_rows(&idx);
                            ridge_solve(&gs, &cs, r).ok()?
                        }
                    };
                    let pred = fv.select_columns(&idx) * &w;
                    Some((rmse(&pred, valid.y), w))
                })
                .collect();
            let scores: Vec<f64> = fits
                .iter()
                .map(|f| f.as_ref().map_or(f64::NAN, |f| f.0))
                .collect();
            if let Some(i) = argmin(&scores) {
                if best.as_ref().is_none_or(|b| scores[i] < b.0) {
                    let (h, r) = (self.hiddens[cands[i].0], cands[i].1);
                    let w = fits[i].as_ref().map(|f| f.1.clone()).unwrap_or_default();
                    best = Some((scores[i], h, r, scale, layer.narrowed(h), w));
                }
            }
        }
        let (score, h, r, s, layer, w) = best
            .ok_or_else(|| LearnError::Numerical("every ELM candidate failed to solve".into()))?;
        (self.hidden, self.ridge, self.scale) = (h, r, s);
        self.layer = Some(layer);
        self.out = w;
        log::debug!("ELM: hidden={h} ridge={r:e} scale={s} (valid RMSE {score:.5})");
        Ok(())
    }

    fn predict(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.layer {
            Some(l) => l.features(x) * &self.out,
            None => DMatrix::from_element(x.nrows(), 0, f64::NAN),
        }
    }

    fn parameter_count(&self) -> usize {
        self.layer.as_ref().map_or(0, |l| l.w.len() + l.b.len()) + self.out.len()
    }

    fn describe(&self) -> String {
        format!(
            "hidden={}, ridge={:e}, weight scale={}",
            self.hidden, self.ridge, self.scale
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fewer rows than features: the rows'-space solve is the ridge
    /// solution of the normal equations, to rounding.
    #[test]
    fn the_rows_space_solve_is_the_ridge_solution() {
        let f = DMatrix::from_fn(20, 31, |i, j| ((i * 37 + j * 11) % 29) as f64 / 29.0 - 0.4);
        let y = DMatrix::from_fn(20, 3, |i, j| ((i * 5 + j * 7) % 13) as f64 / 13.0);
        let g = gram(&f);
        let lambda_rel = 1e-4;
        let s = g.trace() / g.nrows() as f64;
        let primal = ridge_solve(&g, &cross(&f, &y), lambda_rel).unwrap();
        let dual = dual_ridge_solve(&f, &(&f * f.transpose()), &y, lambda_rel * s).unwrap();
        let scale = primal.amax();
        assert!(
            (&primal - &dual).amax() < 1e-8 * scale,
            "primal {primal} dual {dual}"
        );
    }
}
