//! Any byte string through the `.tnet` decoder and the MCU's hot-swap path
//! (flash default + RAM slot): must never panic; a rejected blob must leave
//! the running net exactly as it was (also when the running net is the RAM
//! slot); an accepted net must equal the plain decoder's and run inference
//! and a control step with commands inside the limits. Inputs whose length is odd get their CRC
//! trailer recomputed first, so the fuzzer also explores the checks behind
//! the checksum (lengths, NaN/∞, empty ranges) instead of stopping at it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tendril_firmware::control::{control_step, ControlConfig, ControlState, Setpoint, StepInput};
use tendril_firmware::{infer, McuNet, McuSlots, NetStore, DEFAULT_NET};
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
    if store.load(data, (7, n_out)).is_err() {
        assert_eq!(store.active(), &running, "a rejected blob changed the running net");
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
        setpoint: Some(Setpoint {
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
