//! The relaxed kernel with AVX2 and FMA: [`super::reference`] with the 64
//! pre-activations in eight registers, the chain unrolled (each unit's
//! lane and column offsets are constants), and each unit's column added
//! one unit late in program order (see `super`'s documentation). Bit for
//! bit the reference's result (tested).

use std::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_set1_ps, _mm256_setzero_ps,
    _mm256_storeu_ps,
};

use tendril_shared::{MAX_HIDDEN, POSE_DIM};

use super::reference::activate;
use super::{Columns, RelaxedNet, BLOCKS, LANES, OUT_LANES};

/// What the chain carries from one unit to the next.
struct Link {
    /// The newest term's numerator `w t P` and `1/Q` (unit j − 1's).
    wtp: f32,
    r: f32,
    /// The next unit's sum of every feature but the newest.
    older: f32,
    /// The previous unit's output, whose column is still to be added.
    pending: f32,
}

/// Every output's folded pre-activation (lanes past the net's outputs: 0).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn pre_outputs(net: &RelaxedNet, x: &[f32; POSE_DIM]) -> [f32; OUT_LANES] {
    match (net.hidden_tanh, net.outputs <= LANES) {
        (true, true) => chain::<true, 1>(net, x),
        (true, false) => chain::<true, 2>(net, x),
        (false, true) => chain::<false, 1>(net, x),
        (false, false) => chain::<false, 2>(net, x),
    }
}

/// The kernel for `tanh` (or linear) hidden units and `OV` registers of
/// outputs.
#[inline(always)]
unsafe fn chain<const TANH: bool, const OV: usize>(
    net: &RelaxedNet,
    x: &[f32; POSE_DIM],
) -> [f32; OUT_LANES] {
    let c = &*net.columns;
    let zero = _mm256_setzero_ps();
    let mut acc = [zero; BLOCKS];
    for (v, a) in acc.iter_mut().enumerate() {
        let (mut even, mut odd) = (load(&c.first[0], v), zero);
        for (i, &xi) in x.iter().enumerate() {
            let term = (load(&c.first[1 + i], v), _mm256_set1_ps(xi));
            if i % 2 == 0 {
                even = _mm256_fmadd_ps(term.0, term.1, even);
            } else {
                odd = _mm256_fmadd_ps(term.0, term.1, odd);
            }
        }
        *a = _mm256_add_ps(even, odd);
    }
    let mut o = [zero; OV];
    for (v, ov) in o.iter_mut().enumerate() {
        *ov = load(&c.out_first[0], v);
        for (i, &xi) in x.iter().enumerate() {
            *ov = _mm256_fmadd_ps(load(&c.out_first[1 + i], v), _mm256_set1_ps(xi), *ov);
        }
    }
    let mut link = Link {
        wtp: 0.0,
        r: 0.0,
        older: lane(acc[0], 0),
        pending: 0.0,
    };
    let n = net.blocks;
    // Each register's units with its index a constant; only the net's.
    macro_rules! blocks {
        ($($b:literal)*) => {$(
            if n > $b {
                block::<TANH, OV, $b>(c, &mut acc, &mut o, &mut link);
            }
        )*};
    }
    blocks!(0 1 2 3 4 5 6 7);
    if n > 0 {
        // The last unit's column: only the outputs still need it.
        let last = (n * LANES).min(MAX_HIDDEN) - 1;
        let g = _mm256_set1_ps(link.pending);
        for (v, ov) in o.iter_mut().enumerate() {
            *ov = _mm256_fmadd_ps(load(&c.out_hidden[last], v), g, *ov);
        }
    }
    let mut out = [0.0f32; OUT_LANES];
    for (v, ov) in o.iter().enumerate() {
        _mm256_storeu_ps(out[v * LANES..].as_mut_ptr(), *ov);
    }
    out
}

/// Units `8B … 8B + 7` (a register of `acc`). Left to the compiler as a
/// loop: unrolled by hand (each lane a constant), the code outgrew what
/// the compiler keeps in registers and ran 28 % slower (1.38 against
/// 1.08 µs, criterion, 2026-12-06).
#[inline(always)]
unsafe fn block<const TANH: bool, const OV: usize, const B: usize>(
    c: &Columns,
    acc: &mut [__m256; BLOCKS],
    o: &mut [__m256; OV],
    link: &mut Link,
) {
    for l in 0..LANES {
        let j = B * LANES + l;
        let s = link.wtp.mul_add(link.r, link.older);
        let (g, wtp, r) = activate(TANH, s, c.newest[j + 1]);
        link.wtp = wtp;
        link.r = r;
        // Unit j − 1's column, after unit j's chain: its lanes before
        // j + 1 are spent or get 0.
        if j > 0 {
            let gv = _mm256_set1_ps(link.pending);
            for (v, a) in acc.iter_mut().enumerate().skip((j - 1) / LANES) {
                *a = _mm256_fmadd_ps(load(&c.hidden[j - 1], v), gv, *a);
            }
            for (v, ov) in o.iter_mut().enumerate() {
                *ov = _mm256_fmadd_ps(load(&c.out_hidden[j - 1], v), gv, *ov);
            }
        }
        link.older = if l + 1 < LANES {
            lane(acc[B], l + 1)
        } else if B + 1 < BLOCKS {
            lane(acc[(B + 1) % BLOCKS], 0)
        } else {
            0.0
        };
        link.pending = g;
    }
}

/// Register `v` (lanes `8v … 8v + 7`) of a column.
#[inline(always)]
unsafe fn load<const N: usize>(column: &[f32; N], v: usize) -> __m256 {
    debug_assert!((v + 1) * LANES <= N);
    // SAFETY (caller's): `v` indexes a whole register of the column.
    _mm256_loadu_ps(column.as_ptr().add(v * LANES))
}

/// Lane `l` of a register (a constant after unrolling: a shuffle).
#[inline(always)]
fn lane(v: __m256, l: usize) -> f32 {
    // SAFETY: `__m256` is eight `f32`s.
    let lanes: [f32; LANES] = unsafe { std::mem::transmute(v) };
    lanes[l]
}
