//! The planner's lift (`docs/design.md` §4.1): the robot reaches a k-dimensional
//! family of tip positions ([`Family`]: a volume, a surface over the
//! lateral plane, or a curve), so the planner plans the tip's k coordinates
//! u_j = a_j · p along the family's axes and lifts them to the full
//! reachable pose (the rest of the position and the orientation follow)
//! with the exact IK: a [`Target::Position`] (k = 3), [`Target::Lateral`]
//! (k = 2) or [`Target::Along`] (k = 1) solved by bounded Gauss–Newton on
//! the tensions, the redundancy resolved to the least total tension (the
//! least bending effort on robots whose datasets are resolved so, three
//! segments: [`crate::dataset::Resolve`]), each
//! point warm-started from the previous one along the path. The lift also
//! gives the tangent `∂pose/∂u_j` of that family from the same tip Jacobian,
//! along which the firmware's integral loop moves a setpoint
//! (`docs/design.md` §6).

use nalgebra::{DMatrix, DVector, Matrix3xX, Vector2, Vector3};

use super::{Family, PlanError};
use crate::dataset::Resolve;
use crate::inverse::{ExactIk, IkSettings, IkSolution, InverseError, Redundancy, Target};
use crate::statics::{Statics, WarmStart};

/// `∂pose/∂u_j` (per metre) along the family's axes: how a reachable pose
/// changes when its tip moves along each axis, first `family.dim()`
/// columns valid, the rest zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FamilyTangent {
    /// The family (dimension and axes) the columns belong to.
    pub family: Family,
    /// The columns `∂pose/∂u_j`.
    pub columns: [[f64; 7]; 3],
}

/// One lifted target.
#[derive(Clone, Debug)]
pub struct Lifted {
    /// The reachable pose: px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
    /// Its tangent along the reachable family.
    pub tangent: FamilyTangent,
    /// The least-total-tension tensions that reach it, N.
    pub tensions: Vec<f64>,
}

/// Lifts tip coordinates on the robot's family to reachable poses with the
/// exact IK, warm-started along the path.
pub struct Lifter {
    ik: ExactIk,
    settings: IkSettings,
    family: Family,
    previous: Option<Previous>,
}

/// The last lift, the start of the next.
struct Previous {
    u: [f64; 3],
    tensions: Vec<f64>,
    warm: WarmStart,
    /// ∂τ/∂u_j there (the tangent's tension directions).
    dtau: Vec<DVector<f64>>,
}

/// Tensions strictly inside their limits by more than this count as free
/// in the tangent (N; the IK's own "at a limit" is 1e-9 N).
const FREE: f64 = 1e-9;
/// Singular values of a projected Jacobian below this fraction of its
/// largest are dropped, and a tension direction must meet the asked move to
/// this relative accuracy.
const RANK_RATIO: f64 = 1e-6;
/// Half-step of [`Lifter::tangent_by_differences`], m: small against the
/// family's curvature (tensions change by ~3 N/m over 0.3 m), large against
/// the IK's tolerances (1e-7 m, a phase-2 optimum to ~1e-6 N).
const DIFFERENCE_STEP: f64 = 1e-4;
/// Resolution of the height range search (m).
const HEIGHT_TOLERANCE: f64 = 1e-4;
/// Lateral directions at which a circle's heights are sampled
/// ([`Lifter::height_band`], [`Lifter::headroom_band`]).
pub(super) const HEIGHT_SAMPLES: usize = 8;

impl Lifter {
    /// A lifter for `statics`' robot on its own family ([`Family::of`]).
    pub fn new(statics: &Statics) -> Result<Lifter, PlanError> {
        Ok(Lifter::on(statics, Family::of(statics)?))
    }

    /// A lifter for `statics`' robot planning in `family`'s coordinates.
    pub fn on(statics: &Statics, family: Family) -> Lifter {
        // The redundancy resolved as the robot's dataset resolves it, so a
        // lifted pose is one the net was trained on (docs/design.md §3).
        let settings = IkSettings {
            statics: *statics.settings(),
            redundancy: Resolve::default_for(statics.robot()).redundancy(),
            ..IkSettings::default()
        };
        Lifter::with_settings(statics, family, settings)
    }

    /// As [`Lifter::on`] with the exact IK's `settings` (its statics
    /// settings are taken as given).
    pub fn with_settings(statics: &Statics, family: Family, settings: IkSettings) -> Lifter {
        Lifter {
            ik: ExactIk::new(statics.robot(), settings),
            settings,
            family,
            previous: None,
        }
    }

    /// A lifter with the same IK and family and no path behind it (the
    /// next lift starts cold).
    pub fn fresh(&self) -> Lifter {
        Lifter {
            ik: self.ik.clone(),
            settings: self.settings,
            family: self.family,
            previous: None,
        }
    }

    /// The exact IK it uses.
    pub fn ik(&self) -> &ExactIk {
        &self.ik
    }

    /// The family it plans in.
    pub fn family(&self) -> Family {
        self.family
    }

    /// The reachable pose whose tip has coordinates `u` (m) on the family.
    pub fn lift(&mut self, u: impl AsRef<[f64]>) -> Result<[f64; 7], PlanError> {
        self.lifted(u).map(|l| l.pose)
    }

    /// The reachable pose at coordinates `u` (m) and its tangent.
    pub fn lift_with_tangent(
        &mut self,
        u: impl AsRef<[f64]>,
    ) -> Result<([f64; 7], FamilyTangent), PlanError> {
        self.lifted(u).map(|l| (l.pose, l.tangent))
    }

    /// The IK target for coordinates `u` (already checked: k finite values).
    fn target(&self, u: &[f64; 3]) -> Target {
        match self.family.dim() {
            3 => Target::Position(Vector3::from(*u)),
            2 => Target::Lateral(Vector2::new(u[0], u[1])),
            _ => Target::Along(Vector3::from(self.family.axes()[0]), u[0]),
        }
    }

    /// The reachable pose at coordinates `u` (m, one per axis of the
    /// family), its tangent and tensions: warm from the previous lift, cold
    /// from the floors if that fails (a jump across the workspace can stall
    /// a warm start).
    pub fn lifted(&mut self, u: impl AsRef<[f64]>) -> Result<Lifted, PlanError> {
        let given = u.as_ref();
        let k = self.family.dim();
        if given.len() != k {
            return Err(PlanError::Dimension {
                got: given.len(),
                family: self.family.describe(),
            });
        }
        if !given.iter().all(|v| v.is_finite()) {
            return Err(PlanError::NotFinite);
        }
        let mut u = [0.0; 3];
        u[..k].copy_from_slice(given);
        let target = self.target(&u);
        // Warm: the previous tensions moved along its tangent (a first-order
        // predictor, so a path step of a fraction of a millimetre starts
        // within ~µm and the Gauss–Newton finishes in a step or two).
        let warm = match &self.previous {
            Some(p) => {
                let start: Vec<f64> = p
                    .tensions
                    .iter()
                    .enumerate()
                    .map(|(i, t)| t + (0..k).map(|j| p.dtau[j][i] * (u[j] - p.u[j])).sum::<f64>())
                    .collect();
                self.ik.solve(&target, Some(&start), Some(&p.warm)).ok()
            }
            None => None,
        };
        let solution = match warm {
            Some(s) => s,
            None => self.ik.solve(&target, None, None).map_err(|e| match e {
                InverseError::Unreachable { closest } => PlanError::OutsideWorkspace {
                    coordinates_m: given.to_vec(),
                    distance_mm: closest.position_error * 1e3,
                },
                e => PlanError::Inverse(e),
            })?,
        };
        let tangent = match self.settings.redundancy {
            // At the edge of the reachable set a side of the difference
            // may not reach: the least-norm tangent there.
            Redundancy::LeastBending => self
                .tangent_by_differences(&solution, &u)
                .or_else(|| self.tangent(&solution)),
            _ => self.tangent(&solution),
        };
        let (tangent, dtau) = tangent.ok_or_else(|| PlanError::Singular {
            coordinates_m: given.to_vec(),
        })?;
        self.previous = Some(Previous {
            u,
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
    /// rule leaves k of them, e.g. two on a four-tendon robot, one per
    /// antagonistic pair), so with A the k × 3 matrix of the family's axes
    /// and J_u = A J_p,F the rows of ∂u/∂τ_F
    ///
    /// ```text
    /// ∂τ_F/∂u = J_u⁺ = J_uᵀ (J_u J_uᵀ)⁻¹   (J_u⁻¹ for k free tensions)
    /// ∂p/∂u   = J_p,F J_u⁺,   ∂θ/∂u = J_θ,F J_u⁺,   ∂q = ½ [0; ∂θ] ⊗ q
    /// ```
    ///
    /// (θ the base-frame rotation vector, δR = θ̂ R). Where fewer than k
    /// tensions are free (the tip at rest, every tendon at its floor) the
    /// lift has a corner; each direction then takes its one-sided
    /// derivative: the least-norm tension direction moving the tip along it,
    /// a tension at a limit joining only if the direction moves it inward.
    /// `None` when no tension direction moves the tip along some axis. Also
    /// returns the tension directions ∂τ/∂u_j.
    fn tangent(&self, s: &IkSolution) -> Option<(FamilyTangent, Vec<DVector<f64>>)> {
        let jacobian = match &s.jacobian {
            Some(j) => j.clone(),
            None => self.ik.tip_jacobian_at(&s.tensions, &s.warm).ok()?,
        };
        let (lo, hi) = self.ik.limits();
        let k = self.family.dim();
        let axes = Matrix3xX::from_fn(k, |r, j| self.family.axes()[j][r]);
        let projected = axes.transpose() * jacobian.rows(0, 3);
        let q = [s.pose[3], s.pose[4], s.pose[5], s.pose[6]];
        let mut columns = [[0.0; 7]; 3];
        let mut dtaus = Vec::with_capacity(k);
        for (j, column) in columns.iter_mut().enumerate().take(k) {
            let mut direction = DVector::zeros(k);
            direction[j] = 1.0;
            let dtau = tension_direction(&projected, &s.tensions, lo, hi, &direction)?;
            let d = &jacobian * &dtau;
            dtaus.push(dtau);
            let dtheta = [d[3], d[4], d[5]];
            // ½ [0; ω] ⊗ q with q = (w, v): (−ω·v, w ω + ω × v) / 2.
            let (w, v) = (q[0], [q[1], q[2], q[3]]);
            let dq = [
                -(dtheta[0] * v[0] + dtheta[1] * v[1] + dtheta[2] * v[2]),
                w * dtheta[0] + dtheta[1] * v[2] - dtheta[2] * v[1],
                w * dtheta[1] + dtheta[2] * v[0] - dtheta[0] * v[2],
                w * dtheta[2] + dtheta[0] * v[1] - dtheta[1] * v[0],
            ];
            column[..3].copy_from_slice(&[d[0], d[1], d[2]]);
            for (out, dqk) in column[3..].iter_mut().zip(dq) {
                *out = 0.5 * dqk;
            }
        }
        let tangent = FamilyTangent {
            family: self.family,
            columns,
        };
        Some((tangent, dtaus))
    }

    /// The tangent of a least-bending family ([`Redundancy::LeastBending`])
    /// by central differences of lifts at u ± h e_j, each warm from `s`.
    /// Its tensions spread over more tendons than the family has
    /// dimensions, and the optimum slides along the target set as the
    /// target moves, so the least-norm tension direction of
    /// [`Lifter::tangent`] is not the family's: a setpoint moved along it
    /// would leave the family the net was trained on (in orientation).
    fn tangent_by_differences(
        &self,
        s: &IkSolution,
        u: &[f64; 3],
    ) -> Option<(FamilyTangent, Vec<DVector<f64>>)> {
        let k = self.family.dim();
        let mut columns = [[0.0; 7]; 3];
        let mut dtaus = Vec::with_capacity(k);
        for (j, column) in columns.iter_mut().enumerate().take(k) {
            let side = |sign: f64| {
                let mut v = *u;
                v[j] += sign * DIFFERENCE_STEP;
                self.ik
                    .solve(&self.target(&v), Some(&s.tensions), Some(&s.warm))
                    .ok()
            };
            let (plus, minus) = (side(1.0)?, side(-1.0)?);
            // The quaternions on s's side of the double cover.
            let aligned = |q: &[f64; 7]| {
                let dot: f64 = (3..7).map(|c| q[c] * s.pose[c]).sum();
                let sign = if dot < 0.0 { -1.0 } else { 1.0 };
                let mut q = *q;
                q[3..].iter_mut().for_each(|c| *c *= sign);
                q
            };
            let (p, m) = (aligned(&plus.pose), aligned(&minus.pose));
            for (c, out) in column.iter_mut().enumerate() {
                *out = (p[c] - m[c]) / (2.0 * DIFFERENCE_STEP);
            }
            dtaus.push(DVector::from_iterator(
                s.tensions.len(),
                plus.tensions
                    .iter()
                    .zip(&minus.tensions)
                    .map(|(a, b)| (a - b) / (2.0 * DIFFERENCE_STEP)),
            ));
        }
        let tangent = FamilyTangent {
            family: self.family,
            columns,
        };
        Some((tangent, dtaus))
    }

    /// The tip's reachable height range (m) at lateral position `xy` (m) on
    /// a robot whose tip reaches a volume: from the least-total-tension
    /// lateral lift there, the highest and lowest heights whose
    /// [`Target::Position`] the exact IK still reaches, by bracketing and
    /// bisection to [`HEIGHT_TOLERANCE`]. `None` when `xy` is out of reach.
    pub fn height_range(&self, xy: [f64; 2]) -> Option<(f64, f64)> {
        // Local runs: the bisection follows one branch of warm starts, and
        // a global search at every height past the end would cost ~7 runs.
        let reach = IkSettings {
            redundancy: Redundancy::Any,
            restarts: 0,
            ..self.settings
        };
        let ik = ExactIk::new(self.ik.robot(), reach);
        let start = ik
            .solve(&Target::Lateral(Vector2::new(xy[0], xy[1])), None, None)
            .ok()?;
        let z0 = start.pose[2];
        let length = self.ik.robot().length;
        let reaches = |z: f64, from: &IkSolution| {
            ik.solve(
                &Target::Position(Vector3::new(xy[0], xy[1], z)),
                Some(&from.tensions),
                Some(&from.warm),
            )
            .ok()
        };
        let mut ends = [0.0; 2];
        for (end, sign) in ends.iter_mut().zip([1.0, -1.0]) {
            let mut inside = (z0, start.clone());
            let mut step = 1e-3;
            let mut outside = loop {
                let z = inside.0 + sign * step;
                if z > 1.01 * length || z < -1.01 * length {
                    break z;
                }
                match reaches(z, &inside.1) {
                    Some(s) => inside = (z, s),
                    None => break z,
                }
                step *= 2.0;
            };
            while (outside - inside.0).abs() > HEIGHT_TOLERANCE {
                let z = 0.5 * (inside.0 + outside);
                match reaches(z, &inside.1) {
                    Some(s) => inside = (z, s),
                    None => outside = z,
                }
            }
            *end = inside.0;
        }
        Some((ends[1], ends[0]))
    }

    /// The heights (m) a circle of `radius` (m) about lateral `center` (m)
    /// can be tracked at: the intersection of the [`Lifter::height_range`]s
    /// of [`HEIGHT_SAMPLES`] points around it. Paths that move in height
    /// about [`Lifter::mid_height`] stay inside it.
    pub fn height_band(&self, center: [f64; 2], radius: f64) -> Result<(f64, f64), PlanError> {
        let no_height = || PlanError::NoHeight {
            center_m: center.to_vec(),
            radius_mm: radius * 1e3,
        };
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for i in 0..HEIGHT_SAMPLES {
            let a = std::f64::consts::TAU * i as f64 / HEIGHT_SAMPLES as f64;
            let xy = [center[0] + radius * a.cos(), center[1] + radius * a.sin()];
            let (l, h) = self.height_range(xy).ok_or_else(no_height)?;
            lo = lo.max(l);
            hi = hi.min(h);
        }
        if lo > hi {
            return Err(no_height());
        }
        Ok((lo, hi))
    }
}

/// The tension direction dτ moving the tip by `direction` in the family's
/// coordinates (see [`Lifter::tangent`]; `projected` is ∂u/∂τ): least-norm
/// on the free tensions when they move the tip that way; else the free
/// tensions plus one at a limit that the direction moves inward, the one
/// costing the least total tension; else the free set grown by every
/// tension at a limit, dropping those the direction pushes out until none
/// is.
fn tension_direction(
    projected: &DMatrix<f64>,
    tau: &[f64],
    lo: &[f64],
    hi: &[f64],
    direction: &DVector<f64>,
) -> Option<DVector<f64>> {
    let n = tau.len();
    let (inside, at_limit): (Vec<usize>, Vec<usize>) =
        (0..n).partition(|&i| tau[i] > lo[i] + FREE && tau[i] < hi[i] - FREE);
    if let Some(d) = least_norm(projected, &inside, direction) {
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
            least_norm(projected, &set, direction).filter(|d| inward(d, c))
        })
        .min_by(|a, b| a.sum().total_cmp(&b.sum()));
    if one_more.is_some() {
        return one_more;
    }
    let mut set: Vec<usize> = (0..n).collect();
    loop {
        let d = least_norm(projected, &set, direction)?;
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
    projected: &DMatrix<f64>,
    set: &[usize],
    direction: &DVector<f64>,
) -> Option<DVector<f64>> {
    if set.is_empty() {
        return None;
    }
    let j = projected.select_columns(set);
    let svd = j.clone().svd(true, true);
    let eps = RANK_RATIO * svd.singular_values.max();
    let d_set = svd.pseudo_inverse(eps).ok()? * direction;
    if (&j * &d_set - direction).norm() > RANK_RATIO * direction.norm()
        || !d_set.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let mut d = DVector::zeros(projected.ncols());
    for (k, &i) in set.iter().enumerate() {
        d[i] = d_set[k];
    }
    Some(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::bend_tensions;
    use nalgebra::Matrix2;

    fn statics() -> Statics {
        crate::statics::repo_statics("seed-4t.toml")
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
        let mut lifter = Lifter::new(&s).unwrap();
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
        let mut lifter = Lifter::new(&s).unwrap();
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

    /// The tangent against central differences of lifts at ± `h`, at each
    /// of `points` (coordinates on the robot's family), to `relative` of
    /// each column's largest entry. Each lift is cold (a fresh lifter): a
    /// lift warm-started along a path may settle a hair away on the
    /// least-tension set (on the two-segment robot ~1e-3·h in orientation,
    /// which a difference over 2h would read as a 1e-3 tangent error), and
    /// to 1e-12 m instead of the IK's default 1e-7 m (whose slack a
    /// difference over 2h would read as up to 1e-7 / 2h).
    fn tight(s: &Statics) -> Lifter {
        let settings = IkSettings {
            position_tol: 1e-12,
            statics: *s.settings(),
            redundancy: Resolve::default_for(s.robot()).redundancy(),
            ..IkSettings::default()
        };
        Lifter::with_settings(s, Family::of(s).unwrap(), settings)
    }

    fn check_tangent_against_central_differences(
        s: &Statics,
        points: &[Vec<f64>],
        h: f64,
        relative: f64,
    ) {
        for u in points {
            let (_, tangent) = tight(s).lift_with_tangent(u).unwrap();
            for k in 0..u.len() {
                let (mut plus, mut minus) = (u.clone(), u.clone());
                plus[k] += h;
                minus[k] -= h;
                let a = tight(s).lift(&plus).unwrap();
                let b = tight(s).lift(&minus).unwrap();
                let scale = tangent.columns[k]
                    .iter()
                    .map(|v| v.abs())
                    .fold(0.0, f64::max);
                for c in 0..7 {
                    let fd = (a[c] - b[c]) / (2.0 * h);
                    assert!(
                        (fd - tangent.columns[k][c]).abs() <= relative * scale,
                        "u {u:?} ∂/∂u{k} component {c}: {} vs {fd}",
                        tangent.columns[k][c]
                    );
                }
            }
        }
    }

    #[test]
    fn tangent_matches_central_differences_of_lifts() {
        let points = [vec![0.015, 0.0], vec![-0.01, 0.012], vec![0.004, -0.03]];
        check_tangent_against_central_differences(&statics(), &points, 2e-5, 1e-4);
    }

    use crate::statics::repo_statics as statics_of;

    /// Lifts reproduce their target coordinates through a fresh, cold
    /// forward solve of the returned tensions (the fact a lift must
    /// satisfy), on any family.
    fn check_lifts_reproduce_targets(s: &Statics, points: &[Vec<f64>]) {
        let mut lifter = Lifter::new(s).unwrap();
        let family = lifter.family();
        for u in points {
            let lifted = lifter.lifted(u).unwrap();
            let fresh = s.solve(&lifted.tensions, None).unwrap();
            let reached = family.coordinates(&fresh.position.into());
            let miss = u
                .iter()
                .zip(reached)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(miss <= 1e-6, "u {u:?}: {miss:e} m");
            let pose = fresh.pose();
            for (k, (a, b)) in pose.iter().zip(&lifted.pose).take(3).enumerate() {
                assert!((a - b).abs() < 1e-8, "u {u:?} p{k}");
            }
            let limits = s.robot().max_tensions();
            assert!(
                lifted
                    .tensions
                    .iter()
                    .zip(&limits)
                    .all(|(t, m)| (0.0..=*m).contains(t)),
                "{:?}",
                lifted.tensions
            );
        }
    }

    /// Points on and around a 20 mm circle of the two-segment robot at a
    /// height it reaches all round, ± 1 mm: the mid height (397.6 mm, the
    /// headroom band's middle) is 2.2 mm under the top of the reachable
    /// band, where the family folds (the height is second order in the
    /// tensions there), and 2 mm above it differences over 40 µm read that
    /// curvature (6e-4 of a column).
    fn two_segment_points(s: &Statics) -> Vec<Vec<f64>> {
        let lifter = Lifter::new(s).unwrap();
        let z = lifter.mid_height([0.0, 0.0], 0.01).unwrap();
        vec![
            vec![0.008, 0.006, z],
            vec![-0.005, 0.008, z + 0.001],
            vec![0.003, -0.0095, z - 0.001],
            vec![0.003, 0.004, z],
        ]
    }

    #[test]
    fn two_segment_lifts_reproduce_3d_targets() {
        let s = statics_of("tdcr-2seg.toml");
        assert_eq!(Lifter::new(&s).unwrap().family().dim(), 3);
        check_lifts_reproduce_targets(&s, &two_segment_points(&s));
    }

    #[test]
    fn two_segment_tangent_matches_central_differences() {
        let s = statics_of("tdcr-2seg.toml");
        check_tangent_against_central_differences(&s, &two_segment_points(&s), 2e-5, 1e-4);
    }

    /// Tips of the three-segment robot, whose lift resolves its six
    /// bending freedoms to the least bending effort, where that family has
    /// one branch: bent to one side (near the axis, below the straight
    /// height, mirror-image S-bends tie; docs/design.md §3).
    fn three_segment_points(s: &Statics) -> Vec<Vec<f64>> {
        [
            [0.3, 0.2, 0.0, 0.0, 0.4, 0.1, 0.2, 0.0, 0.5],
            [0.4, 0.0, 0.0, 0.4, 0.0, 0.0, 0.0, 0.4, 0.0],
            [0.5, 0.3, 0.0, 0.2, 0.0, 0.0, 0.0, 0.4, 0.1],
        ]
        .iter()
        .map(|t| {
            let p = s.solve(t, None).unwrap().position;
            vec![p.x, p.y, p.z]
        })
        .collect()
    }

    #[test]
    fn three_segment_lifts_reproduce_3d_targets() {
        let s = statics_of("tdcr-3seg.toml");
        check_lifts_reproduce_targets(&s, &three_segment_points(&s));
    }

    /// The tangent is the least-bending family's: a setpoint moved along it
    /// stays on the poses the net was trained on. (The least-norm tension
    /// direction that serves the least-total family misses this in
    /// orientation by far more than the tolerance.)
    #[test]
    fn three_segment_tangent_matches_central_differences() {
        let s = statics_of("tdcr-3seg.toml");
        // Differences over 0.4 mm, to 2 %: phase 2 finds the least bending
        // effort to ~1e-6 rad in orientation, which a difference over 2h
        // reads as 1e-6 / 2h (2.5e-3 /m here, against columns of 0.4–18 /m),
        // and the family is steep in height (second order near straight),
        // so a longer difference would read its curvature.
        check_tangent_against_central_differences(&s, &three_segment_points(&s), 2e-4, 2e-2);
    }

    /// The mid height lies inside the height range at the circle's start,
    /// and a circle point at it is liftable (checked above); the range has
    /// room (a two-segment robot's S and C shapes differ by millimetres).
    #[test]
    fn two_segment_mid_height_is_inside_the_reachable_range() {
        let s = statics_of("tdcr-2seg.toml");
        let lifter = Lifter::new(&s).unwrap();
        let (lo, hi) = lifter.height_range([0.01, 0.0]).unwrap();
        let mid = lifter.mid_height([0.0, 0.0], 0.01).unwrap();
        assert!(lo < mid && mid < hi && hi - lo > 1e-3, "{lo} {mid} {hi}");
        assert!(hi <= s.robot().length);
    }

    /// One-tendon robot: the tip's coordinate along its axis, from a little
    /// past where it hangs under gravity to well into the pull.
    fn one_tendon_points(s: &Statics) -> Vec<Vec<f64>> {
        let family = Lifter::new(s).unwrap().family();
        let floors = s.robot().min_tensions();
        let rest = s.solve(&floors, None).unwrap();
        let u0 = family.coordinates(&rest.position.into())[0];
        [0.002, 0.01, 0.03].iter().map(|d| vec![u0 + d]).collect()
    }

    #[test]
    fn one_tendon_lifts_reproduce_their_coordinate() {
        let s = statics_of("seed-1t.toml");
        check_lifts_reproduce_targets(&s, &one_tendon_points(&s));
    }

    #[test]
    fn one_tendon_tangent_matches_central_differences() {
        let s = statics_of("seed-1t.toml");
        check_tangent_against_central_differences(&s, &one_tendon_points(&s), 2e-5, 1e-4);
    }

    #[test]
    fn unreachable_target_is_a_clear_error() {
        let s = statics();
        let err = Lifter::new(&s).unwrap().lift([0.5, 0.0]).unwrap_err();
        assert!(err.to_string().contains("outside"), "{err}");
        let err = Lifter::new(&s).unwrap().lift([f64::NAN, 0.0]).unwrap_err();
        assert!(err.to_string().contains("finite"), "{err}");
        let err = Lifter::new(&s).unwrap().lift([0.0, 0.0, 0.3]).unwrap_err();
        assert!(err.to_string().contains("3 coordinates"), "{err}");
    }
}
