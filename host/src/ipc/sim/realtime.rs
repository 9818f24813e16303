//! When a run did not keep real time: the controller's skipped periods,
//! overruns and stalls beyond what the machine took from it, and the chip's
//! link falling behind. Each is a problem of the run's verdict.

use super::analysis::{ControllerRow, Logs, SetpointRow};
use crate::ipc::controller::ControllerStats;

/// What the sim knows of the machine under a run.
#[derive(Clone, Copy, Debug, Default)]
pub struct MachineTook {
    /// Hypervisor steal on the controller's CPU over the run, ms (None:
    /// the kernel does not say).
    pub steal_ms: Option<u64>,
    /// The planner ran pinned to another CPU than the controller's
    /// ([`stall_shared_with_planner`] applies).
    pub planner_on_another_cpu: bool,
    /// Periods of the controller's longest stall the planner on another CPU
    /// stopped for too ([`MachineTook::with_shared_stall`]); None until
    /// counted, or when the planner shared the controller's CPU.
    pub shared_stall_periods: Option<f64>,
}

impl MachineTook {
    /// This, with [`stall_shared_with_planner`] counted from the run's
    /// `logs` at the controller's `rate_hz` when the planner ran on another
    /// CPU.
    pub(super) fn with_shared_stall(self, logs: &Logs, rate_hz: f64) -> MachineTook {
        let period_ns = 1e9 / rate_hz.max(1.0);
        MachineTook {
            shared_stall_periods: self
                .planner_on_another_cpu
                .then(|| stall_shared_with_planner(&logs.controller, &logs.setpoints, period_ns)),
            ..self
        }
    }
}

/// How many periods of the controller's longest stall (the longest gap
/// between its logged periods) the machine took, as the planner, running
/// on another CPU, shows: none if the planner ticked on; all of them if
/// its ticks stopped for at least half the stall within one planner
/// generation (a killed planner's silence is not a stall). Only
/// meaningful when the planner runs on another CPU: nothing the
/// controller's CPU does can hold it there, and both stopping at once is a
/// pause of the whole machine, which the hypervisor's steal count does not
/// always show and whose CPUs resume a few milliseconds apart (2026-12-07:
/// the controller's and the plant's CPU stopped for 38 ms, the planner's
/// for 32 ms of them, 1.7 ms apart, with 3 ms of steal on record; twice in
/// CI rehearsals a 59–70-period stall failed a test with 10–14 periods
/// accounted for). Less than half is only the overlap, less the planner's
/// own period.
pub fn stall_shared_with_planner(
    controller: &[ControllerRow],
    setpoints: &[SetpointRow],
    controller_period_ns: f64,
) -> f64 {
    let gap = |a: f64, b: f64| b - a;
    let Some((from, to)) = controller
        .windows(2)
        .map(|w| (w[0].t_ns, w[1].t_ns))
        .max_by(|x, y| gap(x.0, x.1).total_cmp(&gap(y.0, y.1)))
    else {
        return 0.0;
    };
    let same_generation = |w: &&[SetpointRow]| w[0].generation == w[1].generation;
    let mut spacings: Vec<f64> = setpoints
        .windows(2)
        .filter(same_generation)
        .map(|w| gap(w[0].t_ns, w[1].t_ns))
        .collect();
    if spacings.is_empty() || controller_period_ns.is_nan() || controller_period_ns <= 0.0 {
        return 0.0;
    }
    let mid = spacings.len() / 2;
    let planner_period = *spacings.select_nth_unstable_by(mid, f64::total_cmp).1;
    let overlap = setpoints
        .windows(2)
        .filter(same_generation)
        .map(|w| (w[1].t_ns.min(to) - w[0].t_ns.max(from)).max(0.0))
        .fold(0.0, f64::max);
    let stall = gap(from, to);
    if overlap >= 0.5 * stall {
        (stall / controller_period_ns - 1.0).max(0.0)
    } else {
        ((overlap - planner_period) / controller_period_ns).max(0.0)
    }
}

/// Real-time bounds of a controller run, beyond what the machine took
/// from it (hypervisor steal on its CPU, and the periods it spent runnable
/// without a CPU): at most [`MAX_SKIPPED_FRACTION`] of its periods
/// skipped (the hardware-in-the-loop tests' bound), at most
/// [`MAX_OVERRUN_FRACTION`] overrun, no stall longer than
/// [`MAX_STALL_PERIODS`] (beyond, too, the periods of it the
/// planner on another CPU stopped for: [`MachineTook::shared_stall_periods`]).
pub const MAX_SKIPPED_FRACTION: f64 = 0.02;
/// See [`MAX_SKIPPED_FRACTION`].
pub const MAX_OVERRUN_FRACTION: f64 = 0.05;
/// See [`MAX_SKIPPED_FRACTION`]: 50 ms without a command at 1 kHz, two
/// and a half motor time constants.
pub const MAX_STALL_PERIODS: u64 = 50;

/// The ways the controller missed real time (see [`MAX_SKIPPED_FRACTION`]).
pub(super) fn real_time_problems(
    c: &ControllerStats,
    rate_hz: f64,
    machine: MachineTook,
) -> Vec<String> {
    let period_ms = 1e3 / rate_hz.max(1.0);
    let stolen = machine.steal_ms.map_or(0.0, |ms| ms as f64 / period_ms);
    let shared = machine.shared_stall_periods.unwrap_or(0.0);
    let excused = stolen + c.skipped_waiting_for_cpu as f64;
    let took_text = format!(
        "the machine took {stolen:.0} periods (hypervisor) and {} (waiting for a CPU)",
        c.skipped_waiting_for_cpu
    );
    let cycles = c.cycles as f64;
    let mut out = Vec::new();
    if c.skipped as f64 > MAX_SKIPPED_FRACTION * cycles + excused {
        out.push(format!(
            "real time missed: the controller skipped {} of {} periods in {} stalls (bound 2 %); \
             {took_text}",
            c.skipped, c.cycles, c.stalls
        ));
    }
    if c.overruns as f64 > MAX_OVERRUN_FRACTION * cycles + excused {
        out.push(format!(
            "real time missed: {} of {} periods overran (bound 5 %); {took_text}",
            c.overruns, c.cycles
        ));
    }
    if c.longest_stall_periods > MAX_STALL_PERIODS
        && (c.longest_stall_periods as f64) > excused + shared
    {
        out.push(format!(
            "real time missed: the controller stalled for {} periods at once (bound \
             {MAX_STALL_PERIODS}); {took_text}; the planner on another CPU stopped for {shared:.0} \
             of them",
            c.longest_stall_periods
        ));
    }
    out
}

/// What says the chip's link could not carry the loop: commands lost,
/// periods the chip missed, or setpoints waiting more than
/// [`LINK_P99_MAX_PERIODS`] for their command (a rate the link cannot
/// carry: the frames queue up).
pub(super) fn link_problems(link: &crate::mcu::bridge::LinkStats) -> Vec<String> {
    let mut out = Vec::new();
    if link.commands_lost > 0 {
        out.push(format!(
            "{} of the chip's commands were lost on the link",
            link.commands_lost
        ));
    }
    if let Some(t) = &link.chip {
        if t.counters.missed_ticks > 0 {
            out.push(format!(
                "the chip missed {} periods",
                t.counters.missed_ticks
            ));
        }
    }
    let p99 = link.setpoint_to_command_periods.1;
    if p99 > LINK_P99_MAX_PERIODS {
        out.push(format!(
            "setpoints waited up to {p99:.1} periods (p99) for the chip's command: the link \
             cannot carry this rate (lower --rate; docs/design.md §5.6)"
        ));
    }
    out
}

/// See [`link_problems`]: 2 periods is the target, a swap over the link
/// may take one more; beyond 5 the link is saturated.
pub const LINK_P99_MAX_PERIODS: f64 = 5.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(cycles: u64, skipped: u64, overruns: u64, longest: u64) -> ControllerStats {
        ControllerStats {
            cycles,
            skipped,
            overruns,
            stalls: 3,
            longest_stall_periods: longest,
            ..ControllerStats::default()
        }
    }

    fn took(steal_ms: Option<u64>, shared: f64) -> MachineTook {
        MachineTook {
            steal_ms,
            planner_on_another_cpu: true,
            shared_stall_periods: Some(shared),
        }
    }

    #[test]
    fn misses_beyond_the_bounds_make_problems_unless_the_machine_took_them() {
        // The careless user's run: 567 overruns, 115 skipped, a 53-period stall.
        let c = stats(7000, 115, 567, 53);
        let found = real_time_problems(&c, 1000.0, took(Some(0), 0.0));
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(found
            .iter()
            .any(|p| p.contains("567 of 7000 periods overran")));
        assert!(found.iter().any(|p| p.contains("53 periods at once")));
        // The same, with 600 ms stolen by the hypervisor: the machine's.
        assert!(real_time_problems(&c, 1000.0, took(Some(600), 0.0)).is_empty());
        // Skipping 3 % of the periods.
        let skipped = real_time_problems(&stats(7000, 210, 10, 5), 1000.0, took(None, 0.0));
        assert_eq!(skipped.len(), 1, "{skipped:?}");
        assert!(skipped[0].contains("skipped 210 of 7000"));
        assert!(real_time_problems(&stats(7000, 100, 10, 5), 1000.0, took(None, 0.0)).is_empty());
        // The 53-period stall, all of it shared by the planner on another
        // CPU: the machine's; 2 periods shared: still the controller's.
        let c = stats(7000, 60, 10, 53);
        assert!(real_time_problems(&c, 1000.0, took(Some(0), 53.0)).is_empty());
        let found = real_time_problems(&c, 1000.0, took(Some(0), 2.0));
        assert!(
            found.iter().any(|p| p.contains("53 periods at once")),
            "{found:?}"
        );
    }

    /// Rows every `period_ms` from 0 to `end_ms`, but none strictly inside
    /// the gaps (ms), in `generation`s switching at `switch_ms`.
    fn ticks(period_ms: f64, end_ms: f64, gaps: &[(f64, f64)], switch_ms: f64) -> Vec<f64> {
        let n = (end_ms / period_ms) as usize;
        (0..=n)
            .map(|k| k as f64 * period_ms)
            .filter(|t| !gaps.iter().any(|&(a, b)| *t > a && *t < b))
            .filter(|t| (*t - switch_ms).abs() > 1e-9 || switch_ms.is_infinite())
            .collect()
    }

    fn controller_rows(ms: &[f64]) -> Vec<ControllerRow> {
        ms.iter()
            .map(|&t| ControllerRow {
                t_ns: t * 1e6,
                status: 0,
                setpoint_seq: 0.0,
                state_seq: 0.0,
            })
            .collect()
    }

    fn setpoint_rows(ms: &[f64], switch_ms: f64) -> Vec<SetpointRow> {
        ms.iter()
            .map(|&t| SetpointRow {
                t_ns: t * 1e6,
                flags: 0,
                position: [0.0; 3],
                generation: usize::from(t > switch_ms),
                stiffness: f64::NAN,
            })
            .collect()
    }

    #[test]
    fn a_stall_the_planner_shared_is_counted_and_one_it_did_not_is_not() {
        // The controller at 1 kHz stops from 100 to 160 ms (59 periods
        // skipped).
        let controller = controller_rows(&ticks(1.0, 400.0, &[(100.0, 160.0)], f64::INFINITY));
        let period_ns = 1e6;
        // The planner stops from 103 to 158 ms, most of the stall: all 59
        // skipped periods are the machine's.
        let planner = ticks(1.0, 400.0, &[(103.0, 158.0)], f64::INFINITY);
        let shared = stall_shared_with_planner(
            &controller,
            &setpoint_rows(&planner, f64::INFINITY),
            period_ns,
        );
        assert!((shared - 59.0).abs() < 1e-9, "shared {shared}");
        // From 130 to 150 ms, a third of it: only those 20 ms, less the
        // planner's 1 ms period.
        let planner = ticks(1.0, 400.0, &[(130.0, 150.0)], f64::INFINITY);
        let shared = stall_shared_with_planner(
            &controller,
            &setpoint_rows(&planner, f64::INFINITY),
            period_ns,
        );
        assert!((shared - 19.0).abs() < 1e-9, "shared {shared}");
        // A planner that ticked on: nothing shared.
        let on = ticks(1.0, 400.0, &[], f64::INFINITY);
        let shared =
            stall_shared_with_planner(&controller, &setpoint_rows(&on, f64::INFINITY), period_ns);
        assert_eq!(shared, 0.0);
        // A planner killed at 90 ms and restarted at 170 ms: its silence is
        // between generations, not a stall.
        let killed = ticks(1.0, 400.0, &[(90.0, 170.0)], f64::INFINITY);
        let shared =
            stall_shared_with_planner(&controller, &setpoint_rows(&killed, 130.0), period_ns);
        assert_eq!(shared, 0.0);
        // No rows: nothing shared.
        assert_eq!(stall_shared_with_planner(&[], &[], period_ns), 0.0);
    }
}
