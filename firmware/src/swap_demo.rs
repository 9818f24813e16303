//! The hot-swap run of the MCU test image `tendril-fw-swap` (docs/design.md
//! §5.3), shared with the QEMU test that checks it: which nets, which blobs
//! are offered at which control period, and the setpoint of every period.
//! The nets are [`crate::synth`] nets of the largest shape the MCU accepts
//! (7 inputs, 64 hidden units, 8 tendons), so the test rebuilds every one of
//! them on the host from the same seeds.

use tendril_shared::{CoContraction, LimitsError, NetShape, TendonLimits, TnetError, POSE_DIM};

use crate::synth::synthetic_blob;

/// Hidden units of every net of the run: the MCU's capacity.
pub const HIDDEN: usize = tendril_shared::MAX_HIDDEN;
/// Outputs (tendons) of every net of the run: 8, which with [`HIDDEN`]
/// units makes the largest net file the MCU accepts
/// ([`tendril_shared::MAX_NET_FILE`]; nine tendons trade a unit for the
/// ninth output and make a shorter file).
pub const OUTPUTS: usize = 8;

const _: () = assert!(
    NetShape {
        inputs: POSE_DIM,
        hidden: HIDDEN,
        outputs: OUTPUTS,
    }
    .encoded_len_v2()
        == tendril_shared::MAX_NET_FILE,
    "the run's nets are the largest the MCU accepts"
);
/// Upper end of every output range and of the tension limits, N.
pub const MAX_TENSION: f32 = 20.0;
/// Slew limit of the run's robot, N/s.
pub const SLEW_RATE: f32 = 500.0;
/// Bytes of each blob of the run: a 7-64-8 `.tnet`.
pub const BLOB_LEN: usize = NetShape {
    inputs: POSE_DIM,
    hidden: HIDDEN,
    outputs: OUTPUTS,
}
.encoded_len();

/// Seed of the net the image is built with (`TENDRIL_FW_NET`, in flash).
pub const FLASH_SEED: u64 = 0xF1A5;

/// The blobs the run offers, in schedule order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Offer {
    /// Valid; offered while the flash net runs: lands in the RAM slot.
    First,
    /// A copy of a valid net with one byte flipped (CRC mismatch, found at
    /// the end of hashing): refused, the first update keeps running.
    Corrupted,
    /// Valid, but superseded by [`Offer::Last`] a few periods later.
    Superseded,
    /// Valid; replaces the first update while it runs from the RAM slot.
    Last,
}

impl Offer {
    /// Every offer, in schedule order.
    pub const ALL: [Offer; 4] = [
        Offer::First,
        Offer::Corrupted,
        Offer::Superseded,
        Offer::Last,
    ];

    /// The period whose swap slice first sees this blob.
    pub const fn period(self) -> u32 {
        match self {
            Offer::First => 5,
            Offer::Corrupted => 30,
            Offer::Superseded => 50,
            Offer::Last => 53,
        }
    }

    /// Seed of the synthetic net behind the blob.
    pub const fn seed(self) -> u64 {
        match self {
            Offer::First => 0xB10B_0001,
            Offer::Corrupted => 0xB10B_0002,
            Offer::Superseded => 0xB10B_0003,
            Offer::Last => 0xB10B_0004,
        }
    }

    /// Name in the image's output.
    pub const fn name(self) -> &'static str {
        match self {
            Offer::First => "first",
            Offer::Corrupted => "corrupted",
            Offer::Superseded => "superseded",
            Offer::Last => "last",
        }
    }
}

/// Control periods the run lasts.
pub const PERIODS: u32 = 90;

/// Encode the net of `seed` (7-64-8, the run's ranges) into `buf`.
pub fn net_blob(seed: u64, buf: &mut [u8]) -> Result<usize, TnetError> {
    synthetic_blob(seed, HIDDEN, OUTPUTS, MAX_TENSION, buf)
}

/// Encode the blob of `offer` into `buf` (the corrupted one with the byte
/// in the middle of its weights flipped); returns its length.
pub fn offer_blob(offer: Offer, buf: &mut [u8]) -> Result<usize, TnetError> {
    let n = net_blob(offer.seed(), buf)?;
    if offer == Offer::Corrupted {
        if let Some(b) = buf.get_mut(n / 2) {
            *b ^= 0x10;
        }
    }
    Ok(n)
}

/// The setpoint of period `k`: a circle of radius 0.1 m at `pz` = 0.35 m
/// with a rocking tilt about x (a unit quaternion), inside the synthetic
/// nets' input box, so every step runs the net.
pub fn pose(k: u32) -> [f32; POSE_DIM] {
    let theta = k as f32 * 0.1;
    let (s, c) = (sin_series(theta), cos_series(theta));
    let half_tilt = 0.1 * s;
    [
        0.1 * c,
        0.1 * s,
        0.35,
        cos_series(half_tilt),
        sin_series(half_tilt),
        0.0,
        0.0,
    ]
}

/// The run's robot: 8 tendons, 0–[`MAX_TENSION`] N, [`SLEW_RATE`],
/// opposite pairs co-contract.
pub fn limits() -> Result<TendonLimits, LimitsError> {
    TendonLimits::uniform(OUTPUTS, MAX_TENSION, SLEW_RATE)?
        .with_cocontraction(CoContraction::opposite_pairs(OUTPUTS))
}

/// `sin x` for |x| ≲ 10 by a Taylor series after reduction to [−π, π]: the
/// same operations on host and MCU (the firmware links no `libm`).
fn sin_series(x: f32) -> f32 {
    let tau = core::f32::consts::TAU;
    let mut r = x;
    while r > core::f32::consts::PI {
        r -= tau;
    }
    while r < -core::f32::consts::PI {
        r += tau;
    }
    let r2 = r * r;
    let mut term = r;
    let mut sum = r;
    for n in 1..10 {
        let d = (2 * n) as f32 * (2 * n + 1) as f32;
        term *= -r2 / d;
        sum += term;
    }
    sum
}

/// `cos x` as [`sin_series`]`(x + π/2)`.
fn cos_series(x: f32) -> f32 {
    sin_series(x + core::f32::consts::FRAC_PI_2)
}
