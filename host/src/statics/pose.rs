//! Tip pose conventions (`docs/design.md` §2): Hamilton quaternion, scalar first
//! (w, x, y, z), sign chosen so that w ≥ 0; R orthonormalised first because
//! RK4 does not keep it exactly orthogonal.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

/// Nearest rotation to `r`: the orthogonal factor U Vᵀ of its polar
/// decomposition, from the SVD r = U Σ Vᵀ.
pub fn orthonormalise(r: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = r.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let mut q = u * v_t;
            if q.determinant() < 0.0 {
                // Reflection: flip the axis of the smallest singular value.
                let mut u = u;
                let j = svd.singular_values.imin();
                u.column_mut(j).neg_mut();
                q = u * v_t;
            }
            q
        }
        _ => *r,
    }
}

/// Quaternion (w, x, y, z) of an orthonormal rotation matrix, w ≥ 0.
pub fn quaternion_wxyz(r: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// Rotation angle between two unit quaternions (w, x, y, z), radians in [0, π].
/// Sign-invariant: q and −q are the same orientation.
pub fn angle_between(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let dot = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]).abs();
    let na = (a.iter().map(|x| x * x).sum::<f64>()).sqrt();
    let nb = (b.iter().map(|x| x * x).sum::<f64>()).sqrt();
    2.0 * (dot / (na * nb)).clamp(0.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn rotation_about_y_gives_expected_quaternion() {
        let theta: f64 = 0.3;
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), theta).into_inner();
        let q = quaternion_wxyz(&r);
        assert!((q[0] - (theta / 2.0).cos()).abs() < 1e-14);
        assert!((q[2] - (theta / 2.0).sin()).abs() < 1e-14);
        assert!(q[1].abs() < 1e-14 && q[3].abs() < 1e-14);
    }

    #[test]
    fn sign_is_chosen_with_w_non_negative() {
        // A rotation by more than π about z has w < 0 when built naively.
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 3.5).into_inner();
        assert!(quaternion_wxyz(&r)[0] >= 0.0);
    }

    #[test]
    fn orthonormalise_removes_drift() {
        let r = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.7).into_inner();
        let drifted = r * 1.001 + Matrix3::from_element(1e-4);
        let o = orthonormalise(&drifted);
        assert!((o.transpose() * o - Matrix3::identity()).norm() < 1e-12);
        assert!((o - r).norm() < 1e-3);
        assert!(o.determinant() > 0.0);
    }

    #[test]
    fn angle_between_is_sign_invariant() {
        let a = [1.0, 0.0, 0.0, 0.0];
        let b = [(0.2f64).cos(), (0.2f64).sin(), 0.0, 0.0];
        let nb = [-b[0], -b[1], -b[2], -b[3]];
        assert!((angle_between(&a, &b) - 0.4).abs() < 1e-12);
        assert!((angle_between(&a, &nb) - 0.4).abs() < 1e-12);
    }
}
