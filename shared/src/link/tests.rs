//! Frame layer tests: hand-built frames (independent CRC and COBS facts),
//! round trips, and streams with corruption, garbage, truncation and
//! oversized frames.

use super::*;
use proptest::prelude::*;
use serde::{Deserialize, Serialize};
use std::vec::Vec;

#[derive(Serialize, Deserialize, Debug, PartialEq, Clone)]
enum Mode {
    Idle,
    Run(u16),
    Stop { code: u8 },
}

#[derive(Serialize, Deserialize, Debug, PartialEq, Clone)]
struct Msg {
    seq: u32,
    on: bool,
    mode: Mode,
    pose: [i16; 3],
    note: Option<u8>,
}

/// Largest postcard encoding of `Msg`: u32 varint 5, bool 1, enum tag 1 +
/// u16 varint 3, three i16 zigzag varints 3 each, option 2.
const MSG_MAX: usize = 5 + 1 + 4 + 9 + 2;
type MsgDecoder = FrameDecoder<{ max_frame_len(MSG_MAX) }>;

fn msg(seq: u32) -> Msg {
    Msg {
        seq,
        on: seq & 1 == 0,
        mode: Mode::Run(seq as u16 ^ 0x5a5a),
        pose: [-1, 300, i16::MIN],
        note: Some(0),
    }
}

fn frame<T: Serialize>(m: &T) -> Vec<u8> {
    let mut buf = [0u8; 512];
    encode(m, &mut buf)
        .expect("test buffer is large enough")
        .to_vec()
}

fn raw_frame(payload: &[u8]) -> Vec<u8> {
    let mut buf = std::vec![0u8; max_frame_len(payload.len())];
    encode_raw(payload, &mut buf)
        .expect("sized by max_frame_len")
        .to_vec()
}

/// Every outcome the decoder reports for `bytes`, in order.
fn outcomes<T: serde::de::DeserializeOwned, const N: usize>(
    dec: &mut FrameDecoder<N>,
    bytes: &[u8],
) -> Vec<Result<T, FrameError>> {
    bytes.iter().filter_map(|&b| dec.push::<T>(b)).collect()
}

fn raw_outcomes<const N: usize>(
    dec: &mut FrameDecoder<N>,
    bytes: &[u8],
) -> Vec<Result<Vec<u8>, FrameError>> {
    bytes
        .iter()
        .filter_map(|&b| dec.push_raw(b).map(|r| r.map(<[u8]>::to_vec)))
        .collect()
}

#[test]
fn hand_built_frame_of_the_crc_check_string() {
    // CRC-32 of "123456789" is the catalogue check value 0xCBF43926, sent
    // little-endian; 13 bytes with no zero are one COBS block with code 14.
    let mut want = std::vec![0x0E];
    want.extend_from_slice(b"123456789");
    want.extend_from_slice(&[0x26, 0x39, 0xF4, 0xCB, 0x00]);
    assert_eq!(raw_frame(b"123456789"), want);
    let mut dec = FrameDecoder::<64>::new();
    assert_eq!(raw_outcomes(&mut dec, &want), [Ok(b"123456789".to_vec())]);
}

#[test]
fn hand_built_frame_with_a_zero_byte() {
    // Payload [0x00]: CRC-32 of a single zero byte is 0xD202EF8D. COBS (as
    // in the paper / Wikipedia's "00 11 22" style examples): the empty run
    // before the zero is code 01, then a 4-byte run is code 05.
    let want = [0x01, 0x05, 0x8D, 0xEF, 0x02, 0xD2, 0x00];
    assert_eq!(raw_frame(&[0x00]), want);
    let mut dec = FrameDecoder::<16>::new();
    assert_eq!(raw_outcomes(&mut dec, &want), [Ok(std::vec![0u8])]);
}

#[test]
fn wikipedia_cobs_example_11_22_00_33() {
    // Wikipedia: 11 22 00 33 encodes as 03 11 22 02 33 00. Our frame of that
    // payload must start with the same code bytes and data (the CRC bytes
    // continue the last run).
    let f = raw_frame(&[0x11, 0x22, 0x00, 0x33]);
    assert_eq!(&f[..4], &[0x03, 0x11, 0x22, 0x02 + 4]);
    assert_eq!(f[4], 0x33);
    assert_eq!(f.last(), Some(&0));
}

#[test]
fn struct_round_trip_and_counters() {
    let mut dec = MsgDecoder::new();
    let mut stream = Vec::new();
    for i in 0..5 {
        stream.extend(frame(&msg(i)));
    }
    let got = outcomes::<Msg, _>(&mut dec, &stream);
    assert_eq!(got, (0..5).map(|i| Ok(msg(i))).collect::<Vec<_>>());
    assert_eq!(
        dec.counters(),
        FrameCounters {
            frames_ok: 5,
            ..FrameCounters::default()
        }
    );
}

#[test]
fn feed_in_chunks_matches_push() {
    let mut stream = std::vec![0x13, 0x37, 0x00];
    for i in 0..20 {
        stream.extend(frame(&msg(i)));
    }
    for chunk in 1..stream.len() {
        let mut dec = MsgDecoder::new();
        let mut got = Vec::new();
        for part in stream.chunks(chunk) {
            dec.feed::<Msg>(part, |m| got.push(m));
        }
        assert_eq!(got, (0..20).map(msg).collect::<Vec<_>>());
        assert_eq!(dec.counters().cobs_errors + dec.counters().crc_errors, 1);
    }
}

#[test]
fn every_single_byte_corruption_is_rejected_and_the_next_frame_survives() {
    let bad = frame(&msg(7));
    let good = frame(&msg(8));
    let body = bad.len() - 1; // the terminator is covered below
    let mut cases = 0;
    for pos in 0..body {
        for x in 1..=255u8 {
            let mut stream = bad.clone();
            stream[pos] ^= x;
            stream.extend_from_slice(&good);
            let mut dec = MsgDecoder::new();
            let got = outcomes::<Msg, _>(&mut dec, &stream);
            let (last, errors) = got.split_last().expect("at least the good frame");
            assert_eq!(last, &Ok(msg(8)), "pos {pos} xor {x:#04x}");
            assert!(
                !errors.is_empty(),
                "pos {pos} xor {x:#04x}: corruption not seen"
            );
            for e in errors {
                assert!(
                    matches!(
                        e,
                        Err(FrameError::Crc | FrameError::Cobs | FrameError::TooShort)
                    ),
                    "pos {pos} xor {x:#04x}: {e:?}"
                );
            }
            let c = dec.counters();
            assert_eq!(c.frames_ok, 1);
            assert_eq!(c.decode_errors + c.oversized, 0);
            // Every byte of the corrupted frame, and nothing else, dropped;
            // except a 0x00 right after another (or first), which is a
            // lone delimiter (ignored) rather than a frame: a byte turned
            // into 0x00 at the start, or just before the terminator.
            let lone = (0..bad.len())
                .filter(|&i| stream[i] == 0 && (i == 0 || stream[i - 1] == 0))
                .count();
            assert_eq!(
                c.bytes_dropped as usize,
                bad.len() - lone,
                "pos {pos} xor {x:#04x}"
            );
            cases += 1;
        }
    }
    assert_eq!(cases, body * 255);
}

#[test]
fn a_corrupted_terminator_loses_two_frames_then_resynchronises() {
    // 0x00 -> non-zero merges the frame with the next one: both go, as one
    // rejected frame, and the third decodes.
    let (a, b, c) = (frame(&msg(1)), frame(&msg(2)), frame(&msg(3)));
    for x in 1..=255u8 {
        let mut stream = a.clone();
        *stream.last_mut().expect("non-empty") = x;
        stream.extend_from_slice(&b);
        stream.extend_from_slice(&c);
        let mut dec = MsgDecoder::new();
        let got = outcomes::<Msg, _>(&mut dec, &stream);
        assert_eq!(got.len(), 2, "xor {x:#04x}: {got:?}");
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok(msg(3)));
        assert_eq!(dec.counters().bytes_dropped as usize, a.len() + b.len());
    }
}

#[test]
fn garbage_prefix() {
    let good = frame(&msg(1));
    // Garbage ended by a 0x00 (e.g. the sender's sync byte): one error, the
    // frame decodes.
    let mut stream = b"\x17garbage\xff\xfe".to_vec();
    stream.push(0);
    stream.extend_from_slice(&good);
    let mut dec = MsgDecoder::new();
    assert_eq!(
        outcomes::<Msg, _>(&mut dec, &stream),
        [Err(FrameError::Cobs), Ok(msg(1))]
    );
    assert_eq!(
        dec.counters(),
        FrameCounters {
            frames_ok: 1,
            cobs_errors: 1,
            bytes_dropped: 11,
            ..FrameCounters::default()
        }
    );
    // Garbage with no 0x00 merges with the first frame (nothing can tell
    // where it starts): that frame is lost, the next one decodes.
    let mut stream = b"\x05\x05\x05".to_vec();
    stream.extend_from_slice(&good);
    stream.extend_from_slice(&frame(&msg(2)));
    let mut dec = MsgDecoder::new();
    let got = outcomes::<Msg, _>(&mut dec, &stream);
    assert_eq!(got.len(), 2);
    assert!(got[0].is_err());
    assert_eq!(got[1], Ok(msg(2)));
    assert_eq!(dec.counters().bytes_dropped as usize, 3 + good.len());
}

#[test]
fn lone_delimiters_are_ignored() {
    let mut stream = std::vec![0, 0, 0];
    stream.extend(frame(&msg(1)));
    stream.extend([0, 0]);
    let mut dec = MsgDecoder::new();
    assert_eq!(outcomes::<Msg, _>(&mut dec, &stream), [Ok(msg(1))]);
    assert_eq!(dec.counters().bytes_dropped, 0);
}

#[test]
fn truncated_frame_then_good_frame() {
    let cut = frame(&msg(5));
    let good = frame(&msg(6));
    for k in 1..cut.len() - 1 {
        let mut stream = cut[..k].to_vec();
        stream.push(0); // the sender restarted and resynchronised
        stream.extend_from_slice(&good);
        let mut dec = MsgDecoder::new();
        let got = outcomes::<Msg, _>(&mut dec, &stream);
        assert_eq!(got.len(), 2, "cut at {k}");
        assert!(
            matches!(
                got[0],
                Err(FrameError::Cobs | FrameError::Crc | FrameError::TooShort)
            ),
            "cut at {k}: {:?}",
            got[0]
        );
        assert_eq!(got[1], Ok(msg(6)));
        assert_eq!(dec.counters().bytes_dropped as usize, k + 1);
    }
}

#[test]
fn oversized_frame_is_dropped_up_to_its_terminator() {
    const N: usize = 32;
    let big = raw_frame(&[0xAB; 40]);
    assert!(big.len() > N);
    let good = raw_frame(b"ok");
    let mut stream = big.clone();
    stream.extend_from_slice(&good);
    let mut dec = FrameDecoder::<N>::new();
    assert_eq!(
        raw_outcomes(&mut dec, &stream),
        [Err(FrameError::Oversized), Ok(b"ok".to_vec())]
    );
    assert_eq!(
        dec.counters(),
        FrameCounters {
            frames_ok: 1,
            oversized: 1,
            bytes_dropped: big.len() as u32,
            ..FrameCounters::default()
        }
    );
    // A long run with no zero at all never grows anything and ends as one
    // oversized frame.
    let mut dec = FrameDecoder::<N>::new();
    for _ in 0..100_000 {
        assert!(dec.push_raw(0x42).is_none());
    }
    assert_eq!(dec.push_raw(0), Some(Err(FrameError::Oversized)));
    assert_eq!(dec.counters().bytes_dropped, 100_001);
}

#[test]
fn frame_of_exactly_n_bytes_fits_one_more_does_not() {
    for n in 1..60usize {
        let f = raw_frame(&std::vec![7u8; n]);
        let len = f.len();
        let mut at = FrameDecoder::<64>::new();
        let fits = len <= 64;
        assert_eq!(raw_outcomes(&mut at, &f).len(), 1);
        assert_eq!(at.counters().frames_ok, u32::from(fits));
        // The same frame in a decoder one byte too small.
        if len <= 65 {
            let mut small = FrameDecoder::<64>::new();
            let mut longer = std::vec![7u8; n];
            longer.resize(n + (65 - len), 7);
            let f2 = raw_frame(&longer);
            assert_eq!(f2.len(), 65);
            assert_eq!(raw_outcomes(&mut small, &f2), [Err(FrameError::Oversized)]);
        }
    }
    // Exactly N: accepted (58 + CRC 4 + code byte + terminator = 64).
    let f = raw_frame(&[7u8; 58]);
    assert_eq!(f.len(), 64);
    let mut dec = FrameDecoder::<64>::new();
    assert_eq!(raw_outcomes(&mut dec, &f), [Ok(std::vec![7u8; 58])]);
}

#[test]
fn valid_frame_with_a_bad_payload_is_a_decode_error() {
    let mut dec = MsgDecoder::new();
    // A bool of 2: the CRC is good, postcard refuses.
    let bad = raw_frame(&[1, 2, 0, 0, 0, 0, 0]);
    // A valid Msg followed by one extra byte.
    let mut buf = [0u8; 64];
    let mut payload = postcard::to_slice(&msg(3), &mut buf)
        .expect("fits")
        .to_vec();
    payload.push(9);
    let trailing = raw_frame(&payload);
    let short = raw_frame(&[1, 1]); // CRC fine, message cut short
    let mut stream = bad.clone();
    stream.extend_from_slice(&trailing);
    stream.extend_from_slice(&short);
    stream.extend(frame(&msg(4)));
    assert_eq!(
        outcomes::<Msg, _>(&mut dec, &stream),
        [
            Err(FrameError::Decode),
            Err(FrameError::TrailingBytes),
            Err(FrameError::Decode),
            Ok(msg(4))
        ]
    );
    assert_eq!(
        dec.counters(),
        FrameCounters {
            frames_ok: 1,
            decode_errors: 3,
            bytes_dropped: (bad.len() + trailing.len() + short.len()) as u32,
            ..FrameCounters::default()
        }
    );
}

#[test]
fn runt_frames_are_crc_errors() {
    // COBS-valid frames of 0..=3 decoded bytes cannot hold a CRC.
    let mut dec = FrameDecoder::<16>::new();
    let stream = [0x01, 0x00, 0x02, 0xAA, 0x00, 0x04, 1, 2, 3, 0x00];
    assert_eq!(
        raw_outcomes(&mut dec, &stream),
        [
            Err(FrameError::TooShort),
            Err(FrameError::TooShort),
            Err(FrameError::TooShort)
        ]
    );
    assert_eq!(dec.counters().crc_errors, 3);
    assert_eq!(dec.counters().bytes_dropped, 10);
    // An empty payload is a valid frame (a unit message).
    let mut dec = FrameDecoder::<16>::new();
    assert_eq!(outcomes::<(), _>(&mut dec, &raw_frame(&[])), [Ok(())]);
}

#[test]
fn encode_reports_a_small_buffer() {
    let full = frame(&msg(9));
    for n in 0..full.len() {
        let mut buf = std::vec![0u8; n];
        assert_eq!(
            encode(&msg(9), &mut buf),
            Err(FrameError::BufferTooSmall),
            "{n}"
        );
        assert_eq!(
            encode_raw(b"123456789", &mut buf[..n.min(14)]),
            Err(FrameError::BufferTooSmall)
        );
    }
    let mut buf = std::vec![0u8; full.len()];
    assert_eq!(encode(&msg(9), &mut buf), Ok(&full[..]));
}

#[test]
fn max_frame_len_is_tight_for_runs_without_zeros() {
    // 254 non-zero data bytes (payload 250 + CRC 4) are the worst case for
    // one COBS block: code, 254 bytes, a final empty-run code, terminator.
    let payload = std::vec![0x11u8; 250];
    let f = raw_frame(&payload);
    assert!(f.len() <= max_frame_len(250));
    assert_eq!(max_frame_len(250), 254 + 1 + 1 + 1);
    assert_eq!(max_frame_len(usize::MAX), usize::MAX);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn arbitrary_payloads_round_trip(payload in proptest::collection::vec(any::<u8>(), 0..700)) {
        let f = raw_frame(&payload);
        prop_assert!(f.len() <= max_frame_len(payload.len()));
        prop_assert_eq!(f.iter().position(|&b| b == 0), Some(f.len() - 1));
        let mut dec = FrameDecoder::<{ max_frame_len(700) }>::new();
        let got = raw_outcomes(&mut dec, &f);
        prop_assert_eq!(got, std::vec![Ok(payload)]);
    }

    #[test]
    fn arbitrary_messages_round_trip(
        seq in any::<u32>(), on in any::<bool>(), tag in 0u8..3, v in any::<u16>(),
        pose in any::<[i16; 3]>(), note in any::<Option<u8>>(),
    ) {
        let mode = match tag { 0 => Mode::Idle, 1 => Mode::Run(v), _ => Mode::Stop { code: v as u8 } };
        let m = Msg { seq, on, mode, pose, note };
        let f = frame(&m);
        prop_assert!(f.len() <= max_frame_len(MSG_MAX));
        let mut dec = MsgDecoder::new();
        prop_assert_eq!(outcomes::<Msg, _>(&mut dec, &f), std::vec![Ok(m)]);
    }

    #[test]
    fn arbitrary_streams_never_panic_and_counters_add_up(
        noise in proptest::collection::vec(any::<u8>(), 0..400),
        cuts in proptest::collection::vec(any::<u16>(), 0..6),
    ) {
        // Good frames spliced into noise at arbitrary points.
        let mut stream = noise.clone();
        for (i, c) in cuts.iter().enumerate() {
            let at = usize::from(*c) % (stream.len() + 1);
            let f = frame(&msg(i as u32));
            stream.splice(at..at, f);
        }
        let mut dec = FrameDecoder::<48>::new();
        let mut prev = dec.counters();
        let mut results = 0u32;
        let mut oks = 0u32;
        for &b in &stream {
            if let Some(r) = dec.push::<Msg>(b) {
                results += 1;
                oks += u32::from(r.is_ok());
            }
            let c = dec.counters();
            prop_assert!(c.frames_ok >= prev.frames_ok && c.crc_errors >= prev.crc_errors
                && c.cobs_errors >= prev.cobs_errors && c.decode_errors >= prev.decode_errors
                && c.oversized >= prev.oversized && c.bytes_dropped >= prev.bytes_dropped);
            prev = c;
        }
        let c = dec.counters();
        prop_assert_eq!(c.frames_ok, oks);
        prop_assert_eq!(
            c.frames_ok + c.crc_errors + c.cobs_errors + c.decode_errors + c.oversized,
            results
        );
        // Every byte up to the last 0x00 is either in a good frame, a
        // dropped frame, or a lone delimiter.
        prop_assert!(c.bytes_dropped as usize <= stream.len());
    }
}
