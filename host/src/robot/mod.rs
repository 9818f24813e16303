//! Robot descriptions: the TOML schema of `docs/design.md` §2, its validation, and
//! the quantities the statics derive from it (section properties, stiffness
//! matrices, tendon routing).
//!
//! Every error names the file, the field and the problem, because a user who
//! mistypes one number in a robot file should not have to guess which.

use std::f64::consts::PI;
use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// Path of the default robot, relative to the workspace root.
pub const DEFAULT_ROBOT: &str = "robots/seed-4t.toml";

/// The default robot's file, built into the binary so the main job runs
/// from any directory.
pub const BUILTIN_DEFAULT_TOML: &str = include_str!("../../robots/seed-4t.toml");

/// Largest tendon count a robot file may declare (the one capacity in `tendril_shared`).
pub use tendril_shared::MAX_TENDONS;

/// Largest bend (rad) a robot may reach under its own weight or one tendon's
/// largest pull: one full turn. Beyond it the rod coils through itself, which
/// the model (no contact) cannot describe.
const MAX_BEND_RAD: f64 = 2.0 * PI;
/// Largest axial compression a tendon's largest pull may cause (a fraction
/// of the length).
const MAX_AXIAL_STRAIN: f64 = 0.1;
/// Largest tan of a helical tendon's angle to the backbone (≈ 84°): wound
/// flatter, the tendon pulls around the rod rather than along it.
const MAX_HELIX_WINDING: f64 = 10.0;

/// A robot file that could not be loaded: which file, which field, what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {field}: {problem}", file.display())]
pub struct RobotError {
    /// The file (or `<inline>` for a string).
    pub file: PathBuf,
    /// Dotted path of the offending field (`backbone.radius`, `tendon[2].offset`), or `file`.
    pub field: String,
    /// What is wrong, in words.
    pub problem: String,
}

/// How a tendon runs along the backbone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Routing {
    /// Constant body-frame offset: r(s) = d (cos φ, sin φ, 0).
    Straight,
    /// Helix about the backbone: the position angle grows linearly with s,
    /// `turns` full turns over the reference length.
    Helical {
        /// Turns over the whole length (sign gives the handedness).
        turns: f64,
    },
}

/// One tendon, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct Tendon {
    /// Distance from the backbone axis, m.
    pub offset: f64,
    /// Position angle about +z at s = 0, rad (0 = +x, counter-clockwise).
    pub angle: f64,
    /// Largest tension the motor may apply, N.
    pub max_tension: f64,
    /// Smallest tension the motor keeps (pretension), N; 0 by default.
    pub min_tension: f64,
    /// Arc length where the tendon is anchored, m; the backbone length by
    /// default (`docs/design.md` §2.1).
    pub end: f64,
    /// Routing along the backbone.
    pub routing: Routing,
}

/// A validated robot description.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    /// Robot name from the file.
    pub name: String,
    /// Reference arc length L, m.
    pub length: f64,
    /// Backbone radius r, m (solid circular section).
    pub radius: f64,
    /// Young's modulus E, Pa.
    pub youngs_modulus: f64,
    /// Shear modulus G, Pa.
    pub shear_modulus: f64,
    /// Effective density ρ, kg/m³.
    pub density: f64,
    /// Gravity g in the base frame, m/s².
    pub gravity: Vector3<f64>,
    /// Tendons, tendon 0 first.
    pub tendons: Vec<Tendon>,
    /// Material damping of the dynamic model from the optional `[damping]`
    /// table (None: the dynamics' documented default); the statics never
    /// read it (`docs/design.md` §4.2).
    pub damping: Option<DampingKeys>,
}

/// The optional `[damping]` table: Kelvin–Voigt damping n = Kse (v − e₃) +
/// Bse v_t, m = Kbt u + Bbt u_t of the dynamic model (`docs/design.md` §4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DampingKeys {
    /// `retardation_s = t_r`: B = t_r K, so a mode of angular frequency ω
    /// gets the damping ratio ω t_r / 2.
    Retardation(f64),
    /// `bse = [shear x, shear y, extension]` (N·s) and `bbt = [bending x,
    /// bending y, torsion]` (N·m²·s), the diagonals; a missing one is zero.
    Diagonals {
        /// Bse, N·s.
        bse: [f64; 3],
        /// Bbt, N·m²·s.
        bbt: [f64; 3],
    },
}

// --- the file schema (serde), kept apart from the validated type -------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    name: String,
    backbone: BackboneFile,
    environment: EnvironmentFile,
    #[serde(default)]
    tendon: Vec<TendonFile>,
    damping: Option<DampingFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DampingFile {
    retardation_s: Option<f64>,
    bse: Option<[f64; 3]>,
    bbt: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BackboneFile {
    length: f64,
    radius: f64,
    youngs_modulus: f64,
    shear_modulus: f64,
    density: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentFile {
    gravity: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TendonFile {
    offset: f64,
    angle_deg: f64,
    max_tension: f64,
    min_tension: Option<f64>,
    end: Option<f64>,
    routing: RoutingName,
    helix_turns: Option<f64>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Debug)]
#[serde(rename_all = "lowercase")]
enum RoutingName {
    Straight,
    Helical,
}

impl DampingFile {
    fn validate(&self, v: &Validator<'_>) -> Result<DampingKeys, RobotError> {
        let diagonal = |name: &str, d: Option<[f64; 3]>| -> Result<[f64; 3], RobotError> {
            let d = d.unwrap_or_default();
            for (k, x) in d.iter().enumerate() {
                v.non_negative(&format!("damping.{name}[{k}]"), *x)?;
            }
            Ok(d)
        };
        match (self.retardation_s, self.bse.is_some() || self.bbt.is_some()) {
            (Some(_), true) => Err(v.err(
                "damping",
                "give either retardation_s or the bse/bbt diagonals, not both".into(),
            )),
            (Some(t), false) => Ok(DampingKeys::Retardation(
                v.non_negative("damping.retardation_s", t)?,
            )),
            (None, true) => Ok(DampingKeys::Diagonals {
                bse: diagonal("bse", self.bse)?,
                bbt: diagonal("bbt", self.bbt)?,
            }),
            (None, false) => Err(v.err(
                "damping",
                "an empty [damping] table: give retardation_s or bse/bbt (or drop the table for the default)".into(),
            )),
        }
    }
}

impl Robot {
    /// Load and validate a robot file.
    pub fn load(path: &Path) -> Result<Robot, RobotError> {
        Self::load_with_source(path).map(|(robot, _)| robot)
    }

    /// Load `path`; if it is the default robot path and no such file exists
    /// (run outside the workspace), use the built-in copy. Returns the robot
    /// and the exact bytes it came from (for content hashes).
    pub fn load_with_source(path: &Path) -> Result<(Robot, String), RobotError> {
        if path == Path::new(DEFAULT_ROBOT) && !path.exists() {
            let origin = Path::new("<built-in robots/seed-4t.toml>");
            return Ok((
                Self::from_toml(BUILTIN_DEFAULT_TOML, origin)?,
                BUILTIN_DEFAULT_TOML.to_string(),
            ));
        }
        let text = std::fs::read_to_string(path).map_err(|e| RobotError {
            file: path.to_path_buf(),
            field: "file".into(),
            problem: format!("cannot read: {e}"),
        })?;
        Ok((Self::from_toml(&text, path)?, text))
    }

    /// Parse and validate robot TOML; `origin` names the source in errors.
    pub fn from_toml(text: &str, origin: &Path) -> Result<Robot, RobotError> {
        let raw: RobotFile = toml::from_str(text).map_err(|e| {
            let field = toml_error_field(text, &e);
            RobotError {
                file: origin.to_path_buf(),
                field,
                problem: e.message().trim().to_string(),
            }
        })?;
        let v = Validator { file: origin };
        let b = &raw.backbone;
        let robot = Robot {
            name: raw.name.clone(),
            length: v.positive("backbone.length", b.length)?,
            radius: v.positive("backbone.radius", b.radius)?,
            youngs_modulus: v.positive("backbone.youngs_modulus", b.youngs_modulus)?,
            shear_modulus: v.positive("backbone.shear_modulus", b.shear_modulus)?,
            density: v.non_negative("backbone.density", b.density)?,
            gravity: {
                for (k, g) in raw.environment.gravity.iter().enumerate() {
                    v.finite(&format!("environment.gravity[{k}]"), *g)?;
                }
                Vector3::from(raw.environment.gravity)
            },
            tendons: Vec::new(),
            damping: raw.damping.as_ref().map(|d| d.validate(&v)).transpose()?,
        };
        if raw.name.trim().is_empty() {
            return Err(v.err("name", "must not be empty".into()));
        }
        if raw.tendon.is_empty() || raw.tendon.len() > MAX_TENDONS {
            return Err(v.err(
                "tendon",
                format!(
                    "a robot needs 1 to {MAX_TENDONS} [[tendon]] tables, found {}",
                    raw.tendon.len()
                ),
            ));
        }
        let mut tendons = Vec::with_capacity(raw.tendon.len());
        for (i, t) in raw.tendon.iter().enumerate() {
            let f = |name: &str| format!("tendon[{i}].{name}");
            let offset = v.positive(&f("offset"), t.offset)?;
            if offset >= robot.length {
                return Err(v.err(
                    &f("offset"),
                    format!(
                        "{offset} m must be smaller than the backbone length {} m",
                        robot.length
                    ),
                ));
            }
            let angle_deg = v.finite(&f("angle_deg"), t.angle_deg)?;
            let max_tension = v.positive(&f("max_tension"), t.max_tension)?;
            let min_tension = match t.min_tension {
                None => 0.0,
                Some(x) => {
                    let x = v.non_negative(&f("min_tension"), x)?;
                    if x > max_tension {
                        return Err(v.err(
                            &f("min_tension"),
                            format!("{x} N is above max_tension {max_tension} N"),
                        ));
                    }
                    x
                }
            };
            let end = match t.end {
                None => robot.length,
                Some(x) => {
                    let x = v.positive(&f("end"), x)?;
                    if x > robot.length {
                        return Err(v.err(
                            &f("end"),
                            format!(
                                "{x} m is beyond the backbone length {} m (the anchor must lie on the rod, in (0, L])",
                                robot.length
                            ),
                        ));
                    }
                    x
                }
            };
            let routing = match (t.routing, t.helix_turns) {
                (RoutingName::Straight, None) => Routing::Straight,
                (RoutingName::Straight, Some(_)) => {
                    return Err(v.err(
                        &f("helix_turns"),
                        "only allowed with routing = \"helical\"".into(),
                    ))
                }
                (RoutingName::Helical, Some(turns)) => Routing::Helical {
                    turns: v.finite(&f("helix_turns"), turns)?,
                },
                (RoutingName::Helical, None) => {
                    return Err(v.err(
                        &f("helix_turns"),
                        "required with routing = \"helical\"".into(),
                    ))
                }
            };
            tendons.push(Tendon {
                offset,
                angle: angle_deg.to_radians(),
                max_tension,
                min_tension,
                end,
                routing,
            });
        }
        let robot = Robot { tendons, ..robot };
        robot.check_physical_ranges(&v)?;
        Ok(robot)
    }

    /// Reject robots whose numbers are each finite and positive but together
    /// describe a rod the statics cannot mean: one that coils into more than
    /// a turn under its own weight or a single tendon's largest pull, that a
    /// tendon compresses to a fraction of its length, or a helix wound almost
    /// flat around the backbone. The error names the quantity out of range,
    /// rather than letting the solver report a NaN residual.
    fn check_physical_ranges(&self, v: &Validator<'_>) -> Result<(), RobotError> {
        let ei = self.kbt().x;
        let ea = self.kse().z;
        let weight = self.weight_per_length().norm();
        // Tip slope of a cantilever under its own weight, w L³ / (6 E I).
        let sag = weight * self.length.powi(3) / (6.0 * ei);
        if sag > MAX_BEND_RAD {
            return Err(v.err(
                "environment.gravity",
                format!(
                    "the backbone's weight ({weight:.3e} N/m) would bend it by {sag:.3e} rad, more than a full turn: its bending stiffness E I = {ei:.3e} N m^2 is too small (check backbone.radius, youngs_modulus, density)"
                ),
            ));
        }
        for (i, t) in self.tendons.iter().enumerate() {
            // Constant-curvature bend of the tendon's span at full tension, κ ℓ = τ d ℓ / (E I).
            let bend = t.max_tension * t.offset * t.end / ei;
            if bend > MAX_BEND_RAD {
                return Err(v.err(
                    &format!("tendon[{i}].max_tension"),
                    format!(
                        "{} N would bend the backbone by {bend:.3e} rad, more than a full turn: its bending stiffness E I = {ei:.3e} N m^2 is too small for this tension (check backbone.radius, youngs_modulus)",
                        t.max_tension
                    ),
                ));
            }
            let strain = t.max_tension / ea;
            if strain > MAX_AXIAL_STRAIN {
                return Err(v.err(
                    &format!("tendon[{i}].max_tension"),
                    format!(
                        "{} N would compress the backbone by {:.3e} % (axial stiffness E A = {ea:.3e} N); at most {} % is modelled",
                        t.max_tension,
                        strain * 100.0,
                        MAX_AXIAL_STRAIN * 100.0
                    ),
                ));
            }
            // Helix angle to the backbone axis: tan α = d φ'.
            let winding = t.offset * t.angle_rate(self.length).abs();
            if winding > MAX_HELIX_WINDING {
                let turns = match t.routing {
                    Routing::Helical { turns } => turns,
                    Routing::Straight => 0.0,
                };
                return Err(v.err(
                    &format!("tendon[{i}].helix_turns"),
                    format!(
                        "{turns} turns over {} m wind the tendon at {:.2} degrees to the backbone (pitch {:.3e} m); at most {:.1} degrees (tan = {MAX_HELIX_WINDING}) is modelled",
                        self.length,
                        winding.atan().to_degrees(),
                        self.length / turns.abs(),
                        MAX_HELIX_WINDING.atan().to_degrees()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Number of tendons.
    pub fn n_tendons(&self) -> usize {
        self.tendons.len()
    }

    /// Cross-section area A = π r², m².
    pub fn area(&self) -> f64 {
        PI * self.radius * self.radius
    }

    /// Second moment of area I = π r⁴ / 4, m⁴.
    pub fn second_moment(&self) -> f64 {
        PI * self.radius.powi(4) / 4.0
    }

    /// Shear/extension stiffness Kse = diag(GA, GA, EA), N.
    pub fn kse(&self) -> Vector3<f64> {
        let a = self.area();
        Vector3::new(
            self.shear_modulus * a,
            self.shear_modulus * a,
            self.youngs_modulus * a,
        )
    }

    /// Bending/torsion stiffness Kbt = diag(EI, EI, GJ) with J = 2I, N·m².
    pub fn kbt(&self) -> Vector3<f64> {
        let i = self.second_moment();
        Vector3::new(
            self.youngs_modulus * i,
            self.youngs_modulus * i,
            self.shear_modulus * 2.0 * i,
        )
    }

    /// Distributed weight f_e = ρ A g in the base frame, N/m.
    pub fn weight_per_length(&self) -> Vector3<f64> {
        self.gravity * (self.density * self.area())
    }

    /// Upper tension limits, N, tendon 0 first.
    pub fn max_tensions(&self) -> Vec<f64> {
        self.tendons.iter().map(|t| t.max_tension).collect()
    }

    /// Lower tension limits (pretension floors), N, tendon 0 first.
    pub fn min_tensions(&self) -> Vec<f64> {
        self.tendons.iter().map(|t| t.min_tension).collect()
    }

    /// The same robot with gravity switched off (for closed-form checks).
    pub fn without_gravity(&self) -> Robot {
        Robot {
            gravity: Vector3::zeros(),
            ..self.clone()
        }
    }

    /// Check a tension vector against this robot: right count, finite, within [0, max].
    pub fn check_tensions(&self, tau: &[f64]) -> Result<(), TensionError> {
        if tau.len() != self.n_tendons() {
            return Err(TensionError::Count {
                expected: self.n_tendons(),
                got: tau.len(),
            });
        }
        for (i, (&t, tendon)) in tau.iter().zip(&self.tendons).enumerate() {
            if !t.is_finite() {
                return Err(TensionError::NotFinite { tendon: i });
            }
            if t < 0.0 {
                return Err(TensionError::Negative {
                    tendon: i,
                    value: t,
                });
            }
            if t > tendon.max_tension {
                return Err(TensionError::AboveMax {
                    tendon: i,
                    value: t,
                    max: tendon.max_tension,
                });
            }
        }
        Ok(())
    }
}

impl Tendon {
    /// Rate of change of the position angle along s, rad/m (0 for straight routing).
    fn angle_rate(&self, length: f64) -> f64 {
        match self.routing {
            Routing::Straight => 0.0,
            Routing::Helical { turns } => 2.0 * PI * turns / length,
        }
    }

    /// Body-frame offset r(s) and its derivatives r'(s), r''(s) (m, 1, 1/m).
    pub fn offset_at(&self, s: f64, length: f64) -> TendonOffset {
        let w = self.angle_rate(length);
        let phi = self.angle + w * s;
        let (sn, cs) = phi.sin_cos();
        let d = self.offset;
        TendonOffset {
            r: Vector3::new(d * cs, d * sn, 0.0),
            dr: Vector3::new(-d * w * sn, d * w * cs, 0.0),
            ddr: Vector3::new(-d * w * w * cs, -d * w * w * sn, 0.0),
        }
    }

    /// Whether r(s) is constant (lets the statics skip the routing terms).
    pub fn is_straight(&self) -> bool {
        matches!(self.routing, Routing::Straight)
    }
}

/// A tendon's body-frame offset at one arc length, with its first two derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TendonOffset {
    /// r(s), m.
    pub r: Vector3<f64>,
    /// r'(s).
    pub dr: Vector3<f64>,
    /// r''(s), 1/m.
    pub ddr: Vector3<f64>,
}

/// "1 tendon", "4 tendons": a count with its noun in the right number.
pub fn count(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// Skew-symmetric matrix x̂ with x̂ y = x × y.
pub fn hat(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x.z, x.y, x.z, 0.0, -x.x, -x.y, x.x, 0.0)
}

/// A tension vector that does not fit the robot.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TensionError {
    /// Wrong number of tensions.
    #[error("expected {expected} tensions (one per tendon), got {got}")]
    Count {
        /// Tendons of the robot.
        expected: usize,
        /// Tensions given.
        got: usize,
    },
    /// NaN or infinite.
    #[error("tension of tendon {tendon} is not a finite number")]
    NotFinite {
        /// Tendon index.
        tendon: usize,
    },
    /// Tendons can only pull.
    #[error("tension of tendon {tendon} is negative ({value} N): tendons can only pull")]
    Negative {
        /// Tendon index.
        tendon: usize,
        /// The value given, N.
        value: f64,
    },
    /// Above the motor limit.
    #[error("tension of tendon {tendon} is {value} N, above its max_tension {max} N")]
    AboveMax {
        /// Tendon index.
        tendon: usize,
        /// The value given, N.
        value: f64,
        /// The robot's limit, N.
        max: f64,
    },
}

struct Validator<'a> {
    file: &'a Path,
}

impl Validator<'_> {
    fn err(&self, field: &str, problem: String) -> RobotError {
        RobotError {
            file: self.file.to_path_buf(),
            field: field.to_string(),
            problem,
        }
    }

    fn finite(&self, field: &str, x: f64) -> Result<f64, RobotError> {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.err(field, format!("must be a finite number, got {x}")))
        }
    }

    fn positive(&self, field: &str, x: f64) -> Result<f64, RobotError> {
        let x = self.finite(field, x)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(self.err(field, format!("must be positive, got {x}")))
        }
    }

    fn non_negative(&self, field: &str, x: f64) -> Result<f64, RobotError> {
        let x = self.finite(field, x)?;
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(self.err(field, format!("must not be negative, got {x}")))
        }
    }
}

/// Best-effort dotted name of the field a TOML error points at: the table
/// header governing the error's line (`tendon[2]` for the third
/// `[[tendon]]`) plus the key on that line, or the missing field's name.
fn toml_error_field(text: &str, e: &toml::de::Error) -> String {
    let missing = e
        .message()
        .split("missing field `")
        .nth(1)
        .and_then(|rest| rest.split('`').next());
    let Some(span) = e.span() else {
        return missing.unwrap_or("file").into();
    };
    let start = span.start.min(text.len());
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next().unwrap_or("");
    // The error's own line counts when it is a header: serde points a missing
    // field, and toml an unknown table, at the table's header.
    let mut table = String::new();
    let mut tendon_index = 0usize;
    for l in text[..line_start].lines().chain(std::iter::once(line)) {
        let l = l.trim();
        if l.starts_with("[[tendon]]") {
            table = format!("tendon[{tendon_index}]");
            tendon_index += 1;
        } else if l.starts_with('[') {
            table = l
                .split('#')
                .next()
                .unwrap_or("")
                .trim()
                .trim_matches(|c| c == '[' || c == ']')
                .trim()
                .to_string();
        }
    }
    if let Some(name) = missing {
        // A field missing at the top level is reported at the file start.
        return if span.start == 0 || table.is_empty() {
            name.into()
        } else {
            format!("{table}.{name}")
        };
    }
    let key = line.split('=').next().unwrap_or("").trim();
    let key = if key.starts_with('[') { "" } else { key };
    match (table.is_empty(), key.is_empty()) {
        (true, true) => "file".into(),
        (true, false) => key.into(),
        (false, true) => table,
        (false, false) => format!("{table}.{key}"),
    }
}

impl fmt::Display for Robot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: L = {} m, r = {} m, E = {:.3e} Pa, {}",
            self.name,
            self.length,
            self.radius,
            self.youngs_modulus,
            count(self.n_tendons(), "tendon")
        )
    }
}

/// A robot file of this repository's `robots/` directory, by file name
/// (`"seed-4t.toml"`): the one loader of the repository's robots for the
/// workspace's unit tests, integration tests, benches and examples. It reads
/// from the source tree the crate was built from, so it is for development
/// only; users load robots with [`Robot::load`].
///
/// # Panics
/// When the file is missing or invalid (a test or bench cannot go on).
pub fn repo_robot(file: &str) -> Robot {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../robots")
        .join(file);
    Robot::load(&path).unwrap_or_else(|e| panic!("{file}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workspace_robot(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../robots")
            .join(name)
    }

    const GOOD: &str = r#"
name = "t"
[backbone]
length = 0.4
radius = 0.0009
youngs_modulus = 207e9
shear_modulus = 79.6e9
density = 39317.0
[environment]
gravity = [9.81, 0.0, 0.0]
[[tendon]]
offset = 0.019
angle_deg = 0.0
max_tension = 10.0
routing = "straight"
"#;

    fn parse(text: &str) -> Result<Robot, RobotError> {
        Robot::from_toml(text, Path::new("bad.toml"))
    }

    #[test]
    fn shipped_robots_load() {
        let r4 = Robot::load(&workspace_robot("seed-4t.toml")).unwrap();
        assert_eq!(r4.n_tendons(), 4);
        assert!((r4.tendons[1].angle - PI / 2.0).abs() < 1e-15);
        // Effective linear density 0.1 kg/m (docs/design.md §2).
        assert!((r4.density * r4.area() - 0.1).abs() < 1e-4);
        let r1 = Robot::load(&workspace_robot("seed-1t.toml")).unwrap();
        assert_eq!(r1.n_tendons(), 1);
    }

    #[test]
    fn unknown_key_is_named() {
        let e = parse(&GOOD.replace("density = 39317.0", "densty = 39317.0")).unwrap_err();
        assert_eq!(e.field, "backbone.densty");
        assert!(e.problem.contains("unknown field"), "{e}");
        assert!(e.to_string().starts_with("bad.toml: backbone.densty:"));
    }

    #[test]
    fn missing_fields_are_named() {
        let e = parse("name = \"x\"\n").unwrap_err();
        assert_eq!(e.field, "backbone", "{e}");
        let e = parse(&GOOD.replace("youngs_modulus = 207e9\n", "")).unwrap_err();
        assert_eq!(e.field, "backbone.youngs_modulus", "{e}");
    }

    #[test]
    fn wrong_type_is_named() {
        let e = parse(&GOOD.replace("radius = 0.0009", "radius = \"thin\"")).unwrap_err();
        assert_eq!(e.field, "backbone.radius");
    }

    #[test]
    fn negative_radius_is_rejected() {
        let e = parse(&GOOD.replace("radius = 0.0009", "radius = -0.0009")).unwrap_err();
        assert_eq!(e.field, "backbone.radius");
        assert!(e.problem.contains("positive"));
    }

    #[test]
    fn nan_is_rejected() {
        let e = parse(&GOOD.replace("gravity = [9.81", "gravity = [nan")).unwrap_err();
        assert_eq!(e.field, "environment.gravity[0]");
        let e = parse(&GOOD.replace("max_tension = 10.0", "max_tension = inf")).unwrap_err();
        assert_eq!(e.field, "tendon[0].max_tension");
    }

    #[test]
    fn zero_tendons_is_rejected() {
        let text = GOOD.split("[[tendon]]").next().unwrap();
        let e = parse(text).unwrap_err();
        assert_eq!(e.field, "tendon");
    }

    #[test]
    fn offset_longer_than_rod_is_rejected() {
        let e = parse(&GOOD.replace("offset = 0.019", "offset = 0.5")).unwrap_err();
        assert_eq!(e.field, "tendon[0].offset");
    }

    #[test]
    fn helical_routing_needs_turns() {
        let e = parse(&GOOD.replace("\"straight\"", "\"helical\"")).unwrap_err();
        assert_eq!(e.field, "tendon[0].helix_turns");
        let r = parse(&GOOD.replace("\"straight\"", "\"helical\"\nhelix_turns = 0.5")).unwrap();
        assert_eq!(r.tendons[0].routing, Routing::Helical { turns: 0.5 });
        // Helix: r(L) has turned by half a turn.
        let o = r.tendons[0].offset_at(r.length, r.length);
        assert!((o.r.x + 0.019).abs() < 1e-12 && o.r.y.abs() < 1e-12);
    }

    #[test]
    fn tension_vectors_are_checked() {
        let r = parse(GOOD).unwrap();
        assert!(r.check_tensions(&[2.0]).is_ok());
        assert!(matches!(
            r.check_tensions(&[1.0, 2.0]),
            Err(TensionError::Count { .. })
        ));
        assert!(matches!(
            r.check_tensions(&[-1.0]),
            Err(TensionError::Negative { .. })
        ));
        assert!(matches!(
            r.check_tensions(&[f64::NAN]),
            Err(TensionError::NotFinite { .. })
        ));
        assert!(matches!(
            r.check_tensions(&[11.0]),
            Err(TensionError::AboveMax { .. })
        ));
    }

    #[test]
    fn end_and_min_tension_default_to_tip_and_zero() {
        let r = parse(GOOD).unwrap();
        assert_eq!(r.tendons[0].end, r.length);
        assert_eq!(r.tendons[0].min_tension, 0.0);
        let r = parse(&GOOD.replace(
            "max_tension = 10.0",
            "max_tension = 10.0\nmin_tension = 2.5\nend = 0.25",
        ))
        .unwrap();
        assert_eq!(r.tendons[0].end, 0.25);
        assert_eq!(r.tendons[0].min_tension, 2.5);
        assert_eq!(r.min_tensions(), vec![2.5]);
    }

    #[test]
    fn bad_end_and_min_tension_are_named() {
        let with = |extra: &str| {
            parse(&GOOD.replace(
                "max_tension = 10.0",
                &format!("max_tension = 10.0\n{extra}"),
            ))
            .unwrap_err()
        };
        for (extra, field, words) in [
            ("end = 0.0", "tendon[0].end", "positive"),
            ("end = -0.1", "tendon[0].end", "positive"),
            ("end = 0.41", "tendon[0].end", "beyond the backbone length"),
            ("end = nan", "tendon[0].end", "finite"),
            ("min_tension = -1.0", "tendon[0].min_tension", "negative"),
            (
                "min_tension = 11.0",
                "tendon[0].min_tension",
                "above max_tension",
            ),
            ("min_tension = inf", "tendon[0].min_tension", "finite"),
        ] {
            let e = with(extra);
            assert_eq!(e.field, field, "{extra}: {e}");
            assert!(e.problem.contains(words), "{extra}: {e}");
            assert!(e.to_string().starts_with("bad.toml: "), "{e}");
        }
    }

    #[test]
    fn missing_max_tension_names_the_tendon() {
        let two = format!("{GOOD}{}", &GOOD[GOOD.find("[[tendon]]").unwrap()..]);
        let text = two.replacen("max_tension = 10.0\n", "", 2);
        let text = format!(
            "{}max_tension = 10.0\n{}",
            &text[..text.find("routing").unwrap()],
            &text[text.find("routing").unwrap()..]
        );
        // Tendon 0 keeps its max_tension, tendon 1 has none.
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "tendon[1].max_tension", "{e}");
        assert!(e.problem.contains("missing field"), "{e}");
    }

    #[test]
    fn unknown_table_after_the_tendons_is_named_itself() {
        let e = parse(&format!("{GOOD}\n[extra]\nfoo = 1\n")).unwrap_err();
        assert_eq!(e.field, "extra", "{e}");
        assert!(e.problem.contains("unknown field"), "{e}");
    }

    #[test]
    fn absurd_robots_name_the_physical_quantity() {
        let e = parse(&GOOD.replace("radius = 0.0009", "radius = 1e-6")).unwrap_err();
        assert_eq!(e.field, "environment.gravity", "{e}");
        assert!(e.problem.contains("bending stiffness"), "{e}");
        let weightless = GOOD.replace("[9.81, 0.0, 0.0]", "[0.0, 0.0, 0.0]");
        let e = parse(&weightless.replace("radius = 0.0009", "radius = 1e-6")).unwrap_err();
        assert_eq!(e.field, "tendon[0].max_tension", "{e}");
        assert!(e.problem.contains("bend the backbone"), "{e}");
        let e = parse(&GOOD.replace("max_tension = 10.0", "max_tension = 1e6")).unwrap_err();
        assert_eq!(e.field, "tendon[0].max_tension", "{e}");
        assert!(e.problem.contains("full turn"), "{e}");
        let e = parse(&GOOD.replace("\"straight\"", "\"helical\"\nhelix_turns = 1e6")).unwrap_err();
        assert_eq!(e.field, "tendon[0].helix_turns", "{e}");
        assert!(e.problem.contains("degrees to the backbone"), "{e}");
        // A thick rod pulled close to its axis: hardly bent, but squashed by 15 %.
        let e = parse(
            &weightless
                .replace("radius = 0.0009", "radius = 0.01")
                .replace("offset = 0.019", "offset = 0.001")
                .replace("max_tension = 10.0", "max_tension = 1e7"),
        )
        .unwrap_err();
        assert_eq!(e.field, "tendon[0].max_tension", "{e}");
        assert!(e.problem.contains("compress"), "{e}");
    }

    #[test]
    fn robot_summary_counts_tendons_in_the_right_number() {
        let r = parse(GOOD).unwrap();
        assert!(r.to_string().ends_with("1 tendon"), "{r}");
        assert_eq!(count(4, "tendon"), "4 tendons");
    }

    #[test]
    fn damping_keys_are_optional_and_validated() {
        assert_eq!(parse(GOOD).unwrap().damping, None);
        let with = |table: &str| parse(&format!("{GOOD}[damping]\n{table}\n"));
        assert_eq!(
            with("retardation_s = 0.01").unwrap().damping,
            Some(DampingKeys::Retardation(0.01))
        );
        // A missing diagonal is zero.
        assert_eq!(
            with("bbt = [5e-4, 5e-4, 5e-4]").unwrap().damping,
            Some(DampingKeys::Diagonals {
                bse: [0.0; 3],
                bbt: [5e-4; 3]
            })
        );
        for (table, field) in [
            ("bbt = [5e-4, -1.0, 5e-4]", "damping.bbt[1]"),
            ("bse = [0.0, 0.0, nan]", "damping.bse[2]"),
            ("retardation_s = -0.002", "damping.retardation_s"),
            ("retardation_s = 0.01\nbbt = [1e-4, 1e-4, 1e-4]", "damping"),
            ("", "damping"),
            ("retardation = 0.01", "damping.retardation"),
        ] {
            let e = with(table).unwrap_err();
            assert_eq!(e.field, field, "{table:?}: {e}");
        }
    }

    #[test]
    fn damping_keys_leave_the_statics_bit_identical() {
        // The statics never read `[damping]`: the same tip to the last bit.
        let plain = parse(GOOD).unwrap();
        let damped = parse(&format!("{GOOD}[damping]\nretardation_s = 0.05\n")).unwrap();
        let tip = |robot: &Robot| {
            crate::statics::Statics::new(robot, crate::statics::SolverSettings::default())
                .solve(&[3.0], None)
                .unwrap()
                .position
        };
        assert_eq!(tip(&plain), tip(&damped));
    }

    #[test]
    fn hat_is_cross_product() {
        let a = Vector3::new(1.0, -2.0, 0.5);
        let b = Vector3::new(0.3, 0.7, -1.1);
        assert!((hat(&a) * b - a.cross(&b)).norm() < 1e-15);
    }
}
