//! Parity of the control period (docs/design.md §5.7): a closed-loop
//! input trace of 2400 periods on the default robot and net, covering
//! every rule of the period, replayed in lock-step through the host build
//! of the node and through the chip image under QEMU `netduinoplus2`,
//! gives the same commands bit for bit (seq, setpoint seq, status, events,
//! tension bits). The comparison is shown to fail when one input is
//! perturbed on one side.
//!
//! Needs `qemu-system-arm` and the Rust target `thumbv7em-none-eabihf`;
//! without them the test FAILS with the line saying what to install.

use std::time::{Duration, Instant};

use tendril::ipc::controller::ControllerConfig;
use tendril::mcu::bridge::setup_for;
use tendril::mcu::trace::{first_difference, replay_chip, replay_host, synthetic, Delivery, Trace};
use tendril::mcu::{locate_image, Chip, McuLink};
use tendril::robot::Robot;
use tendril_firmware::period::event;
use tendril_shared::link::wire::{LinkCommand, Setup};

const PERIODS: usize = 2400;

fn setup() -> (Setup, Vec<u8>) {
    let root = tendril_tests::workspace_root();
    let robot_path = root.join("robots/seed-4t.toml");
    let net_path = root.join("firmware/vectors/default.tnet");
    let robot = Robot::load(&robot_path).unwrap();
    let mut cfg = ControllerConfig::new(robot_path, net_path.clone());
    // The chip-in-the-loop rate, and the integral loop on so the tangent
    // and the feedback's tip count.
    cfg.rate_hz = 100.0;
    cfg.ki_per_s = 5.0;
    let setup = setup_for(&cfg, &robot).unwrap();
    (setup, std::fs::read(net_path).unwrap())
}

fn union(cmds: &[LinkCommand]) -> u32 {
    cmds.iter().fold(0, |a, c| a | c.events)
}

#[test]
fn a_trace_replays_bit_for_bit_on_the_host_build_and_the_chip() {
    let (setup, tnet) = setup();
    let trace = synthetic(&setup, &tnet, PERIODS, 7).unwrap();
    assert_eq!(trace.periods.len(), PERIODS);
    // The file round-trips exactly.
    let back = Trace::from_bytes(&trace.to_bytes().unwrap()).unwrap();
    assert_eq!(back, trace);

    let t = Instant::now();
    let host = replay_host(&trace).unwrap();
    let host_time = t.elapsed();
    assert_eq!(host.len(), PERIODS + 1);
    // The trace covers every rule.
    let ev = union(&host);
    for (name, bit) in [
        ("nonfinite setpoint", event::NONFINITE_SETPOINT),
        ("outside", event::OUTSIDE_WORKSPACE),
        ("bad quaternion", event::BAD_QUATERNION),
        ("watchdog hold", event::WATCHDOG_HOLD),
        ("tracking resumed", event::TRACKING_RESUMED),
        ("plant stale", event::PLANT_STALE),
        ("plant recovered", event::PLANT_RECOVERED),
        ("setpoints lost", event::SETPOINTS_LOST),
        ("planner restart", event::PLANNER_RESTART),
        ("plant states lost", event::PLANT_STATES_LOST),
        ("weights rejected", event::WEIGHTS_REJECTED),
        ("weights swapped", event::WEIGHTS_SWAPPED),
        ("stuck motor", event::STUCK_MOTOR),
    ] {
        assert_ne!(ev & bit, 0, "the trace never raises {name}");
    }
    let rejections = host
        .iter()
        .filter(|c| c.events & event::WEIGHTS_REJECTED != 0)
        .count();
    assert!(
        rejections >= 2,
        "the corrupted update and the out-of-order chunk"
    );
    // Mostly tracking: the circle lies inside the net's box.
    let held = host.iter().filter(|c| c.status & 1 != 0).count();
    assert!(held < PERIODS / 4, "{held} of {PERIODS} periods held");

    // The chip.
    let image = locate_image().unwrap_or_else(|e| panic!("{e:#}"));
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("chip.sock");
    let mut chip = Chip::start(&image, &socket).unwrap();
    let link = McuLink::connect(&socket, Duration::from_secs(5)).unwrap();
    chip.wait_ready(Duration::from_secs(5)).unwrap();
    let t = Instant::now();
    let on_chip = match replay_chip(&trace, link, Duration::from_secs(5)) {
        Ok(c) => c,
        Err(e) => panic!("{e:#}; chip log: {}", chip.log()),
    };
    let chip_time = t.elapsed();
    println!(
        "{} periods: host build {host_time:?}, chip under QEMU {chip_time:?}",
        PERIODS + 1
    );
    if let Some(d) = first_difference(&host, &on_chip) {
        panic!(
            "host and chip differ first at period {}:\n host {:?}\n chip {:?}",
            d.period, d.a, d.b
        );
    }

    // It can fail: one feedback's tip 1 µm off on the host side (the
    // integral loop reads it).
    let mut perturbed = trace.clone();
    let at = PERIODS / 2;
    let k = (at..PERIODS)
        .find(|&k| {
            perturbed.periods[k]
                .deliveries
                .iter()
                .any(|d| matches!(d, Delivery::Feedback(_)))
        })
        .unwrap();
    for d in &mut perturbed.periods[k].deliveries {
        if let Delivery::Feedback(f) = d {
            f.tip[0] += 1;
        }
    }
    let host2 = replay_host(&perturbed).unwrap();
    let d = first_difference(&host2, &on_chip).expect("a perturbed input must show");
    // Command 0 is the first Step's, so trace period k is command k + 1.
    assert!(
        d.period > k,
        "differs at {} before the perturbation at {k}",
        d.period
    );
    println!(
        "perturbed feedback in period {k}: first difference at command {}",
        d.period
    );
}
