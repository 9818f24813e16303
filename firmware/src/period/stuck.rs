//! Stuck-motor detection: the measured tensions against a model of healthy
//! motors driven by the commands sent (moved here from the host controller,
//! so the chip and the host run the one detector).

use tendril_shared::MAX_TENDONS;

/// When a motor counts as stuck: its measured tension leaves the tension a
/// healthy motor would have (the command through a first-order lag of the
/// motor's time constant) by more than `tension_error_n` for `persist_ns`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StuckConfig {
    /// Detect at all.
    pub enabled: bool,
    /// `1 − exp(−T/τ)`: the healthy-motor model's step per period (T the
    /// period, τ the motor's time constant; computed by whoever builds the
    /// configuration, so the chip needs no `exp`).
    pub model_gain: f32,
    /// Measured − expected tension that counts as a fault, N.
    pub tension_error_n: f32,
    /// How long the error must last, ns.
    pub persist_ns: u64,
}

impl StuckConfig {
    /// Detection off.
    pub const OFF: StuckConfig = StuckConfig {
        enabled: false,
        model_gain: 1.0,
        tension_error_n: f32::INFINITY,
        persist_ns: u64::MAX,
    };

    /// Detection for motors of time constant `tau_s` in a loop of period
    /// `period_ns` (`libm::expf`: the same bits on the chip and the host).
    pub fn new(tau_s: f32, tension_error_n: f32, persist_s: f32, period_ns: u64) -> StuckConfig {
        let period_s = period_ns as f32 * 1e-9;
        StuckConfig {
            enabled: true,
            model_gain: 1.0 - libm::expf(-period_s / tau_s.max(1e-6)),
            tension_error_n,
            persist_ns: (persist_s.max(0.0) * 1e9) as u64,
        }
    }
}

/// The detector's memory.
#[derive(Clone, Copy, Debug)]
pub(crate) struct StuckDetector {
    expected: [f32; MAX_TENDONS],
    /// Since when each tendon's error has been over the limit, ns; valid
    /// where its bit of `over` is set. (A bit set and a plain `u64`, not an
    /// `[Option<u64>; _]`: 72 B less of the chip's RAM.)
    over_since: [u64; MAX_TENDONS],
    over: u16,
    synced: bool,
}

const _: () = assert!(MAX_TENDONS <= 16, "one bit of `over` per tendon");

impl StuckDetector {
    pub(crate) const fn new() -> StuckDetector {
        StuckDetector {
            expected: [0.0; MAX_TENDONS],
            over_since: [0; MAX_TENDONS],
            over: 0,
            synced: false,
        }
    }

    /// Forget the model (a new plant, or one back after a gap): the next
    /// measurement becomes the model's state.
    pub(crate) fn resync(&mut self) {
        self.synced = false;
        self.over = 0;
    }

    /// One fresh measurement at `now_ns` after `sent` was applied for about a
    /// period. Returns a stuck tendon and its tension error, if any.
    pub(crate) fn check(
        &mut self,
        cfg: &StuckConfig,
        now_ns: u64,
        sent: &[f32; MAX_TENDONS],
        measured: &[f32; MAX_TENDONS],
        n: usize,
    ) -> Option<(usize, f32)> {
        if !cfg.enabled {
            return None;
        }
        if !self.synced {
            self.expected = *measured;
            self.synced = true;
            return None;
        }
        let mut stuck = None;
        for (i, ((e, (&c, &m)), since)) in self
            .expected
            .iter_mut()
            .zip(sent.iter().zip(measured))
            .zip(&mut self.over_since)
            .enumerate()
            .take(n)
        {
            *e += (c - *e) * cfg.model_gain;
            let err = m - *e;
            // i < MAX_TENDONS ≤ 16 (the zip): the shift never wraps.
            let bit = 1u16.wrapping_shl(i as u32);
            if err.is_finite() && err.abs() <= cfg.tension_error_n {
                self.over &= !bit;
                continue;
            }
            if self.over & bit == 0 {
                self.over |= bit;
                *since = now_ns;
            }
            let from = *since;
            if now_ns.saturating_sub(from) >= cfg.persist_ns && stuck.is_none() {
                stuck = Some((i, err));
            }
        }
        stuck
    }
}
