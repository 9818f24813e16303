//! Tip error of the RK4 discretisation against a 1024-step reference, over a
//! spread of tensions of the default robot: picks `SolverSettings::steps`.
//! Run: `cargo run --release -p tendril --example discretisation`.

use tendril::dataset::Sampler;
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

fn main() -> anyhow::Result<()> {
    let robot = repo_robot("seed-4t.toml");
    let mut cases = Sampler::Adjacent.draw(200, &robot.max_tensions(), 7);
    cases.push(vec![10.0, 10.0, 0.0, 0.0]);
    let fine = Statics::new(
        &robot,
        SolverSettings {
            steps: 1024,
            ..Default::default()
        },
    );
    let reference: Vec<_> = cases
        .iter()
        .map(|t| fine.solve(t, None))
        .collect::<Result<_, _>>()?;
    println!("steps  max tip error [m]  mean tip error [m]");
    for steps in [8, 12, 16, 20, 24, 32, 40] {
        let s = Statics::new(
            &robot,
            SolverSettings {
                steps,
                ..Default::default()
            },
        );
        let errs: Vec<f64> = cases
            .iter()
            .zip(&reference)
            .map(|(t, r)| {
                s.solve(t, None)
                    .map(|sol| (sol.position - r.position).norm())
            })
            .collect::<Result<_, _>>()?;
        let max = errs.iter().cloned().fold(0.0, f64::max);
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        println!("{steps:5}  {max:17.3e}  {mean:18.3e}");
    }
    let s = Statics::new(&robot, SolverSettings::default());
    println!("\nintegrations per solve (16 steps): case, cold, warm (one tension +-0.1 N)");
    for t in [
        [4.0, 3.0, 0.0, 0.0],
        [10.0, 10.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 7.0, 1.0],
    ] {
        let cold = s.solve(&t, None)?;
        let mut next = t;
        next[0] += if t[0] + 0.1 <= 10.0 { 0.1 } else { -0.1 };
        let warm = s.solve(&next, Some(&cold.warm))?;
        println!(
            "{t:?}: {} ({} it), {} ({} it)",
            cold.integrations, cold.iterations, warm.integrations, warm.iterations
        );
    }
    Ok(())
}
