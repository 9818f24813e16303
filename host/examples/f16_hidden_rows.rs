//! Would a net with its hidden rows stored as f16 keep its accuracy if its
//! output rows were re-solved in f32 (issue 30 item 1: more hidden units in
//! the chip's RAM)? The output phase of cascade correlation is an exact
//! least-squares solve over the hidden units' values, so after rounding the
//! hidden rows it can be solved again: here to reproduce the f32 net's own
//! normalised outputs on the non-test rows (a distillation, so the
//! trainer's target transform need not be known).
//!
//! `cargo run --release -p tendril --example f16_hidden_rows -- NET.tnet
//! DATA.csv OUT_DIR [SPLIT_SEED]` writes three variants of NET into OUT_DIR
//! for `tendril evaluate --rows test`: `h16.tnet` (hidden rows rounded to
//! f16, outputs as trained), `h16_resolved.tnet` (and the output rows
//! re-solved, f32) and `h16_resolved_o16.tnet` (and those rounded to f16
//! too). The weights stay f32 in the file: the rounding is what f16
//! storage would do to them. The split is the trainer's (`split_indices`,
//! test fraction 0.03, the given seed, default 1).

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use tendril::dataset::io::Dataset;
use tendril::dataset::split::split_indices;

/// `x` rounded to the nearest f16 (ties to even), as an f32. No overflow
/// handling: f16 reaches 65,504 and these nets' weights stay below ~220.
fn to_f16(x: f32) -> f32 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let a = x.abs();
    // Below f16's smallest normal, 2^-14, its subnormals are steps of 2^-24.
    if a < 2f32.powi(-14) {
        let step = 2f32.powi(-24);
        let q = (a / step).round() * step;
        return q.copysign(x);
    }
    let bits = x.to_bits();
    let lsb = (bits >> 13) & 1;
    f32::from_bits((bits + 0x0FFF + lsb) & !0x1FFF)
}

/// Bytes of postcard's varint of `v`.
fn varint_len(mut v: usize) -> usize {
    let mut n = 1;
    while v >= 128 {
        v >>= 7;
        n += 1;
    }
    n
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(
        args.len() >= 4,
        "usage: f16_hidden_rows NET.tnet DATA.csv OUT_DIR [SPLIT_SEED]"
    );
    let bytes = std::fs::read(&args[1])?;
    let data = Dataset::read_csv(Path::new(&args[2]))?;
    let out_dir = Path::new(&args[3]);
    let net = tendril::net::decode(&bytes)?;
    let shape = net.shape();
    let (ni, nh, no) = (shape.inputs, shape.hidden, shape.outputs);
    let n_hid = nh * (1 + ni) + nh * nh.saturating_sub(1) / 2;
    let n_out = no * (1 + ni + nh);
    // The weight sequences end the file, before the CRC: output rows last,
    // each sequence after its varint length.
    let len = bytes.len();
    let out_start = len - 4 - 4 * n_out;
    let hid_start = out_start - varint_len(n_out) - 4 * n_hid;
    let f = |off: usize| f32::from_le_bytes(bytes[off..off + 4].try_into().unwrap());
    let hid: Vec<f32> = (0..n_hid).map(|i| f(hid_start + 4 * i)).collect();
    let outw: Vec<f32> = (0..n_out).map(|i| f(out_start + 4 * i)).collect();
    anyhow::ensure!(
        net.hidden_row(0).and_then(|r| r.first()) == hid.first()
            && net.output_row(0).and_then(|r| r.first()) == outw.first(),
        "the weight blocks are not where the layout puts them"
    );
    let act = net.hidden_activation();
    let (lo, hi) = (net.input_lo().to_vec(), net.input_hi().to_vec());
    let hid16: Vec<f32> = hid.iter().map(|&w| to_f16(w)).collect();
    let features = |hw: &[f32], pose: &[f64]| -> Vec<f64> {
        let mut z = vec![1.0f64];
        for i in 0..ni {
            z.push((pose[i] - lo[i] as f64) / (hi[i] as f64 - lo[i] as f64));
        }
        let mut off = 0;
        for k in 0..nh {
            let row = &hw[off..off + 1 + ni + k];
            off += 1 + ni + k;
            let s: f64 = row.iter().zip(&z).map(|(w, v)| *w as f64 * v).sum();
            z.push(act.apply(s as f32) as f64);
        }
        z
    };
    let n = data.poses.nrows();
    let seed: u64 = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let (train, _test) = split_indices(n, 0.03, seed);
    let nf = 1 + ni + nh;
    let mut gram = DMatrix::<f64>::zeros(nf, nf);
    let mut fty = DMatrix::<f64>::zeros(nf, no);
    for &r in &train {
        let pose: Vec<f64> = data.poses.row(r).iter().copied().collect();
        let z0 = features(&hid, &pose);
        let z1 = features(&hid16, &pose);
        let zv = DVector::from_vec(z1);
        gram += &zv * zv.transpose();
        for o in 0..no {
            let w = &outw[o * nf..(o + 1) * nf];
            let y: f64 = w.iter().zip(&z0).map(|(w, v)| *w as f64 * v).sum();
            for j in 0..nf {
                fty[(j, o)] += zv[j] * y;
            }
        }
    }
    let lambda = 1e-10 * gram.trace() / nf as f64;
    for j in 0..nf {
        gram[(j, j)] += lambda;
    }
    let sol = gram
        .cholesky()
        .ok_or_else(|| anyhow::anyhow!("the features' Gram matrix is not positive definite"))?
        .solve(&fty);
    let mut resolved = vec![0f32; n_out];
    for o in 0..no {
        for j in 0..nf {
            resolved[o * nf + j] = sol[(j, o)] as f32;
        }
    }
    let write = |name: &str, h: &[f32], o: &[f32]| -> anyhow::Result<()> {
        let mut b = bytes.clone();
        for (i, w) in h.iter().enumerate() {
            b[hid_start + 4 * i..hid_start + 4 * i + 4].copy_from_slice(&w.to_le_bytes());
        }
        for (i, w) in o.iter().enumerate() {
            b[out_start + 4 * i..out_start + 4 * i + 4].copy_from_slice(&w.to_le_bytes());
        }
        let crc = tendril_shared::crc32::crc32(&b[..len - 4]);
        b[len - 4..].copy_from_slice(&crc.to_le_bytes());
        std::fs::write(out_dir.join(name), b)?;
        Ok(())
    };
    let out16: Vec<f32> = resolved.iter().map(|&w| to_f16(w)).collect();
    write("h16.tnet", &hid16, &outw)?;
    write("h16_resolved.tnet", &hid16, &resolved)?;
    write("h16_resolved_o16.tnet", &hid16, &out16)?;
    let maxw = resolved.iter().fold(0f32, |a, w| a.max(w.abs()));
    println!("nh {nh}: wrote variants; max |resolved output w| {maxw}");
    Ok(())
}
