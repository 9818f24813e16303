//! The polish's L-BFGS memory (`docs/design.md` §4, "Polish"): the last
//! curvature pairs (s, y) and the two-loop recursion that turns a gradient
//! into a quasi-Newton direction, with a diagonal initial inverse Hessian.
//!
//! Why its own module: with hundreds of pairs on a 3,000-weight net the
//! recursion streams every pair twice a step (4 × pairs × weights
//! multiply-adds): at 600 pairs in f64, 28 MB that outgrow the cache, and
//! ≈ 5 ms of a 25 ms step on the two-segment robot. So the pairs are kept
//! in f32 (half the bytes; the same validation error after 1,500 steps,
//! 0.0141 against 0.0142 ×100, at 22.3 against 25.7 ms a step), the
//! recursion's vector q and its sums stay f64, the dot products are split
//! across lanes (a plain `sum` is one serial chain the compiler may not
//! reorder), and a dropped pair's buffers are reused.

use std::collections::VecDeque;

/// One curvature pair: the step s, the gradient change y (stored in f32:
/// the recursion streams every pair twice a step, and at 600 pairs they
/// outgrow the cache, so their bytes are its time), and 1 / sᵀy.
struct Pair {
    s: Vec<f32>,
    y: Vec<f32>,
    rho: f64,
}

/// The last `capacity` curvature pairs.
pub(super) struct Memory {
    pairs: VecDeque<Pair>,
    capacity: usize,
    alphas: Vec<f64>,
}

impl Memory {
    /// An empty memory keeping at most `capacity` pairs (at least one).
    pub(super) fn new(capacity: usize) -> Memory {
        let capacity = capacity.max(1);
        Memory {
            pairs: VecDeque::with_capacity(capacity),
            capacity,
            alphas: Vec::with_capacity(capacity),
        }
    }

    /// Forget every pair (after a direction that did not descend).
    pub(super) fn clear(&mut self) {
        self.pairs.clear();
    }

    /// Keep the step `s` = θ₁ − θ₀ and the gradient change `y` = g₁ − g₀
    /// when their curvature sᵀy is positive (else the pair would make the
    /// inverse Hessian indefinite); the oldest pair goes when full.
    pub(super) fn push(&mut self, s: &[f64], y: &[f64]) {
        // Judged as stored (f32), so a pair kept always has a positive
        // curvature and a finite 1 / sᵀy.
        let rounded = |v: f64| f64::from(v as f32);
        let sy: f64 = s
            .iter()
            .zip(y)
            .map(|(a, b)| rounded(*a) * rounded(*b))
            .sum();
        if !(sy > 1e-12 * dot(y, y).sqrt() * dot(s, s).sqrt() && (1.0 / sy).is_finite()) {
            return;
        }
        let mut pair = if self.pairs.len() >= self.capacity {
            self.pairs.pop_front().expect("a full memory has a pair")
        } else {
            Pair {
                s: Vec::new(),
                y: Vec::new(),
                rho: 0.0,
            }
        };
        pair.s.clear();
        pair.s.extend(s.iter().map(|&v| v as f32));
        pair.y.clear();
        pair.y.extend(y.iter().map(|&v| v as f32));
        // The curvature of the pair as stored, so each pair keeps sᵀH y = sᵀs.
        pair.rho = 1.0 / sy;
        self.pairs.push_back(pair);
    }

    /// −H g by the two-loop recursion, H₀ = γ · diag(`inv_d`) with γ from
    /// the newest pair (sᵀy / yᵀ diag(`inv_d`) y; 1 without pairs).
    pub(super) fn direction(&mut self, g: &[f64], inv_d: &[f64]) -> Vec<f64> {
        let mut q = g.to_vec();
        self.alphas.clear();
        for p in self.pairs.iter().rev() {
            let a = p.rho * dot(&p.s, &q);
            axpy(-a, &p.y, &mut q);
            self.alphas.push(a);
        }
        let gamma = match self.pairs.back() {
            Some(p) => {
                let yhy: f64 =
                    p.y.iter()
                        .zip(inv_d)
                        .map(|(&y, i)| f64::from(y) * f64::from(y) * i)
                        .sum();
                1.0 / (p.rho * yhy)
            }
            None => 1.0,
        };
        q.iter_mut().zip(inv_d).for_each(|(v, i)| *v *= gamma * i);
        for (p, a) in self.pairs.iter().zip(self.alphas.iter().rev()) {
            let b = p.rho * dot(&p.y, &q);
            axpy(a - b, &p.s, &mut q);
        }
        q.iter_mut().for_each(|v| *v = -*v);
        q
    }
}

/// Lanes of [`dot`]: independent sums the compiler keeps in vector registers.
const LANES: usize = 8;

/// aᵀb, summed in f64 in [`LANES`] interleaved partial sums (a fixed
/// order); `a` in f64, or a stored pair's f32.
pub(super) fn dot<T: Copy + Into<f64>>(a: &[T], b: &[f64]) -> f64 {
    let mut acc = [0.0; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, y)| x.into() * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..LANES {
            acc[k] += x[k].into() * y[k];
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// y += a x for a stored pair's f32 `x`.
fn axpy(a: f64, x: &[f32], y: &mut [f64]) {
    y.iter_mut()
        .zip(x)
        .for_each(|(yi, &xi)| *yi += a * f64::from(xi));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a quadratic ½ θᵀAθ with A diagonal, pairs from exact steps make
    /// the two-loop direction the Newton step −A⁻¹g once the memory holds
    /// a pair per dimension (the secant equations pin H down).
    #[test]
    fn a_full_memory_on_a_quadratic_gives_the_newton_step() {
        let a = [1.0, 10.0, 100.0, 0.5, 3.0];
        let n = a.len();
        let mut m = Memory::new(n);
        for k in 0..n {
            let mut s = vec![0.0; n];
            // Powers of two: exact in the pairs' f32, so the algebra is
            // checked to f64 rounding.
            s[k] = 0.5f64.powi(k as i32);
            let y: Vec<f64> = s.iter().zip(&a).map(|(si, ai)| si * ai).collect();
            m.push(&s, &y);
        }
        let g = [1.0, -2.0, 3.0, 0.25, -1.5];
        let d = m.direction(&g, &[1.0; 5]);
        for k in 0..n {
            let newton = -g[k] / a[k];
            assert!((d[k] - newton).abs() < 1e-12, "{k}: {} vs {newton}", d[k]);
        }
    }

    #[test]
    fn the_memory_keeps_the_newest_pairs_and_refuses_negative_curvature() {
        let mut m = Memory::new(2);
        m.push(&[1.0, 0.0], &[-1.0, 0.0]);
        assert_eq!(m.pairs.len(), 0);
        // Positive in f64, nothing left in f32 (1e-50 rounds to 0).
        m.push(&[1e-50, 0.0], &[1e-50, 0.0]);
        assert_eq!(m.pairs.len(), 0);
        m.push(&[1.0, 0.0], &[2.0, 0.0]);
        m.push(&[0.0, 1.0], &[0.0, 4.0]);
        m.push(&[1.0, 1.0], &[2.0, 4.0]);
        assert_eq!(m.pairs.len(), 2);
        assert_eq!(m.pairs[1].s, vec![1.0f32, 1.0]);
        assert_eq!(m.pairs[0].s, vec![0.0f32, 1.0]);
    }

    #[test]
    fn the_lane_split_dot_is_the_plain_sum() {
        let a: Vec<f64> = (0..37).map(|i| (i as f64 * 0.37).sin()).collect();
        let b: Vec<f64> = (0..37).map(|i| (i as f64 * 0.11).cos()).collect();
        let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - plain).abs() < 1e-13);
    }
}
