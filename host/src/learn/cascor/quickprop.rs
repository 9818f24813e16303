//! Quickprop (Fahlman, "An Empirical Study of Learning Speed in Back-Propagation
//! Networks", CMU-CS-88-162, 1988): per-weight secant step on the slope, capped
//! at μ times the previous step, with a plain gradient term when the slope
//! keeps its sign or the previous step was zero. The update is a transcription
//! of `QUICKPROP_UPDATE` in Fahlman's public-domain `cascor1.c`.

/// Quickprop hyper-parameters of one training phase.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QuickpropParams {
    /// Maximum growth factor μ of a step relative to the previous one (Fahlman: 1.75–2.0).
    pub mu: f64,
    /// Gradient step size ε before division by the phase's scale (patterns, fan-in).
    pub epsilon: f64,
    /// Weight decay added to every slope (`slope += decay · w`).
    pub decay: f64,
    /// Epochs without a relative improvement of `threshold` before the phase stops.
    pub patience: usize,
    /// Relative improvement that resets the patience counter (0.01 = 1 %).
    pub threshold: f64,
    /// Hard cap on epochs.
    pub max_epochs: usize,
}

/// Per-weight state of Quickprop: previous step and previous slope.
#[derive(Clone, Debug)]
pub struct Quickprop {
    deltas: Vec<f64>,
    prev_slopes: Vec<f64>,
    epsilon: f64,
    mu: f64,
    shrink: f64,
    decay: f64,
}

impl Quickprop {
    /// State for `n` weights with an already scaled step size `epsilon`.
    pub fn new(n: usize, epsilon: f64, mu: f64, decay: f64) -> Quickprop {
        Quickprop {
            deltas: vec![0.0; n],
            prev_slopes: vec![0.0; n],
            epsilon,
            mu,
            shrink: mu / (1.0 + mu),
            decay,
        }
    }

    /// Number of weights handled.
    pub fn len(&self) -> usize {
        self.deltas.len()
    }

    /// Whether no weight is handled.
    pub fn is_empty(&self) -> bool {
        self.deltas.is_empty()
    }

    /// Grow by one weight (a newly installed unit's output weight) with fresh state.
    pub fn push(&mut self) {
        self.deltas.push(0.0);
        self.prev_slopes.push(0.0);
    }

    /// One step minimising the error whose gradient (∂E/∂w) is `slopes`.
    pub fn step(&mut self, weights: &mut [f64], slopes: &[f64]) {
        debug_assert_eq!(weights.len(), self.deltas.len());
        debug_assert_eq!(slopes.len(), self.deltas.len());
        for i in 0..weights.len() {
            let w = weights[i];
            let d = self.deltas[i];
            let s = slopes[i] + self.decay * w;
            let p = self.prev_slopes[i];
            let mut next = 0.0;
            if d < 0.0 {
                if s > 0.0 {
                    next -= self.epsilon * s;
                }
                if s >= self.shrink * p {
                    next += self.mu * d;
                } else {
                    next += d * s / (p - s);
                }
            } else if d > 0.0 {
                if s < 0.0 {
                    next -= self.epsilon * s;
                }
                if s <= self.shrink * p {
                    next += self.mu * d;
                } else {
                    next += d * s / (p - s);
                }
            } else {
                next -= self.epsilon * s;
            }
            if !next.is_finite() {
                next = -self.epsilon * s;
            }
            self.deltas[i] = next;
            weights[i] = w + next;
            self.prev_slopes[i] = s;
        }
    }
}

/// Fahlman's stagnation test: the phase goes on while the monitored value
/// improves by more than `threshold` (relative) within `patience` epochs.
#[derive(Clone, Debug)]
pub struct Patience {
    last: f64,
    quit_epoch: usize,
    patience: usize,
    threshold: f64,
    minimise: bool,
}

impl Patience {
    /// Tracker for a value to minimise (`minimise`) or maximise.
    pub fn new(patience: usize, threshold: f64, minimise: bool) -> Patience {
        Patience {
            last: f64::NAN,
            quit_epoch: patience,
            patience,
            threshold,
            minimise,
        }
    }

    /// Record the value at `epoch`; `true` when the phase should stop.
    pub fn stagnant(&mut self, epoch: usize, value: f64) -> bool {
        let improved = if self.last.is_nan() {
            true
        } else if self.minimise {
            value < self.last * (1.0 - self.threshold)
        } else {
            value > self.last * (1.0 + self.threshold)
        };
        if improved {
            self.last = value;
            self.quit_epoch = epoch + self.patience;
            false
        } else {
            epoch >= self.quit_epoch
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quickprop_minimises_an_anisotropic_quadratic() {
        // E = ½ Σ a_i (w_i − c_i)²: minimum at c, curvatures over three decades.
        let a = [1.0, 10.0, 0.1, 3.0];
        let c = [1.0, -2.0, 0.5, 3.0];
        let mut w = [0.0; 4];
        let mut qp = Quickprop::new(4, 0.05, 2.0, 0.0);
        for _ in 0..200 {
            let g: Vec<f64> = (0..4).map(|i| a[i] * (w[i] - c[i])).collect();
            qp.step(&mut w, &g);
        }
        for i in 0..4 {
            assert!((w[i] - c[i]).abs() < 1e-8, "w[{i}] = {} vs {}", w[i], c[i]);
        }
    }

    #[test]
    fn quickprop_beats_plain_gradient_descent() {
        // Same ε: gradient descent on a flat quadratic crawls, Quickprop jumps.
        let (a, c) = (0.01, 5.0);
        let mut wq = [0.0];
        let mut qp = Quickprop::new(1, 1.0, 2.0, 0.0);
        let mut wg = 0.0;
        for _ in 0..20 {
            let g = [a * (wq[0] - c)];
            qp.step(&mut wq, &g);
            wg -= 1.0 * a * (wg - c);
        }
        assert!((wq[0] - c).abs() < 1e-6);
        assert!((wg - c).abs() > 0.5);
    }

    #[test]
    fn patience_stops_after_stagnation() {
        let mut p = Patience::new(3, 0.01, true);
        assert!(!p.stagnant(0, 1.0));
        assert!(!p.stagnant(1, 0.5));
        assert!(!p.stagnant(2, 0.499));
        assert!(!p.stagnant(3, 0.499));
        assert!(p.stagnant(4, 0.499));
    }
}
