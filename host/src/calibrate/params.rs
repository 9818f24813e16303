//! The parameters a calibration may fit (`--fit LIST`), their values, the
//! bounds that keep the rod physical, and the robot a set of values stands
//! for (`docs/design.md` §11).

use std::f64::consts::PI;
use std::fmt;

use crate::robot::Robot;

/// Largest and smallest tension scale (sensor gain) a fit may reach.
pub const TENSION_SCALE_BOUNDS: (f64, f64) = (0.5, 2.0);
/// Moduli, offsets and density stay within this factor of the nominal file.
const FACTOR_BOUND: f64 = 5.0;
/// The length stays within ±50 % of the nominal.
const LENGTH_BOUND: f64 = 0.5;
/// A tendon's angle stays within ±30° of the nominal.
const ANGLE_BOUND_RAD: f64 = PI / 6.0;
/// The robot's base is within 5 m of the tracker's origin, the bound a
/// robot file's `[base]` has too. (A 50 mm bound made a tracker 200 mm
/// away look like a bent rod: E at a third of its value, issue 47; the
/// translation enters the tips linearly, so Levenberg–Marquardt reaches it
/// from zero once nothing stops it.)
const BASE_TRANSLATION_BOUND_M: f64 = crate::robot::base_pose::MAX_BASE_TRANSLATION_M;
/// The base turns by at most 0.2 rad (≈ 11°) from the file's `[base]`: a
/// small rotation.
const BASE_ROTATION_BOUND_RAD: f64 = 0.2;

/// One fitted quantity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Param {
    /// Young's modulus E, Pa.
    YoungsModulus,
    /// Shear modulus G, Pa.
    ShearModulus,
    /// Effective density ρ, kg/m³.
    Density,
    /// Reference length L, m.
    Length,
    /// Tendon i's offset d_i, m.
    Offset(usize),
    /// Tendon i's angle φ_i, rad.
    Angle(usize),
    /// Tendon i's tension scale s_i (true tension = s_i × recorded tension).
    TensionScale(usize),
    /// Component k of the tracker-frame translation of the base, m.
    BaseTranslation(usize),
    /// Component k of the tracker-frame rotation vector of the base, rad.
    BaseRotation(usize),
}

impl Param {
    /// Whether changing it changes the rod (a new statics solve), rather
    /// than only the frame the tip is seen in.
    pub fn moves_rod(&self) -> bool {
        !matches!(self, Param::BaseTranslation(_) | Param::BaseRotation(_))
    }

    /// Order in which an unidentifiable direction's parameters are fixed
    /// when they weigh alike: the modulus first, because fixing it makes
    /// every d_i/E and ρ/E combination a single number (`docs/design.md` §11).
    pub fn fix_priority(&self) -> usize {
        match self {
            Param::YoungsModulus => 0,
            Param::ShearModulus => 1,
            Param::TensionScale(_) => 2,
            Param::Density => 3,
            Param::Offset(_) => 4,
            Param::Length => 5,
            Param::Angle(_) => 6,
            Param::BaseRotation(_) => 7,
            Param::BaseTranslation(_) => 8,
        }
    }

    /// The unit the value is reported in.
    pub fn unit(&self) -> &'static str {
        match self {
            Param::YoungsModulus | Param::ShearModulus => "Pa",
            Param::Density => "kg/m³",
            Param::Length | Param::Offset(_) | Param::BaseTranslation(_) => "m",
            Param::Angle(_) | Param::BaseRotation(_) => "rad",
            Param::TensionScale(_) => "1",
        }
    }
}

impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const AXIS: [&str; 3] = ["x", "y", "z"];
        match self {
            Param::YoungsModulus => write!(f, "E"),
            Param::ShearModulus => write!(f, "G"),
            Param::Density => write!(f, "density"),
            Param::Length => write!(f, "length"),
            Param::Offset(i) => write!(f, "offset[{i}]"),
            Param::Angle(i) => write!(f, "angle[{i}]"),
            Param::TensionScale(i) => write!(f, "tension_scale[{i}]"),
            Param::BaseTranslation(k) => write!(f, "base_t{}", AXIS[*k]),
            Param::BaseRotation(k) => write!(f, "base_r{}", AXIS[*k]),
        }
    }
}

/// Parse `--fit E,G,density,length,offsets,angles,tension_scale,base` for a
/// robot of `n_tendons`: `offsets`, `angles`, `tension_scale` expand to one
/// parameter per tendon (or name one: `offset2`), `base` to the translation
/// and the small rotation (`base_t`, `base_r` for one of them).
pub fn parse_fit_list(list: &str, n_tendons: usize) -> Result<Vec<Param>, String> {
    let mut out = Vec::new();
    let per_tendon = |name: &str, prefix: &str| -> Option<Option<usize>> {
        let rest = name.strip_prefix(prefix)?;
        if rest.is_empty() || rest == "s" {
            Some(None)
        } else {
            rest.parse().ok().map(Some)
        }
    };
    for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let lower = item.to_ascii_lowercase();
        let mut push_tendons = |make: fn(usize) -> Param, one: Option<usize>| match one {
            Some(i) if i >= n_tendons => Err(format!(
                "--fit {item}: the robot has {}",
                crate::robot::count(n_tendons, "tendon")
            )),
            Some(i) => {
                out.push(make(i));
                Ok(())
            }
            None => {
                out.extend((0..n_tendons).map(make));
                Ok(())
            }
        };
        match lower.as_str() {
            "e" | "youngs_modulus" => out.push(Param::YoungsModulus),
            "g" | "shear_modulus" => out.push(Param::ShearModulus),
            "density" | "rho" => out.push(Param::Density),
            "length" | "l" => out.push(Param::Length),
            "base" => out.extend(
                (0..3)
                    .map(Param::BaseTranslation)
                    .chain((0..3).map(Param::BaseRotation)),
            ),
            "base_t" => out.extend((0..3).map(Param::BaseTranslation)),
            "base_r" => out.extend((0..3).map(Param::BaseRotation)),
            s => {
                if let Some(one) = per_tendon(s, "tension_scale") {
                    push_tendons(Param::TensionScale, one)?
                } else if let Some(one) = per_tendon(s, "offset") {
                    push_tendons(Param::Offset, one)?
                } else if let Some(one) = per_tendon(s, "angle") {
                    push_tendons(Param::Angle, one)?
                } else {
                    return Err(format!(
                        "--fit: unknown parameter {item:?} (known: E, G, density, length, \
                         offsets, angles, tension_scale, base, base_t, base_r; offset2 etc. \
                         for one tendon)"
                    ));
                }
            }
        }
    }
    out.sort();
    out.dedup();
    if out.is_empty() {
        return Err("--fit: no parameter named".into());
    }
    Ok(out)
}

/// Every quantity a calibration may change, at one set of values.
#[derive(Clone, Debug, PartialEq)]
pub struct Values {
    /// E, Pa.
    pub youngs_modulus: f64,
    /// G, Pa.
    pub shear_modulus: f64,
    /// ρ, kg/m³.
    pub density: f64,
    /// L, m.
    pub length: f64,
    /// d_i, m.
    pub offsets: Vec<f64>,
    /// φ_i, rad.
    pub angles: Vec<f64>,
    /// s_i: the tension the rod feels is s_i times the recorded one.
    pub tension_scale: Vec<f64>,
    /// Base origin in the tracker frame, m.
    pub base_translation: [f64; 3],
    /// Base orientation in the tracker frame as a rotation vector, rad.
    pub base_rotation: [f64; 3],
}

impl Values {
    /// The values a robot file states (its `[base]` pose in the tracker's
    /// frame among them), with unit tension scales.
    pub fn of(robot: &Robot) -> Values {
        Values {
            youngs_modulus: robot.youngs_modulus,
            shear_modulus: robot.shear_modulus,
            density: robot.density,
            length: robot.length,
            offsets: robot.tendons.iter().map(|t| t.offset).collect(),
            angles: robot.tendons.iter().map(|t| t.angle).collect(),
            tension_scale: vec![1.0; robot.n_tendons()],
            base_translation: robot.base.translation,
            base_rotation: robot.base.rotation,
        }
    }

    /// The value of `p`.
    pub fn get(&self, p: Param) -> f64 {
        match p {
            Param::YoungsModulus => self.youngs_modulus,
            Param::ShearModulus => self.shear_modulus,
            Param::Density => self.density,
            Param::Length => self.length,
            Param::Offset(i) => self.offsets[i],
            Param::Angle(i) => self.angles[i],
            Param::TensionScale(i) => self.tension_scale[i],
            Param::BaseTranslation(k) => self.base_translation[k],
            Param::BaseRotation(k) => self.base_rotation[k],
        }
    }

    /// Set `p` to `x`.
    pub fn set(&mut self, p: Param, x: f64) {
        match p {
            Param::YoungsModulus => self.youngs_modulus = x,
            Param::ShearModulus => self.shear_modulus = x,
            Param::Density => self.density = x,
            Param::Length => self.length = x,
            Param::Offset(i) => self.offsets[i] = x,
            Param::Angle(i) => self.angles[i] = x,
            Param::TensionScale(i) => self.tension_scale[i] = x,
            Param::BaseTranslation(k) => self.base_translation[k] = x,
            Param::BaseRotation(k) => self.base_rotation[k] = x,
        }
    }

    /// The robot these values describe, from `nominal` (limits, routing,
    /// gravity kept). Anchors keep their fraction of the length.
    pub fn robot(&self, nominal: &Robot) -> Robot {
        let stretch = self.length / nominal.length;
        let mut r = nominal.clone();
        r.youngs_modulus = self.youngs_modulus;
        r.shear_modulus = self.shear_modulus;
        r.density = self.density;
        r.length = self.length;
        for (i, t) in r.tendons.iter_mut().enumerate() {
            t.offset = self.offsets[i];
            t.angle = self.angles[i];
            t.end = if t.end == nominal.length {
                self.length
            } else {
                t.end * stretch
            };
        }
        r.base = self.base();
        r
    }

    /// The robot the statics solve during a fit: [`Values::robot`] with
    /// every tension limit widened by the largest tension scale, so a
    /// scaled recorded tension is always a valid solve input.
    pub fn solving_robot(&self, nominal: &Robot) -> Robot {
        let mut r = self.robot(nominal);
        for t in &mut r.tendons {
            t.max_tension *= TENSION_SCALE_BOUNDS.1;
        }
        r
    }

    /// The tensions the rod feels for recorded `tau`.
    pub fn scaled_tensions(&self, tau: &[f64]) -> Vec<f64> {
        tau.iter()
            .zip(&self.tension_scale)
            .map(|(t, s)| t * s)
            .collect()
    }

    /// The base's pose in the tracker's frame these values give (the
    /// robot file's `[base]`, `docs/design.md` §2.4).
    pub fn base(&self) -> crate::robot::BasePose {
        crate::robot::BasePose {
            translation: self.base_translation,
            rotation: self.base_rotation,
        }
    }
}

/// The scale a parameter is fitted in: the fit works on p / scale, so every
/// unknown is of order one, and the identifiability rule (`docs/design.md`
/// §11) asks whether the data pins p to 5 % of this scale.
pub fn scale(p: Param, nominal: &Values) -> f64 {
    match p {
        Param::Density if nominal.density == 0.0 => 1000.0,
        Param::Angle(_) | Param::BaseRotation(_) => 1.0,
        Param::TensionScale(_) => 1.0,
        Param::BaseTranslation(_) => 0.02,
        _ => nominal.get(p).abs(),
    }
}

/// The interval a fitted `p` must stay in, from the nominal values: the
/// moduli, offsets and density within a factor of 5 (density ≥ 0), the
/// length within ±50 %, offsets below half the length, angles within ±30°,
/// tension scales in [0.5, 2], the base within 5 m and 0.2 rad.
pub fn bounds(p: Param, nominal: &Values) -> (f64, f64) {
    let x = nominal.get(p);
    match p {
        Param::YoungsModulus | Param::ShearModulus => (x / FACTOR_BOUND, x * FACTOR_BOUND),
        Param::Density => (0.0, (x * FACTOR_BOUND).max(1000.0)),
        Param::Length => (x * (1.0 - LENGTH_BOUND), x * (1.0 + LENGTH_BOUND)),
        Param::Offset(_) => (
            x / FACTOR_BOUND,
            (x * FACTOR_BOUND).min(0.5 * nominal.length * (1.0 - LENGTH_BOUND)),
        ),
        Param::Angle(_) => (x - ANGLE_BOUND_RAD, x + ANGLE_BOUND_RAD),
        Param::TensionScale(_) => TENSION_SCALE_BOUNDS,
        Param::BaseTranslation(_) => (-BASE_TRANSLATION_BOUND_M, BASE_TRANSLATION_BOUND_M),
        Param::BaseRotation(_) => (x - BASE_ROTATION_BOUND_RAD, x + BASE_ROTATION_BOUND_RAD),
    }
}

/// A robot as robot-file TOML (`docs/design.md` §2 schema): what
/// `Robot::from_toml` reads back to the same robot. Numbers use Rust's
/// round-trip formatting; `header` lines are written first as comments.
pub fn robot_toml(robot: &Robot, header: &[String]) -> String {
    use crate::robot::{DampingKeys, Routing};
    use std::fmt::Write;
    let f = |x: f64| format!("{x:?}");
    let mut s = String::new();
    for line in header {
        let _ = writeln!(s, "# {line}");
    }
    let _ = writeln!(s, "name = {}", toml_string(&robot.name));
    let _ = writeln!(s, "\n[backbone]");
    let _ = writeln!(s, "length = {}", f(robot.length));
    let _ = writeln!(s, "radius = {}", f(robot.radius));
    let _ = writeln!(s, "youngs_modulus = {}", f(robot.youngs_modulus));
    let _ = writeln!(s, "shear_modulus = {}", f(robot.shear_modulus));
    let _ = writeln!(s, "density = {}", f(robot.density));
    let g = robot.gravity;
    let _ = writeln!(s, "\n[environment]");
    let _ = writeln!(s, "gravity = [{}, {}, {}]", f(g.x), f(g.y), f(g.z));
    for t in &robot.tendons {
        let _ = writeln!(s, "\n[[tendon]]");
        let _ = writeln!(s, "offset = {}", f(t.offset));
        let _ = writeln!(s, "angle_deg = {}", f(t.angle.to_degrees()));
        let _ = writeln!(s, "max_tension = {}", f(t.max_tension));
        if t.min_tension != 0.0 {
            let _ = writeln!(s, "min_tension = {}", f(t.min_tension));
        }
        if t.end != robot.length {
            let _ = writeln!(s, "end = {}", f(t.end));
        }
        match t.routing {
            Routing::Straight => {
                let _ = writeln!(s, "routing = \"straight\"");
            }
            Routing::Helical { turns } => {
                let _ = writeln!(s, "routing = \"helical\"\nhelix_turns = {}", f(turns));
            }
        }
    }
    if !robot.base.is_identity() {
        let (t, r) = (robot.base.translation, robot.base.rotation);
        let _ = writeln!(
            s,
            "\n[base]   # the base's pose in the tracker's frame (docs/design.md §2.4)"
        );
        let _ = writeln!(
            s,
            "translation = [{}, {}, {}]   # m",
            f(t[0]),
            f(t[1]),
            f(t[2])
        );
        let _ = writeln!(
            s,
            "rotation = [{}, {}, {}]   # rad, rotation vector",
            f(r[0]),
            f(r[1]),
            f(r[2])
        );
    }
    match robot.damping {
        None => {}
        Some(DampingKeys::Retardation(t)) => {
            let _ = writeln!(s, "\n[damping]\nretardation_s = {}", f(t));
        }
        Some(DampingKeys::Diagonals { bse, bbt }) => {
            let _ = writeln!(
                s,
                "\n[damping]\nbse = [{}, {}, {}]\nbbt = [{}, {}, {}]",
                f(bse[0]),
                f(bse[1]),
                f(bse[2]),
                f(bbt[0]),
                f(bbt[1]),
                f(bbt[2])
            );
        }
    }
    s
}

/// A TOML basic string.
fn toml_string(text: &str) -> String {
    let mut s = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => s.push_str("\\\""),
            '\\' => s.push_str("\\\\"),
            c if c.is_control() => s.push_str(&format!("\\u{:04X}", c as u32)),
            c => s.push(c),
        }
    }
    s.push('"');
    s
}
