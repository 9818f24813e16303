//! The time scheme (BDF-α) and the material constants the statics do not
//! need: inertia per length and damping (`docs/design.md` §4.2).

use nalgebra::Vector3;

use crate::robot::{DampingKeys, Robot};

/// Coefficients of the BDF-α time derivative (Till, Aloi & Rucker 2019):
///
/// ```text
/// y_t(i) = c₀ y(i) + y_h(i),   y_h(i) = c₁ y(i−1) + c₂ y(i−2) + d₁ y_t(i−1)
/// c₀ = (1.5 + α) / (δt (1 + α)),  c₁ = −2 / δt,
/// c₂ = (0.5 + α) / (δt (1 + α)),  d₁ = α / (1 + α)
/// ```
///
/// α ∈ [−0.5, 0]: α = 0 is BDF2 (most numerical damping), α = −0.5 the
/// trapezoidal rule (none). Second order for every α in the range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BdfAlpha {
    /// α, dimensionless, in [−0.5, 0].
    pub alpha: f64,
    /// Time step δt, s.
    pub dt_s: f64,
}

impl BdfAlpha {
    /// c₀, 1/s: the weight of the current value in y_t.
    pub fn c0(&self) -> f64 {
        (1.5 + self.alpha) / (self.dt_s * (1.0 + self.alpha))
    }

    /// c₁, 1/s: the weight of y(i−1).
    pub fn c1(&self) -> f64 {
        -2.0 / self.dt_s
    }

    /// c₂, 1/s: the weight of y(i−2).
    pub fn c2(&self) -> f64 {
        (0.5 + self.alpha) / (self.dt_s * (1.0 + self.alpha))
    }

    /// d₁: the weight of y_t(i−1).
    pub fn d1(&self) -> f64 {
        self.alpha / (1.0 + self.alpha)
    }
}

/// Kelvin–Voigt material damping: n = Kse (v − e₃) + Bse v_t and
/// m = Kbt u + Bbt u_t, both diagonal in the body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Damping {
    /// Bse diagonal (shear x, shear y, extension), N·s.
    pub bse: Vector3<f64>,
    /// Bbt diagonal (bending x, bending y, torsion), N·m²·s.
    pub bbt: Vector3<f64>,
}

impl Damping {
    /// Retardation time of the default damping, s (robots without a
    /// `[damping]` table). With B = t_r K every mode of angular frequency ω
    /// gets the damping ratio ζ = ω t_r / 2.
    ///
    /// Source: Till, Aloi & Rucker's tendon-robot dynamics example (the
    /// companion code of their IJRR 2019 paper, JohnDTill/ContinuumRobotExamples,
    /// 02_Dynamics/03_Tendon_Robot) damps a spring-steel backbone with spacer
    /// disks (E = 207 GPa, r = 0.675 mm, L = 0.714 m, 34 g) by
    /// Bbt = 5e-4 N·m²·s, i.e. t_r = Bbt / (E I) = 5e-4 / 0.03375 = 14.8 ms.
    /// Kelvin–Voigt damping is a material law (B = η × section property, t_r
    /// = η/E), and the seed robot is the same construction in the same
    /// material, so it keeps t_r: ζ₁ ≈ 17 % at f₁ = 3.6 Hz. (Keeping their
    /// absolute Bbt instead gives ζ₁ ≈ 5.3 %; a robot file can say so with
    /// `[damping] bbt = [5e-4, 5e-4, 5e-4]`, see `docs/design.md` §4.2.)
    pub const DEFAULT_RETARDATION_S: f64 = 14.8e-3;

    /// No material damping (free vibration checks).
    pub fn none() -> Damping {
        Damping {
            bse: Vector3::zeros(),
            bbt: Vector3::zeros(),
        }
    }

    /// Damping proportional to stiffness: B = t_r K (Bse = t_r Kse,
    /// Bbt = t_r Kbt) with retardation time `retardation_s` (s).
    pub fn proportional(robot: &Robot, retardation_s: f64) -> Damping {
        Damping {
            bse: robot.kse() * retardation_s,
            bbt: robot.kbt() * retardation_s,
        }
    }

    /// The robot's damping: its file's `[damping]` table, or
    /// [`Damping::proportional`] with [`Damping::DEFAULT_RETARDATION_S`].
    pub fn of_robot(robot: &Robot) -> Damping {
        match robot.damping {
            None => Damping::proportional(robot, Self::DEFAULT_RETARDATION_S),
            Some(DampingKeys::Retardation(t_r)) => Damping::proportional(robot, t_r),
            Some(DampingKeys::Diagonals { bse, bbt }) => Damping {
                bse: Vector3::from(bse),
                bbt: Vector3::from(bbt),
            },
        }
    }
}

/// Default [`DynamicsSettings::jacobian_coarsening`]: 1, the solve's own
/// grid. Unlike the statics', the time step's shooting problem is stiff
/// (solutions grow like e^{λs}, λL ≈ 5 for the seed robot at 1 ms), so a
/// coarse grid's Jacobian is poor: on the 30 mm circle at 1 kHz a 4× coarser
/// one took 4.2 fine passes per step against 2.3, and an 8× coarser one
/// (2 RK4 steps) did not converge in the first step (issue 29 item 3b,
/// `docs/design.md` §4.2).
pub const JACOBIAN_COARSENING: usize = 1;

/// Discretisation and convergence settings of the dynamic solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicsSettings {
    /// Time step δt, s.
    pub dt_s: f64,
    /// BDF-α parameter α ∈ [−0.5, 0].
    pub alpha: f64,
    /// RK4 steps over the length (the spatial grid).
    pub steps: usize,
    /// Convergence: norm of the tip residual [force N; moment N·m].
    pub tol: f64,
    /// Largest residual accepted when Newton can improve it no further: the
    /// roundoff floor of small time steps, whose shooting problem amplifies
    /// roundoff by e^{λL} (`solver`). 1e-7 N moves the default robot's
    /// tip by ~2e-8 m (L³/3EI ≈ 0.2 m/N).
    pub floor_tol: f64,
    /// Newton iterations per time step before giving up.
    pub max_iter: usize,
    /// The finite-difference Jacobian is taken on a grid this many times
    /// coarser than `steps` (per piece, the largest divisor of its steps up
    /// to this that leaves two steps; 1: the solve's own grid). The answer
    /// is the fine grid's whatever this is.
    pub jacobian_coarsening: usize,
}

impl Default for DynamicsSettings {
    fn default() -> Self {
        DynamicsSettings {
            dt_s: 1e-3,
            // Till, Aloi & Rucker's choice: second order, damping only
            // what the grid cannot resolve.
            alpha: -0.2,
            steps: 16,
            tol: 1e-9,
            floor_tol: 1e-7,
            max_iter: 12,
            jacobian_coarsening: JACOBIAN_COARSENING,
        }
    }
}

impl DynamicsSettings {
    /// The BDF-α coefficients of these settings.
    pub fn scheme(&self) -> BdfAlpha {
        BdfAlpha {
            alpha: self.alpha,
            dt_s: self.dt_s,
        }
    }
}
