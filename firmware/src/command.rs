//! The command stage's co-contraction shift (`docs/design.md` §5.2).
//!
//! A tendon robot bends by the *difference* of antagonistic tensions:
//! pulling a co-contraction set harder together barely moves the tip.
//! When a target leaves `[min, max]` on one side of a bend, clipping that
//! tendon alone destroys the differential (a net asking 17.9 N of a 15 N
//! tendon whose antagonist asks 8.1 N loses 2.9 N of bend: tens of mm).
//! Shifting the whole set by the same weighted amount first keeps the
//! differential; only what still does not fit is clipped afterwards.

use tendril_shared::{CoContraction, TendonLimits, MAX_TENDONS};

/// One tension per tendon slot (N); slots past the tendon count are 0.
pub type Tensions = [f32; MAX_TENDONS];

/// Shift each co-contraction set of `target` (finite entries) along its
/// weights so the set fits in `[min, max]`; when the set's spread is wider
/// than its range, centre it so both ends overshoot equally (the clip that
/// follows then removes the least differential). Sets already in range are
/// untouched. Returns whether any set moved. Deterministic, at most
/// `MAX_TENDONS²` comparisons, no allocation.
pub fn co_contract(target: &mut Tensions, limits: &TendonLimits) -> bool {
    let sets = limits.cocontraction();
    let (set, weight) = (sets.sets(), sets.weights());
    let (lo_t, hi_t) = (limits.min_tension_padded(), limits.max_tension_padded());
    let n = limits.n_tendons().min(MAX_TENDONS);
    let mut moved = false;
    for first in 0..n {
        let Some(&s) = set.get(first) else { break };
        // Each set once, at its first member.
        if s == CoContraction::NONE || set.iter().take(first).any(|&o| o == s) {
            continue;
        }
        // α range keeping every member in range: lo ≤ α ≤ hi.
        let (mut lo, mut hi) = (f32::NEG_INFINITY, f32::INFINITY);
        for i in first..n {
            if let (Some(&si), Some(&w), Some(&t), Some(&a), Some(&b)) = (
                set.get(i),
                weight.get(i),
                target.get(i),
                lo_t.get(i),
                hi_t.get(i),
            ) {
                if si == s && w > 0.0 {
                    lo = lo.max((a - t) / w);
                    hi = hi.min((b - t) / w);
                }
            }
        }
        if !(lo.is_finite() && hi.is_finite()) || (lo <= 0.0 && 0.0 <= hi) {
            continue;
        }
        let alpha = if lo <= hi {
            // The smallest shift that fits (0 lies outside [lo, hi]).
            if hi < 0.0 {
                hi
            } else {
                lo
            }
        } else {
            0.5 * (lo + hi)
        };
        for i in first..n {
            if let (Some(&si), Some(&w), Some(t)) = (set.get(i), weight.get(i), target.get_mut(i)) {
                if si == s {
                    *t += alpha * w;
                }
            }
        }
        moved = true;
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seed_paper() -> TendonLimits {
        TendonLimits::uniform(4, 15.0, 100.0)
            .unwrap()
            .with_min_tension(&[5.0; 4])
            .unwrap()
            .with_cocontraction(CoContraction::opposite_pairs(4))
            .unwrap()
    }

    fn pad(t: [f32; 4]) -> Tensions {
        let mut out = [0.0; MAX_TENDONS];
        out[..4].copy_from_slice(&t);
        out
    }

    #[test]
    fn the_seed_paper_example_keeps_both_differentials() {
        // A net's answer (6.99, 8.08, 15.02, 17.87) N for tensions whose
        // pairs are (0, 2) and (1, 3): both differentials survive the shift.
        let mut t = pad([6.99, 8.08, 15.02, 17.87]);
        assert!(co_contract(&mut t, &seed_paper()));
        assert!((t[2] - t[0] - (15.02 - 6.99)).abs() < 1e-5);
        assert!((t[3] - t[1] - (17.87 - 8.08)).abs() < 1e-5);
        for &v in &t[..4] {
            assert!((5.0..=15.0).contains(&v), "{t:?}");
        }
        // The smallest shift: the high member lands on the max.
        assert!((t[3] - 15.0).abs() < 1e-6 && (t[2] - 15.0).abs() < 1e-6);
    }

    #[test]
    fn a_set_in_range_is_untouched_and_a_too_wide_one_is_centred() {
        let mut t = pad([6.0, 7.0, 14.0, 13.0]);
        let before = t;
        assert!(!co_contract(&mut t, &seed_paper()));
        assert_eq!(t, before);
        // Pair (1, 3) spread 14 N in a 10 N range: overshoot 2 N each end.
        let mut t = pad([6.0, 2.0, 14.0, 16.0]);
        co_contract(&mut t, &seed_paper());
        assert!(
            (t[1] - 3.0).abs() < 1e-6 && (t[3] - 17.0).abs() < 1e-6,
            "{t:?}"
        );
        assert_eq!((t[0], t[2]), (6.0, 14.0));
    }

    #[test]
    fn no_sets_no_shift() {
        let limits = TendonLimits::uniform(4, 15.0, 100.0).unwrap();
        let mut t = pad([1.0, 20.0, 0.0, 0.0]);
        assert!(!co_contract(&mut t, &limits));
        assert_eq!(t, pad([1.0, 20.0, 0.0, 0.0]));
    }
}
