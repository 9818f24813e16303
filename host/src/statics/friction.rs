//! Capstan friction of the tendons in their guides (`docs/design.md` §2.3),
//! for the simulated plant only: the model the IK and the nets use stays
//! frictionless.
//!
//! Along tendon i, pulled at the base (s = 0) by its motor with τ_i,m, the
//! tension follows the capstan (Euler–Eytelwein) law
//!
//! ```text
//! τ_i(s) = τ_i,m e_i(s),   e_i(s) = exp(−σ_i μ θ_i(s)),   θ_i(s) = ∫₀ˢ |t_i'| ds,
//! ```
//!
//! θ_i the angle the tendon's spatial unit tangent t_i has turned through
//! and σ_i ∈ [−1, 1] the sliding direction (+1 pulling: the tension decays
//! toward the tip). The rod sees τ_i(s) in Rucker–Webster's terms and the
//! friction force τ_i' t_i (`Rod::assemble`). θ_i depends on the solution,
//! so [`FrictionState::solve`] iterates: angle profiles from the previous
//! solution, solve, measure the angles again, until the tip stops moving.

use std::sync::Arc;

use nalgebra::Vector3;

use super::integrate::rk4_step;
use super::rod::{Rod, RodState};
use super::shoot::{base_state, Solution, SolveError, Statics, WarmStart};
use crate::robot::MAX_TENDONS;

/// Intervals of each tendon's angle grid, uniform over [0, end_i].
pub const PROFILE_INTERVALS: usize = 32;

/// Fixed-point passes [`FrictionState::solve`] makes at most by default.
/// The error of pass k falls like (μθ)^k/k! (the profile's update is a
/// Volterra map: τ at s depends on the angle before s): from a straight rod
/// (cold) the default robot at 8 N and μ = 0.3 needs 7 passes for 1e-9 m;
/// warm, a 0.05 N step needs ≈ 4 at μ = 0.1 and ≈ 5 at μ = 0.3.
pub const DEFAULT_MAX_PASSES: usize = 8;

/// The fixed point stops when the tip moved less than this between two
/// passes, m.
pub const TIP_TOLERANCE_M: f64 = 1e-9;

/// Default reversal tension τ_rev of [`Friction::reversal_n`], N.
pub const DEFAULT_REVERSAL_N: f64 = 0.05;

/// Capstan friction of the tendons in their guides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Friction {
    /// Friction coefficient μ between tendon and guides (dimensionless, ≥ 0).
    pub mu: f64,
    /// Reversal tension τ_rev, N (> 0): how much the motor's tension must
    /// move after a reversal for the contact to slide fully the other way
    /// (the Dahl-type stick of [`FrictionState::update_direction`]).
    pub reversal_n: f64,
}

impl Friction {
    /// Friction coefficient `mu` with the default reversal tension
    /// [`DEFAULT_REVERSAL_N`].
    pub fn new(mu: f64) -> Friction {
        Friction {
            mu,
            reversal_n: DEFAULT_REVERSAL_N,
        }
    }

    /// Whether the numbers are physical: μ finite and ≥ 0, τ_rev finite and > 0.
    pub fn check(&self) -> Result<(), FrictionError> {
        if !(self.mu.is_finite() && self.mu >= 0.0) {
            return Err(FrictionError::Mu(self.mu));
        }
        if !(self.reversal_n.is_finite() && self.reversal_n > 0.0) {
            return Err(FrictionError::Reversal(self.reversal_n));
        }
        Ok(())
    }
}

/// Friction numbers or a friction state that do not fit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrictionError {
    /// μ is negative or not finite.
    #[error("friction coefficient mu must be finite and >= 0, got {0}")]
    Mu(f64),
    /// τ_rev is not positive or not finite.
    #[error("friction reversal tension must be finite and > 0 N, got {0} N")]
    Reversal(f64),
    /// The state was made for another number of tendons than the robot has.
    #[error("friction state has {state} tendons, the robot {robot}")]
    TendonCount {
        /// Tendons of the friction state.
        state: usize,
        /// Tendons of the robot.
        robot: usize,
    },
}

/// One tendon's angle θ_i at the nodes k·end_i/N, k = 0..=N, rad.
pub type AngleGrid = [f64; PROFILE_INTERVALS + 1];

/// One tendon's turned angle θ(s) on [0, end]: the not-a-knot cubic spline
/// through its node values. Why a spline and not the piecewise-linear θ
/// (θ' piecewise constant): the friction force τ' t jumps where θ' does,
/// and RK4's stages sit on the nodes (the grid's nodes are the steps' ends
/// and midpoints), where a jump costs the quadrature first order — on the
/// default robot the base reaction was off by 8 mN at μ = 0.2 (the telescoping
/// of ∫ d(τ t)/ds broke). The spline is C², so RK4 keeps its order, and it
/// interpolates to O(h⁴) instead of O(h²). A linear θ stays linear (M = 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AngleSpline {
    /// θ at the nodes, rad.
    theta: AngleGrid,
    /// θ'' at the nodes, 1/m².
    second: AngleGrid,
    /// Span end_i, m.
    end: f64,
}

impl AngleSpline {
    /// The spline through `theta` at the nodes k·end/N. Not-a-knot (θ'''
    /// continuous at the second and last-but-one node): with uniform spacing
    /// that makes M₁ = d₁/6 and M_{N−1} = d_{N−1}/6 directly, d_k =
    /// 6(θ_{k+1} − 2θ_k + θ_{k−1})/h², and M₀, M_N the linear extrapolations.
    pub fn new(theta: &AngleGrid, end: f64) -> AngleSpline {
        const N: usize = PROFILE_INTERVALS;
        let h = end / N as f64;
        let d = |k: usize| 6.0 * (theta[k + 1] - 2.0 * theta[k] + theta[k - 1]) / (h * h);
        let mut m = [0.0; N + 1];
        m[1] = d(1) / 6.0;
        m[N - 1] = d(N - 1) / 6.0;
        // M_{k−1} + 4 M_k + M_{k+1} = d_k for k = 2..N−2 (Thomas algorithm),
        // the known M₁ and M_{N−1} moved to the right-hand side.
        let mut diag = [0.0; N + 1];
        let mut rhs = [0.0; N + 1];
        for k in 2..=N - 2 {
            let mut r = d(k);
            if k == 2 {
                r -= m[1];
            }
            if k == N - 2 {
                r -= m[N - 1];
            }
            if k == 2 {
                diag[k] = 4.0;
                rhs[k] = r;
            } else {
                let w = 1.0 / diag[k - 1];
                diag[k] = 4.0 - w;
                rhs[k] = r - w * rhs[k - 1];
            }
        }
        for k in (2..=N - 2).rev() {
            let next = if k == N - 2 { 0.0 } else { m[k + 1] };
            m[k] = (rhs[k] - next) / diag[k];
        }
        m[0] = 2.0 * m[1] - m[2];
        m[N] = 2.0 * m[N - 1] - m[N - 2];
        AngleSpline {
            theta: *theta,
            second: m,
            end,
        }
    }

    /// A zero angle everywhere (the straight rod), on [0, `end`].
    pub fn zero(end: f64) -> AngleSpline {
        AngleSpline {
            theta: [0.0; PROFILE_INTERVALS + 1],
            second: [0.0; PROFILE_INTERVALS + 1],
            end,
        }
    }

    /// θ(s) (rad) and θ'(s) (1/m), clamped to the first and last interval
    /// outside [0, end].
    #[inline(always)]
    pub fn eval(&self, s: f64) -> (f64, f64) {
        let h = self.end / PROFILE_INTERVALS as f64;
        let k = ((s / h).max(0.0) as usize).min(PROFILE_INTERVALS - 1);
        let t = s - k as f64 * h;
        let u = h - t;
        let (m0, m1) = (self.second[k], self.second[k + 1]);
        let a = self.theta[k] / h - m0 * h / 6.0;
        let b = self.theta[k + 1] / h - m1 * h / 6.0;
        let theta = (m0 * u * u * u + m1 * t * t * t) / (6.0 * h) + a * u + b * t;
        let slope = (m1 * t * t - m0 * u * u) / (2.0 * h) + b - a;
        (theta, slope)
    }

    /// θ at the nodes, rad.
    pub fn nodes(&self) -> &AngleGrid {
        &self.theta
    }
}

/// How each tendon's tension changes along its path under capstan
/// friction, for one solve: e_i(s) = exp(−c_i θ_i(s)) with c_i = σ_i μ and
/// θ_i the [`AngleSpline`] through its values at [`PROFILE_INTERVALS`]
/// uniform intervals of [0, end_i]. τ_i(s) = τ_i,m e_i(s) and
/// τ_i' = −c_i θ_i' τ_i are exactly consistent, so the tendon's net load on
/// the rod is its pull at the base, whatever the grid.
#[derive(Clone, Debug, PartialEq)]
pub struct TensionProfile {
    /// Per tendon: c_i = σ_i μ (dimensionless).
    rate: [f64; MAX_TENDONS],
    /// Per tendon: θ_i(s).
    theta: [AngleSpline; MAX_TENDONS],
}

impl TensionProfile {
    /// The profile with exponents `rates` (c_i = σ_i μ), anchors `ends` (m)
    /// and angle grids `theta` (rad), one of each per tendon.
    ///
    /// # Panics
    /// If the three do not have the same length of at most [`MAX_TENDONS`],
    /// or an end is not positive (callers pass a validated robot's).
    pub fn new(rates: &[f64], ends: &[f64], theta: &[AngleGrid]) -> TensionProfile {
        assert!(
            rates.len() == ends.len() && ends.len() == theta.len() && rates.len() <= MAX_TENDONS,
            "a tension profile needs one rate, end and angle grid per tendon (got {}, {}, {})",
            rates.len(),
            ends.len(),
            theta.len()
        );
        assert!(
            ends.iter().all(|&e| e > 0.0),
            "tendon ends must be positive"
        );
        let mut profile = TensionProfile {
            rate: [0.0; MAX_TENDONS],
            theta: [AngleSpline::zero(1.0); MAX_TENDONS],
        };
        profile.rate[..rates.len()].copy_from_slice(rates);
        for ((spline, grid), &end) in profile.theta.iter_mut().zip(theta).zip(ends) {
            *spline = AngleSpline::new(grid, end);
        }
        profile
    }

    /// The profile with exponents `rates` (c_i = σ_i μ) on ready splines.
    fn from_splines(rates: &[f64], splines: &[AngleSpline]) -> TensionProfile {
        let mut profile = TensionProfile {
            rate: [0.0; MAX_TENDONS],
            theta: [AngleSpline::zero(1.0); MAX_TENDONS],
        };
        profile.rate[..rates.len()].copy_from_slice(rates);
        profile.theta[..splines.len()].copy_from_slice(splines);
        profile
    }

    /// Tendon `i`'s turned angle θ_i(s), rad.
    pub fn angle(&self, i: usize, s: f64) -> f64 {
        self.theta[i].eval(s).0
    }

    /// Tendon `i`'s tension factor e_i(s) = τ_i(s)/τ_i,m and its
    /// logarithmic derivative e_i'/e_i = −c_i θ_i'(s) (1/m).
    #[inline(always)]
    pub fn factor(&self, i: usize, s: f64) -> (f64, f64) {
        let (theta, slope) = self.theta[i].eval(s);
        let c = self.rate[i];
        ((-c * theta).exp(), -c * slope)
    }
}

/// Per-tendon sliding direction and angle profiles, carried from step to step.
#[derive(Clone, Debug)]
pub struct FrictionState {
    friction: Friction,
    /// σ_i ∈ [−1, 1].
    sigma: Vec<f64>,
    /// The motors' tensions [`FrictionState::update_direction`] saw last, N.
    motor: Vec<f64>,
    /// θ_i(s) from the last solution (zero: a straight rod; its span is the
    /// robot's end_i once a solve has run).
    theta: Vec<AngleSpline>,
    /// Most fixed-point passes per solve.
    max_passes: usize,
    /// Passes the last solve made.
    passes: usize,
    /// How far the tip moved in the last solve's last pass, m.
    tip_change: f64,
}

impl FrictionState {
    /// The state of `n_tendons` tendons at rest: σ_i = 0 (no history, so no
    /// sliding direction: the first pull from the slack tendons' 0 N drives
    /// σ_i to +1 within τ_rev), motors at 0 N, angle profiles of the
    /// straight rod.
    ///
    /// # Panics
    /// If `friction` is not physical ([`Friction::check`]) or `n_tendons`
    /// exceeds [`MAX_TENDONS`].
    pub fn new(friction: Friction, n_tendons: usize) -> FrictionState {
        if let Err(e) = friction.check() {
            panic!("FrictionState::new: {e}");
        }
        assert!(
            n_tendons <= MAX_TENDONS,
            "FrictionState::new: {n_tendons} tendons, at most {MAX_TENDONS}"
        );
        FrictionState {
            friction,
            sigma: vec![0.0; n_tendons],
            motor: vec![0.0; n_tendons],
            theta: vec![AngleSpline::zero(1.0); n_tendons],
            max_passes: DEFAULT_MAX_PASSES,
            passes: 0,
            tip_change: 0.0,
        }
    }

    /// The friction numbers.
    pub fn friction(&self) -> Friction {
        self.friction
    }

    /// Set the most fixed-point passes a solve makes (at least 1). One pass
    /// solves with the previous solution's angle profile and then updates
    /// it: a profile lagging one solve behind.
    pub fn set_max_passes(&mut self, passes: usize) {
        self.max_passes = passes.max(1);
    }

    /// Passes the last [`FrictionState::solve`] made.
    pub fn passes(&self) -> usize {
        self.passes
    }

    /// How far the tip moved between the last solve's last two passes, m
    /// (0 after a frictionless single pass, infinite after one pass of a
    /// profile that was not checked).
    pub fn tip_change(&self) -> f64 {
        self.tip_change
    }

    /// The motors' tensions moved to `motor_tensions` (N): update each σ_i.
    /// Dahl-type: σ_i ← clamp(σ_i + (Δτ_i,m/τ_rev)(1 − σ_i sgn Δτ_i,m), −1, 1),
    /// so σ_i moves toward sgn Δτ_i,m and reaches it after a tension change
    /// of about τ_rev past a reversal; no change leaves it alone.
    ///
    /// # Panics
    /// If `motor_tensions` does not have one finite entry per tendon.
    pub fn update_direction(&mut self, motor_tensions: &[f64]) {
        assert!(
            motor_tensions.len() == self.sigma.len(),
            "update_direction: {} motor tensions for {} tendons",
            motor_tensions.len(),
            self.sigma.len()
        );
        for (i, ((sigma, last), &now)) in self
            .sigma
            .iter_mut()
            .zip(&mut self.motor)
            .zip(motor_tensions)
            .enumerate()
        {
            assert!(
                now.is_finite(),
                "update_direction: motor tension {i} is not finite ({now})"
            );
            let delta = now - *last;
            if delta != 0.0 {
                let step = delta / self.friction.reversal_n * (1.0 - *sigma * delta.signum());
                *sigma = (*sigma + step).clamp(-1.0, 1.0);
            }
            *last = now;
        }
    }

    /// σ_i of each tendon.
    pub fn direction(&self) -> &[f64] {
        &self.sigma
    }

    /// Tension of tendon `i` at arc length `s` (m) under motor tension `motor` (N), from the current profile.
    /// (The current σ_i and the angle profile of the last solution.)
    pub fn tension_at(&self, i: usize, s: f64, motor: f64) -> f64 {
        let theta = self.theta[i].eval(s).0;
        motor * (-self.sigma[i] * self.friction.mu * theta).exp()
    }

    /// Tendon `i`'s angle profile θ_i(s) (rad) from the last solution.
    pub fn angle_at(&self, i: usize, s: f64) -> f64 {
        self.theta[i].eval(s).0
    }

    /// Statics with friction for motor tensions `motor_tensions`: fixed point on the angle
    /// profiles (at most `max_passes`, default [`DEFAULT_MAX_PASSES`]), warm-started; keeps the final profiles.
    ///
    /// Each pass solves with the angle profiles of the previous solution
    /// (the last solve's, carried in the state) and the current σ, then
    /// measures the angles again. It stops when the tip moved less than
    /// [`TIP_TOLERANCE_M`] between two passes or after the passes allowed
    /// ([`FrictionState::set_max_passes`]; [`FrictionState::tip_change`]
    /// says how far it was). With μ = 0 or every σ_i = 0 the tension is
    /// uniform and this is [`Statics::solve`], bit for bit, in one pass.
    pub fn solve(
        &mut self,
        statics: &Statics,
        motor_tensions: &[f64],
        warm: Option<&WarmStart>,
    ) -> Result<Solution, SolveError> {
        let robot = statics.robot();
        if robot.n_tendons() != self.sigma.len() {
            return Err(FrictionError::TendonCount {
                state: self.sigma.len(),
                robot: robot.n_tendons(),
            }
            .into());
        }
        robot.check_tensions(motor_tensions)?;
        let ends: Vec<f64> = robot.tendons.iter().map(|t| t.end).collect();
        let measure = |sol: &Solution| -> Result<Vec<AngleSpline>, SolveError> {
            Ok(tendon_angles(statics, sol)?
                .iter()
                .zip(&ends)
                .map(|(grid, &end)| AngleSpline::new(grid, end))
                .collect())
        };
        let rates: Vec<f64> = self.sigma.iter().map(|s| s * self.friction.mu).collect();
        if rates.iter().all(|&c| c == 0.0) {
            let sol = statics.solve(motor_tensions, warm)?;
            self.theta = measure(&sol)?;
            self.passes = 1;
            self.tip_change = 0.0;
            return Ok(sol);
        }
        let mut warm = warm.cloned();
        let mut last: Option<Solution> = None;
        self.tip_change = f64::INFINITY;
        for pass in 1..=self.max_passes {
            let profile = Arc::new(TensionProfile::from_splines(&rates, &self.theta));
            let sol = statics.solve_with_profile(motor_tensions, Some(profile), warm.as_ref())?;
            self.theta = measure(&sol)?;
            self.passes = pass;
            if let Some(prev) = &last {
                self.tip_change = (sol.position - prev.position).norm();
            }
            warm = Some(sol.warm.clone());
            let done = self.tip_change < TIP_TOLERANCE_M;
            last = Some(sol);
            if done {
                break;
            }
        }
        Ok(last.expect("at least one pass"))
    }
}

/// The angle θ_i each tendon's spatial unit tangent t_i = R q_i/|q_i| has
/// turned through, at the nodes of its grid (k·end_i/N), for a converged
/// `sol` of `statics` (with its friction profile). The rod is integrated
/// from the solution's base through every tendon's nodes (at least the
/// solver's steps per metre); θ grows by the angle between the tangents at
/// consecutive nodes, which is ∫|t'| ds exactly for a plane path and to
/// O(h³) otherwise. At an anchor the state just before it is used: the
/// corner the tendons running on turn there is counted in their next
/// interval (a capstan over the kink), and the tendon anchored there ends
/// before it.
pub fn tendon_angles(statics: &Statics, sol: &Solution) -> Result<Vec<AngleGrid>, SolveError> {
    let rod = statics.solution_rod(sol);
    let n = rod.n_tendons;
    let steps = statics.settings().steps.max(1);
    // Every tendon's nodes, in order of arc length.
    let mut nodes: Vec<(f64, usize, usize)> = (0..n)
        .flat_map(|i| {
            let end = rod.end[i];
            (0..=PROFILE_INTERVALS).map(move |k| {
                let s = if k == PROFILE_INTERVALS {
                    end
                } else {
                    end * (k as f64 / PROFILE_INTERVALS as f64)
                };
                (s, i, k)
            })
        })
        .collect();
    nodes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut tangents = vec![[Vector3::zeros(); PROFILE_INTERVALS + 1]; n];
    let mut y = base_state(&rod, &sol.warm.x);
    let mut a = 0.0;
    let mut idx = 0;
    while idx < nodes.len() {
        let b = nodes[idx].0;
        if b > a {
            let pieces = ((b - a) / rod.length * steps as f64).ceil().max(1.0) as usize;
            let h = (b - a) / pieces as f64;
            let running = rod.running_to(b);
            for j in 0..pieces {
                y = rk4_step(&rod, a + j as f64 * h, &y, h, running)?;
            }
            a = b;
        }
        while idx < nodes.len() && nodes[idx].0 == b {
            let (_, i, k) = nodes[idx];
            tangents[i][k] = spatial_tangent(&rod, i, b, &y);
            idx += 1;
        }
        if b < rod.length && rod.anchored_at(b) != 0 {
            y = rod.across_anchor(b, &y);
        }
    }
    Ok(tangents
        .iter()
        .map(|t| {
            let mut theta = [0.0; PROFILE_INTERVALS + 1];
            for k in 0..PROFILE_INTERVALS {
                let turned = t[k].cross(&t[k + 1]).norm().atan2(t[k].dot(&t[k + 1]));
                theta[k + 1] = theta[k] + turned;
            }
            theta
        })
        .collect())
}

/// Tendon `i`'s unit tangent t_i = R q_i/|q_i| (base frame) at `s`.
fn spatial_tangent(rod: &Rod, i: usize, s: f64, y: &RodState) -> Vector3<f64> {
    (y.rot * Rod::tendon_tangent(y, &rod.routing(i, s))).normalize()
}
