//! Cross-process figures for BENCHMARKS.md ("IPC and closed loop"):
//!
//! 1. setpoint → tension-command latency across processes over iceoryx2:
//!    this process publishes a setpoint (stamped with CLOCK_MONOTONIC) once
//!    per millisecond; a child process receives it, runs the firmware control
//!    step and publishes the tension command; this process receives it.
//!    Reported: one-way setpoint hop (stamp → child receive), and the chain
//!    setpoint stamp → command received (two hops + the control step).
//!    With event-driven wake-ups (default, no busy wait), event-driven with
//!    both processes on one CPU and the receiver at the higher real-time
//!    priority (what `tendril sim` does), and spinning.
//! 2. controller lateness and overruns over a long `tendril sim` run at 1 kHz.
//!
//! `cargo bench -p tendril --bench ipc -- [--samples N] [--lateness-secs S] [--skip-sim]`
//! (no criterion: percentiles of cross-process latencies, not mean times).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use tendril::ipc::clock::{
    allowed_cpus, now_ns, pin_to_cpu, set_allowed_cpus, sleep_until, tighten_timer_slack,
    try_realtime,
};
use tendril::ipc::controller::Slots;
use tendril::ipc::stats::Summary;
use tendril::ipc::transport::{self, Services, Svc};
use tendril::plan::stand_in::quick_net;
use tendril::robot::{repo_robot, Robot};
use tendril::statics::{SolverSettings, Statics};
use tendril_firmware::control::{
    control_step, ControlConfig, ControlSetpoint, ControlState, StepInput,
};
use tendril_shared::messages::{setpoint_flags, Header, Setpoint, TensionCommand, MAX_TENDONS};
use tendril_shared::TendonLimits;

const CHILD_ENV: &str = "TENDRIL_IPC_BENCH_CHILD";

fn robot() -> Robot {
    repo_robot("seed-4t.toml")
}

fn sp_event(
    node: &Node<Svc>,
    prefix: &str,
) -> iceoryx2::service::port_factory::event::PortFactory<Svc> {
    let name = ServiceName::new(&format!("{prefix}/bench_setpoint")).unwrap();
    node.service_builder(&name)
        .event()
        .open_or_create()
        .unwrap()
}

/// Wait for the next message: on the event (sleeping) or by polling.
fn wait_for<T: transport::Message>(
    spin: bool,
    listener: &Listener<Svc>,
    sub: &transport::Sub<T>,
) -> Option<T> {
    let deadline = now_ns() + 2_000_000_000;
    loop {
        if let Ok(Some(s)) = sub.receive() {
            return Some(s.payload().0);
        }
        if now_ns() > deadline {
            return None;
        }
        if !spin {
            let _ = listener.timed_wait(|_| {}, Duration::from_millis(100));
        }
    }
}

/// How the child waits, and where the two processes run.
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// Sleep on the event; both at SCHED_FIFO 50, unpinned.
    Event,
    /// Sleep on the event; both on one CPU, the child at 55 (above the parent).
    Pinned,
    /// Busy-poll; both at 50, unpinned.
    Spin,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Event => "event",
            Mode::Pinned => "event, one CPU, receiver above sender",
            Mode::Spin => "spin",
        }
    }
}

/// The CPU the pinned mode uses.
fn bench_cpu() -> usize {
    allowed_cpus().last().copied().unwrap_or(0)
}

/// The child: a controller that reacts to each setpoint immediately.
fn child(prefix: &str, mode: Mode) {
    let spin = mode == Mode::Spin;
    let r = robot();
    let statics = Statics::new(&r, SolverSettings::default());
    let mut slots: Box<Slots> = Box::default();
    slots
        .load(&quick_net(&statics, 800, 32, 6.0, 1).unwrap(), (7, 4))
        .unwrap();
    let limits = TendonLimits::uniform(4, 10.0, 200.0).unwrap();
    let cfg = ControlConfig::new(limits);
    let mut state = ControlState::new(&limits, &[0.0; MAX_TENDONS], now_ns());

    let node = transport::node("tendril-bench-child").unwrap();
    let services = Services::open_or_create(&node, prefix).unwrap();
    let sub = transport::subscriber(&services.setpoint).unwrap();
    let cmd_pub = transport::publisher(&services.tension_cmd).unwrap();
    let notifier = transport::notifier(&services.tension_cmd_event).unwrap();
    let ev = sp_event(&node, prefix);
    let listener = ev.listener_builder().create().unwrap();
    tighten_timer_slack();
    if mode == Mode::Pinned {
        pin_to_cpu(bench_cpu());
        try_realtime(55);
    } else {
        try_realtime(50);
    }
    while let Some(sp) = wait_for(spin, &listener, &sub) {
        let t_recv = now_ns();
        let input = StepInput {
            now_ns: t_recv,
            setpoint: Some(ControlSetpoint {
                seq: sp.header.seq,
                pose: sp.pose,
                tangent: None,
            }),
            feedback: None,
        };
        let (next, out) = control_step(&cfg, slots.active(), &state, &input);
        state = next;
        let cmd = TensionCommand {
            header: Header {
                seq: sp.header.seq,
                stamp_ns: t_recv,
            },
            setpoint_seq: sp.header.seq,
            tensions: out.command,
            pad: Default::default(),
            count: 4,
            status: out.status.bits(),
        };
        transport::send(&cmd_pub, cmd).unwrap();
        notifier.notify().unwrap();
        if sp.flags & setpoint_flags::FINAL != 0 {
            break;
        }
    }
}

/// Run one latency measurement with a child in `mode`.
fn latency(samples: usize, mode: Mode) -> (Summary, Summary) {
    let spin = mode == Mode::Spin;
    let prefix = format!(
        "tendril-bench-{}-{}",
        std::process::id(),
        now_ns() % 1_000_000_000
    );
    let node = transport::node("tendril-bench").unwrap();
    let services = Services::open_or_create(&node, &prefix).unwrap();
    let ev = sp_event(&node, &prefix);
    let sp_pub = transport::publisher(&services.setpoint).unwrap();
    let sp_notify = ev.notifier_builder().create().unwrap();
    let cmd_sub = transport::subscriber(&services.tension_cmd).unwrap();
    let listener = transport::listener(&services.tension_cmd_event).unwrap();
    let mut kid = Command::new(std::env::current_exe().unwrap())
        .env(CHILD_ENV, format!("{prefix},{}", mode as u8))
        .spawn()
        .unwrap();
    tighten_timer_slack();
    if mode == Mode::Pinned {
        pin_to_cpu(bench_cpu());
    }
    try_realtime(50);

    // A reachable pose in the quick net's box (tip 15 mm off axis).
    let statics = Statics::new(&robot(), SolverSettings::default());
    let pose = tendril::plan::Lifter::new(&statics)
        .unwrap()
        .lift([0.015, 0.0])
        .unwrap();
    let pose = pose.map(|v| v as f32);
    let send = |seq: u64, flags: u32| {
        let stamp = now_ns();
        transport::send(
            &sp_pub,
            Setpoint {
                header: Header {
                    seq,
                    stamp_ns: stamp,
                },
                pose,
                velocity: [0.0; 7],
                tangent: [[0.0; 7]; 3],
                tangent_axes: [[0.0; 3]; 3],
                tangent_dim: 0,
                flags,
                dynamic_offset: [0.0; 3],
                reserved: 0,
            },
        )
        .unwrap();
        sp_notify.notify().unwrap();
        stamp
    };
    // Wait for the child to connect and answer.
    let mut seq = 0;
    loop {
        seq += 1;
        send(seq, 0);
        std::thread::sleep(Duration::from_millis(20));
        if let Ok(Some(_)) = cmd_sub.receive() {
            while let Ok(Some(_)) = cmd_sub.receive() {}
            break;
        }
    }
    let mut hop = Vec::with_capacity(samples);
    let mut chain = Vec::with_capacity(samples);
    let start = now_ns() + 1_000_000;
    for i in 0..samples {
        sleep_until(start + i as u64 * 1_000_000, 30_000);
        seq += 1;
        let t0 = send(
            seq,
            if i + 1 == samples {
                setpoint_flags::FINAL
            } else {
                0
            },
        );
        loop {
            let Some(cmd) = wait_for(spin, &listener, &cmd_sub) else {
                panic!("no tension command for setpoint {seq}");
            };
            if cmd.setpoint_seq == seq {
                let t1 = now_ns();
                hop.push(cmd.header.stamp_ns - t0);
                chain.push(t1 - t0);
                break;
            }
        }
    }
    let _ = kid.wait();
    (Summary::of_ns(&mut hop), Summary::of_ns(&mut chain))
}

fn sim_lateness(secs: f64, realtime: bool) -> serde_json::Value {
    let out: PathBuf =
        std::env::temp_dir().join(format!("tendril-ipc-bench-{}", std::process::id()));
    let status = Command::new(env!("CARGO_BIN_EXE_tendril"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
        .args([
            "sim",
            "--quick-model",
            "--trajectory",
            "circle",
            "--settle",
            "1",
        ])
        .arg(format!("--duration={secs}"))
        .arg(format!(
            "--realtime={}",
            if realtime { "on" } else { "off" }
        ))
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    r
}

fn main() {
    if let Ok(spec) = std::env::var(CHILD_ENV) {
        let (prefix, mode) = spec.split_once(',').unwrap();
        let mode = match mode {
            "1" => Mode::Pinned,
            "2" => Mode::Spin,
            _ => Mode::Event,
        };
        child(prefix, mode);
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    let opt = |name: &str, default: f64| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let samples = opt("--samples", 10_000.0) as usize;
    let secs = opt("--lateness-secs", 60.0);
    println!(
        "| mode | hop p50 | hop p99 | hop p99.9 | chain p50 | chain p99 | chain p99.9 | samples |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let cpus = allowed_cpus();
    for mode in [Mode::Event, Mode::Pinned, Mode::Spin] {
        let (hop, chain) = latency(samples, mode);
        // Undo the pinned mode's affinity: a spinning FIFO child on our one
        // CPU would starve us.
        set_allowed_cpus(&cpus);
        println!(
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
            mode.name(),
            hop.p50,
            hop.p99,
            hop.p999,
            chain.p50,
            chain.p99,
            chain.p999,
            hop.count
        );
    }
    if args.iter().any(|a| a == "--skip-sim") {
        return;
    }
    println!();
    println!("| sim {secs} s @ 1 kHz | cycles | overruns | overrun fraction | skipped | lateness p50 (µs) | p99 | p99.9 | max | cmd latency p50 (µs) | p99 | plant step p50 (µs) | RMS (mm) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for rt in [true, false] {
        let r = sim_lateness(secs, rt);
        let c = &r["controller"];
        println!(
            "| SCHED_FIFO {} | {} | {} | {:.5} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.3} |",
            if rt { "on" } else { "off" },
            c["cycles"],
            c["overruns"],
            c["overrun_fraction"].as_f64().unwrap_or(0.0),
            c["skipped"],
            c["lateness_us"]["p50"].as_f64().unwrap_or(0.0),
            c["lateness_us"]["p99"].as_f64().unwrap_or(0.0),
            c["lateness_us"]["p999"].as_f64().unwrap_or(0.0),
            c["lateness_us"]["max"].as_f64().unwrap_or(0.0),
            r["ipc_latency_us"]["p50"].as_f64().unwrap_or(0.0),
            r["ipc_latency_us"]["p99"].as_f64().unwrap_or(0.0),
            r["plant"]["step_us"]["p50"].as_f64().unwrap_or(0.0),
            r["rms_tracking_error_mm"].as_f64().unwrap_or(f64::NAN),
        );
    }
}
