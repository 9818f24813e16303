//! Activation functions of the cascade net's units and their `f32`
//! numerics (docs/design.md §5): the code the firmware runs on every hidden
//! unit, written so host and MCU builds round identically. The byte codes
//! that stand for them in a `.tnet` file belong to the wire format
//! ([`crate::tnet`]).

use core::fmt;

/// Activation function of a layer of units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Activation {
    /// Identity: Fahlman's choice for outputs with continuous targets.
    Linear,
    /// Logistic sigmoid `1/(1+e^−x)`, range (0, 1) like the normalised targets.
    Sigmoid,
    /// Fahlman's symmetric sigmoid `1/(1+e^−x) − 0.5`, range (−0.5, 0.5):
    /// the hidden units of cascade correlation.
    SymmetricSigmoid,
}

impl Activation {
    /// Apply the activation in `f32`, the exact code the firmware runs: only
    /// exactly rounded `+ − × ÷`, comparisons and bit moves, so host and MCU
    /// builds give bit-identical results. The sigmoids use `exp_neg`
    /// instead of `libm::expf` (≈ 54 Cortex-M4F instructions with range
    /// checks, a `vdiv` and `scalbnf`; the hidden units' sigmoids were 38 % of
    /// an inference). Absolute error ≤ 1e-6 over every `f32` (measured
    /// 1.0e-7, see the tests); ±∞ saturate to the limits, NaN gives NaN.
    #[inline]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Activation::Linear => x,
            Activation::Sigmoid => 1.0 / (1.0 + exp_neg(x)),
            Activation::SymmetricSigmoid => 1.0 / (1.0 + exp_neg(x)) - 0.5,
        }
    }
}

/// Inputs are clamped to `±SIGMOID_CLAMP` before [`exp_neg`]: the sigmoid
/// there is within `1/(1+e^24) ≈ 4e-11` of its limit, and `e^±24` keeps the
/// power-of-two scale a normal number (no overflow, no ∞/∞ = NaN).
const SIGMOID_CLAMP: f32 = 24.0;

/// `−log2(e)`: `e^−x = 2^(−x log2 e)`.
const NEG_LOG2_E: f32 = -core::f32::consts::LOG2_E;

/// `1.5·2^23 + 127`: adding it to `|t| < 2^22` rounds `t` to the nearest
/// integer `k` (the sum's ulp is 1) and leaves `k + 127`, the biased
/// exponent of `2^k`, in the low mantissa bits.
const ROUND_BIAS: f32 = 12_583_039.0;

/// Coefficients of `2^f ≈ 1 + f (C1 + f (C2 + f (C3 + f (C4 + f C5))))` on
/// `|f| ≤ 0.5`: minimax in relative error with the constant term fixed at 1
/// (so `σ(0) = 0.5` exactly), each coefficient rounded to `f32` and the rest
/// re-fitted; relative error 1.3e-7.
const EXP2_C: [f32; 5] = [
    f32::from_bits(0x3f31_7215), // 0.693147004
    f32::from_bits(0x3e75_fcd8), // 0.240222335
    f32::from_bits(0x3d63_5bd8), // 0.0555075109
    f32::from_bits(0x3c1e_76e6), // 0.00967190228
    f32::from_bits(0x3aad_d9cb), // 0.00132637599
];

/// `e^−x` for the sigmoids, branch-free and panic-free in ≈ 25 M4F
/// instructions: clamp `x` to `±SIGMOID_CLAMP`, `t = −x log2 e`,
/// `k = round(t)` by the [`ROUND_BIAS`] trick, `f = t − k` (exact,
/// `|f| ≤ 0.5`), a degree-5 polynomial for `2^f`, times `2^k` built from the
/// exponent bits. Relative error ≈ 2e-7, which moves a sigmoid by at most a
/// quarter of that (`dσ = σ(1−σ)·δ`). NaN falls through both comparisons and
/// propagates through `f` and the polynomial, so NaN in gives NaN out.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    let x = if x > SIGMOID_CLAMP { SIGMOID_CLAMP } else { x };
    let x = if x < -SIGMOID_CLAMP {
        -SIGMOID_CLAMP
    } else {
        x
    };
    let t = x * NEG_LOG2_E;
    let biased = t + ROUND_BIAS;
    let k = biased - ROUND_BIAS;
    let f = t - k;
    let [c1, c2, c3, c4, c5] = EXP2_C;
    let p = 1.0 + f * (c1 + f * (c2 + f * (c3 + f * (c4 + f * c5))));
    // `k + 127` sits in bits 0..8 of `biased` (92..=162 for |t| ≤ 34.7) and
    // everything above bit 8 shifts out: the bits of 2^k.
    let scale = f32::from_bits(biased.to_bits() << 23);
    p * scale
}

impl fmt::Display for Activation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Activation::Linear => "linear",
            Activation::Sigmoid => "sigmoid",
            Activation::SymmetricSigmoid => "symmetric-sigmoid",
        })
    }
}

#[cfg(test)]
mod tests {
    //! The sigmoids against `f64` references (`libm::exp`, independent of the
    //! `f32` code under test) over dense sweeps, a stride through every
    //! `f32` bit pattern, and the special values.
    use super::Activation;

    /// Required bound on the absolute error of both sigmoids.
    const BOUND: f64 = 1e-6;

    fn sym_ref(x: f32) -> f64 {
        1.0 / (1.0 + libm::exp(-f64::from(x))) - 0.5
    }

    fn sym_err(x: f32) -> f64 {
        (f64::from(Activation::SymmetricSigmoid.apply(x)) - sym_ref(x)).abs()
    }

    #[test]
    fn symmetric_sigmoid_error_dense_sweep() {
        // 2·10^6 points over [−40, 40]: every range-reduction interval
        // (k = −58 … 58) and the clamp at ±24 many times over.
        let n = 2_000_000;
        let mut worst = (0.0f64, 0.0f32);
        for i in 0..=n {
            let x = -40.0 + 80.0 * (i as f64 / n as f64);
            let x = x as f32;
            let e = sym_err(x);
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 <= BOUND, "error {:e} at x = {}", worst.0, worst.1);
        // Measured 9.8e-8; this catches a wrong polynomial coefficient (1 %
        // off in the quartic one alone gives 2.1e-6, in the cubic 2.4e-5).
        assert!(worst.0 < 2e-7, "error {:e} at x = {}", worst.0, worst.1);
    }

    #[test]
    fn symmetric_sigmoid_error_all_f32_stride() {
        // Every 1021st bit pattern (4.2·10^6 values: subnormals, huge
        // magnitudes, both signs, NaNs); the bound on every finite one,
        // NaN in gives NaN out, and nothing leaves [−0.5, 0.5].
        let mut worst = 0.0f64;
        let mut bits = 0u32;
        let mut count = 0u32;
        loop {
            let x = f32::from_bits(bits);
            let y = Activation::SymmetricSigmoid.apply(x);
            if x.is_nan() {
                assert!(y.is_nan(), "NaN {bits:#x} gave {y}");
            } else {
                assert!((-0.5..=0.5).contains(&y), "x = {x}: {y}");
                worst = worst.max(sym_err(x));
            }
            count += 1;
            match bits.checked_add(1021) {
                Some(b) => bits = b,
                None => break,
            }
        }
        assert!(count > 4_000_000);
        assert!(worst <= BOUND, "worst error {worst:e}");
    }

    #[test]
    fn symmetric_sigmoid_special_values() {
        let s = |x: f32| Activation::SymmetricSigmoid.apply(x);
        assert_eq!(s(0.0), 0.0);
        assert_eq!(s(-0.0), 0.0);
        assert_eq!(s(f32::INFINITY), 0.5);
        assert_eq!(s(f32::NEG_INFINITY), -0.5);
        assert_eq!(s(f32::MAX), 0.5);
        assert_eq!(s(f32::MIN), -0.5);
        for x in [f32::MIN_POSITIVE, 1e-40, -1e-40, 1e-30, -1e-30] {
            assert!(s(x).abs() <= 1e-6, "{x}: {}", s(x));
        }
        for x in [24.0f32, 24.000002, 25.0, 1e10, -24.0, -25.0, -1e10] {
            assert!(sym_err(x) <= BOUND, "{x}");
        }
        assert!(s(f32::NAN).is_nan());
        assert!(s(-f32::NAN).is_nan());
        // A NaN with payload bits that would land in the exponent of 2^k.
        assert!(s(f32::from_bits(0x7fc0_01ff)).is_nan());
        assert!(s(f32::from_bits(0xffff_ffff)).is_nan());
    }

    #[test]
    fn plain_sigmoid_error_and_limits() {
        let sig = |x: f32| Activation::Sigmoid.apply(x);
        let n = 1_000_000;
        let mut worst = 0.0f64;
        for i in 0..=n {
            let x = (-40.0 + 80.0 * (i as f64 / n as f64)) as f32;
            let r = 1.0 / (1.0 + libm::exp(-f64::from(x)));
            worst = worst.max((f64::from(sig(x)) - r).abs());
        }
        assert!(worst <= BOUND, "worst error {worst:e}");
        assert_eq!(sig(0.0), 0.5);
        assert_eq!(sig(f32::INFINITY), 1.0);
        assert!(sig(f32::NEG_INFINITY) >= 0.0 && sig(f32::NEG_INFINITY) < 1e-10);
        assert!(sig(f32::NAN).is_nan());
        assert_eq!(Activation::Linear.apply(3.5), 3.5);
    }
}
