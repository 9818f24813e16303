//! A fixed workload of cold and warm statics solves, for instruction counts
//! under `valgrind --tool=callgrind` (deterministic, unlike wall time on a
//! shared machine): `cargo build --release -p tendril --example statics_cost`
//! then `valgrind --tool=callgrind target/release/examples/statics_cost cold|warm|chain|multi|batch|uniform`
//! (multi: cold solves of the two-segment tdcr-2seg robot; batch: 600 uniform
//! rows through the batch fk call, one thread; uniform: the same rows solved
//! cold one by one, without the batch machinery; tips: the chain's tips
//! against tight and 1024-step solves, printed, for "equal accuracy"
//! against the C++ reference; point: the criterion bench's warm solve, 1000
//! times). Optional further arguments: a robot file and a
//! step count, e.g. `cold bench/cpp-reference/till-4t.toml 20`, and anywhere
//! after the mode the flags `tol=<N>` (the solver's residual tolerance),
//! `final=<m>` (`SolverSettings::final_step_m`: a warm solve may end on an
//! unverified chord step moving the tip at most this), `start=<t1,t2,..>`
//! (the chain's first tensions, default 4,3,0,0) and
//! `no-predict` (chain: no dx/dτ).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use tendril::dataset::Sampler;
use tendril::robot::{repo_robot, Robot};
use tendril::statics::batch::{solve_all, Load};
use tendril::statics::{walk_step, SolverSettings, Statics};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).cloned().unwrap_or_else(|| "cold".into());
    // Flags anywhere after the mode; the rest are positional.
    let flag = |name: &str| {
        args.iter()
            .skip(2)
            .find_map(|a| a.strip_prefix(name).map(str::to_owned))
    };
    let predict = !args.iter().skip(2).any(|a| a == "no-predict");
    let tol: Option<f64> = flag("tol=").map(|s| s.parse()).transpose()?;
    let final_step: Option<f64> = flag("final=").map(|s| s.parse()).transpose()?;
    let start: Option<Vec<f64>> = flag("start=")
        .map(|s| s.split(',').map(str::parse).collect())
        .transpose()?;
    let positional: Vec<&String> = args
        .iter()
        .skip(2)
        .filter(|a| !a.contains('=') && *a != "no-predict")
        .collect();
    // Optional: another robot file and step count (cold/warm modes).
    let file = positional.first().map(|s| s.to_string());
    let steps = positional.get(1).map(|s| s.parse()).transpose()?;
    let robot = match (&file, mode.as_str()) {
        (Some(path), _) => Robot::load(Path::new(path))?,
        (None, "multi") => repo_robot("tdcr-2seg.toml"),
        (None, _) => repo_robot("seed-4t.toml"),
    };
    let settings = SolverSettings {
        steps: steps.unwrap_or(SolverSettings::default().steps),
        tol: tol.unwrap_or(SolverSettings::default().tol),
        final_step_m: final_step.unwrap_or_default(),
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
    let mut first = start.unwrap_or_else(|| vec![4.0, 3.0, 0.0, 0.0]);
    first.truncate(max.len());
    first.resize(max.len(), 0.0);
    if mode == "tips" {
        return tips(&robot, &statics, &first);
    }
    if mode == "point" {
        // The criterion bench's warm solve, repeated: 0.1 N up on the first
        // tendon from the cold solve at `first` (with dx/dτ unless
        // `no-predict`), for instruction counts of exactly that solve.
        let mut prev = statics.solve(&first, None)?;
        if predict {
            statics.add_tension_sensitivity(&mut prev);
        }
        let mut next = first.clone();
        next[0] += if first[0] + 0.1 <= max[0] { 0.1 } else { -0.1 };
        let (solves, mut integrations) = (1000, 0.0);
        for _ in 0..solves {
            integrations += statics.solve(&next, Some(&prev.warm))?.integrations;
        }
        println!(
            "point: {solves} solves, {:.2} integrations per solve",
            integrations / solves as f64
        );
        return Ok(());
    }
    if mode == "chain" {
        // A chain of warm solves, each 0.1 N from the last on a tendon
        // picked by a fixed pseudo-random walk (a plant, a path), started
        // once with dx/dτ: what `Statics::add_tension_sensitivity` is for.
        let mut tau = first;
        let mut prev = statics.solve(&tau, None)?;
        if predict {
            statics.add_tension_sensitivity(&mut prev);
        }
        let mut state = 12345u64;
        let (mut integrations, solves) = (0.0, 200);
        for _ in 0..solves {
            walk_step(&mut state, &mut tau, &max);
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

/// The tips "equal accuracy" is judged by: at the solver's settings, the
/// warm solve 0.1 N up from `first` (from the cold solve's warm start, with
/// and without dx/dτ), then the chain's 200 warm solves with dx/dτ carried and
/// without; each against the same grid solved tight (stopping error) and 1024
/// steps solved tight (the converged answer). One line per point
/// (`bench`/`chain`, tensions, then the tips in m, each x y z: predicted,
/// no-predict, tight, 1024-step, then the plain-pass equivalents of the
/// predicted and no-predict solves), then the largest errors.
fn tips(robot: &Robot, statics: &Statics, first: &[f64]) -> anyhow::Result<()> {
    let tight_settings = |steps| SolverSettings {
        steps,
        tol: 1e-12,
        ..SolverSettings::default()
    };
    let tight = Statics::new(robot, tight_settings(statics.settings().steps));
    let fine = Statics::new(robot, tight_settings(1024));
    let max = robot.max_tensions();
    let cold = statics.solve(first, None)?;
    let mut predicted = cold.clone();
    statics.add_tension_sensitivity(&mut predicted);
    let mut plain = cold;
    let mut tight_prev = tight.solve(first, None)?;
    let mut fine_prev = fine.solve(first, None)?;
    // Largest |tip − reference| of (predicted, no-predict) against (tight, 1024).
    let mut worst = [[0.0f64; 2]; 2];
    let mut tau = first.to_vec();
    let mut state = 12345u64;
    for k in 0..=200 {
        let what = if k == 0 { "bench" } else { "chain" };
        if k == 0 {
            tau[0] += if tau[0] + 0.1 <= max[0] { 0.1 } else { -0.1 };
        } else {
            if k == 1 {
                tau = first.to_vec();
            }
            walk_step(&mut state, &mut tau, &max);
        }
        let p = statics.solve(&tau, Some(&predicted.warm))?;
        let n = statics.solve(&tau, Some(&plain.warm))?;
        let t = tight.solve(&tau, Some(&tight_prev.warm))?;
        let f = fine.solve(&tau, Some(&fine_prev.warm))?;
        let mut line = what.to_string();
        for v in &tau {
            line += &format!(" {v}");
        }
        for s in [&p, &n, &t, &f] {
            for c in s.position.iter() {
                line += &format!(" {c:.17e}");
            }
        }
        line += &format!(" passes {:.2} {:.2}", p.integrations, n.integrations);
        println!("{line}");
        for (i, s) in [&p, &n].into_iter().enumerate() {
            for (j, r) in [&t, &f].into_iter().enumerate() {
                worst[i][j] = worst[i][j].max((s.position - r.position).norm());
            }
        }
        if k == 0 {
            // The chain starts again from the first point's cold solves.
            continue;
        }
        predicted = p;
        plain = n;
        tight_prev = t;
        fine_prev = f;
    }
    println!(
        "worst tip error, tol {:e}, {} steps: predicted {:.2e} m (vs tight) {:.2e} m (vs 1024); \
         no-predict {:.2e} m {:.2e} m",
        statics.settings().tol,
        statics.settings().steps,
        worst[0][0],
        worst[0][1],
        worst[1][0],
        worst[1][1]
    );
    Ok(())
}
