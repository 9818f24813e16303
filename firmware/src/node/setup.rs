//! The link's `Setup` and the period's configuration, both ways
//! ([`period_config`] validates a Setup into a [`PeriodConfig`];
//! [`setup_of`] flattens one for the link), and why a Setup is refused.

use tendril_shared::link::wire::Setup;
use tendril_shared::{CoContraction, TendonLimits, MAX_TENDONS};

use crate::control::{ControlConfig, IntegralConfig, SafeHold};
use crate::period::{PeriodConfig, StuckConfig};

/// Why a Setup was refused
/// ([`Hello::setup_error`](tendril_shared::link::wire::Hello::setup_error)).
pub mod setup_error {
    /// Tendon count 0 or above the capacity.
    pub const TENDONS: u8 = 1;
    /// The tension limits do not validate (floors above ceilings, NaN…).
    pub const LIMITS: u8 = 2;
    /// The co-contraction sets do not validate.
    pub const COCONTRACTION: u8 = 3;
    /// A time or gain out of range (zero period, negative gain, NaN).
    pub const TIMING: u8 = 4;
}

/// Commands the plant may be behind over the link without it being a fault
/// ([`PeriodConfig::commands_in_flight`]). A command reaches the plant
/// through the bridge, and the plant's state comes back the same way, at
/// most every ¾ period: the round trip can exceed the period, and then
/// the state shows the command before last. Measured on the default
/// robot's 10 s circle at 100 Hz: 174 of 1,217 periods were one behind,
/// none more.
pub const LINK_COMMANDS_IN_FLIGHT: u8 = 1;

/// The first `n` entries.
fn first(a: &[f32; MAX_TENDONS], n: usize) -> &[f32] {
    a.get(..n).unwrap_or(&[])
}

/// The period's configuration from a Setup, validated.
pub fn period_config(s: &Setup) -> Result<PeriodConfig, u8> {
    config_with(s, limits_of(s)?)
}

/// [`period_config`] in two steps, each not inlined, so that the stack of
/// one is free before the other runs (the node's Setup is the chip's
/// deepest stack after the period's: tests/tests/mcu_budget.rs): the tension
/// limits, then the rest with them.
#[inline(never)]
pub(super) fn config_with(s: &Setup, limits: TendonLimits) -> Result<PeriodConfig, u8> {
    let finite_pos = |v: f32| v.is_finite() && v >= 0.0;
    let times_ok = s.period_ns > 0 && s.watchdog_ns > 0 && s.max_dt_ns > 0;
    let gains_ok = [
        s.quaternion_tolerance,
        s.box_margin,
        s.ki,
        s.correction_limit,
        s.lead_s,
        s.stuck_model_gain,
        s.stuck_error_n,
        s.correction_filter_tau_s,
        s.correction_map_gain,
        s.correction_map_limit,
    ]
    .into_iter()
    .all(finite_pos)
        && (finite_pos(s.correction_window) || s.correction_window == f32::INFINITY);
    let map_ok = s.correction_map_scale.is_finite()
        && s.correction_map_scale > 0.0
        && s.jump_m.is_finite()
        && s.jump_m > 0.0;
    if !times_ok || !gains_ok || !map_ok {
        return Err(setup_error::TIMING);
    }
    // One literal, built where the caller wants it: a `ControlConfig`
    // built first and then moved in was a copy (264 B) on the stack.
    Ok(PeriodConfig {
        control: ControlConfig {
            limits,
            watchdog_ns: u64::from(s.watchdog_ns),
            max_dt_ns: u64::from(s.max_dt_ns),
            quaternion_tolerance: s.quaternion_tolerance,
            box_margin: s.box_margin,
            safe_hold: SafeHold::Freeze,
            integral: if s.ki > 0.0 {
                IntegralConfig {
                    ki: s.ki,
                    limit: s.correction_limit,
                    feedback_timeout_ns: u64::from(s.feedback_timeout_ns),
                    window: s.correction_window,
                    filter_tau_s: s.correction_filter_tau_s,
                    map_gain: s.correction_map_gain,
                    map_scale: s.correction_map_scale,
                    map_limit: s.correction_map_limit,
                }
            } else {
                IntegralConfig::OFF
            },
        },
        period_ns: u64::from(s.period_ns),
        lead_s: s.lead_s,
        plant_stale_ns: u64::from(s.plant_stale_ns),
        stuck: if s.stuck_enabled {
            StuckConfig {
                enabled: true,
                model_gain: s.stuck_model_gain,
                tension_error_n: s.stuck_error_n,
                persist_ns: u64::from(s.stuck_persist_ns),
            }
        } else {
            StuckConfig::OFF
        },
        swap_slice_bytes: crate::SWAP_SLICE_BYTES,
        jump_m: s.jump_m,
        settle_after_jump_ns: u64::from(s.settle_after_jump_ns),
        commands_in_flight: LINK_COMMANDS_IN_FLIGHT,
    })
}

/// The tension limits of a Setup, validated (the first step of
/// [`period_config`]).
#[inline(never)]
pub(super) fn limits_of(s: &Setup) -> Result<TendonLimits, u8> {
    let n = usize::from(s.n_tendons);
    if n == 0 || n > MAX_TENDONS {
        return Err(setup_error::TENDONS);
    }
    // No sets: every tendon outside one (NONE), or the all-zero arrays of
    // a setup that never filled them (a set member has a weight > 0). Set 0
    // is a set: testing `c != 0` lost a robot's only set on the link.
    let in_a_set = s
        .cocontraction_sets
        .iter()
        .zip(&s.cocontraction_weights)
        .take(n)
        .any(|(&c, &w)| c != CoContraction::NONE && w != 0.0);
    let sets = in_a_set.then(|| {
        CoContraction::new(
            s.cocontraction_sets.get(..n).unwrap_or(&[]),
            s.cocontraction_weights.get(..n).unwrap_or(&[]),
        )
    });
    // One chain (the limits' errors first, as they were): separate steps
    // kept a copy (160 B) of the limits per step on the stack.
    TendonLimits::new(first(&s.max_tension, n), first(&s.slew_rate, n))
        .and_then(|l| l.with_min_tension(first(&s.min_tension, n)))
        .map_err(|_| setup_error::LIMITS)
        .and_then(|l| match sets {
            None => Ok(l),
            Some(sets) => sets
                .and_then(|sets| l.with_cocontraction(sets))
                .map_err(|_| setup_error::COCONTRACTION),
        })
}

/// The link's `Setup` for a period configuration: [`period_config`]'s
/// inverse, beside it (the host's bridge and the budget image use it;
/// round trip: `node::tests`). Times above u32::MAX ns are clamped to it.
pub fn setup_of(p: &PeriodConfig) -> Setup {
    let l = &p.control.limits;
    let n = l.n_tendons();
    let pad = |a: &[f32]| {
        let mut out = [0.0f32; MAX_TENDONS];
        for (d, v) in out.iter_mut().zip(a) {
            *d = *v;
        }
        out
    };
    let mut sets = [0u8; MAX_TENDONS];
    for (d, c) in sets.iter_mut().zip(l.cocontraction().sets()).take(n) {
        *d = *c;
    }
    let ns = |v: u64| v.min(u64::from(u32::MAX)) as u32;
    let ic = p.control.integral;
    Setup {
        n_tendons: n as u8,
        max_tension: pad(l.max_tension()),
        min_tension: pad(l.min_tension()),
        slew_rate: pad(l.slew_rate()),
        cocontraction_sets: sets,
        cocontraction_weights: *l.cocontraction().weights(),
        period_ns: ns(p.period_ns),
        watchdog_ns: ns(p.control.watchdog_ns),
        max_dt_ns: ns(p.control.max_dt_ns),
        quaternion_tolerance: p.control.quaternion_tolerance,
        box_margin: p.control.box_margin,
        ki: ic.ki,
        correction_limit: ic.limit,
        feedback_timeout_ns: ns(ic.feedback_timeout_ns),
        correction_window: ic.window,
        correction_filter_tau_s: ic.filter_tau_s,
        correction_map_gain: ic.map_gain,
        correction_map_scale: ic.map_scale,
        correction_map_limit: ic.map_limit,
        jump_m: p.jump_m,
        settle_after_jump_ns: ns(p.settle_after_jump_ns),
        lead_s: p.lead_s,
        plant_stale_ns: ns(p.plant_stale_ns),
        stuck_enabled: p.stuck.enabled,
        stuck_model_gain: p.stuck.model_gain,
        stuck_error_n: p.stuck.tension_error_n,
        stuck_persist_ns: ns(p.stuck.persist_ns),
    }
}
