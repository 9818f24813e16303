//! The dynamic Cosserat rod at one grid point after the time discretisation
//! (`docs/design.md` §4.2; Till, Aloi & Rucker 2019, with the tendon loads of
//! Rucker & Webster 2011 as in `docs/design.md` §2):
//!
//! ```text
//! p_s = R v                     R_s = R û
//! n = Kse (v − e₃) + Bse v_t    m = Kbt u + Bbt u_t
//! n_s = −û n − Rᵀ f_e − f_t + ρA (ω̂ q + q_t)
//! m_s = −û m − v̂ n − l_t + ω̂ ρJ ω + ρJ ω_t
//! q_s = v_t − û q + ω̂ v         ω_s = u_t − û ω
//! ```
//!
//! with every time derivative x_t = c₀ x + x_h (BDF-α), q and ω the body-frame
//! linear and angular velocities and f_t = a + A v_s + G u_s,
//! l_t = b + Gᵀ v_s + H u_s the tendons' distributed load. Differentiating the
//! constitutive law gives n_s = (Kse + c₀ Bse) v_s + Bse (v_s)_h, so the
//! strain rates solve the statics' 6×6 system with Kse + c₀ Bse and
//! Kbt + c₀ Bbt in place of Kse and Kbt.

use std::ops::{Add, Mul};
use std::sync::Arc;

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::numerics::dense::Factor6;
use crate::numerics::rk4::Rk4State;
use crate::robot::{hat, Robot, MAX_TENDONS};
use crate::statics::rod::{Rod, TendonSet};
use crate::statics::{SingularSystem, TensionProfile};

use super::params::Damping;

/// The quantities whose time derivatives enter the balance laws, at one
/// grid point: strains, velocities, and the strains' arc-length rates (for
/// the damping terms' (v_s)_t).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TimeVars {
    /// w = v − e₃.
    pub w: Vector3<f64>,
    /// u, 1/m.
    pub u: Vector3<f64>,
    /// q, body-frame linear velocity, m/s.
    pub q: Vector3<f64>,
    /// ω, body-frame angular velocity, rad/s.
    pub omega: Vector3<f64>,
    /// v_s, 1/m.
    pub ws: Vector3<f64>,
    /// u_s, 1/m².
    pub us: Vector3<f64>,
}

impl Add for TimeVars {
    type Output = TimeVars;
    fn add(self, o: TimeVars) -> TimeVars {
        TimeVars {
            w: self.w + o.w,
            u: self.u + o.u,
            q: self.q + o.q,
            omega: self.omega + o.omega,
            ws: self.ws + o.ws,
            us: self.us + o.us,
        }
    }
}

impl Mul<f64> for TimeVars {
    type Output = TimeVars;
    fn mul(self, k: f64) -> TimeVars {
        TimeVars {
            w: self.w * k,
            u: self.u * k,
            q: self.q * k,
            omega: self.omega * k,
            ws: self.ws * k,
            us: self.us * k,
        }
    }
}

/// The rod's state at one arc length and time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynState {
    /// Position p, base frame, m.
    pub p: Vector3<f64>,
    /// Orientation R (columns = body axes in the base frame).
    pub rot: Matrix3<f64>,
    /// Shear/extension strain deviation w = v − e₃ (as in the statics: keeps
    /// n exact to roundoff).
    pub w: Vector3<f64>,
    /// Curvature/torsion u, 1/m.
    pub u: Vector3<f64>,
    /// Body-frame linear velocity q, m/s.
    pub q: Vector3<f64>,
    /// Body-frame angular velocity ω, rad/s.
    pub omega: Vector3<f64>,
}

/// d/ds of a [`DynState`].
#[derive(Clone, Copy, Debug)]
pub struct DynRates {
    dp: Vector3<f64>,
    dr: Matrix3<f64>,
    dw: Vector3<f64>,
    du: Vector3<f64>,
    dq: Vector3<f64>,
    domega: Vector3<f64>,
}

impl DynState {
    /// The clamped base, s = 0: p = 0, R = I, at rest, strains (w, u).
    pub fn at_base(w: Vector3<f64>, u: Vector3<f64>) -> DynState {
        DynState {
            p: Vector3::zeros(),
            rot: Matrix3::identity(),
            w,
            u,
            q: Vector3::zeros(),
            omega: Vector3::zeros(),
        }
    }

    /// v = e₃ + w.
    pub fn v(&self) -> Vector3<f64> {
        self.w + Vector3::z()
    }

    /// The time-differentiated quantities of this state with its strain rates.
    pub(super) fn time_vars(&self, ws: Vector3<f64>, us: Vector3<f64>) -> TimeVars {
        TimeVars {
            w: self.w,
            u: self.u,
            q: self.q,
            omega: self.omega,
            ws,
            us,
        }
    }
}

impl Rk4State for DynState {
    type Rates = DynRates;

    /// `self + h · rates`.
    #[inline(always)]
    fn advanced(&self, r: &DynRates, h: f64) -> DynState {
        DynState {
            p: self.p + r.dp * h,
            rot: self.rot + r.dr * h,
            w: self.w + r.dw * h,
            u: self.u + r.du * h,
            q: self.q + r.dq * h,
            omega: self.omega + r.domega * h,
        }
    }

    #[inline(always)]
    fn rk4_mean(k: [&DynRates; 4]) -> DynRates {
        let avg = |f: fn(&DynRates) -> Vector3<f64>| {
            (f(k[0]) + (f(k[1]) + f(k[2])) * 2.0 + f(k[3])) / 6.0
        };
        DynRates {
            dp: avg(|r| r.dp),
            dr: (k[0].dr + (k[1].dr + k[2].dr) * 2.0 + k[3].dr) / 6.0,
            dw: avg(|r| r.dw),
            du: avg(|r| r.du),
            dq: avg(|r| r.dq),
            domega: avg(|r| r.domega),
        }
    }
}

/// The dynamic rod of one robot under one set of tensions and tip load.
#[derive(Clone, Debug)]
pub struct DynamicRod {
    /// The statics' rod: knots, running tendons, stiffness, weight.
    pub(super) rod: Rod,
    /// Bse, N·s, and Bbt, N·m²·s (diagonals).
    damping: Damping,
    /// ρA, mass per length, kg/m.
    rho_a: f64,
    /// ρJ diagonal, rotary inertia per length, kg·m.
    rho_j: Vector3<f64>,
    /// Per tendon: body-frame offset r, r', r'' as functions of s.
    tendons: Vec<crate::robot::Tendon>,
    /// Per tendon: constant offset when straight (the common, cheap case).
    straight: [Option<Vector3<f64>>; MAX_TENDONS],
    /// Tensions τ_i, N (with a friction profile, the motors' at s = 0).
    tension: [f64; MAX_TENDONS],
    /// Capstan friction (`docs/design.md` §2.3): τ_i(s) = τ_i,m e_i(s).
    profile: Option<Arc<TensionProfile>>,
    /// External tip force and moment, base frame, N and N·m.
    tip_load: (Vector3<f64>, Vector3<f64>),
}

/// A tendon's offset at s: r, r', r''.
struct Offset {
    r: Vector3<f64>,
    dr: Vector3<f64>,
    ddr: Vector3<f64>,
}

impl DynamicRod {
    /// The rod of `robot` with `damping`, tensions zero, no tip load.
    pub fn new(robot: &Robot, damping: Damping) -> DynamicRod {
        let i = robot.second_moment();
        let mut straight = [None; MAX_TENDONS];
        for (k, t) in robot.tendons.iter().enumerate() {
            if t.is_straight() {
                straight[k] = Some(t.offset_at(0.0, robot.length).r);
            }
        }
        DynamicRod {
            rod: Rod::new(robot),
            damping,
            rho_a: robot.density * robot.area(),
            // Solid circular section: J = diag(I, I, 2I).
            rho_j: Vector3::new(i, i, 2.0 * i) * robot.density,
            tendons: robot.tendons.clone(),
            straight,
            tension: [0.0; MAX_TENDONS],
            profile: None,
            tip_load: (Vector3::zeros(), Vector3::zeros()),
        }
    }

    /// Set (or with `None` remove) the capstan friction profile
    /// (`docs/design.md` §2.3): the tensions become the motors' and tendon
    /// i carries τ_i,m e_i(s), with the friction force τ_i' t_i on the rod.
    pub fn set_profile(&mut self, profile: Option<Arc<TensionProfile>>) {
        self.rod.set_profile(profile.clone());
        self.profile = profile;
    }

    /// Tendon `i`'s tension τ_i(s) (N) and gradient τ_i'(s) (N/m).
    fn tension_at(&self, i: usize, s: f64) -> (f64, f64) {
        let tau = self.tension[i];
        match &self.profile {
            None => (tau, 0.0),
            Some(p) => {
                let (e, dlog) = p.factor(i, s);
                (tau * e, tau * e * dlog)
            }
        }
    }

    /// Mass per length ρA, kg/m.
    pub fn mass_per_length(&self) -> f64 {
        self.rho_a
    }

    /// Set the tendon tensions (N), one per tendon, validated by the caller.
    pub fn set_tensions(&mut self, tau: &[f64]) {
        self.tension = [0.0; MAX_TENDONS];
        self.tension[..tau.len()].copy_from_slice(tau);
        self.rod.set_tensions(tau);
    }

    /// Set the external tip force (N) and moment (N·m), base frame.
    pub fn set_tip_load(&mut self, force: Vector3<f64>, moment: Vector3<f64>) {
        self.tip_load = (force, moment);
    }

    fn offset(&self, i: usize, s: f64) -> Offset {
        if let Some(r) = self.straight[i] {
            return Offset {
                r,
                dr: Vector3::zeros(),
                ddr: Vector3::zeros(),
            };
        }
        let o = self.tendons[i].offset_at(s, self.rod.length);
        Offset {
            r: o.r,
            dr: o.dr,
            ddr: o.ddr,
        }
    }

    /// Internal force and moment with damping, body frame (N, N·m):
    /// n = Kse w + Bse (c₀ w + w_h), m = Kbt u + Bbt (c₀ u + u_h).
    pub fn internal_wrench(
        &self,
        y: &DynState,
        hist: &TimeVars,
        c0: f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let w_t = y.w * c0 + hist.w;
        let u_t = y.u * c0 + hist.u;
        (
            self.rod.kse.component_mul(&y.w) + self.damping.bse.component_mul(&w_t),
            self.rod.kbt.component_mul(&y.u) + self.damping.bbt.component_mul(&u_t),
        )
    }

    /// d/ds of the state at (s, y), with `hist` the history terms of this grid
    /// point and `c0` the scheme's c₀ (c₀ = 0 with zero history: the statics).
    /// Also returns the time-differentiated quantities the history keeps.
    pub fn rates(
        &self,
        s: f64,
        y: &DynState,
        hist: &TimeVars,
        c0: f64,
        running: TendonSet,
    ) -> Result<(DynRates, TimeVars), SingularSystem> {
        // One branch per call, not per tendon (as in the statics, §2.3).
        match &self.profile {
            None => self.rates_with::<false>(s, y, hist, c0, running),
            Some(_) => self.rates_with::<true>(s, y, hist, c0, running),
        }
    }

    /// [`DynamicRod::rates`] with (`FRICTION`) or without the tension profile.
    #[inline(always)]
    fn rates_with<const FRICTION: bool>(
        &self,
        s: f64,
        y: &DynState,
        hist: &TimeVars,
        c0: f64,
        running: TendonSet,
    ) -> Result<(DynRates, TimeVars), SingularSystem> {
        let (kse, kbt) = (self.rod.kse, self.rod.kbt);
        let (bse, bbt) = (self.damping.bse, self.damping.bbt);
        let v = y.v();
        let v_t = y.w * c0 + hist.w;
        let u_t = y.u * c0 + hist.u;
        let q_t = y.q * c0 + hist.q;
        let omega_t = y.omega * c0 + hist.omega;
        let (n, m) = self.internal_wrench(y, hist, c0);

        // Tendon terms exactly as the statics' (docs/design.md §2).
        let mut a_mat = Matrix3::zeros();
        let mut g_mat = Matrix3::zeros();
        let mut h_mat = Matrix3::zeros();
        let mut a_vec = Vector3::zeros();
        let mut b_vec = Vector3::zeros();
        // Capstan friction forces τ_i' t_i and their moments (§2.3).
        let mut friction_f = Vector3::zeros();
        let mut friction_m = Vector3::zeros();
        for i in 0..self.tendons.len() {
            if self.tension[i] == 0.0 || running & (1 << i) == 0 {
                continue;
            }
            let (tau, dtau) = if FRICTION {
                self.tension_at(i, s)
            } else {
                (self.tension[i], 0.0)
            };
            let g = self.offset(i, s);
            let t = y.u.cross(&g.r) + g.dr + v;
            let t2 = t.norm_squared();
            if FRICTION && dtau != 0.0 {
                let f_i = t * (dtau / t2.sqrt());
                friction_f += f_i;
                friction_m += g.r.cross(&f_i);
            }
            let c = tau / (t2 * t2.sqrt());
            let a_i = (Matrix3::from_diagonal_element(t2) - t * t.transpose()) * c;
            let r_hat = hat(&g.r);
            let g_i = -a_i * r_hat;
            let alpha = y.u.cross(&t) + y.u.cross(&g.dr) + g.ddr;
            let a_vec_i = a_i * alpha;
            a_mat += a_i;
            g_mat += g_i;
            h_mat += r_hat * g_i;
            a_vec += a_vec_i;
            b_vec += g.r.cross(&a_vec_i);
        }

        let mut k = Matrix6::zeros();
        k.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::from_diagonal(&(kse + bse * c0)) + a_mat));
        k.fixed_view_mut::<3, 3>(0, 3).copy_from(&g_mat);
        k.fixed_view_mut::<3, 3>(3, 0).copy_from(&g_mat.transpose());
        k.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::from_diagonal(&(kbt + bbt * c0)) + h_mat));

        let inertia_f = (y.omega.cross(&y.q) + q_t) * self.rho_a;
        let j_omega = self.rho_j.component_mul(&y.omega);
        let inertia_m = y.omega.cross(&j_omega) + self.rho_j.component_mul(&omega_t);
        let mut top = -y.u.cross(&n) - y.rot.tr_mul(&self.rod.f_e) - a_vec + inertia_f
            - bse.component_mul(&hist.ws);
        let mut bottom =
            -y.u.cross(&m) - v.cross(&n) - b_vec + inertia_m - bbt.component_mul(&hist.us);
        if FRICTION {
            top -= friction_f;
            bottom -= friction_m;
        }
        let rhs = Vector6::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z);
        let mut x = rhs;
        if !Factor6::cholesky_or_lu(k).solve_vector(&mut x) || !x.iter().all(|v| v.is_finite()) {
            return Err(SingularSystem { s });
        }
        let ws = Vector3::new(x[0], x[1], x[2]);
        let us = Vector3::new(x[3], x[4], x[5]);
        let rates = DynRates {
            dp: y.rot * v,
            dr: y.rot * hat(&y.u),
            dw: ws,
            du: us,
            dq: v_t - y.u.cross(&y.q) + y.omega.cross(&v),
            domega: u_t - y.u.cross(&y.omega),
        };
        Ok((rates, y.time_vars(ws, us)))
    }

    /// Unit tangent of tendon `i` at (s, y), body frame, with its offset r.
    fn tendon_direction(&self, i: usize, s: f64, y: &DynState) -> (Vector3<f64>, Vector3<f64>) {
        let g = self.offset(i, s);
        let t = y.u.cross(&g.r) + g.dr + y.v();
        (t.normalize(), g.r)
    }

    /// Pull Σ τ_i t_i and its moment Σ r_i × τ_i t_i of the tendons in `set`.
    fn tendon_pull(&self, s: f64, y: &DynState, set: TendonSet) -> Vector6<f64> {
        let mut out = Vector6::zeros();
        for i in 0..self.tendons.len() {
            if set & (1 << i) == 0 || self.tension[i] == 0.0 {
                continue;
            }
            let (t, r) = self.tendon_direction(i, s, y);
            let f = t * self.tension_at(i, s).0;
            let mo = r.cross(&f);
            out += Vector6::new(f.x, f.y, f.z, mo.x, mo.y, mo.z);
        }
        out
    }

    fn anchored_at(&self, s: f64) -> TendonSet {
        (0..self.tendons.len())
            .filter(|&i| self.tendons[i].end == s)
            .fold(0, |set, i| set | (1 << i))
    }

    /// The state just past an inner anchor at `s`: the combined wrench of
    /// backbone and tendons, [n + Σ τ t; m + Σ r × τ t], stays continuous
    /// while the anchored tendons stop (`docs/design.md` §2.1), with the
    /// damped constitutive law on either side (`hist_before`, `hist_after`
    /// the two grid points' histories). Position, orientation and velocities
    /// are continuous.
    pub fn across_anchor(
        &self,
        s: f64,
        before: &DynState,
        hist_before: &TimeVars,
        hist_after: &TimeVars,
        c0: f64,
    ) -> DynState {
        let crossing = self.rod.running_to(s);
        let passing = crossing & !self.anchored_at(s);
        let (n, m) = self.internal_wrench(before, hist_before, c0);
        let combined =
            Vector6::new(n.x, n.y, n.z, m.x, m.y, m.z) + self.tendon_pull(s, before, crossing);
        let kse_eff = self.rod.kse + self.damping.bse * c0;
        let kbt_eff = self.rod.kbt + self.damping.bbt * c0;
        let strains_for = |target: Vector6<f64>| {
            let n = Vector3::new(target[0], target[1], target[2]);
            let m = Vector3::new(target[3], target[4], target[5]);
            (
                (n - self.damping.bse.component_mul(&hist_after.w)).component_div(&kse_eff),
                (m - self.damping.bbt.component_mul(&hist_after.u)).component_div(&kbt_eff),
            )
        };
        let (w, u) = strains_for(combined - self.tendon_pull(s, before, passing));
        let mut after = DynState { w, u, ..*before };
        // Newton on the passing tendons' direction change; the first iterate
        // is already within the ratio of tendon to section stiffness.
        for _ in 0..2 {
            if passing == 0 {
                break;
            }
            let (n, m) = self.internal_wrench(&after, hist_after, c0);
            let gap = Vector6::new(n.x, n.y, n.z, m.x, m.y, m.z)
                + self.tendon_pull(s, &after, passing)
                - combined;
            let jac = self.wrench_stiffness(s, &after, passing, &kse_eff, &kbt_eff);
            let Some(step) = jac.lu().solve(&gap) else {
                break;
            };
            after.w -= Vector3::new(step[0], step[1], step[2]);
            after.u -= Vector3::new(step[3], step[4], step[5]);
        }
        after
    }

    /// ∂[N; M]/∂(w, u) of backbone plus the tendons in `set`.
    fn wrench_stiffness(
        &self,
        s: f64,
        y: &DynState,
        set: TendonSet,
        kse_eff: &Vector3<f64>,
        kbt_eff: &Vector3<f64>,
    ) -> Matrix6<f64> {
        let mut k = Matrix6::from_diagonal(&Vector6::new(
            kse_eff.x, kse_eff.y, kse_eff.z, kbt_eff.x, kbt_eff.y, kbt_eff.z,
        ));
        for i in 0..self.tendons.len() {
            if set & (1 << i) == 0 || self.tension[i] == 0.0 {
                continue;
            }
            let g = self.offset(i, s);
            let t = y.u.cross(&g.r) + g.dr + y.v();
            let norm = t.norm();
            let dir = t / norm;
            let a =
                (Matrix3::identity() - dir * dir.transpose()) * (self.tension_at(i, s).0 / norm);
            let r_hat = hat(&g.r);
            let a_r = a * r_hat;
            let mut block = k.fixed_view_mut::<3, 3>(0, 0);
            block += a;
            let mut block = k.fixed_view_mut::<3, 3>(0, 3);
            block -= a_r;
            let mut block = k.fixed_view_mut::<3, 3>(3, 0);
            block += r_hat * a;
            let mut block = k.fixed_view_mut::<3, 3>(3, 3);
            block -= r_hat * a_r;
        }
        k
    }

    /// Tip boundary residual, body frame: [−n(L) + Σ F_i + Rᵀ F_ext;
    /// −m(L) + Σ r_i × F_i + Rᵀ M_ext] with F_i = −τ_i t_i for the tendons
    /// anchored at the tip; zero at the solution.
    pub fn tip_residual(&self, tip: &DynState, hist: &TimeVars, c0: f64) -> Vector6<f64> {
        let (n, m) = self.internal_wrench(tip, hist, c0);
        let (f_ext, m_ext) = self.tip_load;
        let at_tip = (0..self.tendons.len())
            .filter(|&i| self.tendons[i].end >= self.rod.length)
            .fold(0, |set, i| set | (1 << i));
        let force = -n + tip.rot.tr_mul(&f_ext);
        let moment = -m + tip.rot.tr_mul(&m_ext);
        Vector6::new(force.x, force.y, force.z, moment.x, moment.y, moment.z)
            - self.tendon_pull(self.rod.length, tip, at_tip)
    }
}
