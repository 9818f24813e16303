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
use super::profile::{AngleGrid, AngleSpline, FrictionError, TensionProfile, PROFILE_INTERVALS};
use super::rod::{Rod, RodState};
use super::shoot::base_state;
use super::{Solution, SolveError, Statics, WarmStart};
use crate::robot::MAX_TENDONS;

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
