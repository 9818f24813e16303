//! The planner's lift: a continuum robot bending on its tendons has two
//! degrees of freedom, so the planner plans the tip's lateral position
//! (x, y) and lifts it to the full reachable pose (z and orientation follow)
//! with the exact IK (`docs/design.md` §4.1): a [`Target::Lateral`] solved
//! by bounded Gauss–Newton on the tensions, the redundancy resolved to the
//! least total tension, each point warm-started from the previous one along
//! the path. The lift also gives the tangent `∂pose/∂(x, y)` of that family
//! from the same tip Jacobian, along which the firmware's integral loop
//! moves a setpoint (`docs/design.md` §6).

use nalgebra::{DMatrix, DVector, Vector2};

use super::KinematicsError;
use crate::inverse::{ExactIk, IkSettings, IkSolution, InverseError, Target};
use crate::statics::{Statics, WarmStart};

/// `[∂pose/∂px, ∂pose/∂py]`: how a reachable pose changes when its tip
/// moves laterally (per metre).
pub type Tangent = [[f64; 7]; 2];

/// One lifted lateral position.
#[derive(Clone, Debug)]
pub struct Lifted {
    /// The reachable pose: px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// Its tangent along the reachable family.
    pub tangent: Tangent,
    /// The least-total-tension tensions that reach it, N.
    pub tensions: Vec<f64>,
}

/// Lifts lateral tip positions to reachable poses with the exact IK,
/// warm-started along the path.
pub struct Lifter {
    ik: ExactIk,
    previous: Option<Previous>,
}

/// The last lift, the start of the next.
struct Previous {
    xy: [f64; 2],
    tensions: Vec<f64>,
    warm: WarmStart,
    /// ∂τ/∂x, ∂τ/∂y there (the tangent's tension directions).
    dtau: [DVector<f64>; 2],
}

/// Tensions strictly inside their limits by more than this count as free
/// in the tangent (N; the IK's own "at a limit" is 1e-9 N).
const FREE: f64 = 1e-9;
/// Singular values of a lateral Jacobian below this fraction of its largest
/// are dropped, and a tension direction must meet the asked lateral move to
/// this relative accuracy.
const RANK_RATIO: f64 = 1e-6;

impl Lifter {
    /// A lifter for `statics`' robot, with its solver settings.
    pub fn new(statics: &Statics) -> Lifter {
        let settings = IkSettings {
            statics: *statics.settings(),
            ..IkSettings::default()
        };
        Lifter {
            ik: ExactIk::new(statics.robot(), settings),
            previous: None,
        }
    }

    /// The exact IK it uses.
    pub fn ik(&self) -> &ExactIk {
        &self.ik
    }

    /// The reachable pose whose tip is at lateral position `xy` (m).
    pub fn lift(&mut self, xy: [f64; 2]) -> Result<[f64; 7], KinematicsError> {
        self.lifted(xy).map(|l| l.pose)
    }

    /// The reachable pose at lateral position `xy` (m) and its tangent.
    pub fn lift_with_tangent(
        &mut self,
        xy: [f64; 2],
    ) -> Result<([f64; 7], Tangent), KinematicsError> {
        self.lifted(xy).map(|l| (l.pose, l.tangent))
    }

    /// The reachable pose at lateral position `xy` (m), its tangent and
    /// tensions: warm from the previous lift, cold from the floors if that
    /// fails (a jump across the workspace can stall a warm start).
    pub fn lifted(&mut self, xy: [f64; 2]) -> Result<Lifted, KinematicsError> {
        if !(xy[0].is_finite() && xy[1].is_finite()) {
            return Err(KinematicsError::NotFinite);
        }
        let target = Target::Lateral(Vector2::new(xy[0], xy[1]));
        // Warm: the previous tensions moved along its tangent (a first-order
        // predictor, so a path step of a fraction of a millimetre starts
        // within ~µm and the Gauss–Newton finishes in a step or two).
        let warm = match &self.previous {
            Some(p) => {
                let (dx, dy) = (xy[0] - p.xy[0], xy[1] - p.xy[1]);
                let start: Vec<f64> = p
                    .tensions
                    .iter()
                    .enumerate()
                    .map(|(i, t)| t + p.dtau[0][i] * dx + p.dtau[1][i] * dy)
                    .collect();
                self.ik.solve(&target, Some(&start), Some(&p.warm)).ok()
            }
            None => None,
        };
        let solution = match warm {
            Some(s) => s,
            None => self.ik.solve(&target, None, None).map_err(|e| match e {
                InverseError::Unreachable { closest } => KinematicsError::OutsideWorkspace {
                    x_mm: xy[0] * 1e3,
                    y_mm: xy[1] * 1e3,
                    distance_mm: closest.position_error * 1e3,
                },
                e => KinematicsError::Inverse(e),
            })?,
        };
        let (tangent, dtau) = self.tangent(&solution).ok_or(KinematicsError::Singular {
            x_mm: xy[0] * 1e3,
            y_mm: xy[1] * 1e3,
        })?;
        self.previous = Some(Previous {
            xy,
            tensions: solution.tensions.clone(),
            warm: solution.warm.clone(),
            dtau,
        });
        Ok(Lifted {
            pose: solution.pose,
            tangent,
            tensions: solution.tensions,
        })
    }

    /// The tangent of the lift at `s` from its tip Jacobian J = ∂pose/∂τ
    /// (`docs/design.md` §4.1, "The planner's lift"). The lift moves only the
    /// free tensions F (strictly inside their limits; the least-total-tension
    /// rule leaves two of them on a four-tendon robot, one per antagonistic
    /// pair), so with J_xy the rows of ∂(px, py)/∂τ_F
    ///
    /// ```text
    /// ∂τ_F/∂(x, y) = J_xy⁺ = J_xyᵀ (J_xy J_xyᵀ)⁻¹   (J_xy⁻¹ for two free tensions)
    /// ∂p/∂(x, y)   = J_p,F J_xy⁺,   ∂θ/∂(x, y) = J_θ,F J_xy⁺,   ∂q = ½ [0; ∂θ] ⊗ q
    /// ```
    ///
    /// (θ the base-frame rotation vector, δR = θ̂ R). Where fewer than two
    /// tensions are free (the tip at rest, every tendon at its floor) the
    /// lift has a corner; each direction then takes its one-sided
    /// derivative: the least-norm tension direction moving the tip along it,
    /// a tension at a limit joining only if the direction moves it inward.
    /// `None` when no tension direction moves the tip laterally. Also
    /// returns the tension directions ∂τ/∂x, ∂τ/∂y.
    fn tangent(&self, s: &IkSolution) -> Option<(Tangent, [DVector<f64>; 2])> {
        let jacobian = match &s.jacobian {
            Some(j) => j.clone(),
            None => self.ik.tip_jacobian_at(&s.tensions, &s.warm).ok()?,
        };
        let (lo, hi) = self.ik.limits();
        let q = [s.pose[3], s.pose[4], s.pose[5], s.pose[6]];
        let mut tangent = [[0.0; 7]; 2];
        let n = s.tensions.len();
        let mut dtaus = [DVector::zeros(n), DVector::zeros(n)];
        for (k, row) in tangent.iter_mut().enumerate() {
            let mut direction = Vector2::zeros();
            direction[k] = 1.0;
            dtaus[k] = tension_direction(&jacobian, &s.tensions, lo, hi, &direction)?;
            let d = &jacobian * &dtaus[k];
            let dtheta = [d[3], d[4], d[5]];
            // ½ [0; ω] ⊗ q with q = (w, v): (−ω·v, w ω + ω × v) / 2.
            let (w, v) = (q[0], [q[1], q[2], q[3]]);
            let dq = [
                -(dtheta[0] * v[0] + dtheta[1] * v[1] + dtheta[2] * v[2]),
                w * dtheta[0] + dtheta[1] * v[2] - dtheta[2] * v[1],
                w * dtheta[1] + dtheta[2] * v[0] - dtheta[0] * v[2],
                w * dtheta[2] + dtheta[0] * v[1] - dtheta[1] * v[0],
            ];
            row[..3].copy_from_slice(&[d[0], d[1], d[2]]);
            for (out, dqk) in row[3..].iter_mut().zip(dq) {
                *out = 0.5 * dqk;
            }
        }
        Some((tangent, dtaus))
    }
}

/// The tension direction dτ moving the tip by `direction` in (x, y) (see
/// [`Lifter::tangent`]): least-norm on the free tensions when they move the
/// tip that way; else the free tensions plus one at a limit that the
/// direction moves inward, the one costing the least total tension; else
/// the free set grown by every tension at a limit, dropping those the
/// direction pushes out until none is.
fn tension_direction(
    jacobian: &DMatrix<f64>,
    tau: &[f64],
    lo: &[f64],
    hi: &[f64],
    direction: &Vector2<f64>,
) -> Option<DVector<f64>> {
    let n = tau.len();
    let lateral = jacobian.rows(0, 2).into_owned();
    let (inside, at_limit): (Vec<usize>, Vec<usize>) =
        (0..n).partition(|&i| tau[i] > lo[i] + FREE && tau[i] < hi[i] - FREE);
    if let Some(d) = least_norm(&lateral, &inside, direction) {
        return Some(d);
    }
    let inward = |d: &DVector<f64>, i: usize| {
        !((tau[i] <= lo[i] + FREE && d[i] < 0.0) || (tau[i] >= hi[i] - FREE && d[i] > 0.0))
    };
    let one_more = at_limit
        .iter()
        .filter_map(|&c| {
            let mut set = inside.clone();
            set.push(c);
            least_norm(&lateral, &set, direction).filter(|d| inward(d, c))
        })
        .min_by(|a, b| a.sum().total_cmp(&b.sum()));
    if one_more.is_some() {
        return one_more;
    }
    let mut set: Vec<usize> = (0..n).collect();
    loop {
        let d = least_norm(&lateral, &set, direction)?;
        let before = set.len();
        set.retain(|&i| inward(&d, i));
        if set.len() == before {
            return Some(d);
        }
    }
}

/// The least-norm dτ on the tensions in `set` (zero elsewhere) with
/// J_S dτ = direction, `None` when no dτ on them moves the tip so.
fn least_norm(
    lateral: &DMatrix<f64>,
    set: &[usize],
    direction: &Vector2<f64>,
) -> Option<DVector<f64>> {
    if set.is_empty() {
        return None;
    }
    let j = lateral.select_columns(set);
    let svd = j.clone().svd(true, true);
    let eps = RANK_RATIO * svd.singular_values.max();
    let rhs = DVector::from_column_slice(direction.as_slice());
    let d_set = svd.pseudo_inverse(eps).ok()? * &rhs;
    if (&j * &d_set - &rhs).norm() > RANK_RATIO * rhs.norm() || !d_set.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let mut d = DVector::zeros(lateral.ncols());
    for (k, &i) in set.iter().enumerate() {
        d[i] = d_set[k];
    }
    Some(d)
}

/// The pose `pose` moved laterally by `c = (cx, cy)` (m) along the robot's
/// own reachable family, to first order: `pose + [∂pose/∂px ∂pose/∂py] c`,
/// quaternion re-normalised with `w ≥ 0`. The tangent comes from the
/// statics ([`Lifter::lift_with_tangent`]), so unlike
/// [`super::arc::arc_shift`] it includes gravity and the real tendon
/// routing. The firmware's integral loop applies the same first-order shift
/// in f32 (`docs/design.md` §5).
pub fn family_shift(pose: &[f64; 7], tangent: &[[f64; 7]; 2], c: [f64; 2]) -> [f64; 7] {
    let mut out = [0.0; 7];
    for (k, v) in out.iter_mut().enumerate() {
        *v = pose[k] + tangent[0][k] * c[0] + tangent[1][k] * c[1];
    }
    let n = out[3..].iter().map(|v| v * v).sum::<f64>().sqrt();
    let sign = if out[3] < 0.0 { -1.0 } else { 1.0 };
    if n > 0.0 && n.is_finite() {
        for v in &mut out[3..] {
            *v *= sign / n;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::bend_tensions;
    use crate::robot::Robot;
    use crate::statics::SolverSettings;
    use nalgebra::Matrix2;
    use std::path::Path;

    fn robot() -> Robot {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml");
        Robot::load(&path).unwrap()
    }

    fn statics() -> Statics {
        Statics::new(&robot(), SolverSettings::default())
    }

    /// A 30 mm circle about the axis, `n` points.
    fn circle(n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                [0.015 * a.cos(), 0.015 * a.sin()]
            })
            .collect()
    }

    /// Lifted poses reproduce their (x, y) through a fresh, cold forward
    /// solve of the returned tensions, and that solve's pose is the lift's.
    #[test]
    fn lifted_circle_reproduces_its_targets_through_forward_statics() {
        let s = statics();
        let mut lifter = Lifter::new(&s);
        for xy in circle(24) {
            let lifted = lifter.lifted(xy).unwrap();
            let fresh = statics().solve(&lifted.tensions, None).unwrap();
            let miss = (fresh.position.x - xy[0]).hypot(fresh.position.y - xy[1]);
            assert!(miss <= 1e-6, "xy {xy:?}: {miss:e} m");
            // Two solves of the same tensions that each meet the residual
            // tolerance (5e-10 N·m) may differ by up to L/EI × 5e-10 ≈ 6e-9
            // in rotation on the seed robot.
            let pose = fresh.pose();
            for (k, (a, b)) in pose.iter().zip(&lifted.pose).enumerate() {
                assert!((a - b).abs() < 1e-8, "xy {xy:?} component {k}: {:e}", a - b);
            }
            // Least total tension: at most one tendon of each antagonistic pair pulls.
            let t = &lifted.tensions;
            assert!(t[0].min(t[2]) < 1e-9 && t[1].min(t[3]) < 1e-9, "{t:?}");
        }
    }

    /// The old lift, kept here as the independent reference: Newton with
    /// finite differences on the 2-D bend vector b of the tension family
    /// τ_i = clamp(b · (cos φ_i, sin φ_i), 0, τ_max).
    fn bend_lift(s: &Statics, xy: [f64; 2]) -> [f64; 7] {
        let target = Vector2::new(xy[0], xy[1]);
        let tip = |b: &Vector2<f64>| {
            let sol = s.solve(&bend_tensions(s, b), None).unwrap();
            (sol.pose(), Vector2::new(sol.position.x, sol.position.y))
        };
        let mut bend = Vector2::zeros();
        let h = 1e-4;
        for _ in 0..40 {
            let (pose, p) = tip(&bend);
            let r = p - target;
            if r.norm() < 1e-10 {
                return pose;
            }
            let (_, px) = tip(&(bend + Vector2::new(h, 0.0)));
            let (_, py) = tip(&(bend + Vector2::new(0.0, h)));
            let j = Matrix2::from_columns(&[(px - p) / h, (py - p) / h]);
            let step = j.try_inverse().unwrap() * r;
            bend -= step * (2.0 / step.norm().max(1e-12)).min(1.0);
        }
        panic!("bend lift did not converge at {xy:?}");
    }

    /// On the symmetric default robot the least-total-tension lift is the
    /// bend family's (two adjacent tendons facing the target).
    #[test]
    fn lift_equals_the_bend_family_lift_on_the_symmetric_robot() {
        let s = statics();
        let mut lifter = Lifter::new(&s);
        for xy in [[0.015, 0.0], [0.0, 0.015], [-0.012, 0.009], [0.004, -0.03]] {
            let exact = lifter.lift(xy).unwrap();
            let reference = bend_lift(&s, xy);
            let d = (0..3)
                .map(|k| (exact[k] - reference[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(d <= 1e-6, "xy {xy:?}: {d:e} m");
            for k in 3..7 {
                assert!((exact[k] - reference[k]).abs() < 1e-5, "xy {xy:?} q{k}");
            }
        }
    }

    /// The tangent against central differences of lifts at ± 20 µm.
    #[test]
    fn tangent_matches_central_differences_of_lifts() {
        let s = statics();
        let h = 2e-5;
        for xy in [[0.015, 0.0], [-0.01, 0.012], [0.004, -0.03]] {
            let mut lifter = Lifter::new(&s);
            let (_, tangent) = lifter.lift_with_tangent(xy).unwrap();
            for k in 0..2 {
                let (mut plus, mut minus) = (xy, xy);
                plus[k] += h;
                minus[k] -= h;
                let a = lifter.lift(plus).unwrap();
                let b = lifter.lift(minus).unwrap();
                for c in 0..7 {
                    let fd = (a[c] - b[c]) / (2.0 * h);
                    let scale = tangent[k].iter().map(|v| v.abs()).fold(0.0, f64::max);
                    assert!(
                        (fd - tangent[k][c]).abs() <= 1e-4 * scale,
                        "xy {xy:?} ∂/∂{k} component {c}: {} vs {fd}",
                        tangent[k][c]
                    );
                }
            }
        }
    }

    #[test]
    fn unreachable_target_is_a_clear_error() {
        let s = statics();
        let err = Lifter::new(&s).lift([0.5, 0.0]).unwrap_err();
        assert!(err.to_string().contains("outside"), "{err}");
        let err = Lifter::new(&s).lift([f64::NAN, 0.0]).unwrap_err();
        assert!(err.to_string().contains("finite"), "{err}");
    }
}
