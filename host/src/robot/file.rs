//! The robot file: its TOML schema (`docs/design.md` §2), kept apart from the
//! validated [`Robot`], and the validator that turns one into the other.
//!
//! Every error names the file, the field and the problem, because a user who
//! mistypes one number in a robot file should not have to guess which.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::Deserialize;

use super::base_pose::MAX_BASE_TRANSLATION_M;
use super::{BasePose, DampingKeys, Robot, Routing, Tendon, MAX_TENDONS};

/// Path of the default robot, relative to the workspace root.
pub const DEFAULT_ROBOT: &str = "robots/seed-4t.toml";

/// The default robot's file, built into the binary so the main job runs
/// from any directory.
pub const BUILTIN_DEFAULT_TOML: &str = include_str!("../../../robots/seed-4t.toml");

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
    base: Option<BaseFile>,
}

/// `[base]`: the base's pose in the tracker's frame (`docs/design.md` §2.4).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BaseFile {
    #[serde(default)]
    translation: [f64; 3],
    #[serde(default)]
    rotation: [f64; 3],
}

impl BaseFile {
    fn validate(&self, v: &Validator<'_>) -> Result<BasePose, RobotError> {
        for (k, x) in self.translation.iter().enumerate() {
            v.finite(&format!("base.translation[{k}]"), *x)?;
        }
        for (k, x) in self.rotation.iter().enumerate() {
            v.finite(&format!("base.rotation[{k}]"), *x)?;
        }
        let norm = |a: &[f64; 3]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm(&self.translation) > MAX_BASE_TRANSLATION_M {
            return Err(v.err(
                "base.translation",
                format!(
                    "the base is {:.3} m from the tracker's origin: at most {MAX_BASE_TRANSLATION_M} m (metres, not millimetres)",
                    norm(&self.translation)
                ),
            ));
        }
        if norm(&self.rotation) > PI {
            return Err(v.err(
                "base.rotation",
                format!(
                    "a rotation vector of {:.3} rad: at most π (axis × angle, radians, not degrees)",
                    norm(&self.rotation)
                ),
            ));
        }
        Ok(BasePose {
            translation: self.translation,
            rotation: self.rotation,
        })
    }
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

/// Largest robot file read: the largest robot in `robots/` is a few KiB.
pub const MAX_ROBOT_FILE_BYTES: u64 = 1 << 20;

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
        let cannot_read = |problem: String| RobotError {
            file: path.to_path_buf(),
            field: "file".into(),
            problem: format!("cannot read: {problem}"),
        };
        // A robot file is a page of TOML: an endless or huge input is refused
        // before it is read whole (issue 31: `--robot /dev/zero`).
        let bytes = crate::fsutil::read_capped(path, MAX_ROBOT_FILE_BYTES)
            .map_err(|e| cannot_read(e.to_string()))?;
        let text =
            String::from_utf8(bytes).map_err(|e| cannot_read(format!("not UTF-8 text ({e})")))?;
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
            base: match &raw.base {
                Some(b) => b.validate(&v)?,
                None => BasePose::IDENTITY,
            },
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
pub(crate) fn toml_error_field(text: &str, e: &toml::de::Error) -> String {
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

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A valid one-tendon robot the tests edit one key at a time.
    pub(in crate::robot) const GOOD: &str = r#"
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

    pub(in crate::robot) fn parse(text: &str) -> Result<Robot, RobotError> {
        Robot::from_toml(text, Path::new("bad.toml"))
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
}
