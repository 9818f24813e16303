//! The Cosserat rod loaded by Cosserat strings: state, constitutive law,
//! the coupled strain-rate system, and the point loads where tendons are
//! anchored (`docs/design.md` §2 and §2.1; Rucker & Webster 2011, eqs. 13–17).
//!
//! The shear/extension strain is carried as its deviation from the reference,
//! `w = v − e3`, not as `v` itself. The axial stiffness EA ≈ 5·10⁵ N makes
//! `n = Kse (v − e3)` lose ~6 digits to cancellation when `v ≈ 1` is stored;
//! storing `w` keeps the internal force exact to roundoff, which is what lets
//! the shooting residual reach 1e-10 N.

use std::sync::Arc;

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use super::profile::TensionProfile;

use crate::numerics::dense::Factor6;
use crate::robot::{hat, Robot, MAX_TENDONS};

pub use super::state::{RodRates, RodState, SingularSystem};

/// Newton steps on the running tendons' tangents across an anchor
/// ([`Rod::across_anchor`]); the first iterate is already within the ratio
/// of tendon to shear or torsion stiffness, so two reach roundoff.
const ANCHOR_NEWTON_STEPS: usize = 2;

/// A set of tendons as bits (bit i = tendon i).
pub type TendonSet = u16;

/// Geometry of one tendon at one arc length: body-frame offset and derivatives.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Routing {
    pub r: Vector3<f64>,
    pub dr: Vector3<f64>,
    pub ddr: Vector3<f64>,
}

/// One running tendon's terms at one point of the rod, kept from the
/// strain-rate system for its linearisation (`tangent`).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct TendonTerms {
    /// Offset r_i, m.
    pub r: Vector3<f64>,
    /// r_i'.
    pub dr: Vector3<f64>,
    /// Tangent q_i = û r_i + r_i' + v.
    pub q: Vector3<f64>,
    /// |q_i|².
    pub q2: f64,
    /// τ_i(s) / |q_i|³, N.
    pub c: f64,
    /// τ_i'(s), N/m: the capstan friction's tension gradient (zero without
    /// a [`TensionProfile`]); the friction force is τ_i' q_i/|q_i|.
    pub dtau: f64,
    /// û q_i + û r_i' + r_i'' (a_i = A_i alpha).
    pub alpha: Vector3<f64>,
}

/// The strain-rate system at one point: its factor, solution and parts.
#[derive(Clone, Debug)]
pub(super) struct System {
    /// The factored matrix K.
    pub factor: Factor6,
    /// v' (= w').
    pub dw: Vector3<f64>,
    /// u'.
    pub du: Vector3<f64>,
    /// Internal force n, body frame, N.
    pub n: Vector3<f64>,
    /// Internal moment m, body frame, N m.
    pub m: Vector3<f64>,
    /// The running, pulled tendons' terms.
    pub terms: [TendonTerms; MAX_TENDONS],
    /// Valid entries of `terms`.
    pub n_terms: usize,
}

/// R û, column by column: column k is R (u × e_k), a difference of two of
/// R's columns scaled by components of u (half the products of a full 3×3
/// product with the hat matrix; it is evaluated at every RK4 stage).
#[inline(always)]
pub(super) fn rot_times_hat(rot: &Matrix3<f64>, u: &Vector3<f64>) -> Matrix3<f64> {
    let (c0, c1, c2) = (rot.column(0), rot.column(1), rot.column(2));
    Matrix3::from_columns(&[
        c1 * u.z - c2 * u.y,
        c2 * u.x - c0 * u.z,
        c0 * u.y - c1 * u.x,
    ])
}

/// The rod model of one robot under one set of tendon tensions: everything
/// the strain-rate system needs, in fixed-size storage so that evaluating it
/// allocates nothing.
#[derive(Clone, Debug)]
pub struct Rod {
    /// Kse diagonal (GA, GA, EA), N.
    pub kse: Vector3<f64>,
    /// Kbt diagonal (EI, EI, GJ), N·m².
    pub kbt: Vector3<f64>,
    /// Distributed weight f_e = ρ A g, base frame, N/m.
    pub f_e: Vector3<f64>,
    /// Reference length L, m.
    pub length: f64,
    /// Number of tendons in use.
    pub(super) n_tendons: usize,
    /// Per tendon: offset d (m), angle at s = 0 (rad), helix rate (rad/m).
    geometry: [(f64, f64, f64); MAX_TENDONS],
    /// Per tendon: r(0) when the routing is straight (constant r, r' = r'' = 0),
    /// so the hot loop needs no trigonometry for the common case.
    straight: [Option<Vector3<f64>>; MAX_TENDONS],
    /// Tendon tensions τ_i, N: with a `profile`, the motors' tensions
    /// τ_i,m at the base (s = 0).
    pub(super) tension: [f64; MAX_TENDONS],
    /// Capstan friction (`docs/design.md` §2.3): how each tendon's tension
    /// changes along its path, τ_i(s) = τ_i,m e_i(s). `None` is the
    /// frictionless model, τ_i(s) = τ_i, and costs nothing on the hot path.
    profile: Option<Arc<TensionProfile>>,
    /// The tendons with a non-zero tension.
    pulled: TendonSet,
    /// Per tendon: arc length of its anchor, m.
    pub(super) end: [f64; MAX_TENDONS],
    /// Anchor positions strictly inside (0, L), ascending, distinct: the
    /// knots of the piecewise integration.
    knots: [f64; MAX_TENDONS],
    /// Number of valid entries in `knots`.
    n_knots: usize,
}

impl Rod {
    /// The rod of `robot` with all tensions zero.
    pub fn new(robot: &Robot) -> Rod {
        let mut geometry = [(0.0, 0.0, 0.0); MAX_TENDONS];
        let mut straight = [None; MAX_TENDONS];
        for (k, t) in robot.tendons.iter().enumerate() {
            if t.is_straight() {
                straight[k] = Some(t.offset_at(0.0, robot.length).r);
            }
        }
        for (g, t) in geometry.iter_mut().zip(&robot.tendons) {
            let rate = match t.routing {
                crate::robot::Routing::Straight => 0.0,
                crate::robot::Routing::Helical { turns } => {
                    2.0 * std::f64::consts::PI * turns / robot.length
                }
            };
            *g = (t.offset, t.angle, rate);
        }
        let mut end = [robot.length; MAX_TENDONS];
        let mut knots = [robot.length; MAX_TENDONS];
        let mut n_knots = 0;
        for (k, t) in robot.tendons.iter().enumerate() {
            end[k] = t.end;
            if t.end < robot.length && !knots[..n_knots].contains(&t.end) {
                knots[n_knots] = t.end;
                n_knots += 1;
            }
        }
        knots[..n_knots].sort_by(f64::total_cmp);
        Rod {
            kse: robot.kse(),
            kbt: robot.kbt(),
            f_e: robot.weight_per_length(),
            length: robot.length,
            n_tendons: robot.n_tendons(),
            geometry,
            straight,
            tension: [0.0; MAX_TENDONS],
            profile: None,
            pulled: 0,
            end,
            knots,
            n_knots,
        }
    }

    /// Anchor positions inside the rod, ascending (the integration knots), m.
    pub fn knots(&self) -> &[f64] {
        &self.knots[..self.n_knots]
    }

    /// The tendons that run over the piece of rod ending at arc length `b`
    /// (those anchored at `b` or beyond): only they load that piece.
    pub fn running_to(&self, b: f64) -> TendonSet {
        (0..self.n_tendons)
            .filter(|&i| self.end[i] >= b)
            .fold(0, |set, i| set | (1 << i))
    }

    /// The tendons anchored exactly at arc length `s`.
    pub(super) fn anchored_at(&self, s: f64) -> TendonSet {
        (0..self.n_tendons)
            .filter(|&i| self.end[i] == s)
            .fold(0, |set, i| set | (1 << i))
    }

    /// Set the tendon tensions (N). `tau` must have one entry per tendon;
    /// the caller ([`crate::statics::shoot`]) validates it.
    pub fn set_tensions(&mut self, tau: &[f64]) {
        self.tension = [0.0; MAX_TENDONS];
        self.pulled = 0;
        for (i, (t, &x)) in self.tension.iter_mut().zip(tau).enumerate() {
            *t = x;
            if x != 0.0 {
                self.pulled |= 1 << i;
            }
        }
    }

    /// Tension of tendon `i`, N (with a friction profile, the motor's
    /// tension at the base).
    pub fn tension(&self, i: usize) -> f64 {
        self.tension[i]
    }

    /// Set (or with `None` remove) the capstan friction profile: the
    /// tensions set by [`Rod::set_tensions`] become the motors' tensions at
    /// s = 0, and tendon i's tension at s is τ_i,m e_i(s).
    pub fn set_profile(&mut self, profile: Option<Arc<TensionProfile>>) {
        self.profile = profile;
    }

    /// The friction profile in use, if any.
    pub fn profile(&self) -> Option<&Arc<TensionProfile>> {
        self.profile.as_ref()
    }

    /// Tendon `i`'s tension factor at `s` and its logarithmic derivative:
    /// (e_i(s), e_i'(s)/e_i(s)); (1, 0) without friction. Since τ_i(s) =
    /// τ_i,m e_i(s), this is also ∂τ_i(s)/∂τ_i,m.
    #[inline(always)]
    pub(super) fn tension_factor(&self, i: usize, s: f64) -> (f64, f64) {
        match &self.profile {
            None => (1.0, 0.0),
            Some(p) => p.factor(i, s),
        }
    }

    /// Tendon `i`'s tension τ_i(s) (N) and its gradient τ_i'(s) (N/m) at
    /// arc length `s`: (τ_i, 0) without friction.
    #[inline(always)]
    pub(super) fn tension_at(&self, i: usize, s: f64) -> (f64, f64) {
        let tau = self.tension[i];
        match &self.profile {
            None => (tau, 0.0),
            Some(p) => {
                let (e, dlog) = p.factor(i, s);
                (tau * e, tau * e * dlog)
            }
        }
    }

    /// Where tendon `i` runs at arc length `s` of the rod in `state` (base
    /// frame, m): p + R r_i(s); None past its anchor.
    pub fn tendon_point(&self, i: usize, s: f64, state: &RodState) -> Option<Vector3<f64>> {
        (i < self.n_tendons && s <= self.end[i]).then(|| state.p + state.rot * self.routing(i, s).r)
    }

    /// Tendon `i`'s offset r_i(s) with r_i'(s), r_i''(s).
    pub(super) fn routing(&self, i: usize, s: f64) -> Routing {
        if let Some(r) = self.straight[i] {
            return Routing {
                r,
                ..Routing::default()
            };
        }
        let (d, phi0, rate) = self.geometry[i];
        let (sn, cs) = (phi0 + rate * s).sin_cos();
        Routing {
            r: Vector3::new(d * cs, d * sn, 0.0),
            dr: Vector3::new(-d * rate * sn, d * rate * cs, 0.0),
            ddr: Vector3::new(-d * rate * rate * cs, -d * rate * rate * sn, 0.0),
        }
    }

    /// Internal force n = Kse (v − e3) and moment m = Kbt u, body frame (N, N·m).
    pub fn internal_wrench(&self, state: &RodState) -> (Vector3<f64>, Vector3<f64>) {
        (
            self.kse.component_mul(&state.w),
            self.kbt.component_mul(&state.u),
        )
    }

    /// Tendon tangent in the body frame, q_i = û r_i + r_i' + v.
    pub(super) fn tendon_tangent(state: &RodState, g: &Routing) -> Vector3<f64> {
        state.u.cross(&g.r) + g.dr + state.v()
    }

    /// The coupled strain-rate system of `docs/design.md` §2:
    ///
    /// ```text
    /// [Kse + A   G      ] [v']   [ −û n − Rᵀ f_e − a ]
    /// [Gᵀ        Kbt + H] [u'] = [ −û m − v̂ n − b    ]
    /// ```
    ///
    /// with, per tendon, A_i = −τ_i q̂_i² / |q_i|³, G_i = −A_i r̂_i,
    /// a_i = A_i (û q_i + û r_i' + r_i''), b_i = r̂_i a_i, H_i = r̂_i G_i.
    /// The matrix is symmetric positive definite; solved by Cholesky. Only
    /// the tendons in `running` load the rod here (`docs/design.md` §2.1).
    /// With a friction profile, τ_i is τ_i(s) and the friction force
    /// f_i = τ_i' q_i/|q_i| at r_i is one more explicit load (§2.3):
    /// top −= Σ f_i, bottom −= Σ r_i × f_i.
    pub fn strain_rates(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
    ) -> Result<(Vector3<f64>, Vector3<f64>), SingularSystem> {
        match &self.profile {
            None => self.strain_rates_with::<false>(s, state, running),
            Some(_) => self.strain_rates_with::<true>(s, state, running),
        }
    }

    /// [`Rod::strain_rates`] with (`FRICTION`) or without the tension
    /// profile, chosen by the caller once per step rather than per stage.
    #[inline(always)]
    fn strain_rates_with<const FRICTION: bool>(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
    ) -> Result<(Vector3<f64>, Vector3<f64>), SingularSystem> {
        // The same assembly and factor as [`Rod::system`] (so the plain and
        // the tangent pass stay bit-identical), without keeping the parts.
        let (k, rhs) = self.assemble_with::<FRICTION>(s, state, running, |_| {});
        let (_, x) = Factor6::ldlt_solve(&k, rhs).ok_or(SingularSystem { s })?;
        Ok((
            Vector3::new(x[0], x[1], x[2]),
            Vector3::new(x[3], x[4], x[5]),
        ))
    }

    /// The strain-rate system at one point, assembled, factored and solved;
    /// the factor and each tendon's terms stay for the tangent pass.
    pub(super) fn system(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
    ) -> Result<System, SingularSystem> {
        let mut terms = [TendonTerms::default(); MAX_TENDONS];
        let mut n_terms = 0;
        let (k, rhs) = self.assemble(s, state, running, |term| {
            terms[n_terms] = term;
            n_terms += 1;
        });
        // K is SPD by construction: K = diag(Kse, Kbt) + Σ Bᵢᵀ Aᵢ Bᵢ with
        // Bᵢ = [I, −r̂ᵢ] and Aᵢ ⪰ 0.
        let (factor, x) = Factor6::ldlt_solve(&k, rhs).ok_or(SingularSystem { s })?;
        let (n, m) = self.internal_wrench(state);
        Ok(System {
            factor,
            dw: Vector3::new(x[0], x[1], x[2]),
            du: Vector3::new(x[3], x[4], x[5]),
            n,
            m,
            terms,
            n_terms,
        })
    }

    /// The strain-rate matrix K (lower triangle, row-major) and right-hand
    /// side of [`Rod::strain_rates`], handing each running, pulled tendon's
    /// terms to `keep`. Per tendon, with Bᵢ = [I, −r̂ᵢ], Bᵢᵀ q = [q; k],
    /// k = r × q, and BᵢᵀBᵢ = [I, −r̂; r̂, |r|² I − r rᵀ]:
    /// Bᵢᵀ Aᵢ Bᵢ = c (|q|² BᵢᵀBᵢ − [q; k][q; k]ᵀ) — a rank-one update of a
    /// fixed pattern, so no 3×3 products are formed.
    #[inline(always)]
    fn assemble(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
        keep: impl FnMut(TendonTerms),
    ) -> ([[f64; 6]; 6], [f64; 6]) {
        match &self.profile {
            None => self.assemble_with::<false>(s, state, running, keep),
            Some(_) => self.assemble_with::<true>(s, state, running, keep),
        }
    }

    /// [`Rod::assemble`], with (`FRICTION`) or without the tension profile.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // block indices of K, as in the formula
    fn assemble_with<const FRICTION: bool>(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
        mut keep: impl FnMut(TendonTerms),
    ) -> ([[f64; 6]; 6], [f64; 6]) {
        let (n, m) = self.internal_wrench(state);
        let mut k = [[0.0; 6]; 6];
        for i in 0..3 {
            k[i][i] = self.kse[i];
            k[i + 3][i + 3] = self.kbt[i];
        }
        let mut a_sum = Vector3::zeros();
        let mut b_sum = Vector3::zeros();
        // Capstan friction forces Σ f_i and moments Σ r_i × f_i (body frame).
        let mut friction_f = Vector3::zeros();
        let mut friction_m = Vector3::zeros();
        // Only the pulled tendons that run here load the rod: visit their bits.
        let mut active = running & self.pulled;
        while active != 0 {
            let i = active.trailing_zeros() as usize;
            active &= active - 1;
            let (tau, dtau) = if FRICTION {
                self.tension_at(i, s)
            } else {
                (self.tension[i], 0.0)
            };
            let g = self.routing(i, s);
            let q = Self::tendon_tangent(state, &g);
            let q2 = q.norm_squared();
            let q_norm = q2.sqrt();
            let c = tau / (q2 * q_norm);
            let r = g.r;
            if FRICTION && dtau != 0.0 {
                // f_i = τ_i' t_i: the tension the guides take off the tendon
                // (d(τ_i t_i)/ds = τ_i t_i' + τ_i' t_i; the first part is A/a).
                let f_i = q * (dtau / q_norm);
                friction_f += f_i;
                friction_m += r.cross(&f_i);
            }
            let kq = r.cross(&q);
            let z = [q.x, q.y, q.z, kq.x, kq.y, kq.z];
            // The whole square (constant bounds vectorise; the upper
            // triangle is never read).
            for (row, &za) in k.iter_mut().zip(&z) {
                let cza = c * za;
                for (kab, &zb) in row.iter_mut().zip(&z) {
                    *kab -= cza * zb;
                }
            }
            let cq2 = c * q2;
            for a in 0..3 {
                k[a][a] += cq2;
            }
            // r̂ (lower-left block) and |r|² I − r rᵀ (lower-right block).
            k[3][1] -= cq2 * r.z;
            k[3][2] += cq2 * r.y;
            k[4][0] += cq2 * r.z;
            k[4][2] -= cq2 * r.x;
            k[5][0] -= cq2 * r.y;
            k[5][1] += cq2 * r.x;
            let r2 = r.norm_squared();
            for a in 0..3 {
                for b in 0..3 {
                    let id = if a == b { r2 } else { 0.0 };
                    k[a + 3][b + 3] += cq2 * (id - r[a] * r[b]);
                }
            }
            // a_i = A_i (û q + û r' + r''), b_i = r̂ a_i.
            let alpha = if self.straight[i].is_some() {
                state.u.cross(&q) // r' = r'' = 0
            } else {
                state.u.cross(&q) + state.u.cross(&g.dr) + g.ddr
            };
            let a_i = (alpha * q2 - q * q.dot(&alpha)) * c;
            a_sum += a_i;
            b_sum += r.cross(&a_i);
            keep(TendonTerms {
                r,
                dr: g.dr,
                q,
                q2,
                c,
                dtau,
                alpha,
            });
        }
        let v = state.v();
        let mut top = -state.u.cross(&n) - state.rot.tr_mul(&self.f_e) - a_sum;
        let mut bottom = -state.u.cross(&m) - v.cross(&n) - b_sum;
        if FRICTION {
            top -= friction_f;
            bottom -= friction_m;
        }
        (k, [top.x, top.y, top.z, bottom.x, bottom.y, bottom.z])
    }

    /// All state rates at arc length s with the tendons `running`:
    /// p' = R v, R' = R û, and the strain rates.
    pub fn rates(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
    ) -> Result<RodRates, SingularSystem> {
        match &self.profile {
            None => self.rates_with::<false>(s, state, running),
            Some(_) => self.rates_with::<true>(s, state, running),
        }
    }

    /// [`Rod::rates`] with (`FRICTION`) or without the tension profile:
    /// the RK4 step ([`super::integrate::rk4_step`]) picks once per step, so
    /// that the frictionless stages carry no branch (measured: one per stage
    /// cost ≈ 1–3 % of a solve's instructions).
    #[inline(always)]
    pub(super) fn rates_with<const FRICTION: bool>(
        &self,
        s: f64,
        state: &RodState,
        running: TendonSet,
    ) -> Result<RodRates, SingularSystem> {
        let (dw, du) = self.strain_rates_with::<FRICTION>(s, state, running)?;
        Ok(RodRates {
            dp: state.rot * state.v(),
            dr: rot_times_hat(&state.rot, &state.u),
            dw,
            du,
        })
    }

    /// Point force of tendon `i` on the rod where it is anchored (body frame):
    /// it pulls back along its own tangent, F_i = −τ_i(s) q_i/|q_i|.
    fn anchor_force(&self, i: usize, s: f64, state: &RodState) -> (Vector3<f64>, Vector3<f64>) {
        let g = self.routing(i, s);
        let q = Self::tendon_tangent(state, &g);
        let f_i = q * (-self.tension_at(i, s).0 / q.norm());
        (f_i, g.r)
    }

    /// The pull of the tendons in `set` on the section at `s` (body frame):
    /// force Σ τ_i(s) t_i and its moment Σ r_i × τ_i(s) t_i, with t_i = q_i/|q_i|.
    fn tendon_pull(
        &self,
        s: f64,
        state: &RodState,
        set: TendonSet,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let mut force = Vector3::zeros();
        let mut moment = Vector3::zeros();
        for i in 0..self.n_tendons {
            if set & (1 << i) == 0 || self.tension[i] == 0.0 {
                continue;
            }
            let (f_i, r_i) = self.anchor_force(i, s, state);
            force -= f_i;
            moment -= r_i.cross(&f_i);
        }
        (force, moment)
    }

    /// The state just past an anchor at `s` < L (`docs/design.md` §2.1).
    /// Every tendon anchored there applies its point load F_j = −τ_j q_j/|q_j|
    /// (strains just before s), so n(s⁺) = n(s⁻) − F_j, m(s⁺) = m(s⁻) − r̂_j F_j.
    /// Where the shear or torsion strain jumps, the tendons running on change
    /// direction too and pull on the section as well; the state past the anchor
    /// is the one that keeps the combined wrench of backbone and tendons,
    /// N = n + Σ τ_i t_i and M = m + Σ r_i × τ_i t_i, continuous. The rule
    /// above is its first iterate; Newton steps refine the running tendons'
    /// tangents from there, the Jacobian being the stiffness K of the tendons
    /// running on (see [`Rod::stiffness`]).
    pub fn across_anchor(&self, s: f64, before: &RodState) -> RodState {
        let crossing = self.running_to(s);
        let passing = crossing & !self.anchored_at(s);
        let (n, m) = self.internal_wrench(before);
        let (pull_f, pull_m) = self.tendon_pull(s, before, crossing);
        let (big_n, big_m) = (n + pull_f, m + pull_m);
        let (pass_f, pass_m) = self.tendon_pull(s, before, passing);
        let mut after = RodState {
            w: (big_n - pass_f).component_div(&self.kse),
            u: (big_m - pass_m).component_div(&self.kbt),
            ..*before
        };
        if passing == 0 {
            return after;
        }
        for _ in 0..ANCHOR_NEWTON_STEPS {
            let (n, m) = self.internal_wrench(&after);
            let (pass_f, pass_m) = self.tendon_pull(s, &after, passing);
            let gap_f = n + pass_f - big_n;
            let gap_m = m + pass_m - big_m;
            let gap = Vector6::new(gap_f.x, gap_f.y, gap_f.z, gap_m.x, gap_m.y, gap_m.z);
            let Some(step) = self
                .stiffness(s, &after, passing)
                .cholesky()
                .map(|c| c.solve(&gap))
            else {
                break;
            };
            after.w -= Vector3::new(step[0], step[1], step[2]);
            after.u -= Vector3::new(step[3], step[4], step[5]);
        }
        after
    }

    /// K = diag(Kse, Kbt) + Σ Bᵢᵀ Aᵢ Bᵢ over the tendons in `set` at `state`,
    /// with Aᵢ = (τᵢ(s)/|qᵢ|)(I − tᵢ tᵢᵀ) and Bᵢ = [I, −r̂ᵢ]: the strain-rate
    /// matrix, and also the derivative of the combined wrench [N; M] (body
    /// frame) with respect to the strains (w, u).
    pub(super) fn stiffness(&self, s: f64, state: &RodState, set: TendonSet) -> Matrix6<f64> {
        let mut k = Matrix6::from_diagonal(&Vector6::new(
            self.kse.x, self.kse.y, self.kse.z, self.kbt.x, self.kbt.y, self.kbt.z,
        ));
        for i in 0..self.n_tendons {
            if set & (1 << i) == 0 || self.tension[i] == 0.0 {
                continue;
            }
            let g = self.routing(i, s);
            let q = Self::tendon_tangent(state, &g);
            let norm = q.norm();
            let t = q / norm;
            let a = (Matrix3::identity() - t * t.transpose()) * (self.tension_at(i, s).0 / norm);
            let r_hat = hat(&g.r);
            let a_r = a * r_hat;
            let mut block = Matrix6::zeros();
            block.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
            block.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-a_r));
            block.fixed_view_mut::<3, 3>(3, 0).copy_from(&(r_hat * a));
            block
                .fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(-(r_hat * a_r)));
            k += block;
        }
        k
    }

    /// Tip boundary residual (body frame):
    /// [−n(L) + Σ F_i + Rᵀ F_ext ; −m(L) + Σ r̂_i F_i + Rᵀ M_ext] with
    /// F_i = −τ_i(L) q_i(L)/|q_i(L)|, each tendon anchored at the tip pulling back
    /// along its own tangent (with friction, at the tension that reaches it). External loads are given in the base frame (N, N·m).
    pub fn tip_residual(
        &self,
        tip: &RodState,
        f_ext: &Vector3<f64>,
        m_ext: &Vector3<f64>,
    ) -> Vector6<f64> {
        let (n, m) = self.internal_wrench(tip);
        let mut force = -n + tip.rot.tr_mul(f_ext);
        let mut moment = -m + tip.rot.tr_mul(m_ext);
        for i in 0..self.n_tendons {
            if self.tension[i] == 0.0 || self.end[i] < self.length {
                continue;
            }
            let (f_i, r_i) = self.anchor_force(i, self.length, tip);
            force += f_i;
            moment += r_i.cross(&f_i);
        }
        Vector6::new(force.x, force.y, force.z, moment.x, moment.y, moment.z)
    }

    /// Rough base wrench (n(0), u(0)) for a cold start: the tendons' tip
    /// loads, and the weight and tip load carried to the base along the arc
    /// the tendons alone would bend the rod into (constant curvature
    /// u_t = m_t ⊘ Kbt). Exact for straight tip-anchored tendons without
    /// gravity or tip load; a good Newton start otherwise (wherever a tendon
    /// is anchored, its net load on the rod is its pull where it leaves the
    /// base), and better than the straight rod's moments once the rod bends.
    pub fn initial_guess(&self, f_ext: &Vector3<f64>, m_ext: &Vector3<f64>) -> Vector6<f64> {
        let mut n0 = self.f_e * self.length + f_ext;
        let mut m_t = Vector3::zeros();
        for i in 0..self.n_tendons {
            let f_i = Vector3::new(0.0, 0.0, -self.tension[i]);
            n0 += f_i;
            m_t += self.routing(i, self.length).r.cross(&f_i);
        }
        let (p_mean, p_tip) = arc_moments(&m_t.component_div(&self.kbt), self.length);
        let m0 = m_t + p_mean.cross(&self.f_e) + p_tip.cross(f_ext) + m_ext;
        let u0 = m0.component_div(&self.kbt);
        Vector6::new(n0.x, n0.y, n0.z, u0.x, u0.y, u0.z)
    }
}

/// For an inextensible arc from the base along e3 with constant body-frame
/// curvature `u` (no torsion) and length `l`: (∫₀ˡ p ds, p(l)), the first
/// moment of the arc (what a uniform load's moment about the base needs) and
/// its tip. With κ = |u| and w = u × e3 (the direction the arc bends, times κ):
/// p(s) = sin(κs)/κ e3 + (1 − cos κs)/κ² w.
fn arc_moments(u: &Vector3<f64>, l: f64) -> (Vector3<f64>, Vector3<f64>) {
    let e3 = Vector3::z();
    let w = u.cross(&e3);
    let k2 = w.norm_squared();
    let x2 = k2 * l * l;
    // (1 − cos κl)/κ², (l − sin(κl)/κ)/κ², sin(κl)/κ; series below κl = 1e-3,
    // where the closed forms lose their digits to cancellation.
    let (c1, c2, c3) = if x2 < 1e-6 {
        (
            l * l * (0.5 - x2 / 24.0),
            l * l * l * (1.0 / 6.0 - x2 / 120.0),
            l * (1.0 - x2 / 6.0),
        )
    } else {
        let k = k2.sqrt();
        let (sn, cs) = (k * l).sin_cos();
        ((1.0 - cs) / k2, (l - sn / k) / k2, sn / k)
    };
    (e3 * c1 + w * c2, e3 * c3 + w * c1)
}

#[cfg(test)]
mod tests;
