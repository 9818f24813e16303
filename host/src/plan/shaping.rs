//! Steps that excite no mode (`docs/design.md` §6.4): a step of the
//! planner's target becomes a minimum-jerk move convolved with a ZVD input
//! shaper designed on the rod's first bending mode.
//!
//! The shaper is three impulses (Singer & Seering 1990) at t = 0, T_d/2, T_d
//! (T_d = 1/f_d the damped period) with amplitudes 1, 2K, K² over (1 + K)²,
//! K = exp(−ζπ/√(1 − ζ²)): each impulse's ringing cancels the others' at
//! the design mode, and the double zero there makes the cancellation
//! tolerate a mode that is off. The minimum-jerk move, 10s³ − 15s⁴ + 6s⁵ over
//! half the mode's period, bounds the jerk the motors are asked for and
//! attenuates the mode a little more. Their residual vibration (the ringing
//! left, as a fraction of an unshaped step's) is ≤ 5 % for a mode anywhere
//! within ±15 % of the design and a damping ratio from 1 % to 17 %
//! ([`StepShaping::residual_vibration`], checked in the tests).
//!
//! *Where it runs:* in the planner, which knows the targets and the robot
//! file, and costs nothing on the chip. In the firmware's period the
//! shaper would need a delay line as long as the mode's period (0.9 s on
//! the three-segment robot: 3 coordinates × 930 periods of f32 = 11 KB at
//! 1 kHz, against the 2 KB the chip has left), and the chip in the loop
//! gets the same shaped setpoints over its link either way.

use serde::{Deserialize, Serialize};

use crate::dynamics::modes::{identify, ModeSearch, ModesError};
use crate::dynamics::Damping;
use crate::robot::Robot;

/// The damping ratio a shaper is designed for is at most this: a robot
/// file's damping is a guess (the seed robot's default gives ζ₁ ≈ 17 %),
/// real tendon robots have 2–5 %, and a ZVD designed for 5 % leaves ≤ 5 %
/// from ζ = 1 % to 17 % (a design for 17 % would leave 12 % at 1 %).
pub const MAX_DESIGN_DAMPING: f64 = 0.05;

/// The minimum-jerk move lasts this fraction of the mode's period.
pub const MOVE_PERIODS: f64 = 0.5;

/// How the planner moves between step targets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepShaping {
    /// The mode designed for: undamped natural frequency, Hz.
    pub mode_hz: f64,
    /// Its damping ratio as designed for.
    pub damping_ratio: f64,
    /// Duration of the minimum-jerk move, s.
    pub move_s: f64,
}

/// Whether the planner shapes its steps (a planner's configuration).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum ShapingChoice {
    /// Designed for the robot file's first mode ([`StepShaping::for_robot`])
    /// unless the planner only holds.
    #[default]
    Auto,
    /// Steps jump.
    Off,
    /// This design.
    Designed(StepShaping),
}

impl ShapingChoice {
    /// A design given (what a launcher that designed it passes on).
    pub fn is_designed(&self) -> bool {
        matches!(self, ShapingChoice::Designed(_))
    }

    /// The shaping a planner following `shape` on `robot` uses: none for a
    /// hold, or when off.
    pub fn resolve(
        self,
        robot: &Robot,
        shape: &crate::plan::PathShape,
    ) -> Result<Option<StepShaping>, ShapingError> {
        if matches!(shape, crate::plan::PathShape::Hold { .. }) {
            return Ok(None);
        }
        match self {
            ShapingChoice::Off => Ok(None),
            ShapingChoice::Auto => StepShaping::for_robot(robot).map(Some),
            ShapingChoice::Designed(s) => s.check().map(|()| Some(s)),
        }
    }
}

/// The first mode's inverse (`docs/design.md` §6.4): a rod whose tip
/// follows its command x through ẍ/ω² + 2ζẋ/ω + x = u lags an
/// accelerating command, and asking for u = r + 2ζṙ/ω + r̈/ω² puts it on r.
/// The offset u − r is what the planner sends beside the pose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalInverse {
    /// The mode: undamped natural frequency, Hz.
    pub mode_hz: f64,
    /// Its damping ratio.
    pub damping_ratio: f64,
}

impl ModalInverse {
    /// u − r = 2ζ/ω · ṙ + r̈/ω² for each coordinate.
    pub fn offset(&self, velocity: &[f64; 7], acceleration: &[f64; 7]) -> [f64; 7] {
        let w = std::f64::consts::TAU * self.mode_hz;
        std::array::from_fn(|k| {
            2.0 * self.damping_ratio / w * velocity[k] + acceleration[k] / (w * w)
        })
    }
}

/// Why a shaping could not be designed.
#[derive(Debug, thiserror::Error)]
pub enum ShapingError {
    /// The mode is not a positive frequency with 0 ≤ ζ < 1, or the move's
    /// time is negative.
    #[error(
        "step shaping: mode {mode_hz} Hz, ζ {damping_ratio}, move {move_s} s: the mode \
         must be in (0, 1000] Hz with 0 ≤ ζ < 1 and the move ≥ 0 s"
    )]
    Bad {
        /// Frequency given, Hz.
        mode_hz: f64,
        /// Damping ratio given.
        damping_ratio: f64,
        /// Move time given, s.
        move_s: f64,
    },
    /// The robot's modes could not be identified.
    #[error("step shaping: {0}")]
    Modes(#[from] ModesError),
}

impl StepShaping {
    /// The shaping for a mode of `mode_hz` with damping ratio `zeta`
    /// (capped at [`MAX_DESIGN_DAMPING`]), its move [`MOVE_PERIODS`] long.
    pub fn for_mode(mode_hz: f64, zeta: f64) -> Result<StepShaping, ShapingError> {
        let s = StepShaping {
            mode_hz,
            damping_ratio: zeta.min(MAX_DESIGN_DAMPING),
            move_s: MOVE_PERIODS / mode_hz,
        };
        s.check()?;
        Ok(s)
    }

    /// The shaping for `robot`'s first bending mode at rest, identified
    /// from its dynamic model with the robot file's damping — what the
    /// controller's side knows, never a reality's.
    pub fn for_robot(robot: &Robot) -> Result<StepShaping, ShapingError> {
        let zeros = vec![0.0; robot.n_tendons()];
        let first = identify(
            robot,
            Damping::of_robot(robot),
            &zeros,
            &ModeSearch::default(),
        )?[0];
        StepShaping::for_mode(first.freq_hz, first.damping_ratio)
    }

    /// The inverse of the mode this shaping was designed for.
    pub fn modal_inverse(&self) -> ModalInverse {
        ModalInverse {
            mode_hz: self.mode_hz,
            damping_ratio: self.damping_ratio,
        }
    }

    /// Check the numbers (a configuration file may hold anything).
    pub fn check(&self) -> Result<(), ShapingError> {
        let ok = self.mode_hz > 0.0
            && self.mode_hz <= 1000.0
            && (0.0..1.0).contains(&self.damping_ratio)
            && self.move_s >= 0.0
            && self.move_s.is_finite();
        if ok {
            Ok(())
        } else {
            Err(ShapingError::Bad {
                mode_hz: self.mode_hz,
                damping_ratio: self.damping_ratio,
                move_s: self.move_s,
            })
        }
    }

    /// The ZVD shaper's impulses: (time s, amplitude), amplitudes summing to 1.
    pub fn impulses(&self) -> [(f64, f64); 3] {
        let z = self.damping_ratio;
        let root = (1.0 - z * z).sqrt();
        let k = (-z * std::f64::consts::PI / root).exp();
        let period_d = 1.0 / (self.mode_hz * root);
        let norm = (1.0 + k) * (1.0 + k);
        [
            (0.0, 1.0 / norm),
            (0.5 * period_d, 2.0 * k / norm),
            (period_d, k * k / norm),
        ]
    }

    /// How long a shaped step takes from its first motion to its last, s.
    pub fn length_s(&self) -> f64 {
        self.impulses()[2].0 + self.move_s
    }

    /// The fraction of a step made `t` s after it was asked for (0 before,
    /// 1 after [`StepShaping::length_s`]), and its rate (1/s).
    pub fn progress(&self, t: f64) -> (f64, f64) {
        self.impulses().iter().fold((0.0, 0.0), |(f, r), &(at, a)| {
            let (p, dp) = minimum_jerk(t - at, self.move_s);
            (f + a * p, r + a * dp)
        })
    }

    /// The path time at time `t` (s) after a path starts from rest: the
    /// path's clock runs at the rate [`StepShaping::progress`] gives, so its
    /// speed rises from 0 to the path's own as a shaped step does, and the
    /// start excites the mode no more than such a step would. Once the
    /// shaping's length has passed it runs at the path's pace, behind by
    /// a constant lag; before the start (t ≤ 0) it is 0.
    pub fn eased_time(&self, t: f64) -> f64 {
        self.impulses()
            .iter()
            .map(|&(at, a)| a * minimum_jerk_integral(t - at, self.move_s))
            .sum()
    }

    /// The ringing a shaped step leaves on a mode of natural frequency
    /// `freq_hz` and damping `zeta`, as a fraction of what an unshaped step
    /// leaves: |Σ_k A_k P(s) e^{s t_k}| e^{−ζω t_end} with s = ζω + iω_d
    /// and P the move's weighting of the mode (1 for a hard step).
    pub fn residual_vibration(&self, freq_hz: f64, zeta: f64) -> f64 {
        let w = std::f64::consts::TAU * freq_hz;
        let (sigma, wd) = (zeta * w, w * (1.0 - zeta * zeta).sqrt());
        let (mut c, mut s) = (0.0, 0.0);
        let impulses = self.impulses();
        for (t, a) in impulses {
            let e = a * (sigma * t).exp();
            c += e * (wd * t).cos();
            s += e * (wd * t).sin();
        }
        let shaper = c.hypot(s) * (-sigma * impulses[2].0).exp();
        shaper * self.move_weight(sigma, wd)
    }

    /// |∫ ṗ(τ) e^{(σ + iω_d)τ} dτ| e^{−σT} of the minimum-jerk move over T:
    /// how much of a hard step's ringing the move leaves (Simpson's rule on
    /// 200 panels: the integrand is a polynomial times an exponential).
    fn move_weight(&self, sigma: f64, wd: f64) -> f64 {
        let t_move = self.move_s;
        if t_move <= 0.0 {
            return 1.0;
        }
        let n = 200;
        let h = t_move / n as f64;
        let (mut c, mut s) = (0.0, 0.0);
        for i in 0..=n {
            let tau = i as f64 * h;
            let weight = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let (_, rate) = minimum_jerk(tau, t_move);
            let e = weight * rate * (sigma * tau).exp();
            c += e * (wd * tau).cos();
            s += e * (wd * tau).sin();
        }
        (c.hypot(s) * h / 3.0) * (-sigma * t_move).exp()
    }
}

/// The minimum-jerk move from 0 to 1 over `duration` s at time `t` (s):
/// its position 10s³ − 15s⁴ + 6s⁵ (s = t / duration, clamped) and rate;
/// a step when `duration` is 0.
fn minimum_jerk(t: f64, duration: f64) -> (f64, f64) {
    if t <= 0.0 {
        return (0.0, 0.0);
    }
    if duration <= 0.0 || t >= duration {
        return (1.0, 0.0);
    }
    let s = t / duration;
    let p = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
    let dp = 30.0 * s * s * (1.0 - s) * (1.0 - s) / duration;
    (p, dp)
}

/// ∫₀ᵗ of the minimum-jerk move's position: T (2.5s⁴ − 3s⁵ + s⁶) within
/// the move, then T/2 + (t − T) after it (its mean position over the move
/// is ½); t for a step.
fn minimum_jerk_integral(t: f64, duration: f64) -> f64 {
    if t <= 0.0 {
        return 0.0;
    }
    if duration <= 0.0 {
        return t;
    }
    if t >= duration {
        return 0.5 * duration + (t - duration);
    }
    let s = t / duration;
    duration * s.powi(4) * (2.5 - 3.0 * s + s * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A second-order mode x'' + 2ζω x' + ω² x = ω² u driven by the shaped
    /// step u, integrated exactly for a piecewise-linear u (fine steps): its
    /// ringing after the step, against a hard step's, is the closed form.
    fn simulated_residual(shaping: &StepShaping, freq_hz: f64, zeta: f64) -> f64 {
        let w = std::f64::consts::TAU * freq_hz;
        let dt = 1e-5;
        let (mut x, mut v) = (0.0f64, 0.0f64);
        let end = shaping.length_s();
        let mut t = 0.0;
        // Semi-analytic: RK4 on tiny steps is exact to far below 1e-4 here.
        let f = |t: f64, x: f64, v: f64| {
            let u = shaping.progress(t).0;
            (v, w * w * (u - x) - 2.0 * zeta * w * v)
        };
        while t < end {
            let (k1x, k1v) = f(t, x, v);
            let (k2x, k2v) = f(t + dt / 2.0, x + dt / 2.0 * k1x, v + dt / 2.0 * k1v);
            let (k3x, k3v) = f(t + dt / 2.0, x + dt / 2.0 * k2x, v + dt / 2.0 * k2v);
            let (k4x, k4v) = f(t + dt, x + dt * k3x, v + dt * k3v);
            x += dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
            v += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
            t += dt;
        }
        // The free ringing's amplitude after the end, from x − 1 and v, over
        // a hard step's at t = end (1 − e^{−σt}(cos ω_d t + σ/ω_d sin ω_d t)
        // rings with amplitude 1/√(1 − ζ²) in this measure).
        let root = (1.0 - zeta * zeta).sqrt();
        let wd = w * root;
        let e = x - 1.0;
        (e * e + ((v + zeta * w * e) / wd).powi(2)).sqrt() * root
    }

    #[test]
    fn the_shaped_step_leaves_the_ringing_the_closed_form_says() {
        let shaping = StepShaping::for_mode(3.6, 0.05).unwrap();
        for (r, zeta) in [
            (1.0, 0.05),
            (0.85, 0.05),
            (1.15, 0.01),
            (1.3, 0.17),
            (2.0, 0.05),
        ] {
            let f = 3.6 * r;
            let closed = shaping.residual_vibration(f, zeta);
            let simulated = simulated_residual(&shaping, f, zeta);
            assert!(
                (closed - simulated).abs() < 1e-4 + 1e-3 * closed,
                "mode {r} × design, ζ {zeta}: closed form {closed:.5}, simulated {simulated:.5}"
            );
        }
        // At the design mode nothing rings.
        assert!(shaping.residual_vibration(3.6, 0.05) < 1e-9);
    }

    #[test]
    fn the_shaping_tolerates_the_mode_fifteen_percent_off_and_any_damping() {
        let shaping = StepShaping::for_mode(1.07, 0.05).unwrap();
        let mut worst: f64 = 0.0;
        for i in 0..=60 {
            let r = 0.85 + 0.3 * i as f64 / 60.0;
            for zeta in [0.01, 0.02, 0.05, 0.1, 0.17] {
                worst = worst.max(shaping.residual_vibration(1.07 * r, zeta));
            }
        }
        assert!(worst <= 0.05, "worst residual vibration {worst:.4}");
        // A shaper for the wrong mode (twice too high) leaves much of it.
        let wrong = StepShaping::for_mode(2.14, 0.05).unwrap();
        let left = wrong.residual_vibration(1.07, 0.05);
        assert!(left > 0.2, "{left}");
    }

    #[test]
    fn a_shaped_step_goes_all_the_way_and_no_further() {
        let shaping = StepShaping::for_mode(2.4, 0.2).unwrap();
        assert_eq!(shaping.damping_ratio, MAX_DESIGN_DAMPING);
        let mut last = 0.0;
        let n = 1000;
        for i in 0..=n {
            let t = shaping.length_s() * i as f64 / n as f64;
            let (p, rate) = shaping.progress(t);
            assert!(p >= last - 1e-15 && rate >= 0.0, "t {t}: {p} after {last}");
            last = p;
        }
        assert!((last - 1.0).abs() < 1e-12);
        assert_eq!(shaping.progress(-1.0), (0.0, 0.0));
        let (end, rate) = shaping.progress(1e3);
        assert!((end - 1.0).abs() < 1e-12 && rate == 0.0);
    }

    /// The eased clock's rate is the shaped step's progress (its derivative
    /// by central differences), and after the shaping it runs at pace,
    /// behind by the shaping's mean delay.
    #[test]
    fn the_eased_clock_speeds_up_as_a_shaped_step_moves() {
        let shaping = StepShaping::for_mode(1.07, 0.05).unwrap();
        let h = 1e-6;
        for k in 0..=50 {
            let t = 1.2 * shaping.length_s() * k as f64 / 50.0;
            let rate = (shaping.eased_time(t + h) - shaping.eased_time(t - h)) / (2.0 * h);
            let (p, _) = shaping.progress(t);
            assert!((rate - p).abs() < 1e-6, "t {t}: rate {rate} vs {p}");
        }
        let lag: f64 = shaping
            .impulses()
            .iter()
            .map(|(at, a)| a * (at + 0.5 * shaping.move_s))
            .sum();
        let t = 3.0 * shaping.length_s();
        assert!((t - shaping.eased_time(t) - lag).abs() < 1e-12);
        assert_eq!(shaping.eased_time(-0.5), 0.0);
    }

    #[test]
    fn bad_modes_are_refused() {
        assert!(StepShaping::for_mode(0.0, 0.05).is_err());
        assert!(StepShaping::for_mode(f64::NAN, 0.05).is_err());
        assert!(StepShaping::for_mode(2.0, -0.1).is_err());
    }
}
