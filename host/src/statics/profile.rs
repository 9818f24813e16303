//! The tensions along a tendon with friction ([`TensionProfile`]): the
//! capstan law on each tendon's turned angle θ_i(s), a spline over a grid
//! (`docs/design.md` §2.1). What the rod's equations read; the fixed point
//! that finds it is [`super::friction`].

use crate::robot::MAX_TENDONS;

/// Intervals of each tendon's angle grid, uniform over [0, end_i].
pub const PROFILE_INTERVALS: usize = 32;

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
    pub(super) fn from_splines(rates: &[f64], splines: &[AngleSpline]) -> TensionProfile {
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
