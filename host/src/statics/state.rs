//! The backbone's state at one arc length ([`RodState`]), its rates, and the
//! singular system a pass can meet; `w = v − e3` carried, not `v`
//! (see [`super::rod`]).

use nalgebra::{Matrix3, Vector3};

use crate::numerics::rk4::Rk4State;

/// The backbone's state at one arc length s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodState {
    /// Position p(s), base frame, m.
    pub p: Vector3<f64>,
    /// Orientation R(s): columns are the body axes in the base frame.
    pub rot: Matrix3<f64>,
    /// Shear/extension strain deviation w = v − e3 (body frame, dimensionless).
    pub w: Vector3<f64>,
    /// Curvature/torsion u (body frame), 1/m.
    pub u: Vector3<f64>,
}

/// d/ds of a [`RodState`].
#[derive(Clone, Copy, Debug)]
pub struct RodRates {
    /// p' = R v.
    pub dp: Vector3<f64>,
    /// R' = R û.
    pub dr: Matrix3<f64>,
    /// v' (= w').
    pub dw: Vector3<f64>,
    /// u'.
    pub du: Vector3<f64>,
}

impl RodState {
    /// The state at the base, s = 0: p = 0, R = I, strains from the base
    /// internal force n(0) and moment-equivalent curvature u(0).
    pub fn at_base(n0: &Vector3<f64>, u0: &Vector3<f64>, kse: &Vector3<f64>) -> RodState {
        RodState {
            p: Vector3::zeros(),
            rot: Matrix3::identity(),
            w: n0.component_div(kse),
            u: *u0,
        }
    }

    /// v = e3 + w.
    pub fn v(&self) -> Vector3<f64> {
        self.w + Vector3::z()
    }
}

impl Rk4State for RodState {
    type Rates = RodRates;

    /// `self + h · rates` (one RK4 stage).
    #[inline(always)]
    fn advanced(&self, rates: &RodRates, h: f64) -> RodState {
        RodState {
            p: self.p + rates.dp * h,
            rot: self.rot + rates.dr * h,
            w: self.w + rates.dw * h,
            u: self.u + rates.du * h,
        }
    }

    #[inline(always)]
    fn rk4_mean(k: [&RodRates; 4]) -> RodRates {
        RodRates {
            dp: (k[0].dp + (k[1].dp + k[2].dp) * 2.0 + k[3].dp) / 6.0,
            dr: (k[0].dr + (k[1].dr + k[2].dr) * 2.0 + k[3].dr) / 6.0,
            dw: (k[0].dw + (k[1].dw + k[2].dw) * 2.0 + k[3].dw) / 6.0,
            du: (k[0].du + (k[1].du + k[2].du) * 2.0 + k[3].du) / 6.0,
        }
    }
}

/// The strain-rate system could not be solved: its 6×6 matrix is singular
/// or not finite (a tendon tangent of zero length, or non-finite state).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("the rod's strain-rate system is singular or not finite at s = {s:.6} m")]
pub struct SingularSystem {
    /// Arc length where it happened, m.
    pub s: f64,
}
