//! A deterministic synthetic net: the hot-swap update blob the MCU binary's
//! vectors offer, and a fixture for tests and benches. Weights come from
//! SplitMix64, so a seed fixes the blob exactly.

use tendril_shared::{encode, Activation, NetShape, TnetError, TnetView};

/// Most weights [`synthetic_blob`] can produce (7 inputs, 64 hidden, 8
/// outputs needs 3,104).
pub const MAX_WEIGHTS: usize = 4096;

/// Input box of the synthetic net: a plausible tip workspace of the seed
/// robot (`px, py` ±0.15 m, `pz` 0.30–0.40 m, a quaternion near identity).
pub const INPUT_LO: [f32; 7] = [-0.15, -0.15, 0.30, 0.90, -0.30, -0.30, -0.05];
/// Upper ends of [`INPUT_LO`].
pub const INPUT_HI: [f32; 7] = [0.15, 0.15, 0.40, 1.00, 0.30, 0.30, 0.05];

/// SplitMix64: tiny, well-mixed, and identical on every platform.
#[derive(Clone, Copy, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)` (24 random bits, exact in `f32`).
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
}

/// Encode a 7-input net with `hidden` symmetric-sigmoid units and `outputs`
/// linear outputs (range 0–`max_tension` N), weights uniform in [−1, 1],
/// input box [`INPUT_LO`]–[`INPUT_HI`], into `buf`; returns the length written.
pub fn synthetic_blob(
    seed: u64,
    hidden: usize,
    outputs: usize,
    max_tension: f32,
    buf: &mut [u8],
) -> Result<usize, TnetError> {
    let lo = [0.0f32; tendril_shared::MAX_TENDONS];
    let hi = [max_tension; tendril_shared::MAX_TENDONS];
    let ranges = Ranges {
        input_lo: &INPUT_LO,
        input_hi: &INPUT_HI,
        output_lo: lo.get(..outputs).unwrap_or(&lo),
        output_hi: hi.get(..outputs).unwrap_or(&hi),
    };
    synthetic_blob_with(seed, hidden, &ranges, buf)
}

/// Normalisation ranges for [`synthetic_blob_with`] (their lengths set the
/// net's input and output counts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ranges<'a> {
    /// Lower ends of the input box.
    pub input_lo: &'a [f32],
    /// Upper ends of the input box.
    pub input_hi: &'a [f32],
    /// Lower ends of the output ranges, N.
    pub output_lo: &'a [f32],
    /// Upper ends of the output ranges, N.
    pub output_hi: &'a [f32],
}

/// Like [`synthetic_blob`] with given ranges: a net that fits the same robot
/// and input box as another one (the hot-swap update for a trained net).
pub fn synthetic_blob_with(
    seed: u64,
    hidden: usize,
    ranges: &Ranges<'_>,
    buf: &mut [u8],
) -> Result<usize, TnetError> {
    let shape = NetShape {
        inputs: ranges.input_lo.len(),
        hidden,
        outputs: ranges.output_lo.len(),
    };
    let nh = shape.hidden_weight_count();
    let no = shape.output_weight_count();
    let mut weights = [0.0f32; MAX_WEIGHTS];
    let mut rng = SplitMix64(seed);
    for w in weights.iter_mut().take(nh + no) {
        *w = rng.uniform(-1.0, 1.0);
    }
    let (hw, rest) = weights.split_at(nh.min(MAX_WEIGHTS));
    let ow = rest
        .get(..no)
        .ok_or(TnetError::ShapeTooLarge { value: nh + no })?;
    let view = TnetView {
        shape,
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: Activation::Linear,
        input_lo: ranges.input_lo,
        input_hi: ranges.input_hi,
        output_lo: ranges.output_lo,
        output_hi: ranges.output_hi,
        hidden_weights: hw,
        output_weights: ow,
    };
    encode(&view, buf)
}
