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
//! modelled quasi-statically: the controller's correction c + M x
//! integrates its low-passed error, ċ = k_i f, τ_f ḟ = e − f, its error
//! map learning as the firmware's does, Ṁ = k_M f x̃ᵀ / (ℓ² + |x̃|²), and
//! the tip is the command plus a disturbance d, so e = −(c + M x + d) =
//! −S[d], linear in d for the setpoints sent (without the map,
//! S(s) = s (τ_f s + 1) / (τ_f s² + s + k_i)). With the offset o the
//! disturbance is κ g + o, so a frame's error is
//!
//!   e = −κ S[g] + S[−o] = −κ φ + ψ,
//!
//! linear in κ with the regressor φ = S[g] and the known ψ = S[−o], both
//! simulated on the planner's clock, the integral frozen where the
//! controller freezes it (a shaped move and the settle after it, its hold).
//!
//! The settle hold. Its frames are fitted, the first target then has an
//! estimate, unless the robot's weight bends it: at one pose a stiffer
//! backbone and a lighter one move the tip alike (the default robot's
//! first step target, where g and the density's h = ∂tip/∂(ln ρ) both lie
//! along x), and the integral starts from nothing there, so the hold's
//! error mixes both; at later targets the integral has taken the mixed
//! constant part and the transients tell κ alone. On the default robot
//! with E, G and ρ 10 % off, the hold gave κ̂ 0.063 for 0.091, and the
//! second target began worse than with no estimate at all.
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
use tendril_firmware::control::MAP_MEAN_TAU_S;

/// The relative change of E and G of the central difference for g.
const DIFFERENCE: f64 = 0.01;

/// The largest |κ̂| estimated (E off by −23 % to +43 %): a file further off
/// wants calibration (`tendril calibrate`), not a loop.
pub const MAX_STIFFNESS_ERROR: f64 = 0.3;

/// The smallest |κ̂| applied; a fit within it is taken as 0 (the file is
/// right). It is the fit's own noise bound at the least excitation
/// ([`MIN_EXCITATION_M2`]), and about what a net's or a robot's other
/// static errors read as stiffness: at one pose any constant error along
/// g does (`tdcr-2seg`'s settle hold on a rod as stiff as its file gave
/// −0.006, and the second step target then settled in 1.1 s, not 0.62).
/// An error of 1 % moves the tip ≈ 0.1 mm, which the integral holds.
const MIN_STIFFNESS_ERROR: f64 = 0.01;

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

/// Frames are not fitted for this many times as long as the loop below did
/// not follow the setpoints, after it follows again (and for at most
/// [`AFTER_HOLD_S`]): it brings the tip back to the path first. A planner
/// a few periods late trips the controller's watchdog for as long (3–10
/// times a run on the project's shared VM); its tip moved by a few
/// periods' worth of path, and a whole second without fitting after each
/// left a step target unfitted.
const AFTER_HOLD_FACTOR: f64 = 10.0;

/// See [`AFTER_HOLD_FACTOR`], s: after a long hold (a cut link), a second.
const AFTER_HOLD_S: f64 = 1.0;

/// The settle hold's frames are fitted where the tip's sensitivity to the
/// backbone's density at the first pose is at most this share of its
/// sensitivity to stiffness (module docs).
const SEPARABLE_WEIGHT_SHARE: f64 = 0.1;

/// How long the model's regressors are kept for frames that arrive late, s
/// (the built-in trackers deliver within 50 ms).
const HISTORY_S: f64 = 0.5;

/// g, per row of a trajectory: how the model's tip moves, at the row's
/// feed-forward tensions, per unit relative change of the backbone's
/// stiffness (E and G together), m, base frame.
#[derive(Clone, Debug)]
pub struct StiffnessDirections {
    rows: Vec<Vec<f64>>,
    /// Whether one pose tells the stiffness from the weight there (module
    /// docs): the settle hold's frames are fitted only then.
    hold_tells_stiffness: bool,
}

impl StiffnessDirections {
    /// The directions along `traj` for `robot`: a central difference of
    /// two statics solves per row, E and G scaled by 1 ± 1 %, warm-started
    /// along the rows. A row without feed-forward tensions gets 0 (no
    /// adaptation there). Where gravity acts, two more solves at the first
    /// row, the density scaled by 1 ± 1 %, tell whether the settle hold
    /// can be fitted.
    pub fn new(traj: &Trajectory, robot: &Robot) -> Result<StiffnessDirections, PlanError> {
        let stiffer = |factor: f64| {
            let mut r = robot.clone();
            r.youngs_modulus *= factor;
            r.shear_modulus *= factor;
            r
        };
        let rows = sensitivities(
            traj.feedforward_rows(),
            (&stiffer(1.0 + DIFFERENCE), &stiffer(1.0 - DIFFERENCE)),
            "stiffness",
        )?;
        let first = traj
            .feedforward_rows()
            .iter()
            .position(|t| t.iter().all(|v| v.is_finite()));
        let hold_tells_stiffness = match first {
            Some(i) if robot.gravity.norm() > 0.0 => {
                let heavier = |factor: f64| {
                    let mut r = robot.clone();
                    r.density *= factor;
                    r
                };
                let h = sensitivities(
                    &traj.feedforward_rows()[i..=i],
                    (&heavier(1.0 + DIFFERENCE), &heavier(1.0 - DIFFERENCE)),
                    "density",
                )?;
                let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
                norm(&h[0]) <= SEPARABLE_WEIGHT_SHARE * norm(&rows[i])
            }
            _ => true,
        };
        Ok(StiffnessDirections {
            rows,
            hold_tells_stiffness,
        })
    }

    /// g at time `t` (s on the trajectory), blended as the poses are.
    pub fn at(&self, traj: &Trajectory, t: f64, scratch: &mut Vec<f64>) -> [f64; 3] {
        traj.blend(&self.rows, t, scratch);
        [scratch[0], scratch[1], scratch[2]]
    }

    /// Whether the settle hold's frames tell the stiffness (module docs):
    /// no gravity, or its share h = ∂tip/∂(ln ρ) at the first pose at most
    /// [`SEPARABLE_WEIGHT_SHARE`] of g there.
    pub fn hold_tells_stiffness(&self) -> bool {
        self.hold_tells_stiffness
    }
}

/// ∂tip/∂(ln p) at each of `rows` (tensions, N) by a central difference
/// between the robots `(up, down)`, p scaled by 1 ± [`DIFFERENCE`],
/// warm-started along the rows; a row with a non-finite tension gets 0.
fn sensitivities(
    rows: &[Vec<f64>],
    (up, down): (&Robot, &Robot),
    what: &str,
) -> Result<Vec<Vec<f64>>, PlanError> {
    let (up, down) = (
        Statics::new(up, SolverSettings::default()),
        Statics::new(down, SolverSettings::default()),
    );
    let (mut warm_up, mut warm_down) = (None, None);
    let mut out = Vec::with_capacity(rows.len());
    for tensions in rows {
        if tensions.iter().any(|v| !v.is_finite()) {
            out.push(vec![0.0; 3]);
            continue;
        }
        let more = up.solve(tensions, warm_up.as_ref());
        let less = down.solve(tensions, warm_down.as_ref());
        let (more, less) = more.and_then(|a| Ok((a, less?))).map_err(|e| {
            PlanError::Statics(format!(
                "the tip's sensitivity to {what} at {tensions:?} N: {e}"
            ))
        })?;
        out.push(
            ((more.position - less.position) / (2.0 * DIFFERENCE))
                .as_slice()
                .to_vec(),
        );
        warm_up = Some(more.warm);
        warm_down = Some(less.warm);
    }
    Ok(out)
}

/// The controller's correction as the planner models it for one input d
/// (module docs): e = −(c + M x + d), τ_f ḟ = e − f, ċ = k_i f, and the
/// error map Ṁ = k_M f x̃ᵀ / (ℓ² + |x̃|²) (x the setpoint from where
/// tracking began, x̃ from its running mean: the firmware's
/// `IntegralConfig`), in the base frame.
#[derive(Clone, Copy, Debug, Default)]
struct ModelLoop {
    c: [f64; 3],
    f: [f64; 3],
    map: [[f64; 3]; 3],
}

/// Where the controller's error map is evaluated and learns: the setpoint
/// from the map's origin (x) and from its running mean (x̃), m.
#[derive(Clone, Copy, Debug)]
struct MapPlace {
    x: [f64; 3],
    x_tilde: [f64; 3],
}

impl ModelLoop {
    /// The correction at `x`: c + M x.
    fn correction(&self, x: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|j| self.c[j] + (0..3).map(|i| self.map[j][i] * x[i]).sum::<f64>())
    }

    /// Advance by `dt` with input `d` at `place`, the integral (and the
    /// map) frozen when `quiet`; returns S[d] = −e = c + M x + d after the
    /// step.
    fn step(
        &mut self,
        gains: &IntegralGains,
        d: [f64; 3],
        place: &MapPlace,
        dt: f64,
        quiet: bool,
    ) -> [f64; 3] {
        if !quiet {
            let held = self.correction(&place.x);
            for (k, (c, f)) in self.c.iter_mut().zip(&mut self.f).enumerate() {
                let e = -(held[k] + d[k]);
                // Semi-implicit Euler: stable for dt ≪ τ_f, 1/k_i (1 ms
                // against 80 ms and 250 ms).
                // A controller without the filter (τ_f = 0) integrates e.
                *f += (dt / gains.filter_tau_s).min(1.0) * (e - *f);
                *c += dt * gains.ki_per_s * *f;
            }
            if gains.map_gain_per_s > 0.0 {
                let x2: f64 = place.x_tilde.iter().map(|v| v * v).sum();
                let rate = gains.map_gain_per_s * dt / (gains.map_scale_m.powi(2) + x2);
                for (row, f) in self.map.iter_mut().zip(self.f) {
                    for (m, xi) in row.iter_mut().zip(place.x_tilde) {
                        *m += rate * f * xi;
                    }
                }
            }
        }
        let held = self.correction(&place.x);
        std::array::from_fn(|k| held[k] + d[k])
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
    /// The controller's map origin (its first setpoint) and the running
    /// mean the map learns about, m, base frame.
    map_origin: Option<[f64; 3]>,
    map_mean: [f64; 3],
    history: VecDeque<Tick>,
    last_tick: Option<f64>,
    quiet_until: f64,
    /// No frame is fitted before this (after a hold), s.
    fit_after: f64,
    /// The loop below not following: its first and latest tick, s.
    held: Option<(f64, f64)>,
    last_frame: Option<f64>,
    /// The applied estimate before and after the shaped move under way.
    taking_up: Option<(f64, f64)>,
    /// Σ λ φ·z and Σ λ |φ|² of the fit.
    num: f64,
    den: f64,
    fitted: f64,
    applied: f64,
    /// The settle hold's frames are fitted.
    fit_hold: bool,
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
            map_origin: None,
            map_mean: [0.0; 3],
            history: VecDeque::new(),
            last_tick: None,
            quiet_until: f64::NEG_INFINITY,
            fit_after: f64::NEG_INFINITY,
            held: None,
            last_frame: None,
            taking_up: None,
            num: 0.0,
            den: 0.0,
            fitted: 0.0,
            applied: 0.0,
            fit_hold: true,
            offset: [0.0; 3],
        }
    }

    /// Whether the settle hold's frames are fitted (module docs; yes
    /// unless told otherwise): the model loop runs through the hold as the
    /// controller's integral and error map do, but where the robot's weight
    /// bends it, one pose cannot tell a stiffer backbone from a lighter one
    /// ([`StiffnessDirections::hold_tells_stiffness`]).
    pub fn fits_the_settle_hold(mut self, fit: bool) -> StiffnessEstimator {
        self.fit_hold = fit;
        self
    }

    /// The planner's tick at `t` (s on its clock) asking for the position
    /// `setpoint` (m, base frame) with the direction `g` there (m),
    /// whether a shaped move is under way, and whether the planner holds
    /// its first pose (`holding_first`: the settle hold, fitted only where
    /// [`fits_the_settle_hold`](Self::fits_the_settle_hold)); `steps`: the
    /// trajectory is stepwise, with the progress (0–1) of the shaped step
    /// under way if any.
    pub fn tick(
        &mut self,
        t: f64,
        setpoint: [f64; 3],
        g: [f64; 3],
        moving: bool,
        holding_first: bool,
        steps: Option<Option<f64>>,
    ) {
        let dt = self.last_tick.map_or(0.0, |t0| (t - t0).clamp(0.0, 0.05));
        self.last_tick = Some(t);
        if moving {
            self.quiet_until = t + self.quiet_after_move_s;
        }
        // The controller integrates nothing while it holds; once it
        // follows again it does, and frames are fitted a while later.
        let stopped = self.held.is_some_and(|(_, latest)| latest >= t);
        if !stopped {
            if let Some((first, _)) = self.held.take() {
                let recovery = (AFTER_HOLD_FACTOR * (t - first)).min(AFTER_HOLD_S);
                self.fit_after = self.fit_after.max(t + recovery);
            }
        }
        let quiet = moving || t < self.quiet_until || stopped;
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
        let place = self.map_place(setpoint, dt, quiet);
        let g = g.map(|v| if v.is_finite() { v } else { 0.0 });
        let phi = self.phi_loop.step(&self.gains, g, &place, dt, quiet);
        // The offset net of what the controller's integral already holds
        // of the stiffness error (module docs): −κ̂ φ + c_ψ.
        let held = self.psi_loop.correction(&place.x);
        self.offset = std::array::from_fn(|k| -self.applied * phi[k] + held[k]);
        let psi = self
            .psi_loop
            .step(&self.gains, self.offset.map(|o| -o), &place, dt, quiet);
        self.history.push_back(Tick {
            t,
            phi,
            psi,
            fitted: !quiet && t >= self.fit_after && (self.fit_hold || !holding_first),
        });
        while self.history.front().is_some_and(|h| h.t < t - HISTORY_S) {
            self.history.pop_front();
        }
    }

    /// The error map's place for the setpoint `setpoint` after `dt`: its
    /// running mean moves as the controller's does, only while it
    /// integrates (it sees no frame in a move's quiet), by backward Euler
    /// with the firmware's time constant.
    fn map_place(&mut self, setpoint: [f64; 3], dt: f64, quiet: bool) -> MapPlace {
        let setpoint = setpoint.map(|v| if v.is_finite() { v } else { 0.0 });
        let origin = match self.map_origin {
            Some(origin) => origin,
            None => {
                self.map_mean = setpoint;
                *self.map_origin.insert(setpoint)
            }
        };
        if !quiet {
            let a = dt / (f64::from(MAP_MEAN_TAU_S) + dt);
            for (m, p) in self.map_mean.iter_mut().zip(setpoint) {
                *m += a * (p - *m);
            }
        }
        MapPlace {
            x: std::array::from_fn(|k| setpoint[k] - origin[k]),
            x_tilde: std::array::from_fn(|k| setpoint[k] - self.map_mean[k]),
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
            let fit = (self.num / self.den).clamp(-MAX_STIFFNESS_ERROR, MAX_STIFFNESS_ERROR);
            self.fitted = if fit.abs() < MIN_STIFFNESS_ERROR {
                0.0
            } else {
                fit
            };
        }
    }

    /// The loop below does not follow the setpoints at `t` (the controller
    /// holds, or its commands stopped), told before the tick at `t`: the
    /// model's integral is frozen while it holds, as the controller's is,
    /// and no frame is fitted until [`AFTER_HOLD_FACTOR`] times the hold's
    /// length after it (at most [`AFTER_HOLD_S`]). A tip held while the
    /// path moves on is an error no stiffness explains; fitted, a 1 s cut
    /// link on the circle took the estimate to its bound (+0.30) and the
    /// tip 1.35 mm RMS off the path after.
    pub fn hold(&mut self, t: f64) {
        self.held = Some((self.held.map_or(t, |(first, _)| first), t));
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
        let directions = StiffnessDirections::new(traj, robot)?;
        Ok(StiffnessAdaptation {
            estimator: StiffnessEstimator::new(gains, quiet_after_move_s, mode_hz, loop_delay_s)
                .fits_the_settle_hold(directions.hold_tells_stiffness()),
            directions,
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
        let p = desired.point.pose;
        self.estimator.tick(
            t,
            [p[0], p[1], p[2]],
            g,
            desired.moving,
            desired.holding,
            steps,
        );
        along_axes(&desired.point, self.estimator.offset())
    }

    /// A tracker frame: the tip at `tip` (m, base frame) measured at `t`
    /// (s on the planner's clock), against what `motion` asked for then
    /// less the error the loop had there on the model
    /// ([`Motion::expected_error`]): a robot that is its file shows that
    /// one, and it tells nothing of the robot's stiffness.
    pub fn frame(&mut self, motion: &Motion, t: f64, tip: [f64; 3]) {
        self.estimator.frame(t, tip, |t| {
            let now = motion.at(t);
            let (p, e) = (now.point.pose, motion.expected_error(t, &now));
            [p[0] - e[0], p[1] - e[1], p[2] - e[2]]
        });
    }

    /// κ̂ applied now ([`StiffnessEstimator::applied`]).
    pub fn applied(&self) -> f64 {
        self.estimator.applied()
    }
}

#[cfg(test)]
mod tests;
