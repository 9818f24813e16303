//! The tip Jacobian ∂pose/∂τ, exact from the shooting solution's
//! sensitivities (`docs/design.md` §4.1): one pass of the rod with its
//! tangent in the shooting unknowns x and the tensions τ gives the tip
//! residual r(x, τ) and tip state T(x, τ) with their partial derivatives;
//! along the solution r = 0, so by the implicit function theorem
//!
//! ```text
//! dx/dτ = −R_x⁻¹ R_τ,    dT/dτ = T_x dx/dτ + T_τ.
//! ```
//!
//! The orientation part is the base-frame rotation vector δθ of the tip,
//! δR = θ̂ R, so that the rows are [∂p/∂τ; ∂θ/∂τ].

use nalgebra::{DMatrix, Matrix3, Vector3, Vector6};

use crate::statics::rod::{Rod, RodState};
use crate::statics::tangent::{integrate_with_sensitivity, FullSensitivity};
use crate::statics::{SingularSystem, TensionSensitivity};

/// Tip pose and its Jacobian with respect to the tensions at one solution.
#[derive(Clone, Debug)]
pub struct TipJacobian {
    /// Tip position, base frame, m.
    pub position: Vector3<f64>,
    /// Tip rotation as integrated (not re-orthonormalised).
    pub rotation: Matrix3<f64>,
    /// 6 × tendons: rows 0–2 ∂p/∂τ (m/N), rows 3–5 ∂θ/∂τ (rad/N, base frame).
    pub jacobian: DMatrix<f64>,
    /// dx/dτ of the shooting unknowns, which the same pass gives: the
    /// statics warm start's first-order prediction
    /// ([`crate::statics::WarmStart::set_tension_sensitivity`]).
    pub dx_dtau: TensionSensitivity,
}

/// Why the Jacobian could not be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JacobianError {
    /// The rod's strain-rate system failed on the way.
    #[error(transparent)]
    Singular(#[from] SingularSystem),
    /// The shooting Jacobian R_x is singular at this solution.
    #[error(
        "the shooting Jacobian is singular: the tip does not depend smoothly on the tensions here"
    )]
    SingularShooting,
}

/// The tip Jacobian of `rod` (its tensions set) at the converged shooting
/// unknowns `x` = [n(0); u(0)], integrated with `steps` RK4 steps (the
/// solver's grid, so the tip is the solver's tip). No tip load.
pub fn tip_jacobian(
    rod: &Rod,
    x: &Vector6<f64>,
    steps: usize,
) -> Result<TipJacobian, JacobianError> {
    let base = RodState::at_base(
        &Vector3::new(x[0], x[1], x[2]),
        &Vector3::new(x[3], x[4], x[5]),
        &rod.kse,
    );
    let start = FullSensitivity::with_tensions(rod);
    let (tip, t) = integrate_with_sensitivity(rod, base, steps, start)?;
    let zero = Vector3::zeros();
    let r = rod.tip_residual_jacobian(&tip, &t, &zero, &zero);
    let r_x = r.fixed_columns::<6>(0).into_owned();
    let lu = r_x.lu();
    let tendons = t.columns - 6;
    let mut jacobian = DMatrix::zeros(6, tendons);
    let mut dx_dtau = TensionSensitivity::zeros();
    for i in 0..tendons {
        let r_tau: Vector6<f64> = r.column(6 + i).into();
        let dx = lu.solve(&(-r_tau)).ok_or(JacobianError::SingularShooting)?;
        dx_dtau.set_column(i, &dx);
        let mut dp = t.p[6 + i];
        let mut d_rot = t.rot[6 + i];
        for (k, dxk) in dx.iter().enumerate() {
            dp += t.p[k] * *dxk;
            d_rot += t.rot[k] * *dxk;
        }
        // δR Rᵀ is skew for an exact rotation; its skew part is δθ̂.
        let w = d_rot * tip.rot.transpose();
        let dtheta = Vector3::new(
            w[(2, 1)] - w[(1, 2)],
            w[(0, 2)] - w[(2, 0)],
            w[(1, 0)] - w[(0, 1)],
        ) * 0.5;
        jacobian.fixed_view_mut::<3, 1>(0, i).copy_from(&dp);
        jacobian.fixed_view_mut::<3, 1>(3, i).copy_from(&dtheta);
    }
    if !jacobian.iter().all(|v| v.is_finite()) {
        return Err(JacobianError::SingularShooting);
    }
    Ok(TipJacobian {
        position: tip.p,
        rotation: tip.rot,
        jacobian,
        dx_dtau,
    })
}
