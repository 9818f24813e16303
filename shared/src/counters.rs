//! What the firmware's control period has counted since it was configured:
//! the numbers the host's report and the chip's telemetry both carry.

use serde::{Deserialize, Serialize};

/// Counts kept by the firmware's `period::Period`, all since configuration. `u32`: at
/// 1 kHz they wrap after 49 days (a controller is reconfigured long before;
/// wrapping is harmless, they are statistics).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counters {
    /// Periods run.
    pub periods: u32,
    /// Ticks missed before a period (the previous one overran).
    pub missed_ticks: u32,
    /// Setpoints taken (the newest of each period's arrivals).
    pub setpoints: u32,
    /// Setpoints lost in sequence gaps.
    pub setpoints_lost: u32,
    /// Setpoint sequences that restarted (a new planner).
    pub planner_restarts: u32,
    /// Plant-state sequences that restarted (a new plant).
    pub plant_restarts: u32,
    /// Plant states lost in sequence gaps.
    pub plant_states_lost: u32,
    /// Plant states back after a stale gap.
    pub plant_recoveries: u32,
    /// Periods with no plant state for the stale time.
    pub plant_stale_periods: u32,
    /// Plant states that had not applied the previous command.
    pub commands_not_applied: u32,
    /// Setpoints rejected for NaN/∞.
    pub rejected_nonfinite: u32,
    /// Setpoints rejected for a non-unit quaternion.
    pub rejected_quaternion: u32,
    /// Periods whose setpoint lay outside the workspace (target held).
    pub rejected_workspace: u32,
    /// Watchdog trips (safe holds entered for silence).
    pub watchdog_trips: u32,
    /// Watchdog holds that ended with the next setpoint in sequence (a late
    /// planner, not a lost one).
    pub watchdog_trips_late_planner: u32,
    /// Stuck-motor holds entered.
    pub stuck_motor_holds: u32,
    /// Periods in a safe hold after tracking began.
    pub hold_periods: u32,
    /// Periods before the first setpoint.
    pub startup_hold_periods: u32,
    /// Periods with a tension at its range or slew limit.
    pub saturated_periods: u32,
    /// Periods with the integral correction active.
    pub correction_periods: u32,
    /// Nets swapped in.
    pub weight_swaps: u32,
    /// Weight updates rejected (the old net kept).
    pub weight_rejections: u32,
}

impl Counters {
    /// All zero, as a constant (`Default` is not `const`): for a period
    /// that is a constant before it is configured.
    pub const ZERO: Counters = Counters {
        periods: 0,
        missed_ticks: 0,
        setpoints: 0,
        setpoints_lost: 0,
        planner_restarts: 0,
        plant_restarts: 0,
        plant_states_lost: 0,
        plant_recoveries: 0,
        plant_stale_periods: 0,
        commands_not_applied: 0,
        rejected_nonfinite: 0,
        rejected_quaternion: 0,
        rejected_workspace: 0,
        watchdog_trips: 0,
        watchdog_trips_late_planner: 0,
        stuck_motor_holds: 0,
        hold_periods: 0,
        startup_hold_periods: 0,
        saturated_periods: 0,
        correction_periods: 0,
        weight_swaps: 0,
        weight_rejections: 0,
    };
}
