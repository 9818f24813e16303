//! Fixed-step classical Runge–Kutta (RK4) integration of the rod from base to
//! tip, piecewise between the tendon anchors (`docs/design.md` §2.1). Fixed
//! steps keep the shooting residual a smooth function of the unknowns (an
//! adaptive integrator's step changes would make it jump), and 16–24 steps
//! already put the tip within 1e-7 m of the converged answer. An anchor is a
//! knot: no step straddles the jump of the internal wrench there.

use nalgebra::Vector3;

use super::rod::{Rod, RodRates, RodState, SingularSystem, TendonSet};
use crate::numerics::rk4;

/// Fewest RK4 steps on a piece between anchors, however short it is.
pub const MIN_STEPS_PER_PIECE: usize = 2;

/// RK4 steps on the piece [a, b] of a rod of `length` with `steps` steps over
/// the whole length: the same steps per metre everywhere, at least
/// [`MIN_STEPS_PER_PIECE`] when the rod has anchors inside it. Without
/// inner anchors the one piece gets exactly `steps`.
pub fn piece_steps(steps: usize, a: f64, b: f64, length: f64, has_knots: bool) -> usize {
    let n = ((b - a) / length * steps as f64).round() as usize;
    if has_knots {
        n.max(MIN_STEPS_PER_PIECE)
    } else {
        n.max(1)
    }
}

/// One piece of the fixed-step schedule between anchors.
#[derive(Clone, Copy, Debug)]
pub struct Piece {
    /// Start of the piece (arc length, m).
    pub a: f64,
    /// End of the piece: an anchor (a knot) or the tip, m.
    pub b: f64,
    /// RK4 steps on the piece ([`piece_steps`]).
    pub n: usize,
    /// Step length, m.
    pub h: f64,
    /// The tendons that load the piece (those anchored at or beyond `b`).
    pub running: TendonSet,
}

impl Piece {
    /// Whether the piece ends at an inner anchor (its point load follows).
    pub fn ends_at_anchor(&self, length: f64) -> bool {
        self.b < length
    }
}

/// The pieces base to tip, the anchors as knots: the one schedule both the
/// state integration and its tangent follow, so they stay in step.
pub fn pieces(rod: &Rod, steps: usize) -> impl Iterator<Item = Piece> + '_ {
    let steps = steps.max(1);
    let has_knots = !rod.knots().is_empty();
    let ends = rod
        .knots()
        .iter()
        .copied()
        .chain(std::iter::once(rod.length));
    ends.scan(0.0, move |a, b| {
        let n = piece_steps(steps, *a, b, rod.length, has_knots);
        let piece = Piece {
            a: *a,
            b,
            n,
            h: (b - *a) / n as f64,
            running: rod.running_to(b),
        };
        *a = b;
        Some(piece)
    })
}

/// Integrate from s = 0 to s = L with `steps` RK4 steps over the length,
/// piece by piece between the anchors, applying each anchor's point load at
/// its knot; `observe` sees the state at every node (s_k, state_k), base and
/// tip included (at a knot, the state just before the anchor).
pub fn integrate_observed<F>(
    rod: &Rod,
    base: RodState,
    steps: usize,
    observe: F,
) -> Result<RodState, SingularSystem>
where
    F: FnMut(f64, &RodState),
{
    // Friction or not is decided once per pass: the frictionless stages
    // carry no branch (one per stage cost 1–3 % of a solve's instructions).
    match rod.profile() {
        None => integrate_observed_with::<false, F>(rod, base, steps, observe),
        Some(_) => integrate_observed_with::<true, F>(rod, base, steps, observe),
    }
}

/// [`integrate_observed`] with (`FRICTION`) or without the rod's tension profile.
fn integrate_observed_with<const FRICTION: bool, F>(
    rod: &Rod,
    base: RodState,
    steps: usize,
    mut observe: F,
) -> Result<RodState, SingularSystem>
where
    F: FnMut(f64, &RodState),
{
    let mut y = base;
    observe(0.0, &y);
    for piece in pieces(rod, steps) {
        for k in 0..piece.n {
            let s = piece.a + k as f64 * piece.h;
            y = rk4::rk4_step_with(s, &y, piece.h, PassRates::<FRICTION>(rod, piece.running))?;
            observe(s + piece.h, &y);
        }
        if piece.ends_at_anchor(rod.length) {
            y = rod.across_anchor(piece.b, &y);
        }
    }
    Ok(y)
}

/// Integrate from base to tip; returns the tip state.
pub fn integrate(rod: &Rod, base: RodState, steps: usize) -> Result<RodState, SingularSystem> {
    integrate_observed(rod, base, steps, |_, _| {})
}

/// Backbone positions at `points` ≥ 2 evenly spaced arc lengths, base to tip,
/// integrating with at least `steps` steps per length between every pair of
/// neighbouring sample points and anchors.
pub fn integrate_sampled(
    rod: &Rod,
    base: RodState,
    steps: usize,
    points: usize,
) -> Result<Vec<Vector3<f64>>, SingularSystem> {
    Ok(integrate_sampled_states(rod, base, steps, points)?
        .into_iter()
        .map(|(_, y)| y.p)
        .collect())
}

/// As [`integrate_sampled`], with the whole state and its arc length at
/// each sample (after an anchor's jump when the sample is on one).
pub fn integrate_sampled_states(
    rod: &Rod,
    base: RodState,
    steps: usize,
    points: usize,
) -> Result<Vec<(f64, RodState)>, SingularSystem> {
    let points = points.max(2);
    let intervals = points - 1;
    let sample = |k: usize| {
        if k == intervals {
            rod.length
        } else {
            rod.length * k as f64 / intervals as f64
        }
    };
    let mut out = Vec::with_capacity(points);
    let mut y = base;
    out.push((0.0, y));
    let mut a = 0.0;
    let mut knots = rod.knots().iter().copied().peekable();
    for k in 1..=intervals {
        let next_sample = sample(k);
        // Anchors before this sample point are knots of their own.
        loop {
            let b = match knots.peek() {
                Some(&knot) if knot <= next_sample => knot,
                _ => next_sample,
            };
            let n = ((b - a) / rod.length * steps.max(1) as f64).ceil().max(1.0) as usize;
            let h = (b - a) / n as f64;
            let running = rod.running_to(b);
            for j in 0..n {
                y = rk4_step(rod, a + j as f64 * h, &y, h, running)?;
            }
            a = b;
            if knots.peek() == Some(&b) {
                knots.next();
                y = rod.across_anchor(b, &y);
            }
            if b == next_sample {
                break;
            }
        }
        out.push((next_sample, y));
    }
    Ok(out)
}

/// One classical RK4 step of size `h` from arc length `s`, the tendons
/// `running` loading the rod.
pub fn rk4_step(
    rod: &Rod,
    s: f64,
    y: &RodState,
    h: f64,
    running: TendonSet,
) -> Result<RodState, SingularSystem> {
    match rod.profile() {
        None => rk4::rk4_step_with(s, y, h, PassRates::<false>(rod, running)),
        Some(_) => rk4::rk4_step_with(s, y, h, PassRates::<true>(rod, running)),
    }
}

/// The rod's rates with the tendons `running`, for RK4: a type rather than
/// a closure so that the four stages inline them (as a closure they stayed
/// a call each: the plain pass took 7 % longer, 20.9 against 19.5 µs a
/// one-pass warm solve on the VM's Zen 1, 2026-12-06).
struct PassRates<'a, const FRICTION: bool>(&'a Rod, TendonSet);

impl<const FRICTION: bool> rk4::Rates<RodState, SingularSystem> for PassRates<'_, FRICTION> {
    #[inline(always)]
    fn at(&mut self, _stage: usize, s: f64, y: &RodState) -> Result<RodRates, SingularSystem> {
        self.0.rates_with::<FRICTION>(s, y, self.1)
    }
}
