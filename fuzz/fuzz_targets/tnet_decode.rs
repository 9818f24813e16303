//! Any byte string through the `.tnet` decoder and the MCU's hot-swap paths
//! (flash default + RAM slot), one-shot and incremental: must never panic; a
//! rejected blob must leave the running net exactly as it was (also when the
//! running net is the RAM slot); an accepted net must equal the plain
//! decoder's and run inference and a control step with commands inside the
//! limits. The incremental swap (docs/design.md §5.3) runs the same bytes
//! with a slice size taken from the input, sometimes after a valid update
//! it supersedes mid-check: the old net runs at every period until a
//! `Swapped` slice, which comes exactly when the one-shot path accepts,
//! and a rejection carries the one-shot path's error. Inputs whose length is odd get their CRC
//! trailer recomputed first, so the fuzzer also explores the checks behind
//! the checksum (lengths, NaN/∞, empty ranges) instead of stopping at it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tendril_firmware::control::{
    control_step, ControlConfig, ControlSetpoint, ControlState, StepInput,
};
use tendril_firmware::{
    infer, McuNet, McuSlots, McuSwap, NetStore, SwapError, SwapEvent, DEFAULT_NET,
};
use tendril_shared::{TendonLimits, MAX_TENDONS};

/// A valid 7-12-4 update (the MCU vectors' hot-swap blob).
static UPDATE: &[u8] = include_bytes!("../../firmware/vectors/swap.tnet");

fuzz_target!(|input: &[u8]| {
    let mut owned = input.to_vec();
    if owned.len() % 2 == 1 && owned.len() >= 8 {
        let n = owned.len() - 4;
        let crc = tendril_shared::crc32::crc32(&owned[..n]);
        owned[n..].copy_from_slice(&crc.to_le_bytes());
    }
    let data = &owned[..];
    let n_out = match tendril_shared::tnet::read_header(data) {
        Ok((s, _, _)) => s.outputs.clamp(1, MAX_TENDONS),
        Err(_) => 4,
    };
    let mut ram = Box::new(McuNet::empty());
    let mut store = McuSlots::new(&DEFAULT_NET, &mut ram);
    // Half the inputs run with the flash net, half with a valid update
    // already running from the RAM slot (the slot a new blob is written to).
    if input.first().is_some_and(|b| b & 1 == 1) {
        store.load(UPDATE, (7, 4)).expect("the update blob loads");
        assert!(store.running_ram());
    }
    let running = store.active().clone();
    let was_ram = store.running_ram();
    let decoded = McuNet::decode(data);
    let one_shot = {
        let mut ram2 = Box::new(McuNet::empty());
        let mut probe = McuSlots::new(&DEFAULT_NET, &mut ram2);
        probe.load(data, (7, n_out))
    };
    incremental(input, data, (7, n_out), was_ram, &one_shot);
    if store.load(data, (7, n_out)).is_err() {
        assert_eq!(
            store.active(),
            &running,
            "a rejected blob changed the running net"
        );
        assert_eq!(store.running_ram(), was_ram);
        return;
    }
    assert_eq!(Ok(store.active()), decoded.as_ref());
    let net: &McuNet = store.active();
    let pose = [0.0, 0.0, 0.35, 1.0, 0.0, 0.0, 0.0];
    let _ = infer(net, &pose);
    let cfg = ControlConfig::new(TendonLimits::uniform(n_out, 10.0, 100.0).expect("valid limits"));
    let st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let input = StepInput {
        now_ns: 1_000_000,
        setpoint: Some(ControlSetpoint {
            seq: 1,
            pose,
            tangent: None,
        }),
        feedback: None,
    };
    let (_, out) = control_step(&cfg, net, &st, &input);
    for &c in &out.command {
        assert!(c.is_finite() && (0.0..=10.0).contains(&c));
        assert!(c <= 0.1 + 1e-6, "slew limit: 100 N/s over 1 ms");
    }
});

/// The incremental swap of `data` from the same starting point (flash net,
/// or [`UPDATE`] running from the RAM slot), slice size from the input's
/// last byte; with the input's second byte odd, [`UPDATE`] is offered first
/// and superseded by `data` after a few slices.
fn incremental(
    input: &[u8],
    data: &[u8],
    want: (usize, usize),
    ram_running: bool,
    one_shot: &Result<(), SwapError>,
) {
    let mut ram = Box::new(McuNet::empty());
    let mut store = McuSlots::new(&DEFAULT_NET, &mut ram);
    if ram_running {
        store.load(UPDATE, (7, 4)).expect("the update blob loads");
    }
    let old = store.active().clone();
    let budget = usize::from(input.last().copied().unwrap_or(0)) * 61 + 1;
    let mut swap = McuSwap::new();
    if input.get(1).is_some_and(|b| b & 1 == 1) {
        swap.offer(UPDATE, (7, 4)).expect("nothing in progress");
        let slices = usize::from(input.get(2).copied().unwrap_or(0) % 8);
        for _ in 0..slices {
            assert_eq!(swap.slice(&mut store, budget), SwapEvent::Working);
            assert_eq!(store.active(), &old);
        }
        assert_eq!(swap.offer(data, want), Err(SwapError::Superseded));
    } else {
        swap.offer(data, want).expect("nothing in progress");
    }
    // Structure, hash, six arrays, ranges, write: bounded by the slice size.
    let limit = 12 + 2 * (data.len() / (budget & !3).max(4) + 1);
    for _ in 0..limit {
        match swap.slice(&mut store, budget) {
            SwapEvent::Working => assert_eq!(store.active(), &old, "the old net stopped mid-check"),
            SwapEvent::Swapped => {
                assert_eq!(
                    one_shot,
                    &Ok(()),
                    "incremental swap accepted what load refused"
                );
                assert_eq!(Ok(store.active()), McuNet::decode(data).as_ref());
                assert!(store.running_ram());
                return;
            }
            SwapEvent::Rejected(e) => {
                assert_eq!(one_shot, &Err(e), "incremental and one-shot disagree");
                assert_eq!(
                    store.active(),
                    &old,
                    "a rejected blob changed the running net"
                );
                assert_eq!(store.running_ram(), ram_running);
                return;
            }
            SwapEvent::Idle => panic!("idle before the job ended"),
        }
    }
    panic!("the incremental swap did not finish in {limit} slices");
}
