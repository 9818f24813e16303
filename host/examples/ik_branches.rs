//! Is a robot's inverse kinematics a function over its dataset? (issue 30:
//! why the three-segment net's tail error stays large.)
//!
//! A learner maps a pose to one tension vector. If two tension vectors far
//! apart reach the same pose (two branches, as a six-joint arm has several
//! elbow-up/down solutions), a net averages them and misses both. This
//! finds the rows whose nearest neighbour in pose space has the most
//! different tensions (pose distance: position in mm plus orientation in
//! degrees, one degree counted as one millimetre), then asks the exact IK
//! for that neighbour's pose starting from the row's own tensions. A
//! solution that reaches the pose (≤ 1 µm) far from the neighbour's
//! tensions is a second branch.
//!
//! `cargo run --release -p tendril --example ik_branches -- ROBOT DATA.csv [pairs]`
//! (default 8 pairs). Co-contraction (every tendon of a group pulled alike)
//! is taken out of the tension distance, so only differences that bend the
//! robot count.

use std::path::Path;

use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use tendril::dataset::Dataset;
use tendril::inverse::{ExactIk, IkSettings, Target};
use tendril::robot::Robot;

/// Position (mm) and orientation (rotation vector, degrees) of a pose row.
fn features(data: &Dataset, r: usize) -> [f64; 6] {
    let p = data.poses.row(r);
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(p[3], p[4], p[5], p[6]));
    let v = q.scaled_axis().map(f64::to_degrees);
    [p[0] * 1e3, p[1] * 1e3, p[2] * 1e3, v[0], v[1], v[2]]
}

/// Largest difference between two tension vectors once each anchor group's
/// common part (its minimum) is taken out: what bends the robot.
fn bending_distance(robot: &Robot, a: &[f64], b: &[f64]) -> f64 {
    let mut groups: Vec<(f64, Vec<usize>)> = Vec::new();
    for (k, t) in robot.tendons.iter().enumerate() {
        match groups
            .iter_mut()
            .find(|(end, _)| (end - t.end).abs() < 1e-12)
        {
            Some((_, g)) => g.push(k),
            None => groups.push((t.end, vec![k])),
        }
    }
    let centred = |x: &[f64], g: &[usize]| -> Vec<f64> {
        let m = g.iter().map(|&k| x[k]).fold(f64::INFINITY, f64::min);
        g.iter()
            .map(|&k| x[k] - if g.len() > 1 { m } else { 0.0 })
            .collect()
    };
    groups
        .iter()
        .flat_map(|(_, g)| {
            let (ca, cb) = (centred(a, g), centred(b, g));
            ca.into_iter().zip(cb).map(|(u, v)| (u - v).abs())
        })
        .fold(0.0, f64::max)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, robot, data, rest @ ..] = args.as_slice() else {
        anyhow::bail!("usage: ik_branches ROBOT DATA.csv [pairs]");
    };
    let pairs: usize = rest.first().map(|s| s.parse()).transpose()?.unwrap_or(8);
    let robot = Robot::load(Path::new(robot))?;
    let data = Dataset::read_csv(Path::new(data))?;
    let n = data.tensions.nrows();
    let f: Vec<[f64; 6]> = (0..n).map(|r| features(&data, r)).collect();
    let t = |r: usize| -> Vec<f64> { data.tensions.row(r).iter().copied().collect() };
    // Each row's nearest neighbour in pose space (brute force: n² / 2 cores).
    let nearest: Vec<(usize, f64)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut best = (i, f64::INFINITY);
            for (j, fj) in f.iter().enumerate() {
                let d: f64 = f[i].iter().zip(fj).map(|(a, b)| (a - b) * (a - b)).sum();
                if j != i && d < best.1 {
                    best = (j, d);
                }
            }
            (best.0, best.1.sqrt())
        })
        .collect();
    let mut ratio: Vec<(f64, usize)> = nearest
        .iter()
        .enumerate()
        .map(|(i, &(j, d))| (bending_distance(&robot, &t(i), &t(j)) / d.max(1e-9), i))
        .collect();
    let mut sorted: Vec<f64> = ratio.iter().map(|r| r.0).collect();
    sorted.sort_by(f64::total_cmp);
    println!(
        "{n} rows; nearest pose neighbour: median distance {:.2} mm-equivalent; bending tension change per mm-equivalent: median {:.3}, p99 {:.3}, max {:.3} N",
        {
            let mut d: Vec<f64> = nearest.iter().map(|x| x.1).collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        },
        sorted[n / 2],
        sorted[n * 99 / 100],
        sorted[n - 1]
    );
    ratio.sort_by(|a, b| b.0.total_cmp(&a.0));
    let ik = ExactIk::new(&robot, IkSettings::default());
    let mut branches = 0;
    for &(_, i) in ratio.iter().take(pairs) {
        let j = nearest[i].0;
        let mut pose = [0.0; 7];
        for (c, v) in pose.iter_mut().enumerate() {
            *v = data.poses[(j, c)];
        }
        let target = Target::from_pose(&pose, false)?;
        let (ti, tj) = (t(i), t(j));
        match ik.solve(&target, Some(&ti), None) {
            Ok(s) => {
                let to_j = bending_distance(&robot, &s.tensions, &tj);
                let reached =
                    s.position_error <= 1e-6 && s.orientation_error.unwrap_or(0.0) <= 1e-6;
                let branch = reached && to_j > 0.1 * robot.max_tensions()[0];
                branches += usize::from(branch);
                println!(
                    "row {j}'s pose from row {i}'s tensions (rows {:.2} mm-eq apart, {:.3} N): reached to {:.1e} m, {:.3} N from row {j}'s tensions{}",
                    nearest[i].1,
                    bending_distance(&robot, &ti, &tj),
                    s.position_error,
                    to_j,
                    if branch { " — another branch" } else { "" }
                );
            }
            Err(e) => println!("row {j}'s pose from row {i}'s tensions: {e}"),
        }
    }
    println!("{branches} of {pairs} poses have a second tension branch");
    Ok(())
}
