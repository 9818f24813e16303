//! Per-tendon actuation limits the control step enforces: the tension range
//! `[0, max_tension]` (tendons can only pull) and the slew rate (how fast a
//! motor may change its tension, N/s).

pub use crate::capacity::MAX_TENDONS;

/// Why a set of limits was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    /// Zero tendons, or more than [`MAX_TENDONS`].
    #[error("robot has {0} tendons, tendril supports 1 to 8")]
    TendonCount(usize),
    /// The two per-tendon arrays have different lengths.
    #[error("{max_tension} max tensions but {slew_rate} slew rates")]
    LengthMismatch {
        /// Length of the max tension array.
        max_tension: usize,
        /// Length of the slew rate array.
        slew_rate: usize,
    },
    /// A max tension that is not a positive finite number of newtons.
    #[error("tendon {0}: max tension must be a positive finite number of newtons")]
    MaxTension(usize),
    /// A slew rate that is not a positive finite number of N/s.
    #[error("tendon {0}: slew rate must be a positive finite number of N/s")]
    SlewRate(usize),
}

/// Validated per-tendon limits for 1–[`MAX_TENDONS`] tendons. Fields are
/// private so every `TendonLimits` in existence is valid; entries past
/// `n_tendons` are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TendonLimits {
    n: usize,
    max_tension: [f32; MAX_TENDONS],
    slew_rate: [f32; MAX_TENDONS],
}

impl TendonLimits {
    /// Limits with one max tension (N) and one slew rate (N/s) per tendon.
    pub fn new(max_tension: &[f32], slew_rate: &[f32]) -> Result<Self, LimitsError> {
        let n = max_tension.len();
        if n == 0 || n > MAX_TENDONS {
            return Err(LimitsError::TendonCount(n));
        }
        if slew_rate.len() != n {
            return Err(LimitsError::LengthMismatch {
                max_tension: n,
                slew_rate: slew_rate.len(),
            });
        }
        let mut lim = TendonLimits {
            n,
            max_tension: [0.0; MAX_TENDONS],
            slew_rate: [0.0; MAX_TENDONS],
        };
        let pairs = max_tension.iter().zip(slew_rate);
        let slots = lim.max_tension.iter_mut().zip(lim.slew_rate.iter_mut());
        for (i, ((&t, &s), (mt, sr))) in pairs.zip(slots).enumerate() {
            if !(t.is_finite() && t > 0.0) {
                return Err(LimitsError::MaxTension(i));
            }
            if !(s.is_finite() && s > 0.0) {
                return Err(LimitsError::SlewRate(i));
            }
            *mt = t;
            *sr = s;
        }
        Ok(lim)
    }

    /// Same max tension and slew rate for `n` tendons.
    pub fn uniform(n: usize, max_tension: f32, slew_rate: f32) -> Result<Self, LimitsError> {
        if n == 0 || n > MAX_TENDONS {
            return Err(LimitsError::TendonCount(n));
        }
        let t = [max_tension; MAX_TENDONS];
        let s = [slew_rate; MAX_TENDONS];
        Self::new(t.get(..n).unwrap_or(&t), s.get(..n).unwrap_or(&s))
    }

    /// Number of tendons.
    pub fn n_tendons(&self) -> usize {
        self.n
    }

    /// Max tension per tendon, N (`n_tendons()` long).
    pub fn max_tension(&self) -> &[f32] {
        self.max_tension.get(..self.n).unwrap_or(&self.max_tension)
    }

    /// Slew rate per tendon, N/s (`n_tendons()` long).
    pub fn slew_rate(&self) -> &[f32] {
        self.slew_rate.get(..self.n).unwrap_or(&self.slew_rate)
    }

    /// Max tension of every slot, zero past `n_tendons()` (so clamping a
    /// full-width command zeroes unused slots).
    pub fn max_tension_padded(&self) -> &[f32; MAX_TENDONS] {
        &self.max_tension
    }

    /// Slew rate of every slot, zero past `n_tendons()`.
    pub fn slew_rate_padded(&self) -> &[f32; MAX_TENDONS] {
        &self.slew_rate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_valid_and_names_the_bad_tendon() {
        let l = TendonLimits::new(&[10.0, 5.0], &[100.0, 50.0]).unwrap();
        assert_eq!(l.n_tendons(), 2);
        assert_eq!(l.max_tension(), &[10.0, 5.0]);
        assert_eq!(l.max_tension_padded()[2], 0.0);
        assert_eq!(
            TendonLimits::new(&[10.0, f32::NAN], &[1.0, 1.0]),
            Err(LimitsError::MaxTension(1))
        );
        assert_eq!(
            TendonLimits::new(&[10.0, 1.0], &[1.0, -1.0]),
            Err(LimitsError::SlewRate(1))
        );
        assert_eq!(
            TendonLimits::new(&[], &[]),
            Err(LimitsError::TendonCount(0))
        );
        assert_eq!(
            TendonLimits::uniform(9, 1.0, 1.0),
            Err(LimitsError::TendonCount(9))
        );
        assert!(matches!(
            TendonLimits::new(&[1.0], &[1.0, 2.0]),
            Err(LimitsError::LengthMismatch { .. })
        ));
        assert_eq!(
            TendonLimits::uniform(4, 10.0, 200.0).unwrap().slew_rate(),
            &[200.0; 4]
        );
    }
}
