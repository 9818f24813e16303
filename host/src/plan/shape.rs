//! The path schema: what the planner follows, serialised with a `kind`
//! tag and units in the field names, and whether a robot's family can
//! follow it (`docs/design.md` §6).

use serde::{Deserialize, Serialize};

use super::{Family, PlanError};

/// What the planner follows (serialised with a `kind` tag, units in the
/// field names). Points are the tip's coordinates on the robot's family
/// (module docs): x, y (m) for a robot that bends over a surface; x, y, z,
/// or x, y and a `height_m`, for one that reaches a volume (no height: the
/// robot's mid height, [`super::Lifter::mid_height`]); the one coordinate along
/// the axis for one that moves on a curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PathShape {
    /// Hold one point.
    Hold {
        /// The point, m.
        center_m: Vec<f64>,
        /// Height for a lateral `center_m` on a robot that reaches a volume, m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Visit points in turn, `dwell_s` seconds each.
    Steps {
        /// Targets, m.
        targets_m: Vec<Vec<f64>>,
        /// Seconds per target.
        dwell_s: f64,
        /// Height for lateral targets on a robot that reaches a volume, m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Circle of `radius_m` about lateral `center_m` at `freq_hz`, starting at +x.
    Circle {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Radius, m.
        radius_m: f64,
        /// Revolutions per second.
        freq_hz: f64,
        /// Height on a robot that reaches a volume, m (default: its mid height).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// Lemniscate of Gerono (figure eight) of half-width `radius_m` about `center_m`.
    FigureEight {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Half-width, m.
        radius_m: f64,
        /// Periods per second.
        freq_hz: f64,
        /// Height on a robot that reaches a volume, m (default: its mid height).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_m: Option<f64>,
    },
    /// A circle whose height moves at a constant rate from `heights_m[0]`
    /// to `heights_m[1]` over `turns` revolutions and back over as many,
    /// turning back on a parabola ([`super::path::helix_height`]; periodic;
    /// a robot that reaches a volume).
    Helix {
        /// Lateral centre, m.
        center_m: [f64; 2],
        /// Radius, m.
        radius_m: f64,
        /// Revolutions per second.
        freq_hz: f64,
        /// Start and top heights, m.
        heights_m: [f64; 2],
        /// Revolutions from one height to the other (a multiple of ½, so
        /// the path closes).
        turns: f64,
    },
    /// The tip's coordinate along the axis of a robot that moves on a
    /// curve, `from_m + (to_m − from_m) (1 − cos 2π f t) / 2`.
    Sweep {
        /// Start (and end) coordinate, m.
        from_m: f64,
        /// Farthest coordinate, m.
        to_m: f64,
        /// Periods per second.
        freq_hz: f64,
    },
    /// Full poses from a table (times increasing).
    Table {
        /// The rows.
        rows: Vec<PoseRow>,
    },
}

impl PathShape {
    /// The 30 mm circle (radius 15 mm) at 0.2 Hz about the axis, at the
    /// robot's mid height where it reaches a volume: the path `tendril sim`
    /// and `tendril planner` follow unless told, and the main job's first
    /// loop run.
    pub fn default_circle() -> PathShape {
        PathShape::Circle {
            center_m: [0.0, 0.0],
            radius_m: 0.015,
            freq_hz: 0.2,
            height_m: None,
        }
    }

    /// Whether the path has an acceleration everywhere (a circle, a figure
    /// eight, a sweep, a helix, whose height turns back on a parabola):
    /// what the dynamic offset needs, r̈ (steps and pose tables jump or
    /// turn a corner).
    pub fn is_smooth(&self) -> bool {
        matches!(
            self,
            PathShape::Circle { .. }
                | PathShape::FigureEight { .. }
                | PathShape::Sweep { .. }
                | PathShape::Helix { .. }
        )
    }

    /// How long the path takes to come back to where it was, s: what
    /// learning for repeated paths learns over (`docs/design.md` §6.4).
    /// None for paths that do not repeat as drawn (a hold, steps, a table).
    pub fn period_s(&self) -> Option<f64> {
        match *self {
            PathShape::Circle { freq_hz, .. }
            | PathShape::FigureEight { freq_hz, .. }
            | PathShape::Sweep { freq_hz, .. } => Some(1.0 / freq_hz),
            PathShape::Helix { freq_hz, turns, .. } => Some(2.0 * turns / freq_hz),
            _ => None,
        }
        .filter(|p| p.is_finite() && *p > 0.0)
    }

    /// The shape's name as in its `kind` tag.
    pub fn name(&self) -> &'static str {
        match self {
            PathShape::Hold { .. } => "hold",
            PathShape::Steps { .. } => "steps",
            PathShape::Circle { .. } => "circle",
            PathShape::FigureEight { .. } => "figure_eight",
            PathShape::Helix { .. } => "helix",
            PathShape::Sweep { .. } => "sweep",
            PathShape::Table { .. } => "table",
        }
    }

    /// Whether a robot of `family` can follow the shape (its kind and the
    /// number of coordinates of its points), before anything is lifted:
    /// a [`PlanError::Shape`] naming the shape and the family if not.
    pub fn check(&self, family: &Family) -> Result<(), PlanError> {
        let k = family.dim();
        let points = |points: &[&Vec<f64>], height: &Option<f64>| {
            for p in points {
                let fits = p.len() == k || (k == 3 && p.len() == 2);
                if !fits {
                    let why = format!(
                        "a point has {} coordinates, the robot's family {k}",
                        p.len()
                    );
                    return Err(unfit(self, family, &why));
                }
                if height.is_some() && !(k == 3 && p.len() == 2) {
                    return Err(unfit(
                        self,
                        family,
                        "a height needs lateral (x, y) points on a robot that reaches a volume",
                    ));
                }
            }
            Ok(())
        };
        match self {
            PathShape::Hold { center_m, height_m } => points(&[center_m], height_m),
            PathShape::Steps {
                targets_m,
                height_m,
                ..
            } => points(&targets_m.iter().collect::<Vec<_>>(), height_m),
            PathShape::Circle { height_m, .. } | PathShape::FigureEight { height_m, .. } => {
                if k < 2 {
                    Err(unfit(self, family, "a lateral path needs two coordinates"))
                } else if height_m.is_some() && k != 3 {
                    Err(unfit(
                        self,
                        family,
                        "a height needs a robot that reaches a volume",
                    ))
                } else {
                    Ok(())
                }
            }
            PathShape::Helix { .. } if k != 3 => Err(unfit(
                self,
                family,
                "a helix needs a robot that reaches a volume",
            )),
            PathShape::Sweep { .. } if k != 1 => Err(unfit(
                self,
                family,
                "a sweep is for a robot whose tip moves on a curve (plan a circle or steps)",
            )),
            PathShape::Helix { .. } | PathShape::Sweep { .. } | PathShape::Table { .. } => Ok(()),
        }
    }
}

/// One row of a pose table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseRow {
    /// Time from the start, s.
    pub t_s: f64,
    /// px, py, pz (m), qw, qx, qy, qz.
    pub pose: [f64; 7],
}

/// The shape cannot be followed by a robot of this family.
pub(super) fn unfit(shape: &PathShape, family: &Family, why: &str) -> PlanError {
    PlanError::Shape(format!(
        "trajectory {}: {why}; this robot's tip reaches {}",
        shape.name(),
        family.describe()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Configurations written before heights existed still read.
    #[test]
    fn shapes_without_a_height_still_deserialise() {
        let text = r#"{"kind":"circle","center_m":[0.0,0.0],"radius_m":0.015,"freq_hz":0.2}"#;
        let shape: PathShape = serde_json::from_str(text).unwrap();
        assert_eq!(shape, PathShape::default_circle());
        let text = r#"{"kind":"steps","targets_m":[[0.01,0.0]],"dwell_s":2.0}"#;
        assert!(serde_json::from_str::<PathShape>(text).is_ok());
    }
}
