//! The robot's tendon groups, derived once from its geometry: the anchor
//! groups (tendons that end at the same arc length, the segments of a
//! multi-segment robot) and, inside them, the co-contraction sets the
//! firmware's command stage shifts together (`docs/design.md` §5.2). The
//! dataset sampler, the learner's capacity and targets, the family lift and
//! the command stage all read these two functions, so a segment means the
//! same tendons to all of them.

use std::f64::consts::{PI, TAU};

use tendril_shared::{CoContraction, MAX_TENDONS};

use super::Robot;

/// Two anchors closer than this (m) are the same.
const SAME_M: f64 = 1e-9;

/// Position angles within this (rad) of opposite, or unit vectors summing
/// to within this of zero, cancel: a calibrated file's fitted angles are off
/// a drawing's by thousandths of a degree, and its tendons still
/// co-contract (a set's weights make the moments cancel whatever the
/// offsets; the command stage gives the dataset's tensions back exactly
/// for any weights, `learn::targets`).
const CANCEL_RAD: f64 = 1e-3;

/// Bending degrees of freedom of `robot`: each anchor group (segment)
/// bends in as many directions as it has tendons, at most two.
pub fn bending_dof(robot: &Robot) -> usize {
    anchor_groups(robot).iter().map(|g| g.len().min(2)).sum()
}

/// The robot's tendons grouped by anchor (`end`), the group nearest the base
/// first; within a group, counter-clockwise by angle from +x, so that
/// neighbours in the list (and the last and the first) are neighbours on
/// the disk. Tendons with equal angles keep their file order.
pub fn anchor_groups(robot: &Robot) -> Vec<Vec<usize>> {
    let tendons = &robot.tendons;
    let mut order: Vec<usize> = (0..tendons.len()).collect();
    order.sort_by(|&a, &b| tendons[a].end.total_cmp(&tendons[b].end).then(a.cmp(&b)));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in order {
        match groups.last_mut() {
            Some(g) if (tendons[g[0]].end - tendons[i].end).abs() < SAME_M => g.push(i),
            _ => groups.push(vec![i]),
        }
    }
    for g in &mut groups {
        g.sort_by(|&a, &b| {
            let angle = |i: usize| tendons[i].angle.rem_euclid(TAU);
            angle(a).total_cmp(&angle(b)).then(a.cmp(&b))
        });
    }
    groups
}

/// Co-contraction sets of `robot`: tendons of one anchor group
/// ([`anchor_groups`]) with the same routing that cancel each other's
/// bending moment.
///
/// - An opposite pair (position angles π apart) is a set with weights
///   `w_i ∝ d_j` (so `w_i d_i = w_j d_j`: no net moment);
/// - three or more tendons of such a group that are left unpaired, with
///   unit vectors summing to zero (equally spaced), form one set with
///   weights `w_j ∝ 1 / d_j` (equal for equal offsets).
///
/// Other tendons belong to no set and are clipped on their own. Sets are
/// numbered in the order their first tendon appears in the file.
pub fn cocontraction_sets(robot: &Robot) -> CoContraction {
    let n = robot.tendons.len().min(MAX_TENDONS);
    let t = &robot.tendons[..n];
    let mut anchor = [usize::MAX; MAX_TENDONS];
    for (k, group) in anchor_groups(robot).iter().enumerate() {
        for &i in group.iter().filter(|&&i| i < n) {
            anchor[i] = k;
        }
    }
    let mut set = [CoContraction::NONE; MAX_TENDONS];
    let mut weight = [0.0f32; MAX_TENDONS];
    let mut next = 0u8;
    let same_group = |a: usize, b: usize| anchor[a] == anchor[b] && t[a].routing == t[b].routing;
    for i in 0..n {
        if set[i] != CoContraction::NONE {
            continue;
        }
        let partner = (i + 1..n).find(|&j| {
            set[j] == CoContraction::NONE && same_group(i, j) && {
                let d = (t[j].angle - t[i].angle).rem_euclid(2.0 * PI);
                (d - PI).abs() < CANCEL_RAD
            }
        });
        if let Some(j) = partner {
            let top = t[i].offset.max(t[j].offset);
            set[i] = next;
            set[j] = next;
            weight[i] = (t[j].offset / top) as f32;
            weight[j] = (t[i].offset / top) as f32;
            next += 1;
        }
    }
    // Equally spaced leftovers of one group.
    for i in 0..n {
        if set[i] != CoContraction::NONE {
            continue;
        }
        let members: Vec<usize> = (i..n)
            .filter(|&j| set[j] == CoContraction::NONE && same_group(i, j))
            .collect();
        let (sx, sy) = members.iter().fold((0.0, 0.0), |(x, y), &j| {
            (x + t[j].angle.cos(), y + t[j].angle.sin())
        });
        if members.len() >= 3 && sx.hypot(sy) < CANCEL_RAD {
            // w_j d_j equal: the moments Σ w_j d_j u_j = c Σ u_j vanish.
            let top = members
                .iter()
                .map(|&j| 1.0 / t[j].offset)
                .fold(0.0, f64::max);
            for &j in &members {
                set[j] = next;
                weight[j] = (1.0 / t[j].offset / top) as f32;
            }
            next += 1;
        }
    }
    // Every set has ≥ 2 members and unit-or-less positive weights by
    // construction; `new` checks it again.
    CoContraction::new(&set[..n], &weight[..n]).unwrap_or_else(|_| CoContraction::none())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    use crate::robot::repo_robot as robot;

    /// Three segments of 0.1 m with four, three and one tendons (eight, the
    /// most a robot may have), listed out of angle order and interleaved.
    pub(crate) fn three_segments() -> Robot {
        let mut text = String::from(
            "name = \"three-seg\"\n[backbone]\nlength = 0.3\nradius = 0.0007\n\
             youngs_modulus = 54e9\nshear_modulus = 20.8e9\ndensity = 0.0\n\
             [environment]\ngravity = [0.0, 0.0, 0.0]\n",
        );
        for (angle, end) in [
            (270.0, 0.2),
            (90.0, 0.1),
            (0.0, 0.1),
            (45.0, 0.3),
            (30.0, 0.2),
            (270.0, 0.1),
            (180.0, 0.1),
            (150.0, 0.2),
        ] {
            text += &format!(
                "[[tendon]]\noffset = 0.008\nangle_deg = {angle}\nmax_tension = 4.0\n\
                 end = {end}\nrouting = \"straight\"\n"
            );
        }
        Robot::from_toml(&text, std::path::Path::new("three-seg.toml")).unwrap()
    }

    #[test]
    fn anchor_groups_follow_the_segments_and_the_ring() {
        let robot = three_segments();
        assert_eq!(
            anchor_groups(&robot),
            vec![vec![2, 1, 6, 5], vec![4, 7, 0], vec![3]]
        );
        let seed = crate::robot::repo_robot("seed-4t.toml");
        assert_eq!(anchor_groups(&seed), vec![vec![0, 1, 2, 3]]);
    }

    #[test]
    fn seed_robots_pair_opposite_tendons() {
        let sets = cocontraction_sets(&robot("seed-paper.toml"));
        let s = sets.sets();
        assert_eq!((s[0], s[2]), (s[0], s[0]));
        assert_eq!(s[1], s[3]);
        assert_ne!(s[0], s[1]);
        assert_eq!(&sets.weights()[..4], &[1.0; 4]);
        assert!(cocontraction_sets(&robot("seed-1t.toml")).is_empty());
    }

    #[test]
    fn two_segment_robot_groups_by_anchor() {
        // Six tendons, three per segment at 120°: no opposite pairs, but each
        // segment's three are equally spaced → one set per segment.
        let r = robot("tdcr-2seg.toml");
        let sets = cocontraction_sets(&r);
        let s = &sets.sets()[..6];
        for i in 0..6 {
            for j in 0..6 {
                let same_anchor = (r.tendons[i].end - r.tendons[j].end).abs() < 1e-12;
                assert_eq!(s[i] == s[j], same_anchor, "tendons {i}, {j}: {s:?}");
            }
        }
        assert!(s.iter().all(|&x| x != CoContraction::NONE));
    }

    /// A calibrated file's tendons: angles off the drawing by thousandths
    /// of a degree, offsets by microns to a millimetre. They still form the
    /// drawing's sets (without them the targets are the raw, kinked
    /// tensions, and a net trained on the calibrated file missed by 2 mm,
    /// BENCHMARKS.md), and each set's weights cancel its moments:
    /// Σ w_j d_j u_j = 0.
    #[test]
    fn a_calibrated_files_nearly_symmetric_tendons_keep_their_sets() {
        for name in ["tdcr-2seg.toml", "seed-4t.toml"] {
            let nominal = robot(name);
            let mut r = nominal.clone();
            for (k, t) in r.tendons.iter_mut().enumerate() {
                t.angle += 8e-5 * (k as f64 - 2.5);
                t.offset *= 1.0 + 0.03 * ((k % 3) as f64 - 1.0);
            }
            let (a, b) = (cocontraction_sets(&nominal), cocontraction_sets(&r));
            let n = r.n_tendons();
            assert_eq!(a.sets()[..n], b.sets()[..n], "{name}");
            for set in 0..n as u8 {
                let (mut mx, mut my) = (0.0, 0.0);
                for (j, t) in r
                    .tendons
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| b.sets()[*j] == set)
                {
                    let w = f64::from(b.weights()[j]);
                    mx += w * t.offset * t.angle.cos();
                    my += w * t.offset * t.angle.sin();
                }
                let scale = r.tendons[0].offset;
                assert!(
                    f64::hypot(mx, my) < 2e-3 * scale,
                    "{name} set {set}: {mx}, {my}"
                );
            }
        }
    }

    #[test]
    fn every_cocontraction_set_lies_in_one_anchor_group() {
        // The interleaved three-segment robot: the 90°/270° and 0°/180° pairs
        // of the first segment are sets, the second segment's three tendons
        // 120° apart are one, and the 270° tendon of the second segment is
        // not paired across the anchors with the first's 90°.
        let r = three_segments();
        let groups = anchor_groups(&r);
        let sets = cocontraction_sets(&r);
        let group_of = |i: usize| groups.iter().position(|g| g.contains(&i)).unwrap();
        let s = &sets.sets()[..r.n_tendons()];
        for i in 0..s.len() {
            for j in 0..s.len() {
                if s[i] != CoContraction::NONE && s[i] == s[j] {
                    assert_eq!(group_of(i), group_of(j), "tendons {i}, {j}: {s:?}");
                }
            }
        }
        assert_eq!((s[1], s[2]), (s[5], s[6]), "{s:?}");
        assert_eq!((s[0], s[4]), (s[7], s[7]), "{s:?}");
        assert_ne!(s[0], s[1], "{s:?}");
        assert_eq!(s[3], CoContraction::NONE, "{s:?}");
    }
}
