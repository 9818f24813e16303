//! The controller process: the firmware's `no_std` control step (the very
//! function the MCU runs) inside an absolute-deadline loop at 1 kHz.
//!
//! Each period: sleep until `t0 + k·T`, take the newest setpoint, plant state
//! and weight update, run [`tendril_firmware::control::control_step`],
//! publish the tension command and raise the plant's event. The host wrapper
//! adds only what the MCU gets from its hardware: the clock, the transport,
//! and *motor-lag lead*: the plant's motors trail their command by a time
//! constant, so the setpoint handed to the step is the planner's pose
//! advanced by `velocity · lead`; the measured tip given to the integral
//! loop is advanced by the same amount, so the loop still integrates
//! `p_desired(t) − p_measured(t)` and does not fight the lead.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use tendril_firmware::control::{
    control_step, ControlConfig, ControlState, Feedback, IntegralConfig, SafeHold,
    Setpoint as FwSetpoint, Status, StepInput, POSE_DIM,
};
use tendril_firmware::swap::NetSlots;
use tendril_shared::messages::{
    command_status, setpoint_flags, Header, PlantState, Setpoint, TensionCommand, WeightUpdate,
    MAX_TENDONS,
};
use tendril_shared::TendonLimits;

use super::clock::{now_ns, tighten_timer_slack, Ticker};
use super::stats::{CsvLog, Summary};
use super::transport::{self, Services};
use super::{IpcError, StopWatch};
use crate::robot::Robot;

/// Hidden-unit capacity of the controller's net buffers.
pub const NET_CAPACITY: usize = 64;

/// The double-buffered net the controller runs.
pub type Slots = NetSlots<
    POSE_DIM,
    NET_CAPACITY,
    MAX_TENDONS,
    { tendril_shared::weight_capacity(POSE_DIM, NET_CAPACITY, MAX_TENDONS) },
>;

/// Everything the controller process needs.
#[derive(Clone, Debug)]
pub struct ControllerConfig {
    /// Robot file (tension limits, tendon count).
    pub robot: PathBuf,
    /// The `.tnet` to start with.
    pub model: PathBuf,
    /// Service-name prefix.
    pub prefix: String,
    /// Loop rate (Hz).
    pub rate: f64,
    /// Spin this long before each deadline instead of sleeping (µs).
    pub spin_us: f64,
    /// Try `SCHED_FIFO`.
    pub realtime: bool,
    /// Pin to this CPU (see [`super::clock::PLANT_PRIORITY`] for why `sim`
    /// puts controller and plant on one CPU).
    pub cpu: Option<usize>,
    /// Setpoint silence (in periods) that trips the watchdog.
    pub watchdog_periods: f64,
    /// Integral gain of the outer loop (1/s); 0 = IK alone.
    pub ki: f64,
    /// Where the integral correction runs: `true` = the firmware's loop
    /// (along the setpoint's tangent if it has one, else position only),
    /// `false` = host side ([`super::correction`]) with the firmware loop off.
    pub firmware_integral: bool,
    /// Bound on the integral correction per axis (m).
    pub correction_limit: f64,
    /// The host-side correction integrates only while the lateral tip error
    /// is at most this (m): see [`super::correction::LateralIntegral`].
    pub correction_window: f64,
    /// Motor-lag lead (s): advance the setpoint by velocity · lead.
    pub lead: f64,
    /// Slew-rate limit (N/s) per tendon.
    pub slew_rate: f64,
    /// Fraction of the net's input box a setpoint may lie outside.
    pub box_margin: f64,
    /// Stop after this many seconds (None: until told).
    pub duration: Option<f64>,
    /// Per-period CSV log.
    pub log: Option<PathBuf>,
    /// Statistics JSON written at exit.
    pub stats: Option<PathBuf>,
}

impl ControllerConfig {
    /// Defaults for `robot` and `model`: 1 kHz, watchdog 2.5 periods, IK
    /// alone (no correction), 21 ms lead for the default 20 ms motors.
    pub fn new(robot: PathBuf, model: PathBuf) -> ControllerConfig {
        ControllerConfig {
            robot,
            model,
            prefix: super::DEFAULT_PREFIX.into(),
            rate: 1000.0,
            spin_us: 50.0,
            realtime: false,
            cpu: None,
            watchdog_periods: 2.5,
            ki: 0.0,
            firmware_integral: false,
            correction_limit: 0.003,
            correction_window: 0.002,
            lead: 0.021,
            slew_rate: 200.0,
            box_margin: 0.05,
            duration: None,
            log: None,
            stats: None,
        }
    }
}

/// What the controller reports at exit.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct ControllerStats {
    /// Periods run.
    pub cycles: u64,
    /// Periods whose work ran past the next deadline.
    pub overruns: u64,
    /// Periods skipped after an overrun (never run late).
    pub skipped: u64,
    /// `overruns / cycles`.
    pub overrun_fraction: f64,
    /// Wake-up time minus deadline (µs).
    pub lateness_us: Summary,
    /// Work per period: receive, control step, publish (µs).
    pub step_us: Summary,
    /// Age of a setpoint when the controller picked it up (µs).
    pub setpoint_age_us: Summary,
    /// Setpoints received.
    pub setpoints: u64,
    /// Setpoints rejected: NaN/∞.
    pub rejected_nonfinite: u64,
    /// Setpoints rejected: quaternion not unit.
    pub rejected_quaternion: u64,
    /// Setpoints held: outside the net's workspace box.
    pub rejected_workspace: u64,
    /// Entries into safe hold (watchdog).
    pub watchdog_trips: u64,
    /// Periods spent in safe hold.
    pub hold_cycles: u64,
    /// Periods whose command hit a range or slew limit.
    pub saturated_cycles: u64,
    /// Weight updates swapped in.
    pub weight_swaps: u64,
    /// Weight updates rejected (old net kept).
    pub weight_rejections: u64,
    /// Times the setpoint sequence restarted (a new planner).
    pub planner_restarts: u64,
    /// Times the plant-state sequence restarted (a new plant).
    pub plant_restarts: u64,
    /// Periods with no fresh plant state for over 20 periods.
    pub plant_stale_cycles: u64,
    /// Gaps to a stale plant state that were recovered from.
    pub plant_recoveries: u64,
}

/// Column names of the controller log.
pub fn log_header(n: usize) -> String {
    let mut cols = vec![
        "t_ns".to_string(),
        "lateness_ns".into(),
        "work_ns".into(),
        "status".into(),
        "sp_seq".into(),
        "state_seq".into(),
    ];
    cols.extend((0..n).map(|i| format!("cmd{i}")));
    cols.join(",")
}

/// Load a `.tnet` file into the controller's net buffers.
pub fn load_net(slots: &mut Slots, bytes: &[u8], tendons: usize) -> Result<(), IpcError> {
    slots
        .load(bytes, (POSE_DIM, tendons))
        .map_err(|e| IpcError::Other(e.to_string()))
}

/// Run the controller process until stopped.
pub fn run(cfg: &ControllerConfig) -> Result<ControllerStats, IpcError> {
    if !(cfg.rate > 0.0 && cfg.rate <= 20_000.0) {
        return Err(IpcError::Config(format!(
            "controller rate {} Hz: must be in (0, 20000]",
            cfg.rate
        )));
    }
    if !(cfg.ki >= 0.0 && cfg.lead >= 0.0 && cfg.slew_rate > 0.0 && cfg.watchdog_periods > 0.0) {
        return Err(IpcError::Config(
            "controller: ki and lead must be ≥ 0, slew rate and watchdog > 0".into(),
        ));
    }
    let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
    let n = robot.n_tendons();
    let max: Vec<f32> = robot.max_tensions().iter().map(|&v| v as f32).collect();
    let slew = vec![cfg.slew_rate as f32; n];
    let limits = TendonLimits::new(&max, &slew)
        .map_err(|e| IpcError::Config(format!("tension limits: {e:?}")))?;
    let bytes = std::fs::read(&cfg.model).map_err(|source| IpcError::Io {
        path: cfg.model.clone(),
        source,
    })?;
    let mut slots: Box<Slots> = Box::default();
    load_net(&mut slots, &bytes, n)
        .map_err(|e| IpcError::Other(format!("{}: {e}", cfg.model.display())))?;

    let period_ns = (1e9 / cfg.rate).round() as u64;
    let mut fw = ControlConfig::new(limits);
    fw.watchdog_ns = (cfg.watchdog_periods * period_ns as f64) as u64;
    fw.max_dt_ns = 5 * period_ns;
    fw.box_margin = cfg.box_margin as f32;
    fw.safe_hold = SafeHold::Freeze;
    if cfg.ki > 0.0 && cfg.firmware_integral {
        fw.integral = IntegralConfig {
            ki: cfg.ki as f32,
            limit: cfg.correction_limit as f32,
            feedback_timeout_ns: 20 * period_ns,
            window: cfg.correction_window as f32,
        };
    }

    let node = transport::node("tendril-controller")?;
    let services = Services::open_or_create(&node, &cfg.prefix)?;
    let setpoints = transport::subscriber(&services.setpoint)?;
    let states = transport::subscriber(&services.plant_state)?;
    let weights = transport::subscriber(&services.weights)?;
    let commands = transport::publisher(&services.tension_cmd)?;
    let notifier = transport::notifier(&services.tension_cmd_event)?;
    let stop = StopWatch::new(&services)?;
    let mut log = CsvLog::create(cfg.log.as_deref(), &log_header(n))?;

    tighten_timer_slack();
    super::clock::apply_scheduling(
        "controller",
        cfg.cpu,
        cfg.realtime,
        super::clock::CONTROLLER_PRIORITY,
    );

    let start = now_ns() + period_ns;
    let mut state = ControlState::new(&limits, &[0.0; MAX_TENDONS], start);
    let mut ticker = Ticker::new(start, period_ns);
    let spin_ns = (cfg.spin_us * 1e3) as u64;
    let mut stats = ControllerStats::default();
    let mut lateness = Vec::with_capacity(1 << 17);
    let mut work = Vec::with_capacity(1 << 17);
    let mut sp_age = Vec::with_capacity(1 << 17);
    let mut local_sp_seq = 0u64;
    let mut local_fb_seq = 0u64;
    let mut last_sp: Option<Setpoint> = None;
    let mut last_state: Option<PlantState> = None;
    let mut last_state_time = start;
    let mut stale = false;
    let mut in_hold = false;
    let mut cmd_seq = 0u64;
    let mut overran = false;
    let host_correction = cfg.ki > 0.0 && !cfg.firmware_integral;
    let mut integral = super::correction::LateralIntegral::default();
    let gains = super::correction::IntegralGains {
        ki: cfg.ki,
        limit: cfg.correction_limit,
        window: cfg.correction_window,
    };
    let mut last_good_sp: Option<Setpoint> = None;
    let length = robot.length;
    let mut last_flush = start;

    loop {
        let tick = ticker.wait(spin_ns);
        let t_wake = now_ns();
        lateness.push(tick.lateness_ns);
        let mut extra = 0u32;
        if overran || tick.skipped > 0 {
            extra |= command_status::OVERRUN;
        }

        // Newest messages since the last period.
        let (sp, _) = transport::latest(&setpoints)?;
        let (fb, _) = transport::latest(&states)?;
        let (wu, _): (Option<WeightUpdate>, usize) = transport::latest(&weights)?;

        if let Some(w) = wu {
            match w
                .payload()
                .ok_or_else(|| "length field exceeds capacity".to_string())
                .and_then(|b| slots.load(b, (POSE_DIM, n)).map_err(|e| e.to_string()))
            {
                Ok(()) => {
                    stats.weight_swaps += 1;
                    extra |= command_status::WEIGHTS_SWAPPED;
                    log::info!(
                        "controller: new weights swapped in (update #{})",
                        w.header.seq
                    );
                }
                Err(e) => {
                    stats.weight_rejections += 1;
                    extra |= command_status::WEIGHTS_REJECTED;
                    log::warn!(
                        "controller: weight update #{} rejected, old net kept: {e}",
                        w.header.seq
                    );
                }
            }
        }

        let mut fw_sp = None;
        if let Some(s) = sp {
            stats.setpoints += 1;
            sp_age.push(t_wake.saturating_sub(s.header.stamp_ns));
            if last_sp.is_some_and(|p| s.header.seq <= p.header.seq) {
                stats.planner_restarts += 1;
                log::info!(
                    "controller: setpoint sequence restarted at #{}: new planner",
                    s.header.seq
                );
            }
            local_sp_seq += 1;
            let mut pose = s.pose;
            if s.flags & setpoint_flags::HAS_VELOCITY != 0 && cfg.lead > 0.0 {
                for (p, v) in pose.iter_mut().zip(&s.velocity) {
                    *p += v * cfg.lead as f32;
                }
            }
            // The planner's tangent, for the firmware's own integral loop.
            let tangent = (s.flags & setpoint_flags::HAS_TANGENT != 0).then_some(s.tangent);
            fw_sp = Some(FwSetpoint {
                seq: local_sp_seq,
                pose,
                tangent,
            });
            last_sp = Some(s);
        }
        let mut fw_fb = None;
        if let Some(f) = fb {
            if last_state.is_some_and(|p| f.header.seq <= p.header.seq) {
                stats.plant_restarts += 1;
                log::info!("controller: plant-state sequence restarted: new plant");
            }
            if stale {
                stale = false;
                stats.plant_recoveries += 1;
                log::info!("controller: plant state back after a gap");
            }
            local_fb_seq += 1;
            let mut tip = [f.tip_pose[0], f.tip_pose[1], f.tip_pose[2]];
            // Advance the measurement by the same lead as the setpoint.
            if let Some(s) = last_sp.filter(|s| s.flags & setpoint_flags::HAS_VELOCITY != 0) {
                for (p, v) in tip.iter_mut().zip(&s.velocity) {
                    *p += v * cfg.lead as f32;
                }
            }
            fw_fb = Some(Feedback {
                seq: local_fb_seq,
                tip_position: tip,
            });
            last_state = Some(f);
            last_state_time = t_wake;
        } else if !stale && t_wake.saturating_sub(last_state_time) > 20 * period_ns {
            stale = true;
            log::warn!("controller: no plant state for 20 periods");
        }
        if stale {
            stats.plant_stale_cycles += 1;
            extra |= command_status::PLANT_STALE;
        }

        // Host-side correction (see `correction`): move the setpoint handed
        // to the firmware by the integral, along the robot's reachable poses
        // (the planner's tangent), or along a constant-curvature arc when a
        // setpoint comes without one.
        if host_correction {
            if let (Some(sp), Some(s)) = (fw_sp.as_mut(), last_sp) {
                if sp.pose.iter().all(|v| v.is_finite()) {
                    let pose = sp.pose.map(|v| v as f64);
                    let shifted = if s.flags & setpoint_flags::HAS_TANGENT != 0 {
                        let tangent = s.tangent.map(|row| row.map(|v| v as f64));
                        super::correction::family_shift(&pose, &tangent, integral.c)
                    } else {
                        super::correction::arc_shift(&pose, integral.c, length)
                    };
                    sp.pose = shifted.map(|v| v as f32);
                }
            }
        }

        let input = StepInput {
            now_ns: tick.deadline_ns,
            setpoint: fw_sp,
            feedback: fw_fb,
        };
        let (next, out) = control_step(&fw, slots.active(), &state, &input);
        state = next;
        let status = out.status;
        if status.contains(Status::NEW_SETPOINT) {
            last_good_sp = last_sp;
        }
        // Integrate only while tracking an accepted setpoint with fresh
        // feedback; a rejected or injected setpoint never reaches the integral.
        // Nor while the slew limit holds the command back: the motors are
        // still on their way, and integrating that lag is wind-up.
        let tracking = !status.intersects(
            Status::SAFE_HOLD
                | Status::NO_SETPOINT
                | Status::OUT_OF_WORKSPACE
                | Status::SETPOINT_REJECTED
                | Status::SLEW_LIMITED,
        ) && !stale;
        if host_correction && tracking {
            if let (Some(s), Some(f)) = (last_good_sp, &fw_fb) {
                let mut desired = [s.pose[0] as f64, s.pose[1] as f64];
                if s.flags & setpoint_flags::HAS_VELOCITY != 0 {
                    desired[0] += s.velocity[0] as f64 * cfg.lead;
                    desired[1] += s.velocity[1] as f64 * cfg.lead;
                }
                let measured = [f.tip_position[0] as f64, f.tip_position[1] as f64];
                integral.update(desired, measured, &gains, period_ns as f64 * 1e-9);
            }
        }
        if host_correction && integral.c != [0.0, 0.0] {
            extra |= command_status::CORRECTION;
        }
        if status.contains(Status::NONFINITE_SETPOINT) {
            stats.rejected_nonfinite += 1;
            log::warn!("controller: setpoint with NaN/∞ rejected");
        }
        if status.contains(Status::BAD_QUATERNION) {
            stats.rejected_quaternion += 1;
            log::warn!("controller: setpoint with a non-unit quaternion rejected");
        }
        if status.contains(Status::OUT_OF_WORKSPACE) {
            stats.rejected_workspace += 1;
            if stats.rejected_workspace == 1 || stats.rejected_workspace.is_power_of_two() {
                log::warn!(
                    "controller: setpoint outside the workspace held ({} so far)",
                    stats.rejected_workspace
                );
            }
        }
        let hold = status.contains(Status::SAFE_HOLD);
        if hold {
            stats.hold_cycles += 1;
            if !in_hold {
                stats.watchdog_trips += 1;
                log::warn!(
                    "controller: no setpoint for {:.1} periods: safe hold",
                    cfg.watchdog_periods
                );
            }
        } else if in_hold {
            log::info!("controller: setpoints back, tracking resumed");
        }
        in_hold = hold;
        if status.contains(Status::SATURATED) {
            stats.saturated_cycles += 1;
        }

        cmd_seq += 1;
        let mut cmd = TensionCommand {
            header: Header {
                seq: cmd_seq,
                stamp_ns: 0,
            },
            setpoint_seq: last_sp.map_or(0, |s| s.header.seq),
            count: out.count as u32,
            status: status.bits() | extra,
            ..TensionCommand::default()
        };
        cmd.tensions = out.command;
        cmd.header.stamp_ns = now_ns();
        transport::send(&commands, cmd)?;
        notifier
            .notify()
            .map_err(|e| IpcError::Send(format!("tension_cmd event: {e:?}")))?;

        let t_done = now_ns();
        overran = ticker.finish(t_done);
        work.push(t_done - t_wake);
        let mut row = Vec::with_capacity(6 + n);
        row.extend([
            tick.deadline_ns as f64,
            tick.lateness_ns as f64,
            (t_done - t_wake) as f64,
            cmd.status as f64,
            cmd.setpoint_seq as f64,
            last_state.map_or(0.0, |s| s.header.seq as f64),
        ]);
        row.extend(out.command[..n].iter().map(|&v| v as f64));
        log.row(&row)?;
        if t_done - last_flush > 100_000_000 {
            log.flush()?;
            last_flush = t_done;
        }
        if stop.requested()
            || cfg
                .duration
                .is_some_and(|d| (t_done - start) as f64 * 1e-9 >= d)
        {
            break;
        }
    }
    log.flush()?;
    stats.cycles = ticker.cycles;
    stats.overruns = ticker.overruns;
    stats.skipped = ticker.skipped;
    stats.overrun_fraction = ticker.overruns as f64 / ticker.cycles.max(1) as f64;
    stats.lateness_us = Summary::of_ns(&mut lateness);
    stats.step_us = Summary::of_ns(&mut work);
    stats.setpoint_age_us = Summary::of_ns(&mut sp_age);
    if let Some(path) = &cfg.stats {
        let json = serde_json::to_vec_pretty(&stats).map_err(|e| IpcError::Other(e.to_string()))?;
        super::write_file(path, &json)?;
    }
    Ok(stats)
}
