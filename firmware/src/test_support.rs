//! Helpers the firmware's unit tests share: synthetic nets, their f64
//! reference, poses inside the default net's input box.

use std::vec::Vec;

use tendril_shared::{weight_capacity, CascadeNet};

use crate::synth::{synthetic_blob, SplitMix64, INPUT_HI, INPUT_LO};

pub(crate) type Net = CascadeNet<7, 16, 8, { weight_capacity(7, 16, 8) }>;

pub(crate) type Net64 = CascadeNet<7, 64, 8, { weight_capacity(7, 64, 8) }>;

pub(crate) fn blob(seed: u64, hidden: usize, outputs: usize) -> Vec<u8> {
    let mut buf = std::vec![0u8; 16384];
    let n = synthetic_blob(seed, hidden, outputs, 10.0, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// f64 reference straight from the documented flat layout, regenerating the
/// synthetic weights from the seed (independent of the decoder's storage).
pub(crate) fn reference(seed: u64, hidden: usize, outputs: usize, x: &[f32; 7]) -> Vec<f64> {
    let ni = 7;
    let nh_w: usize = (0..hidden).map(|k| 1 + ni + k).sum();
    let no_w = outputs * (1 + ni + hidden);
    let mut rng = SplitMix64(seed);
    let w: Vec<f64> = (0..nh_w + no_w)
        .map(|_| rng.uniform(-1.0, 1.0) as f64)
        .collect();
    let mut feat: Vec<f64> = std::vec![1.0];
    for i in 0..ni {
        let (lo, hi) = (INPUT_LO[i] as f64, INPUT_HI[i] as f64);
        feat.push((x[i] as f64 - lo) / (hi - lo));
    }
    let mut off = 0;
    for k in 0..hidden {
        let len = 1 + ni + k;
        let s: f64 = w[off..off + len]
            .iter()
            .zip(&feat)
            .map(|(a, b)| a * b)
            .sum();
        feat.push(1.0 / (1.0 + (-s).exp()) - 0.5);
        off += len;
    }
    (0..outputs)
        .map(|o| {
            let len = 1 + ni + hidden;
            let row = &w[nh_w + o * len..nh_w + (o + 1) * len];
            let s: f64 = row.iter().zip(&feat).map(|(a, b)| a * b).sum();
            10.0 * s
        })
        .collect()
}

/// The centre of the synthetic net's input box (every normalised input 0.5;
/// its quaternion is not unit, so the control step would refuse it).
pub(crate) fn box_centre() -> [f32; 7] {
    let mut p = [0.0f32; 7];
    for i in 0..7 {
        p[i] = 0.5 * (INPUT_LO[i] + INPUT_HI[i]);
    }
    p
}

/// A valid setpoint inside the box: centre position, unit quaternion.
pub(crate) fn mid_pose() -> [f32; 7] {
    let qx = (1.0f32 - 0.98 * 0.98).sqrt();
    [0.0, 0.0, 0.35, 0.98, qx, 0.0, 0.0]
}
