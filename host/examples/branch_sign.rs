//! Which IK branch is each row on? (issue 30, three segments.)
//!
//! For each row: the tip Jacobian ∂pose/∂τ (6 × tendons) times a fixed map
//! from per-group bending coordinates to tensions, a 6 × 6 matrix B; the
//! sign of det B says on which side of the fold the row lies. Writes the
//! rows of each sign to `OUT-pos.csv` / `OUT-neg.csv`.
//!
//! `cargo run --release -p tendril --example branch_sign -- ROBOT DATA.csv OUT`

use std::path::Path;

use nalgebra::DMatrix;
use rayon::prelude::*;
use tendril::dataset::Dataset;
use tendril::inverse::{ExactIk, IkSettings};
use tendril::robot::{anchor_groups, Robot};
use tendril::statics::{SolverSettings, Statics};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, robot, data, out] = args.as_slice() else {
        anyhow::bail!("usage: branch_sign ROBOT DATA.csv OUT");
    };
    let robot = Robot::load(Path::new(robot))?;
    let data = Dataset::read_csv(Path::new(data))?;
    let groups = anchor_groups(&robot);
    let n_t = robot.tendons.len();
    let dim = 2 * groups.len();
    // Bending coordinates → tensions: group g's 2-D moment direction m gives
    // tendon k the tension (2/3) d_k·m (least norm, no co-contraction).
    let mut p = DMatrix::zeros(n_t, dim);
    for (g, group) in groups.iter().enumerate() {
        for &k in group {
            let a = robot.tendons[k].angle;
            p[(k, 2 * g)] = 2.0 / 3.0 * a.cos();
            p[(k, 2 * g + 1)] = 2.0 / 3.0 * a.sin();
        }
    }
    let statics = Statics::new(&robot, SolverSettings::default());
    let ik = ExactIk::new(&robot, IkSettings::default());
    let n = data.tensions.nrows();
    let dets: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|r| {
            let t: Vec<f64> = data.tensions.row(r).iter().copied().collect();
            let s = statics.solve(&t, None).expect("statics");
            let j = ik.tip_jacobian_at(&t, &s.warm).expect("jacobian");
            let mut b = j * &p;
            // Position in mm, angle in degrees: one scale for the sign's sake.
            for c in 0..dim {
                for row in 0..3 {
                    b[(row, c)] *= 1e3;
                }
                for row in 3..6 {
                    b[(row, c)] = b[(row, c)].to_degrees();
                }
            }
            b.determinant()
        })
        .collect();
    let pos: Vec<usize> = (0..n).filter(|&r| dets[r] > 0.0).collect();
    let neg: Vec<usize> = (0..n).filter(|&r| dets[r] <= 0.0).collect();
    let mut abs: Vec<f64> = dets.iter().map(|d| d.abs()).collect();
    abs.sort_by(f64::total_cmp);
    println!(
        "{n} rows: det > 0 {}, det ≤ 0 {}; |det| p1 {:.3e}, median {:.3e}, p99 {:.3e}",
        pos.len(),
        neg.len(),
        abs[n / 100],
        abs[n / 2],
        abs[n * 99 / 100]
    );
    for (rows, tag) in [(pos, "pos"), (neg, "neg")] {
        let sub = Dataset {
            n_tendons: data.n_tendons,
            tensions: data.tensions.select_rows(rows.iter()),
            poses: data.poses.select_rows(rows.iter()),
        };
        sub.write_csv(Path::new(&format!("{out}-{tag}.csv")))?;
    }
    Ok(())
}
