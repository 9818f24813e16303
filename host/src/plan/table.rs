//! Pose tables: full poses over time from a file, their feed-forward
//! tensions from the exact IK on the full pose (`docs/design.md` §4.1), and
//! the tangents of the reachable poses at the same coordinates.

use std::path::Path;

use super::trajectory::Trajectory;
use super::{FamilyTangent, Lifter, PlanError, PoseRow};
use crate::inverse::{ExactIk, InverseError, Target};
use crate::statics::WarmStart;

/// The trajectory of a pose table: its rows' poses, linearly interpolated,
/// with exact feed-forward tensions ([`table_feedforward`]).
pub(super) fn table(lifter: &mut Lifter, rows: &[PoseRow]) -> Result<Trajectory, PlanError> {
    if rows.is_empty() || rows.windows(2).any(|w| w[1].t_s <= w[0].t_s) {
        return Err(PlanError::Shape(
            "pose table needs rows with increasing times".into(),
        ));
    }
    let family = lifter.family();
    let k = family.dim();
    // The table's poses are the user's; their tangents come from
    // the reachable pose at the same coordinates on the family.
    // If some row is out of reach there are none, and the
    // firmware's correction moves the position alone.
    let tangents: Result<Vec<FamilyTangent>, _> = rows
        .iter()
        .map(|r| {
            let u = family.coordinates(&[r.pose[0], r.pose[1], r.pose[2]]);
            lifter.lift_with_tangent(&u[..k]).map(|(_, d)| d)
        })
        .collect();
    let tangents = tangents.unwrap_or_else(|e| {
        log::warn!("pose table: no tangents for the correction ({e})");
        Vec::new()
    });
    let (feedforward, feedforward_miss) = table_feedforward(lifter.ik(), rows);
    Ok(Trajectory {
        times: rows.iter().map(|r| r.t_s).collect(),
        poses: rows.iter().map(|r| r.pose).collect(),
        tangents,
        feedforward,
        feedforward_miss,
        periodic: false,
        stepwise: false,
        shaping: None,
    })
}

/// Exact tensions for each row of a pose table (full-pose targets with the
/// IK's default orientation weight, the backbone length in m/rad,
/// `docs/design.md` §4.1), each row warm-started from the previous one, and
/// each row's miss: 0 when reached, the distance to the closest reachable
/// pose when out of reach (the row is named in the log, its reference is
/// that closest pose's tensions), NaN when the IK gave no answer.
fn table_feedforward(ik: &ExactIk, rows: &[PoseRow]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = ik.robot().tendons.len();
    let mut tensions = Vec::with_capacity(rows.len());
    let mut misses = Vec::with_capacity(rows.len());
    let mut previous: Option<(Vec<f64>, WarmStart)> = None;
    let mut out_of_reach = 0;
    for (i, row) in rows.iter().enumerate() {
        let answer = Target::from_pose(&row.pose, false).and_then(|target| {
            let start = previous.as_ref().map(|(t, w)| (t.as_slice(), w));
            ik.solve(&target, start.map(|s| s.0), start.map(|s| s.1))
        });
        let (tau, miss) = match answer {
            Ok(s) => {
                previous = Some((s.tensions.clone(), s.warm));
                (s.tensions, 0.0)
            }
            Err(InverseError::Unreachable { closest }) => {
                out_of_reach += 1;
                log::warn!(
                    "pose table row {} (t = {} s) is out of reach: feed-forward from the closest reachable pose, {:.3} mm and {:.4} rad away ({})",
                    i + 1,
                    row.t_s,
                    closest.position_error * 1e3,
                    closest.orientation_error.unwrap_or(f64::NAN),
                    closest.active_limits()
                );
                previous = Some((closest.tensions.clone(), closest.warm));
                (closest.tensions, closest.position_error)
            }
            Err(e) => {
                log::warn!(
                    "pose table row {} (t = {} s): no feed-forward tensions ({e})",
                    i + 1,
                    row.t_s
                );
                (vec![f64::NAN; n], f64::NAN)
            }
        };
        tensions.push(tau);
        misses.push(miss);
    }
    if out_of_reach > 0 {
        log::warn!(
            "pose table: {out_of_reach} of {} rows out of reach (their feed-forward is the closest reachable pose's)",
            rows.len()
        );
    }
    (tensions, misses)
}

/// Read a pose table (`t,px,py,pz,qw,qx,qy,qz`, header line required).
pub fn read_pose_csv(path: &Path) -> Result<Vec<PoseRow>, PlanError> {
    // A pose table at 1 kHz for an hour is ≈ 200 MB; beyond 512 MiB it is
    // not one (and `/dev/zero` is refused, never read until memory runs out).
    let bytes = crate::fsutil::read_capped(path, 512 << 20).map_err(|cause| PlanError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    let text = String::from_utf8(bytes).map_err(|e| PlanError::Io {
        path: path.to_path_buf(),
        cause: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
    })?;
    let mut rows = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split(',').map(|s| s.trim().parse::<f64>()).collect();
        match v {
            Ok(v) if v.len() == 8 && v.iter().all(|x| x.is_finite()) => {
                rows.push(PoseRow {
                    t_s: v[0],
                    pose: [v[1], v[2], v[3], v[4], v[5], v[6], v[7]],
                });
            }
            _ => {
                return Err(PlanError::Shape(format!(
                    "{} line {}: expected 8 finite numbers t,px,py,pz,qw,qx,qy,qz",
                    path.display(),
                    n + 1
                )))
            }
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::PathShape;
    use crate::statics::Statics;
    use nalgebra::Vector3;

    fn statics() -> Statics {
        crate::statics::repo_statics("seed-4t.toml")
    }

    #[test]
    fn pose_tables_get_the_tangent_of_the_reachable_pose_at_each_row() {
        let s = statics();
        let xys = [[0.01, 0.0], [0.0, 0.02], [-0.015, -0.005]];
        let mut lifter = Lifter::new(&s).unwrap();
        let lifted: Vec<([f64; 7], FamilyTangent)> = xys
            .iter()
            .map(|&xy| lifter.lift_with_tangent(xy).unwrap())
            .collect();
        let rows: Vec<PoseRow> = lifted
            .iter()
            .enumerate()
            .map(|(i, (p, _))| PoseRow {
                t_s: i as f64,
                pose: *p,
            })
            .collect();
        let traj = Trajectory::new(&PathShape::Table { rows: rows.clone() }, &s).unwrap();
        for (i, (_, d)) in lifted.iter().enumerate() {
            let got = traj.sample(i as f64).tangent.expect("a tangent");
            for j in 0..2 {
                for k in 0..7 {
                    assert!(
                        (got.columns[j][k] - d.columns[j][k]).abs() < 1e-4,
                        "row {i}: {got:?} vs {d:?}"
                    );
                }
            }
        }
        // A row out of reach: no tangents (the correction falls back).
        let mut far = rows;
        far[1].pose[0] = 0.5;
        let traj = Trajectory::new(&PathShape::Table { rows: far }, &s).unwrap();
        assert!(traj.sample(0.0).tangent.is_none());
    }

    /// Feed-forward tensions of a pose table: reachable rows (poses of
    /// known tensions) get tensions whose fresh forward solve gives the
    /// row's pose; a row out of reach is no failure, its miss is the
    /// distance to where its (closest-pose) tensions put the tip.
    #[test]
    fn pose_table_rows_get_exact_feedforward_tensions() {
        let s = statics();
        let truth = [
            [3.0, 1.0, 0.0, 0.0],
            [0.0, 2.0, 1.5, 0.0],
            [0.5, 0.0, 0.0, 4.0],
        ];
        let mut rows: Vec<PoseRow> = truth
            .iter()
            .enumerate()
            .map(|(i, tau)| PoseRow {
                t_s: i as f64,
                pose: s.solve(tau, None).unwrap().pose(),
            })
            .collect();
        let traj = Trajectory::new(&PathShape::Table { rows: rows.clone() }, &s).unwrap();
        assert_eq!(traj.tendons(), 4);
        let mut ff = Vec::new();
        for row in &rows {
            assert_eq!(traj.feedforward(row.t_s, &mut ff), 0.0);
            let reached = statics().solve(&ff, None).unwrap();
            let p = reached.position;
            let miss = (p - Vector3::new(row.pose[0], row.pose[1], row.pose[2])).norm();
            assert!(miss <= 1e-6, "row at {} s: {miss:e} m", row.t_s);
            assert!(ff.iter().all(|&t| (0.0..=10.0).contains(&t)), "{ff:?}");
        }
        rows[1].pose[0] += 0.3;
        let traj = Trajectory::new(&PathShape::Table { rows: rows.clone() }, &s).unwrap();
        let miss = traj.feedforward(1.0, &mut ff);
        let p = statics().solve(&ff, None).unwrap().position;
        let expected = (p - Vector3::new(rows[1].pose[0], rows[1].pose[1], rows[1].pose[2])).norm();
        assert!(
            miss > 0.1 && (miss - expected).abs() < 1e-9,
            "{miss} vs {expected}"
        );
        assert_eq!(traj.feedforward(2.0, &mut ff), 0.0);
    }
}
