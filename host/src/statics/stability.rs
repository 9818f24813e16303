//! Stability of a statics solution: the conjugate-point test of the
//! shooting solution (`docs/design.md` §2.3), after Till & Rucker, "Elastic
//! Stability of Cosserat Rods and Parallel Continuum Robots", IEEE T-RO
//! 33(3), 2017, and the generalised Jacobi condition for a rod clamped at one
//! end and free at the other.
//!
//! The Jacobi fields of a clamped base are the shooting sensitivities
//! ∂y(s)/∂x, x = [n(0); u(0)] (`tangent`). Cut the rod at s and freeze the
//! part beyond the cut into a rigid body that keeps its dead loads (the tip
//! force at the tip, the weight of [s, L] where it hangs): rod [0, s] plus
//! that body is a conservative clamped–free system in equilibrium, whose
//! linearised tip condition is δW(s) = G(s) δΘ(s): W = [R n_c; R m_c] the
//! spatial combined wrench of backbone and the tendons crossing s, δΘ the
//! spatial rotation of the section, and G = Σ (ρ_k F_kᵀ − (F_k·ρ_k) I) the
//! load stiffness of the dead forces F_k on arms ρ_k from p(s). So that piece
//! has a neutral (buckling) mode exactly where
//! D(s) = det [∂W/∂x − (0; G ∂Θ/∂x)] vanishes. For s → 0 the piece is stiff
//! and stable; its energy's index can change only where D(s) = 0. So the
//! equilibrium is stable when D keeps its sign on (0, L], and the first sign
//! change marks a conjugate point. At s = L, G = 0 and ∂W/∂x = −diag(R, R) J
//! with J the shooting Jacobian: the test ends on det J, whose vanishing is
//! also where a branch folds or bifurcates. (Holding the cut with a dead
//! *couple* instead of the rigid body would not do: a dead couple is not
//! conservative in three dimensions, and the test then flags stable bent
//! cantilevers.)
//!
//! What it covers: dead (constant, base-frame) tip forces and weight, which
//! are conservative, and tendons at fixed tension, whose potential is
//! τ times the tendon's length (a tendon crossing the cut is anchored to the
//! frozen body there), so rod and tendons together are conservative too.
//! What it does not: a dead tip *moment* is not conservative in three
//! dimensions (Ziegler) and enters G as nothing; follower loads (friction,
//! tendons over contact) are outside the energy argument. For those the sign
//! change of D is still where the linearised problem has a neutral mode, but
//! a D that keeps its sign is no proof of stability.

use nalgebra::{Matrix3, Matrix6, SMatrix, Vector3};

use super::integrate::pieces;
use super::rod::{Rod, RodState, SingularSystem, TendonSet};
use super::tangent::ShootingSensitivity;
use crate::numerics::rk4::rk4_step;

/// What the stability pass finds along the rod.
#[derive(Clone, Copy, Debug)]
pub struct StabilityPass {
    /// The first conjugate point, arc length in m (linearly interpolated
    /// between the grid nodes around the sign change), or `None` when the
    /// equilibrium is stable.
    pub conjugate_at_m: Option<f64>,
    /// The shooting Jacobian ∂r(L)/∂x on the solve's own grid (for the
    /// continuation's predictor).
    pub jacobian: Matrix6<f64>,
}

/// Integrate the rod and its six Jacobi fields from the base unknowns `x`
/// on the solve's grid of `steps` steps and watch the sign of
/// D(s) = det ∂W(s)/∂x (module doc). `f_ext`, `m_ext`: the tip load, base
/// frame, for the Jacobian returned.
pub fn stability_pass(
    rod: &Rod,
    base: RodState,
    steps: usize,
    f_ext: &Vector3<f64>,
    m_ext: &Vector3<f64>,
) -> Result<StabilityPass, SingularSystem> {
    let mut yt = (base, ShootingSensitivity::at_base(&rod.kse, 0, true, false));
    let mut nodes = Vec::with_capacity(steps + 2 * rod.knots().len() + 1);
    nodes.push(Node::at(rod, 0.0, &yt.0, &yt.1, rod.running_to(0.0)));
    for piece in pieces(rod, steps) {
        for k in 0..piece.n {
            let s = piece.a + k as f64 * piece.h;
            yt = rk4_step(s, &yt, piece.h, |_, s, (y, t)| {
                rod.rates_with_sensitivity(s, y, t, piece.running)
            })?;
            nodes.push(Node::at(rod, s + piece.h, &yt.0, &yt.1, piece.running));
        }
        if piece.ends_at_anchor(rod.length) {
            yt = rod.across_anchor_with_sensitivity(piece.b, &yt.0, &yt.1)?;
        }
    }
    // The frozen tail's dead loads, tip to base: the tip force at p(L) and
    // the weight, ∫ (p(ξ) − p(s)) dξ over [s, L] by the trapezoidal rule.
    let tip = yt.0.p;
    let mut first_moment = Vector3::zeros();
    let mut tail = 0.0;
    let mut dets = vec![0.0; nodes.len()];
    let mut matrices = vec![Matrix6::zeros(); nodes.len()];
    for k in (0..nodes.len()).rev() {
        if k + 1 < nodes.len() {
            let h = nodes[k + 1].s - nodes[k].s;
            first_moment += (nodes[k + 1].p + nodes[k].p) * (0.5 * h);
            tail += h;
        }
        let node = &nodes[k];
        let rho = tip - node.p;
        let arm = first_moment - node.p * tail;
        let g = load_stiffness(&rho, f_ext) + load_stiffness(&arm, &rod.f_e);
        let mut m = node.wrench;
        let correction = g * node.rotation;
        for j in 0..6 {
            for i in 0..3 {
                m[(3 + i, j)] -= correction[(i, j)];
            }
        }
        // In the section's own frame (same determinant): a section turned
        // past a right angle would otherwise give the matrix eigenvalues
        // with negative real parts that mean nothing.
        for j in 0..6 {
            let top = node.rot.tr_mul(&m.fixed_view::<3, 1>(0, j).into_owned());
            let bottom = node.rot.tr_mul(&m.fixed_view::<3, 1>(3, j).into_owned());
            m.fixed_view_mut::<3, 1>(0, j).copy_from(&top);
            m.fixed_view_mut::<3, 1>(3, j).copy_from(&bottom);
        }
        dets[k] = m.determinant();
        matrices[k] = m;
    }
    // D's sign at every node; the eigenvalue count (for double roots, where
    // D only touches zero) where |D| has a local minimum, the node after it,
    // and the tip: a double crossing leaves the count changed from there on.
    let reference = dets[0].signum();
    let count_base = negative_real_eigenvalues(&matrices[0]);
    let last = nodes.len() - 1;
    let dip = |k: usize| {
        k == last
            || (k >= 1 && dets[k].abs() < dets[k - 1].abs() && dets[k].abs() <= dets[k + 1].abs())
            || (k >= 2
                && dets[k - 1].abs() < dets[k - 2].abs()
                && dets[k - 1].abs() <= dets[k].abs())
    };
    let mut conjugate = None;
    for k in 1..nodes.len() {
        let d = reference * dets[k];
        let positive = d > 0.0;
        if !positive || (dip(k) && negative_real_eigenvalues(&matrices[k]) != count_base) {
            // Where the linear interpolant of D crosses zero; a double root
            // (two modes at once, as a rod of round section has) leaves D's
            // sign alone and is seen by the eigenvalues.
            let d0 = reference * dets[k - 1];
            let frac = if !positive && d0 > 0.0 && d.is_finite() {
                d0 / (d0 - d)
            } else {
                1.0
            };
            conjugate = Some(nodes[k - 1].s + frac * (nodes[k].s - nodes[k - 1].s));
            break;
        }
    }
    Ok(StabilityPass {
        conjugate_at_m: conjugate,
        jacobian: rod.tip_residual_jacobian(&yt.0, &yt.1, f_ext, m_ext),
    })
}

/// How many eigenvalues of `m` are real (to roundoff) and negative: where
/// two of them cross zero together D keeps its sign, but this count changes.
fn negative_real_eigenvalues(m: &Matrix6<f64>) -> usize {
    let tiny = 1e-6 * m.norm();
    m.complex_eigenvalues()
        .iter()
        .filter(|z| z.re < 0.0 && z.im.abs() <= tiny)
        .count()
}

/// G = ρ Fᵀ − (F·ρ) I: the change of the moment about the section of a dead
/// force `f` on a rigid arm `rho` when the arm turns by δΘ, (δΘ × ρ) × F.
fn load_stiffness(rho: &Vector3<f64>, f: &Vector3<f64>) -> Matrix3<f64> {
    rho * f.transpose() - Matrix3::identity() * f.dot(rho)
}

/// What the stability test keeps of one grid node.
struct Node {
    /// Arc length, m.
    s: f64,
    /// Position, base frame, m.
    p: Vector3<f64>,
    /// Orientation R(s).
    rot: Matrix3<f64>,
    /// ∂W/∂x ([`spatial_wrench_jacobian`]).
    wrench: Matrix6<f64>,
    /// ∂Θ/∂x, the spatial rotation of the section: δΘ̂ = δR Rᵀ.
    rotation: SMatrix<f64, 3, 6>,
}

impl Node {
    fn at(rod: &Rod, s: f64, y: &RodState, t: &ShootingSensitivity, running: TendonSet) -> Node {
        let mut rotation = SMatrix::<f64, 3, 6>::zeros();
        for j in 0..6 {
            let w = t.rot[j] * y.rot.transpose();
            let skew = (w - w.transpose()) * 0.5;
            rotation.column_mut(j).copy_from(&Vector3::new(
                skew[(2, 1)],
                skew[(0, 2)],
                skew[(1, 0)],
            ));
        }
        Node {
            s,
            p: y.p,
            rot: y.rot,
            wrench: spatial_wrench_jacobian(rod, s, y, t, running),
            rotation,
        }
    }
}

/// ∂W(s)/∂x, W = [R n_c; R m_c] the spatial combined wrench of backbone and
/// the tendons `running` across the section at `s`: n_c = n + Σ τ_i q̂_i,
/// m_c = m + Σ r_i × τ_i q̂_i (at the tip, W − [F_ext; M_ext] is R times the
/// tip residual).
fn spatial_wrench_jacobian(
    rod: &Rod,
    s: f64,
    y: &RodState,
    t: &ShootingSensitivity,
    running: TendonSet,
) -> Matrix6<f64> {
    let (mut n_c, mut m_c) = rod.internal_wrench(y);
    let pulled = |i: usize| running & (1 << i) != 0 && rod.tension(i) != 0.0;
    for i in (0..rod.n_tendons).filter(|&i| pulled(i)) {
        let g = rod.routing(i, s);
        let f = Rod::tendon_tangent(y, &g).normalize() * rod.tension_at(i, s).0;
        n_c += f;
        m_c += g.r.cross(&f);
    }
    let mut jac = Matrix6::zeros();
    for j in 0..6 {
        let mut dn = rod.kse.component_mul(&t.w[j]);
        let mut dm = rod.kbt.component_mul(&t.u[j]);
        for i in (0..rod.n_tendons).filter(|&i| pulled(i)) {
            let g = rod.routing(i, s);
            let q = Rod::tendon_tangent(y, &g);
            // τ δq̂ = −δF, F = −τ q̂ the tendon's pull on the rod.
            let df = -rod.force_change(i, s, &q, &(t.u[j].cross(&g.r) + t.w[j]));
            dn += df;
            dm += g.r.cross(&df);
        }
        let top = t.rot[j] * n_c + y.rot * dn;
        let bottom = t.rot[j] * m_c + y.rot * dm;
        jac.fixed_view_mut::<3, 1>(0, j).copy_from(&top);
        jac.fixed_view_mut::<3, 1>(3, j).copy_from(&bottom);
    }
    jac
}
