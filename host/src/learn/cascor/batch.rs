//! The polish's loss and gradient over tiles of rows (`docs/design.md` §4,
//! "Polish"): the same sums as the per-row reference
//! (`super::polish::loss_and_gradient_per_row`), laid out so the inner loops
//! run across rows.
//!
//! Why: per row, every unit is a dot product, which the compiler may not
//! vectorise (it would reorder the sum); across a tile of rows, unit k's
//! pre-activation is a sum of feature columns, s = Σ_j w_k[j] Z[:, j], an
//! axpy per weight, whose lanes are rows and whose order per row is the
//! reference's. A tile's columns (32 rows, eight AVX registers of f64) stay
//! in registers while the weights stream past; the backward pass is the
//! same shape (δ_k = σ'(z_k) ⊙ Σ_u w_u[k] δ_u, pulled from the later
//! units), and the gradient ∂L/∂w_u[j] = Σ_r δ_u[r] Z[r, j] runs along
//! each unit's weights, a few rows at a time, from a transposed copy of the
//! tile's features.
//!
//! Rows are summed in blocks of [`BLOCK`] (tiles in order inside, blocks
//! in order after), so the result does not depend on the number of threads.
//! f64 throughout, like the reference: the L-BFGS line search compares
//! losses that differ in their sixth digit late in a run.

use std::ops::Range;

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::net::{hidden_activation, hidden_prime, logistic, GrowingNet, OutputKind};

/// Rows of a tile: a feature column of a tile fills eight AVX registers.
const TILE: usize = 32;
/// Rows per block of the polish's parallel sums (a whole number of tiles):
/// fixed, so every sum's order is too, and the result does not depend on
/// the number of threads. The per-row reference sums in the same blocks.
pub(super) const BLOCK: usize = 256;

/// A loss and a `p`-long gradient summed over the rows `0..n`: `block`
/// sums each block of [`BLOCK`] rows, the blocks run in parallel and are
/// added in order.
pub(super) fn sum_blocks(
    n: usize,
    p: usize,
    block: impl Fn(Range<usize>) -> (f64, Vec<f64>) + Sync,
) -> (f64, Vec<f64>) {
    let blocks: Vec<(f64, Vec<f64>)> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| block(b * BLOCK..((b + 1) * BLOCK).min(n)))
        .collect();
    let mut grad = vec![0.0; p];
    let mut loss = 0.0;
    for (l, g) in blocks {
        loss += l;
        grad.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
    }
    (loss, grad)
}

/// The loss's rows, as [`super::polish::Rows`] holds them.
#[derive(Clone, Copy)]
pub(super) struct Batch<'a> {
    /// Inputs, `n × I` (column-major: a tile's input column is contiguous).
    pub x: &'a DMatrix<f64>,
    /// Targets, `n × O`.
    pub y: &'a DMatrix<f64>,
    /// Row r's metric M_r at `r·O² ..`, row-major (`None`: the identity).
    pub metric: Option<&'a [f64]>,
    /// δ of the pseudo-Huber loss (`None`: squared).
    pub delta: Option<f64>,
}

/// What every tile reads: the net, and its weights by the feature they read.
struct Layout<'n> {
    net: &'n GrowingNet,
    /// 1 + inputs: where the hidden units' features start.
    base: usize,
    /// Units: hidden, then outputs (the flat vector's order).
    units: usize,
    /// Row k: w_u[base + k] for u = 0..units (hidden unit k's consumers;
    /// 0 where u ≤ k, which do not see it).
    consumers: Vec<f64>,
    /// Each unit's first weight in the flat vector.
    offsets: Vec<usize>,
}

impl<'n> Layout<'n> {
    fn new(net: &'n GrowingNet) -> Self {
        let base = 1 + net.n_inputs;
        let units = net.n_hidden() + net.n_outputs;
        let all = || net.hidden.iter().chain(&net.outputs);
        let mut consumers = vec![0.0; net.n_hidden() * units];
        for (u, w) in all().enumerate() {
            for (k, &wk) in w.iter().skip(base).enumerate() {
                consumers[k * units + u] = wk;
            }
        }
        let offsets = all()
            .scan(0, |at, w| {
                let here = *at;
                *at += w.len();
                Some(here)
            })
            .collect();
        Layout {
            net,
            base,
            units,
            consumers,
            offsets,
        }
    }
}

/// One tile's columns, allocated once per block.
struct Tile {
    /// Features, column j at `j·TILE ..`: bias, inputs, hidden units.
    z: Vec<f64>,
    /// The features again, row r at `r·(1 + I + H) ..`.
    zt: Vec<f64>,
    /// ∂L/∂s_u of every unit's weighted sum, column u at `u·TILE ..`.
    d: Vec<f64>,
    /// Outputs, column o at `o·TILE ..`.
    out: Vec<f64>,
    /// One row's e, M e.
    e: Vec<f64>,
    me: Vec<f64>,
}

impl Tile {
    fn new(l: &Layout<'_>) -> Tile {
        let o = l.net.n_outputs;
        Tile {
            z: vec![0.0; (l.base + l.net.n_hidden()) * TILE],
            zt: vec![0.0; (l.base + l.net.n_hidden()) * TILE],
            d: vec![0.0; l.units * TILE],
            out: vec![0.0; o * TILE],
            e: vec![0.0; o],
            me: vec![0.0; o],
        }
    }
}

/// Half the summed (metric-weighted, optionally robust) squared error of
/// `net` over the rows, and, when `with_gradient`, its gradient with
/// respect to the flat weight vector (else an empty vector): what
/// `super::polish::loss_and_gradient_per_row` computes, to rounding.
pub(super) fn loss_and_gradient(
    net: &GrowingNet,
    rows: Batch<'_>,
    with_gradient: bool,
) -> (f64, Vec<f64>) {
    loss_and_gradient_with(cpu_has_fma(), net, rows, with_gradient)
}

/// [`loss_and_gradient`] on the fast path (AVX2 and FMA; only where the CPU
/// has them) or the portable one.
fn loss_and_gradient_with(
    fast: bool,
    net: &GrowingNet,
    rows: Batch<'_>,
    with_gradient: bool,
) -> (f64, Vec<f64>) {
    let layout = Layout::new(net);
    let p = if with_gradient {
        net.parameter_count()
    } else {
        0
    };
    let n = rows.x.nrows();
    sum_blocks(n, p, |block| {
        let mut tile = Tile::new(&layout);
        let mut sums = Sums {
            loss: 0.0,
            grad: vec![0.0; p],
        };
        for r0 in block.step_by(TILE) {
            let span = r0..(r0 + TILE).min(n);
            tile_pass(fast, &layout, rows, span, &mut tile, &mut sums);
        }
        (sums.loss, sums.grad)
    })
}

/// Whether this CPU has the fused multiply-add the fast kernel is built for.
fn cpu_has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A block's running sums: the loss (row by row, in order) and the
/// gradient (empty when not wanted).
struct Sums {
    loss: f64,
    grad: Vec<f64>,
}

/// One tile, the rows of `span` (at most [`TILE`]), into `sums`.
fn tile_pass(
    fast: bool,
    l: &Layout<'_>,
    rows: Batch<'_>,
    span: Range<usize>,
    t: &mut Tile,
    sums: &mut Sums,
) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is true only where `cpu_has_fma()` found AVX2 and
        // FMA on this CPU (the tests' `false` is always safe).
        return unsafe { tile_pass_fma(l, rows, span, t, sums) };
    }
    let _ = fast;
    tile_kernel::<false>(l, rows, span, t, sums)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn tile_pass_fma(
    l: &Layout<'_>,
    rows: Batch<'_>,
    span: Range<usize>,
    t: &mut Tile,
    sums: &mut Sums,
) {
    tile_kernel::<true>(l, rows, span, t, sums)
}

/// a·b + c, fused on the fast path (without FMA, `mul_add` would be a
/// library call).
#[inline(always)]
fn mac<const FAST: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FAST {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// The hidden units' activation 1/(1 + e^−s) − ½: on the fast path with
/// [`exp`] below, which vectorises across the tile (the library's `exp`,
/// one call per row, was a fifth of the kernel's time).
#[inline(always)]
fn activation<const FAST: bool>(s: f64) -> f64 {
    if FAST {
        1.0 / (1.0 + exp(-s)) - 0.5
    } else {
        hidden_activation(s)
    }
}

/// e^x within two ulps, branch-free so it vectorises: x = k ln 2 + r with
/// |r| ≤ ln 2 / 2, e^r by its Taylor series to r¹³ (the remainder is below
/// 2⁻⁵⁵), 2^k written into the exponent bits. x is clamped to ±708, where
/// e^x is still a normal number: the activation there is ½ or −½ to 1e−300.
#[inline(always)]
fn exp(x: f64) -> f64 {
    // 1.5·2⁵²: x·log₂e + MAGIC rounds to an integer held in the low bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    // ln 2 in two parts (fdlibm's): k·LN2_HI is exact for |k| < 2¹¹.
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // 1/n!, n = 0..=13.
    const C: [f64; 14] = {
        let mut c = [1.0; 14];
        let mut n = 1;
        while n < 14 {
            c[n] = c[n - 1] / n as f64;
            n += 1;
        }
        c
    };
    let x = x.clamp(-708.0, 708.0);
    let t = x * std::f64::consts::LOG2_E + MAGIC;
    let k = t - MAGIC;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = C[13];
    for &c in C[..13].iter().rev() {
        // Fused: only the fast path (AVX2 and FMA) calls this.
        p = p.mul_add(r, c);
    }
    let scale = f64::from_bits(t.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(1023) << 52);
    p * scale
}

/// Σ_j w[j] · column j of `cols` (as many columns as `w` has weights).
#[inline(always)]
fn combine<const FAST: bool>(cols: &[f64], w: &[f64]) -> [f64; TILE] {
    let mut acc = [0.0; TILE];
    for (col, &wj) in cols.chunks_exact(TILE).zip(w) {
        let col: &[f64; TILE] = col.try_into().expect("a whole column");
        for (a, &c) in acc.iter_mut().zip(col) {
            *a = mac::<FAST>(c, wj, *a);
        }
    }
    acc
}

/// The tile forward, its rows' losses, and, when the gradient is wanted,
/// backward into the gradient.
#[inline(always)]
fn tile_kernel<const FAST: bool>(
    l: &Layout<'_>,
    rows: Batch<'_>,
    span: Range<usize>,
    t: &mut Tile,
    sums: &mut Sums,
) {
    forward::<FAST>(l, rows.x, span.clone(), t);
    sums.loss = output_errors(l, rows, span, t, sums.loss);
    if !sums.grad.is_empty() {
        backward::<FAST>(l, t);
        gradient::<FAST>(l, t, &mut sums.grad);
    }
}

/// The tile's features into `t.z` and outputs into `t.out`; rows past
/// the span are zero inputs (finite, and their δ is zero).
#[inline(always)]
fn forward<const FAST: bool>(l: &Layout<'_>, x: &DMatrix<f64>, span: Range<usize>, t: &mut Tile) {
    let (n, xs) = (x.nrows(), x.as_slice());
    let (r0, len) = (span.start, span.len());
    t.z[..TILE].fill(1.0);
    for c in 0..l.net.n_inputs {
        let col = &mut t.z[(1 + c) * TILE..(2 + c) * TILE];
        col[..len].copy_from_slice(&xs[c * n + r0..c * n + r0 + len]);
        col[len..].fill(0.0);
    }
    for (k, w) in l.net.hidden.iter().enumerate() {
        let (seen, rest) = t.z.split_at_mut((l.base + k) * TILE);
        let s = combine::<FAST>(seen, w);
        for (z, s) in rest[..TILE].iter_mut().zip(s) {
            *z = activation::<FAST>(s);
        }
    }
    for (o, w) in l.net.outputs.iter().enumerate() {
        let s = combine::<FAST>(&t.z, w);
        let out = &mut t.out[o * TILE..(o + 1) * TILE];
        for (y, s) in out.iter_mut().zip(s) {
            *y = match l.net.output_kind {
                OutputKind::Linear => s,
                OutputKind::Sigmoid => logistic(s),
            };
        }
    }
}

/// `loss` plus each row's (in row order), and ∂L/∂s of the outputs into
/// their δ columns: ∂L/∂out = M e (robust: / √(1 + r²/δ²)), times the
/// output's slope.
fn output_errors(
    l: &Layout<'_>,
    rows: Batch<'_>,
    span: Range<usize>,
    t: &mut Tile,
    mut loss: f64,
) -> f64 {
    let (h, o) = (l.net.n_hidden(), l.net.n_outputs);
    let (r0, len) = (span.start, span.len());
    for r in 0..len {
        for (k, e) in t.e.iter_mut().enumerate() {
            *e = t.out[k * TILE + r] - rows.y[(r0 + r, k)];
        }
        match rows.metric {
            Some(m) => {
                let m = &m[(r0 + r) * o * o..(r0 + r + 1) * o * o];
                for (i, me) in t.me.iter_mut().enumerate() {
                    *me = dot(&m[i * o..(i + 1) * o], &t.e);
                }
            }
            None => t.me.copy_from_slice(&t.e),
        }
        let r2 = dot(&t.e, &t.me);
        loss += match rows.delta {
            Some(delta) => {
                let root = (1.0 + r2 / (delta * delta)).sqrt();
                t.me.iter_mut().for_each(|v| *v /= root);
                delta * delta * (root - 1.0)
            }
            None => 0.5 * r2,
        };
        for (k, &me) in t.me.iter().enumerate() {
            let y = t.out[k * TILE + r];
            t.d[(h + k) * TILE + r] = match l.net.output_kind {
                OutputKind::Linear => me,
                OutputKind::Sigmoid => me * y * (1.0 - y),
            };
        }
    }
    for k in 0..o {
        t.d[(h + k) * TILE + len..(h + k + 1) * TILE].fill(0.0);
    }
    loss
}

/// δ of the hidden units, last first: δ_k = σ'(z_k) ⊙ Σ_{u>k} w_u[base+k] δ_u
/// (the later units' and the outputs' δ are complete when unit k's turn comes).
#[inline(always)]
fn backward<const FAST: bool>(l: &Layout<'_>, t: &mut Tile) {
    for k in (0..l.net.n_hidden()).rev() {
        let w = &l.consumers[k * l.units + k + 1..(k + 1) * l.units];
        let (head, later) = t.d.split_at_mut((k + 1) * TILE);
        let sum = combine::<FAST>(later, w);
        let z = &t.z[(l.base + k) * TILE..(l.base + k + 1) * TILE];
        for ((d, s), &z) in head[k * TILE..].iter_mut().zip(sum).zip(z) {
            *d = s * hidden_prime(z);
        }
    }
}

/// ∂L/∂w_u[j] += Σ_r δ_u[r] Z[r, j] for every weight: for each unit, its
/// weights' row of the gradient gains δ_u[r] times row r of the features,
/// four rows at a time, along the row (contiguous in `t.zt`).
#[inline(always)]
fn gradient<const FAST: bool>(l: &Layout<'_>, t: &mut Tile, grad: &mut [f64]) {
    let m = t.z.len() / TILE;
    for (j, col) in t.z.chunks_exact(TILE).enumerate() {
        for (r, &v) in col.iter().enumerate() {
            t.zt[r * m + j] = v;
        }
    }
    let all = l.net.hidden.iter().chain(&l.net.outputs);
    for (u, (w, &at)) in all.zip(&l.offsets).enumerate() {
        let g = &mut grad[at..at + w.len()];
        let d = &t.d[u * TILE..(u + 1) * TILE];
        for (d, z) in d.chunks_exact(4).zip(t.zt.chunks_exact(4 * m)) {
            let (z0, rest) = z.split_at(m);
            let (z1, rest) = rest.split_at(m);
            let (z2, z3) = rest.split_at(m);
            let rows = z0.iter().zip(z1).zip(z2).zip(z3);
            for (g, (((&a, &b), &c), &e)) in g.iter_mut().zip(rows) {
                let s = mac::<FAST>(d[0], a, *g);
                let s = mac::<FAST>(d[1], b, s);
                let s = mac::<FAST>(d[2], c, s);
                *g = mac::<FAST>(d[3], e, s);
            }
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::cascor::polish::{loss_and_gradient_per_row, RowMetrics, Rows};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random `inputs`-`hidden`-`outputs` cascade with weights of the
    /// polished nets' spread (|w| up to a few).
    fn random_net(inputs: usize, hidden: usize, outputs: usize, kind: OutputKind) -> GrowingNet {
        let mut rng = ChaCha8Rng::seed_from_u64(hidden as u64);
        let mut row = |len: usize| (0..len).map(|_| rng.random_range(-3.0..3.0)).collect();
        GrowingNet {
            n_inputs: inputs,
            n_outputs: outputs,
            hidden: (0..hidden).map(|k| row(1 + inputs + k)).collect(),
            outputs: (0..outputs).map(|_| row(1 + inputs + hidden)).collect(),
            output_kind: kind,
        }
    }

    /// `n` rows (not a whole number of tiles or blocks) and a symmetric
    /// positive definite metric per row, M = A Aᵀ + I.
    fn random_rows(
        n: usize,
        inputs: usize,
        outputs: usize,
    ) -> (DMatrix<f64>, DMatrix<f64>, RowMetrics) {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let x = DMatrix::from_fn(n, inputs, |_, _| rng.random_range(-1.0..1.0));
        let y = DMatrix::from_fn(n, outputs, |_, _| rng.random_range(0.0..1.0));
        let mut m = Vec::with_capacity(n * outputs * outputs);
        for _ in 0..n {
            let a: Vec<f64> = (0..outputs * outputs)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            for i in 0..outputs {
                for j in 0..outputs {
                    let aat: f64 = (0..outputs)
                        .map(|k| a[i * outputs + k] * a[j * outputs + k])
                        .sum();
                    m.push(aat + f64::from(u8::from(i == j)));
                }
            }
        }
        (x, y, RowMetrics { outputs, m })
    }

    fn batch<'a>(rows: Rows<'a>) -> Batch<'a> {
        Batch {
            x: rows.x,
            y: rows.y,
            metric: rows.metric.map(|m| &m.m[..]),
            delta: rows.delta,
        }
    }

    /// Every case of the loss: both output kinds, with and without the tip
    /// metric and the robust loss.
    fn each_case(mut check: impl FnMut(&GrowingNet, Rows<'_>, &str)) {
        let (x, y, m) = random_rows(1000, 5, 3);
        for kind in [OutputKind::Linear, OutputKind::Sigmoid] {
            let net = random_net(5, 12, 3, kind);
            for metric in [None, Some(&m)] {
                for delta in [None, Some(0.05)] {
                    let rows = Rows {
                        x: &x,
                        y: &y,
                        metric,
                        delta,
                    };
                    let case = format!("{kind}, metric {}, δ {delta:?}", metric.is_some());
                    check(&net, rows, &case);
                }
            }
        }
    }

    #[test]
    fn the_batched_loss_and_gradient_are_the_per_row_ones() {
        for fast in [false, cpu_has_fma()] {
            each_case(|net, rows, case| {
                let (loss, grad) = loss_and_gradient_with(fast, net, batch(rows), true);
                let (reference, want) = loss_and_gradient_per_row(net, rows, true);
                // Summed in another order (and fused): rounding apart.
                assert!(
                    (loss - reference).abs() <= 1e-13 * reference,
                    "{case}: loss {loss} vs {reference}"
                );
                let scale = want.iter().fold(0.0f64, |a, g| a.max(g.abs()));
                assert_eq!(grad.len(), want.len());
                for (k, (g, w)) in grad.iter().zip(&want).enumerate() {
                    assert!(
                        (g - w).abs() <= 1e-12 * scale,
                        "{case}, fast {fast}, weight {k}: {g} vs {w} (largest {scale})"
                    );
                }
                let (alone, none) = loss_and_gradient_with(fast, net, batch(rows), false);
                assert_eq!((alone.to_bits(), none.len()), (loss.to_bits(), 0));
            });
        }
    }

    #[test]
    fn the_fast_exp_is_the_librarys_within_two_ulps() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut xs: Vec<f64> = (0..100_000)
            .map(|i| {
                let wide = if i % 2 == 0 { 708.0 } else { 40.0 };
                rng.random_range(-wide..wide)
            })
            .collect();
        xs.extend([0.0, -0.0, 1.0, -1.0, 708.0, -708.0]);
        for x in xs {
            let (fast, lib) = (exp(x), x.exp());
            assert!(
                (fast - lib).abs() <= 2.0 * f64::EPSILON * lib,
                "e^{x}: {fast} vs {lib}"
            );
        }
        // Past the clamp: the activation saturates as the library's does.
        assert_eq!(activation::<true>(800.0), 0.5);
        assert!((activation::<true>(-800.0) + 0.5).abs() < 1e-300);
        assert!(activation::<true>(f64::NAN).is_nan());
    }

    #[test]
    fn the_portable_path_is_the_reference_loss_bit_for_bit() {
        // Each row's sums in the reference's order, the library's exp and
        // the rows in its blocks: only the fast path's fused multiply-adds
        // and polynomial exp may change a bit.
        each_case(|net, rows, case| {
            let (loss, _) = loss_and_gradient_with(false, net, batch(rows), false);
            let (reference, _) = loss_and_gradient_per_row(net, rows, false);
            assert_eq!(loss.to_bits(), reference.to_bits(), "{case}");
        });
    }

    #[test]
    fn a_net_without_hidden_units_or_rows_has_a_loss() {
        let (x, y, _) = random_rows(40, 2, 2);
        let net = random_net(2, 0, 2, OutputKind::Linear);
        let rows = Rows::plain(&x, &y);
        let (loss, grad) = loss_and_gradient_with(cpu_has_fma(), &net, batch(rows), true);
        let (reference, want) = loss_and_gradient_per_row(&net, rows, true);
        assert!((loss - reference).abs() <= 1e-13 * reference);
        assert!(grad
            .iter()
            .zip(&want)
            .all(|(g, w)| (g - w).abs() <= 1e-12 * (1.0 + w.abs())));
        let (ex, ey) = (DMatrix::zeros(0, 2), DMatrix::zeros(0, 2));
        let empty = loss_and_gradient(&net, batch(Rows::plain(&ex, &ey)), true);
        assert_eq!(empty, (0.0, vec![0.0; net.parameter_count()]));
    }
}
