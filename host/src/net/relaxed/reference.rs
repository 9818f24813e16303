//! The relaxed kernel in plain Rust: the statement of what the AVX2 kernel
//! (`super::avx2`) computes, operation for operation and so bit for bit
//! (`mul_add` is the fused multiply-add there too). It runs where the
//! AVX2 one cannot (not x86-64), and it is that kernel's test.

#[cfg(any(test, not(target_arch = "x86_64")))]
use tendril_shared::{MAX_HIDDEN, POSE_DIM};

use super::tanh_parts;
#[cfg(any(test, not(target_arch = "x86_64")))]
use super::{RelaxedNet, LANES, OUT_LANES};

/// Every output's folded pre-activation (lanes past the net's outputs: 0).
#[cfg(any(test, not(target_arch = "x86_64")))]
pub(super) fn pre_outputs(net: &RelaxedNet, x: &[f32; POSE_DIM]) -> [f32; OUT_LANES] {
    let c = &*net.columns;
    // Each unit's sum of the bias and the inputs, the even and the odd
    // inputs apart and then added: a shorter chain before unit 0.
    let mut acc = [0.0f32; MAX_HIDDEN];
    for (k, a) in acc.iter_mut().enumerate() {
        let (mut even, mut odd) = (c.first[0][k], 0.0f32);
        for (i, &xi) in x.iter().enumerate() {
            let w = c.first[1 + i][k];
            if i % 2 == 0 {
                even = w.mul_add(xi, even);
            } else {
                odd = w.mul_add(xi, odd);
            }
        }
        *a = even + odd;
    }
    let mut o = c.out_first[0];
    for (i, &xi) in x.iter().enumerate() {
        for (oq, &w) in o.iter_mut().zip(&c.out_first[1 + i]) {
            *oq = w.mul_add(xi, *oq);
        }
    }
    // The chain. Unit j's pre-activation is its sum so far plus the newest
    // term, unit j − 1's (w tP)·(1/Q); its output g_j then joins every
    // later unit's sum (k ≥ j + 2: unit j + 1 takes it as its newest) and
    // the outputs'.
    let (mut wtp, mut r) = (0.0f32, 0.0f32);
    for j in 0..net.blocks * LANES {
        let s = wtp.mul_add(r, acc[j]);
        let g;
        (g, wtp, r) = activate(net.hidden_tanh, s, c.newest[j + 1]);
        for (a, &w) in acc.iter_mut().zip(&c.hidden[j]).skip(j + 2) {
            *a = w.mul_add(g, *a);
        }
        for (oq, &w) in o.iter_mut().zip(&c.out_hidden[j]) {
            *oq = w.mul_add(g, *oq);
        }
    }
    o
}

/// A hidden unit's output `g` from its pre-activation `s`, with the next
/// unit's newest term `w g` as `(numerator, 1/Q)`: for a `tanh` unit
/// [`tanh_parts`], for a linear one `(s, w s, 1)`.
#[inline(always)]
pub(super) fn activate(tanh: bool, s: f32, w: f32) -> (f32, f32, f32) {
    if tanh {
        let (tp, wtp, r) = tanh_parts(s, w);
        (tp * r, wtp, r)
    } else {
        (s, w * s, 1.0)
    }
}
