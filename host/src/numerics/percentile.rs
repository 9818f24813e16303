//! The nearest-rank percentile, one definition for every number the
//! project reports as a percentile (the learners' p95 tip error, the
//! closed loop's p95 tracking error, the processes' latency p50…p99.9 and
//! the real-time loop's histogram), so that a p95 means the same thing in
//! every table.
//!
//! The p-th percentile (0–100) of n samples is the smallest sample with at
//! least p % of the samples at or below it: the k-th smallest, with
//! k = ⌈p/100 · n⌉ kept within 1..=n. It is always one of the samples (no
//! interpolation), so a p95 of latencies is a latency that happened.

/// The 1-based rank of the p-th percentile (0–100) of `n` samples sorted
/// ascending: ⌈p/100 · n⌉, at least 1 (p = 0, or NaN, gives the smallest)
/// and at most `n` (p ≥ 100 gives the largest). For `n` = 0 it is 1, which
/// no sample has: callers check for no samples first.
pub fn nearest_rank(p: f64, n: u64) -> u64 {
    // `as` saturates: a negative or NaN product is 0, then raised to 1.
    (((p / 100.0) * n as f64).ceil() as u64).clamp(1, n.max(1))
}

/// The p-th percentile (0–100) of samples already sorted ascending;
/// `None` if there are none.
pub fn of_sorted<T: Copy>(sorted: &[T], p: f64) -> Option<T> {
    // A rank is at most the length, which fits in usize.
    let rank = nearest_rank(p, sorted.len() as u64) as usize;
    sorted.get(rank - 1).copied()
}

/// The p-th percentile (0–100) of integer samples (e.g. durations in ns),
/// sorting them in place; `None` if there are none.
pub fn of_u64(samples: &mut [u64], p: f64) -> Option<u64> {
    samples.sort_unstable();
    of_sorted(samples, p)
}

/// The p-th percentile (0–100) of real samples, sorting them in place by
/// [`f64::total_cmp`] (a NaN sorts above +∞, so a high percentile can be
/// NaN: filter them out first if they mean "no value"); `None` if there
/// are none.
pub fn of_f64(samples: &mut [f64], p: f64) -> Option<f64> {
    samples.sort_unstable_by(f64::total_cmp);
    of_sorted(samples, p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_by_hand() {
        // ⌈p/100 · n⌉ within 1..=n.
        assert_eq!(nearest_rank(0.0, 10), 1);
        assert_eq!(nearest_rank(10.0, 10), 1);
        assert_eq!(nearest_rank(10.5, 10), 2);
        assert_eq!(nearest_rank(50.0, 10), 5);
        assert_eq!(nearest_rank(95.0, 10), 10);
        assert_eq!(nearest_rank(100.0, 10), 10);
        assert_eq!(nearest_rank(95.0, 20), 19);
        assert_eq!(nearest_rank(25.0, 1000), 250);
        assert_eq!(nearest_rank(-5.0, 10), 1);
        assert_eq!(nearest_rank(f64::NAN, 10), 1);
        assert_eq!(nearest_rank(150.0, 10), 10);
        assert_eq!(nearest_rank(50.0, 0), 1);
    }

    #[test]
    fn percentiles_by_hand() {
        // Unsorted on purpose: the samples 15, 20, 35, 40, 50.
        let mut v = [35.0, 50.0, 15.0, 40.0, 20.0];
        assert_eq!(of_f64(&mut v, 0.0), Some(15.0));
        assert_eq!(of_f64(&mut v, 5.0), Some(15.0)); // ⌈0.25⌉ = 1
        assert_eq!(of_f64(&mut v, 30.0), Some(20.0)); // ⌈1.5⌉ = 2
        assert_eq!(of_f64(&mut v, 40.0), Some(20.0)); // exactly 2
        assert_eq!(of_f64(&mut v, 50.0), Some(35.0)); // ⌈2.5⌉ = 3
        assert_eq!(of_f64(&mut v, 95.0), Some(50.0)); // ⌈4.75⌉ = 5
        assert_eq!(of_f64(&mut v, 100.0), Some(50.0));
        assert_eq!(v, [15.0, 20.0, 35.0, 40.0, 50.0], "sorted in place");

        let mut v: Vec<u64> = (1..=100).rev().collect();
        assert_eq!(of_u64(&mut v, 0.0), Some(1));
        assert_eq!(of_u64(&mut v, 50.0), Some(50));
        assert_eq!(of_u64(&mut v, 99.0), Some(99));
        assert_eq!(of_u64(&mut v, 100.0), Some(100));

        // One sample is every percentile.
        for p in [0.0, 50.0, 100.0] {
            assert_eq!(of_u64(&mut [7], p), Some(7));
            assert_eq!(of_f64(&mut [7.5], p), Some(7.5));
        }
        // None is none.
        assert_eq!(of_u64(&mut [], 50.0), None);
        assert_eq!(of_f64(&mut [], 0.0), None);
        assert_eq!(of_sorted::<f64>(&[], 100.0), None);
        // Repeated values: p50 of 1, 2, 2, 2, 9 is 2 (rank 3).
        assert_eq!(of_sorted(&[1, 2, 2, 2, 9], 50.0), Some(2));
    }
}
