//! Checks of the capstan friction (`docs/design.md` §2.3) against
//! independent facts: the closed-form capstan cantilever, the exact angle of
//! a constant-curvature arc, the frictionless solve, global force
//! equilibrium at the base, and the direction of the hysteresis loop.

use std::sync::Arc;

use nalgebra::Vector3;

use crate::robot::{repo_robot as load, Robot};
use crate::statics::friction::tendon_angles;
use crate::statics::profile::PROFILE_INTERVALS;
use crate::statics::*;

fn with_steps(steps: usize) -> SolverSettings {
    SolverSettings {
        steps,
        ..SolverSettings::default()
    }
}

/// The tip's rotation angle about +y (the plane x–z the tendon at +x bends in).
fn tip_angle(sol: &Solution) -> f64 {
    let r = &sol.rotation;
    r[(0, 2)].atan2(r[(2, 2)])
}

/// A friction state of one tendon driven to `motor` with direction `sigma`
/// = ±1: from the rest (0 N) straight up (pulling), or from above down
/// (releasing).
fn driven(mu: f64, motor: f64, sigma: f64) -> FrictionState {
    let mut state = FrictionState::new(Friction::new(mu), 1);
    if sigma < 0.0 {
        state.update_direction(&[motor + 1.0]);
    }
    state.update_direction(&[motor]);
    assert_eq!(state.direction(), &[sigma]);
    state
}

#[test]
fn capstan_cantilever_matches_the_closed_form() {
    // One straight tendon at offset d, no gravity, no tip load. The combined
    // wrench vanishes (N = M = 0), so m = d τ(s) e_y exactly: κ(s) = d τ(s)/EI,
    // and the tendon's tangent is the backbone's (u × r ∥ e3), so θ' = κ
    // (extension changes n, not m or the tangent's direction: the closed form
    // below is exact in the Cosserat model). With τ = τ_m e^(−σμθ):
    //   σ = +1: θ(s) = ln(1 + μκ₀s)/μ,   τ(s) = τ_m/(1 + μκ₀s)
    //   σ = −1: θ(s) = −ln(1 − μκ₀s)/μ,  τ(s) = τ_m/(1 − μκ₀s),   κ₀ = dτ_m/EI.
    // What the model adds is error: the cubic spline of θ on h = L/32 misses
    // θ by about (5/384) h⁴ max|θ''''| between nodes (the clamped spline's
    // bound; not-a-knot's is of the same order, so 10× that), each τ(s) by
    // μ times that (relative), and the tip angle ∫κ by θ(L) times that. The
    // Newton tolerance (5e-10 N·m of moment residual, /EI, over L) leaves
    // ≈ 2e-9 rad; 256 RK4 steps keep the integration error below that.
    let robot = load("seed-1t.toml").without_gravity();
    let statics = Statics::new(&robot, with_steps(256));
    let (d, ei, l) = (robot.tendons[0].offset, robot.kbt().x, robot.length);
    let tau_m = 8.0;
    let kappa0 = d * tau_m / ei;
    let h = l / PROFILE_INTERVALS as f64;
    for &mu in &[0.1, 0.3] {
        for &sigma in &[1.0, -1.0] {
            let mut state = driven(mu, tau_m, sigma);
            let sol = state.solve(&statics, &[tau_m], None).unwrap();
            // 1 + σμκ₀s > 0 on [0, L] for these numbers.
            let grow = |s: f64| 1.0 + sigma * mu * kappa0 * s;
            let theta = |s: f64| sigma * grow(s).ln() / mu;
            // |θ''''| = 6 μ³κ₀⁴/grow⁴, largest where grow is smallest.
            let theta4 = 6.0 * mu.powi(3) * kappa0.powi(4) / grow(0.0).min(grow(l)).powi(4);
            let rel_tension = 10.0 * mu * 5.0 / 384.0 * h.powi(4) * theta4;
            let tol_angle = theta(l) * rel_tension + 5.0 * 5e-10 / ei * l;
            let err = (tip_angle(&sol) - theta(l)).abs();
            eprintln!("μ = {mu}, σ = {sigma}: tip angle error {err:.2e} rad (tol {tol_angle:.2e})");
            assert!(
                err < tol_angle,
                "μ = {mu}, σ = {sigma}: tip angle {} vs closed form {} ({err:e} > {tol_angle:e})",
                tip_angle(&sol),
                theta(l)
            );
            // Friction matters at this size: the frictionless angle κ₀L is far off.
            assert!((kappa0 * l - theta(l)).abs() > 100.0 * tol_angle);
            for k in 0..=20 {
                let s = l * k as f64 / 20.0;
                let expected = tau_m / grow(s);
                let got = state.tension_at(0, s, tau_m);
                // Interpolation, plus the node angles' own error (≤ the tip's).
                let tol = expected * (rel_tension + mu * tol_angle);
                assert!(
                    (got - expected).abs() < tol,
                    "μ = {mu}, σ = {sigma}, s = {s}: τ = {got} vs {expected} N (tol {tol:e})"
                );
            }
            eprintln!("μ = {mu}, σ = {sigma}: {} passes cold", state.passes());
            assert!(
                state.passes() <= friction::DEFAULT_MAX_PASSES && state.tip_change() < 1e-9,
                "μ = {mu}, σ = {sigma}: {} passes, last move {:e} m",
                state.passes(),
                state.tip_change()
            );
        }
    }
}

#[test]
fn the_profile_of_a_constant_curvature_arc_is_the_capstan_exponential() {
    // Gravity off, one tendon pulled: the exact shape is an arc of
    // κ = τ d/(EI) (docs/design.md §2), along which every straight tendon's
    // tangent is the backbone's, so θ_i(s) = κ s and the profile is exactly
    // τ_m e^(−μκs) for every tendon, at the nodes and between them.
    let robot = load("seed-4t.toml").without_gravity();
    let statics = Statics::new(&robot, SolverSettings::default());
    let tau = 5.0;
    let kappa = tau * robot.tendons[0].offset / robot.kbt().x;
    let sol = statics.solve(&[tau, 0.0, 0.0, 0.0], None).unwrap();
    let theta = tendon_angles(&statics, &sol).unwrap();
    let mu = 0.25;
    let ends = vec![robot.length; 4];
    let profile = TensionProfile::new(&[mu; 4], &ends, &theta);
    for i in 0..4 {
        for k in 0..=50 {
            let s = robot.length * k as f64 / 50.0;
            let expected = (-mu * kappa * s).exp();
            let (e, dlog) = profile.factor(i, s);
            // The solve's curvature is right to its moment residual over EI
            // (5e-10 N·m / 0.107 N·m² ≈ 5e-9 1/m); μ times that in e'/e,
            // μ s times that in e.
            let du = 2.0 * 5e-10 / robot.kbt().x;
            assert!(
                (e - expected).abs() < mu * s * du + 1e-15,
                "tendon {i}, s = {s}: e = {e} vs {expected}"
            );
            assert!(
                (dlog + mu * kappa).abs() < mu * du,
                "tendon {i}: e'/e = {dlog}"
            );
        }
    }
}

#[test]
fn no_friction_is_the_frictionless_solve() {
    let statics = repo_statics("seed-4t.toml");
    let tau = [6.0, 2.5, 0.0, 1.0];
    let plain = statics.solve(&tau, None).unwrap();
    // μ = 0: the uniform-tension path, bit for bit.
    let mut state = FrictionState::new(Friction::new(0.0), 4);
    state.update_direction(&tau);
    let sol = state.solve(&statics, &tau, None).unwrap();
    assert_eq!(sol.pose(), plain.pose());
    assert_eq!(state.passes(), 1);
    // A profile whose exponents are zero goes through the friction code
    // (tension lookups, zero friction force) and must agree too.
    let theta = tendon_angles(&statics, &plain).unwrap();
    let profile = TensionProfile::new(&[0.0; 4], &[statics.robot().length; 4], &theta);
    let with = statics
        .solve_with_profile(&tau, Some(Arc::new(profile)), None)
        .unwrap();
    let err = (with.position - plain.position).norm();
    assert!(err < 1e-12, "zero-exponent profile moved the tip {err:e} m");
}

/// n(0) against the weight and the motors' pulls: N(0) = n(0) + Σ τ_i,m t_i(0)
/// = ρ A g L (base frame, R(0) = I), t_i(0) the tendon's unit tangent at the base.
fn base_force_gap(robot: &Robot, sol: &Solution) -> f64 {
    let x = &sol.warm.x;
    let v = Vector3::new(x[0], x[1], x[2]).component_div(&robot.kse()) + Vector3::z();
    let u = Vector3::new(x[3], x[4], x[5]);
    let mut pulls = Vector3::zeros();
    for (i, t) in robot.tendons.iter().enumerate() {
        let r = t.offset_at(0.0, robot.length).r;
        pulls += (u.cross(&r) + v).normalize() * sol.tensions()[i];
    }
    (sol.base_force() + pulls - robot.weight_per_length() * robot.length).norm()
}

#[test]
fn the_base_reaction_is_the_weight_and_the_motor_pulls_whatever_the_friction() {
    // The tendon's load on the rod, ∫ d(τ t)/ds ds plus its anchor's point
    // load −τ(L) t(L), telescopes to −τ_m t(0): friction moves load along the
    // rod but cannot change the base reaction. Without the τ' t term the
    // gap would be the friction's total, ≈ Σ τ_m (1 − e^(−μθ(L))).
    let statics = repo_statics("seed-4t.toml");
    let robot = statics.robot().clone();
    let tau = [6.0, 2.0, 0.0, 1.0];
    for &mu in &[0.0, 0.2] {
        let mut state = FrictionState::new(Friction::new(mu), 4);
        state.update_direction(&tau);
        let sol = state.solve(&statics, &tau, None).unwrap();
        let gap = base_force_gap(&robot, &sol);
        eprintln!("μ = {mu}: base force gap {gap:.2e} N");
        // The residual tolerance (5e-10) and the RK4 error of 16 steps.
        assert!(gap < 1e-6, "μ = {mu}: base force off by {gap:e} N");
        if mu > 0.0 {
            let lost: f64 = (0..4)
                .map(|i| tau[i] - state.tension_at(i, robot.length, tau[i]))
                .sum();
            eprintln!("μ = {mu}: friction takes {lost:.3} N off the tendons");
            assert!(lost > 1e4 * 1e-6, "friction takes only {lost} N");
        }
    }
}

/// Tip deflection px (m) along a sweep of tendon 0's motor 0 → 6 → 0 N in
/// 0.05 N steps, each step update_direction + solve (warm): (up, down) at
/// the same motor tensions, up[k] and down[k] at k · 0.05 N.
fn sweep(mu: f64) -> (Vec<f64>, Vec<f64>, usize) {
    let statics = repo_statics("seed-4t.toml");
    let mut state = FrictionState::new(Friction::new(mu), 4);
    let steps = 120;
    let mut warm: Option<WarmStart> = None;
    let mut passes = 0;
    let mut at = |k: usize, state: &mut FrictionState| {
        let tau = [0.05 * k as f64, 0.0, 0.0, 0.0];
        state.update_direction(&tau);
        let sol = state.solve(&statics, &tau, warm.as_ref()).unwrap();
        passes += state.passes();
        warm = Some(sol.warm.clone());
        sol.position.x
    };
    let up: Vec<f64> = (0..=steps).map(|k| at(k, &mut state)).collect();
    let mut down: Vec<f64> = (0..=steps).rev().map(|k| at(k, &mut state)).collect();
    down.reverse();
    (up, down, passes)
}

#[test]
fn a_tension_sweep_up_and_down_makes_a_hysteresis_loop() {
    let mut widths = Vec::new();
    for &mu in &[0.1, 0.3] {
        let (up, down, passes) = sweep(mu);
        let n = up.len() - 1;
        // Pulling loses tension toward the tip, releasing gains it: at equal
        // motor tension the rod bends less on the way up.
        for k in 1..n {
            assert!(
                up[k] < down[k],
                "μ = {mu}, {} N: up {} ≥ down {}",
                0.05 * k as f64,
                up[k],
                down[k]
            );
        }
        // The loop closes at both ends: slack tendons carry no friction, and
        // at the top the way down starts where the way up ended.
        assert!((up[0] - down[0]).abs() < 1e-9, "μ = {mu}: open at 0 N");
        assert!((up[n] - down[n]).abs() < 1e-9, "μ = {mu}: open at 6 N");
        let width = (1..n).map(|k| down[k] - up[k]).fold(0.0, f64::max);
        eprintln!(
            "μ = {mu}: loop width {:.3} mm, {:.2} passes per step",
            width * 1e3,
            passes as f64 / (2 * (n + 1)) as f64
        );
        widths.push(width);
    }
    assert!(widths[1] > 2.0 * widths[0], "widths {widths:?}");
}

#[test]
fn with_a_fixed_profile_the_shooting_jacobian_is_exact() {
    // The tangent pass linearises τ_i(s) and the friction force at a fixed
    // profile (docs/design.md §2.3): against central differences of the
    // residual, on the two-segment robot (anchors inside) under gravity-free
    // load with a tip wrench, and a non-trivial profile from a real solve.
    use crate::statics::integrate::integrate;
    use crate::statics::rod::{Rod, RodState};
    use crate::statics::tangent::{integrate_with_sensitivity, ShootingSensitivity};
    use nalgebra::{Matrix6, Vector6};
    let statics = repo_statics("tdcr-2seg.toml");
    let robot = statics.robot().clone();
    let tau = [4.0, 0.0, 1.0, 0.0, 2.0, 0.5];
    let mut state = FrictionState::new(Friction::new(0.3), 6);
    state.update_direction(&tau);
    let sol = state.solve(&statics, &tau, None).unwrap();
    let profile = sol.profile().cloned().expect("a friction profile");
    let mut rod = Rod::new(&robot);
    rod.set_tensions(&tau);
    rod.set_profile(Some(profile));
    let (f_ext, m_ext) = (
        Vector3::new(0.05, -0.1, 0.02),
        Vector3::new(0.004, 0.0, -0.002),
    );
    let base = |x: &Vector6<f64>| {
        RodState::at_base(
            &Vector3::new(x[0], x[1], x[2]),
            &Vector3::new(x[3], x[4], x[5]),
            &rod.kse,
        )
    };
    let x = sol.warm.x + Vector6::new(0.1, 0.05, -0.3, -0.4, 0.3, 0.1);
    let steps = 16;
    let start = ShootingSensitivity::at_base(&rod.kse, 0, true, false);
    let (tip, t) = integrate_with_sensitivity(&rod, base(&x), steps, start).unwrap();
    assert_eq!(tip, integrate(&rod, base(&x), steps).unwrap());
    let exact = rod.tip_residual_jacobian(&tip, &t, &f_ext, &m_ext);
    let residual = |x: &Vector6<f64>| {
        let tip = integrate(&rod, base(x), steps).unwrap();
        rod.tip_residual(&tip, &f_ext, &m_ext)
    };
    let mut fd = Matrix6::zeros();
    for j in 0..6 {
        let h = 1e-6 * x[j].abs().max(if j < 3 { 1.0 } else { 0.1 });
        let (mut xp, mut xm) = (x, x);
        xp[j] += h;
        xm[j] -= h;
        fd.set_column(j, &((residual(&xp) - residual(&xm)) / (2.0 * h)));
    }
    for j in 0..6 {
        let scale = fd.column(j).norm().max(1e-3);
        let err = (exact.column(j) - fd.column(j)).norm() / scale;
        assert!(err < 1e-5, "column {j}: relative error {err:e}");
    }
}
