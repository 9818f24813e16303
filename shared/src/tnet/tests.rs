//! Round trips and one test per decoder error of the `.tnet` format.

use std::vec;
use std::vec::Vec;

use proptest::prelude::*;

use crate::crc32::crc32;
use crate::net::ROW_PAD;
use crate::tnet::{self, Field, TnetError, MAGIC};
use crate::{encode, encoded_len, weight_capacity, Activation, CascadeNet, NetShape, TnetView};

/// An owned net description with distinct, deterministic values.
struct Owned {
    shape: NetShape,
    input_lo: Vec<f32>,
    input_hi: Vec<f32>,
    output_lo: Vec<f32>,
    output_hi: Vec<f32>,
    hidden: Vec<f32>,
    output: Vec<f32>,
}

impl Owned {
    fn new(inputs: usize, hidden: usize, outputs: usize) -> Owned {
        let shape = NetShape {
            inputs,
            hidden,
            outputs,
        };
        let w = |n: usize, base: f32| -> Vec<f32> {
            (0..n)
                .map(|i| base + 0.001 * (i as f32 + 1.0) * if i % 2 == 0 { 1.0 } else { -1.0 })
                .collect()
        };
        Owned {
            shape,
            input_lo: (0..inputs).map(|i| -1.0 - i as f32).collect(),
            input_hi: (0..inputs).map(|i| 1.0 + 0.5 * i as f32).collect(),
            output_lo: vec![0.0; outputs],
            output_hi: (0..outputs).map(|o| 10.0 + o as f32).collect(),
            hidden: w(shape.hidden_weight_count(), 0.5),
            output: w(shape.output_weight_count(), -0.25),
        }
    }

    fn view(&self) -> TnetView<'_> {
        TnetView {
            shape: self.shape,
            hidden_activation: Activation::SymmetricSigmoid,
            output_activation: Activation::Linear,
            input_lo: &self.input_lo,
            input_hi: &self.input_hi,
            output_lo: &self.output_lo,
            output_hi: &self.output_hi,
            hidden_weights: &self.hidden,
            output_weights: &self.output,
        }
    }

    fn blob(&self) -> Vec<u8> {
        crate::encode_to_vec_for_tests(&self.view())
    }
}

/// Recompute the CRC trailer after a deliberate edit, so the decoder gets
/// past the checksum to the check under test.
fn reseal(blob: &mut [u8]) {
    let n = blob.len() - 4;
    let c = crc32(&blob[..n]);
    blob[n..].copy_from_slice(&c.to_le_bytes());
}

/// Byte offset of the (unique) little-endian f32 `v` in `blob`.
fn find_f32(blob: &[u8], v: f32) -> usize {
    let pat = v.to_le_bytes();
    let hits: Vec<usize> = (0..blob.len() - 3)
        .filter(|&i| blob[i..i + 4] == pat)
        .collect();
    assert_eq!(hits.len(), 1, "value {v} must occur exactly once");
    hits[0]
}

type Net = CascadeNet<7, 8, 4, { weight_capacity(7, 8, 4) }>;

#[test]
fn round_trip_preserves_every_value_in_the_documented_layout() {
    let o = Owned::new(7, 3, 4);
    let blob = o.blob();
    assert_eq!(blob.len(), encoded_len(&o.view()).unwrap());
    assert_eq!(&blob[..4], b"TNET");
    let net = Net::decode(&blob).unwrap();
    assert_eq!(net.shape(), o.shape);
    assert_eq!(net.input_lo(), &o.input_lo[..]);
    assert_eq!(net.input_hi(), &o.input_hi[..]);
    assert_eq!(net.output_lo(), &o.output_lo[..]);
    assert_eq!(net.output_hi(), &o.output_hi[..]);
    assert_eq!(net.hidden_activation(), Activation::SymmetricSigmoid);
    assert_eq!(net.output_activation(), Activation::Linear);
    // Hidden unit k's row: [bias, inputs.., hidden 0..k-1], rows concatenated.
    for (k, u) in net.hidden_units().enumerate() {
        let off = o.shape.hidden_row_offset(k);
        let row = &o.hidden[off..off + o.shape.hidden_row_len(k)];
        assert_eq!(u.bias, row[0]);
        assert_eq!(u.inputs, &row[1..8]);
        assert_eq!(u.hidden, &row[8..]);
    }
    for (j, u) in net.output_units().enumerate() {
        let row = &o.output[j * 11..(j + 1) * 11];
        assert_eq!(u.bias, row[0]);
        assert_eq!(u.inputs, &row[1..8]);
        assert_eq!(u.hidden, &row[8..11]);
    }
    // Packed storage with the full input capacity is the file's own layout:
    // hidden rows, output rows, then zeros.
    let used = o.hidden.len() + o.output.len();
    assert_eq!(&net.weights()[..o.hidden.len()], &o.hidden[..]);
    assert_eq!(&net.weights()[o.hidden.len()..used], &o.output[..]);
    assert!(net.weights()[used..].iter().all(|&w| w == 0.0));
    assert_eq!(
        tnet::read_header(&blob).unwrap(),
        (o.shape, Activation::SymmetricSigmoid, Activation::Linear)
    );
}

#[test]
fn shape_encoded_len_is_the_encoders_length() {
    // Shapes whose varints (dimensions and array lengths) take 1, 2 and 3
    // bytes: 127/128 weights, 16,384+ weights.
    for (i, h, o) in [
        (7, 0, 1),
        (7, 3, 4),
        (1, 0, 127),
        (7, 64, 8),
        (16, 120, 16),
        (7, 200, 8),
    ] {
        let owned = Owned::new(i, h, o);
        let shape = owned.shape;
        assert_eq!(
            shape.encoded_len(),
            encoded_len(&owned.view()).unwrap(),
            "{shape:?}"
        );
        assert_eq!(shape.encoded_len(), owned.blob().len(), "{shape:?}");
    }
    // The bound `messages` checks at compile time: the largest net fits.
    let max = NetShape {
        inputs: crate::POSE_DIM,
        hidden: crate::MAX_HIDDEN,
        outputs: 8,
    };
    // 3,134 floats (ranges 2·7 + 2·8, hidden 64·8 + 64·63/2 = 2,528,
    // outputs 8·72 = 576) = 12,536 B; magic 4, version 1, dims 3,
    // activations 2, six lengths 1+1+1+1+2+2 = 8, CRC 4.
    assert_eq!(max.encoded_len(), 12_558);
    assert!(max.encoded_len() <= crate::messages::WEIGHT_UPDATE_CAPACITY);
    // Nine tendons trade a unit for the ninth output: 7-63-9 is 3,128
    // floats (ranges 2·7 + 2·9, hidden 63·8 + 63·62/2 = 2,457, outputs
    // 9·71 = 639), six fewer than 7-64-8, so 7-64-8 stays the largest file.
    let nine = NetShape {
        inputs: crate::POSE_DIM,
        hidden: crate::max_hidden_for(9),
        outputs: 9,
    };
    assert_eq!(nine.hidden, 63);
    assert_eq!(nine.encoded_len(), 12_558 - 6 * 4);
    assert_eq!(crate::MAX_NET_FILE, max.encoded_len_v2());
}

#[test]
fn row_offsets_sum_the_row_lengths() {
    let s = NetShape {
        inputs: 7,
        hidden: 5,
        outputs: 4,
    };
    let mut off = 0;
    for k in 0..5 {
        assert_eq!(s.hidden_row_offset(k), off);
        off += s.hidden_row_len(k);
    }
    assert_eq!(s.hidden_weight_count(), off);
    assert_eq!(s.output_weight_count(), 4 * 13);
}

#[test]
fn a_net_without_hidden_units_and_fewer_inputs_than_capacity_decodes() {
    let o = Owned::new(3, 0, 1);
    let net = Net::decode(&o.blob()).unwrap();
    assert_eq!(net.hidden_units().len(), 0);
    let u = net.output_units().next().unwrap();
    assert_eq!(u.inputs[..3], o.output[1..4]);
    assert_eq!(u.inputs[3..], [0.0; 4]);
    assert!(u.hidden.is_empty());
}

#[test]
fn every_proper_prefix_is_truncated() {
    let blob = Owned::new(7, 2, 2).blob();
    for n in 0..blob.len() {
        assert_eq!(
            Net::decode(&blob[..n]),
            Err(TnetError::Truncated),
            "prefix {n}"
        );
    }
}

#[test]
fn wrong_magic_is_rejected() {
    let mut blob = Owned::new(7, 2, 2).blob();
    blob[0] = b'X';
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::BadMagic { found: *b"XNET" })
    );
}

#[test]
fn other_version_is_rejected() {
    let mut blob = Owned::new(7, 2, 2).blob();
    assert_eq!(blob[4], 1, "version is a one-byte varint");
    // Versions 1 and 2 are read (tnet/provenance.rs tests version 2).
    blob[4] = 3;
    reseal(&mut blob);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::UnsupportedVersion { found: 3 })
    );
}

#[test]
fn zero_inputs_is_an_empty_shape() {
    let mut blob = Owned::new(7, 2, 2).blob();
    blob[5] = 0;
    reseal(&mut blob);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::EmptyShape {
            inputs: 0,
            outputs: 2
        })
    );
    let o = Owned::new(7, 0, 0);
    assert!(matches!(
        encoded_len(&o.view()),
        Err(TnetError::EmptyShape { .. })
    ));
}

#[test]
fn shape_over_capacity_is_rejected_for_each_dimension() {
    let blob = Owned::new(7, 3, 4).blob();
    let over = |e: Result<(), TnetError>| {
        assert!(
            matches!(e, Err(TnetError::ShapeOverCapacity { .. })),
            "{e:?}"
        )
    };
    over(CascadeNet::<6, 8, 4, 1000>::decode(&blob).map(|_| ()));
    over(CascadeNet::<7, 2, 4, 1000>::decode(&blob).map(|_| ()));
    over(CascadeNet::<7, 8, 3, 1000>::decode(&blob).map(|_| ()));
    // Weight storage: 3 hidden rows (8 + 9 + 10), 4 output rows of 11,
    // and the padding the 8-wide dot product reads past the last row.
    let needed = 27 + 44 + ROW_PAD;
    assert_eq!(needed, weight_capacity(7, 3, 4));
    over(CascadeNet::<7, 8, 4, { 27 + 44 + ROW_PAD - 1 }>::decode(&blob).map(|_| ()));
    assert!(
        CascadeNet::<7, 3, 4, { weight_capacity(7, 3, 4) }>::decode(&blob).is_ok(),
        "exact capacity fits"
    );
}

#[test]
fn unknown_activation_is_rejected() {
    let mut blob = Owned::new(7, 2, 2).blob();
    blob[9] = 7;
    reseal(&mut blob);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::UnknownActivation { code: 7 })
    );
}

#[test]
fn array_length_disagreeing_with_shape_is_rejected() {
    let mut blob = Owned::new(7, 2, 2).blob();
    assert_eq!(blob[10], 7, "input_lo length prefix");
    blob[10] = 6;
    reseal(&mut blob);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::LengthMismatch {
            field: Field::InputLo,
            expected: 7,
            found: 6
        })
    );
    let mut o = Owned::new(7, 2, 2);
    o.hidden.pop();
    assert_eq!(
        encoded_len(&o.view()),
        Err(TnetError::LengthMismatch {
            field: Field::HiddenWeights,
            expected: 17,
            found: 16
        })
    );
}

#[test]
fn invalid_varint_is_malformed() {
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(&[0xFF; 8]);
    assert_eq!(Net::decode(&bytes), Err(TnetError::Malformed));
}

#[test]
fn bytes_after_the_crc_are_rejected() {
    let mut blob = Owned::new(7, 2, 2).blob();
    blob.extend_from_slice(&[0, 0]);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::TrailingBytes { extra: 2 })
    );
}

#[test]
fn any_corrupted_byte_fails_the_crc() {
    let o = Owned::new(7, 2, 2);
    let blob = o.blob();
    let at = find_f32(&blob, o.output[3]);
    let mut bad = blob.clone();
    bad[at + 1] ^= 0x10;
    assert!(matches!(
        Net::decode(&bad),
        Err(TnetError::CrcMismatch { .. })
    ));
    let mut bad = blob.clone();
    let last = bad.len() - 1;
    bad[last] ^= 1;
    assert!(matches!(
        Net::decode(&bad),
        Err(TnetError::CrcMismatch { .. })
    ));
}

#[test]
fn nan_or_infinite_values_are_rejected_even_with_a_valid_crc() {
    let o = Owned::new(7, 3, 2);
    let cases = [
        (Field::HiddenWeights, 9, o.hidden[9], f32::NAN),
        (Field::OutputWeights, 4, o.output[4], f32::INFINITY),
        (Field::InputHi, 2, o.input_hi[2], f32::NEG_INFINITY),
        (Field::OutputHi, 1, o.output_hi[1], f32::NAN),
    ];
    for (field, index, old, new) in cases {
        let mut blob = o.blob();
        let at = find_f32(&blob, old);
        blob[at..at + 4].copy_from_slice(&new.to_le_bytes());
        reseal(&mut blob);
        assert_eq!(
            Net::decode(&blob),
            Err(TnetError::NonFinite { field, index }),
            "{field}"
        );
    }
    let mut o = Owned::new(7, 1, 1);
    o.output[0] = f32::NAN;
    assert!(matches!(
        encoded_len(&o.view()),
        Err(TnetError::NonFinite {
            field: Field::OutputWeights,
            index: 0
        })
    ));
}

#[test]
fn empty_normalisation_range_is_rejected() {
    let o = Owned::new(7, 1, 2);
    let mut blob = o.blob();
    let at = find_f32(&blob, o.input_hi[2]);
    blob[at..at + 4].copy_from_slice(&o.input_lo[2].to_le_bytes());
    reseal(&mut blob);
    assert_eq!(
        Net::decode(&blob),
        Err(TnetError::EmptyRange {
            field: Field::InputLo,
            index: 2
        })
    );
    let mut o = Owned::new(7, 1, 2);
    o.output_hi[1] = -1.0;
    assert_eq!(
        encoded_len(&o.view()),
        Err(TnetError::EmptyRange {
            field: Field::OutputLo,
            index: 1
        })
    );
}

#[test]
fn encoder_reports_a_short_buffer_and_oversized_shapes() {
    let o = Owned::new(7, 2, 2);
    let need = encoded_len(&o.view()).unwrap();
    let mut buf = vec![0u8; need - 1];
    assert_eq!(
        encode(&o.view(), &mut buf),
        Err(TnetError::BufferTooSmall {
            needed: need,
            available: need - 1
        })
    );
    let o = Owned::new(70_000, 0, 1);
    assert_eq!(
        encoded_len(&o.view()),
        Err(TnetError::ShapeTooLarge { value: 70_000 })
    );
}

#[test]
fn failed_decode_into_leaves_the_previous_net_untouched() {
    let good = Owned::new(7, 2, 2).blob();
    let mut net = Net::decode(&good).unwrap();
    let before = net.clone();
    // A corrupted byte (CRC mismatch), and a NaN weight behind a valid CRC:
    // the second passes every structural check and fails only on the value,
    // after the whole file was read, the case a writing decoder would have
    // half-overwritten the net for.
    let mut bad = good.clone();
    bad[20] ^= 0xFF;
    assert!(matches!(
        net.decode_into(&bad),
        Err(TnetError::CrcMismatch { .. })
    ));
    assert_eq!(net, before);
    let o = Owned::new(7, 3, 4);
    let mut nan = o.blob();
    let at = find_f32(&nan, *o.output.last().unwrap());
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    reseal(&mut nan);
    assert!(matches!(
        net.decode_into(&nan),
        Err(TnetError::NonFinite {
            field: Field::OutputWeights,
            ..
        })
    ));
    assert_eq!(net, before);
    assert_eq!(
        Net::validate(&nan).err(),
        net.clone().decode_into(&nan).err()
    );
    // A smaller net decoded over a bigger one leaves zeros, not stale weights.
    let mut big = Net::decode(&Owned::new(7, 8, 4).blob()).unwrap();
    big.decode_into(&good).unwrap();
    assert_eq!(big, before);
}

#[test]
fn checked_bytes_decode_only_into_a_net_they_fit() {
    let blob = Owned::new(7, 6, 4).blob();
    let checked = CascadeNet::<7, 16, 4, { weight_capacity(7, 16, 4) }>::check(&blob).unwrap();
    assert_eq!(checked.header().shape, Owned::new(7, 6, 4).shape);
    let mut fits = Net::empty();
    fits.decode_checked(&checked).unwrap();
    assert_eq!(fits, Net::decode(&blob).unwrap());
    let mut small =
        CascadeNet::<7, 5, 4, { weight_capacity(7, 5, 4) }>::decode(&Owned::new(7, 2, 4).blob())
            .unwrap();
    let before = small.clone();
    assert!(matches!(
        small.decode_checked(&checked),
        Err(TnetError::ShapeOverCapacity { hidden: 6, .. })
    ));
    assert_eq!(small, before);
}

#[test]
fn from_view_builds_the_net_the_decoder_builds() {
    for (i, h, o) in [(7, 0, 1), (7, 3, 4), (3, 8, 2), (7, 8, 4)] {
        let owned = Owned::new(i, h, o);
        let decoded = Net::decode(&owned.blob()).unwrap();
        assert_eq!(Net::from_view(&owned.view()), Ok(decoded));
    }
    // And rejects what the decoder rejects, with the same error.
    let mut owned = Owned::new(7, 3, 4);
    owned.hidden[5] = f32::INFINITY;
    assert_eq!(
        Net::from_view(&owned.view()),
        Err(TnetError::NonFinite {
            field: Field::HiddenWeights,
            index: 5
        })
    );
    let mut owned = Owned::new(7, 3, 4);
    owned.output_hi[1] = owned.output_lo[1];
    assert_eq!(
        Net::from_view(&owned.view()),
        Err(TnetError::EmptyRange {
            field: Field::OutputLo,
            index: 1
        })
    );
    let owned = Owned::new(7, 9, 4);
    assert!(matches!(
        Net::from_view(&owned.view()),
        Err(TnetError::ShapeOverCapacity { hidden: 9, .. })
    ));
    let mut owned = Owned::new(7, 3, 4);
    owned.output.pop();
    assert!(matches!(
        Net::from_view(&owned.view()),
        Err(TnetError::LengthMismatch {
            field: Field::OutputWeights,
            ..
        })
    ));
}

/// A net built in const context: what the firmware's build script emits.
static CONST_NET: CascadeNet<2, 1, 1, { weight_capacity(2, 1, 1) }> =
    match CascadeNet::from_view(&TnetView {
        shape: NetShape {
            inputs: 2,
            hidden: 1,
            outputs: 1,
        },
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: Activation::Linear,
        input_lo: &[0.0, -1.0],
        input_hi: &[1.0, 1.0],
        output_lo: &[0.0],
        output_hi: &[f32::from_bits(0x4120_0000)],
        hidden_weights: &[0.5, 0.25, -0.25],
        output_weights: &[1.0, 2.0, 3.0, 4.0],
    }) {
        Ok(n) => n,
        Err(_) => panic!("invalid const net"),
    };

#[test]
fn a_const_net_has_the_packed_layout() {
    assert_eq!(CONST_NET.shape().hidden, 1);
    assert_eq!(CONST_NET.output_hi(), &[10.0]);
    assert_eq!(
        CONST_NET.weights(),
        &[0.5, 0.25, -0.25, 1.0, 2.0, 3.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    );
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = Net::decode(&bytes);
    }

    #[test]
    fn arbitrary_bytes_after_a_valid_header_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut bytes = Owned::new(7, 2, 2).blob()[..12].to_vec();
        bytes.extend_from_slice(&tail);
        // Random weights almost never carry a matching CRC (2^-32).
        prop_assert!(Net::decode(&bytes).is_err());
    }

    #[test]
    fn any_single_byte_change_is_rejected(pos in 0usize..1000, xor in 1u8..=255) {
        let blob = Owned::new(7, 3, 4).blob();
        let mut bad = blob.clone();
        let i = pos % bad.len();
        bad[i] ^= xor;
        prop_assert!(Net::decode(&bad).is_err());
    }

    #[test]
    fn random_shapes_round_trip(i in 1usize..=7, h in 0usize..=8, o in 1usize..=4) {
        let net = Owned::new(i, h, o);
        let d = Net::decode(&net.blob()).unwrap();
        prop_assert_eq!(d.shape(), net.shape);
    }
}

#[test]
fn a_decode_over_any_earlier_net_equals_a_fresh_decode() {
    // The decode zeroes only what its rows do not write when all inputs
    // are present (the hot swap's install: net.rs clear_for); whatever the
    // slot held before, the result must be the fresh decode's, bit for bit.
    let shapes = [
        (7, 8, 4),
        (7, 3, 2),
        (7, 0, 1),
        (6, 8, 4),
        (5, 6, 3),
        (7, 1, 4),
    ];
    for &(ai, ah, ao) in &shapes {
        for &(bi, bh, bo) in &shapes {
            let mut slot = Net::decode(&Owned::new(ai, ah, ao).blob()).unwrap();
            let blob = Owned::new(bi, bh, bo).blob();
            let checked = Net::check(&blob).unwrap();
            slot.decode_checked(&checked).unwrap();
            assert_eq!(
                slot,
                Net::decode(&blob).unwrap(),
                "{ai}-{ah}-{ao} then {bi}-{bh}-{bo}"
            );
        }
    }
}

/// The link's net hash names a net: different nets differ, and it is the
/// file's own CRC field; the CRC-32 of a whole file (its CRC appended) is
/// the same residue for every valid file and would name none.
#[test]
fn net_hash_tells_nets_apart_where_a_whole_file_crc_cannot() {
    let a = Owned::new(7, 3, 4).blob();
    let b = Owned::new(7, 4, 4).blob();
    assert_ne!(a, b);
    assert_ne!(tnet::net_hash(&a), tnet::net_hash(&b));
    let field = |f: &[u8]| u32::from_le_bytes(f[f.len() - 4..].try_into().unwrap());
    assert_eq!(tnet::net_hash(&a), field(&a));
    assert_eq!(tnet::net_hash(&b), field(&b));
    assert_eq!(crc32(&a), 0x2144_DF1C);
    assert_eq!(crc32(&b), 0x2144_DF1C);
}
