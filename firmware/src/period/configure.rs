//! Configuring a [`Period`]: built once ([`Period::new`]), or configured
//! again and restarted in place ([`Period::reconfigure`],
//! [`Period::restart`], [`Period::configure`]).
//!
//! In place because of the chip's stack: a `Period` is 1.2 KB, and one
//! built by value is built on the stack before it is moved into the node's
//! `static` (2.2 KB of stack under a Setup, measured by tests/tests/
//! mcu_budget.rs). Every way in goes through [`Period::restart`], the one
//! list of what a fresh period holds.

use tendril_shared::{TendonLimits, MAX_TENDONS};

use super::{Counters, Period, PeriodCommand, PeriodConfig, StuckConfig};
use crate::control::{ControlConfig, ControlState};
use crate::period::stuck::StuckDetector;

/// A period before any configuration: valid, never run. What a period is
/// configured from, in place ([`Period::configure`]); a constant, so it is
/// copied from flash, never built on the stack.
const UNCONFIGURED: Period = Period {
    cfg: PeriodConfig {
        control: ControlConfig::new(TendonLimits::UNCONFIGURED),
        period_ns: 1_000_000,
        lead_s: 0.0,
        plant_stale_ns: 0,
        stuck: StuckConfig::OFF,
        swap_slice_bytes: crate::SWAP_SLICE_BYTES,
        jump_m: 0.0,
        settle_after_jump_ns: 0,
        commands_in_flight: 0,
    },
    n: 0,
    state: ControlState::holding([0.0; MAX_TENDONS], 0),
    stuck: StuckDetector::new(),
    counters: Counters::ZERO,
    cmd: PeriodCommand {
        seq: 0,
        setpoint_seq: 0,
        feedback_seq: 0,
        tensions: [0.0; MAX_TENDONS],
        count: 0,
        status: 0,
    },
    last_sp: None,
    last_fb_seq: None,
    last_tip: None,
    last_sp_position: None,
    quiet_until_ns: 0,
    local_sp_seq: 0,
    local_fb_seq: 0,
    last_feedback_ns: 0,
    last_setpoint_ns: 0,
    stale: false,
    in_hold: false,
    outside: false,
    tracking_started: false,
    stuck_hold: false,
    hold_after_seq: None,
    last_sp_gap: 0,
};

impl Period {
    /// Configure at time `now_ns`, holding the tension floors until the
    /// first setpoint.
    pub fn new(cfg: PeriodConfig, now_ns: u64) -> Self {
        let mut period = UNCONFIGURED;
        period.reconfigure(&cfg, now_ns);
        period
    }

    /// `slot`'s period configured with `cfg` at `now_ns`, in place (the
    /// first configuration too): what [`Period::new`] gives, without a
    /// `Period` on the stack.
    pub fn configure<'a>(
        slot: &'a mut Option<Period>,
        cfg: &PeriodConfig,
        now_ns: u64,
    ) -> &'a mut Period {
        let period = slot.get_or_insert(UNCONFIGURED);
        period.reconfigure(cfg, now_ns);
        period
    }

    /// Configure again with `cfg` at `now_ns`, in place: as [`Period::new`].
    // Not inlined: its temporaries then take no stack in the frame that
    // validated the configuration (a Setup's, on the chip).
    #[inline(never)]
    pub fn reconfigure(&mut self, cfg: &PeriodConfig, now_ns: u64) {
        self.cfg = *cfg;
        self.restart(now_ns);
    }

    /// Start afresh at `now_ns` with the same configuration, in place:
    /// the counters, the command, the sequences, the holds and the
    /// control state are those of [`Period::new`].
    pub fn restart(&mut self, now_ns: u64) {
        // Every field by name (no `..`): a field added later and not reset
        // here does not compile.
        let Period {
            cfg,
            n,
            state,
            stuck,
            counters,
            cmd,
            last_sp,
            last_fb_seq,
            last_tip,
            last_sp_position,
            quiet_until_ns,
            local_sp_seq,
            local_fb_seq,
            last_feedback_ns,
            last_setpoint_ns,
            stale,
            in_hold,
            outside,
            tracking_started,
            stuck_hold,
            hold_after_seq,
            last_sp_gap,
        } = self;
        *n = cfg.control.limits.n_tendons();
        // The floors until the first setpoint.
        *state = ControlState::new(&cfg.control.limits, &[0.0; MAX_TENDONS], now_ns);
        *stuck = StuckDetector::new();
        *counters = Counters::ZERO;
        *cmd = PeriodCommand {
            seq: 0,
            setpoint_seq: 0,
            feedback_seq: 0,
            tensions: state.command,
            count: *n,
            status: 0,
        };
        *last_sp = None;
        *last_fb_seq = None;
        *last_tip = None;
        *last_sp_position = None;
        *quiet_until_ns = 0;
        *local_sp_seq = 0;
        *local_fb_seq = 0;
        *last_feedback_ns = now_ns;
        *last_setpoint_ns = now_ns;
        *stale = false;
        *in_hold = false;
        *outside = false;
        *tracking_started = false;
        *stuck_hold = false;
        *hold_after_seq = None;
        *last_sp_gap = 0;
    }
}
