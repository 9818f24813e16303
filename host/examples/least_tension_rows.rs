//! Re-solve each row's tip position for the least total tension or the
//! least bending effort (issue 30, three segments): the position-resolved
//! families `tendril generate --resolve` chooses between, for measuring what
//! each costs a learner (`tendril generate` does the second itself).
//!
//! `cargo run --release -p tendril --example least_tension_rows -- ROBOT DATA.csv OUT.csv [rows]`

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use tendril::dataset::Dataset;
use tendril::inverse::{ExactIk, IkSettings, Redundancy, Target};
use tendril::robot::Robot;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, robot, data, out, mode, rest @ ..] = args.as_slice() else {
        anyhow::bail!("usage: least_tension_rows ROBOT DATA.csv OUT.csv total|bending [rows]");
    };
    let redundancy = match mode.as_str() {
        "total" => Redundancy::LeastTotal,
        "bending" => Redundancy::LeastBending,
        other => anyhow::bail!("unknown objective {other}"),
    };
    let robot = Robot::load(Path::new(robot))?;
    let data = Dataset::read_csv(Path::new(data))?;
    let n = rest
        .first()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(data.tensions.nrows())
        .min(data.tensions.nrows());
    let ik = ExactIk::new(
        &robot,
        IkSettings {
            redundancy,
            ..IkSettings::default()
        },
    );
    let failed = AtomicUsize::new(0);
    let t0 = std::time::Instant::now();
    let rows: Vec<Option<(Vec<f64>, [f64; 7])>> = (0..n)
        .into_par_iter()
        .map(|r| {
            let p = data.poses.row(r);
            let target = Target::Position(Vector3::new(p[0], p[1], p[2]));
            match ik.solve(&target, None, None) {
                Ok(s) if s.position_error <= 1e-7 => Some((s.tensions, s.pose)),
                _ => {
                    failed.fetch_add(1, Ordering::Relaxed);
                    None
                }
            }
        })
        .collect();
    let kept: Vec<(Vec<f64>, [f64; 7])> = rows.into_iter().flatten().collect();
    println!(
        "{n} rows re-solved in {:.1} s, {} failed",
        t0.elapsed().as_secs_f64(),
        failed.load(Ordering::Relaxed)
    );
    let m = kept.len();
    let out_data = Dataset {
        n_tendons: data.n_tendons,
        tensions: DMatrix::from_fn(m, data.n_tendons, |r, c| kept[r].0[c]),
        poses: DMatrix::from_fn(m, 7, |r, c| kept[r].1[c]),
    };
    out_data.write_csv(Path::new(out))?;
    Ok(())
}
