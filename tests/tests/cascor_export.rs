//! `.tnet` export: a net written and read back computes exactly what the
//! in-memory encoding does, re-encodes to the same bytes, matches the f64 net
//! to f32 precision; damaged files are refused with a message naming the problem.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril::learn::cascor::export::{to_bytes, write_tnet, Ranges};
use tendril::learn::cascor::{GrowingNet, OutputKind};
use tendril::net::{decode, infer_batch, read_tnet};
use tendril_shared::{Activation, McuNet, NetShape, TnetView};

fn random_net(hidden: usize, outputs: usize, seed: u64) -> (GrowingNet, Ranges) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let net = GrowingNet {
        n_inputs: 7,
        n_outputs: outputs,
        hidden: (0..hidden)
            .map(|k| (0..8 + k).map(|_| rng.random_range(-2.0..2.0)).collect())
            .collect(),
        outputs: (0..outputs)
            .map(|_| {
                (0..8 + hidden)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect()
            })
            .collect(),
        output_kind: OutputKind::Linear,
    };
    let ranges = Ranges {
        input_lo: vec![-0.11, -0.11, 0.2, 0.9, -0.3, -0.3, -0.01],
        input_hi: vec![0.16, 0.11, 0.4, 1.0, 0.3, 0.3, 0.01],
        output_lo: vec![0.0; outputs],
        output_hi: vec![10.0; outputs],
    };
    (net, ranges)
}

fn poses(n: usize, r: &Ranges) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    DMatrix::from_fn(n, 7, |_, c| rng.random_range(r.input_lo[c]..r.input_hi[c]))
}

fn reencode(net: &McuNet) -> Vec<u8> {
    let s = net.shape();
    let hidden: Vec<f32> = net
        .hidden_units()
        .flat_map(|u| {
            std::iter::once(u.bias)
                .chain(u.inputs[..s.inputs].iter().copied())
                .chain(u.hidden.iter().copied())
        })
        .collect();
    let outputs: Vec<f32> = net
        .output_units()
        .flat_map(|u| {
            std::iter::once(u.bias)
                .chain(u.inputs[..s.inputs].iter().copied())
                .chain(u.hidden.iter().copied())
        })
        .collect();
    let view = TnetView {
        shape: NetShape {
            inputs: s.inputs,
            hidden: s.hidden,
            outputs: s.outputs,
        },
        hidden_activation: net.hidden_activation(),
        output_activation: net.output_activation(),
        input_lo: net.input_lo(),
        input_hi: net.input_hi(),
        output_lo: net.output_lo(),
        output_hi: net.output_hi(),
        hidden_weights: &hidden,
        output_weights: &outputs,
    };
    tendril_shared::encode_to_vec(&view).unwrap()
}

#[test]
fn written_file_decodes_to_bit_identical_outputs_and_bytes() {
    let (net, ranges) = random_net(12, 4, 1);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.tnet");
    write_tnet(&path, &net, &ranges).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes, to_bytes(&net, &ranges).unwrap());
    let from_file = read_tnet(&path).unwrap();
    assert_eq!(
        from_file.shape(),
        NetShape {
            inputs: 7,
            hidden: 12,
            outputs: 4
        }
    );
    assert_eq!(from_file.hidden_activation(), Activation::SymmetricSigmoid);
    // Re-encoding the decoded net reproduces the file byte for byte.
    assert_eq!(reencode(&from_file), bytes);
    let x = poses(200, &ranges);
    let a = infer_batch(&from_file, &x);
    let b = infer_batch(&decode(&bytes).unwrap(), &x);
    assert_eq!(a.map(|v| v.to_bits()), b.map(|v| v.to_bits()));
    // And the f32 net matches the f64 net it came from to f32 precision.
    let xn = DMatrix::from_fn(200, 7, |r, c| {
        (x[(r, c)] - ranges.input_lo[c]) / (ranges.input_hi[c] - ranges.input_lo[c])
    });
    let y = net.predict(&xn).map(|v| 10.0 * v);
    let rel = (&a - &y).abs().max() / y.abs().max();
    assert!(rel < 1e-5, "f32 vs f64 relative difference {rel}");
}

#[test]
fn damaged_or_mismatched_files_are_rejected_with_a_clear_message() {
    let (net, ranges) = random_net(3, 2, 2);
    let good = to_bytes(&net, &ranges).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let check = |bytes: &[u8], want: &str| {
        let path = dir.path().join("bad.tnet");
        std::fs::write(&path, bytes).unwrap();
        let e = read_tnet(&path).unwrap_err().to_string();
        assert!(
            e.contains("bad.tnet") && e.contains(want),
            "{e:?} should mention {want:?}"
        );
    };
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    check(&flipped, "corrupted");
    check(&good[..good.len() - 7], "truncated");
    let mut magic = good.clone();
    magic[0] = b'X';
    check(&magic, "magic");
    check(b"", "truncated");
    let (big, r) = random_net(70, 2, 3);
    check(&to_bytes(&big, &r).unwrap(), "capacity");
    let e = read_tnet(&dir.path().join("missing.tnet"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.tnet"), "{e}");
    // NaN weights never make it into a file.
    let mut nan = net.clone();
    nan.hidden[1][2] = f64::NAN;
    assert!(to_bytes(&nan, &ranges)
        .unwrap_err()
        .to_string()
        .contains("finite"));
}
