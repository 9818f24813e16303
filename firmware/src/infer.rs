//! Cascade-correlation inference in `f32`: normalise the pose, run the
//! cascade, de-normalise to newtons. One code path for host and MCU, so the
//! two builds agree bit for bit (IEEE-754 `+`, `*`, `/` are exactly rounded
//! everywhere, the summation order is fixed by this code, and the sigmoids'
//! `exp` is `tendril_shared`'s own plain-`f32` polynomial, not a libm call).

use tendril_shared::net::ROW_PAD;
use tendril_shared::{weight_capacity, Activation, CascadeNet};

/// Dot product over the first `8 ⌊n/8⌋` products of the common length `n`
/// of `w` and `a`, with four interleaved partial sums (`s[i mod 4] += w_i a_i`,
/// in index order) combined as `(s0 + s1) + (s2 + s3)`.
///
/// Four independent accumulators break the add-latency chain (the host build
/// runs several times faster); blocks of eight products let the M4 fetch
/// eight weights and eight activations with two `vldmia`. The order of
/// operations is fixed by this code, not by the compiler, so every target
/// computes the same roundings. The inference runs every row through this
/// (rows are padded to whole blocks); on the M4 it is one call to the
/// assembly kernel `tendril_dot8`, which also does the reduction.
#[inline]
pub fn dot8(w: &[f32], a: &[f32]) -> f32 {
    let blocks = w.len().min(a.len()) / 8;
    dot8_blocks(w, a, blocks)
}

#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline]
fn dot8_blocks(w: &[f32], a: &[f32], blocks: usize) -> f32 {
    let [s0, s1, s2, s3] = mac8(w, a, blocks);
    (s0 + s1) + (s2 + s3)
}

/// Cortex-M4F version: the same operations in the same order, in the
/// assembly routine `tendril_dot8` below. LLVM would emit one `vldr` per
/// operand (3 instructions per MAC); two `vldmia` and eight `vmla.f32` per
/// block make it 1.5. `vmla.f32` is the non-fused multiply-accumulate: the
/// product is rounded before the add, exactly like `s += w * a` in Rust, so
/// the results stay bit-identical to the host build (the QEMU parity test
/// checks).
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[inline]
fn dot8_blocks(w: &[f32], a: &[f32], blocks: usize) -> f32 {
    let blocks = blocks.min(w.len() / 8).min(a.len() / 8);
    // SAFETY: both slices hold at least `8 blocks` f32s (clamped above),
    // which is all `tendril_dot8` reads (nothing for `blocks == 0`); it
    // writes no memory and follows the AAPCS-VFP calling convention.
    unsafe { tendril_dot8(w.as_ptr(), a.as_ptr(), blocks) }
}

/// The four partial sums over the first `blocks` blocks of eight:
/// `s[i mod 4] += w_i a_i` for `i` in order. Callers guarantee both slices
/// hold at least `8 blocks` entries.
#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline]
fn mac8(w: &[f32], a: &[f32], blocks: usize) -> [f32; 4] {
    let (w8, a8) = (blocks_of_8(w), blocks_of_8(a));
    let (w8, a8) = (
        w8.get(..blocks).unwrap_or(w8),
        a8.get(..blocks).unwrap_or(a8),
    );
    let [mut s0, mut s1, mut s2, mut s3] = [0.0f32; 4];
    // Lane j of the four sums only ever sees products j, j+4, j+8, … in
    // order, so a SIMD build (x86 SSE: one `mulps` + `addps` per four
    // products) rounds exactly like the scalar M4 code.
    for (w8, a8) in w8.iter().zip(a8) {
        let [w0, w1, w2, w3, w4, w5, w6, w7] = *w8;
        let [a0, a1, a2, a3, a4, a5, a6, a7] = *a8;
        s0 += w0 * a0;
        s1 += w1 * a1;
        s2 += w2 * a2;
        s3 += w3 * a3;
        s0 += w4 * a4;
        s1 += w5 * a5;
        s2 += w6 * a6;
        s3 += w7 * a7;
    }
    [s0, s1, s2, s3]
}

/// The whole blocks of eight at the start of `s` (what `<[f32]>::as_chunks`
/// gives from Rust 1.88 on; the workspace supports 1.85). Iterating arrays
/// instead of `chunks_exact` + `try_from` lets the host build drop the
/// per-block length checks (−20 % instructions per inference).
#[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
#[inline]
fn blocks_of_8(s: &[f32]) -> &[[f32; 8]] {
    // SAFETY: `[f32; 8]` has the size of 8 `f32`s and their alignment, the
    // first `8 (len / 8)` entries of `s` are initialised `f32`s, and the
    // result borrows `s`.
    unsafe { core::slice::from_raw_parts(s.as_ptr().cast::<[f32; 8]>(), s.len() / 8) }
}

#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
extern "C" {
    /// `blocks` (≥ 0) blocks of eight, reduced: `(s0 + s1) + (s2 + s3)`.
    fn tendril_dot8(w: *const f32, a: *const f32, blocks: usize) -> f32;
}

#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
core::arch::global_asm!(
    ".syntax unified",
    ".fpu fpv4-sp-d16",
    ".thumb",
    ".section .text.tendril_dot8,\"ax\",%progbits",
    ".global tendril_dot8",
    ".type tendril_dot8,%function",
    ".thumb_func",
    "tendril_dot8:",
    "    vpush {{s16-s19}}",
    "    movs r3, #0",
    "    vmov s0, s1, r3, r3",
    "    vmov s2, s3, r3, r3",
    "    cbz r2, 2f",
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
    "2:",
    "    vadd.f32 s0, s0, s1",
    "    vadd.f32 s2, s2, s3",
    "    vadd.f32 s0, s0, s2",
    "    vpop {{s16-s19}}",
    "    bx lr",
    ".size tendril_dot8, .-tendril_dot8",
);

/// The feature vector every unit dots its row with: `[1 (bias), x̂…, h…]`,
/// then [`ROW_PAD`] zeros so a row's dot product rounded up to a multiple of
/// 8 terms stays inside it.
#[repr(C)]
struct Features<const IN: usize, const H: usize> {
    one: f32,
    x: [f32; IN],
    h: [f32; H],
    pad: [f32; ROW_PAD],
}

impl<const IN: usize, const H: usize> Features<IN, H> {
    const LEN: usize = 1 + IN + H + ROW_PAD;

    fn as_slice(&self) -> &[f32] {
        const {
            assert!(core::mem::size_of::<Self>() == 4 * Self::LEN);
            assert!(core::mem::align_of::<Self>() == core::mem::align_of::<f32>());
        }
        // SAFETY: `#[repr(C)]`, only `f32`s, no padding (checked above):
        // `LEN` contiguous initialised `f32`s; provenance from the whole
        // struct.
        unsafe { core::slice::from_raw_parts((self as *const Self).cast::<f32>(), Self::LEN) }
    }
}

/// Normalise `x` into the net's input box: `(x − lo) / (hi − lo)`, entries
/// past the net's input count set to 0.
#[inline]
pub fn normalise<const IN: usize, const H: usize, const OUT: usize, const W: usize>(
    net: &CascadeNet<IN, H, OUT, W>,
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
/// Walks the packed weights ([`CascadeNet::weights`]) row by row: hidden
/// unit `k` computes `act(row_k · [1, x̂, h_0 … h_{k−1}])` over its
/// `1 + IN + k` weights, then each output dots its `1 + IN + H` weights with
/// `[1, x̂, h…]`.
///
/// Every dot product runs over the row length rounded up to a multiple of
/// 8, so it reads up to 7 weights past the row's end: the
/// next row's first weights, or the zero padding after the last row. That
/// is exact: the features those weights meet are hidden units not computed
/// yet (still 0, since unit `k` sees only `h_0 … h_{k−1}`), hidden units the
/// net does not have, or the feature vector's zero padding; and every stored
/// weight is finite (the decoder rejects NaN/∞, unused storage is 0), so each
/// extra product is ±0, and `s + ±0 = s` (at most the sign of a zero sum
/// changes, which no activation or de-normalisation can see). Host and MCU
/// run the same padded sums in the same order, so they agree bit for bit.
///
/// No checks on `x`: a NaN or huge pose gives NaN or extrapolated tensions,
/// which the control step filters. An empty net (no outputs) gives all
/// zeros, as it has no output to compute.
///
/// There is no bad-shape case to report: a `CascadeNet` exists only with a
/// shape whose weights fit its store (every constructor checks), and the
/// inference checks that bound once more before its unchecked reads (a net
/// that failed it would give all zeros), so every padded read is in bounds
/// for every value of the type.
pub fn infer<const IN: usize, const H: usize, const OUT: usize, const W: usize>(
    net: &CascadeNet<IN, H, OUT, W>,
    x: &[f32; IN],
) -> [f32; OUT] {
    let shape = net.shape();
    // `min` is a no-op for every net a constructor made (hidden ≤ H); it
    // keeps the feature reads below inside `f` for the type itself.
    let nh = shape.hidden.min(H);
    let no = net.output_lo().len().min(OUT);
    let w: &[f32] = net.weights();
    // The store bounds a net by its weights, not by `H` and `OUT` at once
    // (a 7-63-9 net fits the store of a 7-64-8 one), so the bound of the
    // padded reads is this net's own: every constructor checks it, and this
    // one comparison makes the unchecked reads below safe whatever the value.
    if weight_capacity(IN, nh, no) > w.len() {
        return [0.0; OUT];
    }
    let out_start = CascadeNet::<IN, H, OUT, W>::hidden_row_offset(nh);
    let row_len = 1 + IN + nh;
    // Row `r` (hidden or output) starts at `start_r` and its padded dot
    // product reads `[start_r, start_r + 8⌈len_r/8⌉) ⊂ [start_r, start_r +
    // len_r + 7)` of the weights, all inside `[0, out_start + no·row_len +
    // ROW_PAD) = [0, weight_capacity(IN, nh, no)) ⊂ [0, w.len())` (checked
    // above), and `[0, 8⌈len_r/8⌉) ⊂ [0, 1 + IN + nh + 7)` of the features.
    let mut f = Features {
        one: 1.0,
        x: normalise(net, x),
        h: [0.0f32; H],
        pad: [0.0f32; ROW_PAD],
    };
    // One loop per activation: no dispatch inside the hot loop.
    match net.hidden_activation() {
        Activation::Linear => hidden_layer(w, &mut f, nh, |s| s),
        Activation::Sigmoid => hidden_layer(w, &mut f, nh, |s| Activation::Sigmoid.apply(s)),
        Activation::SymmetricSigmoid => {
            hidden_layer(w, &mut f, nh, |s| Activation::SymmetricSigmoid.apply(s))
        }
    }
    let blocks = row_len.div_ceil(8);
    let feats = f.as_slice();
    let out_act = net.output_activation();
    let mut y = [0.0f32; OUT];
    let ranges = net.output_lo().iter().zip(net.output_hi()).take(no);
    let mut start = out_start;
    for (yo, (&lo, &hi)) in y.iter_mut().zip(ranges) {
        // SAFETY: output row `o` starts at `out_start + o·row_len` with
        // `o < no` (`y` zips with the `no` output ranges); its padded read
        // is inside `w` and the features by the bound above.
        let s = unsafe { dot8_raw(w.as_ptr().add(start), feats.as_ptr(), blocks) };
        start += row_len;
        *yo = lo + out_act.apply(s) * (hi - lo);
    }
    y
}

/// The cascade's hidden units in order: `h_k = act(row_k · features)`, each
/// row's dot product padded to whole blocks of 8. The caller guarantees
/// that the `nh` rows and their padding lie inside `w` ([`infer`]).
#[inline(always)]
fn hidden_layer<const IN: usize, const H: usize>(
    w: &[f32],
    f: &mut Features<IN, H>,
    nh: usize,
    act: impl Fn(f32) -> f32,
) {
    let mut start = 0;
    for k in 0..nh.min(H) {
        let row_len = 1 + IN + k;
        // SAFETY: row `k < nh` and its padding lie inside `w`, and the
        // first `8⌈row_len/8⌉ ≤ 1 + IN + H + 7` features inside `f`, by
        // `infer`'s bound; the pointers are taken afresh for each row.
        let s = unsafe {
            dot8_raw(
                w.as_ptr().add(start),
                f.as_slice().as_ptr(),
                row_len.div_ceil(8),
            )
        };
        start += row_len;
        if let Some(slot) = f.h.get_mut(k) {
            *slot = act(s);
        }
    }
}

/// [`dot8`] over `8 blocks` entries at raw pointers, without bounds checks
/// (the inference's layout is in bounds by construction, see [`infer`]).
///
/// # Safety
/// `w` and `a` must be valid for reads of `8 blocks` `f32`s.
#[inline(always)]
unsafe fn dot8_raw(w: *const f32, a: *const f32, blocks: usize) -> f32 {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        // SAFETY: the caller's contract is `tendril_dot8`'s.
        unsafe { tendril_dot8(w, a, blocks) }
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    {
        let n = 8 * blocks;
        // SAFETY: the caller guarantees `n` readable `f32`s at each pointer.
        let (w, a) = unsafe {
            (
                core::slice::from_raw_parts(w, n),
                core::slice::from_raw_parts(a, n),
            )
        };
        dot8_blocks(w, a, blocks)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::needless_range_loop)] // index loops read like the formulas here

    use std::vec::Vec;

    use crate::infer::{dot8, infer};

    use crate::synth::{SplitMix64, INPUT_HI, INPUT_LO};

    use crate::test_support::*;

    /// The store bounds a net by its weights: the MCU's net type takes the
    /// nine-tendon net with the most units that fit (7-63-9), infers it as the
    /// f64 reference says, and refuses one unit more (7-64-9).
    #[test]
    fn nine_outputs_fit_the_store_with_one_unit_fewer() {
        use tendril_shared::{max_hidden_for, McuNet, TnetError};
        let h = max_hidden_for(9);
        assert_eq!(h, 63);
        let net = McuNet::decode(&blob(21, h, 9)).unwrap();
        let mut rng = SplitMix64(5);
        for _ in 0..50 {
            let mut x = [0.0f32; 7];
            for i in 0..7 {
                x[i] = rng.uniform(INPUT_LO[i], INPUT_HI[i]);
            }
            let y = infer(&net, &x);
            let r = reference(21, h, 9, &x);
            for o in 0..9 {
                assert!(
                    (y[o] as f64 - r[o]).abs() < 1e-4 * (1.0 + r[o].abs()),
                    "{o}"
                );
            }
        }
        assert!(matches!(
            McuNet::decode(&blob(21, h + 1, 9)),
            Err(TnetError::ShapeOverCapacity { .. })
        ));
    }

    #[test]
    fn dot8_matches_a_plain_sum_over_whole_blocks_for_every_length() {
        for n in 0..42 {
            let w: Vec<f32> = (0..n).map(|i| 0.5 - 0.1 * i as f32).collect();
            let a: Vec<f32> = (0..n).map(|i| 1.0 + 0.25 * i as f32).collect();
            // Only the first 8 ⌊n/8⌋ products count.
            let whole = n / 8 * 8;
            let exact: f64 = w[..whole]
                .iter()
                .zip(&a[..whole])
                .map(|(x, y)| *x as f64 * *y as f64)
                .sum();
            assert!((dot8(&w, &a) as f64 - exact).abs() < 1e-4, "n={n}");
            // The longer slice's extra entries are ignored.
            let mut longer = a.clone();
            longer.extend([1e30; 8]);
            assert_eq!(dot8(&w, &longer), dot8(&w, &a));
        }
    }

    #[test]
    fn inference_matches_an_f64_reference_of_the_documented_layout() {
        let mut rng = SplitMix64(99);
        let cases = [
            (1u64, 0usize, 4usize),
            (2, 1, 1),
            (3, 12, 4),
            (4, 16, 8),
            (5, 64, 8),
            (6, 63, 3),
            (7, 9, 4),
        ];
        for &(seed, hidden, outputs) in &cases {
            let b = blob(seed, hidden, outputs);
            // Every case through the 64-unit MCU capacity; those that fit also
            // through the 16-unit one (a different packing: same result).
            let net = Net64::decode(&b).unwrap();
            let small = Net::decode(&b).ok();
            for _ in 0..50 {
                let mut x = [0.0f32; 7];
                for i in 0..7 {
                    x[i] = rng.uniform(INPUT_LO[i], INPUT_HI[i]);
                }
                let y = infer(&net, &x);
                if let Some(small) = &small {
                    assert_eq!(infer(small, &x), y);
                }
                let r = reference(seed, hidden, outputs, &x);
                for o in 0..outputs {
                    let tol = 1e-4 * (1.0 + r[o].abs());
                    assert!(
                        (y[o] as f64 - r[o]).abs() < tol,
                        "{seed} {o}: {} vs {}",
                        y[o],
                        r[o]
                    );
                }
                assert!(y[outputs..].iter().all(|&v| v == 0.0));
            }
        }
    }

    #[test]
    fn one_hidden_unit_by_hand() {
        // 7-1-1 net with weights from the seed; check the closed form at the box
        // centre, where every normalised input is exactly 0.5.
        let seed = 5;
        let net = Net::decode(&blob(seed, 1, 1)).unwrap();
        let mut rng = SplitMix64(seed);
        let w: Vec<f32> = (0..8 + 9).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let s_h: f64 = w[0] as f64 + 0.5 * w[1..8].iter().map(|&v| v as f64).sum::<f64>();
        let h = 1.0 / (1.0 + (-s_h).exp()) - 0.5;
        let s_o =
            w[8] as f64 + 0.5 * w[9..16].iter().map(|&v| v as f64).sum::<f64>() + w[16] as f64 * h;
        let y = infer(&net, &box_centre());
        assert!(
            (y[0] as f64 - 10.0 * s_o).abs() < 1e-5,
            "{} vs {}",
            y[0],
            10.0 * s_o
        );
    }

    #[test]
    fn empty_net_infers_zeros() {
        assert_eq!(infer(&Net::empty(), &mid_pose()), [0.0; 8]);
    }
}
