//! The 1 kHz controller's period does not allocate (`docs/design.md` §6):
//! 200 000 periods (200 s of loop, past the ≈131 s after which the old
//! 2¹⁷-sample buffers reallocated) of [`Controller::period`],
//! [`Controller::finish`] and the CSV log row, under a counting global
//! allocator, with the paths a run takes: tracking with the firmware's
//! integral correction, NaN setpoints, lost setpoints, a plant silent for
//! 30 periods, a weight hot swap and a rejected update, and a stuck motor.
//! The simulated clock runs at full speed; the inputs are prepared outside
//! the counted region.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use tendril::ipc::clock::{Tick, Ticker};
use tendril::ipc::controller::{log_header, Controller, ControllerConfig, FaultKind, Inbox};
use tendril::ipc::stats::CsvLog;
use tendril::plan::{PathShape, Trajectory};
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};
use tendril_shared::messages::{setpoint_flags, Header, PlantState, Setpoint, WeightUpdate};

/// Counts allocations made by the current thread while `COUNTING` is set.
struct CountingAlloc;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn note_allocation() {
    // `try_with`: the thread-locals may be gone while a thread shuts down.
    let counting = COUNTING.try_with(Cell::get).unwrap_or(false);
    if counting {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Run `f` and return how many allocations it made on this thread.
fn allocations_in<T>(f: impl FnOnce() -> T) -> (T, u64) {
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|c| c.set(true));
    let out = f();
    COUNTING.with(|c| c.set(false));
    (out, ALLOCATIONS.with(Cell::get))
}

#[test]
fn counting_allocator_sees_an_allocation() {
    // The instrument works: a Vec that allocates is counted.
    let (v, n) = allocations_in(|| vec![1u8; 64]);
    assert_eq!(v.len(), 64);
    assert!(n >= 1, "counted {n}");
}

#[test]
fn two_hundred_seconds_of_controller_periods_allocate_nothing() {
    let robot_path = tendril_tests::robot("seed-4t.toml");
    let model_path = tendril_tests::workspace_root().join("firmware/vectors/default.tnet");
    let robot = repo_robot("seed-4t.toml");
    let model = std::fs::read(&model_path).unwrap();
    let mut cfg = ControllerConfig::new(robot_path, model_path);
    cfg.ki_per_s = 10.0;
    let statics = Statics::new(&robot, SolverSettings::default());
    let shape = PathShape::default_circle();
    let traj = Trajectory::new(&shape, &statics).unwrap();
    let valid = WeightUpdate::from_bytes(
        Header {
            seq: 1,
            stamp_ns: 0,
        },
        &model,
    )
    .unwrap();
    let mut corrupt = WeightUpdate::from_bytes(
        Header {
            seq: 2,
            stamp_ns: 0,
        },
        &model,
    )
    .unwrap();
    let mid = corrupt.len as usize / 2;
    corrupt.bytes[mid] ^= 0x10;

    let dir = tempfile::tempdir().unwrap();
    let mut log = CsvLog::create(Some(&dir.path().join("c.csv")), &log_header(4)).unwrap();

    let period = 1_000_000u64;
    let start = 1_000_000_000u64;
    let mut ctl = Controller::new(&cfg, &robot, &model, start).unwrap();
    let mut ticker = Ticker::new(start, period);
    let periods = 200_000u64;
    let stuck_from = 190_000u64;
    let (mut sp_seq, mut st_seq) = (0u64, 0u64);
    let mut motor = [0.0f32; tendril_shared::MAX_TENDONS];
    let mut stuck_value = None;
    let mut total = 0u64;
    let mut last_cmd_seq = 0u64;
    for k in 0..periods {
        // Inputs, prepared outside the counted region.
        let now = start + k * period;
        ticker.plan(now);
        let tick = Tick {
            index: k,
            deadline_ns: now,
            lateness_ns: 20_000 + (k % 7) * 1_000,
            skipped: 0,
        };
        let t = k as f64 * 1e-3;
        let point = traj.sample(t);
        sp_seq += if k % 9_973 == 0 { 3 } else { 1 }; // now and then two lost
        let mut pose = point.pose.map(|v| v as f32);
        if k % 10_007 == 5_000 {
            pose[0] = f32::NAN;
        }
        let setpoint = Setpoint {
            header: Header {
                seq: sp_seq,
                stamp_ns: now - 200_000,
            },
            pose,
            velocity: point.velocity.map(|v| v as f32),
            tangent: point
                .tangent
                .map_or([[0.0; 7]; 3], |d| d.columns.map(|r| r.map(|v| v as f32))),
            tangent_axes: point.tangent.map_or([[0.0; 3]; 3], |d| {
                d.family.axes_padded().map(|a| a.map(|v| v as f32))
            }),
            tangent_dim: point.tangent.map_or(0, |d| d.family.dim() as u32),
            flags: setpoint_flags::HAS_VELOCITY
                | setpoint_flags::HAS_TANGENT
                | setpoint_flags::HAS_DYNAMIC_OFFSET,
            // The modal inverse's size on the circle: tens of µm.
            dynamic_offset: [
                (point.velocity[0] * 0.005) as f32,
                (point.velocity[1] * 0.005) as f32,
                0.0,
            ],
            reserved: 0,
        };
        // A plant: healthy 20 ms motors, the tip 0.3 mm off the setpoint
        // (the IK error the integral removes), silent for 30 periods now and then.
        let silent = k % 50_000 >= 20_000 && k % 50_000 < 20_030;
        let state = (!silent).then(|| {
            st_seq += 1;
            let mut tip = [0.0f32; 7];
            tip.copy_from_slice(&pose);
            tip[0] = point.pose[0] as f32 + 3e-4;
            let mut tensions = motor;
            if k >= stuck_from {
                // Tendon 2 carries 1–3 N on this circle.
                tensions[2] = *stuck_value.get_or_insert(motor[2]);
            }
            PlantState {
                header: Header {
                    seq: st_seq,
                    stamp_ns: now - 300_000,
                },
                command_seq: last_cmd_seq,
                tensions,
                pad: Default::default(),
                tip_pose: tip,
                count: 4,
                // A tracker frame with every state, 0.3 ms old.
                tip_seq: st_seq as u32,
                tip_stamp_ns: now - 300_000,
                ..PlantState::default()
            }
        });
        let weights = match k {
            100_000 => Some(&valid),
            150_000 => Some(&corrupt),
            _ => None,
        };
        let inbox = Inbox {
            setpoint: Some(setpoint),
            setpoints: 1,
            superseded_nonfinite: 0,
            state,
            states: usize::from(state.is_some()),
            weights,
        };

        let (cmd, n) = allocations_in(|| {
            let cmd = ctl.period(&tick, now + 20_000, false, &inbox);
            let row = ctl.finish(15_000 + k % 5_000);
            log.row(row).unwrap();
            cmd
        });
        total += n;
        assert_eq!(n, 0, "period {k} allocated {n} times");

        last_cmd_seq = cmd.header.seq;
        for (m, &c) in motor.iter_mut().zip(&cmd.tensions) {
            *m += (c - *m) * (1.0 - (-0.05f32).exp());
        }
    }
    assert_eq!(total, 0);
    log.flush().unwrap();

    // The paths ran.
    let stats = ctl.stats(&ticker);
    assert_eq!(stats.cycles, periods);
    assert!(
        stats.correction_cycles > periods / 2,
        "{}",
        stats.correction_cycles
    );
    assert_eq!(stats.weight_swaps, 1);
    assert_eq!(stats.weight_rejections, 1);
    assert!(stats.rejected_nonfinite >= 19);
    assert!(stats.setpoints_lost >= 40, "{}", stats.setpoints_lost);
    assert!(stats.plant_recoveries >= 3);
    assert_eq!(stats.lateness_us.count as u64, periods);
    let kinds: Vec<FaultKind> = stats.faults_detected.iter().map(|f| f.kind).collect();
    for kind in [
        FaultKind::NonfiniteSetpoint,
        FaultKind::SetpointsLost,
        FaultKind::PlantStale,
        FaultKind::WeightsRejected,
    ] {
        assert!(kinds.contains(&kind), "{kind:?} not in {kinds:?}");
    }
    // The stuck motor: found after it stuck, nothing stuck before.
    let stuck: Vec<_> = stats
        .faults_detected
        .iter()
        .filter(|f| f.kind == FaultKind::StuckMotor)
        .collect();
    assert_eq!(stuck.len(), 1, "{stuck:?}");
    let at = (stuck[0].t_ns - start) as f64 * 1e-9;
    assert!(
        (190.0..195.0).contains(&at),
        "stuck motor found at {at} s (stuck from 190 s)"
    );
    assert_eq!(stuck[0].tendon, Some(2));
}
