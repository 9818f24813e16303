//! A fixed workload of cold and warm statics solves, for instruction counts
//! under `valgrind --tool=callgrind` (deterministic, unlike wall time on a
//! shared machine): `cargo build --release -p tendril --example statics_cost`
//! then `valgrind --tool=callgrind target/release/examples/statics_cost cold|warm|multi|batch`
//! (multi: cold solves of the two-segment tdcr-2seg robot; batch: 600 uniform
//! rows through the batch fk call, one thread).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use tendril::dataset::Sampler;
use tendril::robot::Robot;
use tendril::statics::batch::{solve_all, Load};
use tendril::statics::{SolverSettings, Statics};

fn main() -> anyhow::Result<()> {
    let mode = std::env::args().nth(1).unwrap_or_else(|| "cold".into());
    let file = if mode == "multi" {
        "tdcr-2seg.toml"
    } else {
        "seed-4t.toml"
    };
    let robot = Robot::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../robots")
            .join(file),
    )?;
    let statics = Statics::new(&robot, SolverSettings::default());
    if mode == "batch" {
        let loads: Vec<Load> = Sampler::Uniform
            .draw(600, &robot.max_tensions(), 5)
            .into_iter()
            .map(Load::tensions)
            .collect();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
        let stop = AtomicBool::new(false);
        let results = pool
            .install(|| solve_all(&statics, &loads, &stop, &|_| {}))
            .unwrap_or_default();
        let passes: f64 = results.iter().flatten().map(|s| s.integrations).sum();
        println!(
            "batch: {} rows, {:.2} integrations per row",
            results.len(),
            passes / 600.0
        );
        return Ok(());
    }
    let cases = Sampler::Adjacent.draw(100, &robot.max_tensions(), 3);
    let (mut solves, mut integrations) = (0usize, 0.0);
    for t in &cases {
        let first = statics.solve(t, None)?;
        if mode == "warm" {
            let mut next = t.clone();
            let i = next.iter().position(|&x| x > 0.0).unwrap_or(0);
            next[i] += if next[i] + 0.1 <= 10.0 { 0.1 } else { -0.1 };
            let sol = statics.solve(&next, Some(&first.warm))?;
            integrations += sol.integrations;
        } else {
            integrations += first.integrations;
        }
        solves += 1;
    }
    println!(
        "{mode}: {solves} solves, {:.2} integrations per solve",
        integrations / solves as f64
    );
    Ok(())
}
