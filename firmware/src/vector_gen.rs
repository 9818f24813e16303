//! The MCU test image's embedded files for any trained net (cargo feature
//! `vector-gen`, std): control-loop inputs inside the net's input box plus
//! NaN/∞/out-of-box/stale/clock-fault/watchdog/hot-swap cases, a small
//! synthetic update net for the hot-swap steps and a NaN-corrupted copy of
//! it. `gen_vectors` writes them to `firmware/vectors/` for the committed
//! default net; the host's firmware-parity check generates them for the
//! net it checks (any tendon count up to `MAX_TENDONS`), so the MCU runs
//! that net on inputs made for it.
//!
//! A host-side tool, never part of an MCU build: it allocates, and indexes
//! fixed-size arrays it builds itself (the crate's panic-freedom lints are
//! for the controller code).
#![allow(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

extern crate std;

use std::boxed::Box;
use std::format;
use std::string::String;
use std::vec;
use std::vec::Vec;

use tendril_shared::{weight_capacity, CascadeNet, MAX_HIDDEN, MAX_TENDONS};

use crate::synth::{synthetic_blob_with, Ranges};
use crate::vectors::{
    Record, VecHeader, HAS_FEEDBACK, HAS_SETPOINT, HEADER_LEN, RECORD_LEN, SWAP_BAD, SWAP_GOOD,
    SWAP_NAN, SWAP_REVERT,
};

/// Decode capacity for reading any trained net (checked against the MCU's after).
type BigNet = CascadeNet<7, 256, MAX_TENDONS, { weight_capacity(7, 256, MAX_TENDONS) }>;

/// The generated files.
#[derive(Clone, Debug)]
pub struct Generated {
    /// `inputs.bin`: the vector header and records.
    pub inputs: Vec<u8>,
    /// `swap.tnet`: the hot-swap update.
    pub swap: Vec<u8>,
    /// `swap_nan.tnet`: the update with a NaN weight under a valid CRC.
    pub swap_nan: Vec<u8>,
    /// The net's inputs, hidden units and outputs.
    pub shape: [usize; 3],
    /// Records in `inputs.bin`.
    pub steps: usize,
    /// Path poses that fell outside the net's input box (0 expected).
    pub outside: usize,
}

/// A pose at fraction `f[i]` of each input range, quaternion normalised.
fn pose_at(lo: &[f32], hi: &[f32], f: [f32; 7]) -> [f32; 7] {
    let mut p = [0.0f32; 7];
    for i in 0..7 {
        p[i] = lo[i] + f[i] * (hi[i] - lo[i]);
    }
    let n = (p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]).sqrt();
    for q in &mut p[3..] {
        *q /= n;
    }
    p
}

fn in_box(lo: &[f32], hi: &[f32], p: &[f32; 7]) -> bool {
    (0..7).all(|i| p[i] >= lo[i] && p[i] <= hi[i])
}

/// The vector files for the `.tnet` `blob` (see the module doc).
pub fn generate(blob: &[u8]) -> Result<Generated, String> {
    let net = Box::new(BigNet::decode(blob).map_err(|e| format!("weight file: {e}"))?);
    let shape = net.shape();
    if shape.inputs != 7 {
        return Err(format!(
            "net has {} inputs, the firmware needs a 7-number pose",
            shape.inputs
        ));
    }
    if shape.hidden > MAX_HIDDEN {
        return Err(format!(
            "net has {} hidden units, the MCU build holds at most {MAX_HIDDEN}: raise MAX_HIDDEN in shared/src/capacity.rs (flash and RAM grow quadratically)",
            shape.hidden
        ));
    }
    let (lo, hi) = (net.input_lo().to_vec(), net.input_hi().to_vec());
    let max_tension = net
        .output_hi()
        .iter()
        .fold(0.0f32, |m, &v| m.max(v))
        .max(1.0);

    let mut recs: Vec<Record> = Vec::new();
    let mut now: u64 = 0;
    let mut seq: u32 = 0;
    let ms = 1_000_000u64;
    let mut push = |now: u64, flags: u32, seq: u32, pose: [f32; 7], tip: [f32; 3]| {
        recs.push(Record {
            now_ns: now,
            flags,
            seq,
            pose,
            tip,
        })
    };
    let path = |k: usize| -> [f32; 7] {
        let t = k as f32 * 0.15;
        let f = [
            0.5 + 0.3 * t.sin(),
            0.5 + 0.3 * (0.7 * t).cos(),
            0.5 + 0.2 * (0.3 * t).sin(),
            0.5,
            0.5 + 0.1 * t.sin(),
            0.5 - 0.1 * t.cos(),
            0.5,
        ];
        pose_at(&lo, &hi, f)
    };
    let mut outside = 0;
    // Before any setpoint: hold.
    for _ in 0..3 {
        now += ms;
        push(now, 0, 0, [0.0; 7], [0.0; 3]);
    }
    // Smooth tracking with feedback 0.5 mm off (the integral loop works).
    let mut last = path(0);
    for k in 0..40 {
        now += ms;
        seq += 1;
        last = path(k);
        outside += usize::from(!in_box(&lo, &hi, &last));
        let tip = [last[0] - 5e-4, last[1] + 5e-4, last[2]];
        push(now, HAS_SETPOINT | HAS_FEEDBACK, seq, last, tip);
    }
    // Bad setpoints: NaN, ∞, huge, out of box, non-unit quaternion, stale.
    let mut bad = Vec::new();
    let mut p = last;
    p[1] = f32::NAN;
    bad.push(p);
    let mut p = last;
    p[0] = f32::INFINITY;
    bad.push(p);
    let mut p = last;
    p[2] = 1e30;
    bad.push(p);
    let mut p = last;
    p[0] = hi[0] + 0.5 * (hi[0] - lo[0]);
    bad.push(p);
    let mut p = last;
    for q in &mut p[3..] {
        *q *= 1.2;
    }
    bad.push(p);
    for p in bad {
        now += ms;
        seq += 1;
        push(now, HAS_SETPOINT, seq, p, [0.0; 3]);
    }
    now += ms;
    push(now, HAS_SETPOINT, seq, path(3), [0.0; 3]); // stale: same seq
                                                     // Clock runs backwards for one step.
    seq += 1;
    push(now - 3 * ms, HAS_SETPOINT, seq, path(41), [0.0; 3]);
    now += ms;
    // Hot swap, each with a setpoint so the step's inference shows which net
    // ran: while the flash net runs, a truncated and a NaN blob (rejected),
    // then the update (accepted, RAM slot); while the RAM slot runs, the
    // same two rejections, the update again (RAM over RAM), and back to the
    // flash net.
    let swaps = [
        SWAP_BAD,
        SWAP_NAN,
        SWAP_GOOD,
        0,
        SWAP_NAN,
        SWAP_BAD,
        0,
        SWAP_GOOD,
        SWAP_REVERT,
    ];
    for (j, flag) in swaps.into_iter().enumerate() {
        now += ms;
        seq += 1;
        push(now, HAS_SETPOINT | flag, seq, path(42 + j), [0.0; 3]);
    }
    // Silence: the watchdog (20 ms) trips.
    for _ in 0..8 {
        now += 10 * ms;
        push(now, 0, 0, [0.0; 7], [0.0; 3]);
    }
    // Recovery.
    for k in 52..72 {
        now += ms;
        seq += 1;
        let pose = path(k);
        let tip = [pose[0], pose[1] - 3e-4, pose[2]];
        push(now, HAS_SETPOINT | HAS_FEEDBACK, seq, pose, tip);
    }
    let header = VecHeader {
        count: recs.len() as u32,
        n_tendons: shape.outputs as u32,
        max_tension,
        slew_rate: 50.0 * max_tension,
        watchdog_ns: 20 * ms,
        max_dt_ns: 5 * ms,
        ki: 2.0,
        integral_limit: 0.005,
        feedback_timeout_ns: 5 * ms,
        quaternion_tolerance: 1e-2,
        box_margin: 0.0,
    };
    let mut bytes = vec![0u8; HEADER_LEN + recs.len() * RECORD_LEN];
    let (h, body) = bytes.split_at_mut(HEADER_LEN);
    header.write(h.try_into().map_err(|_| "header size")?);
    for (r, chunk) in recs.iter().zip(body.chunks_exact_mut(RECORD_LEN)) {
        r.write(chunk.try_into().map_err(|_| "record size")?);
    }

    // The update: a 7-12-O net for the same box and tendons.
    let mut swap = vec![0u8; 8192];
    let ranges = Ranges {
        input_lo: &lo,
        input_hi: &hi,
        output_lo: net.output_lo(),
        output_hi: net.output_hi(),
    };
    let n = synthetic_blob_with(20_261_123, 12, &ranges, &mut swap)
        .map_err(|e| format!("swap net: {e}"))?;
    swap.truncate(n);
    // Its last output weight sits just before the CRC: make it NaN, reseal.
    let mut swap_nan = swap.clone();
    let body = swap_nan.len() - 4;
    swap_nan[body - 4..body].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = tendril_shared::crc32::crc32(&swap_nan[..body]);
    swap_nan[body..].copy_from_slice(&crc.to_le_bytes());

    Ok(Generated {
        inputs: bytes,
        swap,
        swap_nan,
        shape: [shape.inputs, shape.hidden, shape.outputs],
        steps: recs.len(),
        outside,
    })
}
