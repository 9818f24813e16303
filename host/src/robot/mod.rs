//! The robot model: the validated description of `docs/design.md` §2 and the
//! quantities the statics derive from it (section properties, stiffness
//! matrices, tendon routing). The file schema and its validator live in
//! [`file`], the tendon groups in [`groups`].

use std::f64::consts::PI;
use std::fmt;
use std::path::Path;

use nalgebra::{Matrix3, Vector3};

pub mod base_pose;
pub mod file;
pub mod fingerprint;
pub mod groups;

pub use base_pose::{BasePose, RigidMap};
pub use file::{RobotError, BUILTIN_DEFAULT_TOML, DEFAULT_ROBOT};
pub use groups::{anchor_groups, bending_dof, cocontraction_sets};

/// Largest tendon count a robot file may declare (the one capacity in `tendril_shared`).
pub use tendril_shared::MAX_TENDONS;

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
    /// Where the base sits in the tracker's frame, from the optional
    /// `[base]` table (identity without it; `docs/design.md` §2.4). Not
    /// part of the fingerprint: the rod does not change with it.
    pub base: BasePose,
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

impl Robot {
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

/// The first bending mode of the robot's backbone as a uniform clamped-free
/// beam, rad/s: ω₁ = (β₁L)² √(EI / (ρA L⁴)), β₁L = 1.8751 (Euler–Bernoulli;
/// tendon tension and spacer disks shift it by a few per cent). 3.6 Hz on
/// the default robot.
pub fn first_bending_mode_rad_s(robot: &Robot) -> f64 {
    const BETA1_L: f64 = 1.875_104;
    let ei = robot.youngs_modulus * robot.second_moment();
    let rho_a = robot.density * robot.area();
    BETA1_L * BETA1_L * (ei / (rho_a * robot.length.powi(4))).sqrt()
}

#[cfg(test)]
mod tests {
    use super::file::tests::{parse, GOOD};
    use super::*;

    #[test]
    fn shipped_robots_load() {
        let r4 = repo_robot("seed-4t.toml");
        assert_eq!(r4.n_tendons(), 4);
        assert!((r4.tendons[1].angle - PI / 2.0).abs() < 1e-15);
        // Effective linear density 0.1 kg/m (docs/design.md §2).
        assert!((r4.density * r4.area() - 0.1).abs() < 1e-4);
        let r1 = repo_robot("seed-1t.toml");
        assert_eq!(r1.n_tendons(), 1);
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
    fn robot_summary_counts_tendons_in_the_right_number() {
        let r = parse(GOOD).unwrap();
        assert!(r.to_string().ends_with("1 tendon"), "{r}");
        assert_eq!(count(4, "tendon"), "4 tendons");
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
