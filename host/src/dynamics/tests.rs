//! Checks of the dynamics against independent facts (`docs/design.md` §4.2):
//! the statics as the rest state, the Euler–Bernoulli cantilever modes, the
//! BDF-α scheme's numerical damping and order, and the equilibrium a damped
//! run comes to.

use nalgebra::{DMatrix, DVector, Vector3};

use super::*;
use crate::robot::{repo_robot as robot, Robot};
use crate::statics::{SolverSettings, Statics};

fn statics_tip(robot: &Robot, steps: usize, tensions: &[f64]) -> Vector3<f64> {
    let statics = Statics::new(
        robot,
        SolverSettings {
            steps,
            ..SolverSettings::default()
        },
    );
    statics.solve(tensions, None).unwrap().position
}

/// Frequencies (Hz) and per-sample moduli |z| of the damped sinusoids that
/// make up `x` (sampled every `dt_s`), by Prony's method: a linear predictor
/// of `order` fitted in least squares, its characteristic roots z = e^{(σ+iω)dt}.
fn prony(x: &[f64], dt_s: f64, order: usize) -> Vec<(f64, f64)> {
    let rows = x.len() - order;
    let a = DMatrix::from_fn(rows, order, |i, j| x[i + order - 1 - j]);
    let b = DVector::from_fn(rows, |i, _| x[i + order]);
    let coeffs = a.svd(true, true).solve(&b, 1e-14).unwrap();
    let companion = DMatrix::from_fn(order, order, |i, j| {
        if i == 0 {
            coeffs[j]
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    let mut modes: Vec<(f64, f64)> = companion
        .complex_eigenvalues()
        .iter()
        .filter(|z| z.im > 0.0)
        .map(|z| (z.arg() / (2.0 * std::f64::consts::PI * dt_s), z.norm()))
        .collect();
    modes.sort_by(|a, b| a.0.total_cmp(&b.0));
    modes
}

/// Smooth step from 0 to 1 over `ramp_s` (raised cosine): it excites the
/// modes far below 1/ramp_s and hardly any above, so the response is one
/// the time step resolves.
fn smooth_step(t_s: f64, ramp_s: f64) -> f64 {
    if t_s >= ramp_s {
        1.0
    } else {
        0.5 * (1.0 - (std::f64::consts::PI * t_s / ramp_s).cos())
    }
}

/// Released over this long: the cantilever's free vibration starts after it.
const RELEASE_S: f64 = 0.01;

/// The seed backbone without gravity or tendons, held by a small tip force
/// along x, released (the force ramped to zero over [`RELEASE_S`]):
/// the tip's x after the release, every `stride` steps. Material damping
/// B = t_r K with t_r = `retardation_s` (0: none).
fn free_vibration(
    settings: DynamicsSettings,
    retardation_s: f64,
    duration_s: f64,
    stride: usize,
) -> Vec<f64> {
    let seed = robot("seed-4t.toml").without_gravity();
    // 2 mm static tip deflection: F = 3 EI δ / L³.
    let force = 3.0 * seed.kbt().x * 2e-3 / seed.length.powi(3);
    let mut dynamics = Dynamics::at_rest(
        &seed,
        Damping::proportional(&seed, retardation_s),
        settings,
        &[0.0; 4],
        Vector3::new(force, 0.0, 0.0),
        Vector3::zeros(),
    )
    .unwrap();
    let release = (RELEASE_S / settings.dt_s).round() as usize;
    let steps = (duration_s / settings.dt_s).round() as usize;
    let mut out = Vec::new();
    for k in 1..=release + steps {
        let held = 1.0 - smooth_step(k as f64 * settings.dt_s, RELEASE_S);
        dynamics
            .set_tip_load(Vector3::new(force * held, 0.0, 0.0), Vector3::zeros())
            .unwrap();
        let tip = dynamics.step(&[0.0; 4]).unwrap();
        if k >= release && (k - release).is_multiple_of(stride) {
            out.push(tip.position.x);
        }
    }
    out
}

#[test]
fn rest_state_is_the_statics_solution_also_across_inner_anchors() {
    // The dynamic equations with c₀ = 0 and no history are the statics; the
    // initial solve polishes the statics' base unknowns with this module's
    // own integrator, so any term that differs moves the tip.
    for (name, tensions) in [
        ("seed-4t.toml", vec![3.0, 1.0, 0.0, 0.0]),
        ("tdcr-2seg.toml", vec![0.0, 2.0, 0.0, 1.0, 0.0, 1.0]),
    ] {
        let robot = robot(name);
        let settings = DynamicsSettings::default();
        let dynamics = Dynamics::at_rest(
            &robot,
            Damping::of_robot(&robot),
            settings,
            &tensions,
            Vector3::zeros(),
            Vector3::zeros(),
        )
        .unwrap();
        let gap = (dynamics.tip().position - statics_tip(&robot, settings.steps, &tensions)).norm();
        assert!(gap < 1e-9, "{name}: rest tip {gap:.2e} m from the statics");
    }
}

#[test]
fn undamped_cantilever_rings_at_its_euler_bernoulli_frequencies() {
    // docs/design.md §4.2: f₁ = 3.611 Hz, f₂ = 22.63 Hz. BDF-α's own period
    // error grows as δt² (0.46 % at f₂ for δt = 1 ms); shorter steps make the
    // undamped shooting problem too stiff for double precision (see
    // `solver`). So measure at δt = 2 ms and 1 ms and extrapolate to δt → 0
    // as a second-order scheme converges: f = (4 f(δt/2) − f(δt)) / 3.
    let measure = |dt_s: f64| {
        let settings = DynamicsSettings {
            dt_s,
            ..DynamicsSettings::default()
        };
        let stride = (2e-3 / dt_s).round() as usize;
        let x = free_vibration(settings, 0.0, 0.8, stride);
        let modes = prony(&x, settings.dt_s * stride as f64, 8);
        (modes[0].0, modes[1].0)
    };
    let (coarse, fine) = (measure(2e-3), measure(1e-3));
    let f1 = (4.0 * fine.0 - coarse.0) / 3.0;
    let f2 = (4.0 * fine.1 - coarse.1) / 3.0;
    eprintln!(
        "free vibration: dt 2 ms {coarse:.4?} Hz, 1 ms {fine:.4?} Hz, extrapolated f1 = {f1:.4} Hz, f2 = {f2:.4} Hz"
    );
    assert!((f1 / 3.611 - 1.0).abs() < 5e-3, "f1 = {f1} Hz");
    assert!((f2 / 22.63 - 1.0).abs() < 5e-3, "f2 = {f2} Hz");
}

#[test]
fn first_mode_loses_under_one_percent_per_period_to_numerical_damping() {
    // Material damping off, δt = 1 ms: only BDF-α's own damping remains
    // (ω δt ≈ 0.023 for the first mode).
    let settings = DynamicsSettings::default();
    let stride = 2;
    let x = free_vibration(settings, 0.0, 0.8, stride);
    let modes = prony(&x, settings.dt_s * stride as f64, 8);
    let (f1, modulus) = modes[0];
    let samples_per_period = 1.0 / (f1 * settings.dt_s * stride as f64);
    let decay = 1.0 - modulus.powf(samples_per_period);
    eprintln!(
        "numerical damping at alpha = {}: first mode ({f1:.4} Hz) decays {:.4} % per period",
        settings.alpha,
        decay * 100.0
    );
    assert!(decay < 0.01, "decay per period {decay}");
}

#[test]
fn stiffness_proportional_damping_gives_the_first_mode_zeta_of_omega_tr_over_two() {
    // Kelvin–Voigt damping B = t_r K is stiffness-proportional (Rayleigh)
    // damping: every mode keeps its shape and gets ζ = ω t_r / 2. For the
    // default t_r and the Euler–Bernoulli ω₁ = 2π · 3.611 Hz that is ζ₁ ≈ 0.168.
    let settings = DynamicsSettings::default();
    let stride = 2;
    let x = free_vibration(settings, Damping::DEFAULT_RETARDATION_S, 0.8, stride);
    let sample_s = settings.dt_s * stride as f64;
    let (f1, modulus) = prony(&x, sample_s, 8)[0];
    let sigma = modulus.ln() / sample_s;
    let omega_d = 2.0 * std::f64::consts::PI * f1;
    let zeta = -sigma / (sigma * sigma + omega_d * omega_d).sqrt();
    let expected = 2.0 * std::f64::consts::PI * 3.611 * Damping::DEFAULT_RETARDATION_S / 2.0;
    eprintln!("default damping: first mode {f1:.4} Hz (damped), zeta {zeta:.4}, closed form {expected:.4}");
    assert!(
        (zeta / expected - 1.0).abs() < 0.02,
        "zeta1 {zeta:.4}, closed form {expected:.4}"
    );
}

#[test]
fn robot_file_damping_keys_reach_the_dynamics() {
    let seed = robot("seed-4t.toml");
    assert_eq!(
        Damping::of_robot(&seed),
        Damping::proportional(&seed, Damping::DEFAULT_RETARDATION_S)
    );
    let with = |keys| Robot {
        damping: Some(keys),
        ..seed.clone()
    };
    assert_eq!(
        Damping::of_robot(&with(crate::robot::DampingKeys::Retardation(0.01))),
        Damping::proportional(&seed, 0.01)
    );
    let diagonals = crate::robot::DampingKeys::Diagonals {
        bse: [0.0; 3],
        bbt: [5e-4, 5e-4, 4e-4],
    };
    assert_eq!(
        Damping::of_robot(&with(diagonals)),
        Damping {
            bse: Vector3::zeros(),
            bbt: Vector3::new(5e-4, 5e-4, 4e-4),
        }
    );
}

#[test]
fn halving_the_time_step_shrinks_the_error_fourfold_as_bdf2_predicts() {
    // α = 0 is BDF2, second order: the trajectory's change from δt to δt/2
    // is four times its change from δt/2 to δt/4. A smooth 50 ms tension
    // ramp on the seed robot (gravity on, default damping) keeps the
    // response within what the coarsest step resolves.
    let seed = robot("seed-4t.toml");
    let run = |dt_s: f64| {
        let settings = DynamicsSettings {
            dt_s,
            alpha: 0.0,
            ..DynamicsSettings::default()
        };
        let mut dynamics = Dynamics::at_rest(
            &seed,
            Damping::of_robot(&seed),
            settings,
            &[0.0; 4],
            Vector3::zeros(),
            Vector3::zeros(),
        )
        .unwrap();
        let stride = (4e-3 / dt_s).round() as usize;
        let mut out = Vec::new();
        for k in 1..=(0.2 / dt_s).round() as usize {
            let tau = 2.0 * smooth_step(k as f64 * dt_s, 0.05);
            let tip = dynamics.step(&[tau, 0.0, 0.0, 0.0]).unwrap();
            if k.is_multiple_of(stride) {
                out.push(tip.position);
            }
        }
        out
    };
    let (coarse, mid, fine) = (run(4e-3), run(2e-3), run(1e-3));
    let gap = |a: &[Vector3<f64>], b: &[Vector3<f64>]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max)
    };
    let ratio = gap(&coarse, &mid) / gap(&mid, &fine);
    eprintln!(
        "time-step convergence: max tip change {:.3e} m (4 -> 2 ms), {:.3e} m (2 -> 1 ms), ratio {ratio:.3} (2nd order: 4)",
        gap(&coarse, &mid),
        gap(&mid, &fine)
    );
    assert!((3.3..4.7).contains(&ratio), "ratio {ratio}");
}

/// A step of the tensions from rest at zero, run with strong damping until
/// it settles: the tip must come to the statics equilibrium.
fn settles_to_statics(name: &str, tensions: &[f64], duration_s: f64) {
    let robot = robot(name);
    let settings = DynamicsSettings {
        dt_s: 2e-3,
        ..DynamicsSettings::default()
    };
    let zero = vec![0.0; tensions.len()];
    // Retardation 60 ms: the first mode near critical damping, so the run
    // settles within a second or two.
    let mut dynamics = Dynamics::at_rest(
        &robot,
        Damping::proportional(&robot, 0.06),
        settings,
        &zero,
        Vector3::zeros(),
        Vector3::zeros(),
    )
    .unwrap();
    let steps = (duration_s / settings.dt_s).round() as usize;
    let mut peak_speed: f64 = 0.0;
    for _ in 0..steps {
        peak_speed = peak_speed.max(dynamics.step(tensions).unwrap().velocity.norm());
    }
    let tip = dynamics.tip();
    let gap = (tip.position - statics_tip(&robot, settings.steps, tensions)).norm();
    eprintln!(
        "{name}: after {duration_s} s the tip is {gap:.2e} m from statics (peak speed {peak_speed:.3} m/s)"
    );
    assert!(peak_speed > 0.01, "the step did not move the robot");
    assert!(
        gap < 1e-6,
        "{name}: {gap:.3e} m from the statics equilibrium"
    );
}

#[test]
fn damped_step_response_comes_to_the_statics_equilibrium() {
    settles_to_statics("seed-4t.toml", &[2.0, 0.0, 0.0, 0.0], 1.5);
}

#[test]
fn two_segment_step_response_comes_to_the_statics_equilibrium() {
    settles_to_statics("tdcr-2seg.toml", &[0.0, 2.0, 0.0, 1.0, 0.0, 1.0], 2.0);
}

#[test]
fn bad_settings_and_tensions_are_errors() {
    let seed = robot("seed-4t.toml");
    let start = |settings| {
        Dynamics::at_rest(
            &seed,
            Damping::of_robot(&seed),
            settings,
            &[0.0; 4],
            Vector3::zeros(),
            Vector3::zeros(),
        )
    };
    for settings in [
        DynamicsSettings {
            dt_s: 0.0,
            ..DynamicsSettings::default()
        },
        DynamicsSettings {
            alpha: 0.3,
            ..DynamicsSettings::default()
        },
    ] {
        assert!(matches!(
            start(settings),
            Err(DynamicsError::BadSettings(_))
        ));
    }
    let mut dynamics = start(DynamicsSettings::default()).unwrap();
    assert!(dynamics.step(&[f64::NAN, 0.0, 0.0, 0.0]).is_err());
    assert!(dynamics.step(&[1.0, 0.0]).is_err());
    // A rejected step leaves the state where it was.
    assert_eq!(dynamics.tip().time_s, 0.0);
}

#[test]
fn with_a_friction_profile_the_step_response_settles_to_the_friction_statics() {
    // The dynamic rod takes the statics' capstan profile (docs/design.md
    // §2.3): held at the converged profile of the friction statics, the
    // damped step response must come to that equilibrium, not to the
    // frictionless one (2.4 mm away at μ = 0.3).
    use crate::statics::{Friction, FrictionState};
    let robot = robot("seed-4t.toml");
    let settings = DynamicsSettings {
        dt_s: 2e-3,
        ..DynamicsSettings::default()
    };
    let tensions = [4.0, 0.0, 0.0, 0.0];
    let statics = Statics::new(
        &robot,
        SolverSettings {
            steps: settings.steps,
            ..SolverSettings::default()
        },
    );
    let mut friction = FrictionState::new(Friction::new(0.3), 4);
    friction.update_direction(&tensions);
    let sol = friction.solve(&statics, &tensions, None).unwrap();
    let frictionless = statics.solve(&tensions, None).unwrap().position;
    let mut dynamics = Dynamics::at_rest(
        &robot,
        Damping::proportional(&robot, 0.06),
        settings,
        &[0.0; 4],
        Vector3::zeros(),
        Vector3::zeros(),
    )
    .unwrap();
    dynamics.set_friction_profile(sol.profile().cloned());
    for _ in 0..(1.5 / settings.dt_s).round() as usize {
        dynamics.step(&tensions).unwrap();
    }
    let gap = (dynamics.tip().position - sol.position).norm();
    let apart = (frictionless - sol.position).norm();
    eprintln!("friction: settled {gap:.2e} m from the friction statics, {apart:.2e} m from the frictionless");
    assert!(apart > 1e-4, "friction moves the tip only {apart:e} m");
    assert!(
        gap < 1e-6,
        "{gap:.3e} m from the friction statics equilibrium"
    );
}
