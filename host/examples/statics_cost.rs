//! A fixed workload of cold and warm statics solves, for instruction counts
//! under `valgrind --tool=callgrind` (deterministic, unlike wall time on a
//! shared machine): `cargo build --release -p tendril --example statics_cost`
//! then `valgrind --tool=callgrind target/release/examples/statics_cost cold|warm|chain|multi|batch|uniform`
//! (multi: cold solves of the two-segment tdcr-2seg robot; batch: 600 uniform
//! rows through the batch fk call, one thread; uniform: the same rows solved
//! cold one by one, without the batch machinery). Optional further arguments:
//! a robot file and a step count, e.g. `cold bench/cpp-reference/till-4t.toml 20`.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use tendril::dataset::Sampler;
use tendril::robot::{repo_robot, Robot};
use tendril::statics::batch::{solve_all, Load};
use tendril::statics::{SolverSettings, Statics};

fn main() -> anyhow::Result<()> {
    let mode = std::env::args().nth(1).unwrap_or_else(|| "cold".into());
    // Optional: another robot file and step count (cold/warm modes).
    let file = std::env::args().nth(2);
    let steps = std::env::args().nth(3).map(|s| s.parse()).transpose()?;
    let robot = match (&file, mode.as_str()) {
        (Some(path), _) => Robot::load(Path::new(path))?,
        (None, "multi") => repo_robot("tdcr-2seg.toml"),
        (None, _) => repo_robot("seed-4t.toml"),
    };
    let settings = SolverSettings {
        steps: steps.unwrap_or(SolverSettings::default().steps),
        ..SolverSettings::default()
    };
    let statics = Statics::new(&robot, settings);
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
    if mode == "uniform" {
        // The batch's rows, each solved cold on its own: the yardstick of
        // "batch fk costs at most 1.3x a cold solve per row".
        let mut passes = 0.0;
        for tau in Sampler::Uniform.draw(600, &robot.max_tensions(), 5) {
            passes += statics.solve(&tau, None)?.integrations;
        }
        println!(
            "uniform: 600 cold solves, {:.2} integrations per solve",
            passes / 600.0
        );
        return Ok(());
    }
    let max = robot.max_tensions();
    if mode == "chain" {
        // A chain of warm solves, each 0.1 N from the last on a tendon
        // picked by a fixed pseudo-random walk (a plant, a path), started
        // once with dx/dτ: what `Statics::add_tension_sensitivity` is for.
        let mut tau = vec![4.0, 3.0, 0.0, 0.0];
        tau.truncate(max.len());
        tau.resize(max.len(), 0.0);
        let mut prev = statics.solve(&tau, None)?;
        let predict = std::env::args().nth(4).as_deref() != Some("no-predict");
        if predict {
            statics.add_tension_sensitivity(&mut prev);
        }
        let mut state = 12345u64;
        let (mut integrations, solves) = (0.0, 200);
        for _ in 0..solves {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let i = (state >> 33) as usize % tau.len();
            let up = (state >> 40) & 1 == 1;
            tau[i] = (tau[i] + if up { 0.1 } else { -0.1 }).clamp(0.0, max[i]);
            let sol = statics.solve(&tau, Some(&prev.warm))?;
            integrations += sol.integrations;
            prev = sol;
        }
        println!(
            "chain: {solves} solves, {:.2} integrations per solve",
            integrations / solves as f64
        );
        return Ok(());
    }
    let cases = Sampler::Adjacent.draw(100, &max, 3);
    let (mut solves, mut integrations) = (0usize, 0.0);
    for t in &cases {
        let first = statics.solve(t, None)?;
        if mode == "warm" {
            let mut next = t.clone();
            let i = next.iter().position(|&x| x > 0.0).unwrap_or(0);
            next[i] += if next[i] + 0.1 <= max[i] { 0.1 } else { -0.1 };
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
