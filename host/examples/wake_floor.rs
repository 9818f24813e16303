//! How fast the OS wakes a process blocked in `read` on a pipe when another
//! writes a timestamp to it (one per millisecond, then 20 µs of work, like
//! the controller sending a command and finishing its period): the floor
//! under any event-driven IPC here, and how it depends on real-time
//! priorities and CPU placement.
//!
//! `cargo run --release -p tendril --example wake_floor -- [--child-prio N]
//! [--parent-prio N] [--place free|same|different]` (priorities: SCHED_FIFO,
//! 0 = normal). BENCHMARKS.md, "IPC and closed loop", has the table.

use std::io::{Read, Write};
use std::process::{Command, Stdio};

use tendril::ipc::clock::{allowed_cpus, now_ns, pin_to_cpu, try_realtime};

const SAMPLES: usize = 3000;

fn opt(args: &[String], name: &str) -> Option<String> {
    let i = args.iter().position(|a| a == name)?;
    args.get(i + 1).cloned()
}

/// Pin (if `cpu`) and raise to SCHED_FIFO `prio` (if > 0).
fn schedule(cpu: Option<usize>, prio: i32) {
    if let Some(c) = cpu {
        if !pin_to_cpu(c) {
            eprintln!("cannot pin to CPU {c}");
        }
    }
    if prio > 0 && !try_realtime(prio) {
        eprintln!("SCHED_FIFO {prio} refused");
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let prio = |name| opt(&args, name).and_then(|v| v.parse().ok()).unwrap_or(0);
    let (child_prio, parent_prio) = (prio("--child-prio"), prio("--parent-prio"));
    let place = opt(&args, "--place").unwrap_or_else(|| "free".into());
    let cpus = allowed_cpus();
    let (first, last) = (cpus.first().copied(), cpus.last().copied());
    let (parent_cpu, child_cpu) = match place.as_str() {
        "same" => (last, last),
        "different" => (first, last),
        _ => (None, None),
    };
    if let Some(c) = opt(&args, "--child-cpu") {
        schedule(c.parse().ok(), child_prio);
        let mut input = std::io::stdin().lock();
        let mut lat = Vec::with_capacity(SAMPLES);
        let mut buf = [0u8; 8];
        while input.read_exact(&mut buf).is_ok() {
            lat.push(now_ns().saturating_sub(u64::from_le_bytes(buf)));
        }
        lat.sort_unstable();
        let q = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize] as f64 * 1e-3;
        println!(
            "child FIFO {child_prio}, parent FIFO {parent_prio}, placement {place}: \
             wake-up p50 {:.1} µs, p99 {:.1} µs ({} samples)",
            q(0.5),
            q(0.99),
            lat.len()
        );
        return;
    }
    let exe = std::env::current_exe().expect("own path");
    let mut child = Command::new(exe)
        .args(&args[1..])
        .arg("--child-cpu")
        .arg(child_cpu.map_or("none".into(), |c| c.to_string()))
        .stdin(Stdio::piped())
        .spawn()
        .expect("spawn child");
    let mut pipe = child.stdin.take().expect("child stdin");
    std::thread::sleep(std::time::Duration::from_millis(100));
    schedule(parent_cpu, parent_prio);
    for _ in 0..SAMPLES {
        std::thread::sleep(std::time::Duration::from_millis(1));
        pipe.write_all(&now_ns().to_le_bytes()).expect("write");
        // The rest of the sender's period: 20 µs of work.
        let until = now_ns() + 20_000;
        while now_ns() < until {
            std::hint::spin_loop();
        }
    }
    drop(pipe);
    child.wait().expect("child exit");
}
