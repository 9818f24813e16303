//! Any byte stream through the link's frame decoder (`tendril_shared::link`,
//! a `FrameDecoder<256>` decoding a small test message): it must never
//! panic; its counters never go down and account for every reported frame;
//! a byte-level decoder (`push_raw`) fed the same bytes agrees frame by
//! frame (a message ⇔ a good CRC whose payload postcard accepts); and every
//! decoded message re-encodes and decodes back to itself.
//!
//! Inputs whose first byte is odd are read as length-prefixed pieces that
//! are framed with a correct CRC (`encode_raw`) when the length byte's top
//! bit is clear and sent raw otherwise, so the fuzzer reaches postcard
//! behind the CRC (and the oversize path) instead of stopping at the CRC.
#![no_main]

use libfuzzer_sys::fuzz_target;
use serde::{Deserialize, Serialize};
use tendril_shared::link::{
    encode, encode_raw, max_frame_len, FrameCounters, FrameDecoder, FrameError,
};

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
    tail: u64,
}

const N: usize = 256;

fn stream_from(input: &[u8]) -> Vec<u8> {
    let Some((&mode, rest)) = input.split_first() else {
        return Vec::new();
    };
    if mode & 1 == 0 {
        return rest.to_vec();
    }
    let mut out = Vec::new();
    let mut rest = rest;
    while let Some((&head, tail)) = rest.split_first() {
        let n = usize::from(head & 0x7f).min(tail.len());
        let (piece, more) = tail.split_at(n);
        if head & 0x80 == 0 {
            let mut buf = vec![0u8; max_frame_len(piece.len())];
            out.extend_from_slice(encode_raw(piece, &mut buf).expect("sized by max_frame_len"));
        } else {
            out.extend_from_slice(piece);
        }
        rest = more;
    }
    out
}

fn grew(before: &FrameCounters, after: &FrameCounters) -> bool {
    after.frames_ok >= before.frames_ok
        && after.crc_errors >= before.crc_errors
        && after.cobs_errors >= before.cobs_errors
        && after.decode_errors >= before.decode_errors
        && after.oversized >= before.oversized
        && after.bytes_dropped >= before.bytes_dropped
}

fn total(c: &FrameCounters) -> u32 {
    c.frames_ok + c.crc_errors + c.cobs_errors + c.decode_errors + c.oversized
}

fuzz_target!(|input: &[u8]| {
    let stream = stream_from(input);
    let mut dec = Box::new(FrameDecoder::<N>::new());
    let mut raw = Box::new(FrameDecoder::<N>::new());
    let mut prev = dec.counters();
    let mut reported = 0u32;
    for &b in &stream {
        let got = dec.push::<Msg>(b);
        let got_raw = raw.push_raw(b).map(|r| r.map(<[u8]>::to_vec));
        match (&got, &got_raw) {
            (None, None) => {}
            (Some(Ok(_)), Some(Ok(_))) => {}
            (Some(Err(FrameError::Decode)), Some(Ok(payload))) => {
                assert!(postcard::take_from_bytes::<Msg>(payload).is_err());
            }
            (Some(Err(FrameError::TrailingBytes)), Some(Ok(payload))) => {
                assert!(postcard::take_from_bytes::<Msg>(payload)
                    .is_ok_and(|(_, rest)| !rest.is_empty()));
            }
            (Some(Err(e)), Some(Err(e2))) => assert_eq!(e, e2),
            _ => panic!("push and push_raw disagree: {got:?} vs {got_raw:?}"),
        }
        let now = dec.counters();
        assert!(grew(&prev, &now), "counters went down: {prev:?} -> {now:?}");
        prev = now;
        if let Some(result) = got {
            reported += 1;
            if let Ok(msg) = result {
                // Re-encode and decode again with a fresh decoder.
                let mut buf = [0u8; N];
                let frame = encode(&msg, &mut buf).expect("a decoded message fits again");
                assert!(frame.len() <= N);
                let mut again = FrameDecoder::<N>::new();
                let back: Vec<Msg> = frame
                    .iter()
                    .filter_map(|&b| again.push::<Msg>(b))
                    .map(|r| r.expect("a re-encoded message decodes"))
                    .collect();
                assert_eq!(back, [msg]);
            }
        }
    }
    assert_eq!(total(&dec.counters()), reported);
    assert!(dec.counters().bytes_dropped as usize <= stream.len());
});
