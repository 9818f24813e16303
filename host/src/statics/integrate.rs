//! Fixed-step classical Runge–Kutta (RK4) integration of the rod from base to
//! tip. Fixed steps keep the shooting residual a smooth function of the
//! unknowns (an adaptive integrator's step changes would make it jump), and
//! 16–24 steps already put the tip within 1e-7 m of the converged answer.

use super::rod::{Rod, RodRates, RodState};

/// Integrate from s = 0 to s = L in `steps` equal RK4 steps; `observe` sees
/// the state at every node (s_k, state_k), base and tip included.
pub fn integrate_observed<F>(rod: &Rod, base: RodState, steps: usize, mut observe: F) -> RodState
where
    F: FnMut(f64, &RodState),
{
    let steps = steps.max(1);
    let h = rod.length / steps as f64;
    let mut y = base;
    observe(0.0, &y);
    for k in 0..steps {
        let s = k as f64 * h;
        y = rk4_step(rod, s, &y, h);
        observe(s + h, &y);
    }
    y
}

/// Integrate from base to tip; returns the tip state.
pub fn integrate(rod: &Rod, base: RodState, steps: usize) -> RodState {
    integrate_observed(rod, base, steps, |_, _| {})
}

/// One classical RK4 step of size `h` from arc length `s`.
pub fn rk4_step(rod: &Rod, s: f64, y: &RodState, h: f64) -> RodState {
    let k1 = rod.rates(s, y);
    let k2 = rod.rates(s + 0.5 * h, &y.advanced(&k1, 0.5 * h));
    let k3 = rod.rates(s + 0.5 * h, &y.advanced(&k2, 0.5 * h));
    let k4 = rod.rates(s + h, &y.advanced(&k3, h));
    let avg = RodRates {
        dp: (k1.dp + (k2.dp + k3.dp) * 2.0 + k4.dp) / 6.0,
        dr: (k1.dr + (k2.dr + k3.dr) * 2.0 + k4.dr) / 6.0,
        dw: (k1.dw + (k2.dw + k3.dw) * 2.0 + k4.dw) / 6.0,
        du: (k1.du + (k2.du + k3.du) * 2.0 + k4.du) / 6.0,
    };
    y.advanced(&avg, h)
}
