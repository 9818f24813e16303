//! Per-step timing of the dynamic plant (issue 29 item 3b): the seed robot,
//! 16 RK4 steps, default damping, δt = 1 ms, the tensions following the
//! 30 mm circle at 0.2 Hz as `benches/dynamics.rs` does. Each step is timed
//! on its own with `Instant`, so the p50 and p99 are of steps, not of
//! criterion's sample means.
//!
//! `cargo run --release -p tendril --example dynamics_steps -- [steps] [tip.csv] [coarsening]`
//! (`-` for no CSV; coarsening: the Jacobian's, default the settings').
//!
//! Prints p50 / p99 / max step time, wall clock and the thread's CPU time
//! (on a shared machine the wall clock's tail is mostly other processes'
//! time slices; the CPU time is what the step itself costs), and rod passes
//! per step (mean, max);
//! with a CSV path, writes the tip position of every step (t, x, y, z), so two
//! builds' trajectories can be compared.

use std::io::Write;
use std::time::Instant;

use nalgebra::Vector3;
use tendril::dynamics::{Damping, Dynamics, DynamicsSettings};
use tendril::robot::repo_robot;
use tendril::statics::{SolverSettings, Statics};

#[path = "../benches/workloads/circle.rs"]
mod workloads;

fn main() -> anyhow::Result<()> {
    let n: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(5000);
    let csv = std::env::args().nth(2).filter(|f| f != "-");
    let mut settings = DynamicsSettings::default();
    if let Some(c) = std::env::args().nth(3) {
        settings.jacobian_coarsening = c.parse()?;
    }
    let robot = repo_robot("seed-4t.toml");
    let statics = Statics::new(&robot, SolverSettings::default());
    // The bench's path: the 30 mm circle at 0.2 Hz, sampled every 1 ms.
    let path = workloads::circle_tensions(&statics, n + 1);
    let mut dynamics = Dynamics::at_rest(
        &robot,
        Damping::of_robot(&robot),
        settings,
        &path[0],
        Vector3::zeros(),
        Vector3::zeros(),
    )?;
    let mut times = Vec::with_capacity(n);
    let mut cpu = Vec::with_capacity(n);
    let mut passes = Vec::with_capacity(n);
    let mut coarse = Vec::with_capacity(n);
    let mut tips = Vec::with_capacity(n);
    for tensions in &path[1..] {
        let before = dynamics.passes();
        let coarse_before = dynamics.coarse_passes();
        let start = Instant::now();
        let cpu_start = thread_cpu_us();
        let tip = dynamics.step(tensions)?;
        cpu.push(thread_cpu_us() - cpu_start);
        times.push(start.elapsed().as_secs_f64() * 1e6);
        passes.push(dynamics.passes() - before);
        coarse.push(dynamics.coarse_passes() - coarse_before);
        tips.push(tip);
    }
    let mean_passes = passes.iter().sum::<u64>() as f64 / n as f64;
    for (name, t) in [("wall", &times), ("cpu", &cpu)] {
        let mut sorted = t.clone();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((q * n as f64) as usize).min(n - 1)];
        println!(
            "{n} steps, {name}: p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs",
            at(0.5),
            at(0.99),
            sorted[n - 1],
        );
    }
    println!(
        "passes per step: mean {mean_passes:.2}, max {}; coarse (Jacobian) passes: mean {:.2}, max {}",
        passes.iter().max().unwrap_or(&0),
        coarse.iter().sum::<u64>() as f64 / n as f64,
        coarse.iter().max().unwrap_or(&0)
    );
    // How many steps spent how many passes, and their median time.
    let most = *passes.iter().max().unwrap_or(&0) as usize;
    for count in 0..=most {
        let mut t: Vec<f64> = (0..n)
            .filter(|&i| passes[i] as usize == count)
            .map(|i| times[i])
            .collect();
        if !t.is_empty() {
            t.sort_by(f64::total_cmp);
            println!(
                "  {count:2} passes: {:5} steps, p50 {:.1} µs",
                t.len(),
                t[t.len() / 2]
            );
        }
    }
    if let Some(file) = csv {
        let mut out = std::io::BufWriter::new(std::fs::File::create(file)?);
        writeln!(out, "t_s,x_m,y_m,z_m")?;
        for tip in &tips {
            let p = tip.position;
            writeln!(out, "{},{:e},{:e},{:e}", tip.time_s, p.x, p.y, p.z)?;
        }
    }
    Ok(())
}

/// This thread's CPU time, µs (`CLOCK_THREAD_CPUTIME_ID`): excludes the time
/// slices other processes take on a shared machine.
fn thread_cpu_us() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the call's duration.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 * 1e6 + ts.tv_nsec as f64 * 1e-3
}
