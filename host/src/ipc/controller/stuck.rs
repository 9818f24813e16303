//! Stuck-motor detection: measured tensions against a model of healthy
//! motors driven by the commands sent.

use super::*;

/// Stuck-motor detector: a first-order model of each healthy motor driven
/// by the commands sent, compared with the measured tensions.
#[derive(Clone, Copy, Debug)]
pub(super) struct StuckDetector {
    cfg: StuckMotorDetection,
    /// 1 − exp(−T/τ): the model's step per period.
    gain: f32,
    expected: [f32; MAX_TENDONS],
    over_since: [Option<u64>; MAX_TENDONS],
    synced: bool,
}

impl StuckDetector {
    pub(super) fn new(cfg: StuckMotorDetection, period_ns: u64) -> StuckDetector {
        let tau = cfg.motor_tau_s.max(1e-6);
        StuckDetector {
            cfg,
            gain: (1.0 - (-(period_ns as f64 * 1e-9) / tau).exp()) as f32,
            expected: [0.0; MAX_TENDONS],
            over_since: [None; MAX_TENDONS],
            synced: false,
        }
    }

    /// Forget the model (a new plant, or one back after a gap): the next
    /// measurement becomes the model's state.
    pub(super) fn resync(&mut self) {
        self.synced = false;
        self.over_since = [None; MAX_TENDONS];
    }

    /// One fresh measurement at `now_ns` after `sent` was applied for about a
    /// period. Returns a stuck tendon and its tension error, if any.
    pub(super) fn check(
        &mut self,
        now_ns: u64,
        sent: &[f32; MAX_TENDONS],
        measured: &[f32; MAX_TENDONS],
        n: usize,
    ) -> Option<(usize, f32)> {
        if !self.cfg.enabled {
            return None;
        }
        if !self.synced {
            self.expected = *measured;
            self.synced = true;
            return None;
        }
        let persist_ns = (self.cfg.persist_s.max(0.0) * 1e9) as u64;
        let mut stuck = None;
        for (i, ((e, (&c, &m)), since)) in self
            .expected
            .iter_mut()
            .zip(sent.iter().zip(measured))
            .zip(&mut self.over_since)
            .enumerate()
            .take(n)
        {
            *e += (c - *e) * self.gain;
            let err = m - *e;
            if err.is_finite() && err.abs() as f64 <= self.cfg.tension_error_n {
                *since = None;
                continue;
            }
            let from = *since.get_or_insert(now_ns);
            if now_ns - from >= persist_ns && stuck.is_none() {
                stuck = Some((i, err));
            }
        }
        stuck
    }
}
