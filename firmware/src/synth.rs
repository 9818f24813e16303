//! A deterministic synthetic net: the placeholder `.tnet` the MCU binary
//! embeds until a trained one replaces it, and a fixture for tests and
//! benches. Weights come from SplitMix64, so a seed fixes the blob exactly.

use tendril_shared::{encode, Activation, Shape, TnetError, TnetView};

/// Most weights [`synthetic_blob`] can produce (7 inputs, 16 hidden, 8 outputs needs 440).
pub const MAX_WEIGHTS: usize = 1024;

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
/// into `buf`; returns the length written.
pub fn synthetic_blob(
    seed: u64,
    hidden: usize,
    outputs: usize,
    max_tension: f32,
    buf: &mut [u8],
) -> Result<usize, TnetError> {
    let shape = Shape {
        inputs: 7,
        hidden,
        outputs,
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
    let lo = [0.0f32; 8];
    let hi = [max_tension; 8];
    let view = TnetView {
        shape,
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: Activation::Linear,
        input_lo: &INPUT_LO,
        input_hi: &INPUT_HI,
        output_lo: lo.get(..outputs).unwrap_or(&lo),
        output_hi: hi.get(..outputs).unwrap_or(&hi),
        hidden_weights: hw,
        output_weights: ow,
    };
    encode(&view, buf)
}
