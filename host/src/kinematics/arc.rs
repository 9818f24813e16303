//! The constant-curvature arc: the simplest kinematic model of a bending
//! continuum robot (`docs/design.md` §2). A lateral tip move `c` becomes a
//! change of the arc's bend angle θ and bending plane φ: the lateral
//! distance d follows θ through d = L (1 − cos θ)/θ, the tip orientation
//! rotates by the change of (θ, φ), the height by the change of L sin θ / θ.
//! Exact for an inextensible constant-curvature arc; it ignores gravity and
//! the real routing, which the statics tangent ([`super::lift`]) includes.

/// Bend angle θ (rad) of a constant-curvature arc of length `l` whose tip
/// lies at lateral distance `d` from the axis (Newton on d = L(1−cos θ)/θ).
pub fn arc_angle(d: f64, l: f64) -> f64 {
    let target = (d / l).clamp(0.0, 0.72); // 0.72 ≈ max of (1−cos θ)/θ
    let mut th = 2.0 * target; // small-angle start: d ≈ Lθ/2
    for _ in 0..30 {
        if th < 1e-9 {
            return 2.0 * target;
        }
        let f = (1.0 - th.cos()) / th - target;
        let df = (th * th.sin() - (1.0 - th.cos())) / (th * th);
        if df.abs() < 1e-12 {
            break;
        }
        let next = (th - f / df).clamp(0.0, 2.3);
        if (next - th).abs() < 1e-14 {
            th = next;
            break;
        }
        th = next;
    }
    th
}

/// sin θ / θ, finite at 0.
fn sinc(th: f64) -> f64 {
    if th.abs() < 1e-8 {
        1.0 - th * th / 6.0
    } else {
        th.sin() / th
    }
}

/// Hamilton product a ⊗ b of (w, x, y, z) quaternions.
fn qmul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Orientation of an arc bent by θ toward direction φ (rotation about the
/// axis z × (cos φ, sin φ, 0)).
fn arc_rotation(th: f64, phi: f64) -> [f64; 4] {
    let (s, c) = (th / 2.0).sin_cos();
    [c, -phi.sin() * s, phi.cos() * s, 0.0]
}

/// The pose `pose` (px, py, pz, qw, qx, qy, qz) moved laterally by
/// `c = (cx, cy)` (m) as a constant-curvature arc of length `l` would move.
pub fn arc_shift(pose: &[f64; 7], c: [f64; 2], l: f64) -> [f64; 7] {
    let (x0, y0) = (pose[0], pose[1]);
    let (x1, y1) = (x0 + c[0], y0 + c[1]);
    let (d0, d1) = (x0.hypot(y0), x1.hypot(y1));
    let (th0, th1) = (arc_angle(d0, l), arc_angle(d1, l));
    let (phi0, phi1) = (y0.atan2(x0), y1.atan2(x1));
    let r0 = arc_rotation(th0, phi0);
    let r1 = arc_rotation(th1, phi1);
    let r0_inv = [r0[0], -r0[1], -r0[2], -r0[3]];
    let q0 = [pose[3], pose[4], pose[5], pose[6]];
    let mut q = qmul(qmul(r1, r0_inv), q0);
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    for v in &mut q {
        *v /= n;
    }
    if q[0] < 0.0 {
        for v in &mut q {
            *v = -*v;
        }
    }
    let z1 = pose[2] + l * (sinc(th1) - sinc(th0));
    [x1, y1, z1, q[0], q[1], q[2], q[3]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact inextensible constant-curvature arc pose bent by θ toward φ.
    fn arc_pose(th: f64, phi: f64, l: f64) -> [f64; 7] {
        let d = l * (1.0 - th.cos()) / th;
        let q = arc_rotation(th, phi);
        [
            d * phi.cos(),
            d * phi.sin(),
            l * th.sin() / th,
            q[0],
            q[1],
            q[2],
            q[3],
        ]
    }

    #[test]
    fn arc_angle_inverts_the_lateral_distance() {
        for th in [0.01, 0.3, 0.9, 1.5] {
            let d = 0.4 * (1.0 - f64::cos(th)) / th;
            assert!((arc_angle(d, 0.4) - th).abs() < 1e-10);
        }
    }

    #[test]
    fn arc_rotation_bends_toward_plus_x_with_positive_qy() {
        // docs/design.md §2: pulling tendon 0 bends the tip toward +x with qy > 0.
        let p = arc_pose(0.2, 0.0, 0.4);
        assert!(p[0] > 0.0 && p[5] > 0.0);
    }

    #[test]
    fn shifting_an_exact_arc_gives_the_exact_arc_at_the_new_position() {
        let l = 0.4;
        let from = arc_pose(0.25, 0.3, l);
        let to = arc_pose(0.31, -0.4, l);
        let shifted = arc_shift(&from, [to[0] - from[0], to[1] - from[1]], l);
        for k in 0..7 {
            assert!(
                (shifted[k] - to[k]).abs() < 1e-9,
                "component {k}: {} vs {}",
                shifted[k],
                to[k]
            );
        }
    }

    #[test]
    fn zero_shift_is_the_identity() {
        let p = arc_pose(0.1, 1.0, 0.4);
        let s = arc_shift(&p, [0.0, 0.0], 0.4);
        for k in 0..7 {
            assert!((s[k] - p[k]).abs() < 1e-12);
        }
    }
}
