//! Which rows a fit can use, and how they are split into fit and held-out
//! rows (`docs/design.md` §11).

use std::collections::HashMap;

use nalgebra::Vector3;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::data::Measurements;
use super::CalibError;
use crate::robot::Robot;

/// How far the tips of one robot can spread, in robot lengths: a tip
/// stays within a sphere of radius L about the base, so no two are more
/// than 2 L apart; the margin covers a tracker's outliers.
pub const MAX_SPREAD_LENGTHS: f64 = 2.5;

/// Refuse rows no fit can use: every row at one tension set (nothing
/// varies, so nothing can be fitted) and tips spread wider than the robot
/// reaches (positions in millimetres, or another robot's rows).
pub fn check_rows(robot: &Robot, data: &Measurements) -> Result<(), CalibError> {
    let first = (data.tensions.first(), data.tip_forces.first());
    let varies =
        (data.tensions.iter().zip(&data.tip_forces)).any(|(t, f)| (Some(t), Some(f)) != first);
    if !varies {
        return Err(CalibError::Options(format!(
            "every one of the {} rows has the same tensions (and tip load): nothing varies, \
             so nothing can be fitted; measure tension sets spread over the limits \
             (tendril calibrate --plan N proposes them)",
            data.len()
        )));
    }
    let p: Vec<Vector3<f64>> = data.positions.iter().map(|&x| Vector3::from(x)).collect();
    let spread = spread_m(&p);
    if spread > MAX_SPREAD_LENGTHS * robot.length {
        return Err(CalibError::Options(format!(
            "the measured tips spread over {spread:.3} m (the largest distance of a tip from \
             their median), more than a robot of length {} m reaches: positions must be in \
             metres, taken on this robot",
            robot.length
        )));
    }
    Ok(())
}

/// The largest distance of a point from the points' componentwise median, m.
pub fn spread_m(p: &[Vector3<f64>]) -> f64 {
    let median = |k: usize| {
        let mut v: Vec<f64> = p.iter().map(|x| x[k]).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let c = Vector3::new(median(0), median(1), median(2));
    p.iter().map(|x| (x - c).norm()).fold(0.0, f64::max)
}

/// The median distance of the points from their componentwise median, m:
/// how far apart the tips typically are, robust to outliers.
pub fn median_spread_m(p: &[Vector3<f64>]) -> f64 {
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let c = Vector3::new(
        median(p.iter().map(|x| x.x).collect()),
        median(p.iter().map(|x| x.y).collect()),
        median(p.iter().map(|x| x.z).collect()),
    );
    median(p.iter().map(|x| (x - c).norm()).collect())
}

/// Fit and held-out rows (each sorted): `fraction` of the rows held out
/// at random (`seed`), rows that repeat a tension set and tip load kept on
/// one side together — a held-out copy of a fit row would judge the fit
/// by a row it was fitted to.
pub fn split(data: &Measurements, fraction: f64, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut index: HashMap<Vec<u64>, usize> = HashMap::new();
    for i in 0..data.len() {
        let key: Vec<u64> = (data.tensions[i].iter().chain(&data.tip_forces[i]))
            .chain(&data.tip_moments[i])
            .map(|x| x.to_bits())
            .collect();
        let g = *index.entry(key).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(i);
    }
    groups.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let want = (data.len() as f64 * fraction).round() as usize;
    let (mut fit, mut held) = (Vec::new(), Vec::new());
    for g in groups {
        if held.len() < want && held.len() + g.len() <= want.max(1) {
            held.extend(g);
        } else {
            fit.extend(g);
        }
    }
    fit.sort_unstable();
    held.sort_unstable();
    (fit, held)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(tensions: &[f64]) -> Measurements {
        let n = tensions.len();
        Measurements {
            tensions: tensions.iter().map(|&t| vec![t, 0.0]).collect(),
            positions: (0..n).map(|i| [0.0, 0.0, 0.3 + i as f64 * 1e-3]).collect(),
            quaternions: None,
            tip_forces: vec![[0.0; 3]; n],
            tip_moments: vec![[0.0; 3]; n],
            lines: (2..n + 2).collect(),
        }
    }

    #[test]
    fn copies_of_a_row_are_never_on_both_sides() {
        // Ten sets, each measured three times.
        let t: Vec<f64> = (0..30).map(|i| (i / 3) as f64).collect();
        let data = rows(&t);
        let (fit, held) = split(&data, 0.2, 1);
        assert_eq!(fit.len() + held.len(), 30);
        assert_eq!(held.len(), 6, "{held:?}");
        for h in &held {
            assert!(
                fit.iter().all(|f| data.tensions[*f] != data.tensions[*h]),
                "row {h} is held out and fitted"
            );
        }
        let (_, none) = split(&data, 0.0, 1);
        assert!(none.is_empty());
    }
}
