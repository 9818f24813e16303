//! Building a [`Trajectory`] from a [`PathShape`]: the shape's points on
//! the robot's family, lifted to reachable poses by the exact IK
//! ([`Lifter`]) once at start-up (`docs/design.md` §4.1, §6); a pose
//! table's rows through [`super::table`].

use super::path::{
    circle_point, figure_eight_point, helix_height, lateral_circle, periodic_times,
    sweep_coordinate,
};
use super::shape::unfit;
use super::trajectory::Trajectory;
use super::{FamilyTangent, Lifter, PathShape, PlanError};
use crate::statics::Statics;

/// Lifted points as trajectory columns.
#[derive(Default)]
struct LiftedPath {
    poses: Vec<[f64; 7]>,
    tangents: Vec<FamilyTangent>,
    tensions: Vec<Vec<f64>>,
}

impl LiftedPath {
    fn push(&mut self, lifter: &mut Lifter, u: &[f64]) -> Result<(), PlanError> {
        let lifted = lifter.lifted(u)?;
        self.poses.push(lifted.pose);
        self.tangents.push(lifted.tangent);
        self.tensions.push(lifted.tensions);
        Ok(())
    }

    fn into_trajectory(self, times: Vec<f64>, periodic: bool, stepwise: bool) -> Trajectory {
        Trajectory {
            times,
            feedforward_miss: vec![0.0; self.poses.len()],
            poses: self.poses,
            tangents: self.tangents,
            feedforward: self.tensions,
            periodic,
            stepwise,
            shaping: None,
        }
    }
}

/// A point of `shape` on the family: `given` coordinates (k of them, or
/// lateral x, y plus `height` / the mid height on a robot that reaches a
/// volume).
fn on_family(
    shape: &PathShape,
    lifter: &Lifter,
    given: &[f64],
    height: Option<f64>,
    default_height: &mut dyn FnMut(&Lifter) -> Result<f64, PlanError>,
) -> Result<Vec<f64>, PlanError> {
    let family = lifter.family();
    let k = family.dim();
    if given.iter().chain(&height).any(|v| !v.is_finite()) {
        return Err(PlanError::Shape(format!(
            "trajectory {}: coordinates must be finite numbers",
            shape.name()
        )));
    }
    match (k, given.len(), height) {
        (3, 2, h) => {
            let z = match h {
                Some(z) => z,
                None => default_height(lifter)?,
            };
            Ok(vec![given[0], given[1], z])
        }
        (_, n, None) if n == k => Ok(given.to_vec()),
        (_, n, Some(_)) if n == k || k != 3 => Err(unfit(
            shape,
            &family,
            "a height needs lateral (x, y) points on a robot that reaches a volume",
        )),
        (_, n, _) => Err(unfit(
            shape,
            &family,
            &format!("a point has {n} coordinates, the robot's family {k}"),
        )),
    }
}

/// The mid height for a lateral path of `radius` about `center`, computed once.
fn mid_height_once(center: [f64; 2], radius: f64) -> impl FnMut(&Lifter) -> Result<f64, PlanError> {
    let mut cached = None;
    move |lifter: &Lifter| {
        if let Some(z) = cached {
            return Ok(z);
        }
        let z = lifter.mid_height(center, radius)?;
        log::info!(
            "trajectory: mid height {:.2} mm for radius {:.1} mm about ({:.1}, {:.1}) mm",
            z * 1e3,
            radius * 1e3,
            center[0] * 1e3,
            center[1] * 1e3
        );
        cached = Some(z);
        Ok(z)
    }
}

impl Trajectory {
    /// Tabulate `shape` for `statics`' robot: points on the robot's family
    /// lifted to reachable poses by the exact IK, each point warm-started
    /// from the previous one ([`Lifter`]). A shape the family cannot follow
    /// (a circle for a robot whose tip moves on a curve, a sweep for one that
    /// reaches a surface) is a [`PlanError::Shape`] naming both.
    pub fn new(shape: &PathShape, statics: &Statics) -> Result<Trajectory, PlanError> {
        let mut lifter = Lifter::new(statics)?;
        shape.check(&lifter.family())?;
        let lifter = &mut lifter;
        match shape {
            PathShape::Hold { center_m, height_m } => hold(shape, lifter, center_m, *height_m),
            PathShape::Steps {
                targets_m,
                dwell_s,
                height_m,
            } => steps(shape, lifter, targets_m, *dwell_s, *height_m),
            PathShape::Circle {
                center_m,
                radius_m,
                freq_hz,
                height_m,
            }
            | PathShape::FigureEight {
                center_m,
                radius_m,
                freq_hz,
                height_m,
            } => lateral_path(shape, lifter, *center_m, *radius_m, *freq_hz, *height_m),
            PathShape::Helix {
                center_m,
                radius_m,
                freq_hz,
                heights_m,
                turns,
            } => helix(
                shape, lifter, *center_m, *radius_m, *freq_hz, *heights_m, *turns,
            ),
            PathShape::Sweep {
                from_m,
                to_m,
                freq_hz,
            } => sweep(shape, lifter, *from_m, *to_m, *freq_hz),
            PathShape::Table { rows } => super::table::table(lifter, rows),
        }
    }
}

/// Hold one point (at the mid height of the robot there when lateral on a
/// robot that reaches a volume).
fn hold(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: &[f64],
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    let mut z = mid_height_once([center[0], *center.get(1).unwrap_or(&0.0)], 0.0);
    let u = on_family(shape, lifter, center, height, &mut z)?;
    let mut path = LiftedPath::default();
    path.push(lifter, &u)?;
    Ok(path.into_trajectory(vec![0.0], false, true))
}

/// Visit `targets` in turn, `dwell` s each.
fn steps(
    shape: &PathShape,
    lifter: &mut Lifter,
    targets: &[Vec<f64>],
    dwell: f64,
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    if targets.is_empty() || dwell.is_nan() || dwell <= 0.0 {
        return Err(PlanError::Shape(
            "steps need at least one target and a positive dwell".into(),
        ));
    }
    // Lateral targets on a robot that reaches a volume: the mid
    // height of the smallest circle about their centroid holding them.
    let (centroid, radius) = lateral_circle(targets);
    let mut z = mid_height_once(centroid, radius);
    let family = lifter.family();
    let points = targets
        .iter()
        .map(|t| {
            if t.is_empty() {
                return Err(unfit(shape, &family, "an empty target"));
            }
            on_family(shape, lifter, t, height, &mut z)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut path = LiftedPath::default();
    for u in &points {
        path.push(lifter, u)?;
    }
    let times = (0..targets.len()).map(|i| i as f64 * dwell).collect();
    Ok(path.into_trajectory(times, false, true))
}

/// A circle or figure eight of `radius` about lateral `center` at `freq`
/// Hz (at `height`, or the mid height, on a robot that reaches a volume).
fn lateral_path(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: [f64; 2],
    radius: f64,
    freq: f64,
    height: Option<f64>,
) -> Result<Trajectory, PlanError> {
    if !(freq > 0.0 && radius >= 0.0) {
        return Err(PlanError::Shape(
            "a path needs a positive frequency and radius".into(),
        ));
    }
    let family = lifter.family();
    let k = family.dim();
    if k < 2 {
        return Err(unfit(
            shape,
            &family,
            "a lateral path needs two coordinates",
        ));
    }
    let height = match (k, height) {
        (3, Some(z)) => Some(z),
        (3, None) => Some(mid_height_once(center, radius)(lifter)?),
        (_, None) => None,
        (_, Some(_)) => {
            return Err(unfit(
                shape,
                &family,
                "a height needs a robot that reaches a volume",
            ))
        }
    };
    let eight = matches!(shape, PathShape::FigureEight { .. });
    lift_closed(lifter, periodic_times(freq, 1.0), |t| {
        let xy = if eight {
            figure_eight_point(center, radius, freq, t)
        } else {
            circle_point(center, radius, freq, t)
        };
        let mut u = xy.to_vec();
        u.extend(height);
        u
    })
}

/// A circle whose height rises from `heights[0]` to `heights[1]` over
/// `turns` revolutions and falls back over as many.
fn helix(
    shape: &PathShape,
    lifter: &mut Lifter,
    center: [f64; 2],
    radius: f64,
    freq: f64,
    heights: [f64; 2],
    turns: f64,
) -> Result<Trajectory, PlanError> {
    let family = lifter.family();
    if family.dim() != 3 {
        return Err(unfit(
            shape,
            &family,
            "a helix needs a robot that reaches a volume",
        ));
    }
    let halves = 2.0 * turns;
    let valid = freq > 0.0
        && radius >= 0.0
        && halves >= 1.0
        && halves.fract() == 0.0
        && heights.iter().all(|z| z.is_finite());
    if !valid {
        return Err(PlanError::Shape(
            "a helix needs a positive frequency and radius, finite heights and a \
             whole number of half turns (≥ ½)"
                .into(),
        ));
    }
    lift_closed(lifter, periodic_times(freq, 2.0 * turns), |t| {
        let [x, y] = circle_point(center, radius, freq, t);
        vec![x, y, helix_height(heights, turns, freq, t)]
    })
}

/// The tip's coordinate along the axis of a robot that moves on a curve,
/// swept between `from` and `to` at `freq` Hz.
fn sweep(
    shape: &PathShape,
    lifter: &mut Lifter,
    from: f64,
    to: f64,
    freq: f64,
) -> Result<Trajectory, PlanError> {
    let family = lifter.family();
    if family.dim() != 1 {
        return Err(unfit(
            shape,
            &family,
            "a sweep is for a robot whose tip moves on a curve (plan a circle or steps)",
        ));
    }
    if !(freq > 0.0 && from.is_finite() && to.is_finite()) {
        return Err(PlanError::Shape(
            "a sweep needs finite coordinates and a positive frequency".into(),
        ));
    }
    lift_closed(lifter, periodic_times(freq, 1.0), |t| {
        vec![sweep_coordinate(from, to, freq, t)]
    })
}

/// Lift `point(t)` at each of `times` (one period of a closed path) into a
/// periodic trajectory.
fn lift_closed(
    lifter: &mut Lifter,
    times: Vec<f64>,
    point: impl Fn(f64) -> Vec<f64>,
) -> Result<Trajectory, PlanError> {
    let mut path = LiftedPath::default();
    for &t in &times {
        path.push(lifter, &point(t))?;
    }
    Ok(path.into_trajectory(times, true, false))
}
