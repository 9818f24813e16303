//! Run many inferences of the built-in net ([`tendril_firmware::DEFAULT_NET`],
//! generated from `firmware/vectors/default.tnet`) for load-independent cost
//! measurements of the host build: instruction counts with callgrind and user
//! CPU time (criterion's wall times are inflated on a loaded machine).
//!
//! ```text
//! cargo build -p tendril-firmware --features harness --release --example infer_cost
//! valgrind --tool=callgrind target/release/examples/infer_cost 20000   # instructions
//! /usr/bin/time -f %U target/release/examples/infer_cost 1000000      # user seconds
//! ```
//! The argument is the number of inferences (default 1,000,000); the poses
//! are the embedded vectors' finite setpoints, cycled.

use std::hint::black_box;
use std::process::ExitCode;

use tendril_firmware::vectors::{self, HAS_SETPOINT};
use tendril_firmware::{infer, DEFAULT_NET};

static VECTORS: &[u8] = include_bytes!("../vectors/inputs.bin");

fn main() -> ExitCode {
    let n: usize = match std::env::args().nth(1).map(|a| a.parse()) {
        None => 1_000_000,
        Some(Ok(n)) => n,
        Some(Err(e)) => {
            eprintln!("infer_cost: bad inference count: {e}");
            return ExitCode::FAILURE;
        }
    };
    let net = &DEFAULT_NET;
    let poses: Vec<[f32; 7]> = match vectors::parse(VECTORS) {
        Ok((_, recs)) => recs
            .filter(|r| r.flags & HAS_SETPOINT != 0 && r.pose.iter().all(|v| v.is_finite()))
            .map(|r| r.pose)
            .collect(),
        Err(e) => {
            eprintln!("infer_cost: embedded vectors do not parse: {e:?}");
            return ExitCode::FAILURE;
        }
    };
    if poses.is_empty() {
        eprintln!("infer_cost: no finite setpoints in the embedded vectors");
        return ExitCode::FAILURE;
    }
    let mut acc = 0.0f32;
    for i in 0..n {
        let y = infer(net, black_box(&poses[i % poses.len()]));
        acc += y[0];
    }
    println!("{n} inferences, checksum {acc}");
    ExitCode::SUCCESS
}
