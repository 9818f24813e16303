//! Cascade-correlation inference in `f32`: normalise the pose, run the
//! cascade, de-normalise to newtons. One code path for host and MCU, so the
//! two builds agree bit for bit (IEEE-754 `+`, `*`, `/` are exactly rounded
//! everywhere, the summation order is fixed by this code, and the sigmoids'
//! `exp` is `tendril_shared`'s own plain-`f32` polynomial, not a libm call).

use tendril_shared::CascadeNet;

/// The first `n` entries of `a`, or all of it (capacities are checked by the
/// decoder; this keeps indexing panic-free).
#[inline]
fn prefix(a: &[f32], n: usize) -> &[f32] {
    a.get(..n).unwrap_or(a)
}

/// Dot product over the common length of `w` and `a`, with four interleaved
/// partial sums (`s[i mod 4] += w_i a_i`, in index order) combined as
/// `(s0 + s1) + (s2 + s3)`, then the last `len mod 4` products added in order.
///
/// Four independent accumulators break the add-latency chain (the host build
/// runs several times faster); blocks of eight products let the M4 fetch
/// eight weights and eight activations with two `vldmia` ([`mac8`]). The
/// order of operations is fixed by this code, not by the compiler, so every
/// target computes the same roundings.
#[inline]
pub fn dot(w: &[f32], a: &[f32]) -> f32 {
    let n = w.len().min(a.len());
    let (w, a) = (prefix(w, n), prefix(a, n));
    let blocks = n / 8;
    let mut s = mac8(w, a, blocks);
    let done = blocks * 8;
    let (w_rest, a_rest) = (w.get(done..).unwrap_or(&[]), a.get(done..).unwrap_or(&[]));
    let w4 = w_rest.chunks_exact(4);
    let a4 = a_rest.chunks_exact(4);
    let (w_tail, a_tail) = (w4.remainder(), a4.remainder());
    for (wq, aq) in w4.zip(a4) {
        if let ([w0, w1, w2, w3], [a0, a1, a2, a3], [s0, s1, s2, s3]) = (wq, aq, &mut s) {
            *s0 += w0 * a0;
            *s1 += w1 * a1;
            *s2 += w2 * a2;
            *s3 += w3 * a3;
        }
    }
    let [s0, s1, s2, s3] = s;
    let mut sum = (s0 + s1) + (s2 + s3);
    for (x, y) in w_tail.iter().zip(a_tail) {
        sum += x * y;
    }
    sum
}

/// The four partial sums over the first `blocks` blocks of eight:
/// `s[i mod 4] += w_i a_i` for `i` in order. Callers guarantee both slices
/// hold at least `8 blocks` entries.
#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline]
fn mac8(w: &[f32], a: &[f32], blocks: usize) -> [f32; 4] {
    let n = blocks.saturating_mul(8);
    let (w, a) = (prefix(w, n), prefix(a, n));
    let mut s = [0.0f32; 4];
    // Lane j of the four sums only ever sees products j, j+4, j+8, … in
    // order, so a SIMD build (x86 SSE: one `mulps` + `addps` per four
    // products) rounds exactly like the scalar M4 code.
    for (wq, aq) in w.chunks_exact(8).zip(a.chunks_exact(8)) {
        if let (Ok(w8), Ok(a8)) = (<&[f32; 8]>::try_from(wq), <&[f32; 8]>::try_from(aq)) {
            for j in 0..4 {
                s[j] += w8[j] * a8[j];
            }
            for j in 0..4 {
                s[j] += w8[j + 4] * a8[j + 4];
            }
        }
    }
    s
}

/// Cortex-M4F version of [`mac8`]: the same operations in the same order,
/// in the assembly routine `tendril_mac8` below. LLVM emits one `vldr` per operand
/// (3 instructions per MAC); two `vldmia` and eight `vmla.f32` per block make
/// it 1.5. `vmla.f32` is the non-fused multiply-accumulate: the product is
/// rounded before the add, exactly like `s += w * a` in Rust (which LLVM
/// itself compiles to `vmla.f32`), so the results stay bit-identical to the
/// host build (the QEMU parity test checks).
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[inline]
fn mac8(w: &[f32], a: &[f32], blocks: usize) -> [f32; 4] {
    let blocks = blocks.min(w.len() / 8).min(a.len() / 8);
    if blocks == 0 {
        return [0.0; 4];
    }
    // SAFETY: both slices hold at least `8 blocks` f32s (clamped above) and
    // `blocks >= 1`, which is all `tendril_mac8` reads; it writes no memory
    // and follows the AAPCS-VFP calling convention.
    let s = unsafe { tendril_mac8(w.as_ptr(), a.as_ptr(), blocks) };
    [s.s0, s.s1, s.s2, s.s3]
}

/// Four partial sums, returned in `s0–s3` (an AAPCS-VFP homogeneous aggregate).
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[repr(C)]
struct Sums {
    s0: f32,
    s1: f32,
    s2: f32,
    s3: f32,
}

#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
extern "C" {
    /// `blocks` (≥ 1) blocks of eight `s[i mod 4] += w_i a_i` from zero.
    fn tendril_mac8(w: *const f32, a: *const f32, blocks: usize) -> Sums;
}

#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
core::arch::global_asm!(
    ".syntax unified",
    ".fpu fpv4-sp-d16",
    ".thumb",
    ".section .text.tendril_mac8,\"ax\",%progbits",
    ".global tendril_mac8",
    ".type tendril_mac8,%function",
    ".thumb_func",
    "tendril_mac8:",
    "    vpush {{s16-s19}}",
    "    movs r3, #0",
    "    vmov s0, s1, r3, r3",
    "    vmov s2, s3, r3, r3",
    "1:",
    "    vldmia r0!, {{s4-s11}}",
    "    vldmia r1!, {{s12-s19}}",
    "    vmla.f32 s0, s4, s12",
    "    vmla.f32 s1, s5, s13",
    "    vmla.f32 s2, s6, s14",
    "    vmla.f32 s3, s7, s15",
    "    vmla.f32 s0, s8, s16",
    "    vmla.f32 s1, s9, s17",
    "    vmla.f32 s2, s10, s18",
    "    vmla.f32 s3, s11, s19",
    "    subs r2, #1",
    "    bne 1b",
    "    vpop {{s16-s19}}",
    "    bx lr",
    ".size tendril_mac8, .-tendril_mac8",
);

/// The feature vector every unit dots its row with: `[1 (bias), x̂…, h…]`,
/// laid out like [`tendril_shared::Unit`] so one slice covers it.
#[repr(C)]
struct Features<const IN: usize, const H: usize> {
    one: f32,
    x: [f32; IN],
    h: [f32; H],
}

impl<const IN: usize, const H: usize> Features<IN, H> {
    fn as_slice(&self) -> &[f32] {
        const {
            assert!(core::mem::size_of::<Self>() == 4 * (1 + IN + H));
            assert!(core::mem::align_of::<Self>() == core::mem::align_of::<f32>());
        }
        // SAFETY: `#[repr(C)]`, only `f32`s, no padding (checked above):
        // `1 + IN + H` contiguous initialised `f32`s; provenance from the
        // whole struct.
        unsafe { core::slice::from_raw_parts((self as *const Self).cast::<f32>(), 1 + IN + H) }
    }
}

/// `len` rounded up to a multiple of 8, at most `cap`. Dotting a unit's row
/// past its used length adds only `0 × 0` terms (unused weights are zero and
/// so are the features of hidden units not yet computed), so the value is
/// unchanged, and whole blocks of eight are cheaper on the M4 than a tail.
#[inline]
fn padded_len(len: usize, cap: usize) -> usize {
    len.div_ceil(8).saturating_mul(8).min(cap)
}

/// Normalise `x` into the net's input box: `(x − lo) / (hi − lo)`, entries
/// past the net's input count set to 0.
#[inline]
pub fn normalise<const IN: usize, const H: usize, const OUT: usize>(
    net: &CascadeNet<IN, H, OUT>,
    x: &[f32; IN],
) -> [f32; IN] {
    let mut xn = [0.0f32; IN];
    let ranges = net.input_lo().iter().zip(net.input_hi());
    for ((v, &xi), (&lo, &hi)) in xn.iter_mut().zip(x).zip(ranges) {
        *v = (xi - lo) / (hi - lo);
    }
    xn
}

/// Tensions (newtons) the net predicts for pose `x` (`px, py, pz` in m,
/// `qw, qx, qy, qz`); outputs past the net's output count are 0.
///
/// Unit `k` computes `act(row_k · [1, x̂, h_0 … h_{k−1}])` over its
/// `1 + IN + k` used weights (inputs past the net's count are 0 in both),
/// padded with zero terms to a multiple of 8 ([`padded_len`]).
/// No checks on `x`: a NaN or huge pose gives NaN or extrapolated tensions,
/// which the control step filters. An empty net gives all zeros.
pub fn infer<const IN: usize, const H: usize, const OUT: usize>(
    net: &CascadeNet<IN, H, OUT>,
    x: &[f32; IN],
) -> [f32; OUT] {
    let mut f = Features {
        one: 1.0,
        x: normalise(net, x),
        h: [0.0f32; H],
    };
    let hidden_act = net.hidden_activation();
    for (k, unit) in net.hidden_units().iter().enumerate() {
        let len = padded_len(1 + IN + k, 1 + IN + H);
        let s = dot(prefix(unit.as_slice(), len), prefix(f.as_slice(), len));
        if let Some(slot) = f.h.get_mut(k) {
            *slot = hidden_act.apply(s);
        }
    }
    let len = padded_len(1 + IN + net.shape().hidden, 1 + IN + H);
    let feats = prefix(f.as_slice(), len);
    let out_act = net.output_activation();
    let mut y = [0.0f32; OUT];
    let ranges = net.output_lo().iter().zip(net.output_hi());
    for ((yo, unit), (&lo, &hi)) in y.iter_mut().zip(net.output_units()).zip(ranges) {
        let s = dot(prefix(unit.as_slice(), len), feats);
        *yo = lo + out_act.apply(s) * (hi - lo);
    }
    y
}
