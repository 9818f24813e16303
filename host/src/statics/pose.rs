//! Tip pose conventions (`docs/design.md` §2): Hamilton quaternion, scalar first
//! (w, x, y, z), sign chosen so that w ≥ 0; R orthonormalised first because
//! RK4 does not keep it exactly orthogonal.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

/// How far from orthogonal (largest entry of RᵀR − I) an input may be for
/// the Newton–Schulz iteration; farther, the SVD. From 0.1 each step takes
/// the error e to about ¾ e², so the iteration converges.
const NEWTON_SCHULZ_START: f64 = 0.1;
/// A step from an error this small is the last: it leaves ¾ e² ≤ 1e-16,
/// RᵀR = I to rounding. Stopping one step earlier, at RᵀR = I to 1e-14,
/// is not enough: the rotation between two nearby solves' R, turned into an
/// angle through its trace, amplifies that 1e-14 to 1e-9 rad (the tip
/// Jacobian's difference test saw it).
const NEWTON_SCHULZ_LAST: f64 = 1e-8;
/// Steps before falling back to the SVD (from 0.1: 7.5e-3, 4e-5, 1.3e-9,
/// then the last).
const NEWTON_SCHULZ_STEPS: usize = 5;

/// Nearest rotation to `r`: the orthogonal factor of its polar
/// decomposition, U Vᵀ from r = U Σ Vᵀ. RK4 leaves an integrated R off a
/// rotation by ~1e-7 (the default robot, 16 steps), and from there the
/// Newton–Schulz iteration X ← X (3I − XᵀX)/2, which converges
/// quadratically to the same polar factor, takes two 3×3 steps (≈ 0.05 µs
/// against the SVD's 0.54 µs on the VM's Zen 1; every statics solve pays
/// it). A matrix far from a rotation, or a reflection, takes the SVD.
pub fn orthonormalise(r: &Matrix3<f64>) -> Matrix3<f64> {
    if r.determinant() > 0.0 {
        let mut x = *r;
        for _ in 0..NEWTON_SCHULZ_STEPS {
            let e = x.transpose() * x - Matrix3::identity();
            let err = e.amax();
            if err.is_nan() || err >= NEWTON_SCHULZ_START {
                break;
            }
            x -= x * e * 0.5;
            if err <= NEWTON_SCHULZ_LAST {
                return x;
            }
        }
    }
    orthonormalise_svd(r)
}

/// [`orthonormalise`] by the SVD, for any `r`: a reflection flips the axis
/// of the smallest singular value.
fn orthonormalise_svd(r: &Matrix3<f64>) -> Matrix3<f64> {
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

    /// The iteration's answer is the SVD's polar factor, and orthogonal, to
    /// rounding, for drifts from none past an integrator's 1e-7 to 0.02;
    /// far from a rotation both paths are the SVD.
    #[test]
    fn newton_schulz_gives_the_polar_factor() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for drift in [0.0, 1e-12, 1e-10, 1e-6, 1e-3, 0.02] {
            for _ in 0..200 {
                let axis = Vector3::new(rng.random(), rng.random(), rng.random::<f64>() - 0.5);
                let r = Rotation3::new(axis * 3.0).into_inner();
                let d = Matrix3::from_fn(|_, _| rng.random_range(-drift..=drift));
                let drifted = r + d;
                let (fast, svd) = (orthonormalise(&drifted), orthonormalise_svd(&drifted));
                assert!(
                    (fast - svd).amax() < 1e-13,
                    "drift {drift}: {}",
                    (fast - svd).amax()
                );
                assert!((fast.transpose() * fast - Matrix3::identity()).amax() < 1e-14);
            }
        }
        // A reflection and a singular matrix: the SVD's answers.
        let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        assert_eq!(orthonormalise(&reflection), orthonormalise_svd(&reflection));
        assert!(orthonormalise(&reflection).determinant() > 0.0);
        let far = Matrix3::from_element(0.5);
        assert_eq!(orthonormalise(&far), orthonormalise_svd(&far));
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
