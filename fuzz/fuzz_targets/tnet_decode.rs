//! Any byte string through the `.tnet` decoder and the hot-swap path: must
//! never panic; an accepted net must run inference and a control step with
//! commands inside the limits. Inputs whose length is odd get their CRC
//! trailer recomputed first, so the fuzzer also explores the checks behind
//! the checksum (lengths, NaN/∞, empty ranges) instead of stopping at it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tendril_firmware::control::{control_step, ControlConfig, ControlState, Setpoint, StepInput};
use tendril_firmware::{infer, McuNet, McuSlots};
use tendril_shared::{TendonLimits, MAX_TENDONS};

fuzz_target!(|input: &[u8]| {
    let mut owned = input.to_vec();
    if owned.len() % 2 == 1 && owned.len() >= 8 {
        let n = owned.len() - 4;
        let crc = tendril_shared::crc32::crc32(&owned[..n]);
        owned[n..].copy_from_slice(&crc.to_le_bytes());
    }
    let data = &owned[..];
    let _ = tendril_shared::tnet::read_header(data);
    let mut slots = Box::new(McuSlots::new());
    let n_out = match tendril_shared::tnet::read_header(data) {
        Ok((s, _, _)) => s.outputs.clamp(1, MAX_TENDONS),
        Err(_) => 4,
    };
    if slots.load(data, (7, n_out)).is_err() {
        assert!(
            slots.active().is_empty(),
            "a rejected blob must not become active"
        );
        return;
    }
    let net: &McuNet = slots.active();
    let pose = [0.0, 0.0, 0.35, 1.0, 0.0, 0.0, 0.0];
    let _ = infer(net, &pose);
    let cfg = ControlConfig::new(TendonLimits::uniform(n_out, 10.0, 100.0).expect("valid limits"));
    let st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let input = StepInput {
        now_ns: 1_000_000,
        setpoint: Some(Setpoint { seq: 1, pose }),
        feedback: None,
    };
    let (_, out) = control_step(&cfg, net, &st, &input);
    for &c in &out.command {
        assert!(c.is_finite() && (0.0..=10.0).contains(&c));
        assert!(c <= 0.1 + 1e-6, "slew limit: 100 N/s over 1 ms");
    }
});
