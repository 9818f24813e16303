//! Host speed of the firmware core on the default exported net (the figure
//! and its history are in BENCHMARKS.md, "Firmware"). The net is the MCU binary's built-in
//! [`tendril_firmware::DEFAULT_NET`] and the poses are its vectors
//! (`firmware/vectors/`), so this times exactly the code the QEMU parity
//! test checks.
//!
//! `cargo bench -p tendril-firmware --features harness --bench inference`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use tendril_firmware::control::{control_step, ControlSetpoint, ControlState, StepInput};
use tendril_firmware::vectors::{self, HAS_SETPOINT};
use tendril_firmware::{infer, McuNet, DEFAULT_NET};
use tendril_shared::MAX_HIDDEN;
use tendril_shared::MAX_TENDONS;

static NET: &[u8] = include_bytes!("../vectors/default.tnet");
static VECTORS: &[u8] = include_bytes!("../vectors/inputs.bin");

fn poses() -> Vec<[f32; 7]> {
    let (_, recs) = vectors::parse(VECTORS).expect("embedded vectors parse");
    recs.filter(|r| r.flags & HAS_SETPOINT != 0 && r.pose.iter().all(|v| v.is_finite()))
        .map(|r| r.pose)
        .take(32)
        .collect()
}

fn bench(c: &mut Criterion) {
    let net = &DEFAULT_NET;
    let poses = poses();
    let s = net.shape();
    let name = format!(
        "infer {}-{}-{} ({} MACs, cap {MAX_HIDDEN})",
        s.inputs,
        s.hidden,
        s.outputs,
        s.macs()
    );
    let mut i = 0;
    c.bench_function(&name, |b| {
        b.iter(|| {
            i = (i + 1) % poses.len();
            black_box(infer(net, black_box(&poses[i])))
        })
    });

    let (header, _) = vectors::parse(VECTORS).expect("embedded vectors parse");
    let cfg = header.config().expect("vector limits");
    let state = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let mut seq = 0;
    c.bench_function("control_step (inference + limits)", |b| {
        b.iter(|| {
            seq += 1;
            let input = StepInput {
                now_ns: 1_000_000,
                setpoint: Some(ControlSetpoint {
                    seq,
                    pose: poses[seq as usize % poses.len()],
                    tangent: None,
                }),
                feedback: None,
            };
            black_box(control_step(&cfg, net, black_box(&state), &input))
        })
    });

    let name = format!("decode .tnet {} bytes (validate + CRC + write)", NET.len());
    c.bench_function(&name, |b| {
        let mut spare = Box::new(McuNet::empty());
        b.iter(|| spare.decode_into(black_box(NET)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
