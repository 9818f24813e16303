//! The plant's reality (docs/design.md §6.2): how the robot on the bench
//! differs from its robot file, and how it is seen. A reality file changes
//! only the *plant*: the planner, the exact IK and the net keep using the
//! robot file, as they would on a real robot whose true parameters nobody
//! knows.
//!
//! A reality says, each part optional (absent = the ideal plant's value):
//! - `[robot]`: scale factors on E, G, the density and the length; each
//!   tendon's offset and angle off by given amounts, or by amounts drawn up
//!   to a bound from a seed (so one file fits any robot); the base's pose
//!   in the tracker's frame off the file's `[base]`;
//! - `[friction]`: the capstan friction of the tendons in their guides
//!   (docs/design.md §2.3);
//! - `[motors]`: the time constant, a dead band and backlash;
//! - `[tracker]`: rate, latency and its jitter, position and orientation
//!   jitter, dropouts ([`tracker`]);
//! - `[dynamics]`: quasi-static, or the dynamic rod with the damping ratio
//!   of its first bending mode.
//!
//! Files are validated like robot files: every error names the file, the
//! field and the problem. The built-in realities (`robots/realities/`) are
//! compiled in, so `--reality everything` works from any directory.

pub mod tracker;

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::robot::Robot;
pub use tracker::{Frame, Tracker, TrackerSpec};

/// A reality file that could not be loaded: which file, which field, what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {field}: {problem}", file.display())]
pub struct RealityError {
    /// The file (or `<built-in NAME>`).
    pub file: PathBuf,
    /// Dotted path of the offending field (`tracker.rate_hz`), or `file`.
    pub field: String,
    /// What is wrong, in words.
    pub problem: String,
}

/// The built-in realities: (name, file contents), in the order the
/// robustness table lists them.
pub const BUILTIN: &[(&str, &str)] = &[
    (
        "ideal",
        include_str!("../../../../robots/realities/ideal.toml"),
    ),
    (
        "em-tracker",
        include_str!("../../../../robots/realities/em-tracker.toml"),
    ),
    (
        "optical-tracker",
        include_str!("../../../../robots/realities/optical-tracker.toml"),
    ),
    (
        "stiffer-10pct",
        include_str!("../../../../robots/realities/stiffer-10pct.toml"),
    ),
    (
        "softer-10pct",
        include_str!("../../../../robots/realities/softer-10pct.toml"),
    ),
    (
        "geometry",
        include_str!("../../../../robots/realities/geometry.toml"),
    ),
    (
        "friction",
        include_str!("../../../../robots/realities/friction.toml"),
    ),
    (
        "dynamic-light-damping",
        include_str!("../../../../robots/realities/dynamic-light-damping.toml"),
    ),
    (
        "everything",
        include_str!("../../../../robots/realities/everything.toml"),
    ),
];

/// How the real robot differs from its file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotChanges {
    /// Factor on Young's modulus E.
    pub youngs_modulus_scale: Option<f64>,
    /// Factor on the shear modulus G.
    pub shear_modulus_scale: Option<f64>,
    /// Factor on the effective density ρ.
    pub density_scale: Option<f64>,
    /// Factor on the length L (and every anchor's arc length).
    pub length_scale: Option<f64>,
    /// Each tendon's offset error, mm (one entry per tendon).
    pub tendon_offset_delta_mm: Option<Vec<f64>>,
    /// Each tendon's angle error, degrees (one entry per tendon).
    pub tendon_angle_delta_deg: Option<Vec<f64>>,
    /// Offset errors drawn uniformly in ±this, mm, from `seed` (for any robot).
    pub tendon_offset_error_mm: Option<f64>,
    /// Angle errors drawn uniformly in ±this, degrees, from `seed`.
    pub tendon_angle_error_deg: Option<f64>,
    /// Seed of the drawn errors.
    pub seed: Option<u64>,
    /// Where the base really is in the tracker's frame, against the file's
    /// `[base]`: added to its translation, mm (`docs/design.md` §2.4).
    pub base_translation_delta_mm: Option<[f64; 3]>,
    /// ... and added to its rotation vector, mrad.
    pub base_rotation_delta_mrad: Option<[f64; 3]>,
}

/// Capstan friction of the tendons in their guides (docs/design.md §2.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionSpec {
    /// Friction coefficient μ: T(s) = T₀ e^(−μ θ(s)).
    pub mu: f64,
    /// Motor tension change that reverses the friction after the tendon
    /// changes direction, N (the stick zone of the hysteresis).
    #[serde(default = "default_reversal_n")]
    pub reversal_n: f64,
}

fn default_reversal_n() -> f64 {
    0.05
}

/// The motors.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotorSpec {
    /// Time constant, ms (absent: the plant's `--motor-tau-ms`).
    pub time_constant_ms: Option<f64>,
    /// Dead band, N: a motor ignores a command within this of what it
    /// holds (static friction in the drive), then moves to it.
    pub dead_band_n: f64,
    /// Backlash, N: on a reversal the tension stays until the command has
    /// moved back by this (play in the drive).
    pub backlash_n: f64,
}

/// How the plant moves.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamicsSpec {
    /// `quasi-static` or `dynamic`.
    pub model: crate::plant::RobotModel,
    /// Damping ratio of the first bending mode ζ₁ (dynamic only; absent:
    /// the robot file's damping or the default).
    pub damping_ratio: Option<f64>,
}

/// A reality file as written (serde): every part optional.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reality {
    /// Name (the file stem of a built-in).
    pub name: String,
    /// One line saying what it models.
    #[serde(default)]
    pub description: String,
    /// The robot's differences from its file.
    #[serde(default)]
    pub robot: RobotChanges,
    /// Tendon friction.
    pub friction: Option<FrictionSpec>,
    /// The motors.
    pub motors: Option<MotorSpec>,
    /// The tracker.
    pub tracker: Option<TrackerSpec>,
    /// The plant's dynamics.
    pub dynamics: Option<DynamicsSpec>,
}

/// Largest relative change of a material or length parameter a reality may
/// make (a factor in [1/2, 2]): beyond that it is another robot, not a
/// tolerance.
const MAX_SCALE: f64 = 2.0;

impl Reality {
    /// A built-in reality by name.
    pub fn builtin(name: &str) -> Option<Reality> {
        let (_, text) = BUILTIN.iter().find(|(n, _)| *n == name)?;
        // The built-ins are checked by a test; a broken one is a bug.
        Reality::from_toml(text, Path::new(&format!("<built-in {name}>"))).ok()
    }

    /// Load `spec`: a path to a reality file, or the name of a built-in
    /// (`everything`) when no such file exists.
    pub fn load(spec: &Path) -> Result<Reality, RealityError> {
        if !spec.exists() {
            if let Some(name) = spec.to_str() {
                if let Some((n, text)) = BUILTIN.iter().find(|(n, _)| *n == name) {
                    return Reality::from_toml(text, Path::new(&format!("<built-in {n}>")));
                }
            }
        }
        let err = |problem: String| RealityError {
            file: spec.to_path_buf(),
            field: "file".into(),
            problem,
        };
        let bytes = crate::fsutil::read_capped(spec, 1 << 20).map_err(|e| {
            let names: Vec<&str> = BUILTIN.iter().map(|(n, _)| *n).collect();
            err(format!(
                "cannot read ({e}); the built-in realities are {}",
                names.join(", ")
            ))
        })?;
        let text = String::from_utf8(bytes).map_err(|e| err(format!("not UTF-8 text ({e})")))?;
        Reality::from_toml(&text, spec)
    }

    /// Parse and validate reality TOML; `origin` names the source in errors.
    pub fn from_toml(text: &str, origin: &Path) -> Result<Reality, RealityError> {
        let r: Reality = toml::from_str(text).map_err(|e| RealityError {
            file: origin.to_path_buf(),
            field: crate::robot::file::toml_error_field(text, &e),
            problem: e.message().trim().to_string(),
        })?;
        r.validate(origin)?;
        Ok(r)
    }

    fn validate(&self, origin: &Path) -> Result<(), RealityError> {
        let err = |field: &str, problem: String| RealityError {
            file: origin.to_path_buf(),
            field: field.into(),
            problem,
        };
        let within = |field: &str, v: Option<f64>, lo: f64, hi: f64, want: &str| match v {
            Some(x) if !(x.is_finite() && x >= lo && x <= hi) => {
                Err(err(field, format!("{x}: must be {want}")))
            }
            _ => Ok(()),
        };
        // The name becomes a directory of `tendril robustness --out`: one
        // plain file name, never a path out of it.
        if let Err(problem) = crate::fsutil::check_plain_name(&self.name) {
            return Err(err("name", problem));
        }
        let r = &self.robot;
        let scale = "a factor in [0.5, 2]";
        let lo = 1.0 / MAX_SCALE;
        within(
            "robot.youngs_modulus_scale",
            r.youngs_modulus_scale,
            lo,
            MAX_SCALE,
            scale,
        )?;
        within(
            "robot.shear_modulus_scale",
            r.shear_modulus_scale,
            lo,
            MAX_SCALE,
            scale,
        )?;
        within("robot.density_scale", r.density_scale, lo, MAX_SCALE, scale)?;
        within("robot.length_scale", r.length_scale, lo, MAX_SCALE, scale)?;
        within(
            "robot.tendon_offset_error_mm",
            r.tendon_offset_error_mm,
            0.0,
            5.0,
            "a bound in [0, 5] mm",
        )?;
        within(
            "robot.tendon_angle_error_deg",
            r.tendon_angle_error_deg,
            0.0,
            30.0,
            "a bound in [0, 30] degrees",
        )?;
        for (field, list, bound) in [
            (
                "robot.tendon_offset_delta_mm",
                &r.tendon_offset_delta_mm,
                5.0,
            ),
            (
                "robot.tendon_angle_delta_deg",
                &r.tendon_angle_delta_deg,
                30.0,
            ),
        ] {
            for (k, &x) in list.iter().flatten().enumerate() {
                if !(x.is_finite() && x.abs() <= bound) {
                    return Err(err(
                        &format!("{field}[{k}]"),
                        format!("{x}: must be within ±{bound}"),
                    ));
                }
            }
        }
        for (field, v, bound) in [
            (
                "robot.base_translation_delta_mm",
                r.base_translation_delta_mm,
                1000.0,
            ),
            (
                "robot.base_rotation_delta_mrad",
                r.base_rotation_delta_mrad,
                200.0,
            ),
        ] {
            for (k, &x) in v.iter().flatten().enumerate() {
                if !(x.is_finite() && x.abs() <= bound) {
                    return Err(err(
                        &format!("{field}[{k}]"),
                        format!("{x}: must be within ±{bound}"),
                    ));
                }
            }
        }
        if r.tendon_offset_delta_mm.is_some() && r.tendon_offset_error_mm.is_some() {
            return Err(err(
                "robot.tendon_offset_error_mm",
                "give the offsets' errors as a list or as a bound, not both".into(),
            ));
        }
        if r.tendon_angle_delta_deg.is_some() && r.tendon_angle_error_deg.is_some() {
            return Err(err(
                "robot.tendon_angle_error_deg",
                "give the angles' errors as a list or as a bound, not both".into(),
            ));
        }
        if let Some(f) = &self.friction {
            within("friction.mu", Some(f.mu), 0.0, 1.0, "in [0, 1]")?;
            within(
                "friction.reversal_n",
                Some(f.reversal_n),
                1e-6,
                10.0,
                "a tension in (0, 10] N",
            )?;
        }
        if let Some(m) = &self.motors {
            within(
                "motors.time_constant_ms",
                m.time_constant_ms,
                0.1,
                1000.0,
                "in [0.1, 1000] ms",
            )?;
            within(
                "motors.dead_band_n",
                Some(m.dead_band_n),
                0.0,
                1.0,
                "in [0, 1] N",
            )?;
            within(
                "motors.backlash_n",
                Some(m.backlash_n),
                0.0,
                1.0,
                "in [0, 1] N",
            )?;
        }
        if let Some(t) = &self.tracker {
            t.validate()
                .map_err(|(f, p)| err(&format!("tracker.{f}"), p))?;
        }
        if let Some(d) = &self.dynamics {
            within(
                "dynamics.damping_ratio",
                d.damping_ratio,
                1e-3,
                1.0,
                "in [0.001, 1]",
            )?;
        }
        Ok(())
    }

    /// The material damping of the real robot `real` (from
    /// [`Reality::real_robot`]): stiffness-proportional with the first
    /// mode's ζ₁ when `[dynamics] damping_ratio` says so (B = t_r K gives
    /// mode k the ratio ζ_k = ω_k t_r / 2, so t_r = 2ζ₁/ω₁ with the
    /// Euler–Bernoulli ω₁), else the robot file's.
    pub fn damping(&self, real: &Robot) -> crate::dynamics::Damping {
        use crate::dynamics::Damping;
        match self.dynamics.and_then(|d| d.damping_ratio) {
            Some(zeta) => Damping::proportional(
                real,
                2.0 * zeta / crate::robot::first_bending_mode_rad_s(real),
            ),
            None => Damping::of_robot(real),
        }
    }

    /// The real robot: `nominal` changed as this reality says. Errors when a
    /// per-tendon list does not have one entry per tendon, or when the
    /// changed robot is not a valid robot (an offset past the backbone).
    pub fn real_robot(&self, nominal: &Robot) -> Result<Robot, String> {
        let r = &self.robot;
        let mut robot = nominal.clone();
        robot.youngs_modulus *= r.youngs_modulus_scale.unwrap_or(1.0);
        robot.shear_modulus *= r.shear_modulus_scale.unwrap_or(1.0);
        robot.density *= r.density_scale.unwrap_or(1.0);
        let ls = r.length_scale.unwrap_or(1.0);
        robot.length *= ls;
        let n = robot.n_tendons();
        let mut rng = ChaCha8Rng::seed_from_u64(r.seed.unwrap_or(1));
        let mut draw = |bound: f64| bound * (2.0 * rng.random::<f64>() - 1.0);
        let deltas = |list: &Option<Vec<f64>>, field: &str| -> Result<Option<Vec<f64>>, String> {
            match list {
                Some(v) if v.len() != n => Err(format!(
                    "{field} has {} entries but the robot has {n} tendons",
                    v.len()
                )),
                other => Ok(other.clone()),
            }
        };
        let offsets = deltas(&r.tendon_offset_delta_mm, "robot.tendon_offset_delta_mm")?;
        let angles = deltas(&r.tendon_angle_delta_deg, "robot.tendon_angle_delta_deg")?;
        for (k, t) in robot.tendons.iter_mut().enumerate() {
            t.end *= ls;
            let d_mm = match (&offsets, r.tendon_offset_error_mm) {
                (Some(v), _) => v[k],
                (None, Some(b)) => draw(b),
                (None, None) => 0.0,
            };
            let d_deg = match (&angles, r.tendon_angle_error_deg) {
                (Some(v), _) => v[k],
                (None, Some(b)) => draw(b),
                (None, None) => 0.0,
            };
            t.offset += d_mm * 1e-3;
            t.angle += d_deg.to_radians();
            if !(t.offset > 0.0 && t.offset < robot.length) {
                return Err(format!(
                    "tendon {k}'s offset becomes {:.3} mm, outside the backbone",
                    t.offset * 1e3
                ));
            }
        }
        let (dt, dr) = (
            r.base_translation_delta_mm.unwrap_or_default(),
            r.base_rotation_delta_mrad.unwrap_or_default(),
        );
        for k in 0..3 {
            robot.base.translation[k] += dt[k] * 1e-3;
            robot.base.rotation[k] += dr[k] * 1e-3;
        }
        Ok(robot)
    }

    /// One line for reports: what this reality changes.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        let r = &self.robot;
        for (what, v) in [
            ("E", r.youngs_modulus_scale),
            ("G", r.shear_modulus_scale),
            ("ρ", r.density_scale),
            ("L", r.length_scale),
        ] {
            if let Some(s) = v {
                parts.push(format!("{what} ×{s}"));
            }
        }
        if let Some(b) = r.tendon_offset_error_mm {
            parts.push(format!("offsets ±{b} mm"));
        }
        if let Some(b) = r.tendon_angle_error_deg {
            parts.push(format!("angles ±{b}°"));
        }
        if r.tendon_offset_delta_mm.is_some() || r.tendon_angle_delta_deg.is_some() {
            parts.push("tendon geometry off".into());
        }
        if r.base_translation_delta_mm.is_some() || r.base_rotation_delta_mrad.is_some() {
            parts.push("tracker frame off".into());
        }
        if let Some(f) = &self.friction {
            parts.push(format!("friction μ {}", f.mu));
        }
        if let Some(m) = &self.motors {
            if m.dead_band_n > 0.0 {
                parts.push(format!("dead band {} N", m.dead_band_n));
            }
            if m.backlash_n > 0.0 {
                parts.push(format!("backlash {} N", m.backlash_n));
            }
        }
        if let Some(t) = &self.tracker {
            parts.push(t.summary());
        }
        if let Some(d) = &self.dynamics {
            match d.damping_ratio {
                Some(z) => parts.push(format!("{:?} ζ₁ {z}", d.model)),
                None => parts.push(format!("{:?}", d.model)),
            }
        }
        if parts.is_empty() {
            "the robot file, an ideal tracker".into()
        } else {
            parts.join(", ")
        }
    }
}

#[cfg(test)]
mod tests;
