//! Per-tendon actuation limits the control step enforces: the tension range
//! `[min_tension, max_tension]` (tendons can only pull; the floor is the
//! pretension a motor keeps), the slew rate (how fast a motor may change its
//! tension, N/s), and the co-contraction sets the command stage may shift
//! along to bring a command into range (`docs/design.md` §5.2).

pub use crate::capacity::MAX_TENDONS;

/// Why a set of limits was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    /// Zero tendons, or more than [`MAX_TENDONS`].
    #[error("robot has {0} tendons, tendril supports 1 to {max}", max = crate::capacity::MAX_TENDONS)]
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
    /// A min tension that is not finite, negative, or above the max.
    #[error("tendon {0}: min tension must be a finite number of newtons in [0, max tension]")]
    MinTension(usize),
    /// A co-contraction set of fewer than two tendons, a tendon past the
    /// tendon count, or a weight that is not positive and finite.
    #[error("tendon {0}: bad co-contraction set or weight")]
    CoContraction(usize),
}

/// Sets of tendons whose tensions move together without bending the robot
/// (co-contraction): for tendons anchored at the same arc length with
/// offsets `r_i`, a direction `w` (all `w_i > 0`) with `Σ w_i r_i = 0`
/// changes no bending moment, only the axial load. Each tendon belongs to at
/// most one set; the host derives the sets from the robot's geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoContraction {
    /// Set index of each tendon slot, [`CoContraction::NONE`] when in none.
    set: [u8; MAX_TENDONS],
    /// Weight `w_i` of each tendon in its set (largest 1 per set).
    weight: [f32; MAX_TENDONS],
}

impl CoContraction {
    /// The set index of a tendon that belongs to no set.
    pub const NONE: u8 = u8::MAX;

    /// No sets: every tendon is clipped on its own.
    pub const fn none() -> CoContraction {
        CoContraction {
            set: [Self::NONE; MAX_TENDONS],
            weight: [0.0; MAX_TENDONS],
        }
    }

    /// Sets from one entry per tendon: `set[i]` is tendon i's set (any small
    /// number, or [`CoContraction::NONE`]) and `weight[i]` its weight. Every
    /// set needs at least two tendons and positive finite weights.
    pub fn new(set: &[u8], weight: &[f32]) -> Result<CoContraction, LimitsError> {
        if set.len() > MAX_TENDONS || weight.len() != set.len() {
            return Err(LimitsError::CoContraction(set.len().min(MAX_TENDONS)));
        }
        let mut c = CoContraction::none();
        for (i, (&s, &w)) in set.iter().zip(weight).enumerate() {
            if s == Self::NONE {
                continue;
            }
            let members = set.iter().filter(|&&o| o == s).count();
            if members < 2 || !(w.is_finite() && w > 0.0) {
                return Err(LimitsError::CoContraction(i));
            }
            if let (Some(cs), Some(cw)) = (c.set.get_mut(i), c.weight.get_mut(i)) {
                *cs = s;
                *cw = w;
            }
        }
        Ok(c)
    }

    /// Opposite pairs of `n` equally spaced tendons with equal offsets
    /// (tendon i with i + n/2, weights 1) — the sets of the seed robots;
    /// none for odd `n`.
    pub fn opposite_pairs(n: usize) -> CoContraction {
        let mut c = CoContraction::none();
        if !n.is_multiple_of(2) || n > MAX_TENDONS {
            return c;
        }
        let half = n / 2;
        for i in 0..n {
            if let (Some(s), Some(w)) = (c.set.get_mut(i), c.weight.get_mut(i)) {
                *s = (i % half.max(1)) as u8;
                *w = 1.0;
            }
        }
        c
    }

    /// Set index of every tendon slot ([`CoContraction::NONE`]: in none).
    pub fn sets(&self) -> &[u8; MAX_TENDONS] {
        &self.set
    }

    /// Weight of every tendon slot in its set (0 when in none).
    pub fn weights(&self) -> &[f32; MAX_TENDONS] {
        &self.weight
    }

    /// Whether no tendon belongs to a set.
    pub fn is_empty(&self) -> bool {
        self.set.iter().all(|&s| s == Self::NONE)
    }
}

impl Default for CoContraction {
    fn default() -> Self {
        CoContraction::none()
    }
}

/// Validated per-tendon limits for 1–[`MAX_TENDONS`] tendons. Fields are
/// private so every `TendonLimits` in existence is valid; entries past
/// `n_tendons` are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TendonLimits {
    n: usize,
    min_tension: [f32; MAX_TENDONS],
    max_tension: [f32; MAX_TENDONS],
    slew_rate: [f32; MAX_TENDONS],
    cocontraction: CoContraction,
}

impl TendonLimits {
    /// Every tendon slot, 0 to 1 N at 1 N/s, no co-contraction: valid like
    /// every `TendonLimits`, and a constant, for a controller that must
    /// exist before it is configured (the firmware's node, a `static`
    /// whose motors get nothing until its Setup comes; it is then
    /// configured in place instead of built on the chip's stack).
    pub const UNCONFIGURED: TendonLimits = TendonLimits {
        n: MAX_TENDONS,
        min_tension: [0.0; MAX_TENDONS],
        max_tension: [1.0; MAX_TENDONS],
        slew_rate: [1.0; MAX_TENDONS],
        cocontraction: CoContraction::none(),
    };

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
            min_tension: [0.0; MAX_TENDONS],
            max_tension: [0.0; MAX_TENDONS],
            slew_rate: [0.0; MAX_TENDONS],
            cocontraction: CoContraction::none(),
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

    /// These limits with a tension floor per tendon (N, `n_tendons()` long,
    /// each finite and in `[0, max_tension]`).
    pub fn with_min_tension(mut self, min_tension: &[f32]) -> Result<Self, LimitsError> {
        if min_tension.len() != self.n {
            return Err(LimitsError::MinTension(min_tension.len().min(self.n)));
        }
        for (i, (&lo, slot)) in min_tension
            .iter()
            .zip(self.min_tension.iter_mut())
            .enumerate()
        {
            let hi = self.max_tension.get(i).copied().unwrap_or(0.0);
            if !(lo.is_finite() && (0.0..=hi).contains(&lo)) {
                return Err(LimitsError::MinTension(i));
            }
            *slot = lo;
        }
        Ok(self)
    }

    /// These limits with co-contraction sets (every member below
    /// `n_tendons()`).
    pub fn with_cocontraction(mut self, sets: CoContraction) -> Result<Self, LimitsError> {
        for (i, &s) in sets.sets().iter().enumerate() {
            if s != CoContraction::NONE && i >= self.n {
                return Err(LimitsError::CoContraction(i));
            }
        }
        self.cocontraction = sets;
        Ok(self)
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

    /// Min tension per tendon, N (`n_tendons()` long).
    pub fn min_tension(&self) -> &[f32] {
        self.min_tension.get(..self.n).unwrap_or(&self.min_tension)
    }

    /// Min tension of every slot, zero past `n_tendons()`.
    pub fn min_tension_padded(&self) -> &[f32; MAX_TENDONS] {
        &self.min_tension
    }

    /// The co-contraction sets.
    pub fn cocontraction(&self) -> &CoContraction {
        &self.cocontraction
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
            TendonLimits::uniform(10, 1.0, 1.0),
            Err(LimitsError::TendonCount(10))
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

    #[test]
    fn floors_and_sets_are_validated() {
        let l = TendonLimits::uniform(4, 15.0, 100.0).unwrap();
        assert_eq!(l.min_tension(), &[0.0; 4]);
        let with = l.with_min_tension(&[5.0; 4]).unwrap();
        assert_eq!(with.min_tension(), &[5.0; 4]);
        assert_eq!(
            l.with_min_tension(&[5.0, 16.0, 0.0, 0.0]),
            Err(LimitsError::MinTension(1))
        );
        assert_eq!(
            l.with_min_tension(&[-1.0, 0.0, 0.0, 0.0]),
            Err(LimitsError::MinTension(0))
        );
        assert!(l.with_min_tension(&[5.0; 3]).is_err());
        let pairs = CoContraction::opposite_pairs(4);
        assert_eq!(&pairs.sets()[..4], &[0, 1, 0, 1]);
        assert!(CoContraction::opposite_pairs(3).is_empty());
        assert!(l.with_cocontraction(pairs).is_ok());
        assert_eq!(
            TendonLimits::uniform(2, 1.0, 1.0)
                .unwrap()
                .with_cocontraction(pairs),
            Err(LimitsError::CoContraction(2))
        );
        assert_eq!(
            CoContraction::new(&[0, 1, 0, CoContraction::NONE], &[1.0; 4]),
            Err(LimitsError::CoContraction(1)),
            "a set of one tendon"
        );
        assert_eq!(
            CoContraction::new(&[0, 0], &[1.0, 0.0]),
            Err(LimitsError::CoContraction(1))
        );
    }
}
