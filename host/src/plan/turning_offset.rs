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
    /// The offset over the path's first seconds on top of the periodic
    /// one: what takes the ring of the path's start out.
    #[serde(default)]
    pub start: Option<StartOffset>,
    /// The error the loop has on the model with this offset: what the
    /// stiffness adaptation does not read as the robot's.
    #[serde(default)]
    pub expected: Option<ExpectedError>,
}

/// The error (the path less the tip) the loop rehearsed on the model had
/// with the offset, in the turning frame: over the path's first seconds
/// bin by bin, then periodic. A robot that is its file shows it; the
/// stiffness adaptation fits what a robot shows beyond it — read as a
/// stiffness, the ring of the path's start took κ̂ to −0.05 on
/// `tdcr-3seg`'s 0.4 Hz circle, half a millimetre on the radius.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExpectedError {
    /// Width of a start bin, s of real time from the path's start.
    pub bin_s: f64,
    /// The mean error of each start bin, (radial, tangential, height), m.
    pub start: Vec<[f64; 3]>,
    /// After them, the periodic error's harmonics as
    /// [`TurningOffset::harmonics`], m.
    pub harmonics: Vec<[[f64; 2]; 3]>,
}

/// Re Σ_m H_m e^{j2πm·phase} per axis.
fn periodic(harmonics: &[[[f64; 2]; 3]], phase: f64) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for (m, coefficients) in harmonics.iter().enumerate() {
        let angle = std::f64::consts::TAU * m as f64 * phase;
        let (sin, cos) = angle.sin_cos();
        for (u, [re, im]) in sum.iter_mut().zip(coefficients) {
            *u += re * cos - im * sin;
        }
    }
    sum
}

impl ExpectedError {
    /// The error (turning frame, m) `since_s` s of real time after the
    /// path's start, at the path's phase `phase`: the start bins
    /// interpolated between their centres, then the periodic error.
    pub fn at(&self, since_s: f64, phase: f64) -> [f64; 3] {
        if since_s < 0.0 {
            return [0.0; 3];
        }
        let n = self.start.len();
        if n == 0 || self.bin_s.is_nan() || self.bin_s <= 0.0 || since_s >= n as f64 * self.bin_s {
            return periodic(&self.harmonics, phase);
        }
        let x = (since_s / self.bin_s - 0.5).max(0.0);
        let k = (x.floor() as usize).min(n - 1);
        let next = (k + 1).min(n - 1);
        let w = x - k as f64;
        std::array::from_fn(|a| self.start[k][a] * (1.0 - w) + self.start[next][a] * w)
    }
}

/// An offset over the path's first seconds, in the turning frame: raised
/// cosines of half-width `step_s` centred at `step_s`, 2 `step_s`, … of the
/// path's time, `bumps[k]` the (radial, tangential, height) height of the
/// (k+1)th, m. Adjacent ones sum to one between their centres, so the
/// offset is smooth, zero at the path's start (the hold and the approach
/// are not moved) and after its last bump.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartOffset {
    /// Spacing and half-width of the bumps, s of the path's time.
    pub step_s: f64,
    /// Per bump, (radial, tangential, height), m.
    pub bumps: Vec<[f64; 3]>,
}

impl StartOffset {
    /// No offset, `n` bumps `step_s` apart.
    pub fn zero(step_s: f64, n: usize) -> StartOffset {
        StartOffset {
            step_s,
            bumps: vec![[0.0; 3]; n],
        }
    }

    /// The weight of bump `k` at the path's time `t_path` (s).
    pub fn weight(&self, k: usize, t_path: f64) -> f64 {
        let x = (t_path - (k + 1) as f64 * self.step_s) / self.step_s;
        if x.abs() < 1.0 {
            0.5 * (1.0 + (std::f64::consts::PI * x).cos())
        } else {
            0.0
        }
    }

    /// The offset at `t_path` (s), turning frame, m.
    pub fn at(&self, t_path: f64) -> [f64; 3] {
        let mut u = [0.0; 3];
        if self.step_s.is_nan() || self.step_s <= 0.0 || t_path <= 0.0 {
            return u;
        }
        let k = (t_path / self.step_s).floor() as usize;
        for k in [k.wrapping_sub(1), k] {
            if let Some(b) = self.bumps.get(k) {
                let w = self.weight(k, t_path);
                for (u, b) in u.iter_mut().zip(b) {
                    *u += w * b;
                }
            }
        }
        u
    }

    /// The path's time after which it is zero, s.
    pub fn span_s(&self) -> f64 {
        (self.bumps.len() + 1) as f64 * self.step_s
    }
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
            start: None,
            expected: None,
        }
    }

    /// The offset in the base frame (m, x y z) at the path's own time
    /// `t_path` (s) for a setpoint at `position` (m).
    pub fn at(&self, t_path: f64, position: [f64; 3]) -> [f64; 3] {
        let mut turning = periodic(&self.harmonics, self.phase(t_path));
        if let Some(start) = &self.start {
            for (u, s) in turning.iter_mut().zip(start.at(t_path)) {
                *u += s;
            }
        }
        self.unturned(position, turning)
    }

    /// The error the model's loop had with this offset (none: zero), base
    /// frame (m, x y z), `since_s` s of real time after the path's start,
    /// at the path's time `t_path` and the setpoint `position`.
    pub fn expected_error(&self, since_s: f64, t_path: f64, position: [f64; 3]) -> [f64; 3] {
        match &self.expected {
            Some(e) => self.unturned(position, e.at(since_s, self.phase(t_path))),
            None => [0.0; 3],
        }
    }

    fn phase(&self, t_path: f64) -> f64 {
        (t_path / self.period_s).rem_euclid(1.0)
    }

    /// `turning` (radial, tangential, height) at `position` in the base
    /// frame.
    fn unturned(&self, position: [f64; 3], turning: [f64; 3]) -> [f64; 3] {
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

    /// The largest coefficient (a harmonic's or a start bump's), m.
    pub fn largest_m(&self) -> f64 {
        self.coefficients().fold(0.0, |a: f64, v| a.max(v.abs()))
    }

    fn coefficients(&self) -> impl Iterator<Item = f64> + '_ {
        let bumps = self.start.iter().flat_map(|s| s.bumps.iter().flatten());
        self.harmonics
            .iter()
            .flatten()
            .flatten()
            .chain(bumps)
            .copied()
    }

    /// A table a planner can use: finite, a positive period, offsets within
    /// `bound_m` per coefficient.
    pub fn check(&self, bound_m: f64) -> Result<(), String> {
        let finite =
            self.center_m.iter().all(|v| v.is_finite()) && self.coefficients().all(f64::is_finite);
        if !(finite && self.period_s.is_finite() && self.period_s > 0.0) {
            return Err("the turning offset has a non-finite value or a period ≤ 0".into());
        }
        if let Some(start) = &self.start {
            if !(start.step_s.is_finite() && start.step_s > 0.0) {
                return Err("the turning offset's start has a bump spacing ≤ 0".into());
            }
        }
        if let Some(e) = &self.expected {
            let values = e
                .start
                .iter()
                .flatten()
                .chain(e.harmonics.iter().flatten().flatten());
            if !(e.bin_s.is_finite() && e.bin_s > 0.0 && values.copied().all(f64::is_finite)) {
                return Err(
                    "the turning offset's expected error has a non-finite value or a bin ≤ 0"
                        .into(),
                );
            }
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

    /// The start's bumps sum to one between their centres (a constant
    /// height comes out constant), the offset is zero at the path's start
    /// and after the last bump, and it adds to the periodic part.
    #[test]
    fn the_start_offset_is_smooth_and_ends_where_its_bumps_do() {
        let mut start = StartOffset::zero(0.2, 5);
        for b in &mut start.bumps {
            *b = [1e-4, -2e-4, 3e-5];
        }
        for t in [0.2, 0.25, 0.5, 0.77, 1.0] {
            let u = start.at(t);
            assert!(
                (u[0] - 1e-4).abs() < 1e-15 && (u[1] + 2e-4).abs() < 1e-15,
                "{t}: {u:?}"
            );
        }
        assert_eq!(start.at(0.0), [0.0; 3]);
        assert_eq!(start.at(-1.0), [0.0; 3]);
        assert_eq!(start.at(start.span_s()), [0.0; 3]);
        assert_eq!(start.at(5.0), [0.0; 3]);
        // Rising from 0 as (1 − cos)/2 over the first bump's half-width.
        let u = start.at(0.1);
        assert!((u[0] - 0.5e-4).abs() < 1e-15, "{u:?}");
        let mut table = TurningOffset::zero([0.0, 0.0], 5.0, 1);
        table.harmonics[0][0] = [2e-5, 0.0];
        table.start = Some(start);
        let o = table.at(0.5, [0.01, 0.0, 0.3]);
        assert!((o[0] - 1.2e-4).abs() < 1e-15 && (o[1] + 2e-4).abs() < 1e-15);
        assert!((table.largest_m() - 2e-4).abs() < 1e-18);
        table.start.as_mut().unwrap().bumps[2][1] = f64::INFINITY;
        assert!(table.check(1.0).is_err());
    }

    /// The expected error: the start's bins, between their centres a
    /// straight line, then the periodic error; zero before the path, and
    /// turned with the circle as the offset is.
    #[test]
    fn the_expected_error_runs_through_its_bins_then_turns_periodic() {
        let e = ExpectedError {
            bin_s: 0.1,
            start: vec![[1e-4, 0.0, 0.0], [3e-4, 0.0, 0.0], [3e-4, 2e-5, 0.0]],
            harmonics: vec![
                [[5e-5, 0.0], [0.0; 2], [0.0; 2]],
                [[0.0; 2], [1e-5, 0.0], [0.0; 2]],
            ],
        };
        assert_eq!(e.at(-0.1, 0.0), [0.0; 3]);
        assert!((e.at(0.02, 0.0)[0] - 1e-4).abs() < 1e-15);
        assert!((e.at(0.1, 0.0)[0] - 2e-4).abs() < 1e-15);
        assert!((e.at(0.2, 0.0)[1] - 1e-5).abs() < 1e-15);
        // After the bins: 5e-5 radial, 1e-5 cos(2π·phase) tangential.
        let late = e.at(0.31, 0.5);
        assert!(
            (late[0] - 5e-5).abs() < 1e-15 && (late[1] + 1e-5).abs() < 1e-15,
            "{late:?}"
        );
        let mut table = TurningOffset::zero([0.0, 0.0], 2.0, 1);
        assert_eq!(table.expected_error(0.05, 0.0, [0.0, 0.01, 0.3]), [0.0; 3]);
        table.expected = Some(e);
        // At the circle's top (θ = 90°) radial is +y.
        let o = table.expected_error(0.02, 0.0, [0.0, 0.01, 0.3]);
        assert!(o[0].abs() < 1e-15 && (o[1] - 1e-4).abs() < 1e-15, "{o:?}");
        assert!(table.check(1.0).is_ok());
        table.expected.as_mut().unwrap().start[1][2] = f64::NAN;
        assert!(table.check(1.0).is_err());
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
