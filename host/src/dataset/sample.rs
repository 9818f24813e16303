//! Tension samplers (`docs/design.md` §3).

use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// How tension vectors are drawn.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    /// In each anchor group ([`crate::robot::anchor_groups`]) exactly two neighbouring
    /// tendons pull (a group of one: that tendon), each uniform in
    /// [τ_min, τ_max]; the rest stay at their floor. Keeps IK a function for
    /// antagonistic tendon sets; the default for robots with more than two
    /// tendons.
    Adjacent,
    /// Every tendon uniform in [0, τ_max] (the paper's sampler). With
    /// antagonistic tendons the inverse map is not unique.
    Uniform,
}

impl Sampler {
    /// The default for a robot with `n_tendons` tendons.
    pub fn default_for(n_tendons: usize) -> Sampler {
        if n_tendons > 2 {
            Sampler::Adjacent
        } else {
            Sampler::Uniform
        }
    }

    /// Name as used on the command line and in sidecars.
    pub fn name(&self) -> &'static str {
        match self {
            Sampler::Adjacent => "adjacent",
            Sampler::Uniform => "uniform",
        }
    }

    /// Draw `count` tension vectors for tendons with limits `max` (N) and no
    /// pretension, deterministically from `seed`.
    pub fn draw(&self, count: usize, max: &[f64], seed: u64) -> Vec<Vec<f64>> {
        self.draw_between(count, &vec![0.0; max.len()], max, seed)
    }

    /// Draw `count` tension vectors for tendons kept in [`min`, `max`] (N),
    /// deterministically from `seed`: the floors are the tendons' pretension
    /// (`min_tension`), which a slack tendon of the adjacent sampler keeps.
    /// With zero floors this draws exactly what [`Sampler::draw`] always did.
    ///
    /// The adjacent sampler treats all tendons as one ring in index order;
    /// [`Sampler::draw_grouped`] takes the robot's anchor groups.
    pub fn draw_between(&self, count: usize, min: &[f64], max: &[f64], seed: u64) -> Vec<Vec<f64>> {
        self.draw_grouped(count, min, max, &[(0..max.len()).collect()], seed)
    }

    /// As [`Sampler::draw_between`], the adjacent sampler pulling two
    /// neighbours in each of `groups` (tendon indices, each group in ring
    /// order, as [`crate::robot::anchor_groups`] gives them). A robot with one anchor whose
    /// tendons are listed counter-clockwise draws exactly what
    /// [`Sampler::draw_between`] draws.
    pub fn draw_grouped(
        &self,
        count: usize,
        min: &[f64],
        max: &[f64],
        groups: &[Vec<usize>],
        seed: u64,
    ) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = max.len();
        let within = |i: usize, rng: &mut ChaCha8Rng| {
            let lo = min.get(i).copied().unwrap_or(0.0);
            lo + rng.random::<f64>() * (max[i] - lo)
        };
        (0..count)
            .map(|_| match self {
                Sampler::Uniform => (0..n).map(|i| within(i, &mut rng)).collect(),
                Sampler::Adjacent => {
                    let mut t: Vec<f64> =
                        (0..n).map(|i| min.get(i).copied().unwrap_or(0.0)).collect();
                    for group in groups {
                        match group.len() {
                            0 => {}
                            1 => t[group[0]] = within(group[0], &mut rng),
                            m => {
                                let k = rng.random_range(0..m);
                                let (i, j) = (group[k], group[(k + 1) % m]);
                                t[i] = within(i, &mut rng);
                                t[j] = within(j, &mut rng);
                            }
                        }
                    }
                    t
                }
            })
            .collect()
    }
}

/// An order of `samples` in which consecutive tension vectors are close, so
/// each solve can warm-start from the previous one: a boustrophedon (snake)
/// walk over a grid of `cells` per axis, rows reversed alternately so
/// neighbouring cells in the walk share a face.
pub fn snake_order(samples: &[Vec<f64>], max: &[f64], cells: usize) -> Vec<usize> {
    let cells = cells.max(1);
    let key = |t: &Vec<f64>| -> Vec<usize> {
        let mut k = Vec::with_capacity(t.len() + 1);
        let mut parity = 0usize;
        for (&x, &m) in t.iter().zip(max) {
            let c = ((x / m * cells as f64) as usize).min(cells - 1);
            let c = if parity % 2 == 1 { cells - 1 - c } else { c };
            parity += c;
            k.push(c);
        }
        k
    };
    let mut order: Vec<usize> = (0..samples.len()).collect();
    let keys: Vec<Vec<usize>> = samples.iter().map(key).collect();
    order.sort_by(|&a, &b| keys[a].cmp(&keys[b]).then(a.cmp(&b)));
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::robot::anchor_groups;
    use crate::robot::groups::tests::three_segments;

    #[test]
    fn adjacent_sampler_pulls_exactly_two_neighbours_within_limits() {
        let max = [10.0, 8.0, 10.0, 6.0];
        for t in Sampler::Adjacent.draw(2000, &max, 3) {
            let nz: Vec<usize> = (0..4).filter(|&i| t[i] != 0.0).collect();
            assert_eq!(nz.len(), 2, "{t:?}");
            assert!(nz[1] == nz[0] + 1 || (nz[0] == 0 && nz[1] == 3), "{t:?}");
            assert!(t.iter().zip(&max).all(|(x, m)| (0.0..=*m).contains(x)));
        }
    }

    #[test]
    fn samplers_keep_every_tension_within_its_floor_and_limit() {
        let min = [5.0, 0.0, 2.0, 5.0];
        let max = [15.0, 8.0, 10.0, 15.0];
        for sampler in [Sampler::Uniform, Sampler::Adjacent] {
            let draws = sampler.draw_between(3000, &min, &max, 7);
            for t in &draws {
                for i in 0..4 {
                    assert!((min[i]..=max[i]).contains(&t[i]), "{sampler:?}: {t:?}");
                }
            }
            // The floor is reached only by slack tendons, and the range is used.
            let lowest = draws.iter().map(|t| t[0]).fold(f64::INFINITY, f64::min);
            let highest = draws.iter().map(|t| t[0]).fold(0.0, f64::max);
            assert!(
                lowest < 5.1 && highest > 14.9,
                "{sampler:?}: {lowest}..{highest}"
            );
        }
        // Adjacent: the two pulled neighbours vary, the others sit at their floor.
        for t in Sampler::Adjacent.draw_between(500, &min, &max, 8) {
            let at_floor = (0..4).filter(|&i| t[i] == min[i]).count();
            assert!(at_floor >= 2, "{t:?}");
        }
    }

    #[test]
    fn adjacent_sampler_pulls_two_neighbours_in_every_segment() {
        let robot = three_segments();
        let groups = anchor_groups(&robot);
        let (min, max) = (robot.min_tensions(), robot.max_tensions());
        let draws = Sampler::Adjacent.draw_grouped(3000, &min, &max, &groups, 11);
        let mut pairs_seen = std::collections::BTreeSet::new();
        for t in &draws {
            for g in &groups {
                let pulled: Vec<usize> = (0..g.len()).filter(|&k| t[g[k]] != 0.0).collect();
                assert_eq!(pulled.len(), g.len().min(2), "{t:?}");
                if let [a, b] = pulled[..] {
                    // Neighbours on the disk: next to each other in the ring.
                    assert!(b == a + 1 || (a == 0 && b == g.len() - 1), "{t:?}");
                    pairs_seen.insert((g[a], g[b]));
                }
            }
            assert!(t.iter().zip(&max).all(|(x, m)| (0.0..=*m).contains(x)));
        }
        // Every neighbouring pair of the four- and the three-tendon segment is drawn.
        assert_eq!(pairs_seen.len(), 4 + 3);
    }

    #[test]
    fn samplers_are_seeded() {
        let max = [10.0; 4];
        assert_eq!(
            Sampler::Uniform.draw(50, &max, 1),
            Sampler::Uniform.draw(50, &max, 1)
        );
        assert_ne!(
            Sampler::Uniform.draw(50, &max, 1),
            Sampler::Uniform.draw(50, &max, 2)
        );
    }

    #[test]
    fn snake_order_keeps_neighbours_close() {
        let max = [10.0; 2];
        let s = Sampler::Uniform.draw(4000, &max, 5);
        let order = snake_order(&s, &max, 16);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..4000).collect::<Vec<_>>());
        let step = |o: &[usize]| -> f64 {
            o.windows(2)
                .map(|w| {
                    ((s[w[0]][0] - s[w[1]][0]).powi(2) + (s[w[0]][1] - s[w[1]][1]).powi(2)).sqrt()
                })
                .sum::<f64>()
                / o.len() as f64
        };
        let natural: Vec<usize> = (0..4000).collect();
        assert!(step(&order) < step(&natural) / 5.0);
    }
}
