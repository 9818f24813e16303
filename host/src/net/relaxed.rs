//! Single-query inference for latency (issue 29, item 2): [`RelaxedNet`],
//! the same net with *relaxed* arithmetic — not bit-identical to the
//! firmware: each unit within ~2e-7 of the firmware's, which a trained net
//! amplifies as it amplifies the firmware's own rounding — for callers
//! that want one answer fast and make no parity claim.
//!
//! # Why a second path
//! One query through a cascade is a dependency chain: unit k needs unit
//! k − 1. With the firmware's arithmetic each link is a product, a
//! four-sum reduction and the sigmoid's clamp, range reduction, degree-5
//! Horner polynomial and division — about 100 cycles, 64 of them in a row
//! (≈ 2 µs), whatever the layout ([`super::HostNet`]). Here each link is
//! only what the chain cannot avoid:
//!
//! - the pre-activation of unit k is summed from every feature except the
//!   newest (unit k − 1's output) *before* that feature exists — out of the
//!   chain — and the newest enters last, in one fused multiply-add;
//! - the activation is a rational `tanh` evaluated by Estrin's scheme (depth
//!   4 multiply-adds, one division) instead of the firmware's `2^x`;
//! - the factors that turn `tanh` into the net's sigmoids are folded into
//!   the weights once, when the net is built (see [`Unit`]).
//!
//! # Where it may differ, and where it may not
//! The firmware, the QEMU parity, the trace replay, `tendril evaluate`,
//! `compare`'s predictions, `tendril ik` and the Python `Net` all claim the
//! deployed arithmetic and use the bit-identical paths. This one is for
//! single answers where the last bits do not matter (an IK's starting
//! guess, a planner's preview). The test (`net::fast`) bounds its distance
//! from an exact `f64` evaluation of the same weights by three times the
//! firmware's own (on the default net the firmware sits ~1e-4 of the
//! output range from it).
//!
//! # The folding
//! With `g = tanh(t)`, the symmetric sigmoid is `σ(s) − ½ = ½ tanh(s/2)`
//! and the logistic `σ(s) = ½ + ½ tanh(s/2)`, so unit k stores `g_k =
//! tanh(t_k)` with `t_k = s_k / 2`: its row is halved, and each consumer's
//! weight on `h_k = a + b g_k` becomes `w b` with `w a` added to its bias.
//! Scaling by ½ is exact; the bias shift is one rounding.

use tendril_shared::{Activation, McuNet, MAX_HIDDEN, POSE_DIM};

use super::ranges::Ranges;

/// Most features a unit reads: the bias, the inputs, the hidden units.
const MAX_FEATURES: usize = 1 + POSE_DIM + MAX_HIDDEN;

/// `|t|` past which `tanh(t)` is 1 in `f32` to within half an ulp: the
/// rational below is fitted on `[0, TANH_CLAMP]` and the input clamped to it.
const TANH_CLAMP: f32 = 9.0;

/// `tanh(t) ≈ t P(t²) / Q(t²)` on `|t| ≤ 9`: `P` of degree 5 and `Q` of
/// degree 3 in `t²`, fitted by iterated weighted least squares on the
/// absolute error (`scripts/fit-tanh`, 2026-12-03). The `f64` fit is within
/// 5e-8 of `tanh`; evaluated in `f32` with these rounded coefficients,
/// within 3.6e-7 (the rounding of `t²` and of the coefficients dominates).
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

/// How a hidden unit's stored value `g` relates to the firmware's `h`:
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

/// A net with its weights folded for [`RelaxedNet::infer_one`]. Built once
/// per net by [`super::HostNet::new`] on CPUs with AVX2 and FMA.
#[derive(Clone, Debug)]
pub(super) struct RelaxedNet {
    inputs: usize,
    hidden: usize,
    outputs: usize,
    hidden_tanh: bool,
    output: Unit,
    ranges: Ranges,
    /// 1 / the input widths: a multiply per input instead of a divide.
    in_inv_width: [f32; POSE_DIM],
    /// Hidden row `k` without its last weight (`POSE_DIM + k` long), then
    /// the output rows (`1 + POSE_DIM + hidden`), all folded.
    weights: Box<[f32]>,
    /// Hidden row `k`'s last weight (on unit `k − 1`; for `k = 0`, on the
    /// last input), folded.
    newest: Box<[f32]>,
}

impl RelaxedNet {
    /// The folded net, or `None` if this CPU lacks AVX2 and FMA (the kernel
    /// needs hardware fused multiply-adds: in software they are slow).
    pub(super) fn new(net: &McuNet) -> Option<RelaxedNet> {
        if !cpu_has_fma() {
            return None;
        }
        let s = net.shape();
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
            w[0] += bias_shift;
            w
        };
        let mut weights = Vec::new();
        let mut newest = Vec::with_capacity(s.hidden);
        for k in 0..s.hidden {
            let mut w = fold(net.hidden_row(k)?, hidden_unit.scale);
            newest.push(w.pop()?);
            weights.extend(w);
        }
        for o in 0..s.outputs {
            weights.extend(fold(net.output_row(o)?, output.scale));
        }
        let ranges = Ranges::of(net);
        Some(RelaxedNet {
            inputs: s.inputs.min(POSE_DIM),
            hidden: s.hidden.min(MAX_HIDDEN),
            outputs: s.outputs,
            hidden_tanh: hidden_unit.tanh,
            output,
            ranges,
            in_inv_width: ranges.in_width.map(|w| 1.0 / w),
            weights: weights.into_boxed_slice(),
            newest: newest.into_boxed_slice(),
        })
    }

    /// Tensions (N) for one pose into `out[..outputs]`.
    pub(super) fn infer_one(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a `RelaxedNet` exists only where `cpu_has_fma` found AVX2
        // and FMA on this CPU (`RelaxedNet::new`).
        unsafe {
            self.infer_one_fma(pose, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.kernel(pose, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn infer_one_fma(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        self.kernel(pose, out)
    }

    #[inline(always)]
    fn kernel(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        let mut f = [0.0f32; MAX_FEATURES];
        f[0] = 1.0;
        // Inputs the net does not have stay 0, as in the firmware.
        for (i, fi) in f[1..=self.inputs].iter_mut().enumerate() {
            *fi = (pose[i] - self.ranges.in_lo[i]) * self.in_inv_width[i];
        }
        let mut start = 0;
        for k in 0..self.hidden {
            // Everything but the newest feature: ready before unit k − 1 is.
            let len = POSE_DIM + k;
            let Some(w) = self.weights.get(start..start + len) else {
                return;
            };
            start += len;
            let older = dot(w, &f[..len]);
            let s = self
                .newest
                .get(k)
                .map_or(older, |w| w.mul_add(f[len], older));
            f[len + 1] = if self.hidden_tanh { tanh(s) } else { s };
        }
        let len = 1 + POSE_DIM + self.hidden;
        let rows = self.weights.get(start..).unwrap_or(&[]).chunks_exact(len);
        for (o, (d, w)) in out.iter_mut().zip(rows).take(self.outputs).enumerate() {
            let s = dot(w, &f[..len]);
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

/// `w · f` (equal lengths): eight lanes of fused multiply-adds over the
/// whole chunks, a tree reduction, then the rest in index order, so the
/// newest features enter last.
#[inline(always)]
fn dot(w: &[f32], f: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (w8, f8) = (w.chunks_exact(8), f.chunks_exact(8));
    let (wr, fr) = (w8.remainder(), f8.remainder());
    for (wc, fc) in w8.zip(f8) {
        for ((a, &x), &y) in acc.iter_mut().zip(wc).zip(fc) {
            *a = x.mul_add(y, *a);
        }
    }
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    let mut s = ((a0 + a4) + (a1 + a5)) + ((a2 + a6) + (a3 + a7));
    for (&x, &y) in wr.iter().zip(fr) {
        s = x.mul_add(y, s);
    }
    s
}

/// `tanh(t)` within 3.6e-7, see [`TANH_P`]: the clamp, `t²`, `t⁴`, `t⁸`,
/// both polynomials by Estrin's scheme, one division. NaN gives NaN.
#[inline(always)]
fn tanh(t: f32) -> f32 {
    let t = t.clamp(-TANH_CLAMP, TANH_CLAMP);
    let t2 = t * t;
    let t4 = t2 * t2;
    let t8 = t4 * t4;
    let [p0, p1, p2, p3, p4, p5] = TANH_P;
    let p = p5
        .mul_add(t2, p4)
        .mul_add(t8, p3.mul_add(t2, p2).mul_add(t4, p1.mul_add(t2, p0)));
    let [q0, q1, q2, q3] = TANH_Q;
    let q = q3.mul_add(t2, q2).mul_add(t4, q1.mul_add(t2, q0));
    t * p / q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rational against `f64`'s `tanh` over and past its range: the
    /// bound the constants' documentation gives.
    #[test]
    fn tanh_within_its_documented_error() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let t = i as f32 * 6e-5; // ±12, finer than the curvature
            let e = (f64::from(tanh(t)) - f64::from(t).tanh()).abs();
            worst = worst.max(e);
        }
        assert!(worst <= 3.6e-7, "worst |tanh error| {worst:e}");
        assert_eq!(tanh(0.0), 0.0);
        assert!(tanh(f32::NAN).is_nan());
        assert!((tanh(f32::INFINITY) - 1.0).abs() <= 3.6e-7);
    }
}
