//! Single-query inference for latency (issue 29, item 2; issue 48, item 2):
//! [`RelaxedNet`], the same net with *relaxed* arithmetic — not
//! bit-identical to the firmware: each unit within ~2e-7 of the firmware's,
//! which a trained net amplifies as it amplifies the firmware's own
//! rounding — for callers that want one answer fast and make no parity
//! claim.
//!
//! # Why a second path
//! One query through a cascade is a dependency chain: unit k needs unit
//! k − 1. With the firmware's arithmetic each link is a product, a
//! four-sum reduction and the sigmoid's clamp, range reduction, degree-5
//! Horner polynomial and division — about 100 cycles, 64 of them in a row
//! ([`super::HostNet`]). Here each link is only what the chain cannot
//! avoid, and everything else runs beside it:
//!
//! - **columns, not rows.** Every unit's pre-activation is kept in a
//!   vector `acc` (64 lanes, eight AVX registers). When unit j's output
//!   `g_j` exists, its column is added to every later unit at once (one
//!   broadcast, up to eight vector FMAs, no horizontal sums), so unit k's
//!   sum of every feature but the newest is ready long before unit k − 1
//!   is. The newest enters last, in one fused multiply-add.
//! - **the `tanh` split around the chain.** The activation is a rational
//!   `tanh(t) = t P(t²) / Q(t²)` ([`tanh_parts`]); the next unit needs only
//!   `w · tanh(t)`, which is `(w t P) · (1/Q)`: the product `w t` and the
//!   division run beside the polynomial, and the final product folds into
//!   the next unit's FMA. A link is then `t²`, Estrin's scheme for `Q`, the
//!   division and one FMA: ≈ 29 cycles on the VM's Zen 1 (measured 11.7 ns
//!   at ≈ 2.5 GHz), against ≈ 48 for the row layout this replaced.
//! - **the column work after the chain in source order**: unit j's column
//!   is written after unit j + 1's activation, so that the CPU's scheduler
//!   (oldest first) favours the chain (7–15 % faster in a throwaway
//!   harness on the VM's Zen 1; the compiler may still move the
//!   instructions, and the gain in the kernel itself was not isolated).
//! - the factors that turn `tanh` into the net's sigmoids are folded into
//!   the weights once, when the net is built (see [`Unit`]).
//!
//! [`reference`] is the same algorithm in plain Rust, operation for
//! operation: the readable statement of what the AVX2 kernel (`avx2`)
//! computes, and its test (bit for bit).
//!
//! # Where it may differ, and where it may not
//! The firmware, the QEMU parity, the trace replay, `tendril evaluate`,
//! `compare`'s predictions, `tendril ik` and the Python `Net` all claim the
//! deployed arithmetic and use the bit-identical paths. This one is for
//! single answers where the last bits do not matter (an IK's starting
//! guess, a planner's preview, `compare`'s timing column). The test
//! (`net::fast`) bounds its distance from an exact `f64` evaluation of the
//! same weights by three times the firmware's own (on the default net the
//! firmware sits ~1e-4 of the output range from it).
//!
//! # The folding
//! With `g = tanh(t)`, the symmetric sigmoid is `σ(s) − ½ = ½ tanh(s/2)`
//! and the logistic `σ(s) = ½ + ½ tanh(s/2)`, so unit k stores `g_k =
//! tanh(t_k)` with `t_k = s_k / 2`: its row is halved, and each consumer's
//! weight on `h_k = a + b g_k` becomes `w b` with `w a` added to its bias.
//! Scaling by ½ is exact; the bias shift is one rounding.

#[cfg(target_arch = "x86_64")]
mod avx2;
mod reference;

use tendril_shared::{Activation, McuNet, MAX_HIDDEN, MAX_TENDONS, POSE_DIM};

use super::ranges::Ranges;

/// `f32` lanes of one AVX register.
const LANES: usize = 8;
/// Registers that hold every hidden unit's pre-activation.
const BLOCKS: usize = MAX_HIDDEN / LANES;
/// Registers that hold every output's pre-activation.
const OUT_VECTORS: usize = MAX_TENDONS.div_ceil(LANES);
/// Output lanes, [`MAX_TENDONS`] rounded up to whole registers.
const OUT_LANES: usize = OUT_VECTORS * LANES;
const _: () = assert!(
    MAX_HIDDEN.is_multiple_of(LANES),
    "the hidden units fill whole registers"
);

/// `|t|` past which `tanh(t)` is 1 in `f32` to within half an ulp: the
/// rational below is fitted on `[0, TANH_CLAMP]` and the input clamped to it.
const TANH_CLAMP: f32 = 9.0;

/// `tanh(t) ≈ t P(t²) / Q(t²)` on `|t| ≤ 9`: `P` of degree 5 and `Q` of
/// degree 3 in `t²`, fitted by iterated weighted least squares on the
/// absolute error (`scripts/fit-tanh`, 2026-12-03). The `f64` fit is within
/// 5e-8 of `tanh`; evaluated in `f32` as [`tanh_parts`] does, with these
/// rounded coefficients, within 3.6e-7 (the rounding of `t²` and of the
/// coefficients dominates).
const TANH_P: [f32; 6] = [
    0.999_999_76,
    0.129_106_61,
    0.002_911_971_2,
    9.194_887e-6,
    -1.259_071_9e-8,
    1.783_728_7e-11,
];
/// The denominator's coefficients, see [`TANH_P`].
const TANH_Q: [f32; 4] = [1.0, 0.462_438_94, 0.023_726_072, 2.269_378_7e-4];

/// How a unit's stored value `g` relates to the firmware's `h`:
/// `h = a + b g`, and `g` is `tanh(scale · s)` or, for a linear unit, `s`.
#[derive(Clone, Copy, Debug)]
struct Unit {
    /// Added to `b g` to give the firmware's value.
    a: f32,
    /// Multiplies `g`.
    b: f32,
    /// Multiplies the unit's pre-activation before the `tanh`.
    scale: f32,
    /// Whether the unit applies the `tanh` at all (not for `Linear`).
    tanh: bool,
}

impl Unit {
    fn of(act: Activation) -> Unit {
        match act {
            Activation::Linear => Unit {
                a: 0.0,
                b: 1.0,
                scale: 1.0,
                tanh: false,
            },
            Activation::Sigmoid => Unit {
                a: 0.5,
                b: 0.5,
                scale: 0.5,
                tanh: true,
            },
            Activation::SymmetricSigmoid => Unit {
                a: 0.0,
                b: 0.5,
                scale: 0.5,
                tanh: true,
            },
        }
    }
}

/// The folded weights by column: what each feature adds to each unit it
/// feeds. Fixed sizes (the firmware's capacities), zero where the net has
/// no weight, so the kernels index without bounds and a smaller net is a
/// 64-unit net whose extra units are 0 (`tanh(0) = 0`, no outgoing weight).
#[derive(Clone, Debug)]
struct Columns {
    /// The bias (feature 0) and each input's weight into every hidden unit.
    first: [[f32; MAX_HIDDEN]; 1 + POSE_DIM],
    /// Hidden unit j's weight into unit k, for k ≥ j + 2 (0 elsewhere: unit
    /// j + 1's weight on it is [`Columns::newest`]).
    hidden: [[f32; MAX_HIDDEN]; MAX_HIDDEN],
    /// `newest[k]`: unit k's weight on unit k − 1 (0 for k = 0 and past the
    /// last unit).
    newest: [f32; MAX_HIDDEN + 1],
    /// The bias and each input's weight into every output.
    out_first: [[f32; OUT_LANES]; 1 + POSE_DIM],
    /// Hidden unit j's weight into every output.
    out_hidden: [[f32; OUT_LANES]; MAX_HIDDEN],
}

/// A net with its weights folded and transposed for [`RelaxedNet::infer_one`].
/// Built once per net by [`super::HostNet::new`] on CPUs with AVX2 and FMA.
#[derive(Clone, Debug)]
pub(super) struct RelaxedNet {
    inputs: usize,
    /// Registers of hidden units the net fills (⌈hidden / 8⌉).
    blocks: usize,
    outputs: usize,
    hidden_tanh: bool,
    output: Unit,
    ranges: Ranges,
    /// 1 / the input widths: a multiply per input instead of a divide.
    in_inv_width: [f32; POSE_DIM],
    columns: Box<Columns>,
}

impl RelaxedNet {
    /// The folded net, or `None` if this CPU lacks AVX2 and FMA (the kernel
    /// needs hardware fused multiply-adds: in software they are slow).
    pub(super) fn new(net: &McuNet) -> Option<RelaxedNet> {
        if !cpu_has_fma() {
            return None;
        }
        Some(Self::folded(net))
    }

    /// The folded net, whatever the CPU ([`reference`] runs anywhere).
    fn folded(net: &McuNet) -> RelaxedNet {
        let s = net.shape();
        let (inputs, hidden, outputs) = (
            s.inputs.min(POSE_DIM),
            s.hidden.min(MAX_HIDDEN),
            s.outputs.min(MAX_TENDONS),
        );
        let hidden_unit = Unit::of(net.hidden_activation());
        let output = Unit::of(net.output_activation());
        // Each row: scaled by its own unit's factor, its hidden-feature
        // weights by `b` of the feature's unit, `w a` moved into the bias.
        let fold = |row: &[f32], scale: f32| -> Vec<f32> {
            let mut w: Vec<f32> = row.iter().map(|&x| x * scale).collect();
            let mut bias_shift = 0.0f32;
            for x in w.iter_mut().skip(1 + POSE_DIM) {
                bias_shift += *x * hidden_unit.a;
                *x *= hidden_unit.b;
            }
            if let Some(bias) = w.first_mut() {
                *bias += bias_shift;
            }
            w
        };
        let mut c = Box::new(Columns {
            first: [[0.0; MAX_HIDDEN]; 1 + POSE_DIM],
            hidden: [[0.0; MAX_HIDDEN]; MAX_HIDDEN],
            newest: [0.0; MAX_HIDDEN + 1],
            out_first: [[0.0; OUT_LANES]; 1 + POSE_DIM],
            out_hidden: [[0.0; OUT_LANES]; MAX_HIDDEN],
        });
        // Row k reads features [bias, POSE_DIM inputs, units 0..k]; the
        // decoded net pads missing inputs with zero weights.
        for k in 0..hidden {
            let row = fold(net.hidden_row(k).unwrap_or(&[]), hidden_unit.scale);
            for (f, &w) in row.iter().enumerate() {
                match f.checked_sub(1 + POSE_DIM) {
                    None => c.first[f][k] = w,
                    Some(j) if j + 1 == k => c.newest[k] = w,
                    Some(j) => c.hidden[j][k] = w,
                }
            }
        }
        for o in 0..outputs {
            let row = fold(net.output_row(o).unwrap_or(&[]), output.scale);
            for (f, &w) in row.iter().enumerate() {
                match f.checked_sub(1 + POSE_DIM) {
                    None => c.out_first[f][o] = w,
                    Some(j) => c.out_hidden[j][o] = w,
                }
            }
        }
        let ranges = Ranges::of(net);
        RelaxedNet {
            inputs,
            blocks: hidden.div_ceil(LANES),
            outputs,
            hidden_tanh: hidden_unit.tanh,
            output,
            ranges,
            in_inv_width: ranges.in_width.map(|w| 1.0 / w),
            columns: c,
        }
    }

    /// Tensions (N) for one pose into `out[..outputs]`.
    pub(super) fn infer_one(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        let x = self.normalised(pose);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a `RelaxedNet` made by `new` exists only where `cpu_has_fma`
        // found AVX2 and FMA on this CPU.
        let o = unsafe { avx2::pre_outputs(self, &x) };
        #[cfg(not(target_arch = "x86_64"))]
        let o = reference::pre_outputs(self, &x);
        self.finish(&o, out);
    }

    /// The pose scaled to the net's input box; inputs the net does not have
    /// are 0, as in the firmware (whatever the pose holds there).
    #[inline(always)]
    fn normalised(&self, pose: &[f32; POSE_DIM]) -> [f32; POSE_DIM] {
        let mut x = [0.0f32; POSE_DIM];
        for (i, xi) in x.iter_mut().enumerate().take(self.inputs) {
            *xi = (pose[i] - self.ranges.in_lo[i]) * self.in_inv_width[i];
        }
        x
    }

    /// The outputs' activation and range, from their folded pre-activations.
    #[inline(always)]
    fn finish(&self, pre: &[f32; OUT_LANES], out: &mut [f32]) {
        for (o, (d, &s)) in out.iter_mut().zip(pre).take(self.outputs).enumerate() {
            let y = if self.output.tanh {
                self.output.b.mul_add(tanh(s), self.output.a)
            } else {
                s
            };
            *d = y.mul_add(self.ranges.out_width[o], self.ranges.out_lo[o]);
        }
    }
}

/// Whether this CPU runs the kernel's AVX2 and FMA instructions.
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

/// `tanh(t)` split for the chain, with `w` the next unit's weight on this
/// one: `(t P, w t P, 1/Q)`, so that `tanh(t) = tP · (1/Q)` and `w tanh(t)
/// = (w tP) · (1/Q)`. The clamp, `t²` (clamped too: the clamped `t` is off
/// the chain), `t⁴`, `t⁸`, both polynomials by Estrin's scheme, one
/// division beside the numerator. NaN gives NaN (through `t P`).
#[inline(always)]
fn tanh_parts(t: f32, w: f32) -> (f32, f32, f32) {
    let tc = t.clamp(-TANH_CLAMP, TANH_CLAMP);
    let wt = w * tc;
    let t2 = (t * t).min(TANH_CLAMP * TANH_CLAMP);
    let t4 = t2 * t2;
    let t8 = t4 * t4;
    let [p0, p1, p2, p3, p4, p5] = TANH_P;
    let p = p5
        .mul_add(t2, p4)
        .mul_add(t8, p3.mul_add(t2, p2).mul_add(t4, p1.mul_add(t2, p0)));
    let [q0, q1, q2, q3] = TANH_Q;
    let q = q3.mul_add(t2, q2).mul_add(t4, q1.mul_add(t2, q0));
    (tc * p, wt * p, 1.0 / q)
}

/// `tanh(t)` within 3.6e-7, see [`TANH_P`], as the chain computes it.
#[inline(always)]
fn tanh(t: f32) -> f32 {
    let (tp, _, r) = tanh_parts(t, 0.0);
    tp * r
}

#[cfg(test)]
mod tests;
