//! The typed result of one `tendril sim` run: what `report.json` is the
//! serialisation of, and its markdown rendering (`report.md`).
//!
//! Every statistic carries what it covers: a count of the samples behind
//! it, or `null` when there were none (never a 0.0 that measured nothing).

use std::fmt::Write as _;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::oscillation::Oscillation;
use super::supervisor::ProcessRecord;
use crate::ipc::controller::ControllerStats;
use crate::ipc::plant::PlantStats;
use crate::ipc::stats::Summary;

/// The report of one run (`report.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SimReport {
    /// Free-form description of the run.
    pub label: String,
    /// iceoryx2 service-name prefix of the run.
    pub prefix: String,
    /// The net the controller started with.
    pub model: ModelUsed,
    /// Seconds of trajectory after the settle hold, as configured.
    pub duration_s: f64,
    /// Initial hold, s.
    pub settle_s: f64,
    /// How the planner moved between step targets: the mode its shaper was
    /// designed for (`null`: steps jumped, or the path has none).
    #[serde(default)]
    pub step_shaping: Option<crate::plan::StepShaping>,
    /// Whether the planner sent the modal inverse's dynamic offset (only
    /// with a shaping).
    #[serde(default)]
    pub dynamic_offset: bool,
    /// Whether the planner sent the offset that takes the net's own
    /// quasi-static error along the path out (`docs/design.md` §6.4).
    #[serde(default)]
    pub net_error_offset: bool,
    /// Learning for repeated paths: the design the planner learned with
    /// (`null`: off).
    #[serde(default)]
    pub learning: Option<crate::plan::LearningDesign>,
    /// When learning stopped on a growing error (the fault event), s.
    #[serde(default)]
    pub learning_stopped_at_s: Option<f64>,
    /// The circle's offset learned on the model before the run (`null`:
    /// not asked for; `docs/design.md` §6.4).
    #[serde(default)]
    pub model_learning: Option<super::model_learning::ModelLearningReport>,
    /// The stiffness adaptation's estimate at the end, κ̂ (the tip's share
    /// of a stiffness error: 0.091 for a backbone 10 % stiffer than its
    /// file; `null`: off; `docs/design.md` §6.5).
    #[serde(default)]
    pub stiffness_adapted: Option<f64>,
    /// The tracking error's RMS over each whole period of a repeated path
    /// after the settle hold, mm (empty for a path that does not repeat):
    /// what learning lowers pass after pass.
    #[serde(default)]
    pub pass_rms_mm: Vec<f64>,
    /// Tendons of the robot (from the plant log).
    pub tendons: usize,
    /// Whether every process finished cleanly (or died by an injected fault)
    /// and the statistics below measured something.
    pub verdict: Verdict,
    /// Every process the run started: role, pid, start, end and how it ended.
    pub processes: Vec<ProcessRecord>,
    /// RMS of the true tip error against the planner's path over the
    /// tracking samples (outside holds), mm; `null` with no samples.
    pub rms_tracking_error_mm: Option<f64>,
    /// RMS distance from the true tip to the planner's path (the polyline
    /// through the setpoints within ±0.2 s), mm: the tracking error less
    /// the delay along the path (`analysis::path_error_rms`). What compares
    /// two controllers whose commands arrive with different latency.
    #[serde(default)]
    pub rms_path_error_mm: Option<f64>,
    /// Largest tracking error, mm.
    pub max_tracking_error_mm: Option<f64>,
    /// 95th percentile of the tracking error, mm.
    pub p95_tracking_error_mm: Option<f64>,
    /// Plant steps joined with a setpoint in force outside holds: what the
    /// three tracking statistics above cover.
    pub tracking_samples: usize,
    /// First and last tracking sample, s since the first setpoint.
    pub tracking_window_s: Option<[f64; 2]>,
    /// The bound the RMS tracking error was held to, mm (`--max-rms-mm`):
    /// above it the run is not clean.
    #[serde(default)]
    pub max_rms_mm: f64,
    /// Whether the bound was applied: not to a path with jumps (steps, a
    /// pose table) nor after an injected kill or stuck motor.
    #[serde(default)]
    pub max_rms_applied: bool,
    /// Why not, when it was not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_rms_waived_because: Option<String>,
    /// The oscillation test of the tracking error and its evidence: a
    /// sustained tone makes the run not clean.
    #[serde(default)]
    pub oscillation: Oscillation,
    /// The tracking error's last third against its first.
    #[serde(default)]
    pub growth: Option<super::oscillation::Growth>,
    /// Time the hypervisor took from the controller's CPU during the run,
    /// ms (the most any CPU lost when it was not pinned); `None` where the
    /// kernel does not say.
    #[serde(default)]
    pub controller_cpu_steal_ms: Option<u64>,
    /// Periods of the controller's longest stall the machine took as the
    /// planner on another CPU shows (it stopped too: a pause of the whole
    /// machine, `realtime::stall_shared_with_planner`); `null` when the
    /// planner shared the controller's CPU or was not pinned.
    #[serde(default)]
    pub stall_shared_with_planner_periods: Option<f64>,
    /// Every stretch of ≥ 1 s with one target: mean true error over its last 0.5 s.
    pub steady_state: Vec<SteadyState>,
    /// Worst of `steady_state`, mm; `null` when there was no such stretch.
    pub max_steady_state_error_mm: Option<f64>,
    /// The controller's own statistics (`null` when it wrote none: it died).
    pub controller: Option<ControllerStats>,
    /// One-way command latency controller → plant over all plant
    /// generations' commands (µs); `null` when no command arrived.
    pub ipc_latency_us: Option<Summary>,
    /// The plant's statistics.
    pub plant: PlantSummary,
    /// Every injected fault: when, and when and how the loop detected it.
    pub faults: Vec<FaultRecord>,
    /// Decimated time series for the figure.
    pub series: Series,
}

/// Which net the controller ran.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelUsed {
    /// The file given (or the built-in net written into the output directory).
    pub path: PathBuf,
    /// Whether it is the firmware's built-in net (`firmware/vectors/default.tnet`).
    pub built_in: bool,
}

/// The run's overall outcome.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Verdict {
    /// No problem below.
    pub clean: bool,
    /// One line per problem: a process that died uninjected or had to be
    /// killed at shutdown, a statistic with no data behind it.
    pub problems: Vec<String>,
}

/// Steady-state error at one target.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SteadyState {
    /// Start of the stretch, s.
    pub t_s: f64,
    /// Lateral target x, y (mm).
    pub target_mm: [f64; 2],
    /// Mean true error over the stretch's last 0.5 s (mm).
    pub error_mm: f64,
    /// Plant steps averaged.
    pub samples: usize,
    /// From the start of the move to this target until the true error
    /// stayed within 0.1 mm, s (`null`: it never did, or this is the first
    /// target).
    #[serde(default)]
    pub settle_s: Option<f64>,
    /// RMS of the error's deviation from its mean after it settled, mm:
    /// the ringing left.
    #[serde(default)]
    pub vibration_mm: Option<f64>,
}

/// The plant side of the report.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PlantSummary {
    /// Step time of the first plant generation (µs); `null` with no steps.
    pub step_us: Option<Summary>,
    /// Commands the plants received and range-checked (all generations; for
    /// a generation killed before writing statistics, the commands its log
    /// shows applied, checked by the launcher against the robot's limits).
    pub commands_checked: u64,
    /// Of those, commands with a tension out of range or not finite.
    pub out_of_range_commands: u64,
    /// Plant generations that wrote no statistics (killed, or died).
    pub generations_without_stats: Vec<usize>,
    /// Each generation's own statistics, generation 0 first.
    pub generations: Vec<PlantStats>,
}

/// Kinds of injected fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// SIGKILL of the planner.
    PlannerKilled,
    /// A new planner after a kill.
    PlannerRestarted,
    /// SIGKILL of the plant.
    PlantKilled,
    /// A new plant after a kill.
    PlantRestarted,
    /// A weight update with a flipped bit.
    WeightsCorrupted,
    /// A valid weight update (hot swap).
    WeightsSwapped,
    /// A NaN setpoint from the planner.
    NanSetpoint,
    /// A burst of out-of-workspace setpoints from the planner.
    OutsideSetpoint,
    /// A plant motor that stops following its command.
    StuckMotor,
    /// The plant drops a fraction of the commands.
    DroppedCommands,
    /// The plant delays the commands.
    DelayedCommands,
    /// The bridge to the chip killed: the link goes silent and the chip
    /// must hold on its own.
    LinkCut,
    /// A new bridge reconnected to the running chip.
    LinkRestored,
}

/// One injected fault and what the loop made of it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FaultRecord {
    /// What was injected.
    pub kind: FaultKind,
    /// When, s since the first setpoint (`null`: it never took effect,
    /// e.g. scheduled after the run's end).
    pub t_s: Option<f64>,
    /// Whether the loop noticed it (`null`: nothing to notice, e.g. a restart).
    pub detected: Option<bool>,
    /// Detection latency: injection → first sign in the controller's log or
    /// fault list, s.
    pub detection_latency_s: Option<f64>,
    /// How it was detected (the status bit or fault entry).
    pub detected_by: Option<String>,
    /// Details: the pid killed, the tendon stuck, the drop fraction …
    pub detail: String,
    /// Planner kill: periods from the last new setpoint to the safe hold.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub hold_periods_after_last_setpoint: Option<u64>,
    /// Planner restart: s from the new planner's start to the end of the hold.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub resumed_after_s: Option<f64>,
    /// Restarts: RMS tracking error from 1.5 s after the restart to the end, mm.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub rms_after_recovery_mm: Option<f64>,
    /// Plant kill: whether a restart was configured.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub restart_configured: Option<bool>,
    /// Plant kill: the controller flagged the plant state stale.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub controller_flagged_stale: Option<bool>,
    /// Plant kill: when fresh plant states came again, s.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub state_resumed_at_s: Option<f64>,
}

impl FaultRecord {
    /// A fault with no analysis yet.
    pub fn new(kind: FaultKind, t_s: Option<f64>, detail: String) -> FaultRecord {
        FaultRecord {
            kind,
            t_s,
            detected: None,
            detection_latency_s: None,
            detected_by: None,
            detail,
            hold_periods_after_last_setpoint: None,
            resumed_after_s: None,
            rms_after_recovery_mm: None,
            restart_configured: None,
            controller_flagged_stale: None,
            state_resumed_at_s: None,
        }
    }

    /// Record a detection `latency_s` after the injection by `how`.
    pub fn detect(&mut self, latency_s: Option<f64>, how: &str) {
        self.detected = Some(latency_s.is_some());
        self.detection_latency_s = latency_s;
        self.detected_by = latency_s.map(|_| how.to_string());
    }
}

/// Decimated series for the figure.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Series {
    /// Every 10th joined sample.
    pub path: Vec<PathPoint>,
    /// Every 10th plant step.
    pub tensions: Vec<TensionPoint>,
}

/// Desired and true lateral tip position at one time.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct PathPoint {
    /// s since the first setpoint.
    pub t_s: f64,
    /// Desired x, y (mm).
    pub desired_mm: [f64; 2],
    /// True x, y (mm).
    pub actual_mm: [f64; 2],
    /// In a hold (settle or an injected setpoint).
    pub hold: bool,
}

/// Commanded and actual tensions at one plant step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TensionPoint {
    /// s since the first setpoint.
    pub t_s: f64,
    /// Commanded (N).
    pub commanded: Vec<f64>,
    /// Actual (N).
    pub actual: Vec<f64>,
}

fn mm(v: Option<f64>) -> String {
    v.map_or_else(|| "– (no data)".into(), |x| format!("{x:.3}"))
}

fn us(v: &Option<Summary>, pick: fn(&Summary) -> f64) -> String {
    match v {
        Some(s) if s.count > 0 => format!("{:.1} ({} samples)", pick(s), s.count),
        _ => "– (no data)".into(),
    }
}

impl SimReport {
    /// Which of the planner's answers to the rod's mass and to its model's
    /// error were on, in words (`docs/design.md` §6.4, §6.5): the step
    /// shaping, the dynamic offset, the learning, the stiffness adaptation.
    pub fn dynamics_summary(&self) -> String {
        let shaping = match &self.step_shaping {
            Some(s) => format!("shaped for {:.2} Hz", s.mode_hz),
            None => "not shaped".into(),
        };
        let offset = if self.dynamic_offset {
            "offset"
        } else {
            "no offset"
        };
        let learning = match &self.learning {
            Some(l) => format!("learning to {:.1} Hz", l.harmonics() as f64 / l.period_s),
            None => "no learning".into(),
        };
        let stiffness = match self.stiffness_adapted {
            Some(k) => format!("stiffness κ̂ {k:+.3}"),
            None => "stiffness not adapted".into(),
        };
        let net = if self.net_error_offset {
            "net's error offset"
        } else {
            "no net's error offset"
        };
        let model = match &self.model_learning {
            Some(m) => format!("; learned on the model ({:.3} mm)", m.learned_pass_rms_mm),
            None => String::new(),
        };
        format!("{shaping}; {offset}; {net}; {learning}; {stiffness}{model}")
    }

    /// `report.md`: the headline numbers, each with what it covers.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# tendril sim report\n\n{}\n", self.label);
        if self.model.built_in {
            let _ = writeln!(
                s,
                "Net: the firmware's built-in net (`{}`).\n",
                self.model.path.display()
            );
        }
        if self.verdict.clean {
            s.push_str("Outcome: **clean**.\n\n");
        } else {
            s.push_str("Outcome: **failed**:\n\n");
            for p in &self.verdict.problems {
                let _ = writeln!(s, "- {p}");
            }
            s.push('\n');
        }
        s.push_str("| quantity | value |\n|---|---|\n");
        let mut row = |name: &str, value: String| {
            let _ = writeln!(s, "| {name} | {value} |");
        };
        row(
            "tracking samples (plant steps outside holds)",
            self.tracking_samples.to_string(),
        );
        if let Some([a, b]) = self.tracking_window_s {
            row("tracking window (s)", format!("{a:.2} – {b:.2}"));
        }
        if let Some(sh) = &self.step_shaping {
            row(
                "steps and the path's start shaped for the first mode (Hz, ζ; a step's length in s)",
                format!(
                    "{:.3}, {:.3}; {:.3}",
                    sh.mode_hz,
                    sh.damping_ratio,
                    sh.length_s()
                ),
            );
            row(
                "dynamic offset (the mode's inverse) sent",
                if self.dynamic_offset { "yes" } else { "no" }.into(),
            );
        }
        row(
            "the net's own error along the path sent as an offset (from the exact statics)",
            if self.net_error_offset { "yes" } else { "no" }.into(),
        );
        if let Some(l) = &self.learning {
            row(
                "learning for repeated paths: harmonics to (Hz); worst contraction a pass",
                format!(
                    "{:.2}; {:.2}",
                    l.harmonics() as f64 / l.period_s,
                    l.contraction
                ),
            );
            if let Some(t) = self.learning_stopped_at_s {
                row(
                    "learning stopped (the error grew) at (s)",
                    format!("{t:.2}"),
                );
            }
        }
        if let Some(m) = &self.model_learning {
            row(
                "the circle's offset learned on the model: the rehearsed pass unaided → learned (mm RMS); rehearsals; s",
                format!(
                    "{:.3} → {:.3}; {}; {:.0}{}",
                    m.unaided_pass_rms_mm,
                    m.learned_pass_rms_mm,
                    m.rehearsals,
                    m.seconds,
                    m.stopped
                        .as_ref()
                        .map_or(String::new(), |why| format!(" (stopped early: {why})"))
                ),
            );
            if let Some([before, after]) = m.start_window_rms_mm {
                row(
                    "the path's start learned on the model: its first seconds with the periodic offset alone → with the start's (mm RMS)",
                    format!("{before:.3} → {after:.3}"),
                );
            }
        }
        if let Some(k) = self.stiffness_adapted {
            row(
                "stiffness adaptation: κ̂ at the end (the backbone E × 1/(1 − κ̂) of its file's)",
                format!("{k:+.4} (× {:.3})", 1.0 / (1.0 - k)),
            );
        }
        if !self.pass_rms_mm.is_empty() {
            let passes: Vec<String> = self.pass_rms_mm.iter().map(|v| format!("{v:.3}")).collect();
            row(
                "RMS tracking error per period of the path (mm)",
                passes.join(", "),
            );
        }
        row("RMS tracking error (mm)", mm(self.rms_tracking_error_mm));
        row(
            "RMS path error: tracking less the delay along the path (mm)",
            mm(self.rms_path_error_mm),
        );
        row("max tracking error (mm)", mm(self.max_tracking_error_mm));
        row("p95 tracking error (mm)", mm(self.p95_tracking_error_mm));
        row(
            "max steady-state error (mm)",
            mm(self.max_steady_state_error_mm),
        );
        row(
            "RMS bound (mm)",
            match &self.max_rms_waived_because {
                None => format!("{:.3}", self.max_rms_mm),
                Some(why) => format!("{:.3} (not applied: {why})", self.max_rms_mm),
            },
        );
        let o = &self.oscillation;
        row(
            "oscillation",
            match (o.detected, o.frequency_hz, o.tone_rms_mm) {
                (true, Some(f), Some(r)) => format!(
                    "**yes**: {f:.2} Hz, {r:.3} mm RMS, in {} of {} windows above {:.2} Hz",
                    o.windows_with_tone, o.windows, o.band_from_hz
                ),
                _ => format!(
                    "no ({} of {} windows above {:.2} Hz hold a tone)",
                    o.windows_with_tone, o.windows, o.band_from_hz
                ),
            },
        );
        if let Some(g) = &self.growth {
            row(
                "tracking error RMS, first → last third of the run (mm)",
                format!(
                    "{:.3} → {:.3}{}",
                    g.first_third_rms_mm,
                    g.last_third_rms_mm,
                    if g.growing { " (**growing**)" } else { "" }
                ),
            );
        }
        if let Some(ms) = self.controller_cpu_steal_ms {
            row(
                "hypervisor steal on the controller's CPU (ms)",
                ms.to_string(),
            );
        }
        if let Some(p) = self.stall_shared_with_planner_periods.filter(|p| *p > 0.0) {
            row(
                "periods of the longest stall the planner (another CPU) stopped for too",
                format!("{p:.0}"),
            );
        }
        match &self.controller {
            Some(c) => {
                row("controller cycles", c.cycles.to_string());
                row("controller overruns", c.overruns.to_string());
                row(
                    "controller skipped periods (stalls, longest)",
                    format!("{} ({}, {})", c.skipped, c.stalls, c.longest_stall_periods),
                );
                if let Some(ms) = c.cpu_wait_ms {
                    row(
                        "controller waited for a CPU: ms (periods skipped for it)",
                        format!("{ms:.1} ({})", c.skipped_waiting_for_cpu),
                    );
                }
                row(
                    "watchdog trips (of which a late planner)",
                    format!("{} ({})", c.watchdog_trips, c.watchdog_trips_late_planner),
                );
                if c.stuck_motor_holds > 0 {
                    row("stuck-motor holds", c.stuck_motor_holds.to_string());
                }
                let lateness = Some(c.lateness_us);
                row("lateness p50 (µs)", us(&lateness, |s| s.p50));
                row("lateness p99 (µs)", us(&lateness, |s| s.p99));
                if let Some(l) = &c.link {
                    // The chip in the loop: its link and its own counts.
                    let (p50, p99) = l.setpoint_to_command_periods;
                    row(
                        "setpoint → command through the link (periods)",
                        format!("p50 {p50:.2}, p99 {p99:.2}"),
                    );
                    row(
                        "chip commands (lost on the link)",
                        format!("{} ({})", l.commands, l.commands_lost),
                    );
                    if let Some(t) = &l.chip {
                        row(
                            "chip periods (missed ticks)",
                            format!("{} ({})", t.counters.periods, t.counters.missed_ticks),
                        );
                        let f = &t.frames;
                        row(
                            "chip frames received (dropped: CRC, COBS, decode, oversized)",
                            format!(
                                "{} ({}, {}, {}, {})",
                                f.frames_ok,
                                f.crc_errors,
                                f.cobs_errors,
                                f.decode_errors,
                                f.oversized
                            ),
                        );
                    }
                    if l.garbage_bytes_sent > 0 {
                        row(
                            "garbage bytes injected on the link",
                            l.garbage_bytes_sent.to_string(),
                        );
                    }
                    row(
                        "bytes to / from the chip",
                        format!("{} / {}", l.bytes_down, l.bytes_up),
                    );
                }
            }
            None => row("controller statistics", "– (none written)".into()),
        }
        row("IPC latency p50 (µs)", us(&self.ipc_latency_us, |s| s.p50));
        row("IPC latency p99 (µs)", us(&self.ipc_latency_us, |s| s.p99));
        row("plant step median (µs)", us(&self.plant.step_us, |s| s.p50));
        row(
            "out-of-range commands at the plant",
            format!(
                "{} of {} checked",
                self.plant.out_of_range_commands, self.plant.commands_checked
            ),
        );
        if !self.steady_state.is_empty() {
            s.push_str(
                "\n## Steady state\n\n| from (s) | target x, y (mm) | error (mm) | samples | settled within 0.1 mm after (s) | ringing after (mm RMS) |\n|---|---|---|---|---|---|\n",
            );
            let opt =
                |v: Option<f64>, digits: usize| v.map_or("–".into(), |v| format!("{v:.digits$}"));
            for st in &self.steady_state {
                let _ = writeln!(
                    s,
                    "| {:.3} | {:.3}, {:.3} | {:.3} | {} | {} | {} |",
                    st.t_s,
                    st.target_mm[0],
                    st.target_mm[1],
                    st.error_mm,
                    st.samples,
                    opt(st.settle_s, 3),
                    opt(st.vibration_mm, 4)
                );
            }
        }
        s.push_str("\n## Processes\n\n| process | pid | started (s) | ended (s) | end |\n|---|---|---|---|---|\n");
        for p in &self.processes {
            let _ = writeln!(
                s,
                "| {} {} | {} | {:.3} | {} | {} |",
                p.role.name(),
                p.generation,
                p.pid,
                p.started_s,
                p.ended_s.map_or("–".into(), |t| format!("{t:.3}")),
                p.end.describe()
            );
        }
        if !self.faults.is_empty() {
            s.push_str(
                "\n## Injected faults\n\n| fault | at (s) | detected | latency (ms) | by | detail |\n|---|---|---|---|---|---|\n",
            );
            for f in &self.faults {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {} | {} |",
                    serde_json::to_value(f.kind)
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_string))
                        .unwrap_or_default(),
                    f.t_s.map_or("never".into(), |t| format!("{t:.3}")),
                    match f.detected {
                        Some(true) => "yes",
                        Some(false) => "**no**",
                        None => "n/a",
                    },
                    f.detection_latency_s
                        .map_or("–".into(), |t| format!("{:.1}", t * 1e3)),
                    f.detected_by.as_deref().unwrap_or("–"),
                    f.detail
                );
            }
        }
        s.push_str("\nFigure: `sim.png` (desired vs actual tip path, tensions over time).\n");
        s
    }
}
