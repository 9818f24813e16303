//! Adapting the plan to a backbone stiffer or softer than its robot file
//! (`docs/design.md` §6.5).
//!
//! The net gives the tensions that put the *model's* tip on a pose. At the
//! same tensions a real backbone whose E and G are (1 + s) times the
//! file's puts its tip at the model's tip plus κ g, where
//!
//!   g = ∂tip/∂(ln E) at the path's feed-forward tensions τ_d (m),
//!
//! tabulated once per trajectory row from two statics solves with E and G
//! scaled by 1 ± 1 % ([`StiffnessDirections`]), and κ = s / (1 + s): a
//! linear-elastic deflection goes with the compliance 1/E, so κ is the
//! share of it a stiffer backbone does not make (0.091 for 10 % stiffer,
//! −0.111 for 10 % softer). On the default robot 10 % stiffer moves the tip
//! by 1.2–1.4 mm along the 30 mm circle: the net-alone error of that
//! reality, all of it in this one direction. The controller's integral removes such an error only as fast
//! as its mode-capped gain lets it, and on a circle the error turns with
//! the path; but κ does not turn. The planner estimates κ from the tracker
//! and asks for a pose offset that supplies −κ̂ g, which holds everywhere
//! on the path and at every step target at once.
//!
//! The estimate ([`StiffnessEstimator`]). The loop below the planner is
//! modelled quasi-statically: the controller's correction c integrates its
//! low-passed error, ċ = k_i f, τ_f ḟ = e − f, and the tip is the command
//! plus a disturbance d, so e = −(c + d) = −S[d] with
//! S(s) = s (τ_f s + 1) / (τ_f s² + s + k_i). With the offset o the
//! disturbance is κ g + o, so a frame's error is
//!
//!   e = −κ S[g] + S[−o] = −κ φ + ψ,
//!
//! linear in κ with the regressor φ = S[g] and the known ψ = S[−o], both
//! simulated on the planner's clock, the integral frozen where the
//! controller freezes it (a shaped move and the settle after it).
//!
//! The offset. By the same model the controller's integral holds
//! κ c_φ − c_ψ of the stiffness error (c_φ, c_ψ: the model integral's
//! states in φ and ψ), so the offset sent is −κ̂ g less the estimate of
//! that, o = −κ̂ g − (κ̂ c_φ − c_ψ) = −κ̂ φ + c_ψ, and with κ̂ = κ the error
//! is 0 whatever the integral learned before. With one κ̂ from the start
//! this is −κ̂ g; when κ̂ changes, the integral keeps what it learned and
//! the offset supplies the rest. A first version sent −κ̂ g, which counted
//! the error twice where κ̂ was first applied: the integral still held the
//! last target's correction and unwound it at the next (`tdcr-2seg` 10 %
//! off its file: the third step's steady state 0.060 mm, now 0.026). κ is
//! then a least-squares fit of z = ψ − e on φ over the frames, with
//! exponential forgetting; it is used once the frames' φ carry enough
//! excitation that a 0.2 mm tracker leaves it within ±0.01, and bounded to
//! ±[`MAX_STIFFNESS_ERROR`]. Each frame is matched with what the planner
//! asked for, and with the regressors, the loop's delay before it was
//! measured: on a circle the integral leaves a stiffness error mostly along
//! the path, where a late loop leaves its own, so an uncounted 10 ms reads
//! as κ̂ ≈ 0.04 (the controller leads each setpoint by its age, so the
//! host's loop is on time; the chip's command comes back over its link
//! 1.4 ms late). A new estimate changes the offset, which is a
//! step of its own: on a path it is applied through a first-order lag of a
//! few of the rod's periods; between step targets it is taken up on the
//! next shaped move, along the move's own profile, so that neither rings
//! the mode nor moves the offset while the controller settles on a target.

use std::collections::VecDeque;

use super::{along_axes, Desired, IntegralGains, Motion, PlanError, Trajectory};
use crate::robot::Robot;
use crate::statics::{SolverSettings, Statics};

/// The relative change of E and G of the central difference for g.
const DIFFERENCE: f64 = 0.01;

/// The largest |κ̂| estimated (E off by −23 % to +43 %): a file further off
/// wants calibration (`tendril calibrate`), not a loop.
pub const MAX_STIFFNESS_ERROR: f64 = 0.3;

/// The least Σ|φ|² (m²) before the estimate is used: with a tracker whose
/// frames scatter by 0.2 mm per axis, the fit's standard error is then at
/// most 0.2 mm / √(4e-4 m²) = 0.01.
const MIN_EXCITATION_M2: f64 = 4e-4;

/// The fit forgets a frame after this long (s): long against a tracker's
/// noise, short against a robot that warms up or wears.
const FORGET_S: f64 = 5.0;

/// The applied estimate follows the fit with a lag of this many periods of
/// the rod's first mode (and at least [`MIN_APPLY_LAG_S`]).
const APPLY_LAG_PERIODS: f64 = 3.0;

/// See [`APPLY_LAG_PERIODS`], s.
const MIN_APPLY_LAG_S: f64 = 0.5;

/// Frames are not fitted for this long after the loop below stopped
/// following the setpoints, s: it brings the tip back to the path first.
const AFTER_HOLD_S: f64 = 1.0;

/// How long the model's regressors are kept for frames that arrive late, s
/// (the built-in trackers deliver within 50 ms).
const HISTORY_S: f64 = 0.5;

/// g, per row of a trajectory: how the model's tip moves, at the row's
/// feed-forward tensions, per unit relative change of the backbone's
/// stiffness (E and G together), m, base frame.
#[derive(Clone, Debug)]
pub struct StiffnessDirections {
    rows: Vec<Vec<f64>>,
}

impl StiffnessDirections {
    /// The directions along `traj` for `robot`: a central difference of
    /// two statics solves per row, E and G scaled by 1 ± 1 %, warm-started
    /// along the rows. A row without feed-forward tensions gets 0 (no
    /// adaptation there).
    pub fn new(traj: &Trajectory, robot: &Robot) -> Result<StiffnessDirections, PlanError> {
        let scaled = |factor: f64| {
            let mut r = robot.clone();
            r.youngs_modulus *= factor;
            r.shear_modulus *= factor;
            Statics::new(&r, SolverSettings::default())
        };
        let (up, down) = (scaled(1.0 + DIFFERENCE), scaled(1.0 - DIFFERENCE));
        let (mut warm_up, mut warm_down) = (None, None);
        let mut rows = Vec::with_capacity(traj.feedforward_rows().len());
        for tensions in traj.feedforward_rows() {
            if tensions.iter().any(|v| !v.is_finite()) {
                rows.push(vec![0.0; 3]);
                continue;
            }
            let stiffer = up.solve(tensions, warm_up.as_ref());
            let softer = down.solve(tensions, warm_down.as_ref());
            let (stiffer, softer) = stiffer.and_then(|a| Ok((a, softer?))).map_err(|e| {
                PlanError::Statics(format!(
                    "the tip's sensitivity to stiffness at {tensions:?} N: {e}"
                ))
            })?;
            let g = (stiffer.position - softer.position) / (2.0 * DIFFERENCE);
            rows.push(g.as_slice().to_vec());
            warm_up = Some(stiffer.warm);
            warm_down = Some(softer.warm);
        }
        Ok(StiffnessDirections { rows })
    }

    /// g at time `t` (s on the trajectory), blended as the poses are.
    pub fn at(&self, traj: &Trajectory, t: f64, scratch: &mut Vec<f64>) -> [f64; 3] {
        traj.blend(&self.rows, t, scratch);
        [scratch[0], scratch[1], scratch[2]]
    }
}

/// The controller's correction as the planner models it for one input d
/// (module docs): e = −(c + d), τ_f ḟ = e − f, ċ = k_i f, per axis.
#[derive(Clone, Copy, Debug, Default)]
struct ModelLoop {
    c: [f64; 3],
    f: [f64; 3],
}

impl ModelLoop {
    /// Advance by `dt` with input `d`, the integral frozen when `quiet`;
    /// returns S[d] = −e = c + d after the step.
    fn step(&mut self, gains: &IntegralGains, d: [f64; 3], dt: f64, quiet: bool) -> [f64; 3] {
        for ((c, f), d) in self.c.iter_mut().zip(&mut self.f).zip(d) {
            let e = -(*c + d);
            if !quiet {
                // Semi-implicit Euler: stable for dt ≪ τ_f, 1/k_i (1 ms
                // against 80 ms and 250 ms).
                // A controller without the filter (τ_f = 0) integrates e.
                *f += (dt / gains.filter_tau_s).min(1.0) * (e - *f);
                *c += dt * gains.ki_per_s * *f;
            }
        }
        std::array::from_fn(|k| self.c[k] + d[k])
    }
}

/// One planner tick's regressors, kept for the frames measured then.
#[derive(Clone, Copy, Debug)]
struct Tick {
    t: f64,
    phi: [f64; 3],
    psi: [f64; 3],
    /// Frames measured then are fitted.
    fitted: bool,
}

/// The estimate of κ, the share of the model's deflection a backbone of
/// another stiffness does not make (module docs), from the tracker's frames.
#[derive(Clone, Debug)]
pub struct StiffnessEstimator {
    gains: IntegralGains,
    loop_delay_s: f64,
    quiet_after_move_s: f64,
    apply_lag_s: f64,
    phi_loop: ModelLoop,
    psi_loop: ModelLoop,
    history: VecDeque<Tick>,
    last_tick: Option<f64>,
    quiet_until: f64,
    last_frame: Option<f64>,
    /// The applied estimate before and after the shaped move under way.
    taking_up: Option<(f64, f64)>,
    /// Σ λ φ·z and Σ λ |φ|² of the fit.
    num: f64,
    den: f64,
    fitted: f64,
    applied: f64,
    /// The offset sent after the last tick, m, base frame.
    offset: [f64; 3],
}

impl StiffnessEstimator {
    /// An estimator for a controller of `gains` that integrates no frame
    /// during a shaped move and `quiet_after_move_s` after it, on a rod
    /// whose first mode is `mode_hz` (None: unknown), in a loop that puts
    /// a setpoint on the tip `loop_delay_s` after the planner sent it.
    pub fn new(
        gains: IntegralGains,
        quiet_after_move_s: f64,
        mode_hz: Option<f64>,
        loop_delay_s: f64,
    ) -> StiffnessEstimator {
        let apply_lag_s = mode_hz
            .filter(|f| *f > 0.0)
            .map_or(MIN_APPLY_LAG_S, |f| APPLY_LAG_PERIODS / f)
            .max(MIN_APPLY_LAG_S);
        StiffnessEstimator {
            gains,
            loop_delay_s: if loop_delay_s.is_finite() {
                loop_delay_s.max(0.0)
            } else {
                0.0
            },
            quiet_after_move_s,
            apply_lag_s,
            phi_loop: ModelLoop::default(),
            psi_loop: ModelLoop::default(),
            history: VecDeque::new(),
            last_tick: None,
            quiet_until: f64::NEG_INFINITY,
            last_frame: None,
            taking_up: None,
            num: 0.0,
            den: 0.0,
            fitted: 0.0,
            applied: 0.0,
            offset: [0.0; 3],
        }
    }

    /// The planner's tick at `t` (s on its clock) with the direction `g`
    /// there (m), whether a shaped move is under way, and whether the
    /// planner holds its first pose; `steps`: the trajectory is stepwise,
    /// with the progress (0–1) of the shaped step under way if any. The
    /// settle hold's frames are not fitted (the model loop still runs
    /// through it, as the controller's integral does): after the approach
    /// from rest the controller's error map (which the model leaves out)
    /// takes the error 2–4× faster than the model's integral and
    /// overshoots, so those frames contradict each other — fitted, they
    /// gave the default robot 10 % softer a first estimate of the wrong
    /// sign on steps (+0.04), though the right one on the circle.
    pub fn tick(
        &mut self,
        t: f64,
        g: [f64; 3],
        moving: bool,
        holding: bool,
        steps: Option<Option<f64>>,
    ) {
        let dt = self.last_tick.map_or(0.0, |t0| (t - t0).clamp(0.0, 0.05));
        self.last_tick = Some(t);
        if moving {
            self.quiet_until = t + self.quiet_after_move_s;
        }
        let quiet = moving || t < self.quiet_until;
        match steps {
            Some(Some(progress)) => {
                let (from, to) = *self.taking_up.get_or_insert((self.applied, self.fitted));
                self.applied = from + progress.clamp(0.0, 1.0) * (to - from);
            }
            Some(None) => {
                if let Some((_, to)) = self.taking_up.take() {
                    self.applied = to;
                }
            }
            None => {
                self.applied += (self.fitted - self.applied) * (dt / self.apply_lag_s).min(1.0);
            }
        }
        let g = g.map(|v| if v.is_finite() { v } else { 0.0 });
        let phi = self.phi_loop.step(&self.gains, g, dt, quiet);
        // The offset net of what the controller's integral already holds
        // of the stiffness error (module docs): −κ̂ φ + c_ψ.
        self.offset = std::array::from_fn(|k| -self.applied * phi[k] + self.psi_loop.c[k]);
        let psi = self
            .psi_loop
            .step(&self.gains, self.offset.map(|o| -o), dt, quiet);
        self.history.push_back(Tick {
            t,
            phi,
            psi,
            fitted: !quiet && !holding,
        });
        while self.history.front().is_some_and(|h| h.t < t - HISTORY_S) {
            self.history.pop_front();
        }
    }

    /// A tracker frame: the tip at `tip` (m, base frame) measured at `t`
    /// (s on the planner's clock); `asked(t)`: the position the planner
    /// asked for at `t`. The frame is matched with what the planner asked
    /// for, and with the model's regressors, the loop's delay earlier.
    pub fn frame(&mut self, t: f64, tip: [f64; 3], asked: impl Fn(f64) -> [f64; 3]) {
        let t = t - self.loop_delay_s;
        if tip.iter().any(|v| !v.is_finite()) || self.last_frame.is_some_and(|t0| t <= t0) {
            return;
        }
        let asked = asked(t);
        let error: [f64; 3] = std::array::from_fn(|k| asked[k] - tip[k]);
        if error.iter().any(|v| !v.is_finite()) {
            return;
        }
        // The newest tick at or before the frame (a frame is never from
        // the future; one older than the history is dropped).
        let Some(tick) = self.history.iter().rev().find(|h| h.t <= t).copied() else {
            return;
        };
        if !tick.fitted {
            return;
        }
        let since = self.last_frame.map_or(0.0, |t0| t - t0);
        self.last_frame = Some(t);
        let forget = (-since / FORGET_S).exp();
        let z: [f64; 3] = std::array::from_fn(|k| tick.psi[k] - error[k]);
        let dot = |a: &[f64; 3], b: &[f64; 3]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        self.num = forget * self.num + dot(&tick.phi, &z);
        self.den = forget * self.den + dot(&tick.phi, &tick.phi);
        if self.den >= MIN_EXCITATION_M2 {
            self.fitted = (self.num / self.den).clamp(-MAX_STIFFNESS_ERROR, MAX_STIFFNESS_ERROR);
        }
    }

    /// The loop below does not follow the setpoints at `t` (the controller
    /// holds, or its commands stopped): no frame is fitted until
    /// [`AFTER_HOLD_S`] after the last such tick, and the model's integral
    /// is frozen meanwhile. A tip held while the path moves on is an error
    /// no stiffness explains; fitted, a 1 s cut link on the circle took the
    /// estimate to its bound (+0.30) and the tip 1.35 mm RMS off the path after.
    pub fn hold(&mut self, t: f64) {
        self.quiet_until = self.quiet_until.max(t + AFTER_HOLD_S);
    }

    /// κ̂ applied now: the backbone is 1/(1 − κ̂) times as stiff as its file
    /// (0.091 for 10 % stiffer).
    pub fn applied(&self) -> f64 {
        self.applied
    }

    /// The pose offset to send after the last [`tick`](Self::tick) (m,
    /// base frame): −κ̂ g less what the controller's integral holds of the
    /// stiffness error already, −κ̂ φ + c_ψ (module docs).
    pub fn offset(&self) -> [f64; 3] {
        self.offset
    }
}

/// The planner's stiffness adaptation: the directions along its
/// trajectory and the estimate, stepped with the planner's clock.
#[derive(Clone, Debug)]
pub struct StiffnessAdaptation {
    directions: StiffnessDirections,
    estimator: StiffnessEstimator,
    scratch: Vec<f64>,
}

impl StiffnessAdaptation {
    /// For `traj` on `robot` (the directions: two statics solves a row),
    /// below a controller of `gains` that integrates nothing over a shaped
    /// move and `quiet_after_move_s` after it, on a rod whose first mode is
    /// `mode_hz`, in a loop that puts a setpoint on the tip `loop_delay_s`
    /// after the planner sent it.
    pub fn new(
        traj: &Trajectory,
        robot: &Robot,
        gains: IntegralGains,
        quiet_after_move_s: f64,
        mode_hz: Option<f64>,
        loop_delay_s: f64,
    ) -> Result<StiffnessAdaptation, PlanError> {
        Ok(StiffnessAdaptation {
            directions: StiffnessDirections::new(traj, robot)?,
            estimator: StiffnessEstimator::new(gains, quiet_after_move_s, mode_hz, loop_delay_s),
            scratch: Vec::new(),
        })
    }

    /// The planner's tick at `t` (s on its clock) asking for `desired` of
    /// `traj`, the loop below `following` its setpoints or not (a
    /// controller in its hold, a cut link: [`StiffnessEstimator::hold`]):
    /// the offset to send, m along the point's tangent axes (as
    /// [`along_axes`]).
    pub fn step(
        &mut self,
        traj: &Trajectory,
        t: f64,
        desired: &Desired,
        following: bool,
    ) -> [f64; 3] {
        if !following {
            self.estimator.hold(t);
        }
        let g = self.directions.at(traj, desired.t_path, &mut self.scratch);
        let steps = traj.stepwise.then(|| traj.step_progress(desired.t_path));
        self.estimator
            .tick(t, g, desired.moving, desired.holding, steps);
        along_axes(&desired.point, self.estimator.offset())
    }

    /// A tracker frame: the tip at `tip` (m, base frame) measured at `t`
    /// (s on the planner's clock), against what `motion` asked for then.
    pub fn frame(&mut self, motion: &Motion, t: f64, tip: [f64; 3]) {
        self.estimator.frame(t, tip, |t| {
            let p = motion.at(t).point.pose;
            [p[0], p[1], p[2]]
        });
    }

    /// κ̂ applied now ([`StiffnessEstimator::applied`]).
    pub fn applied(&self) -> f64 {
        self.estimator.applied()
    }
}

#[cfg(test)]
mod tests;
