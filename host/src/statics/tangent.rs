//! Sensitivities of the rod to the shooting unknowns x = [n(0); u(0)] and,
//! for the tip Jacobian ∂pose/∂τ (`docs/design.md` §4.1), to the tendon
//! tensions τ: the variational equations integrated alongside the rod
//! (`docs/design.md` §2), giving the exact Jacobian of the discrete shooting
//! map in one pass. One propagation, [`Sensitivity`], serves both: the
//! shooting solve's [`ShootingSensitivity`] (six columns) and the tip
//! Jacobian's [`FullSensitivity`] (six columns and one per tendon).
//!
//! RK4 applied to the state and its linearisation together is exactly the
//! derivative of the RK4 map, so Newton on the residual sees its true
//! Jacobian and converges quadratically. The strain-rate system's factor is
//! reused for all six directions: K δz = −δg, where g(y, z) = K(y) z − b(y)
//! and δg is its change with the state at fixed z. Written per tendon with
//! ψ = z_v + z_u × r + û q + û r' + r'' (so that the tendon's part of g is
//! [A ψ; r × A ψ]) and A = c (|q|² I − q qᵀ), c = τ/|q|³:
//!
//! ```text
//! δ(A ψ) = c [ −(q·δq) ψ + 3 (q·δq)(q·ψ) q/|q|² − (q·ψ) δq − (δq·ψ) q ] + A δψ,
//! δq = δu × r + δw,   δψ = δu × q + u × δq + δu × r'.
//! ```
//!
//! With capstan friction (`docs/design.md` §2.3) the tension profile e_i(s)
//! is held fixed (it is the outer fixed point's, not a function of x): τ_i
//! becomes τ_i(s), the friction force f = τ_i' q/|q| adds
//! δf = (τ_i'/|q|)(δq − t (t·δq)) to δg, and a tension column is ∂/∂τ_i,m,
//! scaled by e_i(s). The Jacobian is then exact for the fixed profile; how
//! the profile itself moves with x is left out (Newton's Jacobian only
//! picks steps; the outer fixed point accounts for it).

use nalgebra::{Matrix3, SMatrix, Vector3, Vector6};

use super::integrate::pieces;
use super::rod::{rot_times_hat, Rod, RodRates, RodState, SingularSystem, TendonSet};
use crate::numerics::dense::Factor6;
use crate::numerics::rk4::{rk4_step, Rk4State};
use crate::robot::MAX_TENDONS;

/// Most columns of a [`Sensitivity`]: the six shooting unknowns and one per
/// tendon.
pub const MAX_COLUMNS: usize = 6 + MAX_TENDONS;

/// ∂(p, R, w, u)/∂(x, τ) of a rod state, one column per unknown, at most
/// `C` of them: columns 0..6 are the shooting unknowns x = [n(0); u(0)],
/// columns 6.. the tendon tensions τ_i. The tensions enter the strain-rate
/// system, the anchor jumps and the tip condition directly. ∂R and ∂p are
/// carried only when asked for: the shooting residual needs ∂R only under
/// gravity or a tip load and never ∂p, and leaving them zero saves a third
/// of the work.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensitivity<const C: usize> {
    /// Columns in use: 6 + tension columns.
    pub columns: usize,
    /// Whether ∂R is carried (otherwise it stays zero).
    pub rotation: bool,
    /// Whether ∂p is carried (otherwise it stays zero).
    pub position: bool,
    /// ∂p per column.
    pub p: [Vector3<f64>; C],
    /// ∂R per column.
    pub rot: [Matrix3<f64>; C],
    /// ∂w per column.
    pub w: [Vector3<f64>; C],
    /// ∂u per column.
    pub u: [Vector3<f64>; C],
}

/// The shooting solve's sensitivity: ∂(R, w, u)/∂x, the six columns of x.
pub type ShootingSensitivity = Sensitivity<6>;

/// The tip Jacobian's sensitivity: ∂(p, R, w, u)/∂(x, τ).
pub type FullSensitivity = Sensitivity<MAX_COLUMNS>;

impl<const C: usize> Sensitivity<C> {
    /// At the base: p(0) = 0 and R(0) = I fixed, w(0) = n(0) ⊘ Kse,
    /// u(0) = u(0); nothing depends on τ yet. `tendons` tension columns
    /// follow the six of x (none for a [`ShootingSensitivity`]).
    pub fn at_base(kse: &Vector3<f64>, tendons: usize, rotation: bool, position: bool) -> Self {
        assert!(
            6 + tendons <= C,
            "{tendons} tension columns do not fit in {C}"
        );
        let mut t = Sensitivity {
            columns: 6 + tendons,
            rotation,
            position,
            p: [Vector3::zeros(); C],
            rot: [Matrix3::zeros(); C],
            w: [Vector3::zeros(); C],
            u: [Vector3::zeros(); C],
        };
        for k in 0..3 {
            t.w[k][k] = 1.0 / kse[k];
            t.u[k + 3][k] = 1.0;
        }
        t
    }

    /// The columns to visit: a constant for the shooting sensitivity, so
    /// that its loops have constant bounds (it is on the statics hot path).
    #[inline(always)]
    fn live(&self) -> usize {
        if C == 6 {
            6
        } else {
            self.columns
        }
    }
}

impl<const C: usize> Rk4State for Sensitivity<C> {
    type Rates = Sensitivity<C>;

    // One loop per field, the carried-or-not test outside it, so that the
    // shooting sensitivity's constant-bound loops vectorise.
    #[inline(always)]
    fn advanced(&self, rates: &Self, h: f64) -> Self {
        let n = self.live();
        let mut out = *self;
        if self.position {
            for j in 0..n {
                out.p[j] += rates.p[j] * h;
            }
        }
        if self.rotation {
            for j in 0..n {
                out.rot[j] += rates.rot[j] * h;
            }
        }
        for j in 0..n {
            out.w[j] += rates.w[j] * h;
        }
        for j in 0..n {
            out.u[j] += rates.u[j] * h;
        }
        out
    }

    #[inline(always)]
    fn rk4_mean(k: [&Self; 4]) -> Self {
        let n = k[0].live();
        let mut out = *k[0];
        if k[0].position {
            for j in 0..n {
                out.p[j] = (k[0].p[j] + (k[1].p[j] + k[2].p[j]) * 2.0 + k[3].p[j]) / 6.0;
            }
        }
        if k[0].rotation {
            for j in 0..n {
                out.rot[j] = (k[0].rot[j] + (k[1].rot[j] + k[2].rot[j]) * 2.0 + k[3].rot[j]) / 6.0;
            }
        }
        for j in 0..n {
            out.w[j] = (k[0].w[j] + (k[1].w[j] + k[2].w[j]) * 2.0 + k[3].w[j]) / 6.0;
        }
        for j in 0..n {
            out.u[j] = (k[0].u[j] + (k[1].u[j] + k[2].u[j]) * 2.0 + k[3].u[j]) / 6.0;
        }
        out
    }
}

impl FullSensitivity {
    /// At the base of `rod`, with one tension column per tendon and ∂p, ∂R
    /// carried: what the tip Jacobian needs.
    pub fn with_tensions(rod: &Rod) -> FullSensitivity {
        Self::at_base(&rod.kse, rod.n_tendons, true, true)
    }
}

/// [w; u] stacked.
fn stack(top: &Vector3<f64>, bottom: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z)
}

impl Rod {
    /// Tendon `i`'s pull on a section at `s` per newton of motor tension
    /// (body frame): e_i(s) [t_i; r_i × t_i], t_i = q_i/|q_i| — the
    /// derivative of the combined wrench and of the tip condition with
    /// respect to τ_i (e_i = 1 without friction).
    fn unit_pull(&self, i: usize, s: f64, state: &RodState) -> Vector6<f64> {
        let g = self.routing(i, s);
        let t = Self::tendon_tangent(state, &g).normalize();
        let pull = stack(&t, &g.r.cross(&t));
        match self.profile() {
            None => pull,
            Some(_) => pull * self.tension_factor(i, s).0,
        }
    }

    /// δF of tendon `i`'s pull F = −τ_i(s) q/|q| at `s` for a change δq of
    /// its tangent.
    pub(super) fn force_change(
        &self,
        i: usize,
        s: f64,
        q: &Vector3<f64>,
        dq: &Vector3<f64>,
    ) -> Vector3<f64> {
        let norm = q.norm();
        let t = q / norm;
        (dq - t * t.dot(dq)) * (-self.tension_at(i, s).0 / norm)
    }

    /// State rates and their linearisation in every column of `t`: the
    /// strain rates from K δz = −δg (the strain-rate factor reused for every
    /// column), ∂R' = ∂R û + R ∂û and ∂p' = ∂R v + R ∂w where carried, and
    /// for a tension column the direct term ∂g/∂τ_i = [A_i ψ_i; r_i × A_i
    /// ψ_i] / τ_i (the tendon's part of g is linear in τ_i), which also
    /// exists where τ_i = 0.
    pub fn rates_with_sensitivity<const C: usize>(
        &self,
        s: f64,
        y: &RodState,
        t: &Sensitivity<C>,
        running: TendonSet,
    ) -> Result<(RodRates, Sensitivity<C>), SingularSystem> {
        let sys = self.system(s, y, running)?;
        let rates = RodRates {
            dp: y.rot * y.v(),
            dr: rot_times_hat(&y.rot, &y.u),
            dw: sys.dw,
            du: sys.du,
        };
        let v = y.v();
        let terms = &sys.terms[..sys.n_terms];
        let mut psi = [Vector3::zeros(); MAX_TENDONS];
        for (p, term) in psi.iter_mut().zip(terms) {
            *p = sys.dw + sys.du.cross(&term.r) + term.alpha;
        }
        let mut per_tension = [Vector6::zeros(); MAX_TENDONS];
        let tension_columns = t.live() - 6;
        for (i, dg) in per_tension.iter_mut().enumerate().take(tension_columns) {
            if running & (1 << i) == 0 {
                continue;
            }
            let g = self.routing(i, s);
            let q = Self::tendon_tangent(y, &g);
            let q2 = q.norm_squared();
            let psi = sys.dw + sys.du.cross(&g.r) + y.u.cross(&q) + y.u.cross(&g.dr) + g.ddr;
            let mut a_psi = (psi * q2 - q * q.dot(&psi)) / (q2 * q2.sqrt());
            if self.profile().is_some() {
                // τ_i(s) = τ_i,m e_i(s) and the friction force τ_i,m e_i' t_i
                // are both linear in the motor's tension.
                let (e, dlog) = self.tension_factor(i, s);
                a_psi = (a_psi + q * (dlog / q2.sqrt())) * e;
            }
            *dg = stack(&a_psi, &g.r.cross(&a_psi));
        }
        let mut out = *t;
        let mut dz = [Vector6::zeros(); C];
        for j in 0..t.live() {
            let dw = t.w[j];
            let du = t.u[j];
            let kse_dw = self.kse.component_mul(&dw);
            let mut top = du.cross(&sys.n) + y.u.cross(&kse_dw);
            if t.rotation {
                top += t.rot[j].tr_mul(&self.f_e);
            }
            let mut bottom = du.cross(&sys.m)
                + y.u.cross(&self.kbt.component_mul(&du))
                + dw.cross(&sys.n)
                + v.cross(&kse_dw);
            for (term, psi) in terms.iter().zip(&psi) {
                let dq = du.cross(&term.r) + dw;
                let dpsi = du.cross(&term.q) + y.u.cross(&dq) + du.cross(&term.dr);
                let q_dq = term.q.dot(&dq);
                let q_psi = term.q.dot(psi);
                let d_apsi = (psi * (-q_dq) + term.q * (3.0 * q_dq * q_psi / term.q2)
                    - dq * q_psi
                    - term.q * dq.dot(psi)
                    + dpsi * term.q2
                    - term.q * term.q.dot(&dpsi))
                    * term.c;
                top += d_apsi;
                bottom += term.r.cross(&d_apsi);
                if term.dtau != 0.0 {
                    // δ of the friction force τ' q/|q| at a fixed profile.
                    let df = (dq - term.q * (q_dq / term.q2)) * (term.dtau / term.q2.sqrt());
                    top += df;
                    bottom += term.r.cross(&df);
                }
            }
            dz[j] = -stack(&top, &bottom);
            if j >= 6 {
                dz[j] -= per_tension[j - 6];
            }
        }
        // K δz = −δg for every column with the one factor.
        if !sys.factor.solve_columns(&mut dz[..t.live()]) {
            return Err(SingularSystem { s });
        }
        for (j, dz) in dz.iter().enumerate().take(t.live()) {
            let dw = t.w[j];
            let du = t.u[j];
            out.w[j] = dz.fixed_rows::<3>(0).into();
            out.u[j] = dz.fixed_rows::<3>(3).into();
            if t.position {
                out.p[j] = t.rot[j] * v + y.rot * dw;
            }
            if t.rotation {
                out.rot[j] = rot_times_hat(&t.rot[j], &y.u) + rot_times_hat(&y.rot, &du);
            }
        }
        Ok((rates, out))
    }

    /// [`Rod::across_anchor`] with its linearisation. The state past the
    /// anchor keeps the combined wrench [N; M] of backbone and tendons, whose
    /// derivative with respect to the strains is the stiffness K of the
    /// tendons crossing the section: K⁺ δz⁺ + Σ_passing δτ_i P_i⁺ = K⁻ δz⁻ +
    /// Σ_crossing δτ_i P_i⁻, K⁻ with every tendon crossing just before s, K⁺
    /// with those running on, P_i the unit pull ([`Rod::unit_pull`]); p and
    /// R do not jump.
    pub fn across_anchor_with_sensitivity<const C: usize>(
        &self,
        s: f64,
        before: &RodState,
        t: &Sensitivity<C>,
    ) -> Result<(RodState, Sensitivity<C>), SingularSystem> {
        let after = self.across_anchor(s, before);
        let crossing = self.running_to(s);
        let passing = crossing & !self.anchored_at(s);
        let k_before = self.stiffness(s, before, crossing);
        let k_after = Factor6::cholesky_or_lu(self.stiffness(s, &after, passing));
        let mut out = *t;
        for j in 0..t.live() {
            let mut rhs = k_before * stack(&t.w[j], &t.u[j]);
            if j >= 6 {
                let i = j - 6;
                if crossing & (1 << i) != 0 {
                    rhs += self.unit_pull(i, s, before);
                }
                if passing & (1 << i) != 0 {
                    rhs -= self.unit_pull(i, s, &after);
                }
            }
            if !k_after.solve_vector(&mut rhs) {
                return Err(SingularSystem { s });
            }
            out.w[j] = rhs.fixed_rows::<3>(0).into();
            out.u[j] = rhs.fixed_rows::<3>(3).into();
        }
        Ok((after, out))
    }

    /// Jacobian of [`Rod::tip_residual`] with respect to every column of
    /// `t` (x, then τ), given the tip state and its sensitivity: a
    /// tip-anchored tendon's pull enters directly, ∂r/∂τ_i = −[t_i; r_i × t_i].
    pub fn tip_residual_jacobian<const C: usize>(
        &self,
        tip: &RodState,
        t: &Sensitivity<C>,
        f_ext: &Vector3<f64>,
        m_ext: &Vector3<f64>,
    ) -> SMatrix<f64, 6, C> {
        let mut jac = SMatrix::<f64, 6, C>::zeros();
        for j in 0..t.live() {
            let dw = t.w[j];
            let du = t.u[j];
            let mut force = -self.kse.component_mul(&dw) + t.rot[j].tr_mul(f_ext);
            let mut moment = -self.kbt.component_mul(&du) + t.rot[j].tr_mul(m_ext);
            for i in 0..self.n_tendons {
                if self.end[i] < self.length {
                    continue;
                }
                let g = self.routing(i, self.length);
                if self.tension[i] != 0.0 {
                    let q = Self::tendon_tangent(tip, &g);
                    let df = self.force_change(i, self.length, &q, &(du.cross(&g.r) + dw));
                    force += df;
                    moment += g.r.cross(&df);
                }
                if j == 6 + i {
                    let pull = self.unit_pull(i, self.length, tip);
                    force -= pull.fixed_rows::<3>(0);
                    moment -= pull.fixed_rows::<3>(3);
                }
            }
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&force);
            jac.fixed_view_mut::<3, 1>(3, j).copy_from(&moment);
        }
        jac
    }
}

/// Integrate the rod and its sensitivity from `start` (at the base, see
/// [`Sensitivity::at_base`]) to the tip on the solver's piecewise grid, one
/// RK4 step of the pair at a time: RK4 of the state and its linearisation
/// together is exactly the derivative of the RK4 map. The tip state is
/// bit-identical to [`super::integrate::integrate`]'s.
pub fn integrate_with_sensitivity<const C: usize>(
    rod: &Rod,
    base: RodState,
    steps: usize,
    start: Sensitivity<C>,
) -> Result<(RodState, Sensitivity<C>), SingularSystem> {
    let mut yt = (base, start);
    for piece in pieces(rod, steps) {
        for k in 0..piece.n {
            let s = piece.a + k as f64 * piece.h;
            yt = rk4_step(s, &yt, piece.h, |_, s, (y, t)| {
                rod.rates_with_sensitivity(s, y, t, piece.running)
            })?;
        }
        if piece.ends_at_anchor(rod.length) {
            yt = rod.across_anchor_with_sensitivity(piece.b, &yt.0, &yt.1)?;
        }
    }
    Ok(yt)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix6, Vector3, Vector6};

    use super::*;
    use crate::robot::{repo_robot as load, Robot};
    use crate::statics::integrate::integrate;

    fn base(rod: &Rod, x: &Vector6<f64>) -> RodState {
        RodState::at_base(
            &Vector3::new(x[0], x[1], x[2]),
            &Vector3::new(x[3], x[4], x[5]),
            &rod.kse,
        )
    }

    /// The sensitivity Jacobian against central differences of the residual.
    fn assert_jacobian_matches_differences(
        robot: &Robot,
        tau: &[f64],
        x: Vector6<f64>,
        f_ext: Vector3<f64>,
        m_ext: Vector3<f64>,
    ) {
        let mut rod = Rod::new(robot);
        rod.set_tensions(tau);
        let steps = 16;
        let track = rod.f_e.norm() > 0.0 || f_ext.norm() > 0.0 || m_ext.norm() > 0.0;
        let start = ShootingSensitivity::at_base(&rod.kse, 0, track, false);
        let (tip, t) = integrate_with_sensitivity(&rod, base(&rod, &x), steps, start).unwrap();
        // Same grid, same arithmetic: the tip is the plain pass's tip, bit for bit.
        assert_eq!(tip, integrate(&rod, base(&rod, &x), steps).unwrap());
        let exact = rod.tip_residual_jacobian(&tip, &t, &f_ext, &m_ext);
        let residual = |x: &Vector6<f64>| {
            let tip = integrate(&rod, base(&rod, x), steps).unwrap();
            rod.tip_residual(&tip, &f_ext, &m_ext)
        };
        let mut fd = Matrix6::zeros();
        for j in 0..6 {
            let h = 1e-6 * x[j].abs().max(if j < 3 { 1.0 } else { 0.1 });
            let mut xp = x;
            let mut xm = x;
            xp[j] += h;
            xm[j] -= h;
            fd.set_column(j, &((residual(&xp) - residual(&xm)) / (2.0 * h)));
        }
        for j in 0..6 {
            let scale = fd.column(j).norm().max(1e-3);
            let err = (exact.column(j) - fd.column(j)).norm() / scale;
            assert!(
                err < 1e-5,
                "column {j}: exact {} vs differences {} (rel {err:e})",
                exact.column(j),
                fd.column(j)
            );
        }
    }

    #[test]
    fn sensitivities_give_the_residual_jacobian_under_gravity() {
        let robot = load("seed-4t.toml");
        let x = Vector6::new(0.3, -0.2, -9.0, -1.2, 0.8, 0.05);
        assert_jacobian_matches_differences(
            &robot,
            &[6.0, 3.0, 0.0, 0.0],
            x,
            Vector3::zeros(),
            Vector3::zeros(),
        );
    }

    #[test]
    fn sensitivities_give_the_residual_jacobian_across_anchors_with_a_tip_wrench() {
        let robot = load("tdcr-2seg.toml");
        let x = Vector6::new(0.1, 0.05, -6.5, -3.0, 1.5, 0.1);
        assert_jacobian_matches_differences(
            &robot,
            &[4.0, 0.0, 1.0, 0.0, 2.0, 0.5],
            x,
            Vector3::new(0.05, -0.1, 0.02),
            Vector3::new(0.004, 0.0, -0.002),
        );
        // Helical routing: r' and r'' enter the tangent equations.
        let mut helical = load("seed-4t.toml").without_gravity();
        helical.tendons[0].routing = crate::robot::Routing::Helical { turns: 0.5 };
        helical.tendons[1].end = 0.25;
        assert_jacobian_matches_differences(
            &helical,
            &[4.0, 2.0, 0.0, 0.0],
            Vector6::new(0.0, 0.1, -6.0, -0.5, 0.4, 0.2),
            Vector3::zeros(),
            Vector3::zeros(),
        );
    }
}
