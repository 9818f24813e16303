//! When a run did not keep real time: the controller's skipped periods,
//! overruns and stalls beyond what the machine took from it, and the chip's
//! link falling behind. Each is a problem of the run's verdict.

use crate::ipc::controller::ControllerStats;

/// Real-time bounds of a controller run, beyond what the machine took
/// from it (hypervisor steal on its CPU, and the periods it spent runnable
/// without a CPU): at most [`MAX_SKIPPED_FRACTION`] of its periods
/// skipped (the hardware-in-the-loop tests' bound), at most
/// [`MAX_OVERRUN_FRACTION`] overrun, no stall longer than
/// [`MAX_STALL_PERIODS`].
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
    steal_ms: Option<u64>,
) -> Vec<String> {
    let period_ms = 1e3 / rate_hz.max(1.0);
    let stolen = steal_ms.map_or(0.0, |ms| ms as f64 / period_ms);
    let excused = stolen + c.skipped_waiting_for_cpu as f64;
    let took = format!(
        "the machine took {stolen:.0} periods (hypervisor) and {} (waiting for a CPU)",
        c.skipped_waiting_for_cpu
    );
    let cycles = c.cycles as f64;
    let mut out = Vec::new();
    if c.skipped as f64 > MAX_SKIPPED_FRACTION * cycles + excused {
        out.push(format!(
            "real time missed: the controller skipped {} of {} periods in {} stalls (bound 2 %); \
             {took}",
            c.skipped, c.cycles, c.stalls
        ));
    }
    if c.overruns as f64 > MAX_OVERRUN_FRACTION * cycles + excused {
        out.push(format!(
            "real time missed: {} of {} periods overran (bound 5 %); {took}",
            c.overruns, c.cycles
        ));
    }
    if c.longest_stall_periods > MAX_STALL_PERIODS && (c.longest_stall_periods as f64) > excused {
        out.push(format!(
            "real time missed: the controller stalled for {} periods at once (bound \
             {MAX_STALL_PERIODS}); {took}",
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

    #[test]
    fn misses_beyond_the_bounds_make_problems_unless_the_machine_took_them() {
        // The careless user's run: 567 overruns, 115 skipped, a 53-period stall.
        let c = stats(7000, 115, 567, 53);
        let found = real_time_problems(&c, 1000.0, Some(0));
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(found
            .iter()
            .any(|p| p.contains("567 of 7000 periods overran")));
        assert!(found.iter().any(|p| p.contains("53 periods at once")));
        // The same, with 600 ms stolen by the hypervisor: the machine's.
        assert!(real_time_problems(&c, 1000.0, Some(600)).is_empty());
        // Skipping 3 % of the periods.
        let skipped = real_time_problems(&stats(7000, 210, 10, 5), 1000.0, None);
        assert_eq!(skipped.len(), 1, "{skipped:?}");
        assert!(skipped[0].contains("skipped 210 of 7000"));
        assert!(real_time_problems(&stats(7000, 100, 10, 5), 1000.0, None).is_empty());
    }
}
