//! Learning for repeated paths (`docs/design.md` §6.4): the planner learns,
//! pass after pass of a periodic path, the offset that puts the tip on the
//! path — iterative learning control in the frequency domain of the path's
//! harmonics.
//!
//! A pass k of a path of period T leaves a tracking error e_k(φ) = r(φ) −
//! y_k(φ) over its phase φ ∈ [0, T). The learned offset goes to the
//! controller through the dynamic offset's channel (the net is asked for
//! the pose plus the offset, the error stays against the pose), and
//! reaches the tip through the loop P (mode, motors, the controller's own
//! integral correction; [`LoopModel`]). Per harmonic m of the path's
//! frequency 1/T:
//!
//!   U_{k+1,m} = Q_m (U_{k,m} + L_m E_{k,m}),   L_m = γ / P̂(j 2π m / T),
//!
//! so E_{k+1,m} = Q_m (1 − L_m P_m) E_{k,m} in the periodic steady state of
//! each pass. Q is a zero-phase low pass (real, 1 up to half its corner, a
//! cosine taper to 0 at the corner, set below the rod's first mode); L is
//! the model's inverse, its phase lead included. The mean (m = 0) is left
//! to the controller's integral, which rejects it (P̂(0) = 0).
//!
//! Monotonic convergence needs |Q_m (1 − L_m P_m)| < 1 at every harmonic.
//! [`LearningDesign::for_path`] checks that bound over a set of plants
//! around the model ([`LoopModel::tolerance_set`]: mode ±15 %, damping ½–2×,
//! the integral's gain ½–2×, motors ½–1.5×, 10 ms more delay) and lowers the
//! corner until it holds with a margin ([`MAX_CONTRACTION`]); when no
//! harmonic passes, learning stays off. At run time [`Learner`] stops
//! learning, keeps the offset of its best pass and says so, when the error
//! grows pass after pass ([`GROWTH`]).

use nalgebra::Complex;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

type Complex64 = Complex<f64>;

/// The worst contraction per pass a design may have over its tolerance set.
pub const MAX_CONTRACTION: f64 = 0.9;

/// The learning gain γ: half of the model's inverse per pass, so a plant
/// twice as strong as the model (or ±60° off in phase) still contracts.
pub const GAIN: f64 = 0.5;

/// A pass whose error RMS is above this factor of the best pass's
/// counts as growing; two in a row stop learning.
pub const GROWTH: f64 = 1.3;

/// An error growth smaller than this is noise, not growth, m.
pub const GROWTH_FLOOR_M: f64 = 10e-6;

/// The width of an error bin, s (the tracker's frames are averaged in it).
const BIN_S: f64 = 0.02;

/// How long after a pass's end its last tracker frames may still arrive, s
/// (trackers deliver late: up to 50 ms in the built-in realities).
pub const LATE_S: f64 = 0.25;

/// The longest run of bins without a frame a pass may have (a tracker at
/// 40 Hz leaves one bin in five empty, a dropped frame two in a row):
/// longer, and the pass is not used.
const MAX_GAP_BINS: usize = 5;

/// The largest learned offset per axis, m: a bound far above the periodic
/// errors a robot 10 % off its file leaves (≈ 0.5 mm), so the learning
/// stays linear where it should work and bounded where it should not.
pub const MAX_LEARNED_OFFSET: f64 = 5e-3;

/// The loop from the learned offset to the tip, per axis of the path's
/// tangent, as the planner models it:
///
///   P(s) = e^{−sθ} M(s) G(s) / (1 + M(s) G(s) K(s) e^{−sθ_fb}),
///
/// the rod's first mode G = ω²/(s² + 2ζωs + ω²), the motors' lag
/// M = 1/(τ_m s + 1) (the controller's lead covers the path's velocity, not
/// the offset's), the controller's integral on its filtered error
/// K = k_i / (s (τ_f s + 1)), a delay θ from planner to motors and θ_fb from
/// tip to controller (the tracker's). Quasi-static gain 1: the net maps a pose to
/// the tensions that reach it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopModel {
    /// The first mode's natural frequency, Hz.
    pub mode_hz: f64,
    /// Its damping ratio.
    pub damping_ratio: f64,
    /// The controller's integral gain k_i, 1/s (0: none).
    pub ki_per_s: f64,
    /// The time constant of the integral's error filter τ_f, s.
    pub filter_tau_s: f64,
    /// The motors' time constant τ_m, s.
    pub motor_tau_s: f64,
    /// Planner to motors, θ, s.
    pub delay_s: f64,
    /// Tip to controller (the tracker's latency), θ_fb, s.
    pub feedback_delay_s: f64,
}

impl LoopModel {
    /// P(j 2π f).
    pub fn response(&self, freq_hz: f64) -> Complex64 {
        let s = Complex64::new(0.0, TAU * freq_hz);
        let w = TAU * self.mode_hz;
        let g = w * w / (s * s + 2.0 * self.damping_ratio * w * s + w * w);
        let m = 1.0 / (self.motor_tau_s * s + 1.0);
        let k = self.ki_per_s / (s * (self.filter_tau_s * s + 1.0));
        let forward = m * g;
        (-s * self.delay_s).exp() * forward
            / (1.0 + forward * k * (-s * self.feedback_delay_s).exp())
    }

    /// The plants a design must contract on: this model with its mode
    /// ±15 % (the shaper's tolerance), its damping ½–2×, the integral's gain
    /// ½–2× (the error map adds to it), the motors ½–1.5× and 10 ms more
    /// delay each way.
    pub fn tolerance_set(&self) -> Vec<LoopModel> {
        let mut out = Vec::new();
        for f in [0.85, 1.0, 1.15] {
            for z in [0.5, 1.0, 2.0] {
                for k in [0.5, 1.0, 2.0] {
                    for m in [0.5, 1.0, 1.5] {
                        for d in [0.0, 0.01] {
                            out.push(LoopModel {
                                mode_hz: self.mode_hz * f,
                                damping_ratio: (self.damping_ratio * z).min(0.9),
                                ki_per_s: self.ki_per_s * k,
                                motor_tau_s: self.motor_tau_s * m,
                                delay_s: self.delay_s + d,
                                feedback_delay_s: self.feedback_delay_s + d,
                                ..*self
                            });
                        }
                    }
                }
            }
        }
        out
    }

    /// Check the numbers (a configuration file may hold anything).
    fn check(&self) -> Result<(), LearningError> {
        let finite_non_negative = [
            self.ki_per_s,
            self.filter_tau_s,
            self.motor_tau_s,
            self.delay_s,
            self.feedback_delay_s,
        ]
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0);
        if self.mode_hz > 0.0
            && self.mode_hz.is_finite()
            && (0.0..1.0).contains(&self.damping_ratio)
            && finite_non_negative
        {
            Ok(())
        } else {
            Err(LearningError::Bad(format!("{self:?}")))
        }
    }
}

/// A learning design for one periodic path on one loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearningDesign {
    /// The path's period T, s.
    pub period_s: f64,
    /// Q's corner, Hz: harmonics at or above it are not learned.
    pub cutoff_hz: f64,
    /// The learning gain γ.
    pub gain: f64,
    /// The loop the learning filter inverts.
    pub model: LoopModel,
    /// The worst |Q (1 − L P)| over the model's tolerance set.
    pub contraction: f64,
}

/// Why learning is off.
#[derive(Debug, thiserror::Error)]
pub enum LearningError {
    /// The path does not repeat.
    #[error("the path does not repeat (learning needs a periodic path: circle, figure-eight, helix, sweep)")]
    NotPeriodic,
    /// The design does not pass the convergence check.
    #[error(
        "the {period_s:.2} s path cannot be learned with a guaranteed contraction (the worst \
         |Q(1 − LP)| is {contraction:.2} over the loop's tolerance, at most {MAX_CONTRACTION} \
         allowed)"
    )]
    WouldNotConverge {
        /// The path's period, s.
        period_s: f64,
        /// The first harmonic's worst contraction.
        contraction: f64,
    },
    /// No mode to design from.
    #[error(
        "learning needs the rod's mode: it is designed with the step shaping (--shape-steps on)"
    )]
    NoMode,
    /// Numbers no design can have.
    #[error("learning design: numbers out of range: {0}")]
    Bad(String),
}

impl LearningDesign {
    /// The design for a path of period `period_s` on `model`: the corner
    /// starts at 85 % of the mode (the tolerance's lowest mode; above it
    /// the inverse asks for the resonance) and 5 Hz at most, and comes down a harmonic at a time
    /// until every harmonic contracts by [`MAX_CONTRACTION`] or better on
    /// the model's [`LoopModel::tolerance_set`].
    pub fn for_path(period_s: f64, model: LoopModel) -> Result<LearningDesign, LearningError> {
        model.check()?;
        if !(period_s > 0.0 && period_s.is_finite()) {
            return Err(LearningError::Bad(format!("period {period_s} s")));
        }
        let plants = model.tolerance_set();
        let start = (0.85 * model.mode_hz).min(5.0);
        let mut harmonics = (start * period_s).floor() as usize;
        let first = |cutoff_hz: f64| LearningDesign {
            period_s,
            cutoff_hz,
            gain: GAIN,
            model,
            contraction: 0.0,
        };
        while harmonics >= 1 {
            // The corner just above the last harmonic learned.
            let cutoff_hz = (harmonics as f64 + 0.5) / period_s;
            let mut design = first(cutoff_hz);
            design.contraction = design.worst_contraction(&plants);
            if design.contraction <= MAX_CONTRACTION {
                return Ok(design);
            }
            harmonics -= 1;
        }
        let mut one = first(1.5 / period_s);
        one.contraction = one.worst_contraction(&plants);
        Err(LearningError::WouldNotConverge {
            period_s,
            contraction: one.contraction,
        })
    }

    /// The harmonics learned: 1 ..= this.
    pub fn harmonics(&self) -> usize {
        (self.cutoff_hz * self.period_s).ceil().max(1.0) as usize - 1
    }

    /// Q at `freq_hz`: 1 up to half the corner, a cosine taper to 0 at it.
    pub fn q(&self, freq_hz: f64) -> f64 {
        let x = freq_hz / self.cutoff_hz;
        if x <= 0.5 {
            1.0
        } else if x >= 1.0 {
            0.0
        } else {
            0.5 * (1.0 + (std::f64::consts::PI * (x - 0.5) / 0.5).cos())
        }
    }

    /// Q_m L_m for harmonic m.
    pub fn filter(&self, m: usize) -> Complex64 {
        let f = m as f64 / self.period_s;
        self.q(f) * self.gain / self.model.response(f)
    }

    /// The worst |Q (1 − L P)| over the harmonics learned and `plants`.
    pub fn worst_contraction(&self, plants: &[LoopModel]) -> f64 {
        let mut worst: f64 = 0.0;
        for m in 1..=self.harmonics() {
            let f = m as f64 / self.period_s;
            let (q, l) = (self.q(f), self.gain / self.model.response(f));
            for p in plants {
                worst = worst.max((q * (1.0 - l * p.response(f))).norm());
            }
        }
        worst
    }
}

/// Learning for repeated paths: on, off, or a design made by a launcher.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum LearningChoice {
    /// No learning.
    #[default]
    Off,
    /// Designed from the step shaping's mode and the controller's gains
    /// where the path repeats.
    Auto,
    /// This design.
    Designed(LearningDesign),
}

/// The controller's integral correction as the planner models it (its
/// gains and error filter after any scaling to the robot's mode): the
/// learning uses k_i and τ_f, the stiffness adaptation the error map too.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntegralGains {
    /// k_i, 1/s.
    pub ki_per_s: f64,
    /// τ_f, s.
    pub filter_tau_s: f64,
    /// The error map's adaptation gain, 1/s (0: no map; the firmware's
    /// `IntegralConfig::map_gain`).
    #[serde(default)]
    pub map_gain_per_s: f64,
    /// The map's normalisation length, m (`IntegralConfig::map_scale`).
    #[serde(default = "default_map_scale_m")]
    pub map_scale_m: f64,
}

/// The map's normalisation length of a configuration that names none, m.
fn default_map_scale_m() -> f64 {
    0.01
}

/// The motors' time constant the model assumes, s (the plant's default).
pub const MODEL_MOTOR_TAU_S: f64 = crate::plant::MOTOR_TAU_S;
/// Planner to motors in the model, s: a controller period and transport.
pub const MODEL_DELAY_S: f64 = 0.002;
/// Tip to controller in the model, s: a tracker's latency.
pub const MODEL_FEEDBACK_DELAY_S: f64 = 0.01;

impl LearningChoice {
    /// The design a planner following a path of period `period_s` (None: it
    /// does not repeat) with `shaping` (the rod's mode; None: off) and a
    /// controller of `gains` uses: Ok(None) when off or when the path does
    /// not repeat; an error says why a learning asked for is off.
    pub fn resolve(
        self,
        shaping: Option<crate::plan::StepShaping>,
        period_s: Option<f64>,
        gains: IntegralGains,
    ) -> Result<Option<LearningDesign>, LearningError> {
        match self {
            LearningChoice::Off => Ok(None),
            LearningChoice::Designed(d) => {
                d.model.check()?;
                if !(d.period_s > 0.0 && d.cutoff_hz > 0.0 && d.gain > 0.0 && d.gain <= 1.0) {
                    return Err(LearningError::Bad(format!("{d:?}")));
                }
                // A design made elsewhere (a configuration file) is checked
                // against this robot's mode: a filter inverting another
                // rod's loop may push where this one pulls.
                if let Some(s) = shaping {
                    let truth = LoopModel {
                        mode_hz: s.mode_hz,
                        damping_ratio: s.damping_ratio,
                        ..d.model
                    };
                    let contraction = d.worst_contraction(&truth.tolerance_set());
                    if contraction > MAX_CONTRACTION {
                        return Err(LearningError::WouldNotConverge {
                            period_s: d.period_s,
                            contraction,
                        });
                    }
                }
                Ok(Some(d))
            }
            LearningChoice::Auto => {
                let Some(period_s) = period_s else {
                    return Ok(None);
                };
                let shaping = shaping.ok_or(LearningError::NoMode)?;
                let model = LoopModel {
                    mode_hz: shaping.mode_hz,
                    damping_ratio: shaping.damping_ratio,
                    ki_per_s: gains.ki_per_s,
                    filter_tau_s: gains.filter_tau_s,
                    motor_tau_s: MODEL_MOTOR_TAU_S,
                    delay_s: MODEL_DELAY_S,
                    feedback_delay_s: MODEL_FEEDBACK_DELAY_S,
                };
                LearningDesign::for_path(period_s, model).map(Some)
            }
        }
    }
}

/// What happened at the end of a pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PassOutcome {
    /// The pass was learned from: its error RMS, m.
    Learned {
        /// The pass's number (1: the first full pass after the path began).
        pass: u64,
        /// RMS over its bins of the error's length, m.
        rms_m: f64,
    },
    /// Too few tracker frames in the pass: nothing learned.
    TooFewFrames {
        /// The pass's number.
        pass: u64,
    },
    /// Measured after learning stopped: the offset is held.
    Held {
        /// The pass's number.
        pass: u64,
        /// RMS over its bins of the error's length, m.
        rms_m: f64,
    },
    /// The error grew: learning stopped, the best pass's offset kept.
    Stopped {
        /// The pass's number.
        pass: u64,
        /// The best pass's RMS, m.
        best_rms_m: f64,
        /// This pass's RMS, m.
        rms_m: f64,
    },
}

/// The learning at run time: configured once, then per tracker frame
/// [`Learner::measure`], per planner period [`Learner::advance`] and
/// [`Learner::offset`]. Allocates only in [`Learner::new`].
#[derive(Clone, Debug)]
pub struct Learner {
    design: LearningDesign,
    /// Q_m L_m, m = 1 ..= M.
    filter: Vec<Complex64>,
    /// The offset's coefficients U_m per axis (u(φ) = Σ Re U_m e^{j2πmφ/T}).
    u: Vec<[Complex64; 3]>,
    /// The offset before the last update, and when (path time, s) the
    /// switch to `u` began: an update is a step of the offset, made as the
    /// shaper makes a step ([`crate::plan::StepShaping`] on the model's
    /// mode), so it does not ring the rod (a switch at once rang the soft
    /// robot's mode at every pass).
    previous_u: Vec<[Complex64; 3]>,
    switch_at: Option<f64>,
    shaping: Option<crate::plan::StepShaping>,
    /// The offset in force during the best pass so far.
    best_u: Vec<[Complex64; 3]>,
    /// The offset in force when the pass being measured began.
    pass_u: Vec<[Complex64; 3]>,
    /// Error sums and frame counts per bin, for the pass measured and the next.
    sums: [Vec<[f64; 3]>; 2],
    counts: [Vec<u32>; 2],
    /// The mean error per bin of the pass being finished.
    means: Vec<[f64; 3]>,
    /// The pass being measured (passes are numbered from 1; pass 0, which
    /// holds the eased start, is not learned from).
    pass: u64,
    best_rms_m: f64,
    growing: u32,
    stopped: bool,
}

impl Learner {
    /// A learner for `design`, with no offset yet.
    pub fn new(design: LearningDesign) -> Learner {
        let m = design.harmonics();
        let bins = ((design.period_s / BIN_S).round() as usize).clamp(16, 4096);
        let zero = vec![[Complex64::new(0.0, 0.0); 3]; m];
        Learner {
            filter: (1..=m).map(|k| design.filter(k)).collect(),
            u: zero.clone(),
            previous_u: zero.clone(),
            switch_at: None,
            shaping: crate::plan::StepShaping::for_mode(
                design.model.mode_hz,
                design.model.damping_ratio,
            )
            .ok(),
            best_u: zero.clone(),
            pass_u: zero,
            sums: [vec![[0.0; 3]; bins], vec![[0.0; 3]; bins]],
            counts: [vec![0; bins], vec![0; bins]],
            means: vec![[0.0; 3]; bins],
            design,
            pass: 1,
            best_rms_m: f64::INFINITY,
            growing: 0,
            stopped: false,
        }
    }

    /// The design learned with.
    pub fn design(&self) -> &LearningDesign {
        &self.design
    }

    /// Whether learning stopped on a growing error.
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    fn bins(&self) -> usize {
        self.counts[0].len()
    }

    /// A tracker frame: the error (path less tip, m, along the tangent's
    /// axes) at path time `t_path` (s). Frames of pass 0 or of passes
    /// already finished are ignored.
    pub fn measure(&mut self, t_path: f64, error: [f64; 3]) {
        if !t_path.is_finite() || error.iter().any(|e| !e.is_finite()) {
            return;
        }
        let period = self.design.period_s;
        let pass = (t_path / period).floor();
        if pass < 1.0 || (pass as u64) < self.pass || (pass as u64) > self.pass + 1 {
            return;
        }
        let pass = pass as u64;
        let bins = self.bins();
        let bin = (((t_path - pass as f64 * period) / period * bins as f64) as usize).min(bins - 1);
        let side = (pass % 2) as usize;
        for (s, e) in self.sums[side][bin].iter_mut().zip(error) {
            *s += e;
        }
        self.counts[side][bin] += 1;
    }

    /// The planner's path time is `t_path`: finish the pass being measured
    /// once its late frames are in.
    pub fn advance(&mut self, t_path: f64) -> Option<PassOutcome> {
        let period = self.design.period_s;
        // NaN never finishes a pass.
        let due = (self.pass + 1) as f64 * period + LATE_S;
        if t_path.is_nan() || t_path < due {
            return None;
        }
        let pass = self.pass;
        let side = (pass % 2) as usize;
        self.previous_u.copy_from_slice(&self.u);
        let outcome = self.finish(pass, side);
        if self.u != self.previous_u {
            self.switch_at = Some(t_path);
        }
        self.sums[side].iter_mut().for_each(|s| *s = [0.0; 3]);
        self.counts[side].iter_mut().for_each(|c| *c = 0);
        self.pass += 1;
        self.pass_u.copy_from_slice(&self.u);
        Some(outcome)
    }

    fn finish(&mut self, pass: u64, side: usize) -> PassOutcome {
        let bins = self.bins();
        // Mean per bin with a frame; an empty bin (a tracker slower than
        // the bins) interpolated between its neighbours, around the pass.
        // A run of more than MAX_GAP_BINS empty bins refuses the pass. No
        // allocation: this runs in the planner's loop.
        let (s, c) = (&self.sums[side], &self.counts[side]);
        let Some(first) = (0..bins).find(|&n| c[n] > 0) else {
            return PassOutcome::TooFewFrames { pass };
        };
        let mut a = first;
        loop {
            let b = (1..=bins)
                .map(|j| (a + j) % bins)
                .find(|&n| c[n] > 0)
                .unwrap_or(a);
            let span = match (b + bins - a) % bins {
                0 => bins,
                span => span,
            };
            if span - 1 > MAX_GAP_BINS {
                return PassOutcome::TooFewFrames { pass };
            }
            let (ea, eb) = (s[a].map(|v| v / c[a] as f64), s[b].map(|v| v / c[b] as f64));
            for j in 0..span {
                let f = j as f64 / span as f64;
                self.means[(a + j) % bins] = std::array::from_fn(|k| ea[k] + f * (eb[k] - ea[k]));
            }
            a = b;
            if a == first {
                break;
            }
        }
        let rms_m = (self
            .means
            .iter()
            .map(|e| e.iter().map(|v| v * v).sum::<f64>())
            .sum::<f64>()
            / bins as f64)
            .sqrt();
        if self.stopped {
            return PassOutcome::Held { pass, rms_m };
        }
        if rms_m < self.best_rms_m {
            self.best_rms_m = rms_m;
            self.best_u.copy_from_slice(&self.pass_u);
            self.growing = 0;
        } else if rms_m > GROWTH * self.best_rms_m && rms_m - self.best_rms_m > GROWTH_FLOOR_M {
            self.growing += 1;
            if self.growing >= 2 {
                self.stopped = true;
                self.u.copy_from_slice(&self.best_u);
                return PassOutcome::Stopped {
                    pass,
                    best_rms_m: self.best_rms_m,
                    rms_m,
                };
            }
        } else {
            self.growing = 0;
        }
        // E_m = (2/N) Σ_n e_n e^{−j2πm(n+½)/N}; U_m += Q_m L_m E_m.
        for (m, (u, ql)) in self.u.iter_mut().zip(&self.filter).enumerate() {
            let k = (m + 1) as f64;
            let mut e = [Complex64::new(0.0, 0.0); 3];
            for (n, mean) in self.means.iter().enumerate() {
                let w = Complex64::from_polar(
                    2.0 / bins as f64,
                    -TAU * k * (n as f64 + 0.5) / bins as f64,
                );
                for (ea, v) in e.iter_mut().zip(mean) {
                    *ea += w * v;
                }
            }
            for (ua, ea) in u.iter_mut().zip(e) {
                *ua += ql * ea;
            }
        }
        PassOutcome::Learned { pass, rms_m }
    }

    /// The learned offset at path time `t_path`, m along the tangent's axes
    /// (zero before the first pass is learned), each axis within
    /// ±[`MAX_LEARNED_OFFSET`].
    pub fn offset(&self, t_path: f64) -> [f64; 3] {
        if !t_path.is_finite() {
            return [0.0; 3];
        }
        let now = self.evaluate(&self.u, t_path);
        let done = match (self.switch_at, self.shaping) {
            (Some(at), Some(s)) => s.progress(t_path - at).0,
            _ => 1.0,
        };
        let out = if done < 1.0 {
            let before = self.evaluate(&self.previous_u, t_path);
            std::array::from_fn(|k| before[k] + done * (now[k] - before[k]))
        } else {
            now
        };
        out.map(|v| v.clamp(-MAX_LEARNED_OFFSET, MAX_LEARNED_OFFSET))
    }

    /// Σ_m Re U_m e^{j2πmφ/T} at path time `t_path`.
    fn evaluate(&self, u: &[[Complex64; 3]], t_path: f64) -> [f64; 3] {
        let phase = TAU * t_path.rem_euclid(self.design.period_s) / self.design.period_s;
        let step = Complex64::from_polar(1.0, phase);
        let mut rotor = step;
        let mut out = [0.0; 3];
        for u in u {
            for (o, ua) in out.iter_mut().zip(u) {
                *o += (ua * rotor).re;
            }
            rotor *= step;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default robot's loop: mode 3.6 Hz, ζ 3.4 %, k_i 4 /s.
    fn seed_loop() -> LoopModel {
        LoopModel {
            mode_hz: 3.6,
            damping_ratio: 0.034,
            ki_per_s: 4.0,
            filter_tau_s: 0.08,
            motor_tau_s: 0.02,
            delay_s: 0.002,
            feedback_delay_s: 0.01,
        }
    }

    /// The path's disturbance d(t) (what the tip misses without learning):
    /// a model error turning with a 0.4 Hz circle and its second harmonic.
    fn disturbance(t: f64, period: f64) -> [f64; 3] {
        let w = TAU / period;
        [
            0.4e-3 * (w * t).cos() + 0.1e-3 * (2.0 * w * t + 0.7).sin(),
            0.4e-3 * (w * t).sin(),
            0.0,
        ]
    }

    /// Runs `passes` passes of a plant `truth` in its periodic steady state
    /// (the tip's harmonics are P(f_m) U_m: linear theory, independent of
    /// the learner's bins and sums), with tracker frames at 100 Hz and
    /// `noise_m` of deterministic jitter; the RMS error of each pass, m.
    fn run(
        learner: &mut Learner,
        truth: &LoopModel,
        passes: usize,
        noise_m: f64,
    ) -> Vec<PassOutcome> {
        run_at(learner, truth, passes, noise_m, 0.01, usize::MAX)
    }

    /// [`run`] with a frame every `dt` s, every `drop`-th frame lost.
    fn run_at(
        learner: &mut Learner,
        truth: &LoopModel,
        passes: usize,
        noise_m: f64,
        dt: f64,
        drop: usize,
    ) -> Vec<PassOutcome> {
        let period = learner.design().period_s;
        let mut out = Vec::new();
        let steps = (passes as f64 * period / dt) as usize;
        for i in 0..steps {
            let t = i as f64 * dt;
            // The tip's answer to the offset in force: Σ Re P_m U_m e^{jmΩt}.
            let mut tip = [0.0; 3];
            let phase = TAU * t / period;
            for (m, u) in learner.u.iter().enumerate() {
                let p = truth.response((m + 1) as f64 / period);
                let rotor = Complex64::from_polar(1.0, (m + 1) as f64 * phase);
                for (y, ua) in tip.iter_mut().zip(u) {
                    *y += (p * ua * rotor).re;
                }
            }
            let d = disturbance(t, period);
            let jitter = noise_m * ((i * 7919) % 101) as f64 / 50.0 - noise_m;
            let e: [f64; 3] = std::array::from_fn(|k| d[k] - tip[k] + jitter);
            if i % drop != drop - 1 {
                learner.measure(t, e);
            }
            if let Some(o) = learner.advance(t) {
                out.push(o);
            }
        }
        out
    }

    fn rms_of(o: &PassOutcome) -> f64 {
        match *o {
            PassOutcome::Learned { rms_m, .. } | PassOutcome::Held { rms_m, .. } => rms_m,
            PassOutcome::Stopped { rms_m, .. } => rms_m,
            PassOutcome::TooFewFrames { .. } => f64::NAN,
        }
    }

    /// The design contracts on its whole tolerance set; on a plant inside
    /// it (mode 12 % low, integral 1.6× the model's: the error map's
    /// share) the error falls pass after pass to the jitter's floor —
    /// from 0.41 mm to under 10 µm in ten passes.
    #[test]
    fn learning_converges_monotonically_on_a_plant_within_the_tolerance() {
        let design = LearningDesign::for_path(2.5, seed_loop()).unwrap();
        assert!(design.contraction <= MAX_CONTRACTION, "{design:?}");
        assert!(design.harmonics() >= 4, "{design:?}");
        let truth = LoopModel {
            mode_hz: 3.6 * 0.88,
            ki_per_s: 6.4,
            ..seed_loop()
        };
        let mut learner = Learner::new(design);
        let outcomes = run(&mut learner, &truth, 14, 0.0);
        let rms: Vec<f64> = outcomes.iter().map(rms_of).collect();
        assert!(rms.len() >= 11, "{outcomes:?}");
        assert!(rms[0] > 3e-4, "the first pass has the disturbance: {rms:?}");
        for w in rms.windows(2).take(6) {
            assert!(w[1] < w[0], "monotonic: {rms:?}");
        }
        assert!(rms[10] < 1e-5, "converged: {rms:?}");
        assert!(!learner.stopped());
        // An EM tracker's 40 Hz with a frame in 20 lost leaves bins empty:
        // they are interpolated, and the passes still learn.
        let mut slow = Learner::new(design);
        let outcomes = run_at(&mut slow, &truth, 14, 0.0, 0.025, 20);
        let rms: Vec<f64> = outcomes.iter().map(rms_of).collect();
        assert!(rms.len() >= 11 && rms[10] < 2e-5, "{outcomes:?}");
        // A tracker that delivers one frame a tenth of a second learns nothing.
        let mut starved = Learner::new(design);
        let outcomes = run_at(&mut starved, &truth, 4, 0.0, 0.13, usize::MAX);
        assert!(
            outcomes
                .iter()
                .all(|o| matches!(o, PassOutcome::TooFewFrames { .. })),
            "{outcomes:?}"
        );
        assert_eq!(starved.offset(1.0), [0.0; 3]);
    }

    /// A learning filter built on a deliberately wrong model (the mode at a
    /// tenth of its frequency: its inverse turns the phase past 90° at the
    /// path's harmonics) fails the convergence check against the true
    /// loop's tolerance set, and a design from it is refused; run anyway,
    /// its error grows, learning stops on the second growing pass and
    /// holds the offset of the best pass, whose error comes back.
    #[test]
    fn a_wrong_model_fails_the_check_and_a_growing_error_stops_learning() {
        let wrong = LoopModel {
            mode_hz: 0.36,
            ..seed_loop()
        };
        let design = LearningDesign {
            period_s: 2.5,
            cutoff_hz: 2.1,
            gain: GAIN,
            model: wrong,
            contraction: 0.0,
        };
        let truth = seed_loop();
        assert!(
            design.worst_contraction(&truth.tolerance_set()) > 1.0,
            "the check sees the wrong model"
        );
        assert!(design.worst_contraction(&wrong.tolerance_set()) < 1.0);
        let mut learner = Learner::new(design);
        let outcomes = run(&mut learner, &truth, 12, 2e-6);
        let stop = outcomes
            .iter()
            .position(|o| matches!(o, PassOutcome::Stopped { .. }))
            .unwrap_or_else(|| panic!("never stopped: {outcomes:?}"));
        assert!(learner.stopped());
        let best = match outcomes[stop] {
            PassOutcome::Stopped {
                best_rms_m, rms_m, ..
            } => {
                assert!(rms_m > 2.0 * best_rms_m, "{outcomes:?}");
                best_rms_m
            }
            _ => unreachable!(),
        };
        // The pass after the stop still began with the grown offset; from
        // the next one on the best pass's offset is held, and so its error.
        let held = &outcomes[stop + 2..];
        assert!(held.len() >= 3, "{outcomes:?}");
        for o in held {
            assert!(matches!(o, PassOutcome::Held { .. }), "{o:?}");
            assert!(
                (rms_of(o) / best - 1.0).abs() < 0.05,
                "{o:?} vs best {best}"
            );
        }
    }

    /// Through the choice: a design from a configuration file built on the
    /// wrong model is refused against the robot's mode, the right one
    /// passes; `Auto` designs only for a repeated path and with a mode.
    #[test]
    fn the_choice_checks_a_design_against_the_robots_mode() {
        let shaping = crate::plan::StepShaping::for_mode(3.6, 0.034).unwrap();
        let gains = IntegralGains {
            ki_per_s: 4.0,
            filter_tau_s: 0.08,
            map_gain_per_s: 0.0,
            map_scale_m: 0.01,
        };
        let right = LearningChoice::Auto
            .resolve(Some(shaping), Some(2.5), gains)
            .unwrap()
            .unwrap();
        assert_eq!(right.model.mode_hz, 3.6);
        let again = LearningChoice::Designed(right).resolve(Some(shaping), Some(2.5), gains);
        assert_eq!(again.unwrap(), Some(right));
        let wrong = LearningDesign {
            model: LoopModel {
                mode_hz: 0.36,
                ..right.model
            },
            ..right
        };
        match LearningChoice::Designed(wrong).resolve(Some(shaping), Some(2.5), gains) {
            Err(LearningError::WouldNotConverge { contraction, .. }) => assert!(contraction > 1.0),
            other => panic!("{other:?}"),
        }
        let off = LearningChoice::Auto.resolve(Some(shaping), None, gains);
        assert_eq!(off.unwrap(), None, "a path that does not repeat");
        assert!(matches!(
            LearningChoice::Auto.resolve(None, Some(2.5), gains),
            Err(LearningError::NoMode)
        ));
        assert_eq!(
            LearningChoice::Off
                .resolve(Some(shaping), Some(2.5), gains)
                .unwrap(),
            None
        );
    }

    /// A soft robot's loop (mode 1.07 Hz) on a 5 s path learns only the
    /// harmonics below 85 % of its mode; a path too fast for its mode
    /// (period 0.5 s: the first harmonic at 2 Hz, past the mode) is
    /// refused with the reason.
    #[test]
    fn the_corner_follows_the_mode_and_a_path_past_it_is_refused() {
        let soft = LoopModel {
            mode_hz: 1.07,
            ki_per_s: 1.19,
            ..seed_loop()
        };
        let d = LearningDesign::for_path(5.0, soft).unwrap();
        let top = d.harmonics() as f64 / d.period_s;
        assert!(top <= 0.85 * 1.07 && d.harmonics() >= 1, "{d:?}");
        match LearningDesign::for_path(0.5, soft) {
            Err(LearningError::WouldNotConverge { .. }) => {}
            other => panic!("{other:?}"),
        }
        assert!(LearningDesign::for_path(f64::NAN, soft).is_err());
    }

    /// The model's response is the closed form at two limits: the
    /// integral rejects the mean (P → 0 as f → 0), and far below the mode
    /// and with no integral the loop passes the offset whole.
    #[test]
    fn the_loop_model_has_its_limits() {
        assert!(seed_loop().response(1e-6).norm() < 1e-5);
        let open = LoopModel {
            ki_per_s: 0.0,
            delay_s: 0.0,
            ..seed_loop()
        };
        assert!((open.response(0.001) - Complex64::new(1.0, 0.0)).norm() < 1e-3);
        // At the integral's corner k_i/2π the closed loop is jω/(jω + k_i).
        let f = 4.0 / TAU;
        let quasi = LoopModel {
            mode_hz: 1e4,
            filter_tau_s: 0.0,
            motor_tau_s: 0.0,
            delay_s: 0.0,
            feedback_delay_s: 0.0,
            ..seed_loop()
        };
        let want = Complex64::new(0.0, 4.0) / Complex64::new(4.0, 4.0);
        assert!((quasi.response(f) - want).norm() < 1e-4);
    }
}
