//! The OS floor under any event-driven IPC on this machine: how long a
//! process blocked in `read` on a pipe takes to wake after a timestamp is
//! written (one per millisecond, like the controller's commands).
//! `cargo run --release -p tendril --example wake_floor [-- --realtime]`.
//! Compare with the iceoryx2 event latency in BENCHMARKS.md.

use std::io::{Read, Write};
use std::process::{Command, Stdio};

use tendril::ipc::clock::{now_ns, try_realtime};

const SAMPLES: usize = 3000;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let realtime = args.iter().any(|a| a == "--realtime");
    if args.iter().any(|a| a == "--child") {
        if realtime && !try_realtime(45) {
            eprintln!("SCHED_FIFO refused");
        }
        let mut input = std::io::stdin().lock();
        let mut lat = Vec::with_capacity(SAMPLES);
        let mut buf = [0u8; 8];
        while input.read_exact(&mut buf).is_ok() {
            lat.push(now_ns().saturating_sub(u64::from_le_bytes(buf)));
        }
        lat.sort_unstable();
        let q = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize] as f64 * 1e-3;
        println!(
            "pipe wake-up ({}): p50 {:.1} µs, p99 {:.1} µs, over {} samples",
            if realtime {
                "SCHED_FIFO"
            } else {
                "normal priority"
            },
            q(0.5),
            q(0.99),
            lat.len()
        );
        return;
    }
    let exe = std::env::current_exe().expect("own path");
    let mut child = Command::new(exe)
        .arg("--child")
        .args(realtime.then_some("--realtime"))
        .stdin(Stdio::piped())
        .spawn()
        .expect("spawn child");
    let mut pipe = child.stdin.take().expect("child stdin");
    for _ in 0..SAMPLES {
        std::thread::sleep(std::time::Duration::from_millis(1));
        pipe.write_all(&now_ns().to_le_bytes()).expect("write");
    }
    drop(pipe);
    child.wait().expect("child exit");
}
