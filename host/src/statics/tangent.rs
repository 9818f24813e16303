//! Sensitivities of the rod to the shooting unknowns x = [n(0); u(0)]: the
//! variational equations integrated alongside the rod (`docs/design.md` §2),
//! giving the exact Jacobian of the discrete shooting map in one pass.
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

use nalgebra::{Matrix3, Matrix3x6, Matrix6, SMatrix, Vector3, Vector6};

use super::integrate::pieces;
use super::rod::{rot_times_hat, Factor, Rod, RodRates, RodState, SingularSystem, TendonSet};
use crate::robot::MAX_TENDONS;

/// ∂(R, w, u)/∂x of a rod state: one column per unknown of x = [n(0); u(0)].
/// (∂p/∂x is not carried: nothing in the residual depends on p.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tangent {
    /// ∂R/∂x_j.
    pub rot: [Matrix3<f64>; 6],
    /// ∂w/∂x.
    pub w: Matrix3x6<f64>,
    /// ∂u/∂x.
    pub u: Matrix3x6<f64>,
}

impl Tangent {
    /// At the base: R(0) = I fixed, w(0) = n(0) ⊘ Kse, u(0) = u(0).
    pub fn at_base(kse: &Vector3<f64>) -> Tangent {
        let mut w = Matrix3x6::zeros();
        let mut u = Matrix3x6::zeros();
        for k in 0..3 {
            w[(k, k)] = 1.0 / kse[k];
            u[(k, k + 3)] = 1.0;
        }
        Tangent {
            rot: [Matrix3::zeros(); 6],
            w,
            u,
        }
    }

    fn advanced(&self, rates: &Tangent, h: f64) -> Tangent {
        let mut rot = self.rot;
        for (r, d) in rot.iter_mut().zip(&rates.rot) {
            *r += d * h;
        }
        Tangent {
            rot,
            w: self.w + rates.w * h,
            u: self.u + rates.u * h,
        }
    }
}

impl Rod {
    /// State rates and their linearisation in the six directions `t`.
    /// `track_rotation`: whether ∂R matters (it does only under gravity or a
    /// tip load; otherwise it is left zero, which saves a third of the work).
    pub fn rates_with_tangent(
        &self,
        s: f64,
        y: &RodState,
        t: &Tangent,
        running: TendonSet,
        track_rotation: bool,
    ) -> Result<(RodRates, Tangent), SingularSystem> {
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
        let mut dg = Matrix6::zeros();
        for j in 0..6 {
            let dw: Vector3<f64> = t.w.column(j).into();
            let du: Vector3<f64> = t.u.column(j).into();
            let kse_dw = self.kse.component_mul(&dw);
            let mut top = du.cross(&sys.n) + y.u.cross(&kse_dw);
            if track_rotation {
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
            }
            dg.fixed_view_mut::<3, 1>(0, j).copy_from(&(-top));
            dg.fixed_view_mut::<3, 1>(3, j).copy_from(&(-bottom));
        }
        if !sys.solve_mut(&mut dg) {
            return Err(SingularSystem { s });
        }
        let mut rot = [Matrix3::zeros(); 6];
        if track_rotation {
            for (j, r) in rot.iter_mut().enumerate() {
                let du = Vector3::new(t.u[(0, j)], t.u[(1, j)], t.u[(2, j)]);
                *r = rot_times_hat(&t.rot[j], &y.u) + rot_times_hat(&y.rot, &du);
            }
        }
        let tangent = Tangent {
            rot,
            w: dg.fixed_view::<3, 6>(0, 0).into(),
            u: dg.fixed_view::<3, 6>(3, 0).into(),
        };
        Ok((rates, tangent))
    }

    /// [`Rod::across_anchor`] with its linearisation. The state past the
    /// anchor keeps the combined wrench [N; M] of backbone and tendons, whose
    /// derivative with respect to the strains is the stiffness K of the
    /// tendons crossing the section; so K⁺ δ(w, u)⁺ = K⁻ δ(w, u)⁻, K⁻ with
    /// every tendon crossing just before s, K⁺ with those running on.
    pub fn across_anchor_with_tangent(
        &self,
        s: f64,
        before: &RodState,
        t: &Tangent,
    ) -> Result<(RodState, Tangent), SingularSystem> {
        let after = self.across_anchor(s, before);
        let crossing = self.running_to(s);
        let passing = crossing & !self.anchored_at(s);
        let k_before = self.stiffness(s, before, crossing);
        let k_after = self.stiffness(s, &after, passing);
        let mut strains = Matrix6::zeros();
        strains.fixed_view_mut::<3, 6>(0, 0).copy_from(&t.w);
        strains.fixed_view_mut::<3, 6>(3, 0).copy_from(&t.u);
        let mut rhs = k_before * strains;
        let solved = match k_after.cholesky() {
            Some(c) => {
                c.solve_mut(&mut rhs);
                true
            }
            None => k_after.lu().solve_mut(&mut rhs),
        };
        if !solved {
            return Err(SingularSystem { s });
        }
        let out = Tangent {
            rot: t.rot,
            w: rhs.fixed_view::<3, 6>(0, 0).into(),
            u: rhs.fixed_view::<3, 6>(3, 0).into(),
        };
        Ok((after, out))
    }

    /// δF of tendon `i`'s pull F = −τ q/|q| for a change δq of its tangent.
    fn force_change(&self, i: usize, q: &Vector3<f64>, dq: &Vector3<f64>) -> Vector3<f64> {
        let norm = q.norm();
        let t = q / norm;
        (dq - t * t.dot(dq)) * (-self.tension[i] / norm)
    }

    /// Jacobian of [`Rod::tip_residual`] with respect to x, given the tip
    /// state and its tangent.
    pub fn tip_residual_jacobian(
        &self,
        tip: &RodState,
        t: &Tangent,
        f_ext: &Vector3<f64>,
        m_ext: &Vector3<f64>,
    ) -> Matrix6<f64> {
        let mut jac = Matrix6::zeros();
        for j in 0..6 {
            let dw: Vector3<f64> = t.w.column(j).into();
            let du: Vector3<f64> = t.u.column(j).into();
            let mut force = -self.kse.component_mul(&dw) + t.rot[j].tr_mul(f_ext);
            let mut moment = -self.kbt.component_mul(&du) + t.rot[j].tr_mul(m_ext);
            for i in 0..self.n_tendons {
                if self.tension[i] == 0.0 || self.end[i] < self.length {
                    continue;
                }
                let g = self.routing(i, self.length);
                let q = Self::tendon_tangent(tip, &g);
                let df = self.force_change(i, &q, &(du.cross(&g.r) + dw));
                force += df;
                moment += g.r.cross(&df);
            }
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&force);
            jac.fixed_view_mut::<3, 1>(3, j).copy_from(&moment);
        }
        jac
    }
}

/// One RK4 step of the state and its tangent together.
fn rk4_step_with_tangent(
    rod: &Rod,
    s: f64,
    y: &RodState,
    t: &Tangent,
    h: f64,
    running: TendonSet,
    track_rotation: bool,
) -> Result<(RodState, Tangent), SingularSystem> {
    let (k1, l1) = rod.rates_with_tangent(s, y, t, running, track_rotation)?;
    let (k2, l2) = rod.rates_with_tangent(
        s + 0.5 * h,
        &y.advanced(&k1, 0.5 * h),
        &t.advanced(&l1, 0.5 * h),
        running,
        track_rotation,
    )?;
    let (k3, l3) = rod.rates_with_tangent(
        s + 0.5 * h,
        &y.advanced(&k2, 0.5 * h),
        &t.advanced(&l2, 0.5 * h),
        running,
        track_rotation,
    )?;
    let (k4, l4) = rod.rates_with_tangent(
        s + h,
        &y.advanced(&k3, h),
        &t.advanced(&l3, h),
        running,
        track_rotation,
    )?;
    let avg = RodRates {
        dp: (k1.dp + (k2.dp + k3.dp) * 2.0 + k4.dp) / 6.0,
        dr: (k1.dr + (k2.dr + k3.dr) * 2.0 + k4.dr) / 6.0,
        dw: (k1.dw + (k2.dw + k3.dw) * 2.0 + k4.dw) / 6.0,
        du: (k1.du + (k2.du + k3.du) * 2.0 + k4.du) / 6.0,
    };
    let mut rot = [Matrix3::zeros(); 6];
    if track_rotation {
        for (j, r) in rot.iter_mut().enumerate() {
            *r = (l1.rot[j] + (l2.rot[j] + l3.rot[j]) * 2.0 + l4.rot[j]) / 6.0;
        }
    }
    let avg_t = Tangent {
        rot,
        w: (l1.w + (l2.w + l3.w) * 2.0 + l4.w) / 6.0,
        u: (l1.u + (l2.u + l3.u) * 2.0 + l4.u) / 6.0,
    };
    Ok((y.advanced(&avg, h), t.advanced(&avg_t, h)))
}

/// Integrate the rod and its tangent from the base to the tip on the same
/// piecewise grid as [`super::integrate::integrate`] (so the tip state is
/// bit-identical to it).
pub fn integrate_with_tangent(
    rod: &Rod,
    base: RodState,
    steps: usize,
    track_rotation: bool,
) -> Result<(RodState, Tangent), SingularSystem> {
    let mut y = base;
    let mut t = Tangent::at_base(&rod.kse);
    for piece in pieces(rod, steps) {
        for k in 0..piece.n {
            let s = piece.a + k as f64 * piece.h;
            (y, t) = rk4_step_with_tangent(rod, s, &y, &t, piece.h, piece.running, track_rotation)?;
        }
        if piece.ends_at_anchor(rod.length) {
            (y, t) = rod.across_anchor_with_tangent(piece.b, &y, &t)?;
        }
    }
    Ok((y, t))
}

/// Most columns of a [`FullTangent`]: the six shooting unknowns and one per
/// tendon.
pub const MAX_COLUMNS: usize = 6 + MAX_TENDONS;

/// ∂(p, R, w, u)/∂(x, τ) of a rod state: columns 0..6 are the shooting
/// unknowns x = [n(0); u(0)], columns 6.. the tendon tensions τ_i. This is
/// what the tip Jacobian ∂pose/∂τ needs (`docs/design.md` §4.1): the
/// position and rotation are carried, and the tensions enter the strain-rate
/// system, the anchor jumps and the tip condition directly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FullTangent {
    /// Columns in use: 6 + tendons.
    pub columns: usize,
    /// ∂p per column.
    pub p: [Vector3<f64>; MAX_COLUMNS],
    /// ∂R per column.
    pub rot: [Matrix3<f64>; MAX_COLUMNS],
    /// ∂w per column.
    pub w: [Vector3<f64>; MAX_COLUMNS],
    /// ∂u per column.
    pub u: [Vector3<f64>; MAX_COLUMNS],
}

impl FullTangent {
    /// At the base: p(0) = 0 and R(0) = I fixed, w(0) = n(0) ⊘ Kse,
    /// u(0) = u(0); nothing depends on τ yet.
    pub fn at_base(kse: &Vector3<f64>, tendons: usize) -> FullTangent {
        let mut t = FullTangent {
            columns: 6 + tendons,
            p: [Vector3::zeros(); MAX_COLUMNS],
            rot: [Matrix3::zeros(); MAX_COLUMNS],
            w: [Vector3::zeros(); MAX_COLUMNS],
            u: [Vector3::zeros(); MAX_COLUMNS],
        };
        for k in 0..3 {
            t.w[k][k] = 1.0 / kse[k];
            t.u[k + 3][k] = 1.0;
        }
        t
    }

    fn advanced(&self, rates: &FullTangent, h: f64) -> FullTangent {
        let mut out = *self;
        for j in 0..self.columns {
            out.p[j] += rates.p[j] * h;
            out.rot[j] += rates.rot[j] * h;
            out.w[j] += rates.w[j] * h;
            out.u[j] += rates.u[j] * h;
        }
        out
    }

    /// RK4's weighted mean (k1 + 2 k2 + 2 k3 + k4) / 6 of four rates.
    fn rk4_mean(k: [&FullTangent; 4]) -> FullTangent {
        let mut out = *k[0];
        for j in 0..k[0].columns {
            out.p[j] = (k[0].p[j] + (k[1].p[j] + k[2].p[j]) * 2.0 + k[3].p[j]) / 6.0;
            out.rot[j] = (k[0].rot[j] + (k[1].rot[j] + k[2].rot[j]) * 2.0 + k[3].rot[j]) / 6.0;
            out.w[j] = (k[0].w[j] + (k[1].w[j] + k[2].w[j]) * 2.0 + k[3].w[j]) / 6.0;
            out.u[j] = (k[0].u[j] + (k[1].u[j] + k[2].u[j]) * 2.0 + k[3].u[j]) / 6.0;
        }
        out
    }
}

/// [w; u] stacked.
fn stack(top: &Vector3<f64>, bottom: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z)
}

impl Rod {
    /// Tendon `i`'s pull on a section per newton of tension (body frame):
    /// [t_i; r_i × t_i], t_i = q_i/|q_i| — the derivative of the combined
    /// wrench and of the tip condition with respect to τ_i.
    fn unit_pull(&self, i: usize, s: f64, state: &RodState) -> Vector6<f64> {
        let g = self.routing(i, s);
        let t = Self::tendon_tangent(state, &g).normalize();
        stack(&t, &g.r.cross(&t))
    }

    /// State rates and their linearisation in every column of `t`: the
    /// state columns as in [`Rod::rates_with_tangent`] (rotation always
    /// tracked) plus ∂p' = ∂R v + R ∂w, and for a tension column the direct
    /// term ∂g/∂τ_i = [A_i ψ_i; r_i × A_i ψ_i] / τ_i (the tendon's part of g
    /// is linear in τ_i), which also exists where τ_i = 0.
    fn rates_with_full_tangent(
        &self,
        s: f64,
        y: &RodState,
        t: &FullTangent,
        running: TendonSet,
    ) -> Result<(RodRates, FullTangent), SingularSystem> {
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
        for (i, dg) in per_tension.iter_mut().enumerate().take(self.n_tendons) {
            if running & (1 << i) == 0 {
                continue;
            }
            let g = self.routing(i, s);
            let q = Self::tendon_tangent(y, &g);
            let q2 = q.norm_squared();
            let psi = sys.dw + sys.du.cross(&g.r) + y.u.cross(&q) + y.u.cross(&g.dr) + g.ddr;
            let a_psi = (psi * q2 - q * q.dot(&psi)) / (q2 * q2.sqrt());
            *dg = stack(&a_psi, &g.r.cross(&a_psi));
        }
        let mut out = *t;
        for j in 0..t.columns {
            let dw = t.w[j];
            let du = t.u[j];
            let kse_dw = self.kse.component_mul(&dw);
            let mut top = du.cross(&sys.n) + y.u.cross(&kse_dw) + t.rot[j].tr_mul(&self.f_e);
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
            }
            let mut dz = -stack(&top, &bottom);
            if j >= 6 {
                dz -= per_tension[j - 6];
            }
            let solved = match &sys.factor {
                Factor::Ldlt(c) => {
                    c.solve_vector(&mut dz);
                    true
                }
                Factor::Lu(lu) => lu.solve_mut(&mut dz),
            };
            if !solved {
                return Err(SingularSystem { s });
            }
            out.w[j] = dz.fixed_rows::<3>(0).into();
            out.u[j] = dz.fixed_rows::<3>(3).into();
            out.p[j] = t.rot[j] * v + y.rot * dw;
            out.rot[j] = rot_times_hat(&t.rot[j], &y.u) + rot_times_hat(&y.rot, &du);
        }
        Ok((rates, out))
    }

    /// [`Rod::across_anchor`] with the full linearisation: the combined
    /// wrench is continuous, K⁺ δz⁺ + Σ_passing δτ_i P_i⁺ = K⁻ δz⁻ +
    /// Σ_crossing δτ_i P_i⁻ with P_i the unit pull ([`Rod::unit_pull`]);
    /// p and R do not jump.
    fn across_anchor_with_full_tangent(
        &self,
        s: f64,
        before: &RodState,
        t: &FullTangent,
    ) -> Result<(RodState, FullTangent), SingularSystem> {
        let after = self.across_anchor(s, before);
        let crossing = self.running_to(s);
        let passing = crossing & !self.anchored_at(s);
        let k_before = self.stiffness(s, before, crossing);
        let k_after = self.stiffness(s, &after, passing);
        let cholesky = k_after.cholesky();
        let lu = k_after.lu();
        let mut out = *t;
        for j in 0..t.columns {
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
            let solved = match &cholesky {
                Some(c) => {
                    c.solve_mut(&mut rhs);
                    true
                }
                None => lu.solve_mut(&mut rhs),
            };
            if !solved {
                return Err(SingularSystem { s });
            }
            out.w[j] = rhs.fixed_rows::<3>(0).into();
            out.u[j] = rhs.fixed_rows::<3>(3).into();
        }
        Ok((after, out))
    }

    /// Jacobian of [`Rod::tip_residual`] with respect to every column of
    /// `t` (x, then τ): a tip-anchored tendon's pull enters directly,
    /// ∂r/∂τ_i = −[t_i; r_i × t_i].
    pub fn tip_residual_full_jacobian(
        &self,
        tip: &RodState,
        t: &FullTangent,
        f_ext: &Vector3<f64>,
        m_ext: &Vector3<f64>,
    ) -> SMatrix<f64, 6, MAX_COLUMNS> {
        let mut jac = SMatrix::<f64, 6, MAX_COLUMNS>::zeros();
        for j in 0..t.columns {
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
                    let df = self.force_change(i, &q, &(du.cross(&g.r) + dw));
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

/// One RK4 step of the state and its full tangent together.
fn rk4_step_with_full_tangent(
    rod: &Rod,
    s: f64,
    y: &RodState,
    t: &FullTangent,
    h: f64,
    running: TendonSet,
) -> Result<(RodState, FullTangent), SingularSystem> {
    let (k1, l1) = rod.rates_with_full_tangent(s, y, t, running)?;
    let (k2, l2) = rod.rates_with_full_tangent(
        s + 0.5 * h,
        &y.advanced(&k1, 0.5 * h),
        &t.advanced(&l1, 0.5 * h),
        running,
    )?;
    let (k3, l3) = rod.rates_with_full_tangent(
        s + 0.5 * h,
        &y.advanced(&k2, 0.5 * h),
        &t.advanced(&l2, 0.5 * h),
        running,
    )?;
    let (k4, l4) =
        rod.rates_with_full_tangent(s + h, &y.advanced(&k3, h), &t.advanced(&l3, h), running)?;
    let avg = RodRates {
        dp: (k1.dp + (k2.dp + k3.dp) * 2.0 + k4.dp) / 6.0,
        dr: (k1.dr + (k2.dr + k3.dr) * 2.0 + k4.dr) / 6.0,
        dw: (k1.dw + (k2.dw + k3.dw) * 2.0 + k4.dw) / 6.0,
        du: (k1.du + (k2.du + k3.du) * 2.0 + k4.du) / 6.0,
    };
    let avg_t = FullTangent::rk4_mean([&l1, &l2, &l3, &l4]);
    Ok((y.advanced(&avg, h), t.advanced(&avg_t, h)))
}

/// Integrate the rod and its full tangent (with respect to x and τ) from the
/// base to the tip on the solver's piecewise grid; the tip state is
/// bit-identical to [`super::integrate::integrate`]'s.
pub fn integrate_with_full_tangent(
    rod: &Rod,
    base: RodState,
    steps: usize,
) -> Result<(RodState, FullTangent), SingularSystem> {
    let mut y = base;
    let mut t = FullTangent::at_base(&rod.kse, rod.n_tendons);
    for piece in pieces(rod, steps) {
        for k in 0..piece.n {
            let s = piece.a + k as f64 * piece.h;
            (y, t) = rk4_step_with_full_tangent(rod, s, &y, &t, piece.h, piece.running)?;
        }
        if piece.ends_at_anchor(rod.length) {
            (y, t) = rod.across_anchor_with_full_tangent(piece.b, &y, &t)?;
        }
    }
    Ok((y, t))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use nalgebra::{Matrix6, Vector3, Vector6};

    use super::*;
    use crate::robot::Robot;
    use crate::statics::integrate::integrate;

    fn load(name: &str) -> Robot {
        Robot::load(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../robots")
                .join(name),
        )
        .unwrap()
    }

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
        let (tip, t) = integrate_with_tangent(&rod, base(&rod, &x), steps, track).unwrap();
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
