//! From the logs and the launcher's events to the typed report: the
//! statistics with what they cover, each process's end, and every
//! injected fault with its detection.

use std::path::Path;

use tendril_shared::messages::{command_status, plant_status};

use super::analysis::{
    self, join, pass_rms, path_error_rms, rms_between, steady_states, tracking, Logs, Sample,
};
use super::faults::Action;
use super::oscillation;
use super::realtime::{link_problems, real_time_problems, MachineTook};
use super::report::{
    FaultKind, FaultRecord, ModelUsed, PathPoint, PlantSummary, Series, SimReport, TensionPoint,
    Verdict,
};
use super::supervisor::{Children, Role};
use super::workdir::RunDir;
use super::{Event, SimConfig, SimError};
use crate::ipc::controller::{ControllerStats, DetectedFault, FaultKind as Detected};
use crate::ipc::plant::PlantStats;
use crate::ipc::stats::Summary;

fn read_json<T: for<'de> serde::Deserialize<'de>>(path: &Path) -> Option<T> {
    let text = std::fs::read(path).ok()?;
    serde_json::from_slice(&text).ok()
}

/// The highest frequency of the trajectory's own motion, Hz (what the
/// oscillation test's band starts above): a figure eight moves at twice its
/// revolution rate, steps at one per dwell; a pose table is taken as slow.
pub fn trajectory_hz(shape: &crate::plan::PathShape) -> f64 {
    use crate::plan::PathShape as S;
    match shape {
        S::Circle { freq_hz, .. } | S::Helix { freq_hz, .. } | S::Sweep { freq_hz, .. } => *freq_hz,
        S::FigureEight { freq_hz, .. } => 2.0 * freq_hz,
        S::Steps { dwell_s, .. } => 1.0 / dwell_s,
        S::Hold { .. } | S::Table { .. } => 0.0,
    }
}

/// What the run's tracking is held to (`--max-rms-mm`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Bound {
    /// The RMS tracking error.
    Rms,
    /// The steady states: a path with jumps, whose RMS is the jumps'
    /// transients, not the loop's accuracy.
    SteadyStates,
    /// Nothing: an injected fault stops tracking by design (the fault
    /// records judge the run); why.
    Waived(&'static str),
}

impl Bound {
    fn of(cfg: &SimConfig, events: &[Event]) -> Bound {
        use crate::plan::PathShape as S;
        if cfg.smoke {
            Bound::Waived(
                "a smoke run (tendril run --quick): its net is small on purpose, so the run \
                 checks that the loop works, not how well the net tracks",
            )
        } else if events.iter().any(|e| matches!(e.action, Action::Kill(_))) {
            Bound::Waived("a process was killed by fault injection")
        } else if cfg.plant.params.faults.stuck.is_some() {
            Bound::Waived("a stuck motor was injected (the loop holds by design)")
        } else if matches!(cfg.planner.shape, S::Steps { .. } | S::Table { .. }) {
            Bound::SteadyStates
        } else {
            Bound::Rms
        }
    }

    /// Why the RMS bound does not apply, if it does not.
    fn rms_waived_because(self) -> Option<String> {
        match self {
            Bound::Rms => None,
            Bound::SteadyStates => Some(
                "a path with jumps: its RMS is the jumps' transients; its steady states are held \
                 to the bound instead"
                    .into(),
            ),
            Bound::Waived(why) => Some(why.into()),
        }
    }
}

/// The report of a finished run.
#[allow(clippy::too_many_arguments)]
pub fn build_report(
    cfg: &SimConfig,
    dir: &RunDir,
    t0: u64,
    children: &Children,
    events: &[Event],
    prefix: &str,
    model: ModelUsed,
    machine: MachineTook,
) -> Result<SimReport, SimError> {
    let planners = children.started(Role::Planner);
    let plants = children.started(Role::Plant);
    let controllers = children.started(Role::Controller);
    let logs = Logs::read(&dir.work, planners, plants, controllers)?;
    let samples = join(&logs, t0);
    let track = tracking(&samples);
    let steady = steady_states(&samples);
    let controller = controller_stats(dir, controllers);
    let mut plant = PlantSummary::default();
    let mut latencies: Vec<Summary> = Vec::new();
    for g in 0..plants {
        match read_json::<PlantStats>(&dir.file(&format!("plant-{g}.json"))) {
            Some(s) => {
                plant.commands_checked += s.commands - s.dropped;
                plant.out_of_range_commands += s.out_of_range_commands;
                latencies.push(s.latency_us);
                plant.generations.push(s);
            }
            None => {
                // A killed plant writes no statistics: its log still shows
                // the commands it applied; range-check those.
                let max = crate::robot::Robot::load(&cfg.robot)
                    .map(|r| r.max_tensions())
                    .unwrap_or_default();
                if !max.is_empty() {
                    let (seen, bad) = logs.commands_logged(g, &max);
                    plant.commands_checked += seen;
                    plant.out_of_range_commands += bad;
                }
                plant.generations_without_stats.push(g);
            }
        }
    }
    plant.step_us = plant
        .generations
        .first()
        .map(|s| s.step_us)
        .filter(|s| s.count > 0);
    let ipc_latency_us = latencies.into_iter().find(|s| s.count > 0);
    let processes = children.records(t0);
    let faults = analyse_faults(cfg, t0, events, &logs, &samples, controller.as_ref());

    let mut problems: Vec<String> = processes
        .iter()
        .filter(|p| !p.end.acceptable())
        .map(|p| {
            format!(
                "{} {} (pid {}) {} at {}",
                p.role.name(),
                p.generation,
                p.pid,
                p.end.describe(),
                p.ended_s.map_or("?".into(), |t| format!("{t:.3} s"))
            )
        })
        .collect();
    let learning_stopped_at_s = logs.learning_stopped_ns().map(|t| (t - t0 as f64) * 1e-9);
    if let Some(t) = learning_stopped_at_s {
        problems.push(format!(
            "learning stopped at {t:.2} s: the error grew pass after pass (the best pass's offset was held)"
        ));
    }
    if track.samples == 0 {
        problems.push("no tracking samples: the tracking statistics measured nothing".into());
    }
    let oscillation = oscillation::detect(
        &samples,
        oscillation::band_from(trajectory_hz(&cfg.planner.shape)),
    );
    if let (true, Some(f), Some(r)) = (
        oscillation.detected,
        oscillation.frequency_hz,
        oscillation.tone_rms_mm,
    ) {
        problems.push(format!(
            "the loop oscillates: {f:.2} Hz, {r:.3} mm RMS ({:.3} mm amplitude) in the tracking \
             error, in {} of {} 2 s windows",
            r * std::f64::consts::SQRT_2,
            oscillation.windows_with_tone,
            oscillation.windows
        ));
    }
    let growth = oscillation::growth(&samples);
    let bound = Bound::of(cfg, events);
    // Only where the RMS is the loop's accuracy: a path with jumps has its
    // transients wherever the jumps fall.
    if let (Bound::Rms, Some(g)) = (bound, &growth) {
        if g.growing {
            problems.push(format!(
                "the tracking error grows over the run ({:.3} mm RMS in its first third, {:.3} mm \
                 in its last): the loop drifts away or swings slower than the tone test sees",
                g.first_third_rms_mm, g.last_third_rms_mm
            ));
        }
    }
    match bound {
        Bound::Rms => {
            if let Some(rms) = track.rms.filter(|&rms| rms > cfg.max_rms_mm) {
                problems.push(format!(
                    "RMS tracking error {rms:.3} mm exceeds the bound {} mm (--max-rms-mm)",
                    cfg.max_rms_mm
                ));
            }
        }
        // The tip must settle on every target (a three-segment net once
        // held one target of four 115 mm off and the run read "clean").
        Bound::SteadyStates => {
            if let Some(worst) = steady
                .iter()
                .max_by(|a, b| a.error_mm.total_cmp(&b.error_mm))
                .filter(|s| s.error_mm > cfg.max_rms_mm)
            {
                problems.push(format!(
                    "steady-state error {:.3} mm at the target ({:.3}, {:.3}) mm exceeds the \
                     bound {} mm (--max-rms-mm)",
                    worst.error_mm, worst.target_mm[0], worst.target_mm[1], cfg.max_rms_mm
                ));
            }
        }
        Bound::Waived(_) => {}
    }
    let machine = machine.with_shared_stall(&logs, cfg.controller.rate_hz);
    match controller.as_ref() {
        None => problems.push("the controller wrote no statistics".into()),
        Some(c) => problems.extend(real_time_problems(c, cfg.controller.rate_hz, machine)),
    }
    let dropped: u64 = (plant.generations.iter())
        .filter_map(|g| g.runlog.as_ref())
        .map(|r| r.dropped)
        .sum();
    if dropped > 0 {
        problems.push(format!(
            "the run log dropped {dropped} records (its writer fell behind): run.mcap is \
             incomplete (fewer --scene-hz or --backbone-points)"
        ));
    }
    if let Some(link) = controller.as_ref().and_then(|c| c.link.as_ref()) {
        problems.extend(link_problems(link));
    }
    if plant.commands_checked == 0 {
        problems.push("the plant range-checked no command".into());
    }
    problems.extend(
        faults
            .iter()
            .filter(|f| f.detected == Some(false))
            .map(|f| {
                format!(
                    "{:?} injected at {:.3} s was not detected",
                    f.kind,
                    f.t_s.unwrap_or(f64::NAN)
                )
            }),
    );

    let secs = |t_ns: f64| (t_ns - t0 as f64) * 1e-9;
    let series = Series {
        path: samples
            .iter()
            .step_by(10)
            .map(|s| PathPoint {
                t_s: s.t,
                desired_mm: [s.desired[0] * 1e3, s.desired[1] * 1e3],
                actual_mm: [s.actual[0] * 1e3, s.actual[1] * 1e3],
                hold: s.hold,
            })
            .collect(),
        tensions: logs
            .plant
            .iter()
            .step_by(10)
            .map(|r| TensionPoint {
                t_s: secs(r.t_ns),
                commanded: r.commanded.clone(),
                actual: r.actual.clone(),
            })
            .collect(),
    };
    Ok(SimReport {
        label: cfg.label.clone(),
        prefix: prefix.to_string(),
        model,
        duration_s: cfg.duration_s,
        settle_s: cfg.planner.settle_s,
        step_shaping: match cfg.planner.step_shaping {
            crate::plan::ShapingChoice::Designed(s) => Some(s),
            _ => None,
        },
        dynamic_offset: cfg.planner.dynamic_offset && cfg.planner.step_shaping.is_designed(),
        net_error_offset: cfg.planner.net_error_offset,
        learning: match cfg.planner.learning {
            crate::plan::LearningChoice::Designed(d) => Some(d),
            _ => None,
        },
        learning_stopped_at_s,
        model_learning: None,
        stiffness_adapted: logs.stiffness_adapted(),
        pass_rms_mm: match (cfg.planner.shape.period_s(), logs.setpoints.first()) {
            // From the end of the first planner's settle hold.
            (Some(period), Some(first)) => {
                let start = (first.t_ns - t0 as f64) * 1e-9 + cfg.planner.settle_s;
                pass_rms(&samples, start, start + cfg.duration_s, period)
            }
            _ => Vec::new(),
        },
        tendons: logs.tendons,
        verdict: Verdict {
            clean: problems.is_empty(),
            problems,
        },
        processes,
        rms_tracking_error_mm: track.rms,
        rms_path_error_mm: path_error_rms(&samples),
        max_tracking_error_mm: track.max,
        p95_tracking_error_mm: track.p95,
        tracking_samples: track.samples,
        tracking_window_s: track.window,
        max_steady_state_error_mm: steady.iter().map(|s| s.error_mm).reduce(f64::max),
        max_rms_mm: cfg.max_rms_mm,
        max_rms_applied: bound == Bound::Rms,
        max_rms_waived_because: bound.rms_waived_because(),
        oscillation,
        growth,
        controller_cpu_steal_ms: machine.steal_ms,
        stall_shared_with_planner_periods: machine.shared_stall_periods,
        steady_state: steady,
        controller,
        ipc_latency_us,
        plant,
        faults,
        series,
    })
}

/// The controller's statistics: one generation's, or with the chip in the
/// loop and the link cut and restored, the last bridge's (the chip's counts
/// run on across bridges) with every generation's fault list.
fn controller_stats(dir: &RunDir, generations: usize) -> Option<ControllerStats> {
    let all: Vec<ControllerStats> = (0..generations.max(1))
        .filter_map(|g| {
            let stem = super::workdir::stem(Role::Controller, g);
            read_json(&dir.file(&format!("{stem}.json")))
        })
        .collect();
    let mut faults: Vec<DetectedFault> = all
        .iter()
        .flat_map(|c| c.faults_detected.iter().cloned())
        .collect();
    faults.sort_by_key(|f| f.t_ns);
    let not_listed = all.iter().map(|c| c.faults_not_listed).sum();
    let mut last = all.into_iter().last()?;
    last.faults_detected = faults;
    last.faults_not_listed = not_listed;
    Some(last)
}

/// Every injected fault with what the loop did about it.
fn analyse_faults(
    cfg: &SimConfig,
    t0: u64,
    events: &[Event],
    logs: &Logs,
    samples: &[Sample],
    controller: Option<&ControllerStats>,
) -> Vec<FaultRecord> {
    let period_ns = 1e9 / cfg.controller.rate_hz;
    let secs = |t: f64| (t - t0 as f64) * 1e-9;
    let end = cfg.planner.settle_s + cfg.duration_s;
    let mut out = Vec::new();
    for ev in events {
        let te = ev.t_ns as f64;
        let t_s = secs(te);
        let pid = ev.pid.map_or(String::new(), |p| format!("pid {p}"));
        let mut f = match ev.action {
            Action::Kill(Role::Planner) => {
                let mut f = FaultRecord::new(FaultKind::PlannerKilled, Some(t_s), pid);
                let hold = logs.controller_flag_after(te, command_status::SAFE_HOLD);
                f.detect(
                    hold.map(|h| (h - te) * 1e-9),
                    "controller safe hold (watchdog)",
                );
                // Last period that saw a new setpoint before the kill.
                let before: Vec<_> = logs.controller.iter().filter(|r| r.t_ns <= te).collect();
                let last_new = before
                    .windows(2)
                    .rev()
                    .find(|w| w[1].setpoint_seq != w[0].setpoint_seq)
                    .map(|w| w[1].t_ns);
                if let (Some(a), Some(b)) = (last_new, hold) {
                    f.hold_periods_after_last_setpoint = Some(((b - a) / period_ns).round() as u64);
                }
                f
            }
            Action::Restart(Role::Planner) => {
                let mut f = FaultRecord::new(FaultKind::PlannerRestarted, Some(t_s), String::new());
                f.resumed_after_s = logs
                    .controller
                    .iter()
                    .find(|r| r.t_ns > te && r.status & command_status::SAFE_HOLD == 0)
                    .map(|r| (r.t_ns - te) * 1e-9);
                f.rms_after_recovery_mm = rms_between(samples, t_s + 1.5, end);
                f
            }
            Action::Kill(Role::Controller) => {
                let restore = cfg.faults.restore_link_after.is_some();
                let detail = if restore {
                    pid
                } else {
                    format!(
                        "{pid}; not restored: no bridge reports what the chip did after the cut"
                    )
                };
                let mut f = FaultRecord::new(FaultKind::LinkCut, Some(t_s), detail);
                // The restored bridge lists the chip's hold during the cut
                // (from the chip's telemetry: when, and after how much silence).
                let hold = controller.and_then(|c| {
                    c.faults_detected.iter().find(|d| {
                        d.kind == Detected::WatchdogHold && d.t_ns as f64 >= te - period_ns
                    })
                });
                f.detect(
                    hold.map(|h| ((h.t_ns as f64 - te) * 1e-9).max(0.0)),
                    "the chip's safe hold (its watchdog), from its telemetry",
                );
                f.hold_periods_after_last_setpoint = hold.map(|h| h.value.round() as u64);
                f
            }
            Action::Restart(Role::Controller) => {
                let mut f = FaultRecord::new(FaultKind::LinkRestored, Some(t_s), String::new());
                f.resumed_after_s = logs
                    .controller
                    .iter()
                    .find(|r| r.t_ns > te && r.status & command_status::SAFE_HOLD == 0)
                    .map(|r| (r.t_ns - te) * 1e-9);
                f.rms_after_recovery_mm = rms_between(samples, t_s + 1.5, end);
                f
            }
            Action::Kill(_) => {
                let restart = cfg.faults.restart_plant_after.is_some();
                let detail = if restart {
                    pid
                } else {
                    format!(
                        "{pid}; not restarted: no plant from here on, the tracking statistics \
                         end at the kill"
                    )
                };
                let mut f = FaultRecord::new(FaultKind::PlantKilled, Some(t_s), detail);
                f.restart_configured = Some(restart);
                let stale = logs.controller_flag_after(te, command_status::PLANT_STALE);
                f.controller_flagged_stale = Some(stale.is_some());
                f.detect(
                    stale.map(|s| (s - te) * 1e-9),
                    "controller plant-stale flag",
                );
                let last_state = logs
                    .controller
                    .iter()
                    .rev()
                    .find(|r| r.t_ns <= te)
                    .map(|r| r.state_seq);
                f.state_resumed_at_s = logs
                    .controller
                    .iter()
                    .filter(|r| r.t_ns > te)
                    .find(|r| Some(r.state_seq) != last_state)
                    .map(|r| secs(r.t_ns));
                f
            }
            Action::Restart(_) => {
                let mut f = FaultRecord::new(FaultKind::PlantRestarted, Some(t_s), String::new());
                f.rms_after_recovery_mm = rms_between(samples, t_s + 1.5, end);
                f
            }
            Action::Weights { corrupt } => {
                let (kind, bit, how) = if corrupt {
                    (
                        FaultKind::WeightsCorrupted,
                        command_status::WEIGHTS_REJECTED,
                        "controller weights-rejected flag",
                    )
                } else {
                    (
                        FaultKind::WeightsSwapped,
                        command_status::WEIGHTS_SWAPPED,
                        "controller weights-swapped flag",
                    )
                };
                let mut f = FaultRecord::new(kind, Some(t_s), String::new());
                let seen = logs.controller_flag_after(te - period_ns, bit);
                f.detect(seen.map(|s| ((s - te) * 1e-9).max(0.0)), how);
                f
            }
        };
        if matches!(ev.action, Action::Restart(_)) {
            f.detected = None;
        }
        out.push(f);
    }
    let detections = controller.map_or(&[][..], |c| &c.faults_detected[..]);
    out.extend(planner_injections(cfg, t0, logs, detections));
    out.extend(plant_faults(cfg, t0, logs, detections));
    out.sort_by(|a, b| {
        let key = |f: &FaultRecord| f.t_s.unwrap_or(f64::INFINITY);
        key(a).total_cmp(&key(b))
    });
    out
}

/// NaN and out-of-workspace setpoints, from the planner's log (injected
/// messages are flagged there), detected by the controller's
/// setpoint-rejected flag.
fn planner_injections(
    cfg: &SimConfig,
    t0: u64,
    logs: &Logs,
    detections: &[DetectedFault],
) -> Vec<FaultRecord> {
    let inject = &cfg.planner.inject;
    let Some(first) = logs.setpoints.iter().find(|s| s.generation == 0) else {
        return Vec::new();
    };
    let planner_start = first.t_ns;
    let mut out = Vec::new();
    for (start, count) in logs.injection_bursts() {
        let since = (start - planner_start) * 1e-9;
        let nearest = |times: &[f64]| {
            times
                .iter()
                .map(|a| (since - a).abs())
                .fold(f64::INFINITY, f64::min)
        };
        let (kind, listed, name) = if nearest(&inject.nan_at_s) <= nearest(&inject.outside_at_s) {
            (
                FaultKind::NanSetpoint,
                Detected::NonfiniteSetpoint,
                "nonfinite_setpoint",
            )
        } else {
            (
                FaultKind::OutsideSetpoint,
                Detected::OutsideWorkspace,
                "outside_workspace",
            )
        };
        let mut f = FaultRecord::new(
            kind,
            Some((start - t0 as f64) * 1e-9),
            format!("{count} message{}", if count == 1 { "" } else { "s" }),
        );
        // The fault list lists a burst once per FAULT_REPEAT_S; the
        // per-period status bit shows every rejection.
        match first_detection(detections, start, |d| d.kind == listed) {
            Some(t) => f.detect(
                Some((t - start) * 1e-9),
                &format!("controller fault list: {name}"),
            ),
            None => {
                let seen = logs.controller_flag_after(start, analysis::REJECTED);
                f.detect(
                    seen.map(|s| (s - start) * 1e-9),
                    "controller setpoint-rejected flag",
                );
            }
        }
        out.push(f);
    }
    out
}

/// Plant-side faults, from the plant's log (it flags its own faults), detected by the controller.
fn plant_faults(
    cfg: &SimConfig,
    t0: u64,
    logs: &Logs,
    detections: &[DetectedFault],
) -> Vec<FaultRecord> {
    let faults = &cfg.plant.params.faults;
    let secs = |t: f64| (t - t0 as f64) * 1e-9;
    let mut out = Vec::new();
    if let Some(stuck) = faults.stuck {
        let at = logs.plant_flag(plant_status::MOTOR_STUCK);
        let mut f = FaultRecord::new(
            FaultKind::StuckMotor,
            at.map(secs),
            format!(
                "tendon {} at {} s after the plant's start",
                stuck.tendon, stuck.at_s
            ),
        );
        if let Some(at) = at {
            let found = first_detection(detections, at, |d| {
                d.kind == Detected::StuckMotor && d.tendon.is_none_or(|k| k == stuck.tendon)
            });
            // Latency from when the fault first had an effect: a motor that
            // sticks while its tendon is not asked to move is invisible until
            // the path asks (its command leaves the stuck tension).
            let threshold = cfg.controller.stuck_motor.tension_error_n;
            let effect = logs
                .first_command_departure(stuck.tendon, at, threshold)
                .unwrap_or(at);
            f.detect(
                found.map(|t| (t - effect).max(0.0) * 1e-9),
                "controller fault list: stuck_motor (latency from the first command the stuck motor did not follow)",
            );
            // A motor stuck where its tendon is never asked to move (a slack
            // tendon the path never needs) changes nothing the controller
            // can see, and nothing the robot does: latent, not missed.
            let departure = logs.largest_command_departure(stuck.tendon, at);
            if found.is_none() && departure.is_some_and(|d| d <= threshold) {
                f.detected = None;
                f.detail.push_str(&format!(
                    "; latent: its command never left the stuck tension by more than {:.3} N \
                     (the detection threshold is {threshold} N), so it had no effect to detect",
                    departure.unwrap_or(0.0)
                ));
            }
        }
        out.push(f);
    }
    if let Some(drop) = faults.drop {
        let at = logs.plant_flag(plant_status::DROPPING);
        let what = format!(
            "{:.0} % of commands from {} to {} s after the plant's start",
            drop.fraction * 100.0,
            drop.from_s,
            drop.to_s
        );
        out.push(unapplied_commands(
            FaultKind::DroppedCommands,
            at,
            what,
            detections,
            secs,
            "dropped",
        ));
    }
    if let Some(delay) = faults.delay {
        let at = logs.plant_flag(plant_status::DELAYING);
        let what = format!(
            "{:.1} ms from {} to {} s after the plant's start",
            delay.delay_s * 1e3,
            delay.from_s,
            delay.to_s
        );
        out.push(unapplied_commands(
            FaultKind::DelayedCommands,
            at,
            what,
            detections,
            secs,
            "delayed",
        ));
    }
    out
}

/// A dropped- or delayed-command fault that the plant flagged at `at`
/// (monotonic ns): detected when the controller lists commands not applied.
fn unapplied_commands(
    kind: FaultKind,
    at: Option<f64>,
    what: String,
    detections: &[DetectedFault],
    secs: impl Fn(f64) -> f64,
    verb: &str,
) -> FaultRecord {
    let mut f = FaultRecord::new(kind, at.map(&secs), what);
    match at.and_then(|at| {
        first_detection(detections, at, |d| d.kind == Detected::CommandsNotApplied).map(|t| (at, t))
    }) {
        Some((at, t)) => f.detect(
            Some((t - at) * 1e-9),
            "controller fault list: commands_not_applied",
        ),
        None => f.detect(
            at.map(|_| 0.0),
            &format!("plant log only: first {verb} command"),
        ),
    }
    f
}

/// Time (monotonic ns) of the first controller detection at or after
/// `from_ns` that `matches`.
fn first_detection(
    detections: &[DetectedFault],
    from_ns: f64,
    matches: impl Fn(&DetectedFault) -> bool,
) -> Option<f64> {
    detections
        .iter()
        .filter(|d| d.t_ns as f64 >= from_ns && matches(d))
        .map(|d| d.t_ns as f64)
        .reduce(f64::min)
}
