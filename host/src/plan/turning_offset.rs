//! An offset that turns with a circle (`docs/design.md` §6.4, "Learning on
//! the model"): per harmonic of the path's period, in the circle's own
//! turning frame — radial, tangential, height — where a bent robot
//! following a circle looks the same at every angle, so that an offset at
//! one harmonic moves the error at that harmonic (and, through the three
//! tendons a segment, at those three apart), not at the harmonics two apart
//! that the fixed frame's turning stiffness couples.

use serde::{Deserialize, Serialize};

/// The offset u(φ, θ) = R(θ) Re Σ_m U_m e^{j2πmφ}: φ the phase of the
/// path's period, θ the tip's angle about the circle's centre, R(θ) the
/// turn from (radial, tangential, height) to (x, y, z).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TurningOffset {
    /// The circle's lateral centre, m (the path's).
    pub center_m: [f64; 2],
    /// The path's period, s.
    pub period_s: f64,
    /// `harmonics[m][axis] = [re, im]` of U_m, m; axis 0 radial, 1
    /// tangential, 2 height. Harmonic 0's imaginary part is unused.
    pub harmonics: Vec<[[f64; 2]; 3]>,
    /// What the table was learned for (a planner sends it only there).
    #[serde(default)]
    pub learned_for: Option<LearnedFor>,
}

/// The robot file and the path a table was learned for: the same circle
/// on another robot, or at another radius or height, needs another.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnedFor {
    /// The robot file's fingerprint (`Robot::fingerprint`).
    pub robot: [u8; 32],
    /// The path.
    pub shape: super::PathShape,
}

impl TurningOffset {
    /// No offset, with `n` harmonics (0 to n − 1).
    pub fn zero(center_m: [f64; 2], period_s: f64, n: usize) -> TurningOffset {
        TurningOffset {
            center_m,
            period_s,
            harmonics: vec![[[0.0; 2]; 3]; n],
            learned_for: None,
        }
    }

    /// The offset in the base frame (m, x y z) at the path's own time
    /// `t_path` (s) for a setpoint at `position` (m).
    pub fn at(&self, t_path: f64, position: [f64; 3]) -> [f64; 3] {
        let phase = (t_path / self.period_s).rem_euclid(1.0);
        let mut turning = [0.0; 3];
        for (m, coefficients) in self.harmonics.iter().enumerate() {
            let angle = std::f64::consts::TAU * m as f64 * phase;
            let (sin, cos) = angle.sin_cos();
            for (u, [re, im]) in turning.iter_mut().zip(coefficients) {
                *u += re * cos - im * sin;
            }
        }
        let theta = (position[1] - self.center_m[1]).atan2(position[0] - self.center_m[0]);
        let (sin, cos) = theta.sin_cos();
        [
            turning[0] * cos - turning[1] * sin,
            turning[0] * sin + turning[1] * cos,
            turning[2],
        ]
    }

    /// The error `e` (m, x y z) at `position` in the turning frame
    /// (radial, tangential, height).
    pub fn turned(&self, position: [f64; 3], e: [f64; 3]) -> [f64; 3] {
        let theta = (position[1] - self.center_m[1]).atan2(position[0] - self.center_m[0]);
        let (sin, cos) = theta.sin_cos();
        [e[0] * cos + e[1] * sin, -e[0] * sin + e[1] * cos, e[2]]
    }

    /// Read a table `tendril sim --model-learning on` wrote
    /// (`turning-offset.json`): JSON, at most 1 MB, finite, a period > 0.
    pub fn read(path: &std::path::Path) -> Result<TurningOffset, String> {
        let bytes = crate::fsutil::read_capped(path, 1 << 20)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        let table: TurningOffset = serde_json::from_slice(&bytes)
            .map_err(|e| format!("{}: not a turning offset: {e}", path.display()))?;
        table
            .check(f64::INFINITY)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(table)
    }

    /// The largest coefficient, m.
    pub fn largest_m(&self) -> f64 {
        self.harmonics
            .iter()
            .flatten()
            .flatten()
            .fold(0.0, |a: f64, v| a.max(v.abs()))
    }

    /// A table a planner can use: finite, a positive period, offsets within
    /// `bound_m` per coefficient.
    pub fn check(&self, bound_m: f64) -> Result<(), String> {
        let finite = self.center_m.iter().all(|v| v.is_finite())
            && self
                .harmonics
                .iter()
                .flatten()
                .flatten()
                .all(|v| v.is_finite());
        if !(finite && self.period_s.is_finite() && self.period_s > 0.0) {
            return Err("the turning offset has a non-finite value or a period ≤ 0".into());
        }
        if self.largest_m() > bound_m {
            return Err(format!(
                "the turning offset's largest coefficient {:.3} mm is over {:.3} mm",
                self.largest_m() * 1e3,
                bound_m * 1e3
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_radial_offset_points_away_from_the_centre_everywhere() {
        let mut u = TurningOffset::zero([0.01, -0.02], 5.0, 3);
        u.harmonics[0][0] = [1e-4, 0.0];
        for theta in [0.0f64, 1.0, 2.5, -2.0] {
            let p = [0.01 + 0.03 * theta.cos(), -0.02 + 0.03 * theta.sin(), 0.2];
            let o = u.at(1.3, p);
            assert!((o[0] - 1e-4 * theta.cos()).abs() < 1e-15, "{o:?}");
            assert!((o[1] - 1e-4 * theta.sin()).abs() < 1e-15, "{o:?}");
            assert_eq!(o[2], 0.0);
            // and turning it back gives the radial offset again
            let back = u.turned(p, o);
            assert!((back[0] - 1e-4).abs() < 1e-15 && back[1].abs() < 1e-15);
        }
    }

    #[test]
    fn a_harmonic_turns_with_the_phase_of_the_period() {
        let mut u = TurningOffset::zero([0.0, 0.0], 4.0, 3);
        // height: 2e-5 cos(2·2πφ) − (−3e-5) sin(2·2πφ)
        u.harmonics[2][2] = [2e-5, -3e-5];
        for t in [0.0, 0.3, 1.0, 2.7, 4.3] {
            let phase = (t / 4.0f64) * std::f64::consts::TAU * 2.0;
            let want = 2e-5 * phase.cos() + 3e-5 * phase.sin();
            let got = u.at(t, [0.02, 0.0, 0.3])[2];
            assert!((got - want).abs() < 1e-15, "t {t}: {got} against {want}");
        }
        assert!(u.check(1e-3).is_ok());
        assert!(u.check(2e-5).is_err());
        u.harmonics[1][0][0] = f64::NAN;
        assert!(u.check(1e-3).is_err());
    }

    #[test]
    fn a_table_reads_back_as_written_and_a_bad_one_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("turning-offset.json");
        let mut u = TurningOffset::zero([0.001, 0.0], 5.0, 2);
        u.harmonics[1] = [[1e-5, -2e-5], [3e-5, 0.0], [0.0, 4e-6]];
        std::fs::write(&path, serde_json::to_vec(&u).unwrap()).unwrap();
        assert_eq!(TurningOffset::read(&path).unwrap(), u);
        for (text, why) in [
            ("{\"center_m\": [0, 0]}", "not a turning offset"),
            (
                "{\"center_m\": [0, 0], \"period_s\": -1, \"harmonics\": []}",
                "period",
            ),
            ("[1, 2", "not a turning offset"),
        ] {
            std::fs::write(&path, text).unwrap();
            let err = TurningOffset::read(&path).unwrap_err();
            assert!(
                err.contains("turning-offset.json") && err.contains(why),
                "{text}: {err}"
            );
        }
        let err = TurningOffset::read(&dir.path().join("missing.json")).unwrap_err();
        assert!(err.contains("missing.json"), "{err}");
    }
}
