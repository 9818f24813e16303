//! What a statics solve gives: the [`Solution`], the [`WarmStart`] it leaves
//! for the next nearby solve, and the sensitivities they carry.

use std::sync::Arc;

use nalgebra::{Matrix3, Matrix6, SMatrix, Vector3, Vector6};

use super::profile::TensionProfile;
use super::rod::RodState;
use crate::robot::MAX_TENDONS;

/// dx/dτ: how the shooting unknowns x = [n(0); u(0)] of a solution move
/// with the tensions, one column per tendon (the unused columns zero).
pub type TensionSensitivity = SMatrix<f64, 6, MAX_TENDONS>;

/// ∂tip/∂x: how the tip pose of the rod integrated from the unknowns x
/// moves with them, one column per unknown; rows 0..3 the position (m),
/// rows 3..12 the orientation R, column by column.
pub type TipSensitivity = SMatrix<f64, 12, 6>;

/// A tip pose as twelve numbers: position (m), then R column by column.
pub(super) type PoseVector = SMatrix<f64, 12, 1>;

/// The tip pose of `tip` as a [`PoseVector`].
pub(super) fn pose_vector(tip: &RodState) -> PoseVector {
    let mut v = PoseVector::zeros();
    v.fixed_rows_mut::<3>(0).copy_from(&tip.p);
    v.fixed_rows_mut::<9>(3).copy_from_slice(tip.rot.as_slice());
    v
}

/// What a previous solve leaves for the next nearby one.
#[derive(Clone, Debug, PartialEq)]
pub struct WarmStart {
    /// Unknowns [n(0) (N); u(0) (1/m)].
    pub x: Vector6<f64>,
    /// Residual Jacobian at or near `x` (the last one Newton used).
    pub jacobian: Matrix6<f64>,
    /// The analytic guess ([`Rod::initial_guess`]) for the tensions and tip
    /// load solved: without `dx_dtau`, or when the tip load changed, a warm
    /// solve starts from `x` moved by how much the guess moves.
    pub(super) guess: Vector6<f64>,
    /// The tensions solved for (the first `tendons` entries), N.
    pub(super) tensions: [f64; MAX_TENDONS],
    pub(super) tendons: usize,
    /// The tip force and moment solved for (base frame).
    pub(super) load: [Vector3<f64>; 2],
    /// dx/dτ near `x`: the first-order prediction of the next solve's
    /// unknowns, x + (dx/dτ) Δτ. `None` until a warm solve (or
    /// [`WarmStart::set_tension_sensitivity`]) provides it.
    // Boxed: 432 bytes that most solutions (a dataset's, a batch's) never
    // carry would otherwise sit in every `Solution` (`fk --input` keeps a
    // chunk of 4,096 of them).
    pub(super) dx_dtau: Option<Box<TensionSensitivity>>,
    /// ∂tip/∂x near `x`, carried with `dx_dtau` when the solver may end on
    /// an unverified chord step ([`SolverSettings::final_step_m`]).
    pub(super) tip_dx: Option<Box<TipSensitivity>>,
}

impl WarmStart {
    /// The tensions this warm start was solved for, N.
    pub fn tensions(&self) -> &[f64] {
        &self.tensions[..self.tendons]
    }

    /// dx/dτ carried for the next solve's prediction, if any.
    pub fn tension_sensitivity(&self) -> Option<&TensionSensitivity> {
        self.dx_dtau.as_deref()
    }

    /// Carries `dx_dtau` (e.g. from the tip Jacobian's pass, which has it
    /// for free: `inverse::jacobian`) for the next solve's prediction.
    pub fn set_tension_sensitivity(&mut self, dx_dtau: TensionSensitivity) {
        if dx_dtau.iter().all(|v| v.is_finite()) {
            self.dx_dtau = Some(Box::new(dx_dtau));
        }
    }

    /// The change of tensions from this warm start to `tensions`, when the
    /// tip load is the same (`None` otherwise: the prediction covers only
    /// the tensions).
    pub(super) fn tension_step(
        &self,
        tensions: &[f64],
        load: &[Vector3<f64>; 2],
    ) -> Option<SMatrix<f64, MAX_TENDONS, 1>> {
        if tensions.len() != self.tendons || *load != self.load {
            return None;
        }
        let mut d = SMatrix::<f64, MAX_TENDONS, 1>::zeros();
        for (i, t) in tensions.iter().enumerate() {
            d[i] = t - self.tensions[i];
        }
        Some(d)
    }
}

/// A converged statics solution.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Tip position, base frame, m.
    pub position: Vector3<f64>,
    /// Tip orientation quaternion (w, x, y, z), w ≥ 0.
    pub quaternion: [f64; 4],
    /// Tip orientation (orthonormalised), columns = body axes in the base frame.
    pub rotation: Matrix3<f64>,
    /// Norm of the tip residual at the solution; when `extrapolated`, an
    /// estimate: the last pass's residual times the least contraction a
    /// carried Jacobian is trusted with.
    pub residual: f64,
    /// Whether the solve ended on a chord step that no pass verified
    /// ([`SolverSettings::final_step_m`]): the pose is then the last
    /// pass's tip moved by ∂tip/∂x, within a few percent of that bound.
    pub extrapolated: bool,
    /// Newton iterations used.
    pub iterations: usize,
    /// Rod passes used, in plain-pass equivalents: a pass with
    /// sensitivities, which gives the Jacobian, counts as
    /// [`SENSITIVITY_PASS_COST`] times its share of the solver's steps.
    pub integrations: f64,
    /// Warm start for a neighbouring solve.
    pub warm: WarmStart,
    pub(super) tensions: Vec<f64>,
    /// The capstan friction profile solved with (`docs/design.md` §2.3), if any.
    pub(super) profile: Option<Arc<TensionProfile>>,
}

impl Solution {
    /// The pose as the dataset stores it: px, py, pz (m), qw, qx, qy, qz.
    pub fn pose(&self) -> [f64; 7] {
        let p = &self.position;
        let q = &self.quaternion;
        [p.x, p.y, p.z, q[0], q[1], q[2], q[3]]
    }

    /// The tendon tensions solved for, N (with friction: the motors').
    pub fn tensions(&self) -> &[f64] {
        &self.tensions
    }

    /// The capstan friction profile this was solved with; `None` for the
    /// frictionless model.
    pub fn profile(&self) -> Option<&Arc<TensionProfile>> {
        self.profile.as_ref()
    }

    /// Base internal force n(0), N.
    pub fn base_force(&self) -> Vector3<f64> {
        self.warm.x.fixed_rows::<3>(0).into()
    }
}
