//! Where the robot's base sits in the tracker's frame (`docs/design.md`
//! §2.4): the robot file's optional `[base]` table, which `tendril
//! calibrate` writes. The statics, the dataset and the net live in the base
//! frame; the tracker, the planner's targets, the plant's reports and the
//! run log live in the tracker's. A tip at p in the base frame is at
//! R p + t in the tracker's, R = exp([r]×).
//!
//! The pose is not part of the robot's fingerprint: moving the tracker does
//! not change what the rod does, so a net trained on the file needs no
//! retraining when only the frame changes.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// The base's pose in the tracker's frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BasePose {
    /// t: the base's origin in the tracker's frame, m.
    pub translation: [f64; 3],
    /// r: the rotation vector of the base's axes in the tracker's frame
    /// (axis × angle), rad.
    pub rotation: [f64; 3],
}

/// Largest distance of the base from the tracker's origin, m: a tracker's
/// working volume is a metre or two (the calibration's bound too).
pub const MAX_BASE_TRANSLATION_M: f64 = 5.0;

impl BasePose {
    /// The tracker's frame is the base frame.
    pub const IDENTITY: BasePose = BasePose {
        translation: [0.0; 3],
        rotation: [0.0; 3],
    };

    /// Whether the tracker's frame is the base frame (every number zero).
    pub fn is_identity(&self) -> bool {
        self.translation
            .iter()
            .chain(&self.rotation)
            .all(|&x| x == 0.0)
    }

    /// The map from the base frame to the tracker's: x ↦ R x + t.
    pub fn to_tracker(&self) -> RigidMap {
        let r = Rotation3::new(Vector3::from(self.rotation));
        RigidMap::new(r, Vector3::from(self.translation), self.is_identity())
    }

    /// The map from the tracker's frame to the base frame: x ↦ Rᵀ (x − t).
    pub fn to_base(&self) -> RigidMap {
        let r = Rotation3::new(Vector3::from(self.rotation)).inverse();
        let t = -(r * Vector3::from(self.translation));
        RigidMap::new(r, t, self.is_identity())
    }

    /// One line for reports: "base at (x, y, z) mm, turned by a mrad about (ax, ay, az)".
    pub fn summary(&self) -> String {
        if self.is_identity() {
            return "the tracker's frame is the base frame".into();
        }
        let t = self.translation.map(|x| x * 1e3);
        let r = Vector3::from(self.rotation);
        let angle = r.norm();
        let turn = if angle == 0.0 {
            String::from("not turned")
        } else {
            let a = r / angle;
            format!(
                "turned by {:.2} mrad about ({:.3}, {:.3}, {:.3})",
                angle * 1e3,
                a.x,
                a.y,
                a.z
            )
        };
        format!(
            "base at ({:.3}, {:.3}, {:.3}) mm in the tracker's frame, {turn}",
            t[0], t[1], t[2]
        )
    }
}

/// A rigid change of frame x' = R x + t, applied to points, directions and
/// tip poses `[px, py, pz, qw, qx, qy, qz]` (Hamilton, w ≥ 0) and their
/// derivatives. The identity returns every number as it came, to the bit:
/// a robot file without `[base]` runs exactly as before the frame existed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidMap {
    r: Matrix3<f64>,
    q: UnitQuaternion<f64>,
    t: Vector3<f64>,
    identity: bool,
}

impl RigidMap {
    fn new(r: Rotation3<f64>, t: Vector3<f64>, identity: bool) -> RigidMap {
        RigidMap {
            r: r.into_inner(),
            q: UnitQuaternion::from_rotation_matrix(&r),
            t,
            identity,
        }
    }

    /// The identity map.
    pub fn identity() -> RigidMap {
        BasePose::IDENTITY.to_tracker()
    }

    /// Whether this map changes nothing.
    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// A point: R p + t.
    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        if self.identity {
            return p;
        }
        (self.r * Vector3::from(p) + self.t).into()
    }

    /// A direction or a displacement: R v.
    pub fn direction(&self, v: [f64; 3]) -> [f64; 3] {
        if self.identity {
            return v;
        }
        (self.r * Vector3::from(v)).into()
    }

    /// q_R ⊗ q for a quaternion (w, x, y, z) or its derivative (linear in
    /// `q`, so a derivative maps like the quaternion it belongs to).
    fn quaternion(&self, q: [f64; 4]) -> [f64; 4] {
        let out = self.q.quaternion() * Quaternion::new(q[0], q[1], q[2], q[3]);
        [out.w, out.i, out.j, out.k]
    }

    /// A tip pose, and in place the derivatives of that pose (velocity,
    /// tangent columns): positions by R p + t, displacements by R, the
    /// quaternion and its derivatives by q_R ⊗ ·, all flipped together
    /// when the mapped quaternion's w would be negative (the w ≥ 0
    /// convention, `docs/design.md` §2).
    pub fn pose_with_derivatives(&self, pose: [f64; 7], derivatives: &mut [[f64; 7]]) -> [f64; 7] {
        if self.identity {
            return pose;
        }
        let [x, y, z, qw, qx, qy, qz] = pose;
        let p = self.point([x, y, z]);
        let q = self.quaternion([qw, qx, qy, qz]);
        let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
        for d in derivatives.iter_mut() {
            let v = self.direction([d[0], d[1], d[2]]);
            let dq = self.quaternion([d[3], d[4], d[5], d[6]]);
            *d = [
                v[0],
                v[1],
                v[2],
                sign * dq[0],
                sign * dq[1],
                sign * dq[2],
                sign * dq[3],
            ];
        }
        [
            p[0],
            p[1],
            p[2],
            sign * q[0],
            sign * q[1],
            sign * q[2],
            sign * q[3],
        ]
    }

    /// A tip pose.
    pub fn pose(&self, pose: [f64; 7]) -> [f64; 7] {
        self.pose_with_derivatives(pose, &mut [])
    }
}

#[cfg(test)]
mod tests {
    use super::super::file::tests::{parse, GOOD};
    use super::*;

    const TURNED: BasePose = BasePose {
        translation: [0.12, -0.05, 0.8],
        rotation: [0.3, -1.1, 2.6],
    };

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn the_identity_leaves_every_bit_alone() {
        let pose = [0.1 + 1e-17, -0.0, 0.39, 0.9, 0.1, -0.3, 0.2];
        let mut d = [[1e-300, -0.0, 3.0, 4.0, 5.0, 6.0, 7.0]];
        let out = BasePose::IDENTITY
            .to_tracker()
            .pose_with_derivatives(pose, &mut d);
        assert_eq!(out.map(f64::to_bits), pose.map(f64::to_bits));
        assert_eq!(d[0][0].to_bits(), 1e-300f64.to_bits());
        assert_eq!(d[0][1].to_bits(), (-0.0f64).to_bits());
        assert!(BasePose::IDENTITY.is_identity() && !TURNED.is_identity());
    }

    #[test]
    fn to_base_undoes_to_tracker_and_keeps_distances() {
        let (fwd, back) = (TURNED.to_tracker(), TURNED.to_base());
        let (a, b) = ([0.01, 0.02, 0.38], [-0.03, 0.0, 0.35]);
        assert!(close(&back.point(fwd.point(a)), &a, 1e-15));
        let (fa, fb) = (fwd.point(a), fwd.point(b));
        let dist = |p: [f64; 3], q: [f64; 3]| (Vector3::from(p) - Vector3::from(q)).norm();
        assert!((dist(fa, fb) - dist(a, b)).abs() < 1e-15);
        let s = (0.5f64).sqrt();
        let pose = [0.01, 0.02, 0.38, s, 0.0, s, 0.0];
        let round = back.pose(fwd.pose(pose));
        assert!(close(&round, &pose, 1e-14), "{round:?}");
    }

    /// The map of a pose's derivative is the derivative of the mapped pose
    /// (central differences along a curve of poses), w ≥ 0 kept.
    #[test]
    fn a_mapped_derivative_is_the_derivative_of_the_mapped_pose() {
        let curve = |s: f64| {
            let q = UnitQuaternion::from_euler_angles(0.2 + s, -0.4 * s, 2.9 + 0.3 * s);
            let q = q.quaternion();
            [0.01 + s, 0.02 - 2.0 * s, 0.38 + s * s, q.w, q.i, q.j, q.k]
        };
        let fwd = TURNED.to_tracker();
        let h = 1e-6;
        let mut d = [std::array::from_fn(|k| {
            (curve(h)[k] - curve(-h)[k]) / (2.0 * h)
        })];
        let mapped = fwd.pose_with_derivatives(curve(0.0), &mut d);
        assert!(mapped[3] >= 0.0);
        // Each pose's sign chosen the same way as the centre's.
        let align = |p: [f64; 7]| {
            let dot: f64 = (3..7).map(|k| p[k] * mapped[k]).sum();
            let s = dot.signum();
            std::array::from_fn::<f64, 7, _>(|k| if k < 3 { p[k] } else { s * p[k] })
        };
        let (plus, minus) = (align(fwd.pose(curve(h))), align(fwd.pose(curve(-h))));
        let numeric: Vec<f64> = (0..7).map(|k| (plus[k] - minus[k]) / (2.0 * h)).collect();
        assert!(close(&d[0], &numeric, 1e-8), "{:?} vs {numeric:?}", d[0]);
    }

    #[test]
    fn the_quaternion_of_a_mapped_pose_is_the_composed_rotation() {
        let fwd = TURNED.to_tracker();
        let tip = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let q = tip.quaternion();
        let mapped = fwd.pose([0.0, 0.0, 0.4, q.w, q.i, q.j, q.k]);
        let expect = Rotation3::new(Vector3::from(TURNED.rotation)) * tip.to_rotation_matrix();
        let got = UnitQuaternion::from_quaternion(Quaternion::new(
            mapped[3], mapped[4], mapped[5], mapped[6],
        ))
        .to_rotation_matrix();
        assert!((got.matrix() - expect.matrix()).abs().max() < 1e-14);
    }

    #[test]
    fn a_base_table_is_read_checked_written_back_and_left_out_of_the_fingerprint() {
        let text =
            format!("{GOOD}\n[base]\ntranslation = [0.1, 0.0, -0.2]\nrotation = [0.0, 0.1, 0.0]\n");
        let robot = parse(&text).unwrap();
        assert_eq!(robot.base.translation, [0.1, 0.0, -0.2]);
        assert_eq!(robot.base.rotation, [0.0, 0.1, 0.0]);
        let plain = parse(GOOD).unwrap();
        assert!(plain.base.is_identity());
        // Moving the tracker does not change the rod: a net stays valid.
        assert_eq!(robot.fingerprint(), plain.fingerprint());
        // The calibration's writer gives the same robot back, frame and all.
        let written = crate::calibrate::params::robot_toml(&robot, &[]);
        assert!(written.contains("[base]"), "{written}");
        assert_eq!(parse(&written).unwrap(), robot);
        assert!(!crate::calibrate::params::robot_toml(&plain, &[]).contains("[base]"));
        // A table with one key gives the other as zero.
        let only_t = parse(&format!("{GOOD}\n[base]\ntranslation = [0.0, 0.0, 1.0]\n")).unwrap();
        assert_eq!(only_t.base.rotation, [0.0; 3]);
        for (table, field, says) in [
            (
                "translation = [150.0, 0.0, 0.0]",
                "base.translation",
                "metres",
            ),
            ("rotation = [0.0, 0.0, 90.0]", "base.rotation", "radians"),
            (
                "translation = [nan, 0.0, 0.0]",
                "base.translation[0]",
                "finite",
            ),
            (
                "translation_mm = [1.0, 0.0, 0.0]",
                "base.translation_mm",
                "unknown field",
            ),
            ("translation = [1.0, 0.0]", "base.translation", ""),
        ] {
            let e = parse(&format!("{GOOD}\n[base]\n{table}\n")).unwrap_err();
            assert_eq!(e.field, field, "{table}: {e}");
            assert!(e.problem.contains(says), "{table}: {e}");
        }
    }
}
